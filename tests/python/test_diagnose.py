"""Model discovery, blind: an effect is hidden in a synthetic campaign, truth.json is moved out
of the campaign, and `juno diagnose` must name the hidden cause (or `none`), with a held-out
gain, and fitted extension parameters near the truth.

Strength and seed are drawn at random for every run of the suite and printed, so a failure can
be replayed (`juno synthesize OUT --effect E --strength S --seed N`).  Strengths are drawn from
[0.7, 1.0] of each effect's documented range (python_harness/juno/effects.py).

Covered here: `none` (the no-effect reference the effect tests compare with), five of the six
effect ids (each found in 20 of 20 synthetic campaigns of a 20-seed study; the registration is
judged on the measured pose, and every model on the terrain replay that the best-fitting model
fits best), and a grouser (named in 17 of 20 in the same study, and reported tied with the
drivetrain loss it mimics in the other 3: its own test says why that tie is the right answer).
How many causes are named (none on a second seed, two effects hidden together, no second cause
from a parameter that only frees the first cause's fit) is tested in
test_diagnose_how_many_causes.py, a file of its own so that the two files' diagnoses run on
both pytest workers.  Detection rates per effect are measured offline by
scripts/detection_rates.py (docs/diagnosis.md, "How often it is right").

A hidden multi-pass is named only because the terrain run is judged on the replay that fits the
chosen model best (diagnose.settle_terrain_drive) and the better of two fits of each candidate
is kept (diagnose.better_of_two_fits): judged on the spin replay chosen at the base model, even
the truth can look worse than the base model, and a multi-pass fit from the base optimum can
lose the rover on the terrain replay.
"""

from __future__ import annotations

import pytest

from blind_draws import candidates_summary, draws_for, draw_and_diagnose, extension_close, hide_and_diagnose

EFFECT_IDS = ("soil_patch", "slip_sinkage", "drivetrain_loss", "terrain_offset", "multipass")
#: Effects that another candidate can mimic so closely that the data cannot tell them apart:
#: each has its own test below, which accepts that tie only where the diagnosis reports it.
MIMICKED = {"grouser": "drivetrain_loss"}


@pytest.fixture(scope="module")
def none_case(tmp_path_factory):
    seed = draws_for("none").randrange(10_000)
    print(f"\n[diagnose] effect none, seed {seed}")
    diagnosis, _ = hide_and_diagnose(tmp_path_factory.mktemp("none"), "none", 1.0, seed)
    return diagnosis, seed


def test_no_effect_names_no_cause(none_case):
    diagnosis, seed = none_case
    for key in ("cause", "candidates", "baseline", "extended", "gain"):
        assert key in diagnosis, f"diagnose JSON lacks '{key}'"
    assert diagnosis["cause"] == "none", f"seed {seed}: a false cause was named: {candidates_summary(diagnosis)}"
    assert len(diagnosis["candidates"]) == 6


def _assert_gain_beats_no_effect(diagnosis: dict, none_diagnosis: dict, effect: str, replay: str) -> None:
    """The held-out gain is positive and larger than the same candidate's with nothing hidden.
    For the registration, the gain it is judged on: the held-out pose's (diagnose._judge; its
    replayed gain is reported, and must not be significantly negative, which _judge checks)."""
    if effect == "terrain_offset":
        gain = diagnosis["gain"]["registration"]["gain"]
        none_gain = max((c["kinematic"]["gain"] for c in none_diagnosis["candidates"]
                         if c["name"] == effect and c.get("kinematic")), default=0.0)
    else:
        gain = diagnosis["gain"]["relative"]
        none_gain = max((c["gain"] for c in none_diagnosis["candidates"] if c["name"] == effect), default=0.0)
    assert gain > 0 and gain > none_gain, f"[{replay}] held-out gain {gain:.1%} vs {none_gain:.1%} with no effect"


@pytest.mark.parametrize("effect", EFFECT_IDS)
def test_hidden_effect_is_found_blind(effect, tmp_path, none_case):
    diagnosis, truth, replay, summary = draw_and_diagnose(tmp_path, effect)
    assert diagnosis["cause"] == effect, f"[{replay}] named {diagnosis['cause']}: {summary}"
    # Only the first cause is asserted: a second cause is named falsely in 2 of 99 cases of the
    # detection study (a small multi-pass on top of slip-sinkage; docs/diagnosis.md), printed here.
    print(f"[diagnose] causes {diagnosis['causes']}; second round: {candidates_summary(diagnosis, 'second_round')}")
    _assert_gain_beats_no_effect(diagnosis, none_case[0], effect, replay)
    far = extension_close(effect, diagnosis["extended"]["extension"], truth["extension"])
    assert not far, f"[{replay}] fitted extension far from the truth: {far}"
    for signal, g in diagnosis["gain"]["per_signal"].items():
        assert g["before"] > 0 and g["after"] >= 0, signal


def test_a_hidden_grouser_is_named_or_reported_tied_with_the_loss_it_mimics(tmp_path, none_case):
    """A grouser's lugs shear the soil at R + h: the same thrust needs more torque, as if a
    fraction h / (R + h) of it were lost in the drivetrain.  Where the drawbar runs do not reach
    the slips at which its thrust gain shows, the data cannot tell the two apart.  Measured
    (two campaigns of the 20-seed study, docs/diagnosis.md): at the true soil and grouser, the
    held-out mean squared residual of the drawbar runs is 1.085 and 1.069; a drivetrain loss
    fitted on the true soil gets 1.084 and 1.071.  Those two campaigns, and a third, name the
    loss and report the grouser as explaining the data about as well (``equally_good``, within TIE_RATIO of the gain; the grouser's fit within 17 %
    of the truth's thrust gain and 6 % of its lugs); the other 17 name the grouser.

    So the grouser must be named, or the loss named with the grouser reported tied with it, and
    in either case the grouser's fit must have the right lugs (-11 % to -2 % of the truth in the
    study, -12 % to -4 % on 8 fresh draws) and a thrust gain of the right size (-49 % to +6 %,
    and -53 % to +14 %: the lugs take up part of the thrust, so it is the weaker-pinned of the
    two)."""
    effect = "grouser"
    diagnosis, truth, replay, summary = draw_and_diagnose(tmp_path, effect)
    named = diagnosis["cause"] == effect
    tied = diagnosis["cause"] == MIMICKED[effect] and effect in diagnosis["equally_good"]
    assert named or tied, f"[{replay}] named {diagnosis['cause']}, equally good {diagnosis['equally_good']}: {summary}"
    if tied:
        # The diagnosis says what would tell them apart: a heavier drawbar run, where the two fits
        # part far more than anywhere within the campaign's loads (measured on the three ties of
        # the 20-seed study: 0.08-0.11 of slip against 0.010-0.011; juno.telling_apart).
        (apart,) = [a for a in diagnosis["telling_apart"] if a["models"] == [MIMICKED[effect], effect]]
        assert apart["difference"] > 2 * apart["difference_within_campaign"], f"[{replay}] {apart}"
    _assert_gain_beats_no_effect(diagnosis, none_case[0], effect, replay)
    fitted = diagnosis["extended"]["extension"] if named else \
        next(c for c in diagnosis["candidates"] if c["name"] == effect)["extension"]
    far = extension_close(effect, fitted, truth["extension"])
    assert not far, f"[{replay}] the grouser's fitted extension is far from the truth: {far}"


def test_every_effect_id_is_tested():
    from juno.effects import EFFECTS
    assert set(EFFECT_IDS) | set(MIMICKED) == set(EFFECTS) - {"none"}
