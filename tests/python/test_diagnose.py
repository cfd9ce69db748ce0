"""Model discovery, blind: an effect is hidden in a synthetic campaign, truth.json is moved out
of the campaign, and `juno diagnose` must name the hidden cause (or `none`), with a held-out
gain, and fitted extension parameters near the truth.

Strength and seed are drawn at random for every run of the suite and printed, so a failure can
be replayed (`juno synthesize OUT --effect E --strength S --seed N`).  Strengths are drawn from
[0.7, 1.0] of each effect's documented range (python_harness/juno/effects.py).

Covered: `none` on two seeds (one shared with the effect tests as the no-effect reference),
five of the six effect ids (each found in 20 of 20 cases on seeds 4000-4019 at the code of
session 20, README "Session 21"; terrain_offset since session 19, where the registration is
judged on the measured pose; multipass since session 20, where every model is judged on the
terrain replay that the best-fitting model fits best), a grouser (named in 17 of 20 on the same
seeds, and reported tied with the drivetrain loss it mimics in the other 3: its own test says
why that tie is the right answer), and two effects hidden together (both must be named, the
stronger first).  Detection rates per effect are measured offline by
scripts/detection_rates.py (README, "What the diagnosis finds").

multipass was left out of this test until session 20: 8 of 10 on seeds 4000-4009 with the FMU's
stiffness fix of session 17 (4005 and 4008 `none`, again in sessions 18 and 19).  On 4005 the
terrain run was judged on the spin replay chosen at the base model, where even the truth was
worse than the base model; on 4008 the multi-pass fit kept was the one from the base optimum,
which lost the rover on the terrain replay (diagnose.settle_terrain_drive and
diagnose.better_of_two_fits say what changed).
"""

from __future__ import annotations

import json
import math
import random
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
JUNO = [str(ROOT / ".venv" / "bin" / "juno")] if (ROOT / ".venv" / "bin" / "juno").exists() else \
    [sys.executable, "-m", "juno.cli"]

EFFECT_IDS = ("soil_patch", "slip_sinkage", "drivetrain_loss", "terrain_offset", "multipass")
#: Effects that another candidate can mimic so closely that the data cannot tell them apart:
#: each has its own test below, which accepts that tie only where the diagnosis reports it.
MIMICKED = {"grouser": "drivetrain_loss"}
_rng = random.SystemRandom()


def _hide_and_diagnose(tmp: Path, effect: str | list[tuple[str, float]], strength: float, seed: int
                       ) -> tuple[dict, dict]:
    """Synthesizes, moves truth.json out of the campaign, diagnoses; returns (diagnosis, truth).
    ``effect`` may be a list of (effect, strength) pairs, hidden together."""
    campaign = tmp / "campaign"
    pairs = [(effect, strength)] if isinstance(effect, str) else effect
    hide = [a for e, st in pairs for a in ("--effect", e, "--strength", f"{st:.4f}")]
    subprocess.run(JUNO + ["synthesize", str(campaign), *hide, "--seed", str(seed), "--quiet"], check=True, cwd=tmp)
    truth_path = tmp / "truth.json"
    shutil.move(str(campaign / "truth.json"), truth_path)
    assert not (campaign / "truth.json").exists()
    out = tmp / "diagnosis.json"
    proc = subprocess.run(JUNO + ["diagnose", str(campaign), "--json", str(out), "--quiet"],
                          capture_output=True, text=True, cwd=tmp)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return json.loads(out.read_text()), json.loads(truth_path.read_text())


@pytest.fixture(scope="module")
def none_case(tmp_path_factory):
    seed = _rng.randrange(10_000)
    print(f"\n[diagnose] effect none, seed {seed}")
    diagnosis, _ = _hide_and_diagnose(tmp_path_factory.mktemp("none"), "none", 1.0, seed)
    return diagnosis, seed


@pytest.mark.parametrize("draw", [1])
def test_no_effect_names_no_cause_on_more_seeds(draw, tmp_path):
    """With nothing hidden, no cause is named, on further random seeds (the false-cause rate
    over many seeds is measured by scripts/detection_rates.py; README)."""
    seed = _rng.randrange(10_000, 20_000)
    print(f"\n[diagnose] effect none, seed {seed}")
    diagnosis, _ = _hide_and_diagnose(tmp_path, "none", 1.0, seed)
    summary = ", ".join(f"{c['name']} {c['gain']:+.1%} z {c['z']:.1f}" for c in diagnosis["candidates"])
    assert diagnosis["cause"] == "none" and diagnosis["causes"] == [], \
        f"seed {seed}: a false cause was named: {summary}"


def test_no_effect_names_no_cause(none_case):
    diagnosis, seed = none_case
    for key in ("cause", "candidates", "baseline", "extended", "gain"):
        assert key in diagnosis, f"diagnose JSON lacks '{key}'"
    summary = ", ".join(f"{c['name']} {c['gain']:+.1%} z {c['z']:.1f}" for c in diagnosis["candidates"])
    assert diagnosis["cause"] == "none", f"seed {seed}: a false cause was named: {summary}"
    assert len(diagnosis["candidates"]) == 6


def _extension_close(effect: str, fitted: dict, truth: dict) -> list[str]:
    """Which fitted extension parameters are far from the truth (empty: all near)."""
    far = []

    def rel(name, tol):
        t, f = truth[name], fitted.get(name, float("nan"))
        if not abs(f - t) <= tol * abs(t):
            far.append(f"{name}: fitted {f:.4g}, truth {t:.4g}")

    if effect == "drivetrain_loss":
        rel("drive.lossFraction", 0.35)
    elif effect == "slip_sinkage":
        rel("slipSinkage.coefficient", 0.6)
    elif effect == "soil_patch":
        dx = fitted["soilPatch.x"] - truth["soilPatch.x"]
        dy = fitted["soilPatch.y"] - truth["soilPatch.y"]
        if (dx * dx + dy * dy) ** 0.5 > 1.0:
            far.append(f"patch centre {dx:+.2f}, {dy:+.2f} m off")
        if not fitted["soilPatch.khFactor"] < 1.0:
            far.append(f"soilPatch.khFactor {fitted['soilPatch.khFactor']:.3f} is not a weaker patch")
    elif effect == "grouser":
        # measured fits (26): lugs -12 % to -2 %, thrust gain -53 % to +14 % (the lugs take up part of it)
        rel("grouser.thrustGain", 0.6)
        rel("grouser.lugHeight", 0.3)
    elif effect == "multipass":
        # The rear wheels follow the whole rut (fraction 1 in the truth) on soil compacted by
        # 1.5-2.5x; measured fits: rut 0.87-1.0, compaction -18 % to +5 % of the truth (earlier
        # studies); rut 0.94-1.0, compaction -12.5 % to +7.1 % on seeds 4000-4019 (session 20).
        if not abs(fitted["multipass.rutFraction"] - truth["multipass.rutFraction"]) <= 0.25:
            far.append(f"multipass.rutFraction fitted {fitted['multipass.rutFraction']:.3f}, "
                       f"truth {truth['multipass.rutFraction']:.3f}")
        rel("multipass.khFactor", 0.3)
    elif effect == "terrain_offset":
        if abs(fitted["terrain.offsetZ"] - truth["terrain.offsetZ"]) > 0.015:
            far.append(f"offsetZ fitted {fitted['terrain.offsetZ']:.4f}, truth {truth['terrain.offsetZ']:.4f}")
        # What a traverse can pin down is where the scan's features are, not the offsets
        # themselves: a shift along y and a yaw about the world origin move the mound alike.
        # Compare where each registration puts the mound (its centre and +-1 m along the track).
        miss = max(_registration_miss(fitted, truth, qx, MOUND_CENTRE[1]) for qx in
                   (MOUND_CENTRE[0] - 1.0, MOUND_CENTRE[0], MOUND_CENTRE[0] + 1.0))
        if miss > 0.12:
            far.append(f"the fitted registration puts the mound {miss:.3f} m from where it is")
    return far


#: Centre of the synthetic terrain's 0.5 m mound, in scan coordinates (juno.synthesize.mound_surface).
MOUND_CENTRE = (4.0, 0.35)


def _registration_miss(fitted: dict, truth: dict, qx: float, qy: float) -> float:
    """Distance (m) between where two registrations put the scan point (qx, qy)."""
    def place(o):
        c, s = math.cos(o["terrain.offsetYaw"]), math.sin(o["terrain.offsetYaw"])
        return (o["terrain.offsetX"] + c * qx - s * qy, o["terrain.offsetY"] + s * qx + c * qy)
    (ax, ay), (bx, by) = place(fitted), place(truth)
    return math.hypot(ax - bx, ay - by)


def _draw_and_diagnose(tmp: Path, effect: str) -> tuple[dict, dict, str, str]:
    """Hides ``effect`` at a random strength in [0.7, 1] and seed; returns (diagnosis, truth,
    the command that replays the draw, a one-line summary of the candidates)."""
    strength = round(_rng.uniform(0.7, 1.0), 3)
    seed = _rng.randrange(10_000)
    replay = f"juno synthesize OUT --effect {effect} --strength {strength} --seed {seed}"
    print(f"\n[diagnose] {replay}")
    diagnosis, truth = _hide_and_diagnose(tmp, effect, strength, seed)
    summary = ", ".join(f"{c['name']} {c['gain']:+.1%} z {c['z']:.1f}" for c in diagnosis["candidates"])
    return diagnosis, truth, replay, summary


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
    diagnosis, truth, replay, summary = _draw_and_diagnose(tmp_path, effect)
    assert diagnosis["cause"] == effect, f"[{replay}] named {diagnosis['cause']}: {summary}"
    # Only the first cause is asserted: a second cause is named falsely in 2 of 99 cases of the
    # detection study (a small multi-pass on top of slip-sinkage; README), printed here.
    second = ", ".join(f"{c['name']} {c['gain']:+.1%} z {c['z']:.1f}" for c in diagnosis["second_round"])
    print(f"[diagnose] causes {diagnosis['causes']}; second round: {second}")
    _assert_gain_beats_no_effect(diagnosis, none_case[0], effect, replay)
    far = _extension_close(effect, diagnosis["extended"]["extension"], truth["extension"])
    assert not far, f"[{replay}] fitted extension far from the truth: {far}"
    for signal, g in diagnosis["gain"]["per_signal"].items():
        assert g["before"] > 0 and g["after"] >= 0, signal


def test_two_hidden_effects_are_named_stronger_first(tmp_path):
    """A drivetrain loss and slip-sinkage together.  Hidden alone at these strengths, the loss
    changes the held-out data far more than slip-sinkage does (held-out gains 83-94 % against
    13-31 %, README "What the diagnosis finds"), so it is the stronger: it must be named first,
    slip-sinkage second, each with its parameter near the truth.

    In 3 of 8 offline draws a grouser (two parameters: its lugs mimic the loss, its thrust gain
    takes up part of the slip-sinkage) won the head-to-head test against the loss as one-cause
    models and was named first.  Now both get a second round and the final models are compared
    (diagnose.choose_branch); those three draws name the loss, then slip-sinkage (README, "Two
    effects at once").  One draw (seed 3346) named the loss alone, its fit having bent the soil
    (0.151 against 0.221); now the pair is also fitted from the paper's soil, the better fit by
    the training loss over every run (diagnose.training_objective).

    With the FMU's stiffness fix (session 17), seed 3199 and CI draws 177 and 8998 (`--strength
    0.888 ... 0.736 --seed 8998`) named the loss alone: the spin-following terrain replay missed
    the torques where the rover climbs the mound at high slip, even at the true parameters.
    The terrain run is now replayed by spin or by torque (identify.REPLAY_DRIVES), whichever
    fits its training blocks better at the base model (diagnose.choose_terrain_drive), and those
    three name both.  Seed 3346 then named grouser + slip-sinkage, the grouser's lugs leading the loss by
    0.0005 after the charge for its second parameter; a runner-up that close gets its own second
    round (diagnose.first_cause_branches), and it names the loss, then slip-sinkage (README,
    "Session 18")."""
    pairs = [("drivetrain_loss", round(_rng.uniform(0.7, 1.0), 3)), ("slip_sinkage", round(_rng.uniform(0.7, 1.0), 3))]
    seed = _rng.randrange(10_000)
    replay = "juno synthesize OUT " + " ".join(f"--effect {e} --strength {st}" for e, st in pairs) + f" --seed {seed}"
    print(f"\n[diagnose] {replay}")
    diagnosis, truth = _hide_and_diagnose(tmp_path, pairs, 0.0, seed)
    second = ", ".join(f"{c['name']} {c['gain']:+.1%} z {c['z']:.1f}" for c in diagnosis["second_round"])
    assert diagnosis["causes"] == ["drivetrain_loss", "slip_sinkage"], \
        f"[{replay}] named {diagnosis['causes']}; second round: {second}"
    # Stronger = explains more of the held-out error.  Each step's relative gain is over its own
    # reference (the base model, then the first cause's model), so the steps compare by how
    # much held-out mean squared residual each removes, not by their relative gains.
    steps = diagnosis["gain"]["steps"]
    removed = [s["held_out_mse_before"] - s["held_out_mse_after"] for s in steps]
    assert removed[0] > removed[1] > 0, f"[{replay}] held-out error removed by each step {removed}: {steps}"
    for effect in ("drivetrain_loss", "slip_sinkage"):
        far = _extension_close(effect, diagnosis["extended"]["extension"], truth["extension"])
        assert not far, f"[{replay}] fitted extension far from the truth: {far}"


def test_a_second_parameter_that_only_frees_the_first_causes_fit_names_no_second_cause(tmp_path):
    """A second extension's gain must survive its own removal with the first cause refitted
    (diagnose._second_round).  A fixed draw, not a random one: slip-sinkage 1.15
    (`--effect slip_sinkage --strength 0.767 --seed 4011`).  There slip-sinkage alone stops in
    a local optimum (coefficient 1.03, drawbar training loss 1.48, from the base optimum and from
    the paper's soil alike); fitted beside it, a drivetrain loss of 0.006 carried the soil out of
    it, and that loss was named a second cause (at the true soil such a loss makes the held-out
    error 4 % worse).  Refitted alone from that optimum with the loss switched off, slip-sinkage
    reaches 1.12 at 1.23, and the loss's gain on top is no longer significant."""
    diagnosis, truth = _hide_and_diagnose(tmp_path, "slip_sinkage", 0.767, 4011)
    second = ", ".join(f"{c['name']} {c['gain']:+.1%} z {c['z']:.1f}" for c in diagnosis["second_round"])
    assert diagnosis["causes"] == ["slip_sinkage"], f"named {diagnosis['causes']}; second round: {second}"
    far = _extension_close("slip_sinkage", diagnosis["extended"]["extension"], truth["extension"])
    assert not far, f"fitted extension far from the truth: {far}"


def test_a_hidden_grouser_is_named_or_reported_tied_with_the_loss_it_mimics(tmp_path, none_case):
    """A grouser's lugs shear the soil at R + h: the same thrust needs more torque, as if a
    fraction h / (R + h) of it were lost in the drivetrain.  Where the drawbar runs do not reach
    the slips at which its thrust gain shows, the data cannot tell the two apart.  Measured
    (seeds 4005 and 4008 of the 20-seed study, README "What the diagnosis finds"): at the true
    soil and grouser, the held-out mean squared residual of the drawbar runs is 1.085 and 1.069;
    a drivetrain loss fitted on the true soil gets 1.084 and 1.071.  Those two campaigns, and
    4012 at the code of session 20, name the loss and report the grouser as explaining the data
    about as well (``equally_good``, within TIE_RATIO of the gain; the grouser's fit within 17 %
    of the truth's thrust gain and 6 % of its lugs); the other 17 name the grouser.

    So the grouser must be named, or the loss named with the grouser reported tied with it, and
    in either case the grouser's fit must have the right lugs (-11 % to -2 % of the truth in the
    study, -12 % to -4 % on 8 fresh draws) and a thrust gain of the right size (-49 % to +6 %,
    and -53 % to +14 %: the lugs take up part of the thrust, so it is the weaker-pinned of the
    two)."""
    effect = "grouser"
    diagnosis, truth, replay, summary = _draw_and_diagnose(tmp_path, effect)
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
    far = _extension_close(effect, fitted, truth["extension"])
    assert not far, f"[{replay}] the grouser's fitted extension is far from the truth: {far}"


def test_every_effect_id_is_tested():
    from juno.effects import EFFECTS
    assert set(EFFECT_IDS) | set(MIMICKED) == set(EFFECTS) - {"none"}
