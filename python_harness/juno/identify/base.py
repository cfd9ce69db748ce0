"""What every fit of the soil shares: its constants (the paper's initial guess, the fixed
integration step, the failure stand-ins), failures (:class:`FitError`, :class:`EvaluationLog`),
the runs a step needs, the search space (log and logit transforms, its bounds and a fit at
one) and the gridded scans of terrain runs."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from ..campaign import Campaign, RunSpec
from ..errors import InputError
from ..rover_model import SOIL_PARAMETERS
from ..simulator import SimulationError

#: The paper's initial guess (Tables 1-3).
PAPER_INITIAL = {"soil.kh": 2.5e5, "soil.eta": 0.5, "soil.gamma": 0.15, "soil.Kvx": 0.5}
#: Integration step used while identifying (s), fixed (``solver.tolerance`` 0: the residuals of
#: neighbouring parameter values then share one discretisation, which the finite-difference
#: Jacobian of the fit needs): 2 ms keeps the steady slip within 0.1 % of 1 ms (5 ms: 0.5 %,
#: which biased K_vx by 2 sigma in noisy synthetic tests).  Not the automatic step's second-order
#: method at a fixed length: it is more accurate at 5 ms than this at 2 ms, but its explicit
#: correction (fmu_src/rover_auto_step.c), without the step-size control that rejects such
#: steps, lets the stiff spin tracker that replays a terrain run from rest swing between the
#: torque limits at fixed steps of 5-8 ms.
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
    """Fixed FMU parameters for identification: the campaign's rover overrides, a payload the
    manifest states (rover.payload) given as part of rover.mass.  To the FMU that is the same
    rover (the payload joins the chassis's mass as rover.mass does, and their sum is the same
    number either way), and it leaves rover.payload to the diagnosis's payload candidate: the
    mass the campaign does not state, 0 where the statement is right."""
    params = dict(campaign.rover)
    if "rover.payload" in params:
        from ..rover_model import rover
        params["rover.mass"] = rover(params).mass
        del params["rover.payload"]
    return params


def terrain_grids(campaign: Campaign, out_dir: str | Path, step: str = "identify --with-terrain") -> dict[str, str]:
    """Each terrain run's LIDAR scan gridded into its own file under ``out_dir`` (run id ->
    path), so that every terrain run is replayed on the ground it was driven on; InputError
    (require_runs) when the campaign has no terrain run."""
    return {run_id: path for run_id, (path, _grid) in gridded_scans(campaign, out_dir, step).items()}


def gridded_scans(campaign: Campaign, out_dir: str | Path, step: str) -> dict[str, tuple[str, object]]:
    """terrain_grids with each run's grid (juno.pointcloud.Grid) as well: run id -> (path, grid)."""
    from ..validate import grid_terrain   # validate imports this module
    grids = {}
    for i, run in enumerate(require_runs(campaign, step)):
        run_dir = Path(out_dir) / f"scan{i}"
        run_dir.mkdir(parents=True, exist_ok=True)
        path, grid = grid_terrain(campaign, run, run_dir)
        grids[run.id] = (str(path), grid)
    return grids


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
