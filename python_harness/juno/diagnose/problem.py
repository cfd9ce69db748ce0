"""The data of a diagnosis (Problem): every run prepared for replay, and each scaled residual
labelled with its run, signal, time and block (training or held out); and the residuals of a
model on it."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ..campaign import Campaign
from ..identify import PreparedRun, Segment, prepare_run, run_residuals
from ..simulator import SOIL_PARAMETERS, JunoFMU, SimulationError
from .candidates import run_parameters

BLOCK = 4.0          # s, length of the alternating training / held-out blocks
OUTPUT_INTERVAL = 0.05   # s between the FMU's output samples the residuals are read from
#: Integration step of the diagnosis (s).  The base model and every candidate share it; its error
#: against 0.25 ms is 0.12 % in torque and 0.0008 in slip on the drawbar benchmark run
#: (docs/benchmarks.md).  The terrain replay uses it too: a coarser step makes the replay of the
#: mound's transients worse than the sensor noise.
DIAGNOSE_STEP = 5e-3


@dataclass
class Problem:
    """Everything a fit needs; picklable so worker processes can rebuild it."""

    campaign_root: str
    grid_file: str | dict[str, str] | None   # each terrain run's gridded scan (run id -> file)
    fmu_path: str
    prepared: list[PreparedRun] = field(default_factory=list)
    train: np.ndarray | None = None      # boolean mask over the concatenated residuals
    meta: dict[str, np.ndarray] = field(default_factory=dict)   # per residual: run, signal, time, block
    #: the lug count of a ripple in the wheel angle the fits take as a nuisance (ripple_nuisance.py)
    ripple_lugs: int | None = None
    #: that ripple's bases over these runs' residuals, made once (ripple_nuisance._bases)
    ripple_bases: list | None = field(default=None, repr=False)
    #: how the terrain runs are replayed (build_problem's ``terrain_drive``, ``terrain_segment``)
    terrain_drive: str = "spin"
    terrain_segment: float | None = None
    #: the terrain runs replayed with fresh sensor noise, for judging (terrain_replicas.py); made
    #: in the process that judges, and not sent to the processes that fit
    terrain_replicas: Any = field(default=None, repr=False, compare=False)
    #: whether the IMU's pitch offset is a free nuisance (sensor_offset.py): not where the
    #: campaign's manifest says the mounting is calibrated (Campaign.imu_mounting)
    pitch_offset_free: bool = True
    #: each run's IMU mounting (run id -> RunSpec.imu_mount): runs on one mounting share one pitch
    #: offset (sensor_offset.py); a run not named is on the campaign's (DEFAULT_IMU_MOUNT)
    imu_mounts: dict[str, str] = field(default_factory=dict)

    def __getstate__(self):
        state = dict(self.__dict__)
        state["terrain_replicas"] = None
        return state


def build_problem(campaign: Campaign, fmu_path: str, grid_file: str | dict[str, str] | None,
                  terrain_segment: float | None = None, terrain_drive: str = "spin") -> Problem:
    """Prepares every run and labels each residual with its run, signal, time and block.
    ``grid_file``: each terrain run's gridded scan (run id -> file; a run without one is left
    out), or one file for every terrain run, or None (no terrain run).
    ``terrain_segment`` (s): replay terrain runs in segments restarted at the measured pose
    (identify.prepare_run; experimental, off by default).  ``terrain_drive``: how terrain runs
    are replayed (identify.REPLAY_DRIVES); drawbar runs follow the measured spins."""
    prepared = _prepared_runs(campaign, grid_file, terrain_segment, terrain_drive)
    runs, signals, times = [], [], []
    for p in prepared:
        for column, (ts, _vs, _out, _sigma, _lag) in p.targets.items():
            runs += [p.run_id] * len(ts)
            signals += [column] * len(ts)
            times.append(ts)
    for p in prepared:
        p.params["solver.step"] = DIAGNOSE_STEP
        p.params["solver.tolerance"] = 0.0
    t = np.concatenate(times) if times else np.zeros(0)
    block = np.floor(t / BLOCK).astype(int)
    problem = Problem(str(campaign.root), grid_file, fmu_path, prepared, terrain_drive=terrain_drive,
                      terrain_segment=terrain_segment, pitch_offset_free=campaign.imu_mounting != "calibrated",
                      imu_mounts={spec.id: spec.imu_mount for spec in campaign.runs})
    problem.train = (block % 2) == 0
    problem.meta = {"run": np.array(runs), "signal": np.array(signals), "time": t, "block": block}
    return problem


def _prepared_runs(campaign: Campaign, grid_file: str | dict[str, str] | None, terrain_segment: float | None,
                   terrain_drive: str) -> list[PreparedRun]:
    """Every run of the campaign prepared for replay (build_problem); a terrain run without a
    gridded scan is left out, and so is a wheel_rig table (steady testbed points, not a replay)."""
    prepared = []
    for run in campaign.runs:
        if run.kind == "wheel_rig":
            continue
        terrain = run.kind == "terrain"
        grid = grid_file.get(run.id) if isinstance(grid_file, dict) else grid_file
        if terrain and grid is None:
            continue
        # The nominal scales: the judging's thresholds and the structure floors are calibrated
        # on them (docs/diagnosis.md, step 1).
        prepared.append(prepare_run(campaign, run, terrain_file=grid if terrain else None,
                                    segment=terrain_segment, drive=terrain_drive if terrain else "spin",
                                    scales="nominal"))
    return prepared


def training_part(problem: Problem, kinds: tuple[str, ...]) -> Problem:
    """The runs of ``kinds`` with only their training samples to compare, each simulated no
    further than its last training sample (training_run); the residuals on it are the training
    residuals of those runs, in the same order.

    Why: a fit sees only the training blocks, and a replay's samples depend only on what came
    before them, so the simulation past a run's last training sample (a held-out block at its
    end: 2 s of a 22 s run, 4 s of a 32 s one) is work no fit uses.  The samples it does
    compare are the same numbers as on the whole replay."""
    runs, start = [], 0
    for p in problem.prepared:
        n = sum(len(v[0]) for v in p.targets.values())
        if p.kind in kinds:
            runs.append(training_run(p, problem.train[start:start + n]))
        start += n
    part = Problem(problem.campaign_root, problem.grid_file, problem.fmu_path, runs,
                   ripple_lugs=problem.ripple_lugs)
    part.train = np.ones(sum(sum(len(v[0]) for v in p.targets.values()) for p in runs), bool)
    return part


def training_run(p: PreparedRun, train: np.ndarray) -> PreparedRun:
    """The prepared run ``p`` comparing only the samples where ``train`` (over its residuals, in
    order) holds, and simulated to the first output sample (OUTPUT_INTERVAL) at or after the
    last of them: the same communication points as the whole replay, so the same numbers.
    Segments after that sample are left out."""
    targets, start, last = {}, 0, 0.0
    for column, (ts, vs, out, sigma, lag) in p.targets.items():
        keep = train[start:start + len(ts)]
        start += len(ts)
        targets[column] = (ts[keep], vs[keep], out, sigma, lag)
        if np.any(keep):
            last = max(last, float(ts[keep][-1]))
    pieces = p.segments or [Segment(0.0, p.duration, {})]
    kept = [s for s in pieces if s.start <= last] or pieces[:1]
    final = kept[-1]
    whole = int(round((final.stop - final.start) / OUTPUT_INTERVAL))
    needed = min(whole, int(np.ceil((last - final.start) / OUTPUT_INTERVAL - 1e-9)) + 1)
    stop = final.stop if needed >= whole else final.start + OUTPUT_INTERVAL * needed
    segments = kept[:-1] + [replace(final, stop=stop)] if p.segments else []
    return replace(p, duration=stop if not p.segments else p.duration, targets=targets, segments=segments)


class ReplayCache:
    """The replays of one fit, remembered: (run, FMU parameters) -> the run's scaled residuals, or
    why its simulation failed.  The model is deterministic (the FMU is reset before every run),
    so a replay asked for again gives the numbers it gave; a fit asks again where least squares
    returns to a point it evaluated (the coarse search's best point is where the fit starts, the
    optimum is replayed for the result).  Keeps the ``size`` most recent replays."""

    def __init__(self, size: int = 128) -> None:
        self.size = size
        self.hits = 0
        self._entries: dict[tuple, tuple[np.ndarray | None, str | None]] = {}

    @staticmethod
    def key(run: PreparedRun, params: dict[str, object]) -> tuple:
        """The prepared run (itself: the same run id prepared for another drive is another
        replay) and its FMU parameters, exactly (every number as a float, names sorted)."""
        return (run.run_id, id(run)) + tuple((k, v if isinstance(v, str) else float(v)) for k, v in sorted(params.items()))

    def get(self, key: tuple) -> tuple[np.ndarray | None, str | None] | None:
        found = self._entries.get(key)
        if found is not None:
            self.hits += 1
            self._entries[key] = self._entries.pop(key)       # most recent last
        return found

    def put(self, key: tuple, value: tuple[np.ndarray | None, str | None]) -> None:
        self._entries[key] = value
        while len(self._entries) > self.size:
            del self._entries[next(iter(self._entries))]


def run_kinds(problem: Problem) -> np.ndarray:
    """The kind of run ("drawbar" or "terrain") of every residual of ``problem``."""
    kind_of = {p.run_id: p.kind for p in problem.prepared}
    return np.array([kind_of[r] for r in problem.meta["run"]])


def all_residuals(fmu: JunoFMU, problem: Problem, params: dict[str, object]) -> np.ndarray:
    """Residuals of every run; a run the model cannot simulate gets NaN (judged as failed)."""
    return residuals_by_run(fmu, problem, params)[0]


def residuals_by_run(fmu: JunoFMU, problem: Problem, params: dict[str, object], cache: ReplayCache | None = None
                     ) -> tuple[np.ndarray, dict[str, str]]:
    """all_residuals's residuals, and for each run that failed (run id), why (its run, file,
    simulation time and FMU message).  ``cache``: replays already made (residuals_or_failure)."""
    parts, failures = [], {}
    for p in problem.prepared:
        one = Problem(problem.campaign_root, problem.grid_file, problem.fmu_path, [p])
        r, failure = residuals_or_failure(fmu, one, params, (p.kind,), cache)
        n = sum(len(v[0]) for v in p.targets.values())
        parts.append(r if r is not None else np.full(n, np.nan))
        if failure is not None:
            failures[p.run_id] = failure
    return np.concatenate(parts), failures


def residuals_for(fmu: JunoFMU, problem: Problem, params: dict[str, object],
                  kinds: tuple[str, ...] = ("drawbar", "terrain"), cache: ReplayCache | None = None
                  ) -> np.ndarray | None:
    """Scaled residuals of the runs of ``kinds`` for the FMU parameters ``params`` (in the
    order of ``problem.prepared``); None if a run fails."""
    return residuals_or_failure(fmu, problem, params, kinds, cache)[0]


def residuals_or_failure(fmu: JunoFMU, problem: Problem, params: dict[str, object],
                         kinds: tuple[str, ...] = ("drawbar", "terrain"), cache: ReplayCache | None = None
                         ) -> tuple[np.ndarray | None, str | None]:
    """(residuals_for's residuals, None), or (None, why the first failed run failed: its run,
    file, simulation time and FMU message).  With a ``cache``, a run replayed before with the
    same parameters is not simulated again."""
    soil = {k: params[k] for k in SOIL_PARAMETERS}
    extra = {k: v for k, v in params.items() if k not in SOIL_PARAMETERS}
    parts = []
    for p in problem.prepared:
        if p.kind not in kinds:
            continue
        # A parameter applied to some runs only (candidates.for_runs: a scan's registration) goes
        # to those runs.  The registration belongs to the scan: runs on flat ground (no terrain
        # file) do not get it (the FMU would raise its flat ground by terrain.offsetZ).
        run_extra = run_parameters(extra, p.run_id)
        if "terrain.file" not in p.params:
            run_extra = {k: v for k, v in run_extra.items() if not k.startswith("terrain.")}
        key = ReplayCache.key(p, {**p.params, **soil, **run_extra}) if cache is not None else None
        known = cache.get(key) if cache is not None else None
        part, failure = known if known is not None else _replay(fmu, p, soil, run_extra)
        if cache is not None and known is None:
            cache.put(key, (part, failure))
        if failure is not None:
            return None, failure
        parts.append(part)
    return (np.concatenate(parts) if parts else np.zeros(0)), None


def _replay(fmu: JunoFMU, p: PreparedRun, soil: dict[str, float], extra: dict[str, object]
            ) -> tuple[np.ndarray | None, str | None]:
    """(scaled residuals of the run ``p``, None), or (None, why its simulation failed or gave
    non-finite values)."""
    try:
        part = run_residuals(fmu, p, soil, extra, OUTPUT_INTERVAL)
    except SimulationError as exc:
        return None, str(exc)
    if not np.all(np.isfinite(part)):
        return None, f"run '{p.run_id}' ({p.file}): the simulation gives non-finite values"
    return part, None
