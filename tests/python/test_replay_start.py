"""Where a replay of a measured run starts (juno.identify.prepare_run).

The replay starts at rest at the measured start pose.  Its heading is a line fitted to the
first second of IMU yaw, not the first sample: over a mound a skid-steered rover's heading error
grows several times over, so the IMU's noise in one sample was enough to send the replay along
another line over the mound.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from juno.campaign import load_campaign, read_run
from juno.identify import START_HEADING_WINDOW, prepare_run, start_heading
from juno.pointcloud import write_esri_ascii
from juno.simulator import JunoFMU
from juno.synthesize import synthesize, truth_grid

IMU_NOISE = 0.005   # rad, the synthetic campaigns' yaw noise
IMU_RATE = 100.0    # Hz


def _imu(heading: float, rate: float, rng: np.random.Generator, seconds: float = 3.0):
    t = 0.001 + np.arange(0.0, seconds, 1.0 / IMU_RATE)
    return t, heading + rate * (t - t[0]) + IMU_NOISE * rng.standard_normal(len(t))


def test_the_start_heading_averages_out_the_imu_noise():
    """Over 400 noisy starts (heading 0.3 rad, turning at up to 0.02 rad/s): the fitted start is
    good to a third of the IMU's noise, where the first sample is only as good as the noise."""
    rng = np.random.default_rng(5)
    fitted, first = [], []
    for _ in range(400):
        t, yaw = _imu(0.3, rng.uniform(-0.02, 0.02), rng)
        fitted.append(start_heading(t, yaw) - 0.3)
        first.append(yaw[0] - 0.3)
    rms = float(np.sqrt(np.mean(np.square(fitted))))
    assert rms < IMU_NOISE / 3, f"start heading error {rms:.4f} rad RMS"
    assert float(np.sqrt(np.mean(np.square(first)))) > 0.8 * IMU_NOISE   # the noise was there


def test_the_start_heading_is_unwrapped_across_pi():
    """A rover heading west: its yaw samples jump between +pi and -pi."""
    rng = np.random.default_rng(6)
    t, yaw = _imu(np.pi - 0.002, 0.0, rng)
    wrapped = (yaw + np.pi) % (2 * np.pi) - np.pi
    assert np.any(wrapped < 0) and np.any(wrapped > 0)
    found = start_heading(t, wrapped)
    assert abs((found - (np.pi - 0.002) + np.pi) % (2 * np.pi) - np.pi) < IMU_NOISE / 2


def test_with_too_few_early_samples_the_first_sample_is_the_start():
    t = np.array([0.0, 0.5 * START_HEADING_WINDOW, 3.0 * START_HEADING_WINDOW])
    assert start_heading(t, np.array([0.1, 0.2, 0.3])) == 0.1


def test_the_replay_at_the_truth_follows_the_measured_heading_over_a_mound(tmp_path):
    """A measured terrain run with the documented sensor noise (seed 4014, whose path runs along
    the mound's flank), replayed with the true soil on the true terrain at 1 ms: the heading stays
    within 0.02 rad RMS of the measured one (0.007 measured; 0.055 when the replay started at the
    first yaw sample, and 0.0015 from noise-free data)."""
    campaign_dir = synthesize(tmp_path / "c", effect="none", seed=4014)
    truth = json.loads((campaign_dir / "truth.json").read_text())
    campaign = load_campaign(campaign_dir)
    run = campaign.runs_of_kind("terrain")[0]
    grid_file = tmp_path / "truth.asc"
    write_esri_ascii(grid_file, truth_grid(4014))
    prepared = prepare_run(campaign, run, terrain_file=str(grid_file))
    data = read_run(campaign, run)
    t_yaw, yaw = data.samples("yaw")
    t_yaw, yaw = t_yaw - data.time[0], np.unwrap(yaw)
    with JunoFMU() as fmu:
        sim = fmu.simulate({**prepared.params, **truth["soil"], "solver.step": 1e-3}, prepared.inputs,
                           prepared.duration, 0.05, outputs=["yaw"])
    late = t_yaw >= 3.0
    error = yaw[late] - np.interp(t_yaw[late], sim["time"], np.unwrap(sim["yaw"]))
    rms = float(np.sqrt(np.mean(error ** 2)))
    assert rms < 0.02, f"the replay's heading is {rms:.4f} rad RMS off the measured one"
    assert prepared.params["init.yaw"] == pytest.approx(start_heading(t_yaw + data.time[0], yaw))
