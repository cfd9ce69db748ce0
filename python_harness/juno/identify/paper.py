"""The paper's identification: each drawbar run's steady-window averages fitted by
Nelder-Mead with the paper's cost (Eqns 10-13) and initial guess (:func:`identify_paper`,
:func:`identify_paper_runs`)."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
from scipy.optimize import minimize

from ..campaign import Campaign, RunData, RunSpec, forward_speed, read_run, steady_average
from ..errors import InputError
from ..parallel import FMUHandle, map_tasks
from ..rover_model import SOIL_PARAMETERS, rover
from ..simulator import InputSignals, JunoFMU, SimulationError
from .base import FAILED_COST, IDENTIFY_STEP, PAPER_INITIAL, EvaluationLog, FitError, base_parameters, require_runs


@dataclass
class SteadyAverages:
    """Steady-window averages of one drawbar run (SI units)."""

    run_id: str
    window: tuple[float, float]
    drawbar: float      # N
    torque_left: float  # N m
    torque_right: float
    speed: float        # m/s, forward speed from the total station
    omega_left: float   # rad/s
    omega_right: float
    wheel_radius: float  # m, the rover's (the campaign's, else the FMU's)

    def weights(self) -> tuple[float, float, float]:
        """The paper's weights w1, w2, w3 from the measured averages."""
        v_r = self.speed / self.wheel_radius
        w = 0.5 * (self.omega_left + self.omega_right)
        return w / (v_r + w), 0.5 * v_r / (v_r + w), 0.5 * v_r / (v_r + w)


def steady_averages(campaign: Campaign, run: RunSpec, data: RunData | None = None) -> SteadyAverages:
    """Averages over the run's steady window (the whole run if none is given)."""
    data = data or read_run(campaign, run)
    t = data.time
    window = tuple(run.steady_window) if run.steady_window else (float(t[0]), float(t[-1]))
    times = np.linspace(window[0], window[1], 101)
    speed = float(np.mean(forward_speed(data, times)))
    return SteadyAverages(run.id, window, steady_average(data, "drawbar_force", window),
                          steady_average(data, "torque_left", window),
                          steady_average(data, "torque_right", window), speed,
                          steady_average(data, "omega_left", window),
                          steady_average(data, "omega_right", window), rover(campaign.rover).wheel_radius)


def paper_cost(fmu: JunoFMU, soil: dict[str, float], avg: SteadyAverages,
               base: dict[str, object] | None = None, output_interval: float = 0.1,
               log: EvaluationLog | None = None, file: str | None = None) -> float:
    """Eqn 10: weighted squared residuals of speed/R and wheel spins over the simulated window.

    The rover starts at the measured average speed with rolling wheels,
    driven by the averaged torques against the averaged drawbar force
    (``drive.mode = 0``), for the length of the steady window.  A simulation that fails (or
    gives a non-finite cost) costs FAILED_COST and is recorded in ``log`` (naming the run and
    its data file ``file``).
    """
    params = {**(base or {}), **soil, "drive.mode": 0, "init.vx": avg.speed, "solver.step": IDENTIFY_STEP,
              "solver.tolerance": 0.0}
    inputs = InputSignals.constant(drawbarForce=avg.drawbar, torqueLeft=avg.torque_left,
                                   torqueRight=avg.torque_right)
    duration = avg.window[1] - avg.window[0]
    # A window shorter than the output interval is compared at its end alone.
    output_interval = min(output_interval, duration)
    try:
        sim = fmu.simulate(params, inputs, duration, output_interval, outputs=("vx", "omegaLeft", "omegaRight"))
    except SimulationError as exc:
        if log is not None:
            log.record(str(exc.located(avg.run_id, file)))
        return FAILED_COST
    w1, w2, w3 = avg.weights()
    res_v = (avg.speed - sim["vx"][1:]) / avg.wheel_radius
    res_r = avg.omega_right - sim["omegaRight"][1:]
    res_l = avg.omega_left - sim["omegaLeft"][1:]
    cost = float(np.sum(w1 * res_v**2 + w2 * res_r**2 + w3 * res_l**2))
    if log is not None:
        log.record(None if np.isfinite(cost) else
                   f"run '{avg.run_id}'" + (f" ({file})" if file else "") + ": the simulated speed or spins "
                   f"are not finite at {_soil_text(soil)}")
    return cost if np.isfinite(cost) else FAILED_COST


def _soil_text(soil: dict[str, float]) -> str:
    return ", ".join(f"{k} = {v:.4g}" for k, v in soil.items())


@dataclass
class PaperResult:
    """One run's paper-style identification (the form of Tables 1-3).

    ``status``: "ok", or "not identified" when the fit did not move from its start or the
    objectives see no parameter direction (``jacobian_rank`` 0); ``converged`` is then False
    whatever the optimiser said.  A fit whose simulations failed is not a result: it raises
    FitError.  ``failed_evaluations``: simulations that failed along the way (at most
    MAX_FAILED_FRACTION of ``evaluations``)."""

    run_id: str
    initial: dict[str, float]
    final: dict[str, float]
    cost: float
    evaluations: int
    converged: bool
    averages: SteadyAverages
    jacobian_rank: int = 0
    wall_time: float = 0.0
    status: str = "ok"
    failed_evaluations: int = 0


def identify_paper(fmu: JunoFMU, campaign: Campaign, run: RunSpec | str,
                   initial: dict[str, float] | None = None, max_evaluations: int = 600,
                   progress: Callable[[str], None] | None = None) -> PaperResult:
    """The paper's identification on one drawbar run (unconstrained Nelder-Mead)."""
    run = campaign.run(run) if isinstance(run, str) else run
    if run.kind != "drawbar":
        raise InputError(f"run '{run.id}' is a {run.kind} run; the paper-style fit needs a drawbar run",
                         campaign.manifest_path)
    initial = dict(initial or PAPER_INITIAL)
    avg = steady_averages(campaign, run)
    base = base_parameters(campaign)
    scale = np.array([initial[k] for k in SOIL_PARAMETERS])
    start = time.perf_counter()
    log = EvaluationLog()

    def cost(y: np.ndarray) -> float:
        soil = dict(zip(SOIL_PARAMETERS, (y * scale).tolist()))
        value = paper_cost(fmu, soil, avg, base, log=log, file=run.file)
        if progress and log.count % 50 == 0:
            progress(f"{run.id}: {log.count} evaluations, cost {value:.3g}")
        return value

    res = minimize(cost, np.ones(4), method="Nelder-Mead",
                   options={"xatol": 1e-4, "fatol": 1e-12, "maxfev": max_evaluations, "adaptive": False})
    fit = f"paper-style fit of run '{run.id}'"
    log.check(fit, optimum_failed=not res.fun < FAILED_COST)
    final = dict(zip(SOIL_PARAMETERS, (res.x * scale).tolist()))
    rank = _paper_rank(fmu, final, avg, base, log, run.file)
    log.check(fit, optimum_failed=rank is None)
    moved = bool(np.any(res.x != 1.0))
    status = "ok" if moved and rank else "not identified"
    return PaperResult(run.id, initial, final, float(res.fun), int(res.nfev), bool(res.success) and status == "ok",
                       avg, int(rank or 0), time.perf_counter() - start, status, log.failed)


def _paper_rank(fmu: JunoFMU, soil: dict[str, float], avg: SteadyAverages, base: dict[str, object],
                log: EvaluationLog | None = None, file: str | None = None) -> int | None:
    """Numerical rank of d(steady objectives)/d(log a): how many directions the data sees;
    None if a simulation failed (recorded in ``log``)."""
    def objectives(s):
        params = {**base, **s, "drive.mode": 0, "init.vx": avg.speed, "solver.step": IDENTIFY_STEP,
                  "solver.tolerance": 0.0}
        inputs = InputSignals.constant(drawbarForce=avg.drawbar, torqueLeft=avg.torque_left,
                                       torqueRight=avg.torque_right)
        try:
            duration = avg.window[1] - avg.window[0]
            sim = fmu.simulate(params, inputs, duration, min(0.5, duration),
                               outputs=("vx", "omegaLeft", "omegaRight"))
        except SimulationError as exc:
            if log is not None:
                log.record(str(exc.located(avg.run_id, file)))
            return None
        y = np.array([sim["vx"][-1] / avg.wheel_radius, sim["omegaLeft"][-1], sim["omegaRight"][-1]])
        if log is not None:
            log.record(None if np.all(np.isfinite(y)) else f"run '{avg.run_id}': non-finite objectives at "
                       f"{_soil_text(s)}")
        return y if np.all(np.isfinite(y)) else None
    y0 = objectives(soil)
    if y0 is None:
        return None
    cols = []
    for k in SOIL_PARAMETERS:
        s = dict(soil)
        s[k] = s[k] * 1.01 if k != "soil.gamma" else min(s[k] * 1.01, 0.999)
        y = objectives(s)
        if y is None:
            return None
        cols.append((y - y0) / 0.01)
    sv = np.linalg.svd(np.array(cols).T, compute_uv=False)
    return int(np.sum(sv > 1e-3 * sv[0])) if sv[0] > 0 else 0


def _paper_task(args) -> PaperResult | FitError:
    """One run's paper-style fit; a FitError is returned, not raised, so the caller raises it
    as it is (a task's raised error would come back wrapped with the task's arguments)."""
    handle, campaign, run_id, initial, max_evaluations = args
    try:
        return identify_paper(handle.get(), campaign, run_id, initial, max_evaluations)
    except FitError as exc:
        return exc


def identify_paper_runs(fmu: JunoFMU, campaign: Campaign, runs: Sequence[RunSpec | str] | None = None,
                        initial: dict[str, float] | None = None, max_evaluations: int = 600,
                        workers: int | None = None, scheduler: str | None = None,
                        progress: Callable[[str], None] | None = None) -> list[PaperResult]:
    """:func:`identify_paper` on each of ``runs`` (default: every drawbar run) as parallel tasks
    (juno.parallel: ``workers`` local processes, default one per core, or the Dask cluster at
    ``scheduler``).  Results in the order of ``runs``, identical to fitting them one by one.
    Raises FitError for the first run (in that order) whose fit failed, InputError when the
    campaign has no drawbar run (require_runs)."""
    ids = [r if isinstance(r, str) else r.id for r in (runs or require_runs(campaign, "identify"))]
    # The paper's averages are steady-state ones: a run without a steady window is averaged over
    # its whole length, start-up included, and the user is told so.
    unwindowed = [run_id for run_id in ids if not campaign.run(run_id).steady_window]
    if progress and unwindowed:
        progress(f"{', '.join(unwindowed)}: no steady_window in the manifest: the paper-style fit averages over "
                 "the whole run, its start-up included")
    handle = FMUHandle(fmu)
    jobs = [(handle, campaign, run_id, initial, max_evaluations) for run_id in ids]

    def done(i: int, p: PaperResult | FitError) -> None:
        if progress and isinstance(p, PaperResult):
            progress(f"{p.run_id}: paper-style fit done ({p.evaluations} evaluations, cost {p.cost:.3g})")
    results = map_tasks(_paper_task, jobs, workers=workers, scheduler=scheduler, on_result=done)
    for r in results:
        if isinstance(r, FitError):
            raise r
    return results
