"""The terrain replay test (juno.terrain_replay): a terrain run's replay is judged by the RMS of
its held-out 4 s block means over the column's own sensor noise, against a floor calibrated on
right models; a swapped pair of torque columns on a terrain run is reported as unexplained, not
called none (the end-to-end case is in test_diagnose_unexplained.py)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from juno.campaign import RunData
from juno.identify import PreparedRun
from juno.terrain_replay import DEFAULT_FLOOR, FLOORS, terrain_replay_tests

RATE = 100.0          # Hz
DURATION = 40.0       # s: ten 4 s blocks, five held out
SIGMA = 2.0           # N m: the torque sensor's noise
NOMINAL = 3.0         # N m: the scale the residuals are divided by


def _run(rng: np.random.Generator) -> tuple[RunData, np.ndarray, np.ndarray]:
    """A terrain run's measured drive torque (a slow swing plus white noise) and its times."""
    t = np.arange(0.0, DURATION, 1.0 / RATE)
    true = 80.0 + 20.0 * np.sin(2 * np.pi * t / 17.0)
    measured = true + SIGMA * rng.standard_normal(len(t))
    data = RunData(Path("t3d.csv"), "terrain", {"time": t, "torque_left": measured}, run_id="t3d")
    return data, t, true


def _test(data: RunData, t: np.ndarray, simulated: np.ndarray):
    prepared = PreparedRun("t3d", "terrain", DURATION, None, {},
                           {"torque_left": (t, data.columns["torque_left"], "T_left", NOMINAL, 0.0)})
    block = np.floor(t / 4.0).astype(int)
    meta = {"run": np.full(len(t), "t3d"), "signal": np.full(len(t), "torque_left"), "block": block}
    residuals = (simulated - data.columns["torque_left"]) / NOMINAL
    return terrain_replay_tests(None, [prepared], meta, block % 2 == 0, residuals, data={"t3d": data})


def test_a_replay_that_follows_the_run_within_its_noise_is_not_reported():
    data, t, true = _run(np.random.default_rng(1))
    result = _test(data, t, true)
    (signal,) = result.runs[0].signals
    assert signal.noise == pytest.approx(SIGMA, rel=0.15), "the sensor noise is estimated from the column itself"
    assert signal.blocks == 5
    assert signal.ratio < 0.5 and not result.significant


def test_a_replay_whose_torque_is_off_by_many_times_the_noise_is_reported_with_its_size():
    data, t, true = _run(np.random.default_rng(2))
    off = 4.0 * FLOORS.get("torque_left", DEFAULT_FLOOR) * SIGMA
    result = _test(data, t, true + off)
    (signal,) = result.runs[0].disagreeing()
    assert signal.signal == "torque_left" and signal.unit == "N m"
    assert signal.rms == pytest.approx(off, rel=0.02) and signal.offset == pytest.approx(off, rel=0.02)
    assert signal.ratio == pytest.approx(off / SIGMA, rel=0.15)
    assert result.significant and "t3d" in result.summary() and "torque_left" in result.summary()


def test_a_campaign_without_terrain_runs_has_no_replay_test():
    prepared = PreparedRun("dbp1", "drawbar", 10.0, None, {}, {})
    assert terrain_replay_tests(None, [prepared], {}, np.zeros(0, bool), np.zeros(0)) is None
