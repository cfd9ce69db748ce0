"""The IMU's mounting as a nuisance of the diagnosis (juno/diagnose/sensor_offset.py): every fit
and every judgement takes a constant offset of the measured pitch off the residuals, one value
for the campaign estimated on the drawbar runs' training blocks, so that no cause is credited
with what a mounting bias explains; what the models report keeps it.

A pitch bias is the same from the first sample, at rest and at any load, in every run alike; a
multi-pass rut pitches the rover only once the rear wheels roll in the front wheels' rut, a
wheelbase after the start, and by as much as the rut, which follows each run's load.  The
campaigns here are built from residuals alone (no FMU): two drawbar runs that measure the pitch
and a drive torque, and a terrain run that measures no pitch, as the diagnosis's terrain runs
do not."""

from __future__ import annotations

import numpy as np

from juno.diagnose.fitting import FitResult, fit_objective
from juno.diagnose.judging import GAIN_MIN, held_out_mse, paired_z, relative_gain, z_threshold
from juno.diagnose.problem import BLOCK, Problem
from juno.diagnose.sensor_offset import mounting_offsets, offset_free
from juno.identify import PreparedRun
from juno.simulator import InputSignals

SAMPLE = 0.05     # s between samples
DURATION = 40.0   # s per run
#: when the rear wheels reach the front wheels' rut in each drawbar run (s), and by how much the
#: rut pitches the rover there (scaled residual): the second run pulls a heavier load
RUT_REACHED = 3.0
RUT_PITCH = {"dbp1": 2.0, "dbp2": 3.5}
#: every pitch sample's bias (scaled residual): a mounting off by 1.2 degrees at 3 mrad of noise
BIAS = 7.0


def _campaign() -> tuple[Problem, np.ndarray, np.ndarray, np.ndarray]:
    """The problem, each residual's kind of run, and masks of its pitch residuals and of the
    pitch's time since its run started (NaN elsewhere)."""
    t = np.arange(0.0, DURATION, SAMPLE)
    runs, kinds, signals, times = [], [], [], []
    prepared = []
    for run, kind, columns in (("dbp1", "drawbar", ("torque_left", "pitch")),
                               ("dbp2", "drawbar", ("torque_left", "pitch")),
                               ("t3d", "terrain", ("torque_left", "pos_x"))):
        targets = {c: (t, np.zeros(len(t)), c, 1.0, 0.0) for c in columns}
        prepared.append(PreparedRun(run, kind, DURATION, InputSignals(t, {}), {}, targets))
        for c in columns:
            runs += [run] * len(t)
            kinds += [kind] * len(t)
            signals += [c] * len(t)
            times.append(t)
    time = np.concatenate(times)
    block = np.floor(time / BLOCK).astype(int)
    problem = Problem("campaign", None, "unused.fmu", prepared, (block % 2) == 0,
                      {"run": np.array(runs), "signal": np.array(signals), "time": time, "block": block})
    return problem, np.array(kinds), np.array(signals) == "pitch", time


def _rut_pitch(problem: Problem, pitch: np.ndarray, time: np.ndarray) -> np.ndarray:
    """The pitch a multi-pass rut leaves in a model without it: nothing before the rear wheels
    reach the rut, then each run's own amount."""
    out = np.zeros(len(time))
    for run, amount in RUT_PITCH.items():
        mine = pitch & (problem.meta["run"] == run) & (time >= RUT_REACHED)
        out[mine] = amount
    return out


def test_the_campaigns_pitch_offset_is_taken_off_every_pitch_residual_and_nothing_else():
    problem, kinds, pitch, _time = _campaign()
    noise = np.random.default_rng(1).standard_normal(len(kinds))
    r = noise + np.where(pitch, BIAS, 0.0)
    free = offset_free(problem, r)
    training = pitch & problem.train & (kinds == "drawbar")
    assert np.allclose(free[pitch], r[pitch] - r[training].mean())
    assert np.array_equal(free[~pitch], r[~pitch]), "only the pitch is measured against a mounting"
    assert abs(free[pitch].mean()) < 0.1
    assert np.array_equal(r, noise + np.where(pitch, BIAS, 0.0)), "the residuals given are not changed"


def test_the_offset_is_estimated_on_the_training_blocks_alone():
    """What the held-out blocks hold moves nothing of what is taken off: they judge it as they
    judge a fitted parameter."""
    problem, kinds, pitch, _time = _campaign()
    r = np.random.default_rng(2).standard_normal(len(kinds)) + np.where(pitch, BIAS, 0.0)
    moved = r + np.where(pitch & ~problem.train, 5.0, 0.0)
    assert np.allclose(offset_free(problem, moved) - offset_free(problem, r), moved - r)


def test_a_run_the_model_could_not_simulate_stays_lost_and_the_others_are_still_offset():
    problem, kinds, pitch, _time = _campaign()
    r = np.random.default_rng(3).standard_normal(len(kinds)) + np.where(pitch, BIAS, 0.0)
    r[problem.meta["run"] == "dbp2"] = np.nan
    free = offset_free(problem, r)
    assert np.all(np.isnan(free[problem.meta["run"] == "dbp2"]))
    first = pitch & (problem.meta["run"] == "dbp1")
    assert np.allclose(free[first], r[first] - r[first & problem.train].mean())


def test_one_mounting_angle_is_taken_off_runs_whose_pitch_noise_differs():
    """Each run's residuals are scaled by its own pitch noise (estimated from the run where the
    sensor is noisier than the nominal scale), so one angle is a different scaled constant in each
    run.  The offset is that angle (the noise-weighted least-squares constant of the unscaled
    residuals), taken off each run over its own scale: a pure mounting bias leaves nothing in any
    run, where a mean of the scaled residuals would leave a constant of opposite signs in the two."""
    problem, kinds, pitch, _time = _campaign()
    scales = {"dbp1": 0.0049, "dbp2": 0.0056}       # rad: the same IMU's noise estimated in two runs
    bias = 0.023                                     # rad: a mounting off by 1.3 degrees
    for p in problem.prepared:
        if p.kind == "drawbar":
            ts, values, output, _sigma, lag = p.targets["pitch"]
            p.targets["pitch"] = (ts, values, output, scales[p.run_id], lag)
    run = problem.meta["run"]
    r = np.zeros(len(kinds))
    for name, scale in scales.items():
        r[pitch & (run == name)] = bias / scale
    assert set(mounting_offsets(problem, r)) == {"pitch"} and set(mounting_offsets(problem, r)["pitch"]) == {"campaign"}
    assert abs(mounting_offsets(problem, r)["pitch"]["campaign"] - bias) < 1e-15
    assert np.max(np.abs(offset_free(problem, r))) < 1e-12


def test_the_offset_reported_is_the_angle_in_the_pitchs_units_with_its_sign():
    """measured - simulated: an IMU that reads 1.2 degrees nose-up of the model gives +21 mrad,
    whatever the mounting setting (the report says what the residuals hold); on the noise, within
    the mean's own error."""
    problem, kinds, pitch, _time = _campaign()
    scale = 0.003
    for p in problem.prepared:
        if "pitch" in p.targets:
            ts, values, output, _sigma, lag = p.targets["pitch"]
            p.targets["pitch"] = (ts, values, output, scale, lag)
    noise = np.random.default_rng(6).standard_normal(len(kinds))
    r = noise + np.where(pitch, BIAS, 0.0)
    n = int(np.sum(pitch & problem.train & (kinds == "drawbar")))
    assert abs(mounting_offsets(problem, r)["pitch"]["campaign"] - BIAS * scale) < 4 * scale / np.sqrt(n)
    problem.pitch_offset_free = False
    assert mounting_offsets(problem, r) == mounting_offsets(problem, offset_free(problem, r))
    problem.prepared = [p for p in problem.prepared if p.kind == "terrain"]
    assert mounting_offsets(problem, r[kinds == "terrain"]) == {}


def test_an_imu_mounted_again_between_runs_has_one_offset_per_mounting():
    """The manifest names each run's mounting (imu_mount): runs on one mounting share one angle,
    estimated on their own drawbar training blocks and taken off their residuals alone."""
    problem, kinds, pitch, _time = _campaign()
    problem.imu_mounts = {"dbp1": "day1", "dbp2": "day2", "t3d": "day2"}
    run = problem.meta["run"]
    noise = np.random.default_rng(7).standard_normal(len(kinds))
    r = noise + np.where(pitch & (run == "dbp1"), BIAS, 0.0) + np.where(pitch & (run == "dbp2"), -0.5 * BIAS, 0.0)
    offsets = mounting_offsets(problem, r)["pitch"]
    assert list(offsets) == ["day1", "day2"]
    assert abs(offsets["day1"] - BIAS) < 0.2 and abs(offsets["day2"] + 0.5 * BIAS) < 0.2
    free = offset_free(problem, r)
    for name in ("dbp1", "dbp2"):
        mine = pitch & (run == name)
        assert np.allclose(free[mine], r[mine] - r[mine & problem.train].mean())
    # the one campaign offset would leave each run a constant of half the two biases' difference
    problem.imu_mounts = {}
    assert abs(offset_free(problem, r)[pitch & (run == "dbp1")].mean()) > 0.7 * BIAS


def test_with_a_calibrated_mounting_no_offset_is_taken_off():
    """A campaign whose manifest says the IMU's mounting is calibrated (Problem.pitch_offset_free
    False, from Campaign.imu_mounting) keeps every pitch residual: its pitch is evidence."""
    problem, kinds, pitch, _time = _campaign()
    problem.pitch_offset_free = False
    r = np.random.default_rng(2).standard_normal(len(kinds)) + np.where(pitch, BIAS, 0.0)
    assert np.array_equal(offset_free(problem, r), r)


def test_a_problem_without_a_pitch_is_left_as_it_is():
    problem, kinds, pitch, _time = _campaign()
    problem.prepared = [p for p in problem.prepared if p.kind == "terrain"]
    r = np.arange(np.sum(kinds == "terrain"), dtype=float)
    assert np.array_equal(offset_free(problem, r), r)


def test_a_model_that_explains_only_a_constant_pitch_is_credited_with_nothing():
    """The reference leaves a mounting bias in every pitch sample; a candidate whose residuals
    lack it (a rut bent to pitch the rover from the start) is no better once the bias is taken
    off both: no held-out gain, no paired evidence, and the same training objective."""
    problem, kinds, pitch, _time = _campaign()
    noise = np.random.default_rng(4).standard_normal(len(kinds))
    reference, candidate = noise + np.where(pitch, BIAS, 0.0), noise
    everywhere = np.ones(len(kinds), bool)
    assert relative_gain(problem, reference, candidate, everywhere) == 0.0
    assert paired_z(problem, reference, candidate, kinds == "drawbar") == 0.0
    assert held_out_mse(problem, reference, everywhere) == held_out_mse(problem, candidate, everywhere)
    fits = [FitResult(n, {}, 1.0, 1.0, r, 1, 0.0) for n, r in (("base", reference), ("multipass", candidate))]
    assert fit_objective(problem, kinds, fits[0]) == fit_objective(problem, kinds, fits[1])


def test_a_model_that_explains_a_pitch_that_starts_with_the_rut_and_follows_the_load_is_credited():
    """A multi-pass rut is no mounting: its pitch starts when the rear wheels reach the rut and
    differs from run to run with the load.  What of it a constant cannot take off stays in the
    reference's residuals, and the candidate that makes it is credited, on top of the bias both
    leave, by more than the two parameters of a multi-pass must buy."""
    problem, kinds, pitch, time = _campaign()
    noise = np.random.default_rng(5).standard_normal(len(kinds))
    biased = noise + np.where(pitch, BIAS, 0.0)
    reference, candidate = biased + _rut_pitch(problem, pitch, time), biased
    assert relative_gain(problem, reference, candidate, np.ones(len(kinds), bool)) > 2 * GAIN_MIN
    assert paired_z(problem, reference, candidate, kinds == "drawbar") > z_threshold(2)
