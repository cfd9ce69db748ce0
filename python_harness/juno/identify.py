"""Identification of the soil parameters a = [k_h, eta, gamma, K_vx].

Two ways:

* :func:`identify_paper` - the paper's: for one drawbar run, the steady-
  window averages of drawbar force and drive torques are the (constant)
  inputs, the averages of forward speed and wheel spins the objectives;
  the cost is Eqns 10-13 with the paper's weights, minimised by an
  unconstrained Nelder-Mead from the paper's initial guess.  Three averaged
  numbers cannot pin four parameters: the result reports that.
* :func:`identify_joint` - beyond the paper: one fit over all drawbar runs
  (and optionally the terrain run) using the whole measured time series,
  in transformed parameters that keep the search physical (log for
  positive values, logit for gamma), a trust-region Gauss-Newton fit of the
  scaled residuals (or Nelder-Mead then that polish), with the parameter
  covariance from the Jacobian (inflated for time-correlated residuals)
  and an identifiability report.

A failed fit is an error, never a result.  Every objective evaluation is logged
(:class:`EvaluationLog`: how many, how many failed, the first failure's run, file, time
and FMU message); a fit whose optimum failed, or over which more than
MAX_FAILED_FRACTION of the evaluations failed, raises :class:`FitError` naming the first
failure.  A parameter the data does not see (a zero Jacobian column) or a fit that did
not move is reported "not identified", with no uncertainty, never "pinned".

Both use every core (juno.parallel): the joint fit evaluates the runs of one residual
vector, and the points of its finite-difference Jacobian, as parallel tasks (each worker
process holds its own FMU instance); :func:`identify_paper_runs` fits the drawbar runs in
parallel and :func:`identify_multistart` runs joint fits from several starting points in
parallel.  Where a task runs does not change its result: the fits are identical, bit for bit,
to the serial ones (``workers=1``).  With ``scheduler="tcp://host:port"`` the tasks run on a
Dask distributed cluster instead.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Mapping, Sequence

import numpy as np
from scipy.optimize import least_squares, minimize
from threadpoolctl import threadpool_limits

from .campaign import Campaign, RunData, RunSpec, forward_speed, read_run, steady_average
from .errors import InputError
from .parallel import FMUHandle, TaskPool, map_tasks, resolve_workers
from .rover_model import SOIL_PARAMETERS, rover
from .sensor_noise import residual_scale
from .simulator import InputSignals, JunoFMU, SimulationError

#: The paper's initial guess (Tables 1-3).
PAPER_INITIAL = {"soil.kh": 2.5e5, "soil.eta": 0.5, "soil.gamma": 0.15, "soil.Kvx": 0.5}
#: Integration step used while identifying (s), fixed (``solver.tolerance`` 0: the residuals of
#: neighbouring parameter values then share one discretisation, which the finite-difference
#: Jacobian of the fit needs): 2 ms keeps the steady slip within 0.1 % of 1 ms (5 ms: 0.5 %,
#: which biased K_vx by 2 sigma in noisy synthetic tests).
IDENTIFY_STEP = 2e-3
#: What a failed simulation costs a Nelder-Mead fit (far above any real cost, so the simplex
#: moves away from it), and the scaled residual every sample gets in a least-squares fit.
FAILED_COST = 1e6
FAILED_RESIDUAL = 1e3
#: The largest fraction of a fit's objective evaluations that may fail.  Why: a failed
#: evaluation returns a made-up constant (FAILED_COST, FAILED_RESIDUAL), which the optimiser
#: takes for a value of the objective.  A few, at the edge of the region the model can
#: simulate, only turn the search back; beyond a small fraction the optimiser has explored a
#: different function from the one it reports minimising, and its optimum, cost and Jacobian
#: say nothing about the data.  A finite-difference Jacobian costs one evaluation per
#: parameter, so 5 % is about one failed point in every fifth iteration.
MAX_FAILED_FRACTION = 0.05
#: A Jacobian column (d residuals / d search parameter) whose norm is at most this fraction of
#: the largest column's is treated as zero: the data does not see that parameter (its
#: pseudo-inverse variance would be 0, which would read as perfectly pinned).
ZERO_COLUMN = 1e-12


# ------------------------------------------------------ failures and shape

class FitError(SimulationError):
    """A fit whose simulations failed: its optimum, or more than MAX_FAILED_FRACTION of its
    objective evaluations.  The CLI maps it (as every SimulationError) to exit status 2.

    ``failed`` and ``evaluations`` count the failed and all evaluations; ``first`` is the
    first failure (a SimulationError naming its run, file, time and FMU message)."""

    def __init__(self, fit: str, failed: int, evaluations: int, first: str, reason: str = ""):
        self.fit, self.failed, self.evaluations, self.first, self.reason = fit, int(failed), int(evaluations), \
            str(first), str(reason)
        what = f"{fit} failed: {reason or f'{failed} of {evaluations} simulations failed'}; first failure"
        super().__init__(what, [self.first])

    def __reduce__(self):
        return (FitError, (self.fit, self.failed, self.evaluations, self.first, self.reason))


@dataclass
class EvaluationLog:
    """How a fit's objective evaluations went: ``count`` evaluations, ``failed`` of them failed,
    ``first_failure`` the first failure's text (run, file, simulation time, FMU message)."""

    count: int = 0
    failed: int = 0
    first_failure: str | None = None

    def record(self, failure: str | None = None) -> None:
        """One evaluation; ``failure`` is its failure's text, or None if it succeeded."""
        self.count += 1
        if failure is not None:
            self.failed += 1
            if self.first_failure is None:
                self.first_failure = failure

    @property
    def failed_fraction(self) -> float:
        return self.failed / self.count if self.count else 0.0

    def check(self, fit: str, optimum_failed: bool) -> None:
        """Raises FitError if the optimum failed or more than MAX_FAILED_FRACTION of the
        evaluations did."""
        if optimum_failed:
            reason = f"the model cannot be simulated at its optimum ({self.failed} of {self.count} " \
                     f"simulations failed)"
        elif self.failed_fraction > MAX_FAILED_FRACTION:
            reason = f"{self.failed} of {self.count} simulations failed (more than " \
                     f"{MAX_FAILED_FRACTION:.0%}: the optimiser minimised the failures' stand-in values)"
        else:
            return
        raise FitError(fit, self.failed, self.count, self.first_failure or "no failure message recorded", reason)


#: What each step needs: step -> (kind of run, what for).
STEP_NEEDS = {
    "identify": ("drawbar", "identification fits the soil to drawbar runs (flat ground, measured drawbar force)"),
    "identify --with-terrain": ("terrain", "the terrain run is fitted together with the drawbar runs"),
    "validate": ("terrain", "validation replays a terrain run on its own gridded scan"),
    "report": ("drawbar", "the report identifies the soil on drawbar runs first"),
    "diagnose": ("drawbar", "the diagnosis fits the soil and every candidate on the drawbar runs; "
                            "terrain runs are judged on their own scans"),
}


def require_runs(campaign: Campaign, step: str) -> list[RunSpec]:
    """The campaign's runs of the kind ``step`` needs (STEP_NEEDS), or an InputError naming the
    manifest, the step and what it needs.  Called before any long computation."""
    kind, why = STEP_NEEDS[step]
    runs = campaign.runs_of_kind(kind)
    if not runs:
        counts = {k: sum(r.kind == k for r in campaign.runs) for k in ("drawbar", "terrain", "wheel_rig")}
        have = " and ".join(f"{n} {k} run{'s' if n != 1 else ''}" for k, n in counts.items() if n)
        raise InputError(f"'{step}' needs at least one {kind} run, and the campaign has none ({have}): {why}",
                         campaign.manifest_path)
    return runs


# ----------------------------------------------------------------- transforms

def to_search(params: dict[str, float]) -> np.ndarray:
    """Physical soil parameters -> unconstrained search vector (log, log, logit, log)."""
    g = params["soil.gamma"]
    return np.array([np.log(params["soil.kh"]), np.log(params["soil.eta"]),
                     np.log(g / (1 - g)), np.log(params["soil.Kvx"])])


#: Bounds of the soil's search vector (ln k_h, ln eta, logit gamma, ln K_vx): k_h 1e3-1e8,
#: eta 0.05-2, gamma 0.01-0.99, K_vx 0.01-100, within the FMU's declared ranges and wide of any
#: soil the paper or the terramechanics literature reports.  Unbounded, a fit that pushed gamma
#: towards 0 (to absorb an unmodelled torque loss) reached logit -33, where gamma has no
#: gradient left and can never come back; and a fit of data the model cannot describe leaves
#: the declared ranges, where the FMU refuses to simulate.  A fit that ends at a bound is
#: reported as doubtful (fit_doubts).
SOIL_SEARCH_BOUNDS = (np.array([np.log(1e3), np.log(0.05), -4.6, np.log(0.01)]),
                      np.array([np.log(1e8), np.log(2.0), 4.6, np.log(100.0)]))


def from_search(x: Sequence[float]) -> dict[str, float]:
    """Inverse of :func:`to_search`."""
    return {"soil.kh": float(np.exp(x[0])), "soil.eta": float(np.exp(x[1])),
            "soil.gamma": float(1 / (1 + np.exp(-np.clip(x[2], -500, 500)))), "soil.Kvx": float(np.exp(x[3]))}


def _jacobian_of_transform(params: dict[str, float]) -> np.ndarray:
    """d(physical)/d(search) at ``params`` (diagonal)."""
    g = params["soil.gamma"]
    return np.diag([params["soil.kh"], params["soil.eta"], g * (1 - g), params["soil.Kvx"]])


def base_parameters(campaign: Campaign) -> dict[str, object]:
    """Fixed FMU parameters for identification: the campaign's rover overrides."""
    return dict(campaign.rover)


def terrain_grids(campaign: Campaign, out_dir: str | Path, step: str = "identify --with-terrain") -> dict[str, str]:
    """Each terrain run's LIDAR scan gridded into its own file under ``out_dir`` (run id ->
    path), so that every terrain run is replayed on the ground it was driven on; InputError
    (require_runs) when the campaign has no terrain run."""
    return {run_id: path for run_id, (path, _grid) in gridded_scans(campaign, out_dir, step).items()}


def gridded_scans(campaign: Campaign, out_dir: str | Path, step: str) -> dict[str, tuple[str, object]]:
    """terrain_grids with each run's grid (juno.pointcloud.Grid) as well: run id -> (path, grid)."""
    from .validate import grid_terrain   # validate imports this module
    grids = {}
    for i, run in enumerate(require_runs(campaign, step)):
        run_dir = Path(out_dir) / f"scan{i}"
        run_dir.mkdir(parents=True, exist_ok=True)
        path, grid = grid_terrain(campaign, run, run_dir)
        grids[run.id] = (str(path), grid)
    return grids


# --------------------------------------------------------- paper-style fit

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
            sim = fmu.simulate(params, inputs, avg.window[1] - avg.window[0], 0.5,
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


# ------------------------------------------------------------- joint fit

#: Signals compared in the joint fit, with each residual's nominal scale (1 sigma, about the
#: paper's instruments' noise): a residual is divided by the larger of it and the sensor noise
#: estimated from the run (_targets, sensor_noise.residual_scale).
#: The model follows the measured wheel spins, so the spins are inputs and the
#: drive torque it needs is compared with the torque from the motor current.
#: Positions enter as increments over ``POSITION_LAG`` (a speed without smoothing lag),
#: so the start-up transient does not leave a constant offset behind.
JOINT_SIGNALS = {
    "torque_left": ("torqueLeftApplied", 3.0), "torque_right": ("torqueRightApplied", 3.0),
    "pos_x": ("x", 0.005), "pos_y": ("y", 0.005), "pos_z": ("z", 0.003), "pitch": ("pitch", 0.003),
}
TERRAIN_SIGNALS = {
    "torque_left": ("torqueLeftApplied", 5.0), "torque_right": ("torqueRightApplied", 5.0),
    "pos_x": ("x", 0.01), "pos_y": ("y", 0.01), "pos_z": ("z", 0.01),
}
INCREMENT_SIGNALS = ("pos_x", "pos_y")
#: A stiff PID so the model's spins follow the measured ones without lag (the
#: default gains lag during the start-up and leave a speed error of a few %).
SPIN_TRACKER = {"drive.Kp": 2000.0, "drive.Ki": 2.0e4, "drive.torqueMax": 2000.0}
POSITION_LAG = 1.0     # s
SETTLING_TIME = 2.0    # s: residuals start after the PID has caught the measured spins

#: How a replay drives the wheels (prepare_run's ``drive``):
#: - ``"spin"``: the stiff PID (SPIN_TRACKER) imposes the measured wheel spins; the model's drive
#:   torque is compared with the measured one.
#: - ``"torque"``: the measured drive torque drives each side, and a damping on the spin error,
#:   K (omega_measured - omega) with K = REPLAY_SPIN_DAMPING, keeps the spins on the measured
#:   ones, as a DC motor's back-EMF does at a constant throttle.  It is done with the FMU's own
#:   DC motor (``drive.mode = 2``, REPLAY_MOTOR) at the throttle that makes its torque
#:   T_measured + K (omega_measured - omega) exactly (torque_replay_throttle): what the rover's
#:   controller did.  The compared torque is then K (omega - omega_measured) off the measured
#:   one, so the torque residual still says how much more or less torque the model needs.
#:   Why: imposing the spins is ill-conditioned where the rover climbs a mound at high slip.
#:   Measured on a noise-free synthetic terrain run (drivetrain loss 0.25 and slip-sinkage 1.43,
#:   the campaign tests/python/test_torque_replay.py builds): replayed with the spins imposed, even at the truth's own 1 ms step, a front wheel
#:   lifted off for 10 s and the torque was 60 N m rms off (5 ms: 10 N m); replayed by torque it
#:   is exact at 1 ms and 3.2 N m rms off at 5 ms.  On drawbar runs the spin replay is the better
#:   conditioned one (at slips of 0.6 the traction hardly changes with spin, so a small traction
#:   error moves a torque-driven wheel's spin a lot: 6.9 N m rms at 5 ms against 0.85 N m).
REPLAY_DRIVES = ("spin", "torque")
#: The DC motor the torque replay runs through: a harness choice, set in full on the FMU, so it
#: does not follow the FMU's defaults.  The constants of the FMU's assumed Juno motor, with a
#: supply voltage ten times the real one, so that the throttle stays well inside [-1, 1] up to
#: about 6000 N m per side (the voltage does not enter K).  K = efficiency gearRatio^2 kt^2 /
#: resistance.
REPLAY_MOTOR = {"motor.voltage": 240.0, "motor.kt": 0.0465, "motor.resistance": 0.2,
                "motor.gearRatio": 129.0, "motor.efficiency": 0.85}
REPLAY_SPIN_DAMPING = (REPLAY_MOTOR["motor.efficiency"]
                       * (REPLAY_MOTOR["motor.gearRatio"] * REPLAY_MOTOR["motor.kt"]) ** 2
                       / REPLAY_MOTOR["motor.resistance"])   # N m s/rad, about 153


def torque_replay_throttle(torque: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """Throttle of REPLAY_MOTOR at which its torque is ``torque`` (N m per side, the measured
    drive torque) when the wheels spin at ``omega`` (rad/s, the measured spin), so that at any
    other spin w it gives torque + REPLAY_SPIN_DAMPING (omega - w)."""
    m = REPLAY_MOTOR
    per_volt = m["motor.efficiency"] * m["motor.gearRatio"] * m["motor.kt"] / m["motor.resistance"]
    return (torque / per_volt + m["motor.kt"] * m["motor.gearRatio"] * omega) / m["motor.voltage"]


#: A run replayed in segments (prepare_run's ``segment``) is not compared for this long after
#: each restart: the spin tracker catches the measured spins and the suspension settles.  At
#: least POSITION_LAG, so that each position increment lies within one segment.
SEGMENT_SETTLE = 1.5   # s
#: The restart speed is the measured path's over this half-window around the restart.
SEGMENT_SPEED_WINDOW = 0.25   # s


@dataclass
class Segment:
    """One piece of a run replayed in segments: simulated from ``start`` to ``stop`` (s from
    the run's start) with the FMU parameters ``init`` (the measured pose and speed) on top."""

    start: float
    stop: float
    init: dict[str, float]


@dataclass
class PreparedRun:
    """A measured run ready to be simulated: inputs, parameters and the samples to compare."""

    run_id: str
    kind: str
    duration: float
    inputs: InputSignals
    params: dict[str, object]
    targets: dict[str, tuple[np.ndarray, np.ndarray, str, float, float]]
    # column -> (t, value, output, sigma, lag): compare value(t) - value(t - lag) when lag > 0
    segments: list[Segment] = field(default_factory=list)   # empty: one replay of the whole run
    file: str | None = None     # the run's data file (as in the manifest), named in failures


def _column_signal(data: RunData, name: str, grid: np.ndarray) -> np.ndarray:
    t, v = data.samples(name)
    return np.interp(grid, t, v)


def restart_segments(data: RunData, duration: float, length: float) -> list[Segment]:
    """Segments of ``length`` s covering a run of ``duration`` s: the first starts as the run
    does (at rest, at the first measured pose); each later one restarts the rover at the
    measured position, heading (``yaw``) and forward speed at its start.  A last piece too short
    to compare anything after SEGMENT_SETTLE joins the one before it."""
    if not (np.isfinite(length) and length > SEGMENT_SETTLE):
        raise ValueError(f"a replay segment must be longer than {SEGMENT_SETTLE} s, got {length}")
    if not data.has("yaw"):
        raise ValueError(f"run '{data.run_id or data.path}': a run replayed in segments needs its measured "
                         f"heading (column 'yaw'), and it has none")
    t0 = data.time[0]
    tx, x = data.samples("pos_x")
    ty, y = data.samples("pos_y")
    tw, yaw = data.samples("yaw")
    tx, ty, tw = tx - t0, ty - t0, tw - t0
    starts = [0.0]
    while starts[-1] + length + SEGMENT_SETTLE + 1.0 < duration:
        starts.append(starts[-1] + length)
    segments = []
    for i, start in enumerate(starts):
        stop = starts[i + 1] if i + 1 < len(starts) else duration
        init: dict[str, float] = {}
        if start > 0:
            lo, hi = max(start - SEGMENT_SPEED_WINDOW, 0.0), min(start + SEGMENT_SPEED_WINDOW, duration)
            vx = (np.interp(hi, tx, x) - np.interp(lo, tx, x)) / (hi - lo)
            vy = (np.interp(hi, ty, y) - np.interp(lo, ty, y)) / (hi - lo)
            heading = float(np.interp(start, tw, yaw))
            init = {"init.x": float(np.interp(start, tx, x)), "init.y": float(np.interp(start, ty, y)),
                    "init.yaw": heading, "init.vx": float(vx * np.cos(heading) + vy * np.sin(heading))}
        segments.append(Segment(start, stop, init))
    return segments


def prepare_run(campaign: Campaign, run: RunSpec, data: RunData | None = None,
                terrain_file: str | None = None, stride: int = 1, segment: float | None = None,
                drive: str = "spin", scales: str = "data") -> PreparedRun:
    """Inputs and comparison targets of a measured run.

    Why the spins drive the model: with both drive torque and drawbar force
    imposed, any imbalance integrates into a speed drift (1 % of the drawbar
    force is 0.5 m/s after 30 s), so a replay driven by the torque alone
    diverges even at the true parameters.  With the measured wheel spins imposed by the PID
    (``drive.mode = 1``), the rover settles at the slip where traction
    balances the load, as the real one did; the torque the model needs is
    then compared with the measured one.  Drawbar runs are on flat ground
    with the measured drawbar force; terrain runs on ``terrain_file``.  The
    rover starts at rest at the first measured pose.

    ``segment`` (s, terrain runs only): replay the run in pieces of that
    length, each later one restarted at the measured pose and speed
    (restart_segments), and leave out the SEGMENT_SETTLE s after each
    restart.  Why: over the terrain the spin-following replay drifts in
    heading, and a drift of a few degrees puts the rover on another part of
    a mound; measured, at the true parameters the 30 s replay of some
    synthetic campaigns ended 0.3-0.5 m off the measured path
    (docs/diagnosis.md, ``--terrain-segments``).

    ``scales``: what each residual is divided by: ``"data"``, the sensor noise estimated from
    the run, never below the nominal scale (_targets), or ``"nominal"``, the nominal scales of
    JOINT_SIGNALS and TERRAIN_SIGNALS alone (the diagnosis's, whose thresholds are calibrated
    on them).

    ``drive``: ``"spin"`` (the spins imposed, as above) or ``"torque"`` (the
    measured torque drives the wheels, and a damping towards the measured
    spins, as a DC motor's, keeps them from drifting; REPLAY_DRIVES says when
    each is the better conditioned).
    """
    if drive not in REPLAY_DRIVES:
        raise ValueError(f"run '{run.id}': unknown replay drive '{drive}' (one of {', '.join(REPLAY_DRIVES)})")
    data = data or read_run(campaign, run)
    t = data.time
    grid = np.arange(t[0], t[-1] + 1e-9, 0.01)
    start_pose = {"init.x": float(data.samples("pos_x")[1][0]), "init.y": float(data.samples("pos_y")[1][0])}
    if data.has("yaw"):
        start_pose["init.yaw"] = float(data.samples("yaw")[1][0])
    params: dict[str, object] = {**base_parameters(campaign), **start_pose, "solver.step": IDENTIFY_STEP,
                                 "solver.tolerance": 0.0, "drive.mode": 1, **SPIN_TRACKER}
    drawbar = (_column_signal(data, "drawbar_force", grid) if run.kind == "drawbar" and data.has("drawbar_force")
               else np.zeros(len(grid)))
    omega_left, omega_right = _column_signal(data, "omega_left", grid), _column_signal(data, "omega_right", grid)
    inputs = InputSignals(grid - t[0], {"drawbarForce": drawbar, "omegaRefLeft": omega_left,
                                        "omegaRefRight": omega_right})
    if drive == "torque":
        inputs.values.update(_replay_throttles(run, data, grid, {"left": omega_left, "right": omega_right}))
        params.update({"drive.mode": 2, **REPLAY_MOTOR})
    duration = float(t[-1] - t[0])
    segments = restart_segments(data, duration, segment) if segment is not None and run.kind == "terrain" else []
    if run.kind == "drawbar":
        signals = JOINT_SIGNALS
    else:
        if terrain_file is None:
            raise ValueError(f"run '{run.id}': a terrain run needs a gridded terrain file")
        params["terrain.file"] = terrain_file
        signals = TERRAIN_SIGNALS
    if scales not in ("data", "nominal"):
        raise ValueError(f"run '{run.id}': unknown residual scales '{scales}' (data or nominal)")
    targets = _targets(data, signals, segments, stride, from_data=scales == "data")
    return PreparedRun(run.id, run.kind, duration, inputs, params, targets, segments, run.file)


def _replay_throttles(run: RunSpec, data: RunData, grid: np.ndarray,
                      omega: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The throttle inputs (``throttleLeft``, ``throttleRight``) of a torque-driven replay on the
    time ``grid`` (s, the run's clock), from the measured drive torques and the spins ``omega``
    (side -> rad/s on the grid); ValueError when a torque column is missing or a throttle would
    exceed the replay motor's range."""
    throttles = {}
    for side in ("left", "right"):
        if not data.has(f"torque_{side}"):
            raise ValueError(f"run '{run.id}': a torque-driven replay needs the measured drive torque "
                             f"(column 'torque_{side}'), and it has none")
        throttle = torque_replay_throttle(_column_signal(data, f"torque_{side}", grid), omega[side])
        worst = int(np.argmax(np.abs(throttle)))
        if abs(throttle[worst]) > 1.0:
            raise ValueError(f"run '{run.id}': at t = {grid[worst] - data.time[0]:.2f} s the measured "
                             f"torque_{side} and omega_{side} are beyond what the torque replay's motor can "
                             f"give (throttle {throttle[worst]:.2f})")
        throttles[f"throttle{side.capitalize()}"] = throttle
    return throttles


def _targets(data: RunData, signals: dict[str, tuple[str, float]], segments: Sequence[Segment],
             stride: int, from_data: bool = True) -> dict[str, tuple]:
    """The comparison targets of a run: measured column -> (times s from the run's start, values,
    FMU output, sigma, lag s), every ``stride``-th sample after SETTLING_TIME, leaving out
    SEGMENT_SETTLE s after each restart of a segmented replay; a position column becomes its
    increments over POSITION_LAG.  sigma is the compared quantity's sensor noise estimated from
    the run, never below the signal's nominal scale (sensor_noise.residual_scale); the nominal
    scale alone unless ``from_data``."""
    targets = {}
    for column, (output, nominal) in signals.items():
        if not data.has(column):
            continue
        ts, vs = data.samples(column)
        ts = ts - data.time[0]
        lag = POSITION_LAG if column in INCREMENT_SIGNALS else 0.0
        sigma = residual_scale(ts, vs, nominal, increment=lag > 0) if from_data else nominal
        if lag > 0:
            vs = vs - np.interp(ts - lag, ts, vs)
        keep = ts >= max(SETTLING_TIME, lag + ts[0])
        for seg in segments[1:]:
            keep &= ~((ts >= seg.start) & (ts < seg.start + SEGMENT_SETTLE))
        targets[column] = (ts[keep][::stride], vs[keep][::stride], output, sigma, lag)
    return targets


def run_residuals(fmu: JunoFMU, prepared: PreparedRun, soil: dict[str, float],
                  extra: dict[str, object] | None = None, output_interval: float = 0.05) -> np.ndarray:
    """Scaled residuals (measured - simulated) / sigma of one prepared run, all signals
    concatenated.  A failed simulation raises SimulationError naming the run and its file."""
    outputs = sorted({target[2] for target in prepared.targets.values()})
    params = {**prepared.params, **soil, **(extra or {})}
    pieces = prepared.segments or [Segment(0.0, prepared.duration, {})]
    try:
        sims = [fmu.simulate({**params, **seg.init}, prepared.inputs, seg.stop, output_interval, outputs=outputs,
                             start_time=seg.start) for seg in pieces]
    except SimulationError as exc:
        raise exc.located(prepared.run_id, prepared.file) from exc
    parts = []
    for column, (ts, vs, out, sigma, lag) in prepared.targets.items():
        model = np.empty(len(ts))
        for i, (seg, sim) in enumerate(zip(pieces, sims)):
            last = i == len(pieces) - 1
            inside = (ts >= seg.start) & ((ts < seg.stop) | last)
            model[inside] = np.interp(ts[inside], sim["time"], sim[out])
            if lag > 0:     # within the same piece: SEGMENT_SETTLE >= lag
                model[inside] -= np.interp(ts[inside] - lag, sim["time"], sim[out])
        parts.append((vs - model) / sigma)
    return np.concatenate(parts)


@dataclass
class JointResult:
    """A joint identification with uncertainty and identifiability.

    ``status``: "ok", or "not identified" when the fit did not move from its start or the data
    does not see some parameter (a zero Jacobian column); such a parameter has an infinite
    ``std`` (null in JSON) and the identifiability "not identified".  A fit whose simulations
    failed is not a result: it raises FitError.  ``failed_evaluations``: simulations that
    failed along the way (at most MAX_FAILED_FRACTION of ``evaluations``)."""

    params: dict[str, float]
    std: dict[str, float]            # 1 sigma, physical units
    relative_std: dict[str, float]
    correlation: np.ndarray
    identifiability: dict[str, str]  # parameter -> "pinned" / "weak" / "not identifiable" / "not identified"
    cost: float                      # mean squared scaled residual
    evaluations: int
    wall_time: float
    runs: list[str] = field(default_factory=list)
    singular_values: list[float] = field(default_factory=list)
    inflation: float = 1.0           # variance inflation for correlated residuals
    status: str = "ok"
    failed_evaluations: int = 0
    #: Why the estimates should not be trusted as they stand (empty: no reason found): a
    #: parameter at the limit of the FMU's declared range, structure beyond sensor noise left in
    #: the residuals (fit_doubts).
    doubts: list[str] = field(default_factory=list)
    structure: dict | None = None    # the residual structure test of the fit (juno.residual_structure)


def correlation_inflation(residuals: np.ndarray, segment_lengths: Sequence[int]) -> float:
    """Variance inflation (>= 1) for time-correlated residuals, from each segment's lag-1
    autocorrelation rho: the sum-of-squares-weighted mean of (1 + rho) / (1 - rho)."""
    total, weight, start = 0.0, 0.0, 0
    for n in segment_lengths:
        seg = residuals[start:start + n]
        start += n
        if n < 3:
            continue
        e = seg - seg.mean()
        denom = float(np.dot(e, e))
        if denom <= 0:
            continue
        rho = min(max(float(np.dot(e[1:], e[:-1]) / denom), 0.0), 0.98)
        w = float(np.dot(seg, seg))
        total += w * (1 + rho) / (1 - rho)
        weight += w
    return max(total / weight, 1.0) if weight > 0 else 1.0


def classify(relative_std: float) -> str:
    """Identifiability of one parameter from its relative 1-sigma uncertainty (not finite: the
    data does not see it)."""
    if not np.isfinite(relative_std):
        return "not identified"
    if relative_std < 0.05:
        return "pinned"
    if relative_std < 0.25:
        return "weak"
    return "not identifiable"


class JointResiduals:
    """The joint fit's residual function: search vector x -> scaled residuals (measured -
    simulated) / sigma of every prepared run, concatenated; FAILED_RESIDUAL everywhere when
    a run fails or gives a non-finite value (so the trust region shrinks away from it).
    ``log`` (EvaluationLog) records every evaluation made for the owning process, and the
    first failure's run, file, time and FMU message.

    Picklable (the FMU travels as an :class:`~juno.parallel.FMUHandle`, the pool not at all),
    so SciPy can send it to worker processes for the finite-difference Jacobian.  In the
    process that made it, with a parallel ``pool``, one call evaluates the runs as parallel
    tasks; anywhere else it evaluates them one after the other with that process's FMU.
    ``evaluations`` counts the calls made in the owning process.
    """

    def __init__(self, fmu: JunoFMU, prepared: Sequence[PreparedRun], extra: dict[str, object] | None = None,
                 pool: TaskPool | None = None):
        self.handle = FMUHandle(fmu)
        self.prepared = list(prepared)
        self.extra = extra
        self.size = sum(len(v[0]) for p in self.prepared for v in p.targets.values())
        self.pool = pool
        self.log = EvaluationLog()
        self._failed_points: list[np.ndarray] = []

    @property
    def evaluations(self) -> int:
        return self.log.count

    def __getstate__(self):
        state = dict(self.__dict__)
        state["pool"] = None
        return state

    def __call__(self, x: np.ndarray) -> np.ndarray:
        soil = from_search(x)
        if self.handle.is_local and self.pool is not None and self.pool.parallel:
            jobs = [(self.handle, p, soil, self.extra) for p in self.prepared]
            outcomes = self.pool.map(_run_task, jobs)
        else:
            fmu = self.handle.get()
            outcomes = []
            for p in self.prepared:
                outcomes.append(_run_or_failure(fmu, p, soil, self.extra))
                if outcomes[-1][1] is not None:
                    break
        failure = next((f for _r, f in outcomes if f is not None), None)
        if self.handle.is_local:
            self.log.record(failure)
        if failure is not None:
            return np.full(self.size, FAILED_RESIDUAL)
        return np.concatenate([r for r, _f in outcomes])

    def map(self, fn: Callable[[np.ndarray], np.ndarray], points) -> list[np.ndarray]:
        """Map-like callable for SciPy's ``workers``: ``fn`` (SciPy's wrapper of this object)
        at each point, as parallel tasks when there is a parallel pool.  A point evaluated in
        a worker process is logged here; if it failed (FAILED_RESIDUAL everywhere), the point
        is kept, so that its failure can be named by simulating it here (failure_at)."""
        points = list(points)
        if self.pool is None or not self.pool.parallel:
            return list(map(fn, points))
        results = self.pool.map(fn, points)
        for x, r in zip(points, results):
            failed = bool(np.all(np.asarray(r) == FAILED_RESIDUAL))
            self.log.record(f"simulation failed in a worker process at {_soil_text(from_search(x))}"
                            if failed else None)
            if failed:
                self._failed_points.append(np.array(x, float))
        return results

    def first_failure(self) -> str | None:
        """The first failure's text; a failure seen only in a worker process is simulated
        again here (the model is deterministic) to name its run, time and FMU message."""
        if self._failed_points and self.log.first_failure is not None and \
                self.log.first_failure.startswith("simulation failed in a worker process"):
            soil = from_search(self._failed_points[0])
            fmu = self.handle.get()
            for p in self.prepared:
                _r, failure = _run_or_failure(fmu, p, soil, self.extra)
                if failure is not None:
                    return failure
        return self.log.first_failure


def _run_or_failure(fmu: JunoFMU, prepared: PreparedRun, soil: dict[str, float],
                    extra: dict[str, object] | None) -> tuple[np.ndarray | None, str | None]:
    """(scaled residuals, None) of one run, or (None, why it failed: run, file, time, FMU
    message) when its simulation fails or gives non-finite values."""
    try:
        r = run_residuals(fmu, prepared, soil, extra)
    except SimulationError as exc:
        return None, str(exc)
    if not np.all(np.isfinite(r)):
        where = f"run '{prepared.run_id}'" + (f" ({prepared.file})" if prepared.file else "")
        return None, f"{where}: the simulation gives non-finite values at {_soil_text(soil)}"
    return r, None


def _run_task(args) -> tuple[np.ndarray | None, str | None]:
    handle, prepared, soil, extra = args
    return _run_or_failure(handle.get(), prepared, soil, extra)


def identify_joint(fmu: JunoFMU, campaign: Campaign, run_ids: Sequence[str] | None = None,
                   include_terrain: bool = False, terrain_file: str | dict[str, str] | None = None,
                   initial: dict[str, float] | None = None, max_evaluations: int = 400,
                   extra: dict[str, object] | None = None, optimizer: str = "least-squares",
                   progress: Callable[[str], None] | None = None, workers: int | None = None,
                   scheduler: str | None = None) -> JointResult:
    """Joint identification over whole time series (see module docstring).

    ``optimizer``: "least-squares" (trust-region Gauss-Newton from the initial guess, about 50
    model evaluations) or "nelder-mead" (the paper's optimizer on the summed squares, then a
    Gauss-Newton polish; about 6 times slower, for checking that the optimum is not local).

    ``workers``: local processes (default: one per core; 1 = everything in this process with
    ``fmu``); ``scheduler``: a Dask scheduler address instead.  In parallel, each residual
    evaluation simulates its runs as parallel tasks and the finite-difference Jacobian's points
    (one per parameter) are evaluated as parallel tasks; the fit is identical to the serial one.

    ``terrain_file``: the gridded scan of each terrain run (run id -> file), or one file for
    all of them.  Raises InputError when the campaign lacks the runs the fit needs
    (require_runs), FitError when its simulations failed (EvaluationLog.check).
    """
    start = time.perf_counter()
    runs = [campaign.run(r) for r in run_ids] if run_ids else require_runs(campaign, "identify")
    if include_terrain:
        runs = runs + [r for r in require_runs(campaign, "identify --with-terrain") if r not in runs]
    if not runs:
        raise InputError("the joint fit was given no run", campaign.manifest_path)

    def grid_of(run: RunSpec) -> str | None:
        if isinstance(terrain_file, dict):
            return terrain_file.get(run.id)
        return terrain_file
    data = {r.id: read_run(campaign, r) for r in runs}
    prepared = [prepare_run(campaign, r, data[r.id], terrain_file=grid_of(r) if r.kind == "terrain" else None)
                for r in runs]
    if optimizer not in ("least-squares", "nelder-mead"):
        raise ValueError(f"unknown optimizer '{optimizer}' (least-squares or nelder-mead)")
    # Tasks per batch: the runs of one evaluation, or the Jacobian's four points.
    n_workers = resolve_workers(workers, max(len(prepared), 4)) if not scheduler else None
    # The fit's own linear algebra is on (residuals x 4) matrices, 17845 x 4 for the benchmark
    # campaign: BLAS threads gain nothing there, and OpenBLAS's spinning between calls took
    # 1.7-2.3 s of CPU per fit (measured) from the cores the simulations need.  One BLAS thread
    # during the fit, serial or parallel alike.
    with TaskPool(n_workers, scheduler) as pool, threadpool_limits(limits=1, user_api="blas"):
        fun = JointResiduals(fmu, prepared, extra, pool)
        result, at_optimum = _fit_joint(fun, runs, prepared, initial, max_evaluations, optimizer, progress, start)
        result.doubts, result.structure = fit_doubts(fmu, campaign, prepared, result, extra, residuals=at_optimum,
                                                     data=data, pool=pool)
    result.wall_time = time.perf_counter() - start
    return result


#: A fitted parameter closer than this to a bound of the search (SOIL_SEARCH_BOUNDS), in the
#: search space (log or logit: about 1 % of the value), sits at the bound: the data pushed it as
#: far as the search allows, which a model that describes the data does not need.
AT_LIMIT = 0.01


@dataclass(frozen=True)
class SearchBound:
    """A soil parameter of a fit that sits at a bound of the search: its name, its value, which
    bound ("lower" or "upper") and that bound's value (the parameter's units)."""
    name: str
    value: float
    side: str
    bound: float


def soil_at_search_bounds(params: Mapping[str, float]) -> list[SearchBound]:
    """The soil parameters of ``params`` that sit at a bound of the search (SOIL_SEARCH_BOUNDS),
    within AT_LIMIT in the search's log or logit space.  Why a bound means doubt: the bounds lie
    wide of any soil the paper or the terramechanics literature reports, so a fit that ends at
    one is a model the data push beyond any real soil."""
    x = to_search(params)
    found = []
    for i, name in enumerate(SOIL_PARAMETERS):
        for bound, side in ((SOIL_SEARCH_BOUNDS[0][i], "lower"), (SOIL_SEARCH_BOUNDS[1][i], "upper")):
            if abs(x[i] - bound) < AT_LIMIT:
                at_bound = from_search(np.where(np.arange(len(SOIL_PARAMETERS)) == i, bound, x))[name]
                found.append(SearchBound(name, float(params[name]), side, float(at_bound)))
    return found


def fit_doubts(fmu: JunoFMU, campaign: Campaign, prepared: Sequence[PreparedRun], result: JointResult,
               extra: dict[str, object] | None = None, residuals: np.ndarray | None = None,
               workers: int | None = 1, data: dict[str, RunData] | None = None, pool: TaskPool | None = None
               ) -> tuple[list[str], dict | None]:
    """Why a joint fit's estimates are doubtful, in words, and the structure test behind it:
    each parameter at a bound of the search (AT_LIMIT); and structure beyond sensor noise in the
    fitted model's residuals on the drawbar runs (juno.residual_structure, every 4 s block
    tested): a model that does not describe the data bends its parameters to absorb what it
    cannot describe, so their uncertainty understates how wrong they are.

    ``residuals``: the fit's scaled residuals at ``result.params`` over ``prepared``, when the
    caller has them (the model is deterministic: simulating them again gives the same numbers);
    ``workers``: local processes for the structure test's replays (1: this process), or
    ``pool``: the open pool to run them on; ``data``: the measured runs (run id -> RunData),
    when already read."""
    from .residual_structure import residual_labels, residual_structure
    doubts = [f"{b.name} = {b.value:.4g} is at the {b.side} bound of the search ({b.bound:.3g}): "
              "the data push it as far as the fit allows" for b in soil_at_search_bounds(result.params)]
    meta = residual_labels(prepared, STRUCTURE_BLOCK)
    t = meta["time"]
    try:
        r = residuals if residuals is not None else \
            np.concatenate([run_residuals(fmu, p, result.params, extra) for p in prepared])
        test = residual_structure(campaign, fmu, prepared, meta, np.zeros(len(t), bool), r,
                                  {**result.params, **(extra or {})}, workers=workers, data=data, pool=pool)
    except SimulationError as exc:
        # The fit stands (its own simulations succeeded); what cannot be said is whether it
        # leaves structure, and that is said.
        doubts.append(f"the residuals could not be tested for structure beyond sensor noise: {exc}")
        return doubts, None
    if test.significant:
        doubts.append("the fitted model leaves structure beyond sensor noise in its residuals ("
                      + "; ".join([f"{s.signal}: {s.ratio:.2g} x its noise" + (f", following {s.follows[0].name}"
                                                                                  if s.follows else "")
                                   for s in test.structured()] + [r.sentence() for r in test.ripples()])
                      + "): the model does not describe these data, and its parameters absorb what it misses")
    return doubts, (test.to_json() if test.signals else None)


#: Blocks (s) of the fit-quality structure test: the diagnosis's.
STRUCTURE_BLOCK = 4.0


def _fit_joint(fun: JointResiduals, runs: list[RunSpec], prepared: list[PreparedRun],
               initial: dict[str, float] | None, max_evaluations: int, optimizer: str,
               progress: Callable[[str], None] | None, start: float) -> tuple[JointResult, np.ndarray]:
    """The joint fit, and its scaled residuals at the optimum."""
    def cost(x: np.ndarray) -> float:
        r = fun(x)
        value = float(np.mean(r * r))
        if progress and fun.evaluations % 25 == 0:
            progress(f"joint fit: {fun.evaluations} evaluations, cost {value:.4g}")
        return value

    x0 = to_search(initial or PAPER_INITIAL)
    if optimizer == "nelder-mead":
        nm = minimize(cost, x0, method="Nelder-Mead",
                      options={"xatol": 1e-3, "fatol": 1e-9, "maxfev": max_evaluations,
                               "initial_simplex": x0 + np.vstack([np.zeros(4), 0.3 * np.eye(4)])})
        x0, f0 = nm.x, nm.fun
    else:
        f0 = np.inf
    # Trust-region Gauss-Newton on the scaled residuals (from the Nelder-Mead point if any);
    # the Jacobian by forward differences, its four points evaluated through fun.map.
    lo, hi = SOIL_SEARCH_BOUNDS
    x0 = np.clip(x0, lo + 1e-9, hi - 1e-9)
    ls = least_squares(fun, x0, method="trf", x_scale=1.0, diff_step=1e-4, max_nfev=80, bounds=(lo, hi),
                       xtol=1e-8, ftol=1e-10, workers=fun.map)
    x_best = ls.x if np.mean(ls.fun**2) <= f0 else x0
    params = from_search(x_best)
    J = ls.jac
    # ls.fun holds the residuals at ls.x (the model is deterministic): no need to simulate again.
    r = np.array(ls.fun, float) if x_best is ls.x else fun(x_best)
    optimum_failed = bool(np.all(r == FAILED_RESIDUAL))
    if optimum_failed or fun.log.failed_fraction > MAX_FAILED_FRACTION:
        fun.log.first_failure = fun.first_failure()
    fun.log.check("joint fit of " + ", ".join(f"'{r_.id}'" for r_ in runs), optimum_failed)
    dof = max(len(r) - 4, 1)
    # Residuals are correlated in time (model mismatch, smoothing), so the
    # white-noise covariance is too optimistic: inflate the variance by the
    # effective-sample-size factor (1 + rho) / (1 - rho) of each signal's
    # lag-1 autocorrelation rho, averaged with the signals' weights.
    inflation = correlation_inflation(r, [len(v[0]) for p in prepared for v in p.targets.values()])
    s2 = float(np.sum(r * r) / dof) * inflation
    sv = np.linalg.svd(J, compute_uv=False)
    try:
        cov_search = s2 * np.linalg.pinv(J.T @ J)
    except np.linalg.LinAlgError:
        cov_search = np.full((4, 4), np.inf)
    T = _jacobian_of_transform(params)
    cov = T @ cov_search @ T
    std = np.sqrt(np.maximum(np.diag(cov), 0))
    # A parameter the residuals do not depend on (its Jacobian column is zero), or every
    # parameter of a fit that never left its start, is not identified: the pseudo-inverse gives
    # it zero variance, which would read as perfectly pinned.
    moved = bool(np.any(x_best != to_search(initial or PAPER_INITIAL)))
    seen = _seen_columns(J) & moved
    std = np.where(seen, std, np.inf)
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(std, std)
    rel = {k: float(std[i] / abs(params[k])) for i, k in enumerate(SOIL_PARAMETERS)}
    return JointResult(params=params, std=dict(zip(SOIL_PARAMETERS, std.tolist())), relative_std=rel,
                       correlation=corr, identifiability={k: classify(v) for k, v in rel.items()},
                       cost=float(np.mean(r * r)), evaluations=fun.evaluations,
                       wall_time=time.perf_counter() - start, runs=[r_.id for r_ in runs],
                       singular_values=sv.tolist(), inflation=inflation,
                       status="ok" if np.all(seen) else "not identified", failed_evaluations=fun.log.failed), r


def _seen_columns(J: np.ndarray) -> np.ndarray:
    """Which parameters the residuals depend on: Jacobian columns whose norm exceeds ZERO_COLUMN
    times the largest column's (none if the Jacobian is zero or not finite)."""
    norms = np.linalg.norm(np.asarray(J, float), axis=0)
    if not np.all(np.isfinite(norms)) or norms.max(initial=0.0) <= 0:
        return np.zeros(J.shape[1], bool)
    return norms > ZERO_COLUMN * norms.max()


# ---------------------------------------------------------- multi-start fit

@dataclass
class MultiStartResult:
    """Joint fits from several starting points; ``best`` has the lowest cost (first on a tie)
    among the fits that did not fail.  A start whose fit failed (FitError) is in ``fits`` with
    ``status`` "failed", its start as ``params``, an infinite cost and no uncertainty."""

    best: JointResult
    fits: list[JointResult]
    starts: list[dict[str, float]]
    wall_time: float

    @property
    def spread(self) -> dict[str, float]:
        """Largest relative distance of any converged fit's estimate from the best one, per
        parameter: near zero when every start found the same optimum."""
        ok = [f for f in self.fits if np.isfinite(f.cost) and f.cost <= 1.01 * self.best.cost]
        return {k: float(max(abs(f.params[k] / self.best.params[k] - 1) for f in ok)) for k in SOIL_PARAMETERS}


def multistart_points(n: int, initial: dict[str, float] | None = None, spread: float = 0.5,
                      seed: int = 0) -> list[dict[str, float]]:
    """``n`` starting points: ``initial`` (the paper's guess by default), then ``n - 1`` points
    scattered around it in the search space (log / logit), normal with ``spread`` (a factor of
    about e^0.5 = 1.6 in each positive parameter), from a seeded generator (reproducible)."""
    if n < 1:
        raise ValueError(f"the number of starts must be at least 1, got {n}")
    x0 = to_search(initial or PAPER_INITIAL)
    rng = np.random.default_rng(seed)
    points = [from_search(x0)] + [from_search(x0 + rng.normal(0.0, spread, size=4)) for _ in range(n - 1)]
    return points


def _joint_task(args) -> JointResult | FitError:
    """One start's joint fit; a FitError is returned (see _paper_task)."""
    handle, campaign, start, kwargs = args
    try:
        return identify_joint(handle.get(), campaign, initial=start, workers=1, **kwargs)
    except FitError as exc:
        return exc


def _failed_start(start: dict[str, float], error: FitError) -> JointResult:
    """The entry of a start whose fit failed: its start, no cost, no uncertainty."""
    none = {k: float("inf") for k in SOIL_PARAMETERS}
    return JointResult(params=dict(start), std=dict(none), relative_std=dict(none),
                       correlation=np.full((4, 4), np.nan), identifiability={k: "not identified" for k in none},
                       cost=float("inf"), evaluations=error.evaluations, wall_time=0.0,
                       status="failed", failed_evaluations=error.failed)


def identify_multistart(fmu: JunoFMU, campaign: Campaign, starts: int | Sequence[dict[str, float]] = 4,
                        seed: int = 0, spread: float = 0.5, workers: int | None = None,
                        scheduler: str | None = None, progress: Callable[[str], None] | None = None,
                        **joint_kwargs) -> MultiStartResult:
    """:func:`identify_joint` from several starting points (``starts``: a number of points from
    :func:`multistart_points`, or the points themselves), one fit per parallel task (each fit
    serial inside its task).  Checks that the optimum is not a local one."""
    t0 = time.perf_counter()
    points = multistart_points(starts, seed=seed, spread=spread) if isinstance(starts, int) else \
        [dict(p) for p in starts]
    handle = FMUHandle(fmu)
    jobs = [(handle, campaign, p, joint_kwargs) for p in points]

    def done(i: int, j: JointResult | FitError) -> None:
        if progress:
            progress(f"start {i + 1}/{len(jobs)}: " + (f"failed: {j}" if isinstance(j, FitError) else
                                                      f"cost {j.cost:.4g} after {j.evaluations} evaluations"))
    outcomes = map_tasks(_joint_task, jobs, workers=workers, scheduler=scheduler, on_result=done)
    if all(isinstance(o, FitError) for o in outcomes):
        raise outcomes[0]
    fits = [_failed_start(p, o) if isinstance(o, FitError) else o for p, o in zip(points, outcomes)]
    costs = [f.cost if np.isfinite(f.cost) and f.status != "failed" else np.inf for f in fits]
    best = fits[int(np.argmin(costs))]
    return MultiStartResult(best, fits, points, time.perf_counter() - t0)
