"""The loss `juno diagnose` fits with (diagnose.fit_loss): squares for ordinary residuals, and
only linear growth for a replay that loses the rover for a few seconds, so that such blocks do not
drag the soil and the extension's parameters to where they are absorbed.

No simulation: the loss, its agreement with the least-squares fit, and the choice between fits
from two starts (diagnose.fit_objective) on made-up residuals.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares

from juno import diagnose
from juno.diagnose import FIT_LOSS_SCALE, FitResult, Problem, fit_loss, fit_objective
from juno.identify import PAPER_INITIAL


def test_ordinary_residuals_are_weighed_by_their_squares():
    r = np.random.default_rng(1).standard_normal(2000) * 0.1 * FIT_LOSS_SCALE
    # within 1 %: at |r| = 0.3 FIT_LOSS_SCALE the soft L1 loss is 2 % below r^2
    assert fit_loss(r) == pytest.approx(float(np.mean(r * r)), rel=1e-2)


def test_large_residuals_grow_linearly_not_quadratically():
    r = np.full(10, 100.0 * FIT_LOSS_SCALE)
    assert fit_loss(2.0 * r) / fit_loss(r) == pytest.approx(2.0, rel=2e-2)
    assert fit_loss(r) < 0.05 * float(np.mean(r * r))


def test_the_loss_is_what_the_least_squares_fit_minimises():
    """scipy's cost with loss="soft_l1" and f_scale is half the summed loss: restarts are chosen
    (fit_objective) by the same quantity the fits descend."""
    rng = np.random.default_rng(2)
    t = np.linspace(0.0, 1.0, 400)
    y = 3.0 * t + rng.standard_normal(t.size)
    y[100:140] += 40.0     # one blown block
    ls = least_squares(lambda p: p[0] * t + p[1] - y, [0.0, 0.0], loss="soft_l1", f_scale=FIT_LOSS_SCALE)
    assert fit_loss(ls.fun) == pytest.approx(2.0 * ls.cost / t.size, rel=1e-12)
    plain = least_squares(lambda p: p[0] * t + p[1] - y, [0.0, 0.0])
    # the robust slope stays near the truth (3); squares follow the blown block
    assert abs(ls.x[0] - 3.0) < 0.5 * abs(plain.x[0] - 3.0)


def test_a_fit_with_one_blown_block_is_preferred_to_one_bent_everywhere():
    """Two fits of the same drawbar data: one follows the data (residuals of order 1) except for a
    4 s block where the replay is lost (residuals of 15); the other is a little wrong everywhere
    (residuals of order 2.5).  By squares the second would win; the fits' loss keeps the first."""
    n = 2000
    meta = {"run": np.array(["dbp1"] * n), "signal": np.array(["speed"] * n),
            "time": np.arange(n) * 0.05, "block": (np.arange(n) * 0.05 // 4.0).astype(int)}
    problem = Problem("campaign", None, "unused.fmu", [], np.ones(n, bool), meta)
    run_kind = np.array(["drawbar"] * n)
    rng = np.random.default_rng(3)
    follows = rng.standard_normal(n)
    follows[400:480] = 15.0
    bent = 2.5 * rng.standard_normal(n)
    assert np.mean(follows ** 2) > np.mean(bent ** 2)

    def fit(r):
        return FitResult("x", dict(PAPER_INITIAL), 0.0, 0.0, r, 1, 0.0)
    assert fit_objective(problem, run_kind, fit(follows)) < fit_objective(problem, run_kind, fit(bent))


def test_plain_squares_when_switched_off(monkeypatch):
    monkeypatch.setattr(diagnose, "FIT_LOSS_SCALE", None)
    r = np.array([0.5, -3.0, 40.0])
    assert diagnose.fit_loss(r) == pytest.approx(float(np.mean(r * r)))
