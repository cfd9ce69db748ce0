"""Identification (juno.identify) on synthetic campaigns with known truth.

* The joint fit recovers k_h, eta, gamma and K_vx within 2 % from noise-free data, and with
  the documented sensor noise the truth lies within 3 reported sigmas of each estimate.
* The paper-style per-run Nelder-Mead converges on each drawbar run: finite cost that is
  much lower than the initial guess's (and no higher than the truth's), physical parameters,
  and a steady-window problem that sees fewer than four parameter directions.

The campaigns and fits are session fixtures (harness_fixtures.py), shared with the other files.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from harness_fixtures import NOISY_TIME_SCALE, PAPER_WINDOWS, say
from juno.identify import FAILED_COST, PAPER_INITIAL, classify, from_search, to_search
from juno.simulator import SOIL_PARAMETERS

pytest_plugins = ["harness_fixtures"]

RECOVERY_TOLERANCE = 0.02   # noise-free: |estimate / truth - 1|
Z_LIMIT = 3.0               # noisy: |estimate - truth| <= 3 sigma
COST_REDUCTION = 100.0      # paper-style: the final cost is below the initial guess's / 100


def physical(soil: dict[str, float]) -> list[str]:
    """What is unphysical about a soil parameter set (empty if nothing)."""
    bad = [f"{k} = {v!r} is not finite" for k, v in soil.items() if not math.isfinite(v)]
    if not bad:
        if soil["soil.kh"] <= 0:
            bad.append(f"k_h = {soil['soil.kh']:.4g} <= 0")
        if soil["soil.eta"] <= 0:
            bad.append(f"eta = {soil['soil.eta']:.4g} <= 0")
        if not 0 <= soil["soil.gamma"] < 1:
            bad.append(f"gamma = {soil['soil.gamma']:.4g} outside [0, 1)")
        if soil["soil.Kvx"] <= 0:
            bad.append(f"K_vx = {soil['soil.Kvx']:.4g} <= 0")
    return bad


# ------------------------------------------------------------------------- transforms

def test_search_transform_round_trips_and_keeps_the_search_physical():
    soil = dict(PAPER_INITIAL)
    back = from_search(to_search(soil))
    for k in SOIL_PARAMETERS:
        assert back[k] == pytest.approx(soil[k], rel=1e-12)
    rng = np.random.default_rng(3)
    for x in rng.normal(0.0, 5.0, size=(200, 4)) + to_search(soil):
        assert physical(from_search(x)) == []


# ------------------------------------------------------------------------- joint fit

def test_joint_fit_recovers_the_truth_from_noise_free_data(clean_campaign, clean_joint):
    truth = clean_campaign.soil
    errors = {k: clean_joint.params[k] / truth[k] - 1 for k in SOIL_PARAMETERS}
    say("noise-free joint fit, relative errors: " + ", ".join(f"{k} {e:+.3%}" for k, e in errors.items()))
    assert clean_joint.runs == [r.id for r in clean_campaign.campaign.runs_of_kind("drawbar")]
    bad = {k: f"{e:+.3%}" for k, e in errors.items() if not abs(e) <= RECOVERY_TOLERANCE}
    assert not bad, f"joint fit misses the noise-free truth by more than {RECOVERY_TOLERANCE:.0%}: {bad}"


def test_joint_fit_truth_lies_within_the_reported_uncertainty(noisy_campaign, noisy_joint):
    truth = noisy_campaign.soil
    z = {k: (noisy_joint.params[k] - truth[k]) / noisy_joint.std[k] for k in SOIL_PARAMETERS}
    say("noisy joint fit, z-scores (estimate - truth) / sigma: " + ", ".join(f"{k} {v:+.2f}" for k, v in z.items()))
    for k in SOIL_PARAMETERS:
        assert math.isfinite(noisy_joint.std[k]) and noisy_joint.std[k] > 0, f"{k}: sigma {noisy_joint.std[k]}"
    outside = {k: round(v, 2) for k, v in z.items() if not abs(v) <= Z_LIMIT}
    assert not outside, f"truth outside {Z_LIMIT:g} reported sigmas (z-scores): {outside}"


def test_joint_fit_uncertainty_is_informative(noisy_campaign, noisy_joint):
    """A covering interval is only worth something if it is narrow: the drawbar time series pin
    all four parameters (relative 1-sigma below 10 %), and the labels follow the numbers."""
    for k in SOIL_PARAMETERS:
        rel = noisy_joint.relative_std[k]
        assert rel == pytest.approx(noisy_joint.std[k] / abs(noisy_joint.params[k]), rel=1e-9)
        assert rel < 0.10, f"{k}: relative 1-sigma {rel:.1%} (uninformative uncertainty)"
        assert noisy_joint.identifiability[k] == classify(rel)


def test_joint_fit_statistics_are_consistent(noisy_joint):
    corr = np.asarray(noisy_joint.correlation, float)
    assert corr.shape == (4, 4)
    assert np.all(np.isfinite(corr))
    np.testing.assert_allclose(np.diag(corr), 1.0, atol=1e-9)
    np.testing.assert_allclose(corr, corr.T, atol=1e-9)
    assert np.all(np.abs(corr) <= 1 + 1e-9)
    assert noisy_joint.inflation >= 1.0
    assert len(noisy_joint.singular_values) == 4 and min(noisy_joint.singular_values) > 0
    # Residuals are scaled by the sensor noise, so at the optimum of a well-specified model with
    # the documented noise their mean square is of order 1 (not 1e-3, not 1e3).
    assert 0.25 < noisy_joint.cost < 4.0, f"mean squared scaled residual {noisy_joint.cost:.4g}"


# ---------------------------------------------------------------------- paper-style fit

def test_paper_fit_converges_on_each_run(noisy_campaign, noisy_paper):
    ids = [r.id for r in noisy_campaign.campaign.runs_of_kind("drawbar")]
    assert [p.result.run_id for p in noisy_paper] == ids
    problems = []
    for p in noisy_paper:
        r = p.result
        if not math.isfinite(r.cost) or r.cost >= FAILED_COST:
            problems.append(f"{r.run_id}: final cost {r.cost!r}")
            continue
        if not r.cost * COST_REDUCTION <= p.initial_cost:
            problems.append(f"{r.run_id}: cost only fell from {p.initial_cost:.4g} to {r.cost:.4g}")
        # A minimiser that stops above the cost of the true parameters has not converged.
        if not r.cost <= p.truth_cost:
            problems.append(f"{r.run_id}: final cost {r.cost:.4g} above the truth's {p.truth_cost:.4g}")
        problems += [f"{r.run_id}: {b}" for b in physical(r.final)]
    assert not problems, "; ".join(problems)


def test_paper_fit_starts_from_the_paper_guess_on_the_steady_window(noisy_paper):
    for p in noisy_paper:
        r = p.result
        assert r.initial == PAPER_INITIAL
        assert math.isfinite(p.initial_cost) and p.initial_cost < FAILED_COST, \
            f"{r.run_id}: the initial guess itself fails ({p.initial_cost})"
        window = tuple(w * NOISY_TIME_SCALE for w in PAPER_WINDOWS[r.run_id])
        assert r.averages.window == pytest.approx(window)
        a = r.averages
        assert a.drawbar > 0 and a.speed > 0 and a.omega_left > 0 and a.omega_right > 0
        assert a.torque_left > 0 and a.torque_right > 0
        assert sum(a.weights()) == pytest.approx(1.0)


def test_paper_fit_reports_poor_identifiability(noisy_paper):
    """Three averaged objectives see at most three of the four parameter directions."""
    ranks = {p.result.run_id: p.result.jacobian_rank for p in noisy_paper}
    say(f"paper-style rank of d(objectives)/d(log a): {ranks}")
    assert all(1 <= rank <= 3 for rank in ranks.values()), ranks
