"""The timing test: a compared signal whose clock is offset from the replay inputs' leaves its own
rate of change times the offset in its residual (juno/timing_structure.py)."""

from __future__ import annotations

import numpy as np
import pytest

from juno.timing_structure import (FALSE_ALARM, LINEAR_LIMIT, MATERIAL_OFFSET, POSITIONS, TIMED_SIGNALS,
                                   rate_of_change, timing_structure)

REPLICAS = 20


def test_the_rate_of_change_is_exact_for_a_quadratic_and_undefined_at_the_ends():
    t = np.arange(0.0, 5.0, 0.1)
    g = rate_of_change(t, 3.0 * t ** 2 - t + 2.0, half_width=0.25)
    inside = np.isfinite(g)
    assert np.allclose(g[inside], 6.0 * t[inside] - 1.0)
    assert np.isnan(g[t < 0.25]).all() and np.isnan(g[t > 5.0 - 0.1 - 0.25]).all()


def _signal(offset: float, noise: float, seed: int = 0, duration: float = 40.0, rate: float = 10.0):
    """A speed-like compared signal (scaled units) that speeds up and slows down every few
    seconds, measured with its clock ``offset`` s behind the inputs' (the sample stamped t holds
    the value at t + offset), white noise of ``noise``; and REPLICAS null residuals of noise alone."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration, 1.0 / rate)

    def model(x):
        return 20.0 * np.sin(2 * np.pi * x / 6.0) + 8.0 * np.sin(2 * np.pi * x / 2.5)

    measured = model(t + offset) + noise * rng.standard_normal(len(t))
    residuals = measured - model(t)
    g = rate_of_change(t, model(t))
    null = noise * rng.standard_normal((REPLICAS, len(t)))
    held_out = (np.floor(t / 4.0) % 2) == 1
    return np.full(len(t), "pos_x"), held_out, g, residuals, null


def _positions(result):
    """The positions' common offset of a timing test."""
    (common,) = [s for s in result.signals if s.signal == POSITIONS]
    return common


def test_an_offset_clock_is_found_with_its_size_and_direction():
    result = timing_structure(*_signal(offset=0.2, noise=1.0))
    (found,) = result.found()
    assert found.signal == POSITIONS and found.significant and result.significant
    assert found.offset == pytest.approx(0.2, abs=4 * found.spread)
    assert found.p_value < FALSE_ALARM
    assert found.direction() == "behind"
    assert found.sentence().startswith(f"the positions (pos_x, pos_y, pos_z) lag the replay by {found.offset:.2g} s")
    assert f"as a clock {found.offset:.2g} s behind the inputs' clock" in found.sentence()
    # each position's own estimate is given beside it, not tested
    (own,) = [s for s in result.signals if s.signal == "pos_x"]
    assert not own.timed and not own.significant and own.offset == found.offset


def test_a_clock_running_ahead_is_said_to_run_ahead():
    (found,) = timing_structure(*_signal(offset=-0.2, noise=1.0)).found()
    assert found.offset < 0 and found.direction() == "ahead of" and "the positions (pos_x, pos_y, pos_z) lead the replay" \
        in found.sentence()


def test_noise_alone_reports_no_offset():
    for seed in range(3):
        result = timing_structure(*_signal(offset=0.0, noise=1.0, seed=seed))
        assert not result.significant and result.found() == []
        assert _positions(result).p_value > FALSE_ALARM


def test_an_offset_below_the_comparisons_resolution_is_not_reported_however_clear():
    """Almost no noise resolves an offset of half the smallest reported one at any p; it is still
    within the replay's own time resolution (and its own lags), so it is not reported."""
    tested = _positions(timing_structure(*_signal(offset=0.5 * MATERIAL_OFFSET, noise=1e-3)))
    assert tested.p_value < 1e-6 and not tested.significant


def test_a_fitted_offset_beyond_the_first_order_limit_is_not_reported():
    """An 'offset' of several seconds is a residual that merely correlates with the rate of
    change: the expansion r = tau dy/dt holds only for offsets shorter than the signal's changes."""
    names, held_out, g, _residuals, null = _signal(offset=0.0, noise=1.0)
    residuals = 3.0 * LINEAR_LIMIT * g + null[0]
    tested = _positions(timing_structure(names, held_out, g, residuals, null))
    assert tested.p_value < 1e-6 and abs(tested.offset) > LINEAR_LIMIT and not tested.significant


def test_only_the_held_out_samples_are_used():
    names, held_out, g, residuals, null = _signal(offset=0.2, noise=1.0)
    residuals = residuals.copy()
    residuals[~held_out] += 100.0 * g[~held_out]       # a training block's misfit does not count
    tested = _positions(timing_structure(names, held_out, g, residuals, null))
    assert tested.offset == pytest.approx(0.2, abs=4 * tested.spread)
    assert tested.samples == int(np.sum(held_out & np.isfinite(g)))


def _two_positions(offset_x: float, offset_y: float, y_share: float = 0.42, seed: int = 0, duration: float = 40.0,
                   rate: float = 10.0):
    """pos_x and pos_y of a run whose y moves at ``y_share`` of x's rate (0.42: a heading of 0.4 rad), each
    time-stamped with its own offset, with white noise of 1 (scaled units) each; and REPLICAS
    null residuals of that noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration, 1.0 / rate)

    def x(u):
        return 20.0 * np.sin(2 * np.pi * u / 6.0) + 8.0 * np.sin(2 * np.pi * u / 2.5)

    parts = [(name, scale * (x(t + offset) - x(t)) + rng.standard_normal(len(t)), scale * rate_of_change(t, x(t)))
             for name, scale, offset in (("pos_x", 1.0, offset_x), ("pos_y", y_share, offset_y))]
    held_out = (np.floor(t / 4.0) % 2) == 1
    return (np.concatenate([np.full(len(t), name) for name, _r, _g in parts]), np.concatenate([held_out, held_out]),
            np.concatenate([g for _n, _r, g in parts]), np.concatenate([r for _n, r, _g in parts]),
            rng.standard_normal((REPLICAS, 2 * len(t))))


def test_the_positions_share_one_clock_so_one_offset_is_tested_over_all_of_them():
    """A total station stamps pos_x and pos_y with one clock.  An offset of it shows in both, and
    the common estimate over both is reported once; a residual in pos_y alone that follows its
    rate of change (a model error, not a clock: pos_x, on the same clock, shows none) is diluted
    by pos_x, not reported as a clock that pos_x contradicts."""
    both = timing_structure(*_two_positions(0.2, 0.2))
    (found,) = both.found()
    assert found.signal == POSITIONS and found.offset == pytest.approx(0.2, abs=4 * found.spread)
    assert found.samples == sum(s.samples for s in both.signals if s.signal in TIMED_SIGNALS)
    alone = timing_structure(*_two_positions(0.0, 0.6))
    own = {s.signal: s for s in alone.signals}
    assert own["pos_y"].offset > 0.3 and own["pos_y"].p_value < FALSE_ALARM     # one by one it would pass
    common = own[POSITIONS]
    assert abs(common.offset) < 0.25 * abs(own["pos_y"].offset) and not alone.significant
    assert common.agreement_p < FALSE_ALARM and both.found()[0].agreement_p > FALSE_ALARM


def test_positions_whose_own_offsets_disagree_are_no_clock_however_large_their_common_one():
    """At a heading of 45 degrees, pos_y off by 0.3 s of its rate of change and pos_x by none: their
    common offset passes its size and its p, but one clock cannot give the two positions different
    offsets (Cochran's Q): not reported."""
    result = timing_structure(*_two_positions(0.0, 0.3, y_share=1.0))
    own = {s.signal: s for s in result.signals}
    assert MATERIAL_OFFSET <= own[POSITIONS].offset <= LINEAR_LIMIT and own[POSITIONS].p_value < FALSE_ALARM
    assert own[POSITIONS].agreement_p < FALSE_ALARM and not result.significant
    assert result.to_json()["signals"][-1]["agreement_p"] == own[POSITIONS].agreement_p


def test_the_pitch_and_torques_are_estimated_but_not_tested():
    """Their replayed dynamics (the chassis settling under load, the speed controller following the
    spins) leave offsets of their own on right models: estimated, reported as not timed, never
    significant however clear."""
    _names, held_out, g, residuals, null = _signal(offset=0.2, noise=1.0)
    names = np.full(len(g), "pitch")
    (tested,) = timing_structure(names, held_out, g, residuals, null).signals
    assert "pitch" not in TIMED_SIGNALS and not tested.timed
    assert tested.p_value < 1e-6 and tested.offset == pytest.approx(0.2, abs=0.02) and not tested.significant
