"""``juno synthesize`` / juno.synthesize.synthesize: a synthetic measured campaign.

Specification:
* the campaign folder layout and manifest (juno.campaign), readable by load_campaign and
  read_run; runs as long as the paper's; the LIDAR scan over at least the 20.8 m^2 test area;
* sensors sampled at different rates (empty cells);
* the truth goes to truth.json only: no file name, column, manifest entry, row time or empty
  cell depends on it (two seeds; "none" against every other supported effect);
* the same seed gives byte-identical files;
* an existing non-empty OUT is refused without --overwrite and left unchanged;
* an unknown --effect is refused with a message;
* ``--heavy-run`` holds one drawbar run at a high slip whatever the soil's traction.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from harness_fixtures import (NOISY_TIME_SCALE, PAPER_WINDOWS, RUN_LENGTHS, SMALL_TIME_SCALE, run_juno, say,
                              tree_snapshot)
from juno.campaign import REQUIRED_COLUMNS, load_campaign, read_run, read_terrain_points
from juno.effects import EFFECTS
from juno.rover_model import SOIL_PARAMETERS, rover
from juno.synthesize import SCAN_DENSITY, TERRAIN_X, TERRAIN_Y, scan_extent, synthesize

pytest_plugins = ["harness_fixtures"]

EXPECTED_FILES = {"campaign.json", "runs/dbp1.csv", "runs/dbp2.csv", "runs/dbp3.csv", "runs/t3d.csv",
                  "terrain/scan.xyz", "truth.json"}
SEED_A, SEED_B = 101, 202
OTHER_EFFECTS = [e for e in EFFECTS if e != "none"]


def files_of(root: Path) -> set[str]:
    return {p.relative_to(root).as_posix() for p in root.rglob("*") if p.is_file()}


def structure(root: Path) -> dict:
    """Everything about a campaign folder that must not depend on the truth: file names, the
    manifest, each CSV's header, row times and empty-cell pattern, the scan's size and header."""
    out: dict = {"files": sorted(files_of(root) - {"truth.json"})}
    out["campaign.json"] = json.loads((root / "campaign.json").read_text())
    for rel in out["files"]:
        text = (root / rel).read_text()
        lines = text.splitlines()
        if rel.endswith(".csv"):
            rows = [line.split(",") for line in lines[1:]]
            out[rel] = {"header": lines[0], "rows": len(rows),
                        "time": [r[0] for r in rows],
                        "empty": [tuple(cell == "" for cell in r) for r in rows]}
        elif rel.endswith(".xyz"):
            out[rel] = {"comments": [ln for ln in lines if ln.startswith("#")],
                        "points": sum(1 for ln in lines if ln.strip() and not ln.startswith("#"))}
    return out


def structure_differences(a: dict, b: dict) -> list[str]:
    diffs = []
    for key in sorted(set(a) | set(b)):
        if a.get(key) == b.get(key):
            continue
        if isinstance(a.get(key), dict) and isinstance(b.get(key), dict):
            sub = [k for k in set(a[key]) | set(b[key]) if a[key].get(k) != b[key].get(k)]
            diffs.append(f"{key}: {sorted(map(str, sub))}")
        else:
            diffs.append(key)
    return diffs


def manifest_shape(obj):
    """The manifest with every leaf value replaced by its type: its keys and nesting only."""
    if isinstance(obj, dict):
        return {k: manifest_shape(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [manifest_shape(v) for v in obj]
    return type(obj).__name__


def one_line_error(proc, *needles: str) -> str:
    """Exit code 2 and exactly one stderr line (``--quiet``), no traceback, naming ``needles``."""
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert proc.returncode == 2, f"exit code {proc.returncode}, stderr:\n{proc.stderr}"
    assert "Traceback" not in proc.stderr, proc.stderr
    assert len(lines) == 1, f"expected a one-line message, got:\n{proc.stderr}"
    for needle in needles:
        assert needle in lines[0], f"message does not name {needle!r}: {lines[0]}"
    return lines[0]


# ---------------------------------------------------------------------- layout and format

def test_folder_layout_and_manifest(noisy_campaign):
    root = noisy_campaign.path
    assert files_of(root) == EXPECTED_FILES
    manifest = json.loads((root / "campaign.json").read_text())
    assert isinstance(manifest.get("name"), str) and manifest["name"].strip()
    assert isinstance(manifest.get("rover", {}), dict)
    entries = {e["id"]: e for e in manifest["runs"]}
    assert list(entries) == ["dbp1", "dbp2", "dbp3", "t3d"]
    for run_id, window in PAPER_WINDOWS.items():
        e = entries[run_id]
        assert e["kind"] == "drawbar" and e["file"] == f"runs/{run_id}.csv" and "terrain" not in e
        assert e["steady_window"] == pytest.approx([w * NOISY_TIME_SCALE for w in window])
    t3d = entries["t3d"]
    assert t3d["kind"] == "terrain" and t3d["file"] == "runs/t3d.csv" and t3d["terrain"] == "terrain/scan.xyz"

    truth = json.loads((root / "truth.json").read_text())
    assert truth["effect"] == "none"
    assert set(truth["soil"]) == set(SOIL_PARAMETERS)


def test_runs_are_readable_and_as_long_as_the_papers(noisy_campaign):
    c = load_campaign(noisy_campaign.path)
    assert [(r.id, r.kind) for r in c.runs] == [("dbp1", "drawbar"), ("dbp2", "drawbar"), ("dbp3", "drawbar"),
                                                  ("t3d", "terrain")]
    for run in c.runs:
        data = read_run(c, run)
        for column in REQUIRED_COLUMNS[run.kind] + ("roll", "pitch", "yaw"):
            assert data.has(column), f"{run.id}: no samples of {column}"
        assert data.time[0] == pytest.approx(0.0, abs=0.05)
        assert data.time[-1] == pytest.approx(RUN_LENGTHS[run.id] * NOISY_TIME_SCALE, abs=0.05)
        if run.kind == "drawbar":
            t, f = data.samples("drawbar_force")
            assert np.median(f[t > t[-1] / 2]) > 100, f"{run.id}: no drawbar force held"
        t, x = data.samples("pos_x")
        assert x[-1] - x[0] > 0.5, f"{run.id}: the rover did not drive forwards ({x[-1] - x[0]:.3f} m)"


def test_lidar_scan_covers_the_test_area_and_the_whole_path(noisy_campaign):
    """The scan covers at least the test area, grows only to hold the rover's footprint along the
    terrain run's path, and keeps its density."""
    c = noisy_campaign.campaign
    run = c.runs_of_kind("terrain")[0]
    points = read_terrain_points(c, run)
    x, y, z = points.T
    (x0, x1), (y0, y1) = scan_extent(*(read_run(c, run).samples(n)[1] for n in ("pos_x", "pos_y")))
    assert x0 <= TERRAIN_X[0] and x1 >= TERRAIN_X[1] and y0 <= TERRAIN_Y[0] and y1 >= TERRAIN_Y[1]
    assert x0 - 0.01 <= x.min() and x.max() <= x1 + 0.01 and y0 - 0.01 <= y.min() and y.max() <= y1 + 0.01
    assert len(points) == pytest.approx(SCAN_DENSITY * (x1 - x0) * (y1 - y0), rel=0.01)
    assert len(points) >= 25000
    assert 0.4 < z.max() - np.median(z) < 0.6, "the scan should show the 0.5 m mound"


def test_sensors_sample_at_different_rates(noisy_campaign):
    c = noisy_campaign.campaign
    for run in c.runs:
        data = read_run(c, run)
        names = [n for n in data.columns if n != "time"]
        values = np.column_stack([data[n] for n in names])
        assert not np.any(np.all(np.isnan(values), axis=1)), f"{run.id}: a row without any sample"
        intervals = {}
        for n in names:
            t, _ = data.samples(n)
            intervals[n] = float(np.median(np.diff(t)))
            assert np.isnan(data[n]).any(), f"{run.id}: column {n} has no empty cell"
        rates = {n: round(1 / dt, 1) for n, dt in intervals.items()}
        say(f"{run.id}: sample rates (Hz) {rates}")
        assert len(set(rates.values())) >= 3, f"{run.id}: {rates}"
        # the total station is the slowest sensor; the motor signals are faster than it
        assert max(intervals[n] for n in ("pos_x", "pos_y", "pos_z")) == max(intervals.values())
        assert intervals["torque_left"] < intervals["pos_x"] and intervals["omega_left"] < intervals["pos_x"]


# --------------------------------------------------------------- the truth stays hidden

def test_truth_is_only_in_truth_json_two_seeds(small_campaign):
    a, b = small_campaign(SEED_A), small_campaign(SEED_B)
    assert a.truth["soil"] != b.truth["soil"], "the two seeds should draw different truths"
    sa, sb = structure(a.path), structure(b.path)
    manifest_a, manifest_b = sa.pop("campaign.json"), sb.pop("campaign.json")
    assert manifest_shape(manifest_a) == manifest_shape(manifest_b), "manifest keys differ"
    assert manifest_a["runs"] == manifest_b["runs"] and manifest_a.get("rover") == manifest_b.get("rover")
    assert structure_differences(sa, sb) == []


def test_manifest_does_not_reveal_the_seed(small_campaign):
    a, b = small_campaign(SEED_A), small_campaign(SEED_B)
    text_a = (a.path / "campaign.json").read_text()
    text_b = (b.path / "campaign.json").read_text()
    assert str(SEED_A) not in text_a
    assert text_a == text_b


@pytest.mark.parametrize("effect", OTHER_EFFECTS)
def test_hidden_effect_leaves_no_trace_outside_truth_json(small_campaign, effect):
    none, hidden = small_campaign(SEED_A), small_campaign(SEED_A, effect)
    assert hidden.truth["effect"] == effect and none.truth["effect"] == "none"
    assert (hidden.path / "campaign.json").read_bytes() == (none.path / "campaign.json").read_bytes()
    assert structure_differences(structure(none.path), structure(hidden.path)) == []
    # the effect did change the measurements (or the scan): it is hidden, not absent
    changed = [rel for rel in sorted(files_of(none.path) - {"campaign.json", "truth.json"})
               if (none.path / rel).read_bytes() != (hidden.path / rel).read_bytes()]
    say(f"effect {effect}: files whose data differ from effect none: {changed}")
    assert changed, f"effect {effect} changed no measured data"


def test_same_seed_gives_identical_files(small_campaign):
    first, second = small_campaign(SEED_A), small_campaign(SEED_A, copy=1)
    a, b = tree_snapshot(first.path), tree_snapshot(second.path)
    assert sorted(a) == sorted(b)
    different = [rel for rel in a if a[rel] != b[rel]]
    assert different == [], f"same seed, different files: {different}"


# ------------------------------------------------------------------------- refusals

def test_refuses_an_existing_nonempty_out_and_leaves_it_unchanged(tmp_path, harness_fmu):
    out = tmp_path / "campaign"
    out.mkdir()
    (out / "notes.txt").write_text("field notes, not a campaign\n")
    (out / "runs").mkdir()
    (out / "runs" / "keep.csv").write_text("time\n0\n")
    before = tree_snapshot(out)
    with pytest.raises(FileExistsError):
        synthesize(out, seed=SEED_A, fmu=harness_fmu, time_scale=SMALL_TIME_SCALE)
    assert tree_snapshot(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["campaign"], "a temporary folder was left behind"


def test_cli_refuses_an_existing_nonempty_out_unless_overwrite(tmp_path):
    out = tmp_path / "campaign"
    out.mkdir()
    (out / "notes.txt").write_text("field notes\n")
    before = tree_snapshot(out)
    proc = run_juno("synthesize", out, "--seed", SEED_A, "--time-scale", SMALL_TIME_SCALE, "--quiet")
    message = one_line_error(proc, str(out))
    assert "overwrite" in message
    assert tree_snapshot(out) == before

    # --overwrite replaces only a campaign written by synthesize, never the user's notes.
    proc = run_juno("synthesize", out, "--seed", SEED_A, "--time-scale", SMALL_TIME_SCALE, "--overwrite",
                    "--quiet")
    message = one_line_error(proc, str(out))
    assert "juno synthesize" in message
    assert tree_snapshot(out) == before

    (out / "notes.txt").unlink()
    report = tmp_path / "synth.json"
    for _ in range(2):   # into the empty folder, then over the campaign it wrote
        proc = run_juno("synthesize", out, "--seed", SEED_A, "--time-scale", SMALL_TIME_SCALE, "--overwrite",
                        "--quiet", "--json", report)
        assert proc.returncode == 0, proc.stderr
    assert files_of(out) == EXPECTED_FILES
    assert Path(json.loads(report.read_text())["campaign"]).resolve() == out.resolve()
    load_campaign(out)


def test_bad_effect_is_refused_with_a_message(tmp_path, harness_fmu):
    out = tmp_path / "campaign"
    proc = run_juno("synthesize", out, "--effect", "no_such_effect", "--time-scale", SMALL_TIME_SCALE, "--quiet")
    message = one_line_error(proc, "no_such_effect")
    assert "none" in message, f"the message should list the known effects: {message}"
    assert not out.exists()
    with pytest.raises(ValueError, match="no_such_effect"):
        synthesize(out, effect="no_such_effect", fmu=harness_fmu, time_scale=SMALL_TIME_SCALE)
    assert not out.exists()
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------------- several effects at once

def test_two_effects_are_hidden_together(tmp_path):
    """``--effect A --strength SA --effect B --strength SB``: both act (the truth's extension is
    the union of each effect's own, at its own strength), and truth.json lists them in order."""
    out = tmp_path / "campaign"
    proc = run_juno("synthesize", out, "--effect", "drivetrain_loss", "--strength", "0.8",
                    "--effect", "slip_sinkage", "--strength", "0.4", "--seed", SEED_A,
                    "--time-scale", SMALL_TIME_SCALE, "--quiet")
    assert proc.returncode == 0, proc.stderr
    truth = json.loads((out / "truth.json").read_text())
    assert truth["effects"] == [{"effect": "drivetrain_loss", "strength": 0.8},
                                {"effect": "slip_sinkage", "strength": 0.4}]
    assert truth["extension"] == pytest.approx({"drive.lossFraction": 0.25 * 0.8,
                                                "slipSinkage.coefficient": 1.5 * 0.4})
    assert files_of(out) == EXPECTED_FILES


@pytest.mark.parametrize("args, needle", [
    (["--effect", "grouser", "--effect", "grouser"], "twice"),
    (["--effect", "none", "--effect", "grouser"], "none"),
    (["--effect", "grouser", "--effect", "multipass", "--strength", "1", "--strength", "1",
      "--strength", "1"], "strengths"),
])
def test_inconsistent_effect_lists_are_refused(tmp_path, args, needle):
    out = tmp_path / "campaign"
    proc = run_juno("synthesize", out, *args, "--time-scale", SMALL_TIME_SCALE, "--quiet")
    one_line_error(proc, needle)
    assert not out.exists()


def _steady_slips(root: Path) -> dict[str, tuple[float, float]]:
    """Per drawbar run: (slip, median drawbar force N) over the run's second half, as measured:
    slip = 1 - v / (omega R), v from the total station's x, omega the mean of the encoders."""
    c = load_campaign(root)
    out = {}
    for run in c.runs_of_kind("drawbar"):
        d = read_run(c, run)
        t, x = d.samples("pos_x")
        half = t > t[-1] / 2
        v = (x[half][-1] - x[half][0]) / (t[half][-1] - t[half][0])
        tw, wl = d.samples("omega_left")
        _, wr = d.samples("omega_right")
        omega = float(np.mean((wl + wr)[tw > t[-1] / 2]) / 2)
        tf, f = d.samples("drawbar_force")
        out[run.id] = (1.0 - v / (omega * rover(c.rover).wheel_radius), float(np.median(f[tf > t[-1] / 2])))
    return out


def test_a_heavy_run_pushes_a_grouser_truth_to_high_slip(tmp_path, harness_fmu):
    """`--heavy-run`: the operator pulls one run until the rover settles at about 70 % slip.  On a
    grouser truth (lugs: more traction) the default loads leave every run below 0.6 slip, where a
    thrust gain and a lower K_vx look alike; the heavy run needs a larger force and gets there."""
    runs = {}
    for heavy in (False, True):
        out = tmp_path / f"heavy-{heavy}"
        synthesize(out, effect="grouser", strength=1.0, seed=31, fmu=harness_fmu, time_scale=0.5,
                   heavy_run=heavy)
        runs[heavy] = _steady_slips(out)
    say(f"slip, drawbar force per run: default {runs[False]}, heavy {runs[True]}")
    assert max(s for s, _f in runs[False].values()) < 0.6
    slip, force = max(runs[True].values())
    assert 0.6 < slip < 0.85, runs[True]
    assert force > max(f for _s, f in runs[False].values()) + 100.0, "the heavy run should need a larger force"


@pytest.mark.parametrize("effect", ["grouser", "multipass"])
def test_a_fast_rover_never_leaves_the_scan(effect, tmp_path, fmu_path):
    """The effects that speed the rover up most, at full strength and full length: the terrain
    run's footprint stays on the scan, so the campaign raises no plausibility finding."""
    from juno.plausibility import check_campaign
    from juno.simulator import JunoFMU
    with JunoFMU(fmu_path) as fmu:
        root = synthesize(tmp_path / "c", effect=effect, strength=1.0, seed=31, fmu=fmu)
    c = load_campaign(root)
    run = c.runs_of_kind("terrain")[0]
    # The footprint goes beyond the test area and the 1 m the gridding adds to it: the scan grew.
    assert read_terrain_points(c, run)[:, 0].max() > TERRAIN_X[1] + 1.0
    assert [str(f) for f in check_campaign(c)] == []
