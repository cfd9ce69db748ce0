"""The joint fit: every drawbar run's whole time series at once, a trust-region fit of the
scaled residuals with the covariance and identifiability of its estimates
(:func:`identify_joint`), and why a fit is doubtful (:func:`fit_doubts`)."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np
from scipy.optimize import least_squares, minimize
from threadpoolctl import threadpool_limits

from ..campaign import Campaign, RunData, RunSpec, read_run
from ..errors import InputError
from ..imu_mounting import MountedResiduals, mounted_residuals, mounting_offsets, without_offsets
from ..parallel import FMUHandle, TaskPool, resolve_workers
from ..rover_model import SOIL_PARAMETERS
from ..simulator import JunoFMU, SimulationError
from .base import (FAILED_RESIDUAL, MAX_FAILED_FRACTION, PAPER_INITIAL, SOIL_SEARCH_BOUNDS, ZERO_COLUMN,
                   EvaluationLog, _jacobian_of_transform, from_search, require_runs, soil_at_search_bounds, to_search)
from .paper import _soil_text
from .replay import PreparedRun, prepare_run, run_residuals
from .replay_bias import ReplayBias, replay_bias


@dataclass
class JointResult:
    """A joint identification with uncertainty and identifiability.

    ``std`` is the total 1 sigma: the statistical part (``std_statistical``, the sensors' noise
    through the Jacobian) and the systematic part (``std_systematic``, the size of the replay's
    own bias ``replay_bias`` measured by a parametric bootstrap at the fit, juno.identify.replay_bias)
    added in quadrature, so that it is the root mean square error of the estimate;
    ``relative_std``, ``identifiability`` and ``correlation`` are the total's.  Where the bias
    was not estimated (``replay_bias`` empty: not asked for, its simulations failed or its refit
    did not converge, which a doubt says), ``std`` is the statistical part alone.  ``bias_refit``: the bootstrap's refit
    (its status, evaluations, seconds), None without one.

    ``status``: "ok", EVALUATION_LIMIT when the search used its budget (``max_evaluations``)
    without meeting a convergence test, or "not identified" when the fit did not move from its start or the data
    does not see some parameter (a zero Jacobian column); such a parameter has an infinite
    ``std`` (null in JSON) and the identifiability "not identified".  "not converged": where the
    fit stopped, the residuals are not differentiable in ``rough_parameters`` (a Jacobian from a
    step JACOBIAN_CHECK_STEP does not reproduce the fit's), so the search did not converge and
    no parameter has an uncertainty (every ``std`` infinite).  A fit whose simulations
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
    #: Parameters in which the residuals are not differentiable where the fit stopped (status
    #: "not converged"): their Jacobian columns at two steps disagree.
    rough_parameters: list[str] = field(default_factory=list)
    #: The 1 sigma of the sensors' noise alone (the Jacobian's covariance); ``std`` adds the
    #: replay's bias to it.
    std_statistical: dict[str, float] = field(default_factory=dict)
    #: The size of the replay's own bias, |replay_bias| (empty where not estimated).
    std_systematic: dict[str, float] = field(default_factory=dict)
    #: The bootstrap's refit of noise-free synthetic runs at the fitted soil minus the fitted
    #: soil: what the replay does to a soil it should recover (empty where not estimated).
    replay_bias: dict[str, float] = field(default_factory=dict)
    bias_refit: dict | None = None
    #: The constant the fitted model's pitch residuals hold on each IMU mounting (mounting -> rad,
    #: measured - simulated; juno.imu_mounting): the IMU's mounting offset, a free parameter of
    #: the fit unless the campaign's mounting is calibrated (``pitch_offset_free``); empty
    #: without a measured pitch.
    pitch_offset: dict[str, float] = field(default_factory=dict)
    pitch_offset_free: bool = True


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

    ``mounted``: the pitch's residuals on each IMU mounting (juno.imu_mounting); with
    ``offset_free`` each mounting's offset is profiled out of the residuals (a free parameter of
    the fit, so that no soil is bent to pitch the rover by a mounting bias), and the offsets the
    owning process's evaluations held are kept for :meth:`offsets_at`.
    """

    def __init__(self, fmu: JunoFMU, prepared: Sequence[PreparedRun], extra: dict[str, object] | None = None,
                 pool: TaskPool | None = None, mounted: Sequence[MountedResiduals] = (), offset_free: bool = False):
        self.handle = FMUHandle(fmu)
        self.prepared = list(prepared)
        self.extra = extra
        self.size = sum(len(v[0]) for p in self.prepared for v in p.targets.values())
        self.pool = pool
        self.log = EvaluationLog()
        self._failed_points: list[np.ndarray] = []
        self.mounted = list(mounted)
        self.offset_free = offset_free
        self._offsets: dict[bytes, dict[str, dict[str, float]]] = {}

    @classmethod
    def for_campaign(cls, fmu: JunoFMU, campaign: Campaign, runs: Sequence[RunSpec],
                     prepared: Sequence[PreparedRun], extra: dict[str, object] | None = None,
                     pool: TaskPool | None = None) -> "JointResiduals":
        """The residuals of the ``prepared`` replays of ``runs`` (in the same order) as the
        ``campaign`` states its IMU: each run on its mounting (RunSpec.imu_mount), every mounting's
        pitch offset free unless the manifest says the mounting is calibrated."""
        mounts = {r.id: r.imu_mount for r in runs}
        return cls(fmu, prepared, extra, pool, mounted_residuals(prepared, mounts),
                   offset_free=campaign.imu_mounting != "calibrated")

    @property
    def evaluations(self) -> int:
        return self.log.count

    def __getstate__(self):
        state = dict(self.__dict__)
        state["pool"] = None
        state["_offsets"] = {}
        return state

    def offsets_at(self, x: np.ndarray) -> dict[str, dict[str, float]]:
        """The offsets (signal -> mounting -> the signal's units) that the residuals at the search
        point ``x`` hold before any is taken off; ``x`` is evaluated here unless this process
        evaluated it already."""
        key = np.asarray(x, float).tobytes()
        if key not in self._offsets:
            self(np.asarray(x, float))
        return self._offsets.get(key, {})

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
        r = np.concatenate([r for r, _f in outcomes])
        if self.mounted:
            if self.handle.is_local:
                self._offsets[np.asarray(x, float).tobytes()] = mounting_offsets(self.mounted, r)
            if self.offset_free:
                r = without_offsets(self.mounted, r)
        return r

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
                   scheduler: str | None = None, estimate_bias: bool | None = None) -> JointResult:
    """Joint identification over whole time series (see module docstring).

    ``optimizer``: "least-squares" (trust-region Gauss-Newton from the initial guess, about 50
    model evaluations) or "nelder-mead" (the paper's optimizer on the summed squares, then a
    Gauss-Newton polish; about 6 times slower, for checking that the optimum is not local).

    ``workers``: local processes (default: one per core; 1 = everything in this process with
    ``fmu``); ``scheduler``: a Dask scheduler address instead.  In parallel, each residual
    evaluation simulates its runs as parallel tasks and the finite-difference Jacobian's points
    (one per parameter) are evaluated as parallel tasks; the fit is identical to the serial one.

    ``estimate_bias``: estimate the replay's own bias by a parametric bootstrap at the fitted soil (one
    more fit, of noise-free synthetic runs; juno.identify.replay_bias) and state it as the
    systematic part of each uncertainty (JointResult); a fit that states no uncertainty
    (status "not converged") gets none.  None (the default): when a fitted run lacks an
    optional column its kind uses (juno.campaign.missing_columns: no pitch, no yaw), where the
    bias is up to several of the noise's sigmas; a campaign with every column gets none
    (lacks_optional_columns says why).

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
        fun = JointResiduals.for_campaign(fmu, campaign, runs, prepared, extra, pool)
        result, at_optimum = _fit_joint(fun, runs, prepared, initial, max_evaluations, optimizer, progress, start)
        result.doubts, result.structure = fit_doubts(fmu, campaign, prepared, result, extra, residuals=at_optimum,
                                                     data=data, pool=pool)
        result.std_statistical = dict(result.std)
        if estimate_bias is None:
            estimate_bias = lacks_optional_columns(campaign, runs)
        if estimate_bias and result.status != "not converged":
            if progress:
                progress("the replay's own bias: a refit of the runs simulated with the fitted soil")
            terrain_files = {r.id: grid_of(r) for r in runs if r.kind == "terrain"}
            try:
                refit = replay_bias(fmu, campaign, runs, data, prepared, result.params, initial, max_evaluations,
                                    optimizer, extra, terrain_files, pool)
            except (SimulationError, ValueError) as exc:
                result.doubts.append(f"the replay's own bias could not be estimated ({exc}): the uncertainty is "
                                     "the sensors' noise alone, and the replay's error, which it leaves out, "
                                     "moves the estimates by up to several of it where a campaign lacks a signal")
            else:
                _add_replay_bias(result, refit)
    result.wall_time = time.perf_counter() - start
    return result


def lacks_optional_columns(campaign: Campaign, runs: Sequence[RunSpec]) -> bool:
    """True when one of ``runs`` lacks an optional column its kind uses (missing_columns): where
    identify_joint estimates the replay's bias by default.  Why only there: the bootstrap costs
    one more fit, 0.5-1.3 of the fit's time (median 0.8 over the fits of
    scripts/uncertainty_coverage.py), which would take the benchmark's joint fit (three
    full-length drawbar runs, every column) past its 5 s target; with every column the bias is small beside the noise's part (median 0.3
    of its sigma over those fits), while without pitch it is most of the error (median 0.8, up
    to 3.7).  docs/results/uncertainty-coverage.md has the figures."""
    from ..campaign import missing_columns
    fitted = {r.id for r in runs}
    return any(fitted & set(m.runs) for m in missing_columns(campaign, tuple({r.kind for r in runs})))


def _add_replay_bias(result: JointResult, refit: ReplayBias) -> None:
    """States the bootstrap's bias as the systematic part of ``result``'s uncertainty: the total
    covariance is the statistical one plus b b^T (b the bias), the mean square error of an
    estimate off by b, whose diagonal is std_statistical^2 + bias^2; relative uncertainties,
    identifiability and correlations follow the total.  A refit that did not converge (its
    residuals not differentiable where it stopped) or did not identify the soil (it did not move,
    or the data does not see a parameter) estimates no bias: its point is not an estimate of the
    synthetic world's soil, so its offset is no bias.  The result then states none, and a doubt
    says why; a refit stopped at its evaluation limit is stated with a doubt."""
    result.bias_refit = {"status": refit.status, "evaluations": refit.evaluations, "wall_time": refit.wall_time}
    if refit.status in NO_BIAS_FROM_REFIT:
        result.doubts.append(f"the replay's own bias could not be estimated (its refit ended '{refit.status}'): "
                             "the uncertainty is the sensors' noise alone, and the replay's error, which it leaves "
                             "out, moves the estimates by up to several of it where a campaign lacks a signal")
        return
    names = list(SOIL_PARAMETERS)
    b = np.array([refit.params[k] - result.params[k] for k in names])
    stat = np.array([result.std_statistical[k] for k in names])
    with np.errstate(invalid="ignore"):
        cov = np.asarray(result.correlation, float) * np.outer(stat, stat) + np.outer(b, b)
        std = np.where(np.isfinite(stat), np.hypot(stat, b), np.inf)
        corr = cov / np.outer(std, std)
    result.replay_bias = dict(zip(names, b.tolist()))
    result.std_systematic = dict(zip(names, np.abs(b).tolist()))
    result.std = dict(zip(names, std.tolist()))
    result.correlation = corr
    result.relative_std = {k: float(std[i] / abs(result.params[k])) for i, k in enumerate(names)}
    result.identifiability = {k: classify(v) for k, v in result.relative_std.items()}
    if refit.status != "ok":
        result.doubts.append(f"the refit that estimates the replay's own bias ended '{refit.status}': the "
                             "systematic part of the uncertainty is where that refit stopped, not a converged "
                             "estimate")


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
    from ..residual_structure import residual_labels, residual_structure
    doubts = [f"{b.name} = {b.value:.4g} is at the {b.side} bound of the search ({b.bound:.3g}): "
              "the data push it as far as the fit allows" for b in soil_at_search_bounds(result.params)]
    if result.rough_parameters:
        doubts.append(f"the residuals are not differentiable in {', '.join(result.rough_parameters)} where the "
                      f"fit stopped (its Jacobian is not reproduced by a step {JACOBIAN_CHECK_STEP / JACOBIAN_STEP:.0f} "
                      "times larger: the replays jump there), so the search stopped without converging and the "
                      "values are not an estimate; no uncertainty is stated")
    if result.status == EVALUATION_LIMIT:
        doubts.append(f"the search stopped at its limit of {result.evaluations} evaluations without meeting its "
                      "convergence tests: the values are where it stopped, not the optimum, and their uncertainty "
                      "is the curvature there (--max-evaluations raises the limit)")
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
        doubts.append(f"the fitted model leaves structure beyond sensor noise in its residuals "
                      f"({'; '.join(test.findings())}): the model does not describe these data, and its "
                      "parameters absorb what it misses")
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
    # The budget counts model evaluations as Nelder-Mead's does: each iteration's residuals and
    # its Jacobian's four points (least_squares' max_nfev counts the residuals alone).
    ls = least_squares(fun, x0, method="trf", x_scale=1.0, diff_step=JACOBIAN_STEP,
                       max_nfev=max(1, max_evaluations // (1 + len(x0))), bounds=(lo, hi),
                       xtol=1e-8, ftol=1e-10, workers=fun.map)
    x_best = ls.x if np.mean(ls.fun**2) <= f0 else x0
    params = from_search(x_best)
    J = ls.jac if x_best is ls.x else None
    # ls.fun holds the residuals at ls.x (the model is deterministic): no need to simulate again.
    r = np.array(ls.fun, float) if x_best is ls.x else fun(x_best)
    pitch_offset = fun.offsets_at(x_best).get("pitch", {}) if fun.mounted else {}
    optimum_failed = bool(np.all(r == FAILED_RESIDUAL))
    if not optimum_failed:
        if J is None:
            J = _forward_jacobian(fun, x_best, r, JACOBIAN_STEP)
        check = _forward_jacobian(fun, x_best, r, JACOBIAN_CHECK_STEP)
        rough = _rough_columns(J, check)
        if rough.any():
            # SciPy's Jacobian holds a failed simulation's made-up residuals where a point of its
            # stencil failed: a column is recomputed (a failed point taken on the other side)
            # before its disagreement with the check is called roughness.
            J = np.array(J, float)
            again = np.flatnonzero(rough)
            J[:, again] = _forward_jacobian(fun, x_best, r, JACOBIAN_STEP, only=again)[:, again]
            rough = _rough_columns(J, check)
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
    # Where the residuals are not differentiable at the Jacobian's step, the Jacobian is not a
    # derivative: the trust region, whose steps it predicts, shrinks until the search stops
    # where it happens to be, and its covariance reads noise as information.  Neither the point
    # nor an uncertainty is an estimate there: every parameter is left without one.
    if rough.any():
        std = np.full(4, np.inf)
    # A search that used its whole budget without meeting a convergence test (least_squares'
    # status 0) stopped where it was: the values are not the optimum, as a paper-style fit that
    # reaches its evaluation limit is not converged; the uncertainty is the curvature there.
    at_limit = bool(x_best is ls.x and ls.status == 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(std, std)
    rel = {k: float(std[i] / abs(params[k])) for i, k in enumerate(SOIL_PARAMETERS)}
    return JointResult(params=params, std=dict(zip(SOIL_PARAMETERS, std.tolist())), relative_std=rel,
                       correlation=corr, identifiability={k: classify(v) for k, v in rel.items()},
                       cost=float(np.mean(r * r)), evaluations=fun.evaluations,
                       wall_time=time.perf_counter() - start, runs=[r_.id for r_ in runs],
                       singular_values=sv.tolist(), inflation=inflation,
                       status=("not converged" if rough.any() else "not identified" if not np.all(seen)
                               else EVALUATION_LIMIT if at_limit else "ok"),
                       failed_evaluations=fun.log.failed, rough_parameters=[k for k, bad in
                                                                             zip(SOIL_PARAMETERS, rough) if bad],
                       pitch_offset=pitch_offset, pitch_offset_free=fun.offset_free), r


#: The status of a joint fit that used its whole budget of evaluations without converging.
EVALUATION_LIMIT = "stopped at the evaluation limit"
#: The statuses of a bias refit (replay_bias) whose point is no estimate, so that no bias is
#: stated from it (_add_replay_bias).
NO_BIAS_FROM_REFIT = ("not converged", "not identified")
#: Relative step of the fit's forward-difference Jacobian in the search space (log, logit).
JACOBIAN_STEP = 1e-4
#: The step of the second Jacobian that checks the first, ten times larger: where the residuals
#: are differentiable the two agree to within the curvature over the larger step; where the
#: replay jumps (a spin tracker swinging between its torque limits starts or stops) each
#: difference is a jump divided by its own step, and they disagree by about the step ratio.
JACOBIAN_CHECK_STEP = 1e-3
#: A Jacobian column that the check's column does not reproduce within this fraction (the norm
#: of their difference over the larger norm) is not a derivative.
JACOBIAN_AGREEMENT = 0.25


def _forward_jacobian(fun: JointResiduals, x: np.ndarray, r: np.ndarray, step: float,
                      only: Sequence[int] | None = None) -> np.ndarray:
    """Forward-difference Jacobian of ``fun`` at ``x`` (residuals ``r``) with relative step
    ``step``, as least_squares takes it (h = step max(1, |x|)), its points through fun.map; with
    ``only``, those columns alone (the others non-finite).  A
    point whose simulation fails is taken again on the other side of ``x`` (a backward
    difference, inside the search): a failed simulation says nothing of whether the residuals are
    differentiable, which the check of another step (_rough_columns) judges.  A column whose
    points fail on both sides is non-finite."""
    h = step * np.maximum(1.0, np.abs(x))
    lo, hi = SOIL_SEARCH_BOUNDS
    h = np.where(x + h > hi, -h, h)       # stay inside the search, as SciPy does
    unit = np.eye(len(x))
    wanted = list(range(len(x))) if only is None else list(only)
    values = {i: np.asarray(ri, float) for i, ri in zip(wanted, fun.map(fun, [x + h[i] * unit[i] for i in wanted]))}
    failed = [i for i, ri in values.items() if np.all(ri == FAILED_RESIDUAL)]
    back = [i for i in failed if lo[i] < x[i] - h[i] < hi[i]]
    for i, ri in zip(back, fun.map(fun, [x - h[i] * unit[i] for i in back])):
        values[i], h[i] = np.asarray(ri, float), -h[i]
    columns = [np.full(len(r), np.nan) if i not in values or np.all(values[i] == FAILED_RESIDUAL)
               else (values[i] - r) / h[i] for i in range(len(x))]
    return np.column_stack(columns)


def _rough_columns(J: np.ndarray, check: np.ndarray) -> np.ndarray:
    """Which parameters' Jacobian columns the check Jacobian (another step) does not reproduce
    within JACOBIAN_AGREEMENT: the residuals are not differentiable in them at this point."""
    J, check = np.asarray(J, float), np.asarray(check, float)
    diff = np.linalg.norm(J - check, axis=0)
    scale = np.maximum(np.linalg.norm(J, axis=0), np.linalg.norm(check, axis=0))
    with np.errstate(invalid="ignore", divide="ignore"):
        rough = ~(diff <= JACOBIAN_AGREEMENT * scale)
    # A column zero at both steps is the same derivative (zero): _seen_columns deals with it.
    return rough & ~((scale == 0) & np.isfinite(diff))


def _seen_columns(J: np.ndarray) -> np.ndarray:
    """Which parameters the residuals depend on: Jacobian columns whose norm exceeds ZERO_COLUMN
    times the largest column's (none if the Jacobian is zero or not finite)."""
    norms = np.linalg.norm(np.asarray(J, float), axis=0)
    if not np.all(np.isfinite(norms)) or norms.max(initial=0.0) <= 0:
        return np.zeros(J.shape[1], bool)
    return norms > ZERO_COLUMN * norms.max()
