"""Model discovery beyond the catalog, blind: a discrepancy that no candidate describes is
reported as unexplained, with the signals it shows in, not given the name of a catalog cause.

The first decoy is a sensor bias: every IMU pitch sample off by a constant (1.05-1.5 degrees at the
drawn strength).  No extension of the model can produce it, and every fit and judgement takes the
campaign's pitch offset as a nuisance (the IMU's mounting, juno/diagnose/sensor_offset.py), so
no fit bends the soil towards it: it stays in every model's pitch residuals alike, where the
structure test finds it.  The campaign is half the
standard length: the bias is many times the pitch sensor's noise, so half the blocks suffice, and
the test costs half a diagnosis.  The second is a drag on one side (a brake dragging on the left wheels, which the motor current
does not see), at half length like the bias: its torque is several times the torque's noise.
The third is a clock offset: the IMU and the total station
time-stamp their samples 0.17-0.25 s off the motor clock, which the block means average away and
the timing test finds in the positions (one clock, one offset); at the standard length, since the default design's 5 Hz
positions give half a campaign only about a hundred held-out samples.  Draws as in test_diagnose.py (blind_draws.py).
"""

from __future__ import annotations

import pytest

from blind_draws import candidates_summary, draw_and_diagnose, draws_for, hide_and_diagnose


def decoy_at_half_length(tmp_path, effect: str) -> tuple[dict, dict, str]:
    """Hides the decoy ``effect`` blind in a half-length campaign (strength in [0.7, 1] and seed
    drawn for it) and checks that the diagnosis names no catalog cause and reports the
    discrepancy unexplained; returns (diagnosis, truth, the command that replays the draw)."""
    draws = draws_for(effect)
    strength = round(draws.uniform(0.7, 1.0), 3)
    seed = draws.randrange(10_000)
    replay = f"juno synthesize OUT --effect {effect} --strength {strength} --seed {seed} --time-scale 0.5"
    print(f"\n[diagnose] {replay}")
    diagnosis, truth = hide_and_diagnose(tmp_path, effect, strength, seed, ("--time-scale", "0.5"))
    assert [e["in_catalog"] for e in truth["effects"]] == [False]
    assert diagnosis["cause"] == "unexplained" and diagnosis["causes"] == [], \
        f"[{replay}] named {diagnosis['cause']}: {diagnosis['explanation']}; {candidates_summary(diagnosis)}"
    return diagnosis, truth, replay


def test_a_sensor_bias_no_candidate_models_is_reported_unexplained(tmp_path):
    diagnosis, truth, replay = decoy_at_half_length(tmp_path, "imu_pitch_bias")
    unexplained = diagnosis["unexplained"]
    signals = {s["signal"]: s for s in unexplained["signals"]}
    assert "pitch" in signals, f"[{replay}] {unexplained['summary']}"
    assert all(s["significant"] and s["ratio_to_noise"] > 0 for s in signals.values())
    assert "pitch" in diagnosis["explanation"]
    # No fit bends the soil to pitch the rover: the bias stays whole in the base model's pitch,
    # a constant of its own size and sign.
    bias = truth["hidden"]["distortion"]["imu.pitchBias"]
    constant = {f["covariate"]: f for f in signals["pitch"]["follows"]}.get("constant", {"share": 0.0, "slope": 0.0})
    assert constant["share"] > 0.9 and constant["slope"] == pytest.approx(bias, rel=0.1), \
        f"[{replay}] the pitch follows {signals['pitch']['follows']}, the bias was {bias}"
    # ... and the report gives it as the offset every fit took off as the IMU's mounting.
    assert diagnosis["criteria"]["pitch_offset_free"]
    assert diagnosis["baseline"]["pitch_offset"]["campaign"] == pytest.approx(bias, rel=0.1), \
        f"[{replay}] the bias was {bias}"


def test_a_brake_dragging_on_one_side_is_reported_unexplained_and_named_by_side(tmp_path):
    """No candidate drags one side: the drivetrain loss drags both alike, and a soil patch that
    the left wheels alone cross would be a false cause.  What the models leave is a difference
    between the left and right drive torques, which the structure test finds following the side."""
    diagnosis, _truth, replay = decoy_at_half_length(tmp_path, "side_drag")
    signals = {s["signal"]: s for s in diagnosis["unexplained"]["signals"]}
    torques = [signals[t] for t in ("torque_left", "torque_right") if t in signals]
    assert torques, f"[{replay}] {diagnosis['unexplained']['summary']}"
    follows = {f["covariate"] for t in torques for f in t["follows"]}
    assert "side" in follows, f"[{replay}] the torques follow {follows}"


def test_a_clock_offset_between_instruments_is_reported_unexplained_with_its_size(tmp_path):
    """The replay is driven by the motor clock's spins; the positions, stamped by the total
    station's clock, follow it offset by the hidden amount (the sample stamped t was taken at
    motor time t - clock.offset, so it holds the model at t + offset with offset = -clock.offset).
    The drive torques share the motor's clock: no offset is reported in them."""
    diagnosis, truth, replay, candidates = draw_and_diagnose(tmp_path, "clock_offset")
    hidden = -truth["hidden"]["distortion"]["clock.offset"]
    assert diagnosis["cause"] == "unexplained" and diagnosis["causes"] == [], \
        f"[{replay}] named {diagnosis['cause']}: {diagnosis['explanation']}; {candidates}"
    offsets = {o["signal"]: o["offset"] for o in diagnosis["unexplained"]["offsets"]}
    assert "positions" in offsets, f"[{replay}] {diagnosis['unexplained']['summary']}"
    assert not {"torque_left", "torque_right"} & set(offsets), f"[{replay}] {offsets}"
    # The measured rate of change's noise and the half-step delay of the replay bias the
    # estimate a little; its sign and size are the hidden offset's.
    assert offsets["positions"] == pytest.approx(hidden, rel=0.3), f"[{replay}] {offsets}, hidden {hidden}"
    assert "the positions (pos_x, pos_y, pos_z) lag the replay" in diagnosis["explanation"]
    assert "as a clock" in diagnosis["explanation"]
