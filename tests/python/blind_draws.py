"""Blind draws for the diagnosis tests: hide effects in a synthetic campaign, move truth.json out
of it, run `juno diagnose`, and compare the fitted extension with the truth.

Strength and seed come from a pseudo-random generator keyed by the test's own name
(:func:`draws_for`), so every run of the suite draws the same campaigns (the suite is
deterministic) while no strength or seed was picked by hand.  Each draw is printed, so it can be
replayed (`juno synthesize OUT --effect E --strength S --seed N`).  Detection rates over fresh
seeds are measured by the opt-in study, scripts/detection_rates.py.
"""

from __future__ import annotations

import json
import math
import random
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
JUNO = [str(ROOT / ".venv" / "bin" / "juno")] if (ROOT / ".venv" / "bin" / "juno").exists() else \
    [sys.executable, "-m", "juno.cli"]

def draws_for(key: str) -> random.Random:
    """The draws of the test named ``key``: a generator seeded by that name alone."""
    return random.Random(f"juno blind draw: {key}")


def hide_and_diagnose(tmp: Path, effect: str | list[tuple[str, float]], strength: float, seed: int,
                      synthesize_args: tuple[str, ...] = ()) -> tuple[dict, dict]:
    """Synthesizes (with ``synthesize_args`` added), moves truth.json out of the campaign,
    diagnoses; returns (diagnosis, truth).  ``effect`` may be a list of (effect, strength)
    pairs, hidden together."""
    campaign = tmp / "campaign"
    pairs = [(effect, strength)] if isinstance(effect, str) else effect
    hide = [a for e, st in pairs for a in ("--effect", e, "--strength", f"{st:.4f}")]
    subprocess.run(JUNO + ["synthesize", str(campaign), *hide, "--seed", str(seed), "--quiet", *synthesize_args],
                   check=True, cwd=tmp)
    truth_path = tmp / "truth.json"
    shutil.move(str(campaign / "truth.json"), truth_path)
    assert not (campaign / "truth.json").exists()
    out = tmp / "diagnosis.json"
    proc = subprocess.run(JUNO + ["diagnose", str(campaign), "--json", str(out), "--quiet"],
                          capture_output=True, text=True, cwd=tmp)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return json.loads(out.read_text()), json.loads(truth_path.read_text())


def extension_close(effect: str, fitted: dict, truth: dict) -> list[str]:
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
        # 1.5-2.5x; measured fits over the synthetic studies: rut 0.87-1.0, compaction -18 % to
        # +7.1 % of the truth.
        if not abs(fitted["multipass.rutFraction"] - truth["multipass.rutFraction"]) <= 0.25:
            far.append(f"multipass.rutFraction fitted {fitted['multipass.rutFraction']:.3f}, "
                       f"truth {truth['multipass.rutFraction']:.3f}")
        rel("multipass.khFactor", 0.3)
    elif effect == "payload":
        rel("rover.payload", 0.3)
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


def draw_and_diagnose(tmp: Path, effect: str) -> tuple[dict, dict, str, str]:
    """Hides ``effect`` at a strength in [0.7, 1] and a seed drawn for it (draws_for); returns
    (diagnosis, truth, the command that replays the draw, a one-line summary of the candidates)."""
    draws = draws_for(effect)
    strength = round(draws.uniform(0.7, 1.0), 3)
    seed = draws.randrange(10_000)
    replay = f"juno synthesize OUT --effect {effect} --strength {strength} --seed {seed}"
    print(f"\n[diagnose] {replay}")
    diagnosis, truth = hide_and_diagnose(tmp, effect, strength, seed)
    return diagnosis, truth, replay, candidates_summary(diagnosis)


def candidates_summary(diagnosis: dict, key: str = "candidates") -> str:
    """One line: each candidate of ``diagnosis[key]`` with its held-out gain and z."""
    return ", ".join(f"{c['name']} {c['gain']:+.1%} z {c['z']:.1f}" for c in diagnosis[key])


def assert_gain_beats_no_effect(diagnosis: dict, none_diagnosis: dict, effect: str, replay: str) -> None:
    """The held-out gain is positive and larger than the same candidate's with nothing hidden.
    For the registration, the gain it is judged on: the held-out pose's (its replayed gain is
    reported, and must not be significantly negative, which the judging checks)."""
    if effect == "terrain_offset":
        gain = diagnosis["gain"]["registration"]["gain"]
        none_gain = max((c["kinematic"]["gain"] for c in none_diagnosis["candidates"]
                         if c["name"] == effect and c.get("kinematic")), default=0.0)
    else:
        gain = diagnosis["gain"]["relative"]
        none_gain = max((c["gain"] for c in none_diagnosis["candidates"] if c["name"] == effect), default=0.0)
    assert gain > 0 and gain > none_gain, f"[{replay}] held-out gain {gain:.1%} vs {none_gain:.1%} with no effect"


def assert_found_blind(tmp: Path, effect: str, none_diagnosis: dict) -> None:
    """``effect``, hidden at a drawn strength and seed, is named as the cause, with a held-out
    gain beyond the same candidate's with nothing hidden (``none_diagnosis``), an extension
    fitted near the truth and no signal made worse than nothing."""
    diagnosis, truth, replay, summary = draw_and_diagnose(tmp, effect)
    assert diagnosis["cause"] == effect, f"[{replay}] named {diagnosis['cause']}: {summary}"
    # Only the first cause is asserted: a second cause is named falsely in 2 of 99 cases of the
    # detection study (a small multi-pass on top of slip-sinkage; docs/diagnosis.md), printed here.
    print(f"[diagnose] causes {diagnosis['causes']}; second round: {candidates_summary(diagnosis, 'second_round')}")
    assert_gain_beats_no_effect(diagnosis, none_diagnosis, effect, replay)
    far = extension_close(effect, diagnosis["extended"]["extension"], truth["extension"])
    assert not far, f"[{replay}] fitted extension far from the truth: {far}"
    for signal, g in diagnosis["gain"]["per_signal"].items():
        assert g["before"] > 0 and g["after"] >= 0, signal
