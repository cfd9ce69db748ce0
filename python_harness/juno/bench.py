"""``juno bench``: the benchmark of the performance targets.  Prints figures; asserts nothing.

Sections (each figure is a median of repeated runs, printed next to the
target, with the load average of the machine when it was taken and
the CPU share of the measuring process: a share well below 100 % means other
processes took the CPU and the wall-clock figure is inflated):

* ``contact``  - ns per contact evaluation at 779 N (``bench_contact``, C):
  volumetric closed form, volumetric quadrature, Wong-Reece with 100 points;
  each model's sinkage for the load and whether they match within 5 %.
* ``fmu-c``    - real-time factor of the FMU from C (``bench_fmu``): a 30 s
  drawbar run (defaults) and a 60 s run on a synthetic mound grid, both
  through ``model_do_step`` and through the FMI functions of the shared
  library, at the baseline, a fixed 1 ms step, and the CPU time per internal
  step; the same runs through ``model_do_step`` at other step settings
  (fixed 10 ms and 20 ms, the FMU's default: the automatic step, which also
  through the FMI functions), each as a
  ratio to the baseline measured in the same run and with its accuracy: the largest RMS difference of slip, torque and
  sinkage from a 0.0625 ms reference (the metric of
  tests/python/test_fmu_accuracy.py); and the Wong-Reece law's cost per
  internal step as a ratio to the volumetric law's over the same runs.
* ``fmpy``     - the same two runs through fmpy (:meth:`JunoFMU.simulate`), at the
  fixed 1 ms baseline and at the FMU's default, the automatic step (as a ratio to the baseline's).

The real-time targets are the FMU's at its default settings: only the runs at the default are
judged against them, a run at a fixed step shows its figure with no target (``at_default`` in
each real-time figure).
* ``cost``     - cost-function evaluations per second: the joint fit's
  residuals (:func:`juno.identify.run_residuals` over the three drawbar runs
  of a synthetic campaign).
* ``joint``    - wall time of :func:`juno.identify.identify_joint` on that
  campaign (noise 1), with one worker process per core (the default) and serially.
* ``diagnose`` - wall time of :func:`juno.diagnose.diagnose` (minutes; only
  with ``--with-diagnose``) on that campaign, and on a campaign of the other synthetic design
  (four longer drawbar runs at 50-60 % throttle, a ridge; ``juno synthesize --design alt``).

Finally the peak resident memory: ``getrusage`` maxrss of this process, the
C programs' own VmHWM and the diagnose workers' (sampled).  The C programs are built on demand in the build
directory (``cmake --build build --target fmu bench_contact bench_fmu``).
"""

from __future__ import annotations

import datetime as _dt
import json
import os
import platform
import re
import resource
import shutil
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

#: The performance targets.
TARGETS = {
    "contact_speedup": 30.0,       # closed form >= 30x faster than Wong-Reece at matching sinkage
    "sinkage_match": 0.05,         # ... matching within 5 %
    "rtf_c": 5000.0,               # FMU >= 5000x real time from C (drawbar and terrain runs)
    "us_per_step": 1.0,            # <= 1 us CPU per internal step of the rover
    "accuracy": 0.002,             # slip, torque, sinkage within 0.2 % RMS of a converged reference
    "wr_ratio": 30.0,              # Wong-Reece >= 30x the volumetric law's cost per step over whole runs
    "rtf_fmpy": 1000.0,            # >= 1000x through fmpy
    "joint_s": 5.0,                # joint identification of three drawbar runs <= 5 s
    "diagnose_s": 60.0,            # a whole diagnose of a standard campaign <= 60 s
    "diagnose_four_drawbar_s": 90.0,  # ... and of a campaign of four drawbar runs <= 90 s
}
SECTIONS = ("contact", "fmu-c", "fmpy", "cost", "joint", "registration")
COMM_STEP = 0.01                   # s, the default experiment's step size (as bench_fmu)


# ------------------------------------------------------------------ helpers

def _checkout() -> Path:
    return Path(__file__).resolve().parents[2]


def machine_info() -> dict[str, Any]:
    """CPU model, cores, memory, OS, Python, and the C compiler of the build."""
    info: dict[str, Any] = {"cpu": platform.processor() or platform.machine(), "logical_cores": os.cpu_count()}
    try:
        text = Path("/proc/cpuinfo").read_text()
        models = re.findall(r"^model name\s*:\s*(.+)$", text, re.M)
        if models:
            info["cpu"] = models[0].strip()
        cores = set()
        for block in text.split("\n\n"):
            phys = re.search(r"^physical id\s*:\s*(\d+)", block, re.M)
            core = re.search(r"^core id\s*:\s*(\d+)", block, re.M)
            if phys and core:
                cores.add((phys.group(1), core.group(1)))
        if cores:
            info["physical_cores"] = len(cores)
        mhz = re.findall(r"^cpu MHz\s*:\s*([\d.]+)", text, re.M)
        if mhz:
            info["mhz"] = float(mhz[0])
        flags = re.search(r"^flags\s*:\s*(.+)$", text, re.M)
        if flags:
            info["hypervisor"] = "hypervisor" in flags.group(1).split()
    except OSError:
        pass
    try:
        mem = re.search(r"^MemTotal:\s*(\d+) kB", Path("/proc/meminfo").read_text(), re.M)
        if mem:
            info["memory_gb"] = int(mem.group(1)) / 1024**2
    except OSError:
        pass
    info["os"] = f"{platform.system()} {platform.release()}"
    info["python"] = platform.python_version()
    try:
        import fmpy
        info["fmpy"] = fmpy.__version__
    except Exception:
        pass
    return info


def _compiler(build_dir: Path) -> str:
    """The C compiler and build type of the CMake build directory (from its CMakeCache.txt)."""
    cache = build_dir / "CMakeCache.txt"
    try:
        text = cache.read_text()
    except OSError:
        return "unknown"
    cc = re.search(r"^CMAKE_C_COMPILER:\w+=(.+)$", text, re.M)
    bt = re.search(r"^CMAKE_BUILD_TYPE:\w+=(.+)$", text, re.M)
    name = cc.group(1).strip() if cc else "cc"
    try:
        version = subprocess.run([name, "--version"], capture_output=True, text=True, timeout=10).stdout.splitlines()[0]
    except (OSError, IndexError, subprocess.SubprocessError):
        version = name
    # CMakeLists.txt makes Release (-O3) the default when the cache leaves the type empty
    return f"{version}, {bt.group(1).strip() if bt else 'Release'} build"


def commit(paths: Sequence[str] = ()) -> str:
    """The checkout's commit (short hash), "+ changes" when the working tree differs from it (in
    ``paths`` only, relative to the checkout, when given)."""
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=_checkout(), capture_output=True,
                              text=True, timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "--", *paths],
                               cwd=_checkout(), capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return (head or "unknown") + (" + changes" if dirty else "")


def loadavg() -> tuple[float, float, float]:
    try:
        return os.getloadavg()
    except OSError:
        return (float("nan"),) * 3


def _fmt_load(load: tuple[float, float, float]) -> str:
    return "load average {:.2f} {:.2f} {:.2f}".format(*load)


def timed(fn: Callable[[], Any], repeats: int) -> tuple[list[float], float, Any]:
    """Runs ``fn`` ``repeats`` times; returns the wall times (s), the CPU share of this
    process over all runs, and the last result."""
    walls, cpu, result = [], 0.0, None
    for _ in range(repeats):
        c0, t0 = time.process_time(), time.perf_counter()
        result = fn()
        walls.append(time.perf_counter() - t0)
        cpu += time.process_time() - c0
    return walls, cpu / max(sum(walls), 1e-12), result


class Report:
    """Collects figures and prints them as a table: figure, median, target, verdict."""

    def __init__(self, say: Callable[[str], None]):
        self.say = say
        self.figures: list[dict[str, Any]] = []
        self.sections: list[dict[str, Any]] = []

    def section(self, title: str) -> None:
        load = loadavg()
        self.sections.append({"title": title, "load": load})
        print(f"\n{title}  [{_fmt_load(load)}]", flush=True)

    def figure(self, key: str, label: str, value: float, unit: str, target: str = "", met: bool | None = None,
               note: str = "", **extra: Any) -> None:
        verdict = "" if met is None else ("met" if met else "MISSED")
        shown = _num(value)
        tgt = f"{target} {verdict}".strip()
        print(f"  {label:<56} {shown:>8} {unit:<6} {tgt:<16} {note}".rstrip(), flush=True)
        self.figures.append({"key": key, "label": label, "value": value, "unit": unit, "target": target,
                             "met": met, "note": note, "section": self.sections[-1]["title"] if self.sections else "",
                             **extra})

    def line(self, text: str) -> None:
        print(f"  {text}", flush=True)


def _num(v: float) -> str:
    if v is None or not np.isfinite(v):
        return "n/a"
    a = abs(v)
    if a >= 1000:
        return f"{v:,.0f}"
    if a >= 100:
        return f"{v:.0f}"
    if a >= 10:
        return f"{v:.1f}"
    return f"{v:.2f}"


def _build(build_dir: Path, say: Callable[[str], None]) -> None:
    cmake = shutil.which("cmake")
    if cmake is None:
        raise FileNotFoundError("cmake not found: build the bench programs first or give --no-build")
    if not (build_dir / "CMakeCache.txt").is_file():
        raise FileNotFoundError(f"{build_dir} is not a CMake build directory "
                                f"(cmake -S . -B {build_dir} -G Ninja first, or --build-dir)")
    say(f"building fmu, bench_contact, bench_fmu in {build_dir}")
    proc = subprocess.run([cmake, "--build", str(build_dir), "--target", "fmu", "bench_contact", "bench_fmu"],
                          capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"building the bench programs failed:\n{proc.stdout[-3000:]}{proc.stderr[-3000:]}")


def _run_c(cmd: list[str], say: Callable[[str], None]) -> dict[str, Any]:
    """Runs a bench program with --json into a temporary file; returns its JSON, with the
    program's own peak memory as ``maxrss_mb`` (its VmHWM; wait4's maxrss counts the memory
    this Python process had when it forked the program)."""
    with tempfile.TemporaryDirectory(prefix="juno-bench-") as tmp:
        out, log, err = Path(tmp) / "result.json", Path(tmp) / "stdout", Path(tmp) / "stderr"
        say("running " + " ".join(Path(c).name if i == 0 else c for i, c in enumerate(cmd)))
        with open(log, "w") as fo, open(err, "w") as fe:
            proc = subprocess.Popen(cmd + ["--json", str(out)], stdout=fo, stderr=fe)
            proc.wait()
        if not out.is_file():
            raise RuntimeError(f"{Path(cmd[0]).name} failed (exit {proc.returncode}): "
                               f"{err.read_text().strip()[-2000:]}")
        data = json.loads(out.read_text())
        data["exit_code"] = proc.returncode
        kb = data.get("peak_rss_kb", -1)
        data["maxrss_mb"] = kb / 1024.0 if kb and kb > 0 else float("nan")
        data["stdout"] = log.read_text()
        return data


def _self_maxrss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


# ------------------------------------------------------------------ sections

def bench_contact(rep: Report, exe: Path, repeats: int, min_time: float, say) -> float:
    rep.section("Contact evaluations at 779 N (C, bench_contact)")
    d = _run_c([str(exe), "--repeats", str(repeats), "--min-time", str(min_time)], say)
    m = {x["key"]: x for x in d["models"]}
    cf, q, wr = m["closed_form"], m["quadrature"], m["wr_matched"]
    s0 = cf["sinkage_m"]
    rep.line(f"sinkage for 779 N (rolling, rear half rebounded, gamma = lambda = {d['gamma']:.4f}, zero slip):")
    for x in d["models"]:
        if x["key"] == "closed_form_forces":
            continue                      # the closed form again, timed without the shear Jacobian
        rel = x["sinkage_m"] / s0 - 1
        name = x["name"] + (f" (x {x['modulus_factor']:.3f})" if x["key"] == "wr_matched" else "")
        match = "" if x["key"] == "closed_form" else (
            f"{rel:+.1%} vs closed form: " + ("matches within 5 %" if abs(rel) <= TARGETS["sinkage_match"]
                                              else "does NOT match within 5 %"))
        rep.line(f"  {name:<62} {x['sinkage_m'] * 1e3:6.2f} mm  {match}")
    share = d.get("cpu_share", float("nan"))
    rep.line(f"ns per evaluation: wall clock, median of {repeats} batches of >= {min_time:g} s each "
             f"(CPU share {share:.0%}):")
    rep.figure("contact_closed_form_ns", "volumetric closed form (patch + shear)", cf["ns_median"], "ns",
               note=f"min {cf['ns_min']:.0f}")
    forces = m["closed_form_forces"]
    rep.figure("contact_closed_form_forces_ns", "volumetric closed form, forces only", forces["ns_median"], "ns",
               note=f"min {forces['ns_min']:.0f}; no shear Jacobian")
    rep.figure("contact_quadrature_ns", "volumetric quadrature (64-point Gauss)", q["ns_median"], "ns",
               note=f"min {q['ns_min']:.0f}; {q['ns_median'] / cf['ns_median']:.1f}x the closed form")
    for key in ("wr_matched", "wr_dry", "wr_dry_lambda0", "wr_toyoura", "wr_toyoura_lambda0"):
        x = m[key]
        label = "Wong-Reece 100 pts, " + x["name"].split(", ", 1)[1].replace(", Bekker moduli scaled to match",
                                                                            " scaled to match")
        rep.figure(f"contact_{key}_ns", label, x["ns_median"], "ns",
                   note=f"min {x['ns_min']:.0f}; {x['ns_median'] / cf['ns_median']:.1f}x the closed form; "
                        f"sinkage {x['sinkage_m'] / s0 - 1:+.1%}")
    fmu_wr = m["wr_matched_fmu"]
    rep.figure("contact_wr_matched_fmu_ns", "Wong-Reece as the FMU uses it (3 calls)", fmu_wr["ns_median"], "ns",
               note=f"min {fmu_wr['ns_min']:.0f}; forces and differences in slip and sinkage")
    # Like for like, the target's comparison: forces alone on both sides (one wong_reece_forces
    # call gives no derivatives), and what an implicit step needs on both sides.
    mismatch = wr["sinkage_m"] / s0 - 1
    matched = abs(mismatch) <= TARGETS["sinkage_match"]
    speed_forces = wr["ns_median"] / forces["ns_median"]
    rep.figure("contact_speedup_forces", "speed-up, forces only, vs Wong-Reece (matched)", speed_forces, "x",
               target=">= 30x", met=bool(speed_forces >= TARGETS["contact_speedup"] and matched),
               note=f"like for like; sinkage {mismatch:+.2%} (within 5 %: {'yes' if matched else 'no'})")
    speed_step = fmu_wr["ns_median"] / cf["ns_median"]
    rep.figure("contact_speedup_step", "speed-up, forces + derivatives, as the FMU uses them", speed_step, "x",
               note="closed form with its shear Jacobian vs Wong-Reece's 3 calls")
    speed = wr["ns_median"] / cf["ns_median"]
    rep.figure("contact_speedup", "closed form with shear Jacobian vs Wong-Reece forces", speed, "x",
               note="not like for like: only the closed form includes derivatives")
    published = [m[k] for k in ("wr_dry", "wr_toyoura")]
    best = min(published, key=lambda x: abs(x["sinkage_m"] / s0 - 1))
    rep.figure("contact_speedup_published", "speed-up vs nearest published set", best["ns_median"] / cf["ns_median"],
               "x", note=f"{best['name'].split(', ', 1)[1]}, sinkage {best['sinkage_m'] / s0 - 1:+.1%}")
    return d["maxrss_mb"]


#: Where a run is not at the FMU's default settings, its real-time factor is shown without a
#: verdict: the real-time targets are the default's (issue: "at the default settings").
NOT_THE_DEFAULT = "no target: the real-time target applies to the default (automatic) step"


def _rtf_target(rtf: float, target: float, at_default: bool) -> tuple[str, bool | None]:
    """The real-time target (``target`` times real time) and whether ``rtf`` meets it, for a run at
    the FMU's default settings; for a run at any other setting no target and no verdict."""
    if not at_default:
        return "", None
    return f">= {target:.0f}x", bool(rtf >= target)


def _us_per_step(run: dict[str, Any]) -> float:
    """CPU microseconds per internal step of one bench_fmu run (its stepping only)."""
    return run["stepping_cpu_s"] / run["steps"] * 1e6 if run.get("steps") else float("nan")


#: The baseline every step setting is compared with: a fixed 1 ms step (bench_fmu arguments).
BASELINE = ["--solver-step", "0.001", "--solver-tolerance", "0"]
#: The step settings timed and traced: key suffix, label, bench_fmu arguments (none: the FMU's
#: default, the automatic step of solver.tolerance 4e-4 m/s and solver.step 20 ms).
STEP_SETTINGS = (
    ("1ms", "fixed solver.step 1 ms (the baseline)", BASELINE),
    ("10ms", "fixed solver.step 10 ms", ["--solver-step", "0.01", "--solver-tolerance", "0"]),
    ("20ms", "fixed solver.step 20 ms", ["--solver-step", "0.02", "--solver-tolerance", "0", "--comm-step", "0.02"]),
    ("auto", "the default: automatic step", []),
)
#: The same baseline as FMU parameters (the fmpy runs).
BASELINE_PARAMETERS = {"solver.step": 1e-3, "solver.tolerance": 0.0}
#: bench_fmu's trace columns: the time, then the FMU's Outputs in the order of fmu_src/model.h.
TRACE_COLUMNS = (["time", "x", "y", "z", "roll", "pitch", "yaw", "vx", "omegaLeft", "omegaRight",
                  "torqueLeftApplied", "torqueRightApplied", "rocker", "spinAngleLeft", "spinAngleRight"]
                 + [f"{w}.{q}" for w in ("FL", "RL", "FR", "RR")
                    for q in ("sinkage", "slip", "Fn", "Ft", "Fx", "Fy", "Fz")])
ACCURACY_SIGNALS = ([f"{w}.slip" for w in ("FL", "RL", "FR", "RR")] + [f"{w}.sinkage" for w in ("FL", "RL", "FR", "RR")]
                    + ["torqueLeftApplied", "torqueRightApplied"])
REFERENCE_STEP = 6.25e-5      # s, the converged reference (tests/python/test_fmu_accuracy.py)
SETTLE = 5.0                  # s, the start from the static equilibrium, left out of the metric


def accuracy_metric(trace: np.ndarray, reference: np.ndarray) -> tuple[float, str]:
    """The largest relative RMS difference from the reference over ACCURACY_SIGNALS after SETTLE
    (the metric of tests/python/test_fmu_accuracy.py), and the signal it is on."""
    part = reference[:, 0] >= SETTLE
    worst, name = -1.0, ""
    for sig in ACCURACY_SIGNALS:
        c = TRACE_COLUMNS.index(sig)
        e = float(np.sqrt(np.mean((trace[part, c] - reference[part, c]) ** 2) / np.mean(reference[part, c] ** 2)))
        if not e <= worst:
            worst, name = e, sig
    return worst, name


def _traces(exe: Path, fmu_dir: Path, grid: Path, args: list[str], prefix: Path, say) -> dict[str, np.ndarray]:
    """bench_fmu's trace of each scenario (communication step 20 ms) with the given settings."""
    settings = [a for i, a in enumerate(args) if a != "--comm-step" and (i == 0 or args[i - 1] != "--comm-step")]
    cmd = [str(exe), "--fmu-dir", str(fmu_dir), "--terrain", str(grid), "--only", "direct", "--repeats", "0",
           "--comm-step", "0.02", *settings, "--trace", str(prefix)]
    say("tracing " + " ".join(cmd[1:]))
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0 or "FAILED" in proc.stdout:
        raise RuntimeError(f"bench_fmu trace failed: {proc.stdout[-2000:]}{proc.stderr[-2000:]}")
    traces = {name: np.loadtxt(f"{prefix}_{name}.txt", ndmin=2) for name in ("drawbar", "terrain")}
    for name, trace in traces.items():
        # the columns are read by position: a trace of another layout would compare other signals
        if trace.shape[1] != len(TRACE_COLUMNS):
            raise RuntimeError(f"bench_fmu's {name} trace has {trace.shape[1]} columns, TRACE_COLUMNS names "
                               f"{len(TRACE_COLUMNS)}: the FMU's outputs changed (fmu_src/model.h); update both")
    return traces


def bench_fmu_c(rep: Report, exe: Path, fmu_dir: Path, grid: Path, repeats: int, say) -> float:
    rep.section("FMU from C (bench_fmu): real-time factor = simulated / wall time")
    d = _run_c([str(exe), "--fmu-dir", str(fmu_dir), "--terrain", str(grid), "--repeats", str(repeats), *BASELINE], say)
    rep.line(f"the baseline: fixed solver.step {d['solver_step']:g} s, communication step {d['comm_step']:g} s; "
             f"median of {repeats} runs; whole run = instantiate + initialise (terrain, equilibrium) + steps")
    base: dict[str, dict[str, Any]] = {}                 # model_do_step's, by scenario
    base_fmi: dict[str, dict[str, Any]] = {}             # the FMI functions'
    for r in d["runs"]:
        label = (f"{r['scenario']} {r['duration']:.0f} s, "
                 f"{'model_do_step' if r['path'] == 'direct' else 'FMI functions'}, fixed 1 ms step")
        key = f"rtf_c_{r['scenario']}_{r['path']}"
        if not r["ok"]:
            rep.figure(key, label, float("nan"), "x", note="FAILED: " + r.get("error", ""), at_default=False)
            continue
        rtf = r["duration"] / r["total_s"]
        target, met = _rtf_target(rtf, TARGETS["rtf_c"], at_default=False)
        (base if r["path"] == "direct" else base_fmi)[r["scenario"]] = r
        rep.figure(key, label, rtf, "x RT", target=target, met=met,
                   note=f"{NOT_THE_DEFAULT}; {r['total_s']:.3f} s; stepping only "
                        f"{r['duration'] / r['stepping_s']:.0f}x, {_us_per_step(r):.2f} us CPU per internal step; "
                        f"CPU {r['cpu_share']:.0%}; end x {r['final_x']:.1f} m", wall_s=r["total_s"],
                   stepping_s=r["stepping_s"], at_default=False)
    for name, r in base.items():
        us = _us_per_step(r)
        rep.figure(f"us_per_step_{name}", f"{name}: CPU per internal step (1 ms, model_do_step)", us, "us",
                   target="<= 1.0 us", met=bool(us <= TARGETS["us_per_step"]), note=f"{r['steps']:.0f} steps")

    # The other step settings against the baseline measured above: real-time factor and accuracy.
    rep.line("the same runs at other step settings (model_do_step), against the fixed 1 ms baseline above; "
             f"accuracy: the largest RMS difference of slip, torque and sinkage from a {REFERENCE_STEP * 1e3:g} ms "
             f"reference after the first {SETTLE:g} s, relative to the signal's RMS (target <= 0.2 %)")
    rss = d["maxrss_mb"]
    with tempfile.TemporaryDirectory(prefix="juno-bench-traces-") as tmp:
        ref = _traces(exe, fmu_dir, grid, ["--solver-step", str(REFERENCE_STEP), "--solver-tolerance", "0"],
                      Path(tmp) / "ref", say)
        for suffix, label, args in STEP_SETTINGS:
            at_default = not args                    # no arguments: the FMU's default settings
            trace = _traces(exe, fmu_dir, grid, args, Path(tmp) / suffix, say)
            # At the default also through the FMI functions, as a plain C host runs the FMU.
            only = [] if at_default else ["--only", "direct"]
            timed_run = _run_c([str(exe), "--fmu-dir", str(fmu_dir), "--terrain", str(grid), "--repeats", str(repeats),
                                *only, *args], say) if args != BASELINE else d
            rss = max(rss, timed_run["maxrss_mb"])
            for r in timed_run["runs"]:
                if r["path"] != "direct" and not at_default:
                    continue
                key = f"rtf_c_{r['scenario']}_{r['path']}_{suffix}"
                row = f"{r['scenario']}, {label}" + (", FMI functions" if r["path"] == "fmi" else "")
                err, sig = accuracy_metric(trace[r["scenario"]], ref[r["scenario"]])
                acc_met = bool(err <= TARGETS["accuracy"])
                if not r["ok"]:
                    rep.figure(key, row, float("nan"), "x", note="FAILED: " + r.get("error", ""),
                               at_default=at_default)
                    continue
                rtf = r["duration"] / r["total_s"]
                target, met = _rtf_target(rtf, TARGETS["rtf_c"], at_default)
                b = (base if r["path"] == "direct" else base_fmi).get(r["scenario"])   # the same path's
                ratio = rtf / (b["duration"] / b["total_s"]) if b else float("nan")
                # the default's target is both: fast and accurate (the trace is model_do_step's, the
                # same computation as the FMI functions')
                rep.figure(key, row, rtf, "x RT", target=target, met=None if met is None else met and acc_met,
                           note=("" if at_default else f"{NOT_THE_DEFAULT}; ") +
                                f"{ratio:.2f} x the fixed 1 ms step; accuracy {err:.3%} ({sig}, "
                                f"{'within' if acc_met else 'NOT within'} 0.2 %); {r['steps'] / r['duration']:.0f} "
                                f"steps/s, {_us_per_step(r):.2f} us CPU each; CPU {r['cpu_share']:.0%}",
                           wall_s=r["total_s"], accuracy=err, ratio_to_baseline=ratio, at_default=at_default)

    # The contact laws over whole runs: Wong-Reece against the volumetric law, per internal step.
    wr = _run_c([str(exe), "--fmu-dir", str(fmu_dir), "--terrain", str(grid), "--repeats", str(max(1, repeats // 2)),
                 "--only", "direct", "--contact-model", "1", *BASELINE], say)
    rss = max(rss, wr["maxrss_mb"])
    for r in wr["runs"]:
        b = base.get(r["scenario"])
        if not r["ok"] or b is None:
            continue
        ratio = _us_per_step(r) / _us_per_step(b)
        rep.figure(f"wr_ratio_{r['scenario']}", f"{r['scenario']}: Wong-Reece / volumetric, CPU per internal step",
                   ratio, "x", target=">= 30x", met=bool(ratio >= TARGETS["wr_ratio"]),
                   note=f"{_us_per_step(r):.1f} us against {_us_per_step(b):.2f} us (whole runs, 1 ms)")
    return rss


def terrain_run(grid: Path) -> tuple[dict[str, object], Any]:
    from .simulator import InputSignals
    return ({"drive.mode": 2, "terrain.file": str(grid), "init.x": 0.8, "init.y": 0.0},
            InputSignals.constant(drawbarForce=0.0, throttleLeft=0.45, throttleRight=0.45))


def bench_fmpy(rep: Report, fmu, grid: Path, repeats: int, say) -> None:
    from .simulator import DEFAULT_OUTPUTS
    rep.section("FMU through fmpy (juno.simulator.JunoFMU.simulate): real-time factor")
    rep.line(f"communication step {COMM_STEP:g} s, {len(DEFAULT_OUTPUTS)} outputs read per step; median of "
             f"{repeats} runs; each run = reset + set-up + initialise + steps")
    params, inputs = terrain_run(grid)
    runs = (("drawbar", 30.0, {"drive.mode": 2}, None), ("terrain", 60.0, params, inputs))
    baseline_wall: dict[str, float] = {}
    for name, duration, p, u in runs:
        say(f"fmpy: {name} run, fixed 1 ms step, x {repeats}")
        walls, share, res = timed(lambda: fmu.simulate({**p, **BASELINE_PARAMETERS}, u, duration, COMM_STEP), repeats)
        wall = float(np.median(walls))
        c_fmi = next((f for f in rep.figures if f["key"] == f"rtf_c_{name}_fmi" and "wall_s" in f), None)
        overhead = ""
        if c_fmi is not None:
            per_step = (wall - c_fmi["wall_s"]) / round(duration / COMM_STEP) * 1e6
            overhead = f"; fmpy adds {per_step:.0f} us per communication step over C"
        target, met = _rtf_target(duration / wall, TARGETS["rtf_fmpy"], at_default=False)
        rep.figure(f"rtf_fmpy_{name}", f"{name} {duration:.0f} s through fmpy, fixed 1 ms step", duration / wall, "x RT",
                   target=target, met=met,
                   note=f"{NOT_THE_DEFAULT}; {wall:.3f} s; CPU {share:.0%}; end x {float(res['x'][-1]):.1f} m"
                        f"{overhead}", wall_s=wall, walls=walls, at_default=False)
        baseline_wall[name] = wall
    # The FMU's default (the automatic step), against the fixed 1 ms baseline just measured.
    default = (f"solver.tolerance {float(fmu.variables['solver.tolerance'].start):g} m/s, "
               f"solver.step {float(fmu.variables['solver.step'].start) * 1e3:g} ms")
    for name, duration, p, u in runs:
        say(f"fmpy: {name} run, the default step, x {repeats}")
        walls, share, res = timed(lambda: fmu.simulate(p, u, duration, COMM_STEP), repeats)
        wall = float(np.median(walls))
        target, met = _rtf_target(duration / wall, TARGETS["rtf_fmpy"], at_default=True)
        rep.figure(f"rtf_fmpy_{name}_auto", f"{name} {duration:.0f} s through fmpy, the default (automatic) step",
                   duration / wall, "x RT", target=target, met=met,
                   note=f"{baseline_wall[name] / wall:.2f} x the fixed 1 ms step; {default}; CPU {share:.0%}",
                   wall_s=wall, walls=walls, at_default=True)


def _campaign(tmp: Path, fmu, say, design: str = "default") -> tuple[Any, float]:
    """A synthetic campaign of ``design`` with nothing hidden (seed 0, noise 1), and the seconds
    its synthesis took."""
    from .campaign import load_campaign
    from .synthesize import synthesize
    say(f"synthesizing a campaign (design {design}, effect none, seed 0, noise 1)")
    t0 = time.perf_counter()
    path = synthesize(tmp / f"campaign-{design}", effect="none", strength=1.0, seed=0, noise=1.0, fmu=fmu,
                      design=design)
    return load_campaign(path), time.perf_counter() - t0


def bench_cost(rep: Report, fmu, campaign, repeats: int, say) -> None:
    from .identify import PAPER_INITIAL, prepare_run, run_residuals
    rep.section("Cost function (juno.identify.run_residuals, joint fit's residuals)")
    runs = campaign.runs_of_kind("drawbar")
    prepared = [prepare_run(campaign, r) for r in runs]
    soil = dict(PAPER_INITIAL)
    simulated = sum(p.duration for p in prepared)
    rep.line(f"one evaluation = residuals of the {len(prepared)} drawbar runs ({simulated:.0f} s simulated at "
             f"solver.step {prepared[0].params['solver.step']:g} s, PID following the measured spins); "
             f"median of {repeats}")

    def evaluate():
        return np.concatenate([run_residuals(fmu, p, soil) for p in prepared])
    say(f"cost function x {repeats}")
    walls, share, r = timed(evaluate, repeats)
    wall = float(np.median(walls))
    rep.figure("cost_evals_per_s", "cost-function evaluations per second", 1.0 / wall, "1/s",
               note=f"{wall:.3f} s each, {len(r)} residuals, {simulated / wall:.0f}x real time; CPU {share:.0%}",
               wall_s=wall)
    walls1, share1, _ = timed(lambda: run_residuals(fmu, prepared[0], soil), repeats)
    w1 = float(np.median(walls1))
    rep.figure("run_residuals_per_s", f"run_residuals per second (run {prepared[0].run_id}, "
               f"{prepared[0].duration:.0f} s)", 1.0 / w1, "1/s", note=f"CPU {share1:.0%}", wall_s=w1)


def _cpu_with_children() -> float:
    """CPU seconds of this process and of its finished (joined) child processes."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def bench_joint(rep: Report, fmu, campaign, repeats: int, say) -> None:
    """The joint fit as the harness runs it (one worker process per core; the pool is joined at
    the end of each fit, so its CPU time is counted) and, for the speed-up, serially."""
    from .identify import identify_joint
    from .parallel import resolve_workers
    rep.section("Joint identification (juno.identify.identify_joint, 3 drawbar runs, noise 1)")
    workers = resolve_workers(None, 4)
    truth_path = Path(campaign.root) / "truth.json"
    truth = json.loads(truth_path.read_text())["soil"] if truth_path.is_file() else None
    medians, fits = {}, {}
    # Alternate the two so that a change of the machine's load hits both alike.
    walls: dict[int, list[float]] = {workers: [], 1: []}
    cpu: dict[int, float] = {workers: 0.0, 1: 0.0}
    for i in range(repeats):
        for w in dict.fromkeys((workers, 1)):
            say(f"identify_joint, {w} worker{'s' if w > 1 else ''}, repeat {i + 1}/{repeats}")
            c0, t0 = _cpu_with_children(), time.perf_counter()
            fits[w] = identify_joint(fmu, campaign, workers=w, progress=say)
            walls[w].append(time.perf_counter() - t0)
            cpu[w] += _cpu_with_children() - c0
    for w in dict.fromkeys((workers, 1)):
        medians[w] = float(np.median(walls[w]))
    j = fits[workers]
    err = ("; vs truth " + ", ".join(f"{k.split('.')[1]} {j.params[k] / truth[k] - 1:+.1%}" for k in truth)
           if truth else "")
    share = cpu[workers] / (sum(walls[workers]) * workers)
    rep.figure("joint_s", f"joint identification wall time ({workers} worker processes)", medians[workers], "s",
               target="<= 5 s", met=bool(medians[workers] <= TARGETS["joint_s"]),
               note=f"{j.evaluations} model evaluations ({medians[workers] / max(j.evaluations, 1):.2f} s each); "
                    f"CPU {share:.0%} of {workers} cores{err}", walls=walls[workers], evaluations=j.evaluations,
               workers=workers)
    if workers > 1:
        s = fits[1]
        same = s.params == j.params and s.std == j.std and s.evaluations == j.evaluations
        rep.figure("joint_serial_s", "joint identification wall time, serial (workers=1)", medians[1], "s",
                   note=f"speed-up {medians[1] / medians[workers]:.2f}x; CPU {cpu[1] / sum(walls[1]):.0%}; "
                        f"{'same optimum bit for bit' if same else 'OPTIMUM DIFFERS from the parallel fit'}",
                   walls=walls[1], evaluations=s.evaluations, identical=bool(same))


def _descendants(root: int) -> list[int]:
    """Process ids below ``root`` (from the parent ids in /proc/*/stat)."""
    parent: dict[int, int] = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
            parent[int(entry.name)] = int(stat[stat.rindex(")") + 2:].split()[1])
        except (OSError, ValueError, IndexError):
            continue
    found, frontier = [], [root]
    while frontier:
        p = frontier.pop()
        kids = [c for c, pp in parent.items() if pp == p]
        found += kids
        frontier += kids
    return found


def _cpu_seconds(pid: int) -> float:
    """utime + stime of a process so far (s), from /proc/<pid>/stat; 0 if gone."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
        fields = stat[stat.rindex(")") + 2:].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        return 0.0


def _vmhwm_kb(pid: int) -> int:
    try:
        m = re.search(r"^VmHWM:\s*(\d+) kB", Path(f"/proc/{pid}/status").read_text(), re.M)
        return int(m.group(1)) if m else 0
    except OSError:
        return 0


def bench_registration(rep: Report, campaign, repeats: int, say) -> None:
    """The scan's registration as the diagnosis fits it before its candidates, on one core:
    the pose of the rover on the gridded scan, solved for every trial offset (no simulation)."""
    from .diagnose import registration_evidence
    from .validate import grid_terrain
    rep.section("Registration (juno.diagnose.registration_evidence, the terrain run's training blocks)")
    (run,) = campaign.runs_of_kind("terrain")[:1]
    with tempfile.TemporaryDirectory(prefix="juno-bench-grid-") as tmp:
        _path, grid = grid_terrain(campaign, run, tmp)
        say(f"registration_evidence, {repeats} repeats")
        walls, share, evidence = timed(lambda: registration_evidence(campaign, grid), repeats)
    found = "no registration found" if evidence is None else \
        f"held-out pose {evidence.ratio:.3g} times better than the scan as it is"
    rep.figure("registration_s", "registration fit and its held-out evidence", float(np.median(walls)), "s",
               note=f"median of {repeats}; CPU {share:.0%} of one core; {found}", walls=walls)


def bench_diagnose(rep: Report, fmu, campaigns: Sequence[tuple[str, Any, str, str]], say) -> float | None:
    """Wall time of a whole diagnose of each of ``campaigns`` (figure key, campaign, label, target
    key), with its CPU share over the cores; returns the largest worker's peak memory (MB)."""
    rep.section("Diagnose (juno.diagnose.diagnose, every candidate, one run)")
    peaks = [_timed_diagnose(rep, fmu, key, campaign, label, target, say) for key, campaign, label, target in campaigns]
    sampled = [p for p in peaks if p is not None]
    return max(sampled) if sampled else None


def _timed_diagnose(rep: Report, fmu, key: str, campaign, label: str, target: str, say) -> float | None:
    import threading
    from .diagnose import diagnose
    peak = [0]
    worker_cpu: dict[int, float] = {}
    stop = threading.Event()

    def watch() -> None:
        """The workers' own peak memory (VmHWM) and CPU time, sampled while they run
        (getrusage(RUSAGE_CHILDREN) misses most of a process pool's CPU time)."""
        while not stop.is_set():
            for pid in _descendants(os.getpid()):
                peak[0] = max(peak[0], _vmhwm_kb(pid))
                worker_cpu[pid] = max(worker_cpu.get(pid, 0.0), _cpu_seconds(pid))
            stop.wait(0.25)
    watcher = threading.Thread(target=watch, daemon=True)
    watcher.start()
    say(f"diagnose: {label}")
    c0, t0 = time.process_time(), time.perf_counter()
    try:
        result = diagnose(campaign, fmu=fmu, progress=say)
    finally:
        stop.set()
        watcher.join()
    wall = time.perf_counter() - t0
    cpu = time.process_time() - c0 + sum(worker_cpu.values())
    cores = os.cpu_count() or 1
    limit = TARGETS[target]
    rep.figure(key, f"diagnose wall time, {label}", wall, "s", target=f"<= {limit:g} s", met=bool(wall <= limit),
               note=f"{len(result.candidates)} candidates on {min(cores, len(result.candidates))} worker "
                    f"processes; CPU {cpu / (wall * cores):.0%} of {cores} cores; cause '{result.cause}'")
    return peak[0] / 1024.0 if peak[0] > 0 else None


# ------------------------------------------------------------------ the whole benchmark

def run_benchmarks(*, quick: bool = False, repeats: int | None = None, long_repeats: int | None = None,
                   sections: Sequence[str] | None = None, with_diagnose: bool = False,
                   build_dir: Path | None = None, build: bool = True, fmu_path: Path | None = None,
                   say: Callable[[str], None] = lambda message: None) -> dict[str, Any]:
    """Run the benchmark sections (all of :data:`SECTIONS` by default), print every figure next
    to its target, and return the machine-readable record (time, machine, loads, figures).

    ``repeats`` (>= 5, default 7, 5 when ``quick``) is the number of repeats of the
    micro-benchmarks, ``long_repeats`` (default 3, 1 when ``quick``) of the joint fit; the C
    programs are built in ``build_dir`` (default: build/ of this checkout) unless ``build`` is
    False."""
    repeats = repeats if repeats is not None else (5 if quick else 7)
    if repeats < 5:
        raise ValueError("repeats must be at least 5 (the micro-benchmarks' medians need them)")
    long_repeats = long_repeats if long_repeats is not None else (1 if quick else 3)
    if long_repeats < 1:
        raise ValueError("long_repeats must be at least 1")
    sections = set(sections or SECTIONS)
    min_time = 0.02 if quick else 0.05

    from .simulator import JunoFMU, default_fmu_path
    build_dir = Path(build_dir) if build_dir else _checkout() / "build"
    fmu_path = Path(fmu_path) if fmu_path else default_fmu_path()
    need_c = bool(sections & {"contact", "fmu-c"})
    if need_c and build:
        _build(build_dir, say)

    info = machine_info()
    info["compiler"] = _compiler(build_dir)
    start_load = loadavg()
    stamp = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    info["commit"] = commit()
    print(f"juno bench, {stamp}, commit {info['commit']}{' (--quick)' if quick else ''}")
    cores = f"{info.get('logical_cores')} logical cores"
    if "physical_cores" in info:
        cores += f" ({info['physical_cores']} physical)"
    mhz = f" at {info['mhz']:.0f} MHz" if "mhz" in info else ""
    vm = ", virtual machine" if info.get("hypervisor") else ""
    print(f"machine: {info['cpu']}{mhz}, {cores}, {info.get('memory_gb', float('nan')):.1f} GB{vm}; {info['os']}; "
          f"Python {info['python']}, fmpy {info.get('fmpy', '?')}; {info['compiler']}")
    print(f"{_fmt_load(start_load)} (1, 5, 15 min) on {info.get('logical_cores')} cores at the start; medians of "
          f"{repeats} repeats (micro-benchmarks), {long_repeats} (joint fit)")

    rep = Report(say)
    campaign_time = None
    with tempfile.TemporaryDirectory(prefix="juno-bench-") as tmp_name:
        tmp = Path(tmp_name)
        grid = tmp / "mound.asc"
        if sections & {"fmu-c", "fmpy"}:
            from .pointcloud import write_esri_ascii
            from .synthesize import truth_grid
            write_esri_ascii(grid, truth_grid(seed=0))
        rss: dict[str, float | None] = {}
        if "contact" in sections:
            rss["bench_contact"] = bench_contact(rep, build_dir / "bench_contact", repeats, min_time, say)
        if "fmu-c" in sections:
            rss["bench_fmu"] = bench_fmu_c(rep, build_dir / "bench_fmu", build_dir / "fmu", grid, repeats, say)
        with JunoFMU(fmu_path) as fmu:
            if "fmpy" in sections:
                bench_fmpy(rep, fmu, grid, repeats, say)
            if sections & {"cost", "joint", "registration"} or with_diagnose:
                campaign, campaign_time = _campaign(tmp, fmu, say)
                if "cost" in sections:
                    bench_cost(rep, fmu, campaign, repeats, say)
                if "joint" in sections:
                    bench_joint(rep, fmu, campaign, long_repeats, say)
                if "registration" in sections:
                    bench_registration(rep, campaign, long_repeats, say)
                if with_diagnose:
                    four_drawbar, _ = _campaign(tmp, fmu, say, design="alt")
                    rss["diagnose workers"] = bench_diagnose(rep, fmu, [
                        ("diagnose_s", campaign, "three drawbar runs and a terrain run (the paper's design)",
                         "diagnose_s"),
                        ("diagnose_four_drawbar_s", four_drawbar, "four drawbar runs and a terrain run (the other "
                         "design)", "diagnose_four_drawbar_s")], say)

    rep.section("Peak memory (resident set high-water mark)")
    rep.figure("maxrss_self_mb", "juno bench process (Python, fmpy, FMU, fits)", _self_maxrss_mb(), "MB",
               note="getrusage maxrss")
    for name, value in rss.items():
        if value is None:
            rep.figure(f"maxrss_{name.split()[0]}_mb", f"{name} (largest)", float("nan"), "MB",
                       note="not sampled")
        else:
            rep.figure(f"maxrss_{name.split()[0]}_mb", name + (" (largest)" if " " in name else ""), value, "MB",
                       note="VmHWM, sampled; forked from this process, so shared pages count" if " " in name
                       else "VmHWM")
    end_load = loadavg()
    if campaign_time is not None:
        rep.line(f"(synthesizing the campaign took {campaign_time:.1f} s)")
    print(f"\n{_fmt_load(end_load)} at the end.  Figures are wall-clock medians; a CPU share well below 100 % "
          f"or a load average above {os.cpu_count()} means other processes shared the machine.")
    missed = [f["label"] for f in rep.figures if f["met"] is False]
    if missed:
        print("targets missed: " + "; ".join(missed))

    return {"time": stamp, "machine": info, "load_start": start_load, "load_end": end_load,
            "repeats": repeats, "long_repeats": long_repeats, "quick": bool(quick),
            "sections": rep.sections, "figures": rep.figures, "targets": TARGETS}
