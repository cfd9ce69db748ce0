"""Model discovery beyond the catalog, blind: a discrepancy that no candidate describes is
reported as unexplained, with the signals it shows in, not given the name of a catalog cause.

The decoy is a sensor bias: every IMU pitch sample off by a constant (1.05-1.5 degrees at the
drawn strength).  No extension of the model can produce it; the base model's fit bends the soil
towards it, and what the fit cannot absorb stays in the residuals.  The campaign is half the
standard length: the bias is many times the pitch sensor's noise, so half the blocks suffice, and
the test costs half a diagnosis.  Draws as in test_diagnose.py (blind_draws.py).

A user's mix-up the drawbar runs cannot show, the torque columns swapped on the terrain run
alone, is found by the terrain run's replay.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np

from blind_draws import JUNO, candidates_summary, draws_for, hide_and_diagnose
from juno.campaign.tables import read_run_csv
from juno.sensor_noise import column_noise
from juno.terrain_replay import FLOORS


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


def _swap_columns(csv: Path, a: str, b: str) -> None:
    """Renames column ``a`` to ``b`` and ``b`` to ``a`` in the header of ``csv`` (a user's mix-up)."""
    header, rest = csv.read_text().split("\n", 1)
    names = header.split(",")
    i, j = names.index(a), names.index(b)
    names[i], names[j] = names[j], names[i]
    csv.write_text(",".join(names) + "\n" + rest)


#: The largest ratio of a terrain run's held-out torque block means to the sensor noise that a
#: right model's replay left in the calibration (juno.terrain_replay.FLOORS).
RIGHT_MODEL_TORQUE = 2.5


def _held_out_side_difference(campaign: Path) -> float:
    """The RMS over the terrain run's held-out 4 s blocks (the odd ones) of the block means of
    torque_left - torque_right, over the torque sensor's noise: what a swap of the two columns
    adds to a replay's torque residuals, in the units of the replay test's floors."""
    run = read_run_csv(campaign / "runs" / "t3d.csv", "terrain")
    t, left = run.samples("torque_left")
    right = run.samples("torque_right")[1]
    blocks = np.floor((t - run.time[0]) / 4.0).astype(int)      # blocks from the run's first row, as replayed
    held_out = [b for b in np.unique(blocks) if b % 2 == 1]
    difference = np.array([np.mean(left[blocks == b] - right[blocks == b]) for b in held_out])
    return float(np.sqrt(np.mean(difference ** 2)) / column_noise(t, left))


def test_torque_columns_swapped_on_the_terrain_run_are_reported_unexplained(tmp_path):
    """A campaign of the other design (four drawbar runs, a ridge) with nothing hidden, but the
    terrain run's torque_left and torque_right columns swapped.  No candidate can model it, and the
    drawbar runs (whose sides pull alike) do not show it: only the terrain run's replay does,
    where the two sides' torques differ.  The diagnosis must not call it none: the base model's
    replay departs from the run beyond what a right model's does (juno.terrain_replay), in a
    torque.

    The campaign is the first of the test's draws on which the swap must be seen: the sides'
    torques differ over the held-out blocks by more than the torque floor plus the most a right
    model's replay leaves (RIGHT_MODEL_TORQUE), so that whatever the replay's own error, the
    residual's block means exceed the floor (the RMS of a sum is at least the difference of the
    RMSs).  A swap where the sides pull alike changes little, and is rightly not reported."""
    draws = draws_for("torque columns swapped on the terrain run")
    for attempt in range(20):
        seed = draws.randrange(10_000)
        campaign = tmp_path / f"campaign-{seed}"
        subprocess.run(JUNO + ["synthesize", str(campaign), "--design", "alt", "--seed", str(seed), "--quiet"],
                       check=True, cwd=tmp_path)
        if _held_out_side_difference(campaign) > FLOORS["torque_left"] + RIGHT_MODEL_TORQUE:
            break
    else:
        raise AssertionError("no draw of 20 whose sides' torques differ by the floor and a right model's error")
    print(f"\n[diagnose] juno synthesize OUT --design alt --seed {seed} (draw {attempt + 1}), then torque_left <-> "
          "torque_right in runs/t3d.csv")
    shutil.move(str(campaign / "truth.json"), tmp_path / "truth.json")
    _swap_columns(campaign / "runs" / "t3d.csv", "torque_left", "torque_right")
    out = tmp_path / "diagnosis.json"
    proc = subprocess.run(JUNO + ["diagnose", str(campaign), "--json", str(out), "--quiet"],
                          capture_output=True, text=True, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-2000:]
    diagnosis = json.loads(out.read_text())
    assert diagnosis["cause"] == "unexplained" and diagnosis["causes"] == [], \
        f"named {diagnosis['cause']}: {diagnosis['explanation']}; {candidates_summary(diagnosis)}"
    replay = diagnosis["unexplained"]["terrain_replay"]
    departing = {s["signal"] for r in replay["runs"] for s in r["signals"] if s["disagrees"]}
    assert replay["disagreeing"] == ["t3d"] and departing & {"torque_left", "torque_right"}, replay["summary"]
    assert "terrain run t3d" in diagnosis["explanation"]
