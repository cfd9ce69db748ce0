"""The harness on any reasonable campaign, not only the layout it was developed on.

Specification: a campaign laid out otherwise than the paper's (three drawbar runs at 45 %
throttle, one mound, one sensor set, clocks at zero) loads, is identified, validated, reported
and diagnosed as well:

* the ``alt`` design (four drawbar runs at 50-60 % throttle, a ridge, other sensor rates and
  noise, clocks starting at 100-5000 s, the columns in another order with an unused
  ``battery_voltage``): the joint fit recovers the truth within its uncertainty, and
  ``juno identify`` and ``juno validate`` exit 0, the latter naming the terrain run;
* a clock offset on every run (time column and steady windows shifted alike) changes nothing:
  the same steady averages, the same replay inputs and comparison targets, the same residuals,
  the same kinematic registration evidence (its blocks counted from the run's first sample);
* the columns in any order, with extra numeric and text columns: read identically, the extra
  ones kept aside;
* sensors at other rates (every column decimated): the fit still recovers the truth within its
  uncertainty;
* only drawbar runs: ``juno identify`` exits 0; ``juno validate`` refuses with a message naming
  the manifest and what is missing; the diagnosis says which candidates it leaves out for want
  of a terrain run, and refuses before any fit when that leaves none;
* five drawbar runs and two terrain runs, each on its own scan: every run is replayed, each
  terrain run on its own gridded scan, and validated and reported under its own id;
* positions in a frame turned from the rover's and no yaw column (an IMU without a heading): the
  replays start along the track, as with a measured heading; the terrain run's pose is left
  untested against its scan, and said so;
* no roll, pitch or yaw column (no IMU angles): ``juno identify``, ``juno validate`` and ``juno
  diagnose`` each name the columns missing from the runs they use, with what that costs, in their
  printout and their JSON (``missing_columns``, empty for a full campaign), and the structure test
  lists no pitch among its signals;
* a drawbar run without a steady window: the paper-style fit says it averages the whole run;
* one diagnosis opens one snapshot of the FMU, and ``juno validate`` grids as the others do.
* the replay's own bias (the parametric bootstrap): on exact data it is the fit's whole error,
  it is estimated by default only where a column is missing, and a terrain run's twin rolls over
  the run's own scan.

Campaigns are short (``time_scale`` 0.25-0.3: runs of 5.5-10 s), so each test takes seconds.
A diagnosis is run once, of one candidate, for what it says of the columns a campaign lacks; its
verdict is not tested here: at these lengths a drawbar run has one held-out block, too few for
the diagnosis's significance tests (a full-length ``alt`` campaign takes minutes).
"""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path
from typing import Callable

import numpy as np
import pytest

from harness_fixtures import run_juno, run_juno_here, say
from juno.campaign import load_campaign, read_run
from juno.identify import gridded_scans, identify_joint, prepare_run, run_residuals, steady_averages
from juno.plausibility import check_campaign
from juno.rover_model import SOIL_PARAMETERS
from juno.synthesize import synthesize

pytest_plugins = ["harness_fixtures"]

#: The alt design's runs at 0.3 of their length: 7-9 s drawbar runs, a 6.6 s terrain run.
ALT_TIME_SCALE = 0.3
ALT_SEED = 31
#: The default design shortened as the other harness tests shorten it (runs of 5.5-8.8 s).
SHORT_TIME_SCALE = 0.25
SHORT_SEED = 3107
#: A fitted parameter recovers the truth when it is within this many of its 1-sigma
#: uncertainties (four parameters: a normal deviate exceeds 3 in 1 % of fits).
Z_MAX = 3.0
#: A clock offset a data logger might have (s), not a multiple of any sample period.
CLOCK_OFFSET = 1234.5


# ------------------------------------------------------------------ campaigns

@pytest.fixture(scope="module")
def alt_campaign(tmp_path_factory, harness_fmu) -> Path:
    """A short alt-design campaign, nothing hidden."""
    return synthesize(tmp_path_factory.mktemp("alt") / "campaign", seed=ALT_SEED, design="alt",
                      time_scale=ALT_TIME_SCALE, fmu=harness_fmu)


@pytest.fixture(scope="module")
def short_campaign(tmp_path_factory, harness_fmu) -> Path:
    """A short default-design campaign, nothing hidden: the source of the hand-made variants."""
    return synthesize(tmp_path_factory.mktemp("short") / "campaign", seed=SHORT_SEED,
                      time_scale=SHORT_TIME_SCALE, fmu=harness_fmu)


def truth_soil(root: Path) -> dict[str, float]:
    """The soil of a synthetic campaign's truth.json (read by the tests only)."""
    return json.loads((root / "truth.json").read_text())["soil"]


def copy_campaign(src: Path, dst: Path) -> tuple[Path, dict]:
    """A copy of campaign ``src`` at ``dst`` without its truth, and its manifest (a dict)."""
    shutil.copytree(src, dst)
    (dst / "truth.json").unlink()
    return dst, json.loads((dst / "campaign.json").read_text())


def save_manifest(root: Path, manifest: dict) -> None:
    (root / "campaign.json").write_text(json.dumps(manifest, indent=2))


Table = tuple[list[str], list[list[str]]]


def rewrite_csv(path: Path, change: Callable[[list[str], list[list[str]]], Table]) -> None:
    """Rewrites a run CSV through ``change(header, rows) -> (header, rows)``."""
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    header, body = change(rows[0], rows[1:])
    with open(path, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(header)
        writer.writerows(body)


def shifted_clock(header: list[str], rows: list[list[str]]) -> Table:
    """Every time stamp CLOCK_OFFSET s later."""
    i = header.index("time")
    for row in rows:
        row[i] = repr(float(row[i]) + CLOCK_OFFSET)
    return header, rows


def decimated(every: dict[tuple[str, ...], int]) -> Callable[[list[str], list[list[str]]], Table]:
    """Keeps every n-th sample of each group of columns (sampled together), dropping rows left empty."""
    def change(header: list[str], rows: list[list[str]]) -> Table:
        for columns, n in every.items():
            idx = [header.index(c) for c in columns if c in header]
            if not idx:
                continue
            count = 0
            for row in rows:
                if row[idx[0]]:
                    if count % n:
                        for i in idx:
                            row[i] = ""
                    count += 1
        return header, [row for row in rows if any(cell for j, cell in enumerate(row) if header[j] != "time")]
    return change


def reordered_with_extras(header: list[str], rows: list[list[str]]) -> Table:
    """The columns in reverse order (time last), then a text and a numeric column juno does not use."""
    order = list(reversed(range(len(header))))
    return ([header[i] for i in order] + ["operator_note", "air_temperature"],
            [[row[i] for i in order] + ["dusty", "21.5"] for row in rows])


def variant(src: Path, dst: Path, change=None, manifest_change=None) -> Path:
    """A hand-made variant of campaign ``src``: every run CSV through ``change``, the manifest
    through ``manifest_change(root, manifest)``."""
    root, manifest = copy_campaign(src, dst)
    if change is not None:
        for run in manifest["runs"]:
            rewrite_csv(root / run["file"], change)
    if manifest_change is not None:
        manifest_change(root, manifest)
    save_manifest(root, manifest)
    return root


def fit_recovers_truth(root: Path, truth: dict[str, float], fmu) -> dict[str, float]:
    """Joint fit of campaign ``root``; asserts each parameter within Z_MAX sigma of the ``truth``
    and returns the z-scores."""
    result = identify_joint(fmu, load_campaign(root), workers=1)
    z = {k: (result.params[k] - truth[k]) / result.std[k] for k in SOIL_PARAMETERS}
    say(f"{root}: joint fit z-scores " + ", ".join(f"{k} {v:+.2f}" for k, v in z.items()))
    assert result.status == "ok"
    far = {k: round(v, 2) for k, v in z.items() if not abs(v) <= Z_MAX}
    assert not far, f"{root}: estimates more than {Z_MAX} sigma off the truth: {far}"
    return z


# ------------------------------------------------------------------ the alt design

def test_an_alt_design_campaign_is_plausible_as_it_is(alt_campaign):
    assert [str(f) for f in check_campaign(load_campaign(alt_campaign))] == []


def test_the_joint_fit_recovers_the_truth_of_an_alt_design_campaign(alt_campaign, harness_fmu):
    fit_recovers_truth(alt_campaign, truth_soil(alt_campaign), harness_fmu)


def test_identify_and_validate_run_on_an_alt_design_campaign(alt_campaign, tmp_path):
    identified = tmp_path / "identify.json"
    proc = run_juno("identify", alt_campaign, "--method", "joint", "--workers", "1", "--replay-bias", "on", "--quiet",
                    "--json", identified)
    assert proc.returncode == 0, proc.stderr
    joint = json.loads(identified.read_text())["joint"]
    assert set(joint["params"]) == set(SOIL_PARAMETERS)
    assert json.loads(identified.read_text())["missing_columns"] == []
    for k in SOIL_PARAMETERS:    # the uncertainty's two parts, apart, and printed
        parts = (joint["std_statistical"][k], joint["std_systematic"][k])
        assert joint["std"][k] == pytest.approx(float(np.hypot(*parts)))
        assert joint["std_systematic"][k] == abs(joint["replay_bias"][k])
        assert f"joint: {k} = " in proc.stdout and (f"(noise {joint['std_statistical'][k]:.2g}, replay bias "
                                                      f"{joint['replay_bias'][k]:+.2g})") in proc.stdout
    validated = tmp_path / "validate.json"
    proc = run_juno("validate", alt_campaign, "--params", identified, "--quiet", "--json", validated)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("t3d: RMS pos_x") and len(proc.stdout.splitlines()) == 1, proc.stdout
    assert json.loads(validated.read_text())["missing_columns"] == []
    rms = json.loads(validated.read_text())["rms"]
    assert list(rms) == ["t3d"] and all(np.isfinite(v) for v in rms["t3d"].values())


# ------------------------------------------------------------------ clocks, columns, rates

def _later_windows(root: Path, manifest: dict) -> None:
    for run in manifest["runs"]:
        if "steady_window" in run:
            run["steady_window"] = [t + CLOCK_OFFSET for t in run["steady_window"]]


def test_a_clock_offset_on_every_run_changes_nothing(short_campaign, tmp_path, harness_fmu):
    """Steady averages, replay inputs, comparison targets and residuals are those of the same
    campaign with its clocks at zero: every time is taken from the run's first sample."""
    shifted = variant(short_campaign, tmp_path / "shifted", shifted_clock, _later_windows)
    original, moved = load_campaign(short_campaign), load_campaign(shifted)
    soil = truth_soil(short_campaign)
    for spec in original.runs:
        a, b = read_run(original, spec), read_run(moved, moved.run(spec.id))
        assert b.time[0] == pytest.approx(a.time[0] + CLOCK_OFFSET)
        if spec.steady_window:
            sa, sb = steady_averages(original, spec), steady_averages(moved, moved.run(spec.id))
            for name in ("drawbar", "torque_left", "speed", "omega_right"):
                assert getattr(sb, name) == pytest.approx(getattr(sa, name), rel=1e-6), f"{spec.id}: {name}"
        if spec.kind != "drawbar":
            continue
        pa, pb = prepare_run(original, spec), prepare_run(moved, moved.run(spec.id))
        assert pb.duration == pytest.approx(pa.duration, abs=1e-9)
        for name, values in pa.inputs.values.items():
            assert np.allclose(pb.inputs.values[name], values, atol=1e-9), f"{spec.id}: input {name}"
        for column, target in pa.targets.items():
            assert np.allclose(pb.targets[column][0], target[0], atol=1e-9), f"{spec.id}: {column} times"
        ra, rb = run_residuals(harness_fmu, pa, soil), run_residuals(harness_fmu, pb, soil)
        assert np.allclose(rb, ra, rtol=1e-6, atol=1e-6), f"{spec.id}: residuals differ"


def test_a_clock_offset_leaves_the_registration_evidence_as_it_is(short_campaign, tmp_path):
    """The scan's registration is fitted on the terrain run's training blocks and judged on its
    held-out ones, the blocks the replays are split into, counted from the run's first sample
    (CLOCK_OFFSET is not a whole number of blocks)."""
    from juno.diagnose.problem import BLOCK
    from juno.diagnose.starts import registration_evidence
    assert (CLOCK_OFFSET / BLOCK) % 1 != 0
    shifted = variant(short_campaign, tmp_path / "shifted", shifted_clock, _later_windows)
    evidence = []
    for root in (short_campaign, shifted):
        campaign = load_campaign(root)
        grid = gridded_scans(campaign, tmp_path / root.name, "validate")["t3d"][1]
        evidence.append(registration_evidence(campaign, grid))
    at_zero, later = evidence
    assert later.ratio == pytest.approx(at_zero.ratio, rel=1e-6)
    assert later.held_out_ms_registered == pytest.approx(at_zero.held_out_ms_registered, rel=1e-6)


#: A total station's frame turned from the rover's start direction (rad).
TURN = np.radians(40.0)


def turned_without_heading(header: list[str], rows: list[list[str]]) -> Table:
    """Positions in a frame turned by TURN about the vertical, and no yaw column (an IMU without a
    heading)."""
    ix, iy = header.index("pos_x"), header.index("pos_y")
    c, s = float(np.cos(TURN)), float(np.sin(TURN))
    for row in rows:
        if row[ix] and row[iy]:
            x, y = float(row[ix]), float(row[iy])
            row[ix], row[iy] = repr(float(c * x - s * y)), repr(float(s * x + c * y))
    keep = [i for i, name in enumerate(header) if name != "yaw"]
    rows = [[row[i] for i in keep] for row in rows]
    return [header[i] for i in keep], [row for row in rows if any(row[1:])]


def _turned_scan(root: Path, manifest: dict) -> None:
    """The terrain run's scan in the same turned frame."""
    c, s = float(np.cos(TURN)), float(np.sin(TURN))
    for run in manifest["runs"]:
        if run["kind"] != "terrain":
            continue
        path = root / run["terrain"]
        lines = []
        for line in path.read_text().splitlines():
            if line.startswith("#"):
                lines.append(line)
                continue
            x, y, z = (float(v) for v in line.split()[:3])
            lines.append(f"{c * x - s * y!r} {s * x + c * y!r} {z!r}")
        path.write_text("\n".join(lines) + "\n")


def test_a_turned_frame_without_a_heading_starts_each_replay_along_its_track(short_campaign, tmp_path, harness_fmu):
    """Without a yaw column the replays start the rover along the direction of its track
    (juno.heading), so that positions in a turned frame replay as in the rover's own: each start
    heading within 0.02 rad of the measured one turned by TURN, and the drawbar runs' residuals
    at the truth's soil within 10 % (in mean square) of the original's; the terrain run's pose
    is not tested against its scan, and the diagnosis says why."""
    from juno.scan_consistency import campaign_scan_consistency
    turned = variant(short_campaign, tmp_path / "turned", turned_without_heading, _turned_scan)
    original, other = load_campaign(short_campaign), load_campaign(turned)
    soil = truth_soil(short_campaign)
    scans = gridded_scans(other, tmp_path / "grids", "validate")
    for spec in original.runs:
        measured = read_run(original, spec).samples("yaw")[1][0]
        pb = prepare_run(other, other.run(spec.id), terrain_file=scans[spec.id][0] if spec.id in scans else None)
        assert pb.params["init.yaw"] == pytest.approx(measured + TURN, abs=0.02), spec.id
        if spec.kind == "drawbar":
            ra = run_residuals(harness_fmu, prepare_run(original, spec), soil)
            rb = run_residuals(harness_fmu, pb, soil)
            assert np.mean(rb ** 2) == pytest.approx(np.mean(ra ** 2), rel=0.1), spec.id
    tests = campaign_scan_consistency(other, {run: grid for run, (_path, grid) in scans.items()}, 4.0)
    assert tests.runs == [] and "yaw" in tests.untested["t3d"]


def test_columns_in_any_order_with_extra_ones_read_the_same(short_campaign, tmp_path):
    shuffled = variant(short_campaign, tmp_path / "columns", reordered_with_extras)
    original, other = load_campaign(short_campaign), load_campaign(shuffled)
    assert [str(f) for f in check_campaign(other)] == []
    for spec in original.runs:
        a, b = read_run(original, spec), read_run(other, other.run(spec.id))
        assert np.array_equal(a.time, b.time)
        for column in ("torque_left", "omega_right", "pos_x", "pos_z", "yaw"):
            ta, va = a.samples(column)
            tb, vb = b.samples(column)
            assert np.array_equal(ta, tb) and np.array_equal(va, vb), f"{spec.id}: column {column}"
        assert np.nanmax(b.extra["air_temperature"]) == 21.5
        assert "operator_note" in b.extra


def test_sensors_at_other_rates_still_recover_the_truth(short_campaign, tmp_path, harness_fmu):
    """Total station at 2.5 Hz, motor current and encoders at 25 Hz, IMU at 50 Hz, load cell at 50 Hz."""
    slower = variant(short_campaign, tmp_path / "rates", decimated({
        ("pos_x", "pos_y", "pos_z"): 2, ("torque_left", "torque_right"): 2, ("omega_left", "omega_right"): 2,
        ("roll", "pitch", "yaw"): 2, ("drawbar_force",): 2}))
    campaign = load_campaign(slower)
    assert [str(f) for f in check_campaign(campaign)] == []
    run = read_run(campaign, campaign.run("dbp1"))
    assert np.median(np.diff(run.samples("pos_x")[0])) == pytest.approx(0.4, rel=0.01)
    fit_recovers_truth(slower, truth_soil(short_campaign), harness_fmu)


# ------------------------------------------------------------------ how many runs of each kind

def _drawbar_only(root: Path, manifest: dict) -> None:
    for run in manifest["runs"]:
        if run["kind"] == "terrain":
            (root / run["file"]).unlink()
            shutil.rmtree(root / Path(run["terrain"]).parent)
    manifest["runs"] = [r for r in manifest["runs"] if r["kind"] == "drawbar"]


def test_a_campaign_of_drawbar_runs_only_is_identified_and_validate_says_what_it_lacks(short_campaign, tmp_path):
    root = variant(short_campaign, tmp_path / "drawbar-only", manifest_change=_drawbar_only)
    identified = tmp_path / "identify.json"
    proc = run_juno("identify", root, "--method", "joint", "--workers", "1", "--quiet", "--json", identified)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(identified.read_text())["joint"]["runs"] == ["dbp1", "dbp2", "dbp3"]
    proc = run_juno("validate", root, "--params", identified, "--quiet")
    assert proc.returncode != 0
    assert "campaign.json" in proc.stderr and "terrain run" in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr


def test_the_diagnosis_of_drawbar_runs_only_leaves_out_the_candidates_that_need_a_terrain_run(short_campaign,
                                                                                               tmp_path, fmu_path):
    from juno.diagnose.candidates import CANDIDATES
    from juno.diagnose.search import prepare
    root = variant(short_campaign, tmp_path / "drawbar-only", manifest_change=_drawbar_only)
    names = ["drivetrain_loss", "terrain_offset"]
    assert CANDIDATES["terrain_offset"].needs_terrain and not CANDIDATES["drivetrain_loss"].needs_terrain
    work = tmp_path / "work"
    work.mkdir()
    said: list[str] = []
    setting = prepare(load_campaign(root), fmu_path, names, str(work), None, said.append)
    assert setting.names == ["drivetrain_loss"]
    assert not setting.grids and {p.kind for p in setting.problem.prepared} == {"drawbar"}
    assert not setting.base.error
    assert any(m.startswith("left out terrain_offset: needs a terrain run") for m in said), said


def test_a_diagnosis_left_without_a_candidate_is_refused_before_any_fit(short_campaign, tmp_path, capsys):
    """Asked only for candidates that need a terrain run, of a campaign without one: an error
    naming the manifest and why, not a "none" that tried nothing."""
    root = variant(short_campaign, tmp_path / "drawbar-only", manifest_change=_drawbar_only)
    proc = run_juno_here(capsys, "diagnose", root, "--candidates", "terrain_offset", "--workers", "1", "--quiet")
    assert proc.returncode != 0
    assert "campaign.json" in proc.stderr and "terrain_offset" in proc.stderr and "terrain run" in proc.stderr, \
        proc.stderr
    assert "Traceback" not in proc.stderr


def _five_drawbar_and_two_terrain_runs(root: Path, manifest: dict) -> None:
    """Two more drawbar runs (copies of dbp1 and dbp2) and a second terrain run: the first one
    and its scan moved 10 m along x, so that it lies on its own scan only."""
    drawbar = [r for r in manifest["runs"] if r["kind"] == "drawbar"]
    for i, run in enumerate(drawbar[:2]):
        new = dict(run, id=f"dbp{4 + i}", file=f"runs/dbp{4 + i}.csv")
        shutil.copy(root / run["file"], root / new["file"])
        manifest["runs"].insert(len(drawbar) + i, new)
    terrain = next(r for r in manifest["runs"] if r["kind"] == "terrain")
    second = dict(terrain, id="t3d_east", file="runs/t3d_east.csv", terrain="terrain/scan_east.xyz")
    shutil.copy(root / terrain["file"], root / second["file"])

    def east(header: list[str], rows: list[list[str]]) -> Table:
        i = header.index("pos_x")
        for row in rows:
            if row[i]:
                row[i] = repr(float(row[i]) + 10.0)
        return header, rows
    rewrite_csv(root / second["file"], east)
    with open(root / terrain["terrain"]) as src, open(root / second["terrain"], "w") as dst:
        for line in src:
            if line.startswith("#") or not line.strip():
                dst.write(line)
            else:
                x, y, z = line.split()
                dst.write(f"{float(x) + 10.0!r} {y} {z}\n")
    manifest["runs"].append(second)


@pytest.fixture(scope="module")
def many_runs(short_campaign, tmp_path_factory) -> Path:
    return variant(short_campaign, tmp_path_factory.mktemp("many") / "campaign",
                   manifest_change=_five_drawbar_and_two_terrain_runs)


def test_five_drawbar_and_two_terrain_runs_are_each_replayed_on_their_own_ground(many_runs, tmp_path):
    from juno.diagnose.problem import build_problem
    campaign = load_campaign(many_runs)
    assert [str(f) for f in check_campaign(campaign)] == []
    scans = gridded_scans(campaign, tmp_path, "validate")   # the terrain runs' scans
    assert set(scans) == {"t3d", "t3d_east"}
    (path_a, grid_a), (path_b, grid_b) = scans["t3d"], scans["t3d_east"]
    assert path_a != path_b and grid_b.x0 == pytest.approx(grid_a.x0 + 10.0, abs=grid_a.cell)
    problem = build_problem(campaign, "unused.fmu", {k: v[0] for k, v in scans.items()})
    assert [p.run_id for p in problem.prepared] == ["dbp1", "dbp2", "dbp3", "dbp4", "dbp5", "t3d", "t3d_east"]
    on = {p.run_id: p.params.get("terrain.file") for p in problem.prepared}
    assert on["t3d"] == path_a and on["t3d_east"] == path_b and on["dbp4"] is None
    assert set(np.unique(problem.meta["run"])) == set(on)


def test_every_terrain_run_is_validated_and_reported_under_its_own_id(many_runs, short_campaign, tmp_path,
                                                                      harness_fmu):
    from juno.report import write_report
    from juno.validate import validate_run
    campaign = load_campaign(many_runs)
    soil = truth_soil(short_campaign)
    validations = [("true soil", validate_run(harness_fmu, campaign, spec, soil, tmp_path))
                   for spec in campaign.runs_of_kind("terrain")]
    a, b = (v.rms for _, v in validations)
    # The second run is the first one moved 10 m east with its scan: it validates alike.
    for name in a:
        assert b[name] == pytest.approx(a[name], rel=0.05, abs=1e-3), name
    report = write_report(tmp_path / "report", campaign, [], None, validations)
    text = report.read_text()
    rows = [line for line in text.splitlines() if line.startswith("| t3d")]
    assert [r.split("|")[1].strip() for r in rows] == ["t3d", "t3d_east"]
    assert "validation_t3d.png" in text and "validation_t3d_east.png" in text
    summary = json.loads((report.parent / "summary.json").read_text())
    assert set(summary["validation"]) == {"t3d", "t3d_east"}


# ------------------------------------------------------------------ one model for the whole diagnosis

def test_a_diagnosis_fits_every_candidate_with_one_snapshot_of_the_fmu(fmu_path, tmp_path):
    """Each fit opens the FMU file anew; the file a diagnosis opens is a copy taken at its start,
    so an FMU rebuilt while it runs cannot mix two models in one comparison.  On a Dask cluster
    the workers need the path given, which is kept."""
    from juno.diagnose.search import fmu_snapshot
    copy = Path(fmu_snapshot(fmu_path, str(tmp_path), None))
    assert copy.parent.parent == tmp_path and copy.read_bytes() == Path(fmu_path).read_bytes()
    assert fmu_snapshot(fmu_path, str(tmp_path / "other"), "tcp://scheduler:8786") == fmu_path


def test_juno_validate_grids_the_scan_as_report_and_diagnose_do(alt_campaign):
    from juno.validate import GRID_CELL
    proc = run_juno("validate", "--help")
    assert proc.returncode == 0 and f"default {GRID_CELL:g}," in " ".join(proc.stdout.split())


def test_the_diagnosis_names_every_terrain_run_it_replays(many_runs, short_campaign):
    from juno.diagnose.search import terrain_runs_named
    assert terrain_runs_named(load_campaign(many_runs)) == "terrain runs t3d, t3d_east"
    assert terrain_runs_named(load_campaign(short_campaign)) == "terrain run t3d"


def test_a_drawbar_run_without_a_steady_window_is_said_to_be_averaged_whole(short_campaign, tmp_path,
                                                                             harness_fmu):
    from juno.identify import identify_paper_runs

    def no_windows(root: Path, manifest: dict) -> None:
        for run in manifest["runs"]:
            run.pop("steady_window", None)
    root = variant(short_campaign, tmp_path / "no-windows", manifest_change=no_windows)
    said: list[str] = []
    results = identify_paper_runs(harness_fmu, load_campaign(root), ["dbp1"], max_evaluations=5, workers=1,
                                  progress=said.append)
    assert said[0].startswith("dbp1: no steady_window in the manifest"), said
    run = read_run(load_campaign(root), "dbp1")
    assert results[0].averages.window == (run.time[0], run.time[-1])


# ------------------------------------------------------------------ a campaign without IMU angles

#: The IMU's attitude columns, all optional (docs/campaign-format.md, "What roll, pitch and yaw buy").
IMU_ANGLES = ("roll", "pitch", "yaw")


def without_imu_angles(header: list[str], rows: list[list[str]]) -> Table:
    """No roll, pitch or yaw column (an IMU that gives none, or none at all); rows left empty dropped."""
    keep = [i for i, name in enumerate(header) if name not in IMU_ANGLES]
    header = [header[i] for i in keep]
    rows = [[row[i] for i in keep] for row in rows]
    return header, [row for row in rows if any(cell for j, cell in enumerate(row) if header[j] != "time")]


@pytest.fixture(scope="module")
def no_imu_angles(short_campaign, tmp_path_factory) -> Path:
    return variant(short_campaign, tmp_path_factory.mktemp("no-imu") / "campaign", without_imu_angles)


def _missing(entries: list[dict]) -> dict[tuple[str, str], dict]:
    """A ``missing_columns`` JSON list by (column, kind)."""
    return {(m["column"], m["kind"]): m for m in entries}


def test_the_columns_a_campaign_lacks_are_named_with_the_runs_and_what_each_costs(no_imu_angles, short_campaign):
    """Each optional column a kind of run uses (OPTIONAL_COLUMN_USES), lacking from the runs of
    that kind, is named once per kind with those runs and what its absence costs there; the
    IMU's accelerations and rates, which no analysis uses, are not; a full campaign lacks nothing."""
    from juno.campaign import OPTIONAL_COLUMN_USES, missing_columns
    found = missing_columns(load_campaign(no_imu_angles))
    assert [(m.column, m.kind) for m in found] == [("pitch", "drawbar"), ("pitch", "terrain"), ("roll", "terrain"),
                                                   ("yaw", "drawbar"), ("yaw", "terrain")]
    for m in found:
        assert m.runs == (("dbp1", "dbp2", "dbp3") if m.kind == "drawbar" else ("t3d",)), m
        assert m.consequence == OPTIONAL_COLUMN_USES[m.column][m.kind]
    assert "k_h" in OPTIONAL_COLUMN_USES["pitch"]["drawbar"]
    assert "not tested against its scan" in OPTIONAL_COLUMN_USES["yaw"]["terrain"]
    assert [(m.column, m.kind) for m in missing_columns(load_campaign(no_imu_angles), ("terrain",))] == \
        [("pitch", "terrain"), ("roll", "terrain"), ("yaw", "terrain")]
    assert missing_columns(load_campaign(short_campaign)) == []


def test_a_fit_without_imu_angles_states_no_more_certainty_than_it_has(no_imu_angles, short_campaign, harness_fmu):
    """Without pitch the joint fit sees k_h less well, and the replay's own error moves k_h and eta
    by several of their noise's deviations (on this campaign's exact data k_h -7.7 %, 2.9 of
    them); what the fit states must still hold: either every estimate lies within Z_MAX of its
    stated 1-sigma uncertainties of the truth, the replay's bias (measured by the bootstrap at the
    fit) included in them, or the fit states no uncertainty at all (status "not converged", every
    ``std`` infinite) and a doubt says why: where it stopped, the residuals are not differentiable
    at the Jacobian's step (a Jacobian from a step ten times larger does not reproduce it), so
    neither the point nor a covariance from that Jacobian is an estimate.  Never a value far off
    with a small uncertainty."""
    result = identify_joint(harness_fmu, load_campaign(no_imu_angles), workers=1)
    truth = truth_soil(short_campaign)
    z = {k: (result.params[k] - truth[k]) / result.std[k] for k in SOIL_PARAMETERS}
    say(f"{no_imu_angles}: status {result.status}, {result.evaluations} evaluations, z-scores "
        + ", ".join(f"{k} {v:+.2f}" for k, v in z.items()))
    if result.status == "ok":
        far = {k: round(v, 2) for k, v in z.items() if not abs(v) <= Z_MAX}
        assert not far, f"estimates more than {Z_MAX} sigma off the truth: {far}"
    else:
        assert result.status == "not converged", result.status
        assert all(np.isinf(s) for s in result.std.values()), result.std
        assert set(result.identifiability.values()) == {"not identified"}
        assert any("not differentiable" in d for d in result.doubts), result.doubts


@pytest.fixture(scope="module")
def exact_short_campaign(tmp_path_factory, harness_fmu) -> Path:
    """The short campaign's truth measured exactly (noise 0)."""
    return synthesize(tmp_path_factory.mktemp("exact") / "campaign", seed=SHORT_SEED, noise=0.0,
                      time_scale=SHORT_TIME_SCALE, fmu=harness_fmu)


@pytest.mark.parametrize("imu_angles", [True, False], ids=["with IMU angles", "without IMU angles"])
def test_on_exact_data_the_stated_replay_bias_is_the_fits_whole_error(exact_short_campaign, tmp_path, harness_fmu,
                                                                       imu_angles):
    """On exact data a fit's error is the replay's own alone, and the bootstrap at the fitted soil
    (runs simulated with it, refitted as the data were) measures it: for every parameter the
    stated bias (``replay_bias``) is the estimate's offset from the truth to within the statistical
    1 sigma, and the stated ``std`` is the statistical and the systematic parts in quadrature.  The
    bias is not zero even with the IMU angles (the replay follows the spins through a PID at the
    fit's step, where motors drove the rover), and without pitch it is several statistical sigmas."""
    root = exact_short_campaign if imu_angles else variant(exact_short_campaign, tmp_path / "no-imu",
                                                           without_imu_angles)
    result = identify_joint(harness_fmu, load_campaign(root), workers=1, estimate_bias=True)
    truth = truth_soil(exact_short_campaign)
    say(f"{root}: exact data, error / replay bias / statistical sigma: " + ", ".join(
        f"{k} {result.params[k] / truth[k] - 1:+.2%} / {result.replay_bias[k] / truth[k]:+.2%} / "
        f"{result.std_statistical[k] / truth[k]:.2%}" for k in SOIL_PARAMETERS))
    assert result.status == "ok" and result.bias_refit["status"] == "ok", (result.status, result.bias_refit)
    for k in SOIL_PARAMETERS:
        error = result.params[k] - truth[k]
        assert abs(error - result.replay_bias[k]) <= result.std_statistical[k], (k, error, result.replay_bias[k])
        assert result.std_systematic[k] == abs(result.replay_bias[k])
        assert result.std[k] == pytest.approx(float(np.hypot(result.std_statistical[k], result.replay_bias[k])))
    if not imu_angles:
        assert abs(result.replay_bias["soil.kh"]) > 2 * result.std_statistical["soil.kh"]


def test_the_bias_bootstraps_twin_of_a_terrain_run_rolls_over_the_runs_own_scan(exact_short_campaign, tmp_path,
                                                                                 harness_fmu):
    """With ``--with-terrain`` the bootstrap simulates each terrain run too (synthetic_run on the
    run's gridded scan, driven by its measured torques): at the truth's soil the twin of an exact
    campaign's terrain run reproduces its pose over the mound (height within 1 mm, roll and pitch
    within 0.1 deg) at the measured samples' own times, and a terrain run given no grid is refused
    rather than simulated on flat ground."""
    from juno.identify.base import terrain_grids
    from juno.identify.replay_bias import synthetic_run
    campaign = load_campaign(exact_short_campaign)
    run = next(r for r in campaign.runs if r.kind == "terrain")
    data = read_run(campaign, run)
    grid = terrain_grids(campaign, tmp_path, "identify --with-terrain")[run.id]
    twin = synthetic_run(harness_fmu, campaign, run, data, truth_soil(exact_short_campaign), terrain_file=grid)
    np.testing.assert_array_equal(twin.time, data.time)
    for column, tolerance in (("pos_z", 1e-3), ("roll", np.radians(0.1)), ("pitch", np.radians(0.1))):
        measured, simulated = data.columns[column], twin.columns[column]
        sampled = np.isfinite(measured)
        np.testing.assert_array_equal(np.isfinite(simulated), sampled)
        error = float(np.max(np.abs(simulated[sampled] - measured[sampled])))
        say(f"{run.id} {column}: twin minus measured at most {error:.2e}")
        assert error <= tolerance, (column, error)
    with pytest.raises(ValueError, match="gridded terrain"):
        synthetic_run(harness_fmu, campaign, run, data, truth_soil(exact_short_campaign), terrain_file=None)


def test_with_every_column_the_fit_states_the_noise_alone_unless_asked_for_the_bias(exact_short_campaign,
                                                                                      harness_fmu):
    """By default (``estimate_bias`` None, ``--replay-bias auto``) a campaign whose runs have every
    column the fit uses gets no bootstrap: it states no bias, and its ``std`` is the statistical
    part alone.  Asked for (``estimate_bias=True``, ``--replay-bias on``), the same soil and the
    same statistical part, and a larger total."""
    campaign = load_campaign(exact_short_campaign)
    plain = identify_joint(harness_fmu, campaign, workers=1)
    full = identify_joint(harness_fmu, campaign, workers=1, estimate_bias=True)
    assert plain.params == full.params and plain.std_statistical == full.std_statistical
    assert plain.std == plain.std_statistical
    assert plain.replay_bias == {} and plain.std_systematic == {} and plain.bias_refit is None
    assert all(full.std[k] > plain.std[k] for k in SOIL_PARAMETERS)


def test_identify_validate_and_diagnose_say_which_angles_are_missing_and_what_that_costs(no_imu_angles, tmp_path,
                                                                                        capsys):
    """Each command prints every missing column once, as a line naming the column, the runs and
    the cost, and carries the same in its JSON (``missing_columns``), for the kinds of run it
    uses: the joint fit its drawbar runs, validate (given the soil) its terrain run, the diagnosis
    both.  The structure test of the drawbar runs, which measure no pitch, lists no pitch among
    the signals it tested or calibrated."""
    from juno.campaign import missing_columns
    every = {(m.column, m.kind): m for m in missing_columns(load_campaign(no_imu_angles))}
    identified, validated, diagnosed = tmp_path / "identify.json", tmp_path / "validate.json", tmp_path / "diagnose.json"
    commands = {
        identified: ("identify", no_imu_angles, "--method", "joint", "--workers", "1"),
        validated: ("validate", no_imu_angles, "--params", identified),
        diagnosed: ("diagnose", no_imu_angles, "--candidates", "drivetrain_loss", "--workers", "1"),
    }
    expected = {identified: [("pitch", "drawbar"), ("yaw", "drawbar")],
                validated: [("pitch", "terrain"), ("roll", "terrain"), ("yaw", "terrain")],
                diagnosed: list(every)}
    for out, args in commands.items():
        proc = run_juno_here(capsys, *args, "--quiet", "--json", out)
        assert proc.returncode == 0, proc.stderr
        entries = json.loads(out.read_text())["missing_columns"]
        assert [(m["column"], m["kind"]) for m in entries] == expected[out], (args[0], entries)
        for key, m in _missing(entries).items():
            assert m["runs"] == list(every[key].runs) and m["consequence"] == every[key].consequence
            assert proc.stdout.count(every[key].sentence() + "\n") == 1, (args[0], proc.stdout)
    structure = json.loads(diagnosed.read_text())["structure"]["base"]
    assert "pitch" not in structure["contact_signals"] and "pitch" not in [s["signal"] for s in structure["signals"]]
    assert {"torque_left", "torque_right"} <= set(structure["contact_signals"])


def test_the_report_says_what_the_campaign_lacks_and_that_its_joint_fit_is_doubtful(no_imu_angles, tmp_path):
    """A report reader sees, before any estimate, what the campaign's runs lack (with what that
    costs) and, above the joint fit's table, every reason to doubt it; summary.json carries both."""
    from juno.campaign import missing_columns
    from juno.identify import JointResult
    from juno.report import write_report
    from juno.rover_model import SOIL_PARAMETERS
    campaign = load_campaign(no_imu_angles)
    doubts = ["soil.gamma at the limit of its range (0.002)", "structure beyond sensor noise: pos_x 5.2 x noise"]
    n = len(SOIL_PARAMETERS)
    joint = JointResult(params={k: 1.0 for k in SOIL_PARAMETERS}, std={k: 0.01 for k in SOIL_PARAMETERS},
                        relative_std={k: 0.01 for k in SOIL_PARAMETERS}, correlation=np.eye(n),
                        identifiability={k: "pinned" for k in SOIL_PARAMETERS}, cost=5.0, evaluations=27,
                        wall_time=1.0, runs=["dbp1", "dbp2", "dbp3"], doubts=doubts)
    text = write_report(tmp_path / "report", campaign, [], joint, []).read_text()
    for m in missing_columns(campaign, ("drawbar", "terrain")):
        assert f"- {m.sentence()}" in text
    section = text[text.index("## 2. Joint identification"):]
    table = section.index("| Parameter |")
    assert "**The fit is doubtful**" in section[:table]
    assert all(f"- {d}" in section[:table] for d in doubts)
    summary = json.loads((tmp_path / "report" / "summary.json").read_text())
    assert summary["joint"]["doubts"] == doubts
    assert [(m["column"], m["kind"]) for m in summary["missing_columns"]] == \
        [(m.column, m.kind) for m in missing_columns(campaign, ("drawbar", "terrain"))]


def test_validate_that_identifies_first_says_when_the_soil_it_validates_is_doubtful(short_campaign, tmp_path,
                                                                                   capsys):
    """Without --params, validate fits the soil itself; a fit the data make doubtful (a pitch
    sensor 1.5 degrees off on a mounting the manifest says is calibrated, so the soil bends to
    absorb it) is validated all the same, and the printout and the JSON (``soil_doubts``) say why
    it should not be trusted."""
    bias = float(np.radians(1.5))

    def pitch_biased(header: list[str], rows: list[list[str]]) -> Table:
        i = header.index("pitch")
        return header, [[repr(float(c) + bias) if j == i and c != "" else c for j, c in enumerate(row)]
                        for row in rows]

    root = variant(short_campaign, tmp_path / "campaign", pitch_biased)
    manifest = root / "campaign.json"
    manifest.write_text(json.dumps({**json.loads(manifest.read_text()), "imu_mounting": "calibrated"}))
    out = tmp_path / "validate.json"
    proc = run_juno_here(capsys, "validate", root, "--quiet", "--json", out)
    assert proc.returncode == 0, proc.stderr
    doubts = json.loads(out.read_text())["soil_doubts"]
    assert any("structure beyond sensor noise" in d for d in doubts), doubts
    for d in doubts:
        assert f"the soil validated comes from a doubtful joint fit: {d}\n" in proc.stdout


def _torque_noise_stated(root: Path, manifest: dict) -> None:
    manifest["sensor_noise"] = {"torque_left": 3.0, "torque_right": 3.0}


def test_the_report_says_which_sensor_noise_the_manifest_states(short_campaign, tmp_path):
    """A noise stated in the manifest is what the report's noise ratios are in units of: the
    report lists it beside the estimate from the samples (before any estimate), and summary.json
    carries every run's columns with the noise used and where it comes from."""
    from juno.report import write_report
    campaign = load_campaign(variant(short_campaign, tmp_path / "stated", manifest_change=_torque_noise_stated))
    report = write_report(tmp_path / "report", campaign, [], None, [])
    text = report.read_text()
    assert "The campaign's sensor noise:" in text
    assert "- sensor noise stated in the manifest: torque_left 3 in runs " in text
    summary = json.loads((report.parent / "summary.json").read_text())
    by_column = {(n["run"], n["column"]): n for n in summary["sensor_noise"]}
    for run in campaign.runs:
        assert by_column[(run.id, "torque_left")]["source"] == "stated"
        assert by_column[(run.id, "torque_left")]["noise"] == 3.0
        assert by_column[(run.id, "omega_left")]["source"] == "estimated"
    plain = write_report(tmp_path / "plain", load_campaign(short_campaign), [], None, []).read_text()
    assert "sensor noise" not in plain


@pytest.mark.parametrize("status", ["not converged", "not identified"])
def test_a_bias_refit_that_did_not_converge_states_no_bias(status):
    """The bootstrap's refit is a fit like any other: one that did not converge, or did not move
    from its start, is no estimate of the synthetic world's soil, so its offset from the fit is
    no bias. The fit then states the noise's part alone, records the refit's status, and a doubt
    says the bias could not be estimated; a refit stopped at its evaluation limit is stated, with
    a doubt."""
    from juno.identify import JointResult
    from juno.identify.joint import EVALUATION_LIMIT, _add_replay_bias
    from juno.identify.replay_bias import ReplayBias

    def fit() -> JointResult:
        n = len(SOIL_PARAMETERS)
        return JointResult(params={k: 1.0 for k in SOIL_PARAMETERS}, std={k: 0.01 for k in SOIL_PARAMETERS},
                           relative_std={k: 0.01 for k in SOIL_PARAMETERS}, correlation=np.eye(n),
                           identifiability={k: "pinned" for k in SOIL_PARAMETERS}, cost=1.0, evaluations=20,
                           wall_time=1.0, runs=["dbp1"], std_statistical={k: 0.01 for k in SOIL_PARAMETERS})
    far = {k: 1.5 for k in SOIL_PARAMETERS}
    failed = fit()
    _add_replay_bias(failed, ReplayBias(params=far, status=status, evaluations=30, wall_time=1.0))
    assert failed.replay_bias == {} and failed.std_systematic == {}
    assert failed.std == failed.std_statistical
    assert failed.bias_refit["status"] == status
    assert any("could not be estimated" in d and status in d for d in failed.doubts), failed.doubts
    stopped = fit()
    _add_replay_bias(stopped, ReplayBias(params=far, status=EVALUATION_LIMIT, evaluations=30, wall_time=1.0))
    assert stopped.replay_bias == pytest.approx({k: 0.5 for k in SOIL_PARAMETERS})
    assert any("where that refit stopped" in d for d in stopped.doubts), stopped.doubts
