"""Residual scales from the data (juno.sensor_noise): a user's instruments are not the paper's.

* The noise of a measured column is estimated from the column itself, within a few % of the
  truth, on a signal that moves as a rover's do.
* A quantised column (an encoder's counts over a read interval) has at least the noise of its
  quantisation, not none: more than half of its second differences are zero, which the median
  alone would read as a noiseless sensor.
* A residual's scale is that noise (an increment's: sqrt(2) times it), never below the
  signal's nominal scale.
* A campaign whose total station is ten times noisier than the paper's gets its positions
  weighed down accordingly, and the joint fit's uncertainty still covers the truth.
* A filtered column's noise is estimated at a fraction of the truth; the manifest may state it
  (``sensor_noise``): the stated value is then used, the outputs say which noise was stated and
  which estimated, and a stated value far from the estimate is reported, naming the column.
"""

from __future__ import annotations

import csv
import shutil

import numpy as np
import pytest

from harness_fixtures import say
from juno.campaign import load_campaign
from juno.identify import INCREMENT_SIGNALS, JOINT_SIGNALS, identify_joint, prepare_run
from juno.campaign import write_campaign
from juno.sensor_noise import (FAR_FACTOR, column_noise, far_from_estimate, noise_statements, quantisation_step,
                               residual_scale, stated_noise_lines)

pytest_plugins = ["harness_fixtures"]

#: The added total-station noise (m, 1 sigma): a GNSS receiver's, ten times the paper's station.
STATION_NOISE = 0.02


def _signal(seed: int, sigma: float, n: int = 2000, rate: float = 50.0) -> tuple[np.ndarray, np.ndarray]:
    """A smooth rover-like signal (a ramp, a slow wave) with white noise of ``sigma``."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / rate
    return t, 150.0 + 2.0 * t + 20.0 * np.sin(0.4 * t) + sigma * rng.standard_normal(n)


@pytest.mark.parametrize("sigma", [0.5, 3.0, 12.0])
def test_the_noise_of_a_column_is_estimated_from_the_column(sigma):
    t, v = _signal(1, sigma)
    assert column_noise(t, v) == pytest.approx(sigma, rel=0.08)


def _encoder_spin(seed: int, counts: int = 2048, rate: float = 20.0, seconds: float = 30.0):
    """A wheel spin as an encoder gives it: the angle of a wheel at a steady spin (0.79 rad/s,
    slowly rising) counted in ``counts`` steps per revolution, read at ``rate``, differenced."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, 1.0 / rate)
    angle = 0.79 * t + 0.0005 * t**2
    n = np.floor(angle * counts / (2.0 * np.pi) + rng.uniform())
    step = 2.0 * np.pi / counts * rate      # rad/s: one count in one read interval
    return t[1:], np.diff(n) * step, angle, step


def test_a_quantised_column_has_at_least_the_noise_of_its_quantisation():
    t, spin, angle, step = _encoder_spin(3)
    true_spin = np.diff(angle) * 20.0
    error = float(np.std(spin - true_spin))
    say(f"encoder spin: {step:.4f} rad/s per count, error {error:.4f} rad/s rms, "
        f"estimated noise {column_noise(t, spin):.4f} rad/s")
    assert np.mean(np.diff(spin, 2) == 0.0) > 0.5, "the premise: most second differences are zero"
    assert column_noise(t, spin) >= step / np.sqrt(12.0) * 0.999
    assert column_noise(t, spin) <= 2.0 * error


def test_a_finely_resolved_column_is_estimated_as_before():
    """The quantisation bound is the column's step: readings printed to many digits leave
    the estimate of their noise unchanged."""
    t, v = _signal(4, 3.0)
    assert column_noise(t, np.round(v, 4)) == pytest.approx(column_noise(t, v), rel=1e-3)


def test_a_moving_position_is_no_quantised_column():
    """A position along the track changes by 2-5 cm a sample with 2 mm of noise: no common
    step, so its noise is the second differences' alone (not its smallest change over sqrt 12)."""
    rng = np.random.default_rng(6)
    t = np.arange(0.0, 30.0, 0.2)
    x = 0.2 * t + 0.05 * np.sin(0.3 * t) + rng.normal(0.0, 0.002, len(t))
    assert quantisation_step(x) == 0.0
    assert column_noise(t, x) == pytest.approx(0.002, rel=0.25)
    _t, spin, _angle, step = _encoder_spin(3)
    assert quantisation_step(spin) == pytest.approx(step, rel=1e-9)


def test_a_residual_is_scaled_by_the_sensor_noise_and_never_below_the_nominal_scale():
    t, v = _signal(2, 6.0)
    assert residual_scale(t, v, nominal=3.0, increment=False) == pytest.approx(6.0, rel=0.08)
    assert residual_scale(t, v, nominal=3.0, increment=True) == pytest.approx(6.0 * np.sqrt(2.0), rel=0.08)
    assert residual_scale(t, v, nominal=20.0, increment=False) == 20.0
    assert residual_scale(t[:4], v[:4], nominal=3.0, increment=False) == 3.0   # too few samples to tell


def test_a_stated_noise_scales_a_residual_in_place_of_the_estimate_and_never_below_the_nominal_scale():
    t, v = _signal(2, 6.0)
    assert residual_scale(t, v, nominal=3.0, increment=False, stated=10.0) == 10.0
    assert residual_scale(t, v, nominal=3.0, increment=True, stated=10.0) == pytest.approx(10.0 * np.sqrt(2.0))
    assert residual_scale(t, v, nominal=3.0, increment=False, stated=1.0) == 3.0
    assert residual_scale(t[:4], v[:4], nominal=3.0, increment=False, stated=10.0) == 10.0


def _low_pass(v: np.ndarray, dt: float, tau: float) -> np.ndarray:
    keep = np.exp(-dt / tau)
    out, state = np.empty_like(v), v[0]
    for i, x in enumerate(v):
        state = keep * state + (1.0 - keep) * x
        out[i] = state
    return out


def test_a_filtered_column_is_estimated_at_a_fraction_of_its_noise_and_its_stated_noise_is_flagged_as_far():
    t, v = _signal(3, 3.0)
    filtered = _low_pass(v, 0.02, 0.15)
    estimate = column_noise(t, filtered)
    assert estimate < 3.0 / FAR_FACTOR, f"a 0.15 s low-pass at 50 Hz leaves {estimate:.3f} of a 3.0 noise"
    assert "filtered" in far_from_estimate(3.0, estimate, "N m")
    assert f"({estimate:.3g} N m) is under 1/3 of the stated 3 N m" in far_from_estimate(3.0, estimate, "N m")
    assert far_from_estimate(3.0, column_noise(t, v)) is None          # white noise: the two agree
    assert "noisier than stated" in far_from_estimate(0.5, column_noise(t, v))
    assert far_from_estimate(3.0, float("nan")) is None                 # too short to estimate


def test_the_noise_statements_say_which_noise_is_stated_and_which_estimated(tmp_path):
    t = np.arange(0.0, 20.0, 0.02)
    runs = {}
    for k, run in enumerate(("dbp1", "dbp2")):
        rng = np.random.default_rng(k)
        torque = 150.0 + 20.0 * np.sin(0.4 * t) + 3.0 * rng.standard_normal(len(t))
        runs[run] = {"time": t, "torque_left": _low_pass(torque, 0.02, 0.15),
                     "torque_right": torque + 1.0, "omega_left": 1.2 + 0.005 * rng.standard_normal(len(t)),
                     "omega_right": 1.2 + 0.005 * rng.standard_normal(len(t)), "pos_x": 0.3 * t, "pos_y": 0 * t,
                     "pos_z": 0.4 + 0 * t, "drawbar_force": 200.0 + 4.0 * rng.standard_normal(len(t))}
    manifest = {"runs": [{"id": r, "kind": "drawbar", "file": f"runs/{r}.csv"} for r in runs],
                "sensor_noise": {"torque_left": 3.0, "torque_right": 3.0}}
    write_campaign(tmp_path / "c", manifest, runs)
    statements = noise_statements(load_campaign(tmp_path / "c"))
    by = {(s.run, s.column): s for s in statements}
    assert by[("dbp1", "torque_left")].source == "stated" and by[("dbp1", "torque_left")].noise == 3.0
    assert by[("dbp1", "torque_left")].estimated < 1.0 and "filtered" in by[("dbp1", "torque_left")].warning
    assert by[("dbp2", "torque_right")].source == "stated" and by[("dbp2", "torque_right")].warning is None
    assert by[("dbp2", "drawbar_force")].source == "estimated" and by[("dbp2", "drawbar_force")].stated is None
    assert by[("dbp2", "drawbar_force")].noise == pytest.approx(4.0, rel=0.1)
    assert by[("dbp2", "drawbar_force")].to_json()["source"] == "estimated"
    lines = stated_noise_lines(statements)
    assert lines[0].startswith("sensor noise stated in the manifest: torque_left 3 in runs dbp1, dbp2 (estimated ")
    assert lines[0].endswith("every other column's is estimated from its samples")
    assert len(lines) == 2, lines     # one warning for the runs alike; torque_right agrees with its estimate
    assert lines[1].startswith("warning: column 'torque_left' of runs dbp1, dbp2: the noise estimated from its samples (")
    assert "under 1/3 of the stated 3: the column is filtered" in lines[1]
    assert stated_noise_lines([s for s in statements if s.source == "estimated"]) == []
    assert noise_statements(load_campaign(tmp_path / "c"), ()) == []


def _with_station_noise(src, dst, sigma: float, seed: int):
    """A copy of the campaign at ``src`` whose pos_x, pos_y and pos_z get white noise of ``sigma``."""
    shutil.copytree(src, dst)
    rng = np.random.default_rng(seed)
    for path in sorted((dst / "runs").glob("*.csv")):
        with open(path, newline="") as f:
            rows = list(csv.reader(f))
        for col in ("pos_x", "pos_y", "pos_z"):
            j = rows[0].index(col)
            for row in rows[1:]:
                if row[j]:
                    row[j] = repr(float(row[j]) + sigma * rng.standard_normal())
        with open(path, "w", newline="") as f:
            csv.writer(f).writerows(rows)
    return load_campaign(dst)


@pytest.fixture(scope="module")
def gnss_campaign(noisy_campaign, tmp_path_factory):
    return _with_station_noise(noisy_campaign.path, tmp_path_factory.mktemp("gnss") / "campaign", STATION_NOISE, 17)


def test_positions_from_a_noisier_station_are_weighed_by_its_noise(gnss_campaign):
    """Each run's scale is estimated from that run alone (a run of this short campaign has 55-88
    station samples, so one estimate scatters by about 20 %); over the runs and the three
    position columns they centre on the station's noise."""
    ratios = []
    for run in gnss_campaign.runs_of_kind("drawbar"):
        targets = prepare_run(gnss_campaign, run).targets
        for column in ("pos_x", "pos_y", "pos_z"):
            expected = STATION_NOISE * (np.sqrt(2.0) if column in INCREMENT_SIGNALS else 1.0)
            ratios.append(targets[column][3] / expected)
        for column in ("torque_left", "torque_right"):     # the motor current is the paper's
            assert targets[column][3] < 1.3 * JOINT_SIGNALS[column][1], (run.id, column)
    say("estimated over nominal station noise: " + ", ".join(f"{r:.2f}" for r in ratios))
    assert np.median(ratios) == pytest.approx(1.0, rel=0.15)
    assert all(0.5 < r < 2.0 for r in ratios)


def test_the_joint_fit_of_a_campaign_with_a_noisier_station_still_covers_the_truth(harness_fmu, gnss_campaign,
                                                                                    noisy_campaign):
    result = identify_joint(harness_fmu, gnss_campaign)
    for k, truth in noisy_campaign.soil.items():
        z = (result.params[k] - truth) / result.std[k]
        say(f"{k}: fitted {result.params[k]:.5g} +- {result.std[k]:.2g}, truth {truth:.5g}, z {z:+.2f}")
        assert abs(z) <= 3.0, f"{k}: the truth is {z:+.1f} reported sigmas from the estimate"
    assert result.cost == pytest.approx(1.0, abs=0.25), "scaled by the sensors' noise, the residuals are about 1"


def test_the_diagnosis_keeps_the_nominal_scales_its_thresholds_are_calibrated_on(gnss_campaign, fmu_path):
    from juno.diagnose.problem import build_problem
    problem = build_problem(gnss_campaign, fmu_path, None, None)
    assert problem.prepared, "the drawbar runs are prepared"
    for prepared in problem.prepared:
        for column, target in prepared.targets.items():
            assert target[3] == JOINT_SIGNALS[column][1], (prepared.run_id, column)
    nominal = prepare_run(gnss_campaign, gnss_campaign.runs_of_kind("drawbar")[0], scales="nominal")
    assert nominal.targets["pos_x"][3] == JOINT_SIGNALS["pos_x"][1]
    with pytest.raises(ValueError, match="unknown residual scales"):
        prepare_run(gnss_campaign, gnss_campaign.runs_of_kind("drawbar")[0], scales="estimated")
