"""Session fixtures shared by the harness tests (test_identify, test_synthesize, test_validate_report,
test_cli, test_main_job).

Load with ``pytest_plugins = ["harness_fixtures"]`` in a test module: the fixtures are then
shared across files, so each expensive step runs once per session:

* two synthetic campaigns with known truth: ``clean_campaign`` (``noise = 0``) and
  ``noisy_campaign`` (``noise = 1``);
* one joint identification of each (``clean_joint``, ``noisy_joint``; 15-35 s each);
* the paper-style per-run identification of the noisy campaign (``noisy_paper``);
* the terrain validation of a third, full-length noisy campaign (``terrain_campaign``) with the
  true soil and with the paper's initial guess (``terrain_validation``);
* a report of the noisy campaign (``noisy_report``).

The end-to-end main job (``bash scripts/main.sh`` in a fresh ``git clone``) takes one to two
minutes: the clone's venv (about 25 s of CPU), its FMU build, and the report (the fits and the
diagnosis: most of it).  When test_main_job is
selected, it is started in the background as soon as collection finishes, so it runs on the
second core while the other tests run; ``main_job`` waits for it.  Under pytest-xdist (the
README's test command runs two workers) every worker collects every test, so none starts it at
collection: the worker that runs test_main_job starts it when the test asks for it, while the
other worker goes on with its own tests.  It is killed (by its own process group id) if the
session ends first.

Under pytest-xdist each worker is a process of its own, so a session fixture would be computed once
per worker that needs it.  The campaigns, fits and short campaigns above are computed once per
session instead (:func:`computed_once`): the first worker that asks computes them into a folder
every worker of the session shares, and the others read that result back.  They are deterministic
(fixed seeds), so which worker computed them does not matter.

Run with ``-s`` to see the measured numbers (estimates against truth, z-scores, RMS errors,
wall times).  (PYTEST_DONT_REWRITE: no asserts here; the test modules import helpers from this
module before pytest loads it as a plugin.)
"""

from __future__ import annotations

import fcntl
import json
import os
import pickle
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, TypeVar

import pytest

REPO = Path(__file__).resolve().parents[2]

#: Synthetic campaigns with known truth.  time_scale 1.0 = the paper's run lengths (22, 35, 32 and
#: 30 s); 0.5 halves them.
#: * noise-free, for the joint fit's recovery: full length.  Half length still recovers the truth
#:   within about 1.2 % (seeds 1-5), full length within 0.4 %: a wide margin to the 2 % spec.
#: * noisy, for the joint fit's uncertainty and the paper-style fits: half length (z-scores
#:   within 2 on seeds 1-5 and 42 at half length; the paper-style fits take half the time).
#: * noisy, for the terrain validation: full length.  With a 15 s terrain run the start-up
#:   transient (the PID catching the measured spins) dominates the whole-run torque RMS (true
#:   soil 23 N m against 39 N m for the initial guess); over 30 s it is 24 against 66 N m.
CLEAN_SEED = 7
CLEAN_TIME_SCALE = 1.0
NOISY_SEED = 42
NOISY_TIME_SCALE = 0.5
TERRAIN_SEED = 2013
TERRAIN_TIME_SCALE = 1.0

#: The paper's steady windows (s) at time_scale 1 (Petersen & McPhee 2013, Tables 1-3).
PAPER_WINDOWS = {"dbp1": (8.0, 18.0), "dbp2": (15.0, 25.0), "dbp3": (15.0, 25.0)}
#: Run lengths (s) at time_scale 1 (juno.synthesize: about 22, 35 and 32 s; terrain run 30 s).
RUN_LENGTHS = {"dbp1": 22.0, "dbp2": 35.0, "dbp3": 32.0, "t3d": 30.0}

#: The main job: shortened campaign, generous time limit.  Its test checks what the job writes
#: (the report's sections, tables and figures, the summary), not the estimates, so a quarter of
#: the paper's run lengths serves as well as half; most of the job's CPU time is the report's
#: fits and diagnosis, which a quarter cuts by about a quarter (65 s to 50 s of CPU, measured).
MAIN_JOB_TIME_SCALE = "0.25"
MAIN_JOB_TIMEOUT = 900.0
MAIN_JOB_FILE = "test_main_job.py"


def say(message: str) -> None:
    """Prints a measured number so that it shows with ``pytest -s``."""
    print(f"[harness] {message}", flush=True)


def juno_command() -> str:
    """The ``juno`` console script of the venv running the tests (.venv/bin/juno)."""
    beside = Path(sys.executable).with_name("juno")
    if beside.is_file():
        return str(beside)
    fallback = REPO / ".venv" / "bin" / "juno"
    if fallback.is_file():
        return str(fallback)
    pytest.fail(f"no juno command beside {sys.executable} nor at {fallback}: run scripts/setup.sh", pytrace=False)


def run_juno(*args: str, timeout: float = 300.0, cwd: str | os.PathLike | None = None,
             env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    """Runs ``juno ARGS`` as a user would, capturing stdout and stderr as text."""
    return subprocess.run([juno_command(), *map(str, args)], capture_output=True, text=True, timeout=timeout,
                          cwd=cwd, env=env)


def run_juno_here(capsys, *args: str) -> subprocess.CompletedProcess:
    """Runs ``juno ARGS`` in this process (``juno.cli.main``, the console script's own code),
    with its exit code, stdout and stderr as :func:`run_juno` returns them.

    For the refusals and short runs the tests make by the dozen: a ``juno`` process spends most
    of a refusal's CPU time starting Python and importing its libraries (0.7-0.9 s of CPU each),
    which this leaves out.  What a user types is still covered by :func:`run_juno` (help, the
    runs end to end).  ``capsys`` is the calling test's fixture; what was printed before is
    discarded."""
    from juno.cli import main

    argv = [str(a) for a in args]
    capsys.readouterr()
    try:
        code = main(argv)
    except SystemExit as exc:          # argparse's refusals exit
        code = 0 if exc.code is None else exc.code
    out = capsys.readouterr()
    return subprocess.CompletedProcess(["juno", *argv], code, out.out, out.err)


def tree_snapshot(root: Path) -> dict[str, bytes]:
    """Relative path -> content of every file below ``root`` (to prove a folder is unchanged)."""
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


# ------------------------------------------------------------------------- pytest hooks

def pytest_configure(config) -> None:
    config.addinivalue_line(
        "markers", "slow: takes minutes (the end-to-end main job); still part of the default run and CI")


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(session, config, items) -> None:
    """Marks the main job test ``slow`` (here rather than by a decorator, so that the marker is
    registered first even when test_main_job.py is the only file collected)."""
    for item in items:
        if Path(str(item.fspath)).name == MAIN_JOB_FILE:
            item.add_marker("slow")


def pytest_collection_finish(session) -> None:
    """Starts the main job in the background when its test is selected (see the module docstring)."""
    if session.config.option.collectonly or hasattr(session.config, "workerinput"):
        return   # an xdist worker: the test may run on another worker, so main_job starts it
    if any(Path(str(item.fspath)).name == MAIN_JOB_FILE for item in session.items):
        _start_main_job()


def pytest_sessionfinish(session, exitstatus) -> None:
    global _MAIN_JOB
    if _MAIN_JOB is not None:
        _MAIN_JOB.stop()
        _MAIN_JOB = None


# ---------------------------------------------------------------------- the main job

@dataclass
class MainJob:
    """``bash scripts/main.sh`` running in a fresh clone of the repository's committed state."""

    workdir: Path
    clone: Path
    log_path: Path
    started: float
    process: subprocess.Popen | None = None
    clone_error: str | None = None
    finished: float | None = None
    returncode: int | None = None

    def wait(self, timeout: float = MAIN_JOB_TIMEOUT) -> int:
        """Waits for the job; returns its exit code (fails the test on a timeout)."""
        if self.clone_error is not None:
            pytest.fail(f"could not make a fresh clone of {REPO}: {self.clone_error}", pytrace=False)
        if self.returncode is None:
            remaining = max(timeout - (time.perf_counter() - self.started), 1.0)
            try:
                self.returncode = self.process.wait(remaining)
            except subprocess.TimeoutExpired:
                self.stop()
                pytest.fail(f"bash scripts/main.sh did not finish within {timeout:.0f} s\n{self.log_tail()}",
                            pytrace=False)
            self.finished = time.perf_counter()
        return self.returncode

    @property
    def wall_time(self) -> float:
        return (self.finished or time.perf_counter()) - self.started

    def log_tail(self, n: int = 60) -> str:
        try:
            lines = self.log_path.read_text(errors="replace").splitlines()
        except OSError:
            return "(no log)"
        return "--- main job log (last lines) ---\n" + "\n".join(lines[-n:])

    def log(self) -> str:
        return self.log_path.read_text(errors="replace") if self.log_path.is_file() else ""

    def stop(self) -> None:
        """Kills the job's own process group if it still runs, then removes its folder."""
        if self.process is not None and self.process.poll() is None:
            try:
                os.killpg(self.process.pid, signal.SIGTERM)
                self.process.wait(10)
            except (ProcessLookupError, subprocess.TimeoutExpired):
                try:
                    os.killpg(self.process.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
        shutil.rmtree(self.workdir, ignore_errors=True)


_MAIN_JOB: MainJob | None = None


def _clean_environment() -> dict[str, str]:
    """The caller's environment without anything that would tie the clone to this checkout."""
    env = dict(os.environ)
    for name in list(env):
        if name.startswith("JUNO_") or name in ("VIRTUAL_ENV", "PYTHONPATH", "PYTHONHOME", "PYTEST_ADDOPTS"):
            env.pop(name)
    venvs = [REPO / ".venv"] + ([Path(sys.prefix)] if sys.prefix != sys.base_prefix else [])

    def in_a_venv(entry: str) -> bool:
        path = Path(entry).resolve()
        return any(path == v.resolve() or v.resolve() in path.parents for v in venvs)

    parts = [p for p in env.get("PATH", "").split(os.pathsep) if p and not in_a_venv(p)]
    env["PATH"] = os.pathsep.join(parts)
    env["JUNO_TIME_SCALE"] = MAIN_JOB_TIME_SCALE
    env["MPLBACKEND"] = "Agg"
    return env


def _start_main_job() -> MainJob:
    """Clones the committed state of the repository and starts ``bash scripts/main.sh`` in it."""
    global _MAIN_JOB
    if _MAIN_JOB is not None:
        return _MAIN_JOB
    workdir = Path(tempfile.mkdtemp(prefix="juno-main-job-"))
    clone = workdir / "JunoRover"
    job = MainJob(workdir=workdir, clone=clone, log_path=workdir / "main.log", started=time.perf_counter())
    _MAIN_JOB = job
    proc = subprocess.run(["git", "clone", "--quiet", "--no-hardlinks", str(REPO), str(clone)],
                          capture_output=True, text=True)
    if proc.returncode != 0:
        job.clone_error = f"git clone exited with {proc.returncode}: {proc.stderr.strip()}"
        return job
    log = open(job.log_path, "wb")
    try:
        job.process = subprocess.Popen(["bash", "scripts/main.sh"], cwd=clone, env=_clean_environment(),
                                       stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT,
                                       start_new_session=True)
    finally:
        log.close()
    return job


@pytest.fixture(scope="session")
def main_job() -> MainJob:
    """The background main job (started now if collection did not start it)."""
    return _start_main_job()


# ------------------------------------------------------- results shared by the workers

_T = TypeVar("_T")


def shared_root(tmp_path_factory) -> Path:
    """The folder every pytest-xdist worker of this session shares: the parent of a worker's
    base temporary folder (``pytest-N/popen-gwK``), or the base folder itself without xdist."""
    base = tmp_path_factory.getbasetemp()
    root = (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / "computed-once"
    root.mkdir(exist_ok=True)
    return root


def computed_once(tmp_path_factory, key: str, compute: Callable[[Path], _T]) -> _T:
    """``compute(folder)``, computed once per session whichever worker asks first.

    The first caller holds ``key``'s lock while it computes into ``folder`` (an empty folder
    named ``key`` in :func:`shared_root`) and pickles the result beside it; a caller that comes
    later, or waits on the lock, reads the pickled result back.  A computation that raises
    leaves no result: the next caller computes again (and fails the same way).  ``compute``
    must not write outside ``folder``, and its result must pickle."""
    root = shared_root(tmp_path_factory)
    result = root / f"{key}.pickle"
    with open(root / f"{key}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if result.is_file():
            return pickle.loads(result.read_bytes())
        folder = root / key
        shutil.rmtree(folder, ignore_errors=True)   # what a computation that raised left
        folder.mkdir()
        value = compute(folder)
        partial = root / f"{key}.pickle.partial"
        partial.write_bytes(pickle.dumps(value))
        partial.replace(result)                     # whole or not at all
        return value


# --------------------------------------------------------------- synthetic campaigns

@dataclass
class SynthCampaign:
    """A synthesized campaign: its folder, the loaded manifest and the truth (read by tests only)."""

    path: Path
    campaign: Any
    truth: dict[str, Any]
    seed: int
    noise: float
    time_scale: float
    seconds: float

    @property
    def soil(self) -> dict[str, float]:
        return dict(self.truth["soil"])


@pytest.fixture(scope="session")
def harness_fmu(fmu_path):
    """One JunoFMU (extracted once, instance reused) for every in-process fixture."""
    from juno.simulator import JunoFMU

    with JunoFMU(fmu_path) as fmu:
        yield fmu


def make_campaign(out: Path, fmu, seed: int, noise: float, time_scale: float, effect: str = "none",
                  strength: float = 1.0) -> SynthCampaign:
    from juno.campaign import load_campaign
    from juno.synthesize import synthesize

    start = time.perf_counter()
    path = synthesize(out, effect=effect, strength=strength, seed=seed, noise=noise, fmu=fmu,
                      time_scale=time_scale)
    seconds = time.perf_counter() - start
    truth = json.loads((Path(path) / "truth.json").read_text())
    return SynthCampaign(Path(path), load_campaign(path), truth, seed, noise, time_scale, seconds)


def _shared_campaign(tmp_path_factory, fmu, key: str, what: str, seed: int, noise: float,
                     time_scale: float) -> SynthCampaign:
    """The session's synthetic campaign ``key``, synthesized once for every xdist worker
    (computed_once) and named ``what`` in the progress line."""
    def synthesized(folder: Path) -> SynthCampaign:
        c = make_campaign(folder / "campaign", fmu, seed, noise, time_scale)
        say(f"synthesized the {what} campaign (seed {seed}, time_scale {time_scale}) in {c.seconds:.1f} s")
        return c

    return computed_once(tmp_path_factory, key, synthesized)


@pytest.fixture(scope="session")
def clean_campaign(tmp_path_factory, harness_fmu) -> SynthCampaign:
    """Synthetic campaign without sensor noise (noise = 0)."""
    return _shared_campaign(tmp_path_factory, harness_fmu, "clean_campaign", "noise-free", CLEAN_SEED, 0.0,
                            CLEAN_TIME_SCALE)


@pytest.fixture(scope="session")
def noisy_campaign(tmp_path_factory, harness_fmu) -> SynthCampaign:
    """Synthetic campaign with the documented sensor noise (noise = 1), half length."""
    return _shared_campaign(tmp_path_factory, harness_fmu, "noisy_campaign", "noisy", NOISY_SEED, 1.0,
                            NOISY_TIME_SCALE)


@pytest.fixture(scope="session")
def terrain_campaign(tmp_path_factory, harness_fmu) -> SynthCampaign:
    """Synthetic campaign with sensor noise, full length, for the terrain validation (no fit)."""
    return _shared_campaign(tmp_path_factory, harness_fmu, "terrain_campaign", "terrain", TERRAIN_SEED, 1.0,
                            TERRAIN_TIME_SCALE)


#: Short campaigns for structure, determinism and CLI checks (runs of 5.5-8.8 s).
SMALL_TIME_SCALE = 0.25


@pytest.fixture(scope="session")
def small_campaign(tmp_path_factory, harness_fmu):
    """Factory of short synthetic campaigns, cached per (seed, effect, noise, copy) for the
    session (computed_once).

    Each lives in its own parent folder under the same leaf name ``campaign``, so two of them
    can be compared file by file.  ``copy`` gives a second, independent synthesis.
    """
    cache: dict[tuple, SynthCampaign] = {}

    def get(seed: int, effect: str = "none", noise: float = 1.0, copy: int = 0) -> SynthCampaign:
        key = (seed, effect, noise, copy)
        if key not in cache:
            def synthesized(folder: Path) -> SynthCampaign:
                c = make_campaign(folder / "campaign", harness_fmu, seed, noise, SMALL_TIME_SCALE, effect)
                say(f"synthesized a short campaign (seed {seed}, effect {effect}, noise {noise:g}) "
                    f"in {c.seconds:.1f} s")
                return c

            cache[key] = computed_once(tmp_path_factory, f"small-{seed}-{effect}-{noise:g}-{copy}", synthesized)
        return cache[key]

    return get


# ------------------------------------------------------------------- identification

def print_joint(label: str, result, truth: dict[str, float]) -> None:
    say(f"{label}: {result.evaluations} model evaluations in {result.wall_time:.1f} s, "
        f"mean squared scaled residual {result.cost:.4g}, inflation {result.inflation:.3g}")
    for k, est in result.params.items():
        t = truth[k]
        sigma = result.std[k]
        z = (est - t) / sigma if sigma > 0 else float("inf")
        say(f"  {k:11s} truth {t:11.5g}  estimate {est:11.5g}  error {est / t - 1:+8.3%}  "
            f"1 sigma {sigma:9.3g} ({result.relative_std[k]:.2%})  z {z:+6.2f}  {result.identifiability[k]}")


@pytest.fixture(scope="session")
def clean_joint(tmp_path_factory, harness_fmu, clean_campaign):
    """identify_joint on the noise-free campaign (computed_once)."""
    from juno.identify import identify_joint

    def fitted(_folder: Path):
        result = identify_joint(harness_fmu, clean_campaign.campaign)
        print_joint("joint fit, noise-free campaign", result, clean_campaign.soil)
        return result

    return computed_once(tmp_path_factory, "clean_joint", fitted)


@pytest.fixture(scope="session")
def noisy_joint(tmp_path_factory, harness_fmu, noisy_campaign):
    """identify_joint on the noisy campaign, serial (computed_once).  Serial so that
    test_identify_speed can compare a two-core fit with it (the two are identical bit for bit)."""
    from juno.identify import identify_joint

    def fitted(_folder: Path):
        result = identify_joint(harness_fmu, noisy_campaign.campaign, workers=1)
        print_joint("joint fit, noisy campaign", result, noisy_campaign.soil)
        return result

    return computed_once(tmp_path_factory, "noisy_joint", fitted)


@dataclass
class PaperRun:
    """A paper-style result with the costs it is judged against."""

    result: Any            # juno.identify.PaperResult
    initial_cost: float    # cost of the paper's initial guess
    truth_cost: float      # cost of the true soil


@pytest.fixture(scope="session")
def noisy_paper(tmp_path_factory, harness_fmu, noisy_campaign) -> list[PaperRun]:
    """identify_paper on each drawbar run of the noisy campaign, with the costs of the initial guess
    and of the truth under the same cost function (computed_once)."""
    from juno.identify import PAPER_INITIAL, base_parameters, identify_paper, paper_cost

    def fitted(_folder: Path) -> list[PaperRun]:
        c = noisy_campaign.campaign
        base = base_parameters(c)
        out = []
        for run in c.runs_of_kind("drawbar"):
            p = identify_paper(harness_fmu, c, run)
            c0 = paper_cost(harness_fmu, dict(PAPER_INITIAL), p.averages, base)
            ct = paper_cost(harness_fmu, noisy_campaign.soil, p.averages, base)
            say(f"paper-style {run.id}: cost {c0:.4g} (initial guess) -> {p.cost:.4g} after {p.evaluations} "
                f"evaluations in {p.wall_time:.1f} s (scipy converged: {p.converged}; cost at the truth {ct:.4g}; "
                f"rank {p.jacobian_rank}/4)")
            say("  " + ", ".join(f"{k} {v:.4g}" for k, v in p.final.items()))
            out.append(PaperRun(p, c0, ct))
        return out

    return computed_once(tmp_path_factory, "noisy_paper", fitted)


# ------------------------------------------------------------- validation and report

@dataclass
class Validation:
    grid_file: Path
    grid: Any                       # juno.pointcloud.Grid as returned by grid_terrain
    truth: Any                      # ValidationResult with the true soil
    initial: Any                    # ValidationResult with the paper's initial guess
    seconds: dict[str, float] = field(default_factory=dict)


@pytest.fixture(scope="session")
def terrain_validation(tmp_path_factory, harness_fmu, terrain_campaign) -> Validation:
    """validate_run on the terrain campaign's terrain run: the true soil and the paper's initial guess."""
    from juno.identify import PAPER_INITIAL
    from juno.validate import grid_terrain, validate_run

    c = terrain_campaign.campaign
    run = c.runs_of_kind("terrain")[0]
    out = tmp_path_factory.mktemp("validation")
    seconds = {}
    t = time.perf_counter()
    grid_file, grid = grid_terrain(c, run, out)
    seconds["gridding"] = time.perf_counter() - t
    t = time.perf_counter()
    v_truth = validate_run(harness_fmu, c, run, terrain_campaign.soil, out, grid_file=grid_file)
    seconds["true soil"] = time.perf_counter() - t
    t = time.perf_counter()
    v_init = validate_run(harness_fmu, c, run, dict(PAPER_INITIAL), out, grid_file=grid_file)
    seconds["initial guess"] = time.perf_counter() - t
    say("validation wall times: " + ", ".join(f"{k} {v:.1f} s" for k, v in seconds.items()))
    for label, v in (("true soil", v_truth), ("paper initial guess", v_init)):
        say(f"validation RMS with the {label}: " + ", ".join(f"{k} {x:.4g}" for k, x in v.rms.items()))
    return Validation(Path(grid_file), grid, v_truth, v_init, seconds)


@pytest.fixture(scope="session")
def noisy_report(tmp_path_factory, harness_fmu, noisy_campaign, noisy_paper, noisy_joint) -> Path:
    """write_report of the noisy campaign, as ``juno report`` writes it: the paper-style fits, the joint
    fit, and the terrain validation with the joint fit and with the best paper-style run.
    Returns the report folder."""
    from juno.report import write_report
    from juno.validate import validate_run

    c = noisy_campaign.campaign
    run = c.runs_of_kind("terrain")[0]
    work = tmp_path_factory.mktemp("report-validation")
    v_joint = validate_run(harness_fmu, c, run, noisy_joint.params, work)
    best = min(noisy_paper, key=lambda p: p.result.cost).result
    v_paper = validate_run(harness_fmu, c, run, best.final, work, grid_file=v_joint.grid_file)
    out = tmp_path_factory.mktemp("report") / "report"
    t = time.perf_counter()
    path = write_report(out, c, [p.result for p in noisy_paper], noisy_joint,
                        [("joint fit", v_joint), (f"paper-style {best.run_id}", v_paper)], truth=noisy_campaign.truth)
    say(f"write_report in {time.perf_counter() - t:.1f} s: {path}")
    return Path(path).parent
