"""Model discovery beyond the catalog, blind: a discrepancy that no candidate describes is
reported as unexplained, with the signals it shows in, not given the name of a catalog cause.

The decoy is a sensor bias: every IMU pitch sample off by a constant (1.05-1.5 degrees at the
drawn strength).  No extension of the model can produce it; the base model's fit bends the soil
towards it, and what the fit cannot absorb stays in the residuals.  The campaign is half the
standard length: the bias is many times the pitch sensor's noise, so half the blocks suffice, and
the test costs half a diagnosis.  Draws as in test_diagnose.py (blind_draws.py).
"""

from __future__ import annotations

from blind_draws import candidates_summary, draws_for, hide_and_diagnose


def test_a_sensor_bias_no_candidate_models_is_reported_unexplained(tmp_path):
    effect = "imu_pitch_bias"
    draws = draws_for(effect)
    strength = round(draws.uniform(0.7, 1.0), 3)
    seed = draws.randrange(10_000)
    replay = f"juno synthesize OUT --effect {effect} --strength {strength} --seed {seed} --time-scale 0.5"
    print(f"\n[diagnose] {replay}")
    diagnosis, truth = hide_and_diagnose(tmp_path, effect, strength, seed, ("--time-scale", "0.5"))
    assert [e["in_catalog"] for e in truth["effects"]] == [False]
    assert diagnosis["cause"] == "unexplained" and diagnosis["causes"] == [], \
        f"[{replay}] named {diagnosis['cause']}: {diagnosis['explanation']}; {candidates_summary(diagnosis)}"
    unexplained = diagnosis["unexplained"]
    signals = {s["signal"]: s for s in unexplained["signals"]}
    assert "pitch" in signals, f"[{replay}] {unexplained['summary']}"
    assert all(s["significant"] and s["ratio_to_noise"] > 0 for s in signals.values())
    assert "pitch" in diagnosis["explanation"]
