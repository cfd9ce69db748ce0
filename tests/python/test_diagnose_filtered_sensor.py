"""A motor current read through a low-pass filter, and its sensor noise stated in the manifest.

A column's sensor noise is estimated from its second differences (juno.sensor_noise), which
assumes the noise white at the sample rate.  A filter in the instrument's electronics leaves only
a fraction of the noise at the sample rate while the slow part of it, which the block means of
the structure test carry, stays whole: the estimate then falls to a fraction of the truth and the
filtered noise reads as structure.  Here both drive torques of a synthetic campaign with nothing
hidden (the alternative design, half length) pass through a first-order low-pass of
FILTER_TIME, as a motor controller's current filter does.

* Without a statement the diagnosis says `unexplained`, naming the drive torques: the known
  limit of docs/diagnosis.md ("Slow sensor noise is structure").
* With each run's torque noise stated in the manifest (``sensor_noise``: the unfiltered sensor's
  noise) it says `none`, its JSON says which noise was stated and which estimated, and both it and
  the plausibility checks warn that the stated noise is far above the estimate, naming the
  columns.

The draw (seed) is blind, as in test_diagnose.py (blind_draws.py).
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

from blind_draws import JUNO, candidates_summary, draws_for
from juno.campaign import format_run_csv, load_campaign, read_run
from juno.sensor_noise import column_noise

#: The filter's time constant (s): a motor controller's current filter.
FILTER_TIME = 0.15
TORQUES = ("torque_left", "torque_right")


def low_pass(values: np.ndarray, dt: float, tau: float) -> np.ndarray:
    """First-order low-pass of samples ``dt`` apart: each output moves towards its input by
    1 - exp(-dt / tau), starting at the first input."""
    keep = float(np.exp(-dt / tau))
    out = np.empty_like(values)
    state = float(values[0])
    for i, v in enumerate(values):
        state = keep * state + (1.0 - keep) * float(v)
        out[i] = state
    return out


def filter_torques(root: Path) -> dict[str, dict[str, float]]:
    """Low-passes both drive torques of every run of the campaign at ``root`` (their own samples,
    in place) and returns each run's unfiltered noise of them (the sensor's, to 2 digits)."""
    campaign = load_campaign(root)
    sensor = {}
    for spec in campaign.runs:
        data = read_run(campaign, spec)
        columns = {**{k: v.copy() for k, v in data.columns.items()}, **data.extra}
        sensor[spec.id] = {}
        for name in TORQUES:
            t, v = data.samples(name)
            sensor[spec.id][name] = float(f"{column_noise(t, v):.2g}")
            own = ~np.isnan(columns[name])
            columns[name][own] = low_pass(v, float(np.median(np.diff(t))), FILTER_TIME)
        campaign.run_path(spec).write_text(format_run_csv(columns))
    return sensor


def state_noise(root: Path, sensor: dict[str, dict[str, float]]) -> None:
    manifest = root / "campaign.json"
    doc = json.loads(manifest.read_text())
    for entry in doc["runs"]:
        entry["sensor_noise"] = sensor[entry["id"]]
    manifest.write_text(json.dumps(doc, indent=2))


def diagnose(root: Path) -> tuple[dict, subprocess.CompletedProcess]:
    out = root.parent / f"{root.name}.json"
    proc = subprocess.run(JUNO + ["diagnose", str(root), "--json", str(out), "--quiet"], capture_output=True,
                          text=True, cwd=root.parent)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return json.loads(out.read_text()), proc


@pytest.fixture(scope="module")
def filtered(tmp_path_factory):
    """The filtered campaign diagnosed without and with its torque noise stated."""
    seed = draws_for("filtered_torque").randrange(10_000)
    replay = f"juno synthesize OUT --seed {seed} --design alt --time-scale 0.5, torques low-passed at {FILTER_TIME} s"
    print(f"\n[diagnose] {replay}")
    tmp = tmp_path_factory.mktemp("filtered")
    root = tmp / "campaign"
    subprocess.run(JUNO + ["synthesize", str(root), "--seed", str(seed), "--design", "alt", "--time-scale", "0.5",
                           "--quiet"], check=True, cwd=tmp)
    (root / "truth.json").unlink()
    sensor = filter_torques(root)
    unstated = diagnose(root)
    state_noise(root, sensor)
    stated = diagnose(root)
    return unstated, stated, sensor, replay


def test_without_a_statement_a_filtered_torque_is_reported_as_unexplained_structure(filtered):
    (diagnosis, _), _, _, replay = filtered
    assert diagnosis["cause"] == "unexplained", \
        f"[{replay}] {diagnosis['cause']}: {diagnosis['explanation']}; {candidates_summary(diagnosis)}"
    named = {s["signal"] for s in diagnosis["unexplained"]["signals"]}
    assert named & set(TORQUES), f"[{replay}] {diagnosis['unexplained']['summary']}"
    assert all(s["source"] == "estimated" for s in diagnosis["sensor_noise"])


def test_with_the_sensor_noise_stated_the_filtered_campaign_names_no_cause(filtered):
    _, (diagnosis, _), sensor, replay = filtered
    assert diagnosis["cause"] == "none", \
        f"[{replay}] {diagnosis['cause']}: {diagnosis['explanation']}; {candidates_summary(diagnosis)}"
    assert diagnosis["causes"] == []


def test_the_outputs_say_which_noise_was_stated_and_which_estimated(filtered):
    _, (diagnosis, proc), sensor, _ = filtered
    by = {(s["run"], s["column"]): s for s in diagnosis["sensor_noise"]}
    for run, columns in sensor.items():
        for column, value in columns.items():
            entry = by[(run, column)]
            assert entry["source"] == "stated" and entry["noise"] == entry["stated"] == value
            assert entry["estimated"] < value / 3, entry
            assert "filtered" in entry["warning"], entry
        assert by[(run, "omega_left")]["source"] == "estimated" and by[(run, "omega_left")]["stated"] is None
        assert by[(run, "omega_left")]["noise"] == by[(run, "omega_left")]["estimated"]
    assert "sensor noise stated in the manifest: torque_left" in proc.stdout
    for column in TORQUES:
        assert f"warning: column '{column}' of runs {', '.join(sensor)}" in proc.stdout, proc.stdout
        # the plausibility checks warn before any fit, naming each run's file
        assert f"runs/dbp1.csv, column '{column}': sensor noise stated in the manifest" in proc.stderr, proc.stderr
