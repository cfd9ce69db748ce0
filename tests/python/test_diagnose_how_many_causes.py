"""How many causes the blind diagnosis names: none where nothing is hidden (a second draw beside
test_diagnose.py's), both of two effects hidden together, the stronger first, and no second
cause from a parameter that only frees the first cause's fit; and two of the catalog's effects
found blind, judged against this file's no-effect draw as test_diagnose.py's are against its own.

These diagnoses are in a file of their own so that pytest-xdist (``--dist loadfile``, one file
per worker) runs them beside test_diagnose.py's, not after them.  Draws as in test_diagnose.py
(blind_draws.py): a strength and seed drawn for each test by its name, printed so that a failure
can be replayed.
"""

from __future__ import annotations

import pytest

from blind_draws import assert_found_blind, candidates_summary, draws_for, extension_close, hide_and_diagnose

#: The catalog effects found blind here (test_diagnose.py has the others).
MORE_EFFECT_IDS = ("slip_sinkage", "drivetrain_loss")


@pytest.fixture(scope="module")
def second_none_case(tmp_path_factory):
    seed = draws_for("none, draw 1").randrange(10_000, 20_000)
    print(f"\n[diagnose] effect none, seed {seed}")
    diagnosis, _ = hide_and_diagnose(tmp_path_factory.mktemp("none"), "none", 1.0, seed)
    return diagnosis, seed


def test_no_effect_names_no_cause_on_a_second_draw(second_none_case):
    """With nothing hidden, no cause is named, on a further seed (the false-cause rate over many
    seeds is measured by scripts/detection_rates.py; docs/diagnosis.md)."""
    diagnosis, seed = second_none_case
    assert diagnosis["cause"] == "none" and diagnosis["causes"] == [], \
        f"seed {seed}: a false cause was named: {candidates_summary(diagnosis)}"


@pytest.mark.parametrize("effect", MORE_EFFECT_IDS)
def test_hidden_effect_is_found_blind(effect, tmp_path, second_none_case):
    assert_found_blind(tmp_path, effect, second_none_case[0])


def test_two_hidden_effects_are_named_stronger_first(tmp_path):
    """A drivetrain loss and slip-sinkage together, each at a strength in [0.7, 1].

    Stronger means: explains more of what the base model gets wrong.  Each effect's one-cause
    model (its parameter and the soil refitted) is judged against the same base model, so its
    held-out gain (the candidates' ``gain``) measures the effect alone, whatever is named first.
    At these strengths the loss is the stronger: on 21 pair draws (15 where slip-sinkage is
    strongest against the loss, loss 0.72-0.79 and slip-sinkage 0.90-1.0, and 6 over the whole
    square), its gain was 36-84 % against slip-sinkage's -0.4 to +25 %, and all 21 named the
    loss, then slip-sinkage, with both parameters near the truth.  So the loss must be named
    first, slip-sinkage second, the loss's gain must be the larger, each step must remove
    held-out error, and each parameter must be near the truth.

    The steps' own sizes do not say which effect is the stronger: the second step is judged
    against the first cause's model, which bends the soil to make up for the missing
    slip-sinkage (k_h at 0.39-0.87 of the truth on 17 of those draws), so it removes that bend's
    error too.  In 5 of the 15 corner draws the second step removed more held-out error than the
    first, so comparing the steps' sizes would be the wrong check.

    What keeps the order right: a grouser (two parameters: its lugs mimic the loss, its thrust
    gain takes up part of the slip-sinkage) can win the head-to-head test against the loss as
    one-cause models (3 of 8 offline draws), so both get a second round and the final models are
    compared (diagnose.choose_branch); a loss fitted alone can bend the soil, so the pair is also
    fitted from the paper's soil; the terrain run is replayed by spin or by torque, whichever
    fits its training blocks better (diagnose.choose_terrain_drive), without which some draws
    named the loss alone; and a runner-up within NEAR_TIE of the leader gets its own second
    round (diagnose.first_cause_branches)."""
    draws = draws_for("drivetrain_loss + slip_sinkage")
    pairs = [("drivetrain_loss", round(draws.uniform(0.7, 1.0), 3)), ("slip_sinkage", round(draws.uniform(0.7, 1.0), 3))]
    seed = draws.randrange(10_000)
    replay = "juno synthesize OUT " + " ".join(f"--effect {e} --strength {st}" for e, st in pairs) + f" --seed {seed}"
    print(f"\n[diagnose] {replay}")
    diagnosis, truth = hide_and_diagnose(tmp_path, pairs, 0.0, seed)
    second = candidates_summary(diagnosis, "second_round")
    assert diagnosis["causes"] == ["drivetrain_loss", "slip_sinkage"], \
        f"[{replay}] named {diagnosis['causes']}; second round: {second}"
    gain = {c["name"]: c["gain"] for c in diagnosis["candidates"]}
    assert gain["drivetrain_loss"] > gain["slip_sinkage"], \
        f"[{replay}] one-cause gains: {candidates_summary(diagnosis)}"
    for step in diagnosis["gain"]["steps"]:
        assert step["held_out_mse_after"] < step["held_out_mse_before"], f"[{replay}] {step}"
    for effect in ("drivetrain_loss", "slip_sinkage"):
        far = extension_close(effect, diagnosis["extended"]["extension"], truth["extension"])
        assert not far, f"[{replay}] fitted extension far from the truth: {far}"


def test_a_second_parameter_that_only_frees_the_first_causes_fit_names_no_second_cause(tmp_path):
    """A second extension's gain must survive its own removal with the first cause refitted
    (diagnose.second_round).  A fixed draw, not a random one: slip-sinkage 1.15
    (`--effect slip_sinkage --strength 0.767 --seed 4011`).  There slip-sinkage alone stops in
    a local optimum (coefficient 1.03, drawbar training loss 1.48, from the base optimum and from
    the paper's soil alike); fitted beside it, a drivetrain loss of 0.006 carried the soil out of
    it, and that loss was named a second cause (at the true soil such a loss makes the held-out
    error 4 % worse).  Refitted alone from that optimum with the loss switched off, slip-sinkage
    reaches 1.12 at 1.23, and the loss's gain on top is no longer significant."""
    diagnosis, truth = hide_and_diagnose(tmp_path, "slip_sinkage", 0.767, 4011)
    assert diagnosis["causes"] == ["slip_sinkage"], \
        f"named {diagnosis['causes']}; second round: {candidates_summary(diagnosis, 'second_round')}"
    far = extension_close("slip_sinkage", diagnosis["extended"]["extension"], truth["extension"])
    assert not far, f"fitted extension far from the truth: {far}"
