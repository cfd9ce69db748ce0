"""Synthetic campaigns the diagnosis was not shaped on: alternative forms, decoys, another design.

Specification:
* every alternative form of a catalog effect and every decoy is hidden in the data (the measured
  files differ from the no-effect campaign of the same seed) without changing the campaign's
  layout, the campaign loads with juno's reader and raises no plausibility finding, and
  truth.json says what it is: ``in_catalog`` false for a decoy, the catalog cause it resembles
  and ``exact_form`` false for an alternative form;
* each acts as documented (juno.effects): the IMU pitch bias shifts every pitch sample and nothing
  else; the clock offset shifts the IMU and total-station samples in time and leaves the motor
  clock's alone; the left-side drag makes the left motor work harder and turns the rover; the
  drivetrain friction raises the motor torque on both sides; the scan tilt raises the scan by
  its slope times the distance from the axis and moves no point sideways; the soil strip
  weakens the soil inside the strip only; the square-root slip-sinkage sinks deeper than the
  linear law; the grouser thrust that builds up with slip helps less than the full gain; a
  deeper rut for half compaction stiffens the rear wheels' soil less; the lug ripple keeps the
  catalog grouser's mean torque and makes the measured torque pulse at the lug-passing
  frequency;
* ``design="alt"``: four drawbar runs, clocks not at zero with the steady windows inside the
  runs, the columns in another order with an unused ``battery_voltage``, another terrain and
  throttle, loaded and plausible as they are;
* an alt design with a heavy run, an unknown design and two effects that set the same parameter
  are refused before anything is written.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from harness_fixtures import run_juno
from juno.campaign import load_campaign, read_run, read_terrain_points, steady_average
from juno.effects import ALTERNATIVE_FORMS, ALTERNATIVE_OF, DECOYS, EFFECT_INFO, LUG_COUNT
from juno.plausibility import check_campaign
from juno.rover_model import rover
from juno.simulator import InputSignals
from juno.synthesize import TABLE2, steady_slip, synthesize

pytest_plugins = ["harness_fixtures"]

#: Runs of 5.5-8.8 s (default design), enough for every effect to show.
TIME_SCALE = 0.25
SEED = 4301
NEW_EFFECTS = list(ALTERNATIVE_FORMS) + list(DECOYS)


@pytest.fixture(scope="module")
def campaigns(tmp_path_factory, harness_fmu):
    """Factory of short campaigns of seed SEED, cached per (effect, strength, noise, design)."""
    cache: dict[tuple, Path] = {}

    def get(effect: str = "none", strength: float = 1.0, noise: float = 1.0, design: str = "default") -> Path:
        key = (effect, strength, noise, design)
        if key not in cache:
            parent = tmp_path_factory.mktemp(f"forms-{effect}-{design}")
            cache[key] = synthesize(parent / "campaign", effect=effect, strength=strength, seed=SEED, noise=noise,
                                    fmu=harness_fmu, time_scale=TIME_SCALE, design=design)
        return cache[key]
    return get


def truth_of(root: Path) -> dict:
    return json.loads((root / "truth.json").read_text())


def run_of(root: Path, run_id: str):
    campaign = load_campaign(root)
    return read_run(campaign, campaign.run(run_id))


def header(root: Path, run_id: str) -> list[str]:
    return (root / "runs" / f"{run_id}.csv").read_text().splitlines()[0].split(",")


# ------------------------------------------------------------------ every new effect

@pytest.mark.parametrize("effect", NEW_EFFECTS)
def test_each_new_effect_is_hidden_in_the_data_and_the_campaign_is_plausible(campaigns, effect):
    none, hidden = campaigns(), campaigns(effect)
    # the layout does not depend on the truth; the data do
    assert (hidden / "campaign.json").read_bytes() == (none / "campaign.json").read_bytes()
    data = ["runs/dbp1.csv", "runs/dbp2.csv", "runs/dbp3.csv", "runs/t3d.csv", "terrain/scan.xyz"]
    changed = [rel for rel in data if (hidden / rel).read_bytes() != (none / rel).read_bytes()]
    assert changed, f"{effect} changed no measured data"
    for rel in data:
        assert (hidden / rel).read_text().splitlines()[0] == (none / rel).read_text().splitlines()[0]
    # juno's reader and its plausibility checks take it as it is (no --force)
    assert [str(f) for f in check_campaign(load_campaign(hidden))] == []
    # the truth says what kind of effect it is
    (record,) = truth_of(hidden)["effects"]
    assert record["effect"] == effect and record["exact_form"] is False
    if effect in DECOYS:
        assert record["in_catalog"] is False and record["catalog_cause"] is None
        assert EFFECT_INFO[effect].in_catalog is False
    else:
        assert record["in_catalog"] is True and record["catalog_cause"] == ALTERNATIVE_OF[effect]
    assert truth_of(hidden)["extension"] == {}, "no extended model reproduces an effect outside the catalog's forms"


def test_every_catalog_effect_and_every_forms_mechanism_has_a_diagnosis_candidate():
    """The catalog is the diagnosis's: each catalog effect (but none) is a candidate of the same
    name, each alternative form's mechanism one of them, and no decoy is one; so a right answer
    is always a name the diagnosis can give, and a decoy never is."""
    from juno.diagnose.candidates import CANDIDATES
    from juno.effects import EFFECTS

    names = set(CANDIDATES)
    assert set(EFFECTS) - {"none"} == names
    assert set(ALTERNATIVE_OF.values()) <= names and set(ALTERNATIVE_OF) == set(ALTERNATIVE_FORMS)
    assert not set(DECOYS) & names
    assert all(not EFFECT_INFO[d].in_catalog for d in DECOYS)


def test_catalog_effects_keep_their_truth_file_as_it_was(campaigns):
    """A catalog effect's truth.json has no keys beyond the ones it always had."""
    truth = truth_of(campaigns("drivetrain_loss"))
    assert set(truth) == {"effect", "strength", "effects", "seed", "noise", "soil", "extension"}
    assert truth["effects"] == [{"effect": "drivetrain_loss", "strength": 1.0}]


# ------------------------------------------------------------------ decoys act as documented

def test_imu_pitch_bias_shifts_every_pitch_sample_by_the_bias_and_nothing_else(campaigns):
    none, biased = campaigns(), campaigns("imu_pitch_bias")
    bias = truth_of(biased)["hidden"]["distortion"]["imu.pitchBias"]
    assert abs(np.degrees(bias)) == pytest.approx(1.5)
    for run_id in ("dbp1", "dbp2", "dbp3", "t3d"):
        a, b = run_of(none, run_id), run_of(biased, run_id)
        for name in a.columns:
            if name == "pitch":
                ok = ~np.isnan(a[name])
                assert np.allclose(b[name][ok] - a[name][ok], bias, rtol=0, atol=1e-12), run_id
            else:
                np.testing.assert_array_equal(a[name], b[name], err_msg=f"{run_id} {name}")


def test_clock_offset_delays_the_imu_and_total_station_samples_not_the_motor_clock(campaigns):
    """Without noise and at strength 0.8 (0.2 s, a whole number of IMU and total-station
    sample periods): the offset run's IMU or total-station sample at t is the no-effect run's at
    t - offset; torque, spin and drawbar force are the same samples."""
    none, offset = campaigns(noise=0.0), campaigns("clock_offset", strength=0.8, noise=0.0)
    shift = truth_of(offset)["hidden"]["distortion"]["clock.offset"]
    assert abs(shift) == pytest.approx(0.2)
    a, b = run_of(none, "dbp2"), run_of(offset, "dbp2")
    for name in ("torque_left", "torque_right", "omega_left", "omega_right", "drawbar_force"):
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)
    for name in ("pitch", "roll", "pos_x", "pos_z"):
        ta, va = a.samples(name)
        tb, vb = b.samples(name)
        np.testing.assert_array_equal(ta, tb)       # the same stamps ...
        inside = (tb - shift >= ta[0]) & (tb - shift <= ta[-1])
        expected = np.interp(tb[inside] - shift, ta, va)
        assert np.allclose(vb[inside], expected, rtol=0, atol=1e-9), name   # ... of other moments
    assert np.ptp(b.samples("pos_x")[1] - a.samples("pos_x")[1]) > 0.01, "the offset moved no sample"


def test_side_drag_makes_the_left_motor_work_harder_and_turns_the_rover(campaigns):
    none, drag = campaigns(noise=0.0), campaigns("side_drag", noise=0.0)
    assert truth_of(drag)["hidden"]["sim"] == {"drive.frictionLeft": pytest.approx(10.0)}
    spec = load_campaign(drag).run("dbp2")
    for root, lo, hi in ((none, -0.5, 0.5), (drag, 4.0, 20.0)):
        run = run_of(root, "dbp2")
        excess = steady_average(run, "torque_left", spec.steady_window) - \
            steady_average(run, "torque_right", spec.steady_window)
        assert lo < excess < hi, (root, excess)
    run = run_of(drag, "dbp2")
    assert steady_average(run, "omega_left", spec.steady_window) < steady_average(run, "omega_right", spec.steady_window)
    assert abs(run.samples("yaw")[1][-1]) > 0.01, "a drag on one side turns the rover"


def test_drivetrain_friction_raises_the_motor_torque_on_both_sides(campaigns):
    none, friction = campaigns(noise=0.0), campaigns("drivetrain_friction", noise=0.0)
    spec = load_campaign(none).run("dbp2")
    for side in ("torque_left", "torque_right"):
        more = steady_average(run_of(friction, "dbp2"), side, spec.steady_window) - \
            steady_average(run_of(none, "dbp2"), side, spec.steady_window)
        assert more > 5.0, (side, more)


def test_terrain_tilt_raises_the_scan_by_the_tilt_and_moves_no_point_sideways(campaigns):
    none, tilted = campaigns(), campaigns("terrain_tilt")
    d = truth_of(tilted)["hidden"]["distortion"]
    assert abs(np.degrees(d["scan.tiltAngle"])) == pytest.approx(1.0)
    a = read_terrain_points(load_campaign(none), "t3d")
    b = read_terrain_points(load_campaign(tilted), "t3d")
    np.testing.assert_array_equal(a[:, :2], b[:, :2])
    across = -(a[:, 0] - d["scan.tiltX"]) * np.sin(d["scan.tiltAxis"]) + a[:, 1] * np.cos(d["scan.tiltAxis"])
    assert np.allclose(b[:, 2] - a[:, 2], np.tan(d["scan.tiltAngle"]) * across, rtol=0, atol=1e-9)
    assert np.ptp(b[:, 2] - a[:, 2]) > 0.05, "a 1 degree tilt over the test area is centimetres"
    # the world is untouched: the runs are the same samples
    assert (tilted / "runs/t3d.csv").read_bytes() == (none / "runs/t3d.csv").read_bytes()


def test_scan_scale_moves_every_scanned_point_along_its_line_from_the_scanner(campaigns):
    """A range scale error: every point of the scan lies on the line from the scanner through where
    the point really is, its distance from the scanner off by the same factor (3 % at strength 1);
    the runs are untouched."""
    none, scaled = campaigns(), campaigns("scan_scale")
    d = truth_of(scaled)["hidden"]["distortion"]
    assert abs(d["scan.scale"]) == pytest.approx(0.03)
    scanner = np.array([d["scan.scannerX"], d["scan.scannerY"], d["scan.scannerZ"]])
    a = read_terrain_points(load_campaign(none), "t3d") - scanner
    b = read_terrain_points(load_campaign(scaled), "t3d") - scanner
    np.testing.assert_allclose(b, (1.0 + d["scan.scale"]) * a, rtol=0, atol=1e-9)
    assert np.max(np.hypot(*(b - a)[:, :2].T)) > 0.2, "3 % of the test area's 10 m is decimetres"
    assert (scaled / "runs/t3d.csv").read_bytes() == (none / "runs/t3d.csv").read_bytes()


# ------------------------------------------------------------------ the FMU forms

def _flat_run(fmu, extra: dict, load: float = 300.0, duration: float = 8.0, throttle: float = 0.45) -> dict:
    t = np.arange(0.0, duration + 1e-9, 0.05)
    inputs = InputSignals(t, {"drawbarForce": load * np.clip(t / 2.0, 0.0, 1.0),
                              "throttleLeft": np.full(len(t), throttle), "throttleRight": np.full(len(t), throttle)})
    params = {**TABLE2, "drive.mode": 2, "solver.step": 1e-3, "solver.tolerance": 0.0, **extra}
    return fmu.simulate(params, inputs, duration, 0.01,
                        outputs=("x", "wheelFL.sinkage", "wheelRL.sinkage", "wheelFL.slip"))


def test_the_soil_strip_weakens_the_soil_inside_the_strip_only(harness_fmu):
    """A front wheel sinks as on uniform soil until it nears the strip, deeper inside it."""
    geometry = rover()
    strip = {"soilStrip.x": 1.3, "soilStrip.halfWidth": 0.25, "soilStrip.khFactor": 0.4,
             "soilStrip.strengthFactor": 0.6}
    plain, weak = _flat_run(harness_fmu, {}, duration=10.0), _flat_run(harness_fmu, strip, duration=10.0)
    wheel_x = plain["x"] + geometry.wheelbase / 2     # the front wheels' hubs
    assert wheel_x[-1] > 1.3 + 0.25 + geometry.wheel_radius, "the run must cross the strip"
    # before its contact patch (a wheel radius ahead of the hub) comes within 15 cm of the strip
    before = wheel_x + geometry.wheel_radius < 1.3 - 0.25 - 0.15
    assert before.sum() > 50
    np.testing.assert_allclose(weak["wheelFL.sinkage"][before], plain["wheelFL.sinkage"][before], rtol=1e-6, atol=1e-9)
    inside = np.abs(weak["x"] + geometry.wheelbase / 2 - 1.3) < 0.15
    assert inside.sum() > 5
    assert np.all(weak["wheelFL.sinkage"][inside] > 1.2 * plain["wheelFL.sinkage"][inside])


def test_square_root_slip_sinkage_sinks_deeper_than_the_linear_law(harness_fmu):
    """k_h / (1 + c s^0.5) is softer than k_h / (1 + c s) at any slip below 1, the same c."""
    none = _flat_run(harness_fmu, {})
    linear = _flat_run(harness_fmu, {"slipSinkage.coefficient": 1.2})
    root = _flat_run(harness_fmu, {"slipSinkage.coefficient": 1.2, "slipSinkage.exponent": 0.5})
    one = _flat_run(harness_fmu, {"slipSinkage.coefficient": 1.2, "slipSinkage.exponent": 1.0})
    late = none["time"] > 5.0
    assert 0.1 < np.mean(root["wheelFL.slip"][late]) < 0.95
    sink = {k: float(np.mean(r["wheelFL.sinkage"][late])) for k, r in (("none", none), ("linear", linear), ("root", root))}
    assert sink["none"] < sink["linear"] < sink["root"], sink
    np.testing.assert_array_equal(one["wheelFL.sinkage"], linear["wheelFL.sinkage"])   # exponent 1 is the linear law


def test_grouser_thrust_that_builds_up_with_slip_helps_less_than_the_full_gain(harness_fmu):
    """At a held load the rover slips least with the full lug gain, more when the gain builds up
    with slip, most without lugs."""
    base = {**TABLE2, "drive.mode": 2, "solver.step": 1e-3}
    lugs = {"grouser.thrustGain": 0.35, "grouser.lugHeight": 0.025}
    slips = [steady_slip(harness_fmu, {**base, **extra}, 600.0, 0.45)
             for extra in (lugs, {**lugs, "grouser.thrustSlip": 0.15}, {})]
    assert slips[0] < slips[1] < slips[2], slips


def test_a_deeper_rut_for_half_compaction_stiffens_the_rear_wheels_soil_less(harness_fmu):
    """multipass.compactionDepth 2 cm instead of 2 mm: the rear wheel, rolling in the front
    wheel's rut on soil compacted less, sinks deeper below the rut's floor."""
    common = {"multipass.rutFraction": 0.6, "multipass.khFactor": 3.0}
    shallow = _flat_run(harness_fmu, common)
    deep = _flat_run(harness_fmu, {**common, "multipass.compactionDepth": 0.02})
    late = shallow["time"] > 5.0
    assert np.mean(deep["wheelRL.sinkage"][late]) > 1.05 * np.mean(shallow["wheelRL.sinkage"][late])


def _lug_band_peak(root: Path, run_id: str) -> tuple[float, float]:
    """A drawbar run's steady mean of the left motor torque (N m) and the largest amplitude of its
    Hann-windowed spectrum within 0.5 Hz of the lug-passing frequency N omega / (2 pi)."""
    campaign = load_campaign(root)
    spec = campaign.run(run_id)
    run = read_run(campaign, spec)
    t, torque = run.samples("torque_left")
    t_spin, spin = run.samples("omega_left")
    lo, hi = spec.steady_window
    inside = (t >= lo) & (t <= hi)
    torque, dt = torque[inside], float(np.median(np.diff(t)))
    lug_hz = LUG_COUNT * float(np.mean(spin[(t_spin >= lo) & (t_spin <= hi)])) / (2 * np.pi)
    freq = np.fft.rfftfreq(len(torque), dt)
    spectrum = np.abs(np.fft.rfft((torque - torque.mean()) * np.hanning(len(torque))))
    return float(np.mean(torque)), float(spectrum[np.abs(freq - lug_hz) < 0.5].max())


def test_the_lug_ripple_keeps_the_grouser_thrust_and_pulses_the_torque_at_the_lug_frequency(campaigns):
    """Without noise: the lug ripple's drawbar runs take the catalog grouser's mean motor torque
    (within 2 %), and their torque spectrum near N omega / (2 pi), 1.5-3 Hz here and below the 25
    Hz Nyquist frequency of the 50 Hz torque samples, is more than four times the grouser's."""
    grouser, ripple = campaigns("grouser", noise=0.0), campaigns("lug_ripple", noise=0.0)
    assert truth_of(ripple)["hidden"]["sim"]["grouser.lugCount"] == LUG_COUNT
    for run_id in ("dbp1", "dbp2", "dbp3"):
        (mean_g, band_g), (mean_r, band_r) = _lug_band_peak(grouser, run_id), _lug_band_peak(ripple, run_id)
        print(f"\n{run_id}: torque {mean_g:.1f} / {mean_r:.1f} N m, at the lug frequency {band_g:.1f} / {band_r:.1f}")
        assert mean_r == pytest.approx(mean_g, rel=0.02)
        assert band_r > 4.0 * band_g


# ------------------------------------------------------------------ the alternative design

def test_the_alternative_design_is_laid_out_differently_and_reads_as_it_is(campaigns):
    default, alt = campaigns(), campaigns(design="alt")
    campaign = load_campaign(alt)
    drawbar = campaign.runs_of_kind("drawbar")
    assert [r.id for r in drawbar] == ["dbp1", "dbp2", "dbp3", "dbp4"]
    for spec in campaign.runs:
        run = read_run(campaign, spec)
        assert run.time[0] >= 100.0, f"{spec.id}: its clock starts at {run.time[0]}"
        if spec.steady_window:
            assert run.time[0] < spec.steady_window[0] < spec.steady_window[1] < run.time[-1]
        assert "battery_voltage" in run.extra and np.nanmin(run.extra["battery_voltage"]) > 20.0
    assert header(alt, "dbp1")[0] == "time"
    assert header(alt, "dbp1")[1:] != header(default, "dbp1")[1:]
    assert sorted(header(alt, "dbp1")) == sorted(header(default, "dbp1") + ["battery_voltage"])
    truth = truth_of(alt)
    assert truth["design"]["name"] == "alt" and 0.5 <= truth["design"]["throttle"] <= 0.6
    # another terrain: the default's mound top (about 0.5 m at x = 4 m) is not there
    a, b = read_terrain_points(load_campaign(default), "t3d"), read_terrain_points(campaign, "t3d")
    assert a[:, 2].max() > 0.45 and 0.2 < b[:, 2].max() < 0.45
    assert [str(f) for f in check_campaign(campaign)] == []


def test_the_alternative_design_holds_decoys_and_alternative_forms_too(campaigns):
    for effect in ("clock_offset", "soil_strip"):
        root = campaigns(effect, design="alt")
        assert truth_of(root)["design"]["name"] == "alt"
        assert [str(f) for f in check_campaign(load_campaign(root))] == []


def test_cli_writes_an_alternative_design_campaign(tmp_path):
    out = tmp_path / "alt"
    proc = run_juno("synthesize", str(out), "--design", "alt", "--effect", "imu_pitch_bias",
                    "--time-scale", "0.2", "--seed", "7")
    assert proc.returncode == 0, proc.stderr
    assert len(load_campaign(out).runs_of_kind("drawbar")) == 4


# ------------------------------------------------------------------ refusals

@pytest.mark.parametrize("kwargs, needle", [
    ({"design": "alt", "heavy_run": True}, "heavy-run"),
    ({"design": "other"}, "unknown design 'other'"),
    ({"effect": ["side_drag", "drivetrain_friction"]}, "drive.frictionLeft"),
    ({"effect": ["no_such_effect"]}, "unknown effect 'no_such_effect'"),
])
def test_bad_designs_and_clashing_effects_are_refused_before_anything_is_written(tmp_path, harness_fmu, kwargs,
                                                                                 needle):
    out = tmp_path / "c"
    with pytest.raises(ValueError, match=needle):
        synthesize(out, seed=1, fmu=harness_fmu, time_scale=TIME_SCALE, **kwargs)
    assert not out.exists() or not any(out.iterdir())


# ------------------------------------------------------------------ the opt-in study

def _study():
    import importlib.util
    path = Path(__file__).resolve().parents[2] / "scripts" / "detection_rates.py"
    spec = importlib.util.spec_from_file_location("detection_rates_forms", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_study_scores_a_form_by_its_mechanism_and_a_decoy_by_naming_no_catalog_cause():
    study = _study()
    assert study.judged_right("soil_strip", {"cause": "soil_patch"})
    assert not study.judged_right("soil_strip", {"cause": "multipass"})
    assert study.judged_right("side_drag", {"cause": "unexplained"})
    assert study.judged_right("side_drag", {"cause": "none"})
    assert not study.judged_right("side_drag", {"cause": "drivetrain_loss"})
    assert study.judged_right("grouser", {"cause": "grouser"})
    cases = [{"effect": "side_drag", "seed": s, "wall_time": 60.0, "cause": cause, "causes": [cause],
              "correct": study.judged_right("side_drag", {"cause": cause}), "unexplained": cause == "unexplained",
              "design": "alt"} for s, cause in ((1, "drivetrain_loss"), (2, "unexplained"))]
    text = study.table(cases)
    assert (f"| side_drag (decoy) | alt | 2 | 1/2 (>= {study.rate_lower_bound(1, 2):.0%}) | drivetrain_loss 1 | 1/2 |"
            in text)
    assert "named correctly" not in text, "no catalog case, no catalog table"
