"""Residual structure: what a model's held-out residuals still contain beyond sensor noise.

The test is run at the true soil of a synthetic campaign, so that what it finds is only what was
put into the data: nothing when the data is the model's own, and the planted discrepancy, with
what it follows, when a sensor or the rover does something no model here knows.
"""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from juno.campaign import load_campaign
from juno.identify import prepare_run, run_residuals
from juno.residual_structure import MATERIAL_FRACTION, REPLICAS, residual_labels, residual_structure
from juno.sensor_noise import column_noise
from juno.rover_model import SOIL_PARAMETERS

from harness_fixtures import NOISY_SEED, NOISY_TIME_SCALE, make_campaign

pytest_plugins = ["harness_fixtures"]

BLOCK = 4.0
STEP = 5e-3


def _offset_columns(src: Path, dst: Path, offsets: dict[str, float]) -> Path:
    """A copy of campaign ``src`` in ``dst`` with a constant added to every sample of some columns."""
    shutil.copytree(src, dst)
    for path in (dst / "runs").glob("*.csv"):
        with path.open(newline="") as f:
            rows = list(csv.reader(f))
        header = rows[0]
        for column, offset in offsets.items():
            if column in header:
                i = header.index(column)
                for row in rows[1:]:
                    if row[i] != "":
                        row[i] = repr(float(row[i]) + offset)
        with path.open("w", newline="") as f:
            csv.writer(f).writerows(rows)
    return dst


def _structure_at_truth(root: Path, fmu, soil: dict[str, float], seed: int = 3, workers: int = 1,
                        replicas: int = REPLICAS):
    """The structure test of the drawbar runs of the campaign at ``root`` at the soil ``soil``
    (and any other FMU parameters in it), with the alternating 4 s training / held-out blocks the
    diagnosis uses, its ``replicas`` simulated in ``workers`` processes."""
    campaign = load_campaign(root)
    prepared = [prepare_run(campaign, run) for run in campaign.runs_of_kind("drawbar")]
    for p in prepared:
        p.params["solver.step"] = STEP
    meta = residual_labels(prepared, BLOCK)
    train = meta["block"] % 2 == 0
    r = np.concatenate([run_residuals(fmu, p, soil, {}, 0.05) for p in prepared])
    return residual_structure(campaign, fmu, prepared, meta, train, r, dict(soil), seed=seed, workers=workers,
                              replicas=replicas)


def _signal(result, name):
    return next(s for s in result.signals if s.signal == name)


def test_white_noise_sigma_is_recovered_from_a_smooth_signal_plus_noise():
    rng = np.random.default_rng(11)
    t = np.arange(0.0, 30.0, 0.02)
    values = 40.0 + 5.0 * np.sin(0.3 * t) + 2.0 * t + 1.7 * rng.standard_normal(len(t))
    assert column_noise(t, values) == pytest.approx(1.7, rel=0.08)


def test_the_models_own_data_has_no_structure(noisy_campaign, harness_fmu):
    result = _structure_at_truth(noisy_campaign.path, harness_fmu, noisy_campaign.soil)
    assert result.signals, "no signal was tested"
    assert not result.significant, [s.to_json() for s in result.signals if s.significant]
    for s in result.signals:
        assert s.noise > 0 and np.isfinite(s.p_value)


def test_a_lug_ripple_the_grouser_leaves_is_reported_at_18_per_revolution(harness_fmu, tmp_path):
    """A campaign hiding the lug_ripple form replayed with the catalog grouser's true thrust (what
    the grouser candidate fits): the drive torques still ripple with the wheel angle at the 18
    lugs per revolution, which the block means cannot show; the periodic part of the test
    reports it on both sides (the block-mean part is left to the tests above: few replicas)."""
    c = make_campaign(tmp_path / "ripple", harness_fmu, NOISY_SEED, 1.0, NOISY_TIME_SCALE, effect="lug_ripple")
    hidden = c.truth["hidden"]["sim"]
    grouser = {k: hidden[k] for k in ("grouser.thrustGain", "grouser.lugHeight")}
    result = _structure_at_truth(c.path, harness_fmu, {**c.soil, **grouser}, replicas=3)
    assert result.significant
    ripples = result.ripples()
    assert sorted(r.signal for r in ripples) == ["torque_left", "torque_right"]
    assert all(r.lugs == hidden["grouser.lugCount"] and r.ratio > 1.0 for r in ripples)
    assert result.to_json()["periodic"]["signals"][0]["per_revolution"] == 18


def test_a_pitch_bias_is_structure_in_pitch_that_follows_a_constant(noisy_campaign, harness_fmu, tmp_path):
    bias = float(np.radians(1.0))
    root = _offset_columns(noisy_campaign.path, tmp_path / "campaign", {"pitch": bias})
    result = _structure_at_truth(root, harness_fmu, noisy_campaign.soil)
    pitch = _signal(result, "pitch")
    assert pitch.significant and pitch.ratio > 2 * MATERIAL_FRACTION
    assert pitch.follows and pitch.follows[0].name == "constant"
    assert pitch.follows[0].slope == pytest.approx(bias, rel=0.1)
    assert [s.signal for s in result.structured()] == ["pitch"]


def test_a_drag_on_the_left_wheels_follows_the_side(noisy_campaign, harness_fmu, tmp_path):
    drag = 8.0   # N m more measured on the left than the wheels need
    root = _offset_columns(noisy_campaign.path, tmp_path / "campaign", {"torque_left": drag})
    result = _structure_at_truth(root, harness_fmu, noisy_campaign.soil)
    left = _signal(result, "torque_left")
    assert left.significant
    side = next(c for c in left.follows if c.name == "side")
    assert side.slope == pytest.approx(drag, rel=0.15)
    assert not _signal(result, "torque_right").significant


def test_the_test_is_deterministic_for_a_seed_wherever_its_replicas_run(noisy_campaign, harness_fmu):
    """The same seed gives the same test, its replicas simulated here or in two worker processes
    (the noise is drawn before any replay is simulated)."""
    a = _structure_at_truth(noisy_campaign.path, harness_fmu, noisy_campaign.soil, seed=5)
    b = _structure_at_truth(noisy_campaign.path, harness_fmu, noisy_campaign.soil, seed=5, workers=2)
    assert a.to_json() == b.to_json()


def test_the_soil_enters_only_through_the_given_parameters(noisy_campaign, harness_fmu):
    """A soil far from the truth leaves structure in the torques: the test looks at the model
    it is given, not at the data alone."""
    wrong = {k: v for k, v in noisy_campaign.soil.items()}
    wrong["soil.Kvx"] = noisy_campaign.soil["soil.Kvx"] * 3.0
    result = _structure_at_truth(noisy_campaign.path, harness_fmu, wrong)
    assert set(SOIL_PARAMETERS) <= set(wrong)
    assert result.significant
    assert {"torque_left", "torque_right"} & {s.signal for s in result.structured()}


def test_exact_measurements_leave_the_replays_own_error_below_its_floor(clean_campaign, harness_fmu):
    """Sensors without noise: the test resolves what the replay itself leaves (its spin-following
    drive against the truth's motors, the fit's tolerance), many times the noise estimated from
    such columns, but no more than a right model leaves on exact measurements: no structure,
    each resolved signal listed below a floor that is the replay's fidelity."""
    from juno.identify import identify_joint
    fit = identify_joint(harness_fmu, clean_campaign.campaign, workers=1)
    assert fit.structure is not None and not fit.structure["significant"], \
        [s for s in fit.structure["signals"] if s["significant"]]
    below = [s for s in fit.structure["signals"] if s["resolved"]]
    assert below, "exact measurements should let the test resolve the replay's own error"
    assert all(s["floor_is_fidelity"] and s["structure_rms"] < s["floor"] for s in below), below
    assert not any("structure beyond sensor noise" in d for d in fit.doubts), fit.doubts


@pytest.mark.parametrize("design", ["default", "alt"])
def test_at_the_designs_sensors_the_floor_is_the_calibrated_fraction_of_their_noise(design):
    """The replay's fidelity sets the floor only for sensors much quieter than the synthetic
    designs': at the designs' own noise (the least a column has: its constant part) the floor is
    the fraction of the noise the calibration at that noise set."""
    from juno.residual_structure import floor_is_fidelity, material_fraction, materiality_floor
    from juno.synthetic_design import DESIGNS
    for sensor in DESIGNS[design].sensors:
        if sensor.column not in ("torque_left", "torque_right", "pitch", "pos_x", "pos_y", "pos_z"):
            continue
        noise = sensor.sigma * (np.sqrt(2.0) if sensor.column in ("pos_x", "pos_y") else 1.0)
        assert not floor_is_fidelity(sensor.column, noise), sensor
        assert materiality_floor(sensor.column, noise) == material_fraction(sensor.column) * noise
        assert materiality_floor(sensor.column, 0.0) > 0.0


def test_the_floors_lie_above_every_right_model_of_the_calibration():
    """The calibration's campaigns with nothing hidden (docs/results/structure-calibration.json,
    written by scripts/structure_calibration.py): at the designs' noise every signal's structure
    stays under its fraction of the noise, and on exact measurements under REPLAY_FIDELITY, the
    replay's fidelity the floors are never below; the calibration covers both."""
    import json
    from juno.residual_structure import REPLAY_FIDELITY, material_fraction
    path = Path(__file__).resolve().parents[2] / "docs" / "results" / "structure-calibration.json"
    cases = json.loads(path.read_text())["cases"]
    noisy = [c for c in cases if c["noise"] > 0]
    exact = [c for c in cases if c["noise"] == 0]
    assert {c["design"] for c in noisy} == {c["design"] for c in exact} == {"default", "alt"}
    for c in noisy:
        assert all(r < material_fraction(s) for s, r in c["ratios"].items()), c
    for c in exact:
        assert all(rms <= REPLAY_FIDELITY[s] for s, rms in c["structure_rms"].items()), c


# ------------------------------------------------------------ the joint identification's doubts

def test_a_joint_fit_of_the_models_own_data_has_no_doubts(noisy_campaign, harness_fmu):
    from juno.identify import identify_joint
    fit = identify_joint(harness_fmu, noisy_campaign.campaign, workers=1)
    assert fit.doubts == [], fit.doubts
    assert fit.structure is not None and not fit.structure["significant"]


def test_a_pitch_bias_is_the_joint_fits_mounting_offset_not_a_bent_soil(noisy_campaign, harness_fmu, tmp_path):
    """With the IMU's mounting free (the manifest's default), the fit takes the pitch's constant
    offset as a free parameter of the instrument: the bias comes back as the offset, the soil is
    the fit's of the data without it (to a small part of its uncertainty: the biased samples are
    written to the file's digits, so the two fits' paths differ by rounding), and nothing is left
    to doubt."""
    from juno.identify import identify_joint
    bias = float(np.radians(1.5))
    plain = identify_joint(harness_fmu, noisy_campaign.campaign, workers=1)
    root = _offset_columns(noisy_campaign.path, tmp_path / "campaign", {"pitch": bias})
    fit = identify_joint(harness_fmu, load_campaign(root), workers=1)
    assert fit.pitch_offset_free and fit.pitch_offset["campaign"] == pytest.approx(plain.pitch_offset["campaign"] + bias,
                                                                                   abs=1e-4)
    for k, v in plain.params.items():
        assert abs(fit.params[k] - v) < 0.25 * plain.std[k], (k, fit.params[k], v, plain.std[k])
    assert fit.doubts == [], fit.doubts


def test_a_joint_fit_of_data_with_a_pitch_bias_and_a_calibrated_mounting_is_doubtful(noisy_campaign, harness_fmu,
                                                                                     tmp_path):
    """Where the manifest says the IMU's mounting is calibrated, the fit takes no offset: it bends
    the soil to absorb the bias and its uncertainty says 'pinned'; the structure its residuals
    keep says the estimates are not to be trusted, and the offset they hold is reported."""
    from juno.identify import identify_joint
    bias = float(np.radians(1.5))
    root = _offset_columns(noisy_campaign.path, tmp_path / "campaign", {"pitch": bias})
    manifest = root / "campaign.json"
    manifest.write_text(json.dumps({**json.loads(manifest.read_text()), "imu_mounting": "calibrated"}))
    fit = identify_joint(harness_fmu, load_campaign(root), workers=1)
    assert not fit.pitch_offset_free
    assert any("structure beyond sensor noise" in d for d in fit.doubts), fit.doubts
    assert fit.structure["significant"]
    assert 0.0 < fit.pitch_offset["campaign"] < bias


def test_a_parameter_at_a_bound_of_the_search_is_a_doubt(noisy_campaign, harness_fmu):
    from juno.identify import JointResult, fit_doubts
    campaign = noisy_campaign.campaign
    prepared = [prepare_run(campaign, run) for run in campaign.runs_of_kind("drawbar")]
    soil = {**noisy_campaign.soil, "soil.Kvx": 100.0}      # the search's upper bound of K_vx
    result = JointResult(soil, {}, {}, np.eye(4), {}, 1.0, 1, 0.0)
    doubts, _structure = fit_doubts(harness_fmu, campaign, prepared, result)
    assert any(d.startswith("soil.Kvx") and "upper bound" in d for d in doubts), doubts
    assert not any(d.startswith(("soil.kh", "soil.eta", "soil.gamma")) for d in doubts)


# ------------------------------------------------------------ the materiality floor per signal

def _signal_with_offset(signal: str, offset: float, noise: float = 5.5, seed: int = 2):
    """One signal's test (residual_structure._test_signal) over 13 held-out blocks of 4 drawbar
    runs: each block mean that of 80 samples of white noise (scaled residuals, sigma 1; the
    signal's sensor noise ``noise`` in its units, a position's compared increment included)
    shifted by ``offset`` in the signal's units; the null from 20 replicas of the noise alone."""
    from juno.residual_structure import _test_signal, _Units
    rng = np.random.default_rng(seed)
    k, replicas = 13, 20
    runs = np.array([f"dbp{1 + i % 4}" for i in range(k)])
    units = _Units(np.arange(k), np.arange(k), runs, np.array([signal] * k), np.arange(k), 4.0 * np.arange(k))
    block_sd = 1.0 / np.sqrt(80.0)
    observed = block_sd * rng.standard_normal(k) + offset / noise
    null = block_sd * rng.standard_normal((replicas, k))
    sensor = {(r, signal): noise / (np.sqrt(2.0) if signal in ("pos_x", "pos_y") else 1.0) for r in set(runs)}
    covariates = {"time": (units.unit_time, "s")}
    return _test_signal(signal, units, observed, null, sensor, {signal: noise}, covariates,
                        {signal: observed}, 6)


def test_a_torque_offset_of_two_thirds_of_its_noise_is_structure_but_not_in_a_position():
    """A right model leaves at most 0.15 of the sensor noise in the torques and the pitch
    (docs/results/structure-calibration.md), but up to half of it in the positions, whose replayed
    path drifts: the torques' and pitch's floor is MATERIAL_FRACTION_CONTACT, the positions'
    MATERIAL_FRACTION.  A 3.7 N m offset on a 5.5 N m torque sensor (what a 9 N m drag on one
    side leaves on the alternative design) is structure; the same ratio in pos_x is not."""
    from juno.residual_structure import MATERIAL_FRACTION_CONTACT, material_fraction
    assert material_fraction("torque_left") == material_fraction("pitch") == MATERIAL_FRACTION_CONTACT
    assert material_fraction("pos_x") == material_fraction("pos_z") == MATERIAL_FRACTION > MATERIAL_FRACTION_CONTACT
    torque = _signal_with_offset("torque_left", 3.7)
    assert torque.p_value < 1e-10 and MATERIAL_FRACTION_CONTACT < torque.ratio < MATERIAL_FRACTION
    assert torque.significant and torque.follows[0].name == "constant"
    position = _signal_with_offset("pos_x", 3.7)
    assert position.ratio == pytest.approx(torque.ratio, rel=1e-9) and position.p_value < 1e-10
    assert not position.significant
    # Below the torques' floor, however clear statistically, it is not structure either; it is
    # resolved (told from noise), with the constant it follows, for the verdict to list.
    small = _signal_with_offset("torque_left", 2.0)
    assert small.p_value < 1e-10 and small.ratio < MATERIAL_FRACTION_CONTACT and not small.significant
    assert small.resolved and small.follows[0].name == "constant"
    assert position.resolved and torque.resolved
    assert not _signal_with_offset("torque_left", 0.0).resolved


# ------------------------------------------------------------ the findings in words

def test_the_findings_are_said_once_each_structure_then_ripples_then_offsets():
    """What a structure test found, in the one wording the diagnosis's verdict, its progress line
    and the joint identification's doubts share: the signals with structure (largest first), then
    the ripples in the wheel angle, then the time offsets; what is not significant is not said."""
    from juno.periodic_structure import PeriodicSignal, PeriodicStructure
    from juno.residual_structure import Covariate, ResidualStructure, SignalStructure
    from juno.timing_structure import SignalOffset, TimingStructure

    def structure(signal: str, ratio: float, significant: bool) -> SignalStructure:
        return SignalStructure(signal, "N m", 13, 3.0, 3.0 * ratio, ratio, 1e-4, significant,
                               [Covariate("slip", 0.8, 12.0, "N m per unit slip")])
    ripple = PeriodicSignal("torque_left", "N m", 12, 2.0, 3.0, 0.47, 1e-5, True, (3, 40), ["dbp1"])
    test = ResidualStructure([structure("torque_left", 0.4, True), structure("pos_x", 0.2, False),
                              structure("torque_right", 0.9, True)], 0.001, 20, ["dbp1"],
                             PeriodicStructure([ripple], 0.01),
                             TimingStructure([SignalOffset("pos_x", 0.2, 0.04, 1e-4, True, 400),
                                              SignalOffset("pos_y", 0.01, 0.04, 0.6, False, 400)], 0.0033))
    said = test.findings()
    assert said == [test.signals[2].sentence(), test.signals[0].sentence(), ripple.sentence(),
                    test.timing.signals[0].sentence()]
    assert said[0].startswith("torque_right 2.7 N m RMS (0.9 x its sensor noise), following slip")
    assert "lags the replay by 0.2 s" in said[3]
    assert test.findings(brief=True) == ["torque_right (0.9 x noise)", "torque_left (0.4 x noise)",
                                         "torque_left ripple at 12 per wheel revolution (0.47 x noise)",
                                         "pos_x offset +0.2 s from the inputs"]
    quiet = ResidualStructure([structure("pos_x", 0.2, False)], 0.001, 20, ["dbp1"])
    assert quiet.findings() == [] and quiet.findings(brief=True) == []


def test_the_search_finds_a_lug_ripple_in_the_base_models_torques_before_it_ranks_the_causes(
        harness_fmu, fmu_path, noisy_campaign, tmp_path):
    """The diagnosis weighs a ripple in the wheel angle between causes (judging.ripple_maker_leads),
    so it tests the base model's held-out drive torques for one before it ranks them
    (search.wheel_angle_ripple): no simulation beyond the model's own residuals.  On the
    lug_ripple campaign, replayed at the true soil with no extension (the base model), it finds
    the 18 lugs on both sides and says so; on the campaign with nothing hidden it finds none."""
    from juno.diagnose import FitResult, build_problem
    from juno.diagnose.problem import all_residuals
    from juno.diagnose.search import Search, wheel_angle_ripple

    ripple = make_campaign(tmp_path / "ripple", harness_fmu, NOISY_SEED, 1.0, NOISY_TIME_SCALE, effect="lug_ripple")
    for c, expect in ((ripple, ["torque_left", "torque_right"]), (noisy_campaign, [])):
        problem = build_problem(c.campaign, fmu_path, None)
        said: list[str] = []
        search = Search(c.campaign, problem, {}, None, 1, None, said.append)
        base = FitResult("base", dict(c.soil), 1.0, 1.0, all_residuals(harness_fmu, problem, dict(c.soil)), 1, 0.0)
        found = wheel_angle_ripple(search, base)
        assert found is not None
        assert sorted(s.signal for s in found.found()) == expect
        assert all(s.lugs == 18 for s in found.found())
        assert bool(said) == bool(expect)
        if expect:
            assert "ripple at 18 per wheel revolution" in said[0]
