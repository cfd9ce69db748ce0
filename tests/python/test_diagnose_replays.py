"""How a diagnosis's fits spend their simulations: what they compute must not depend on it.

* A replay asked for again with the same parameters (a fit returning to a point it evaluated)
  comes from the fit's ReplayCache, not from a new simulation; other parameters are simulated.
* A lone fit whose finite-difference Jacobians are evaluated over two worker processes is the
  same fit, bit for bit, as the one made in this process alone (evaluations counted alike).
"""

from __future__ import annotations

import numpy as np

from juno.diagnose.candidates import CANDIDATES
from juno.diagnose.fitting import fit_candidate
from juno.diagnose.problem import ReplayCache, build_problem, residuals_or_failure
from juno.identify import PAPER_INITIAL

pytest_plugins = ["harness_fixtures"]

SEED = 21


class CountingFMU:
    """An FMU that counts its simulations (run_residuals only calls ``simulate``)."""

    def __init__(self, fmu):
        self.fmu, self.simulations = fmu, 0

    def simulate(self, *args, **kwargs):
        self.simulations += 1
        return self.fmu.simulate(*args, **kwargs)


def test_a_replay_asked_for_again_is_remembered_not_simulated(small_campaign, harness_fmu, fmu_path):
    problem = build_problem(small_campaign(SEED).campaign, fmu_path, None)
    n_runs = len(problem.prepared)
    fmu, cache = CountingFMU(harness_fmu), ReplayCache()
    params = dict(PAPER_INITIAL)
    first, failure = residuals_or_failure(fmu, problem, params, ("drawbar",), cache)
    assert failure is None and fmu.simulations == n_runs
    again, _ = residuals_or_failure(fmu, problem, dict(params), ("drawbar",), cache)
    assert fmu.simulations == n_runs and cache.hits == n_runs, "the same parameters must not be simulated again"
    np.testing.assert_array_equal(again, first)
    uncached, _ = residuals_or_failure(harness_fmu, problem, params, ("drawbar",))
    np.testing.assert_array_equal(uncached, first)
    residuals_or_failure(fmu, problem, {**params, "soil.eta": params["soil.eta"] * 1.01}, ("drawbar",), cache)
    assert fmu.simulations == 2 * n_runs, "other parameters are another replay"


def test_a_lone_fit_is_the_same_with_its_jacobian_over_two_processes(small_campaign, fmu_path):
    problem = build_problem(small_campaign(SEED, "drivetrain_loss").campaign, fmu_path, None)
    candidate = CANDIDATES["drivetrain_loss"]
    here = fit_candidate(problem, candidate, dict(PAPER_INITIAL), max_nfev=3, workers=1)
    spread = fit_candidate(problem, candidate, dict(PAPER_INITIAL), max_nfev=3, workers=2)
    assert not here.error and not spread.error
    assert here.params == spread.params
    np.testing.assert_array_equal(here.residuals, spread.residuals)
    assert here.evaluations == spread.evaluations > 3, "every Jacobian point counts as an evaluation"
