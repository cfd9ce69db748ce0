"""Joint fits from several starting points, in parallel (:func:`identify_multistart`)."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from ..campaign import Campaign
from ..parallel import FMUHandle, map_tasks
from ..rover_model import SOIL_PARAMETERS
from ..simulator import JunoFMU
from .base import PAPER_INITIAL, FitError, from_search, to_search
from .joint import JointResult, identify_joint


@dataclass
class MultiStartResult:
    """Joint fits from several starting points; ``best`` has the lowest cost (first on a tie)
    among the fits that did not fail and converged (status not "not converged"; the first start
    when none did).  A start whose fit failed (FitError) is in ``fits`` with
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
    # A start that failed, or stopped where the residuals are not differentiable ("not
    # converged"), is no estimate to keep: the best is among the others when there are any.
    costs = [f.cost if np.isfinite(f.cost) and f.status not in ("failed", "not converged") else np.inf
             for f in fits]
    best = fits[int(np.argmin(costs))]
    return MultiStartResult(best, fits, points, time.perf_counter() - t0)
