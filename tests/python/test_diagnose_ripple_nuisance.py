"""A ripple in the wheel angle as a nuisance of the fits (juno/diagnose/ripple_nuisance.py):
once the base model's drive torques ripple with the wheel angle, every fit's loss is taken with
that ripple removed from the drawbar runs' drive torques, block by block; what the models are
judged and reported on keeps it."""

from __future__ import annotations

import numpy as np

from juno.diagnose import FitResult, build_problem
from juno.diagnose.problem import BLOCK, Problem, all_residuals
from juno.diagnose.ripple_nuisance import nuisance_free
from juno.diagnose.search import _with_ripple_as_nuisance, ripple_of
from juno.identify import PreparedRun
from juno.periodic_structure import PeriodicBases
from juno.simulator import InputSignals

from harness_fixtures import NOISY_SEED, NOISY_TIME_SCALE, make_campaign

pytest_plugins = ["harness_fixtures"]


def one_drawbar_run(lugs: int, amplitude: float, seed: int = 3) -> tuple[Problem, np.ndarray, np.ndarray]:
    """A drawbar run of 24 s whose left drive torque's residuals are a constant per 4 s block,
    white noise, and ``amplitude`` cos(lugs theta + 0.4) (theta: the left wheel's angle at a spin
    that speeds up from 0.8 to 1.6 rad/s); its pos_x residuals the same ripple (not a torque).
    Returns the problem, the residuals and the block constants."""
    rng = np.random.default_rng(seed)
    grid = np.arange(0.0, 24.0 + 1e-9, 0.01)
    spin = 0.8 + 0.8 * grid / 24.0
    ts = np.arange(0.0, 24.0, 0.02)
    theta = 0.8 * ts + 0.8 * ts ** 2 / 48.0
    block = np.floor(ts / BLOCK).astype(int)
    level = rng.normal(0.0, 1.0, block.max() + 1)
    torque = level[block] + rng.normal(0.0, 1.0, len(ts)) + amplitude * np.cos(lugs * theta + 0.4)
    position = amplitude * np.cos(lugs * theta + 0.4)
    targets = {"torque_left": (ts, np.zeros(len(ts)), "torqueLeft", 3.0, 0.0),
               "pos_x": (ts, np.zeros(len(ts)), "x", 0.005, 1.0)}
    run = PreparedRun("db1", "drawbar", 24.0, InputSignals(grid, {"omegaRefLeft": spin, "omegaRefRight": spin}),
                      {}, targets)
    problem = Problem("campaign", None, "JunoRover.fmu", [run], train=np.concatenate([block % 2 == 0] * 2),
                      ripple_lugs=lugs)
    return problem, np.concatenate([torque, position]), level[block]


def test_the_ripple_is_removed_from_the_drive_torques_block_by_block_and_their_block_means_stay():
    problem, r, levels = one_drawbar_run(lugs=18, amplitude=2.0)
    free = nuisance_free(problem, r)
    n = len(levels)
    torque, rest = free[:n], free[n:]
    ts = problem.prepared[0].targets["torque_left"][0]
    theta = 0.8 * ts + 0.8 * ts ** 2 / 48.0
    for h in (1, 2):
        for f in (np.cos, np.sin):
            assert abs(np.dot(torque, f(h * 18 * theta))) / n < 0.02
    block = np.floor(ts / BLOCK).astype(int)
    means = np.array([torque[block == b].mean() for b in np.unique(block)])
    raw = np.array([r[:n][block == b].mean() for b in np.unique(block)])
    assert np.max(np.abs(means - raw)) < 0.05
    assert np.array_equal(rest, r[n:]), "only the drive torques carry the nuisance"
    assert r is not free, "the residuals given are not changed"


def test_without_a_ripple_set_the_residuals_are_the_same_object():
    problem, r, _levels = one_drawbar_run(lugs=18, amplitude=2.0)
    problem.ripple_lugs = None
    assert nuisance_free(problem, r) is r


def test_a_base_model_that_ripples_is_refitted_with_the_ripple_left_out_and_one_that_does_not_is_kept(
        harness_fmu, fmu_path, noisy_campaign, tmp_path):
    """On the lug_ripple campaign the base model (at the true soil, no extension) ripples at 18
    per revolution: the problem takes 18 lugs as a nuisance, the base model is refitted, and its
    residuals with the nuisance removed no longer ripple, while the residuals it reports still
    do. On the campaign with nothing hidden, nothing changes."""
    ripple = make_campaign(tmp_path / "ripple", harness_fmu, NOISY_SEED, 1.0, NOISY_TIME_SCALE, effect="lug_ripple")
    for c, lugs in ((ripple, 18), (noisy_campaign, None)):
        problem = build_problem(c.campaign, fmu_path, None)
        base = FitResult("base", dict(c.soil), 1.0, 1.0, all_residuals(harness_fmu, problem, dict(c.soil)), 1, 0.0)
        said: list[str] = []
        fitted = _with_ripple_as_nuisance(c.campaign, problem, base, PeriodicBases(), said.append, 1)
        assert problem.ripple_lugs == lugs
        if lugs is None:
            assert fitted is base and said == []
            continue
        assert fitted.error is None and fitted is not base
        assert "18 per revolution" in said[0]
        assert ripple_of(c.campaign, problem, fitted, PeriodicBases()).significant
        cleaned = FitResult("base", fitted.params, 1.0, 1.0, nuisance_free(problem, fitted.residuals), 1, 0.0)
        assert not ripple_of(c.campaign, problem, cleaned, PeriodicBases()).significant
