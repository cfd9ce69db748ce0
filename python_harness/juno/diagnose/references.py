"""What a candidate is judged against: the reference model (best_reference), and a registration
moved onto the reference's soil (on_reference_soil).  These replay models, so they need the FMU."""

from __future__ import annotations

from typing import Sequence

import numpy as np

from ..simulator import SOIL_PARAMETERS, JunoFMU
from .candidates import CANDIDATES
from .fitting import FitResult, fit_objective, replayed
from .problem import Problem, all_residuals


def best_reference(problem: Problem, run_kind: np.ndarray, reference: FitResult,
                   fits: Sequence[FitResult], name: str) -> tuple[FitResult, dict[str, FitResult]]:
    """The reference a candidate must beat: ``reference``, or a candidate's fit with that
    candidate's extension switched off (named ``name``), whichever has the lower training
    objective (fit_objective).

    Why: a candidate's fit also refits the soil (and, in the second round, the first cause)
    from other starting points.  When that alone explains the data better, the gain belongs to
    the better soil, not to the extension: a soil patch of 2 % contrast "on top" of a multi-pass
    fit can gain a quarter of the held-out error merely because its short fits converged the
    soil further, and against the fit with the patch switched off that gain is gone.
    Costs one replay of every run per candidate.  Returns the reference and, by candidate name,
    each candidate's fit with its extension switched off (for judging.judge's ablation)."""
    best, best_cost = reference, fit_objective(problem, run_kind, reference)
    switched_off: dict[str, FitResult] = {}
    fmu = JunoFMU(problem.fmu_path)
    try:
        for res in fits:
            if res.error or not res.params:
                continue
            params = CANDIDATES[res.name].switched_off(res.params)
            r = all_residuals(fmu, problem, params)
            if not np.all(np.isfinite(r)):
                continue
            stripped = replayed(problem, name, params, r)
            switched_off[res.name] = stripped
            cost = fit_objective(problem, run_kind, stripped)
            if cost < best_cost:
                best, best_cost = stripped, cost
    finally:
        fmu.close()
    return best, switched_off


def on_reference_soil(problem: Problem, run_kind: np.ndarray, reference: FitResult, res: FitResult) -> FitResult:
    """A registration-only candidate (terrain_offset: no physical parameter, the soil held at the
    base optimum) moved onto ``reference``'s soil, when best_reference chose a better one; its
    offsets are kept (they are measured kinematically, starts.registration_evidence).  Any other
    fit is returned as it is.

    Why: the other candidates refit the soil, and when one of their fits with its extension
    switched off becomes the reference, a registration judged on the base soil is charged for
    the soil it was not allowed to change: the drawbar runs, which a registration cannot
    change, then count against it."""
    candidate = CANDIDATES.get(res.name)
    if (res.error or candidate is None or not candidate.is_registration
            or all(res.params[k] == reference.params[k] for k in SOIL_PARAMETERS)):
        return res
    params = {**res.params, **{k: reference.params[k] for k in SOIL_PARAMETERS}}
    fmu = JunoFMU(problem.fmu_path)
    try:
        r = all_residuals(fmu, problem, params)
    finally:
        fmu.close()
    if not np.all(np.isfinite(r)):      # the replay failed on that soil: the scan as it is
        params, r = candidate.switched_off(params), reference.residuals.copy()
    return replayed(problem, res.name, params, r, res.evaluations + 1, res.wall_time, res.failed_evaluations)
