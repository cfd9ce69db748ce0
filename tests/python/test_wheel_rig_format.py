"""Specification of the wheel_rig kind of measured run: a single-wheel testbed's table of steady
points, read as strictly as the other kinds (every refusal names file, line and column), and its
plausibility checks (units a lab may have mixed up)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from juno.campaign import (RigSetup, format_rig_csv, load_campaign, read_any, read_rig, read_rig_csv, read_run,
                           write_campaign)
from juno.errors import InputError
from juno.plausibility import PlausibilityError, check_campaign, enforce_plausibility

REPO = Path(__file__).resolve().parents[2]

GOOD_TABLE = """vertical_load,slip,drawbar_pull,drawbar_pull_std,torque,sinkage,operator
80,0.0,-6.5,0.8,0.0,0.005,kk
80,0.1,11.0,0.8,3.0,0.0055,kk
80,0.2,14.5,0.8,4.2,0.0075,kk
80,0.4,15.0,0.8,5.0,0.0125,kk
"""
WHEEL = {"radius": 0.157, "width": 0.165, "lug_height": 0.0, "lug_count": 0}


def make_campaign(root: Path, table: str = GOOD_TABLE, entry: dict | None = None, extra_runs: list | None = None) -> Path:
    """A campaign folder with one wheel_rig run ``rig`` (runs/rig.csv = ``table``)."""
    (root / "runs").mkdir(parents=True, exist_ok=True)
    (root / "runs" / "rig.csv").write_text(table)
    run = {"id": "rig", "kind": "wheel_rig", "file": "runs/rig.csv", "wheel": dict(WHEEL), "carriage_speed": 0.01}
    run.update(entry or {})
    manifest = {"name": "rig-test", "runs": [run] + (extra_runs or [])}
    (root / "campaign.json").write_text(json.dumps(manifest, indent=2))
    return root


def refusal(path: Path) -> InputError:
    with pytest.raises(InputError) as info:
        read_rig_csv(path)
    return info.value


def test_a_rig_campaign_loads_with_its_wheel_and_table(tmp_path):
    """The manifest's wheel becomes a RigSetup, the table's columns float arrays, unknown columns extra."""
    campaign = load_campaign(make_campaign(tmp_path))
    spec = campaign.run("rig")
    assert spec.kind == "wheel_rig"
    assert spec.rig == RigSetup(radius=0.157, width=0.165, lug_height=0.0, lug_count=0, carriage_speed=0.01)
    assert not spec.rig.lugged
    table = read_rig(campaign, spec)
    assert len(table) == 4
    np.testing.assert_array_equal(table["slip"], [0.0, 0.1, 0.2, 0.4])
    np.testing.assert_array_equal(table.std("drawbar_pull"), [0.8] * 4)
    assert table.std("torque") is None
    np.testing.assert_array_equal(table.slip_angle, np.zeros(4))
    assert list(table.extra) == ["operator"]
    assert read_any(campaign, spec).columns.keys() == table.columns.keys()
    assert check_campaign(campaign) == []


def test_a_time_series_reader_refuses_a_rig_table_by_name(tmp_path):
    """read_run (time series) given a wheel_rig run says what it is and where, not an AttributeError."""
    campaign = load_campaign(make_campaign(tmp_path))
    with pytest.raises(InputError, match="'rig' is a wheel_rig table") as info:
        read_run(campaign, "rig")
    assert info.value.path.endswith("campaign.json") and info.value.line is not None


def test_the_example_rig_campaign_loads_and_is_plausible():
    campaign = load_campaign(REPO / "docs" / "example-rig-campaign")
    rigs = campaign.runs_of_kind("wheel_rig")
    assert len(rigs) >= 2 and {r.rig.lugged for r in rigs} == {True, False}
    for spec in rigs:
        assert len(read_rig(campaign, spec)) >= 5
    assert [f for f in check_campaign(campaign) if f.severity == "error"] == []


@pytest.mark.parametrize("text, line, column, message", [
    ("slip,drawbar_pull\n0.1,3\n", 1, "vertical_load", "missing required column"),
    ("vertical_load,slip,drawbar_pull\n80,0.1,abc\n", 2, "drawbar_pull", "not a number"),
    ("vertical_load,slip,drawbar_pull\n80,0.1,3\n80,,4\n", 3, "slip", "set point"),
    ("vertical_load,slip,drawbar_pull,slip_angle\n80,0.1,3,0\n80,0.2,4,\n", 3, "slip_angle", "set point"),
    ("vertical_load,slip,drawbar_pull\n80,0.1,nan\n", 2, "drawbar_pull", "not finite"),
    ("vertical_load,slip,drawbar_pull\n80,0.1,3\n80,0.2\n", 3, None, "row has 2 cells"),
    ("vertical_load,slip,drawbar_pull,torque\n80,0.1,3,\n80,0.2,4,\n", 1, "torque", "no values"),
    ("vertical_load,slip,drawbar_pull,torque_std\n80,0.1,3,0.5\n", 1, "torque_std", "without its measured"),
    ("vertical_load,slip,drawbar_pull,drawbar_pull_std\n80,0.1,3,0.5\n80,0.2,4,\n", 3, "drawbar_pull_std",
     "standard deviation is empty"),
    ("vertical_load,slip,drawbar_pull,drawbar_pull_std\n80,0.1,3,0.5\n80,0.2,4,0\n", 3, "drawbar_pull_std",
     "must be > 0"),
    ("vertical_load,slip,drawbar_pull,slip\n80,0.1,3,0.1\n", 1, "slip", "duplicate column"),
    ("vertical_load,slip,drawbar_pull\n", 1, None, "only a header"),
    ("vertical_load,slip,drawbar_pull\n80,0.1,3\n80,0.1,3\n", 3, None, "repeats line 2"),
    ("vertical_load,slip,drawbar_pull,clock\n80,0.1,3,17\n80,0.2,4,18\n80.0,0.10,3.0,17\n", 4, None,
     "repeats line 2"),
])
def test_bad_tables_are_refused_naming_line_and_column(tmp_path, text, line, column, message):
    path = tmp_path / "rig.csv"
    path.write_text(text)
    error = refusal(path)
    assert message in error.message
    assert (error.path, error.line, error.column) == (str(path), line, column)
    assert str(error).startswith(f"{path}, line {line}")


def test_repeated_set_points_are_kept_and_a_repeated_row_is_refused(tmp_path):
    """Rows are steady points in any order: a set point measured twice is two points, but a row
    equal cell for cell to another (its clock too, when it has one) counts one point twice, as a
    repeated time stamp would in a rover run; a column of one's own tells genuine repeats apart."""
    path = tmp_path / "rig.csv"
    path.write_text("vertical_load,slip,drawbar_pull\n80,0.1,3\n80,0.2,4\n80,0.1,3.2\n")
    assert len(read_rig_csv(path)) == 3
    path.write_text("vertical_load,slip,drawbar_pull,repeat\n80,0.1,3,1\n80,0.1,3,2\n")
    assert len(read_rig_csv(path)) == 2
    path.write_text("vertical_load,slip,drawbar_pull,torque,operator\n80,0.1,3,,kk\n80,0.2,4,1,kk\n80,0.1,3,,kk\n")
    error = refusal(path)
    assert (error.line, error.column) == (4, None) and "counts one point twice" in error.message


@pytest.mark.parametrize("change, message", [
    ({"wheel": None}, "needs a 'wheel' object"),
    ({"wheel": {"radius": 0.157}}, "'wheel' needs 'width'"),
    ({"wheel": {**WHEEL, "radius_m": 0.1}}, "'wheel' has no key 'radius_m'"),
    ({"wheel": {**WHEEL, "radius": -0.1}}, "'wheel.radius' must be a finite number > 0"),
    ({"wheel": {**WHEEL, "lug_height": 0.01}}, "a lugged wheel has both > 0"),
    ({"wheel": {**WHEEL, "lug_count": 2.5}}, "'wheel.lug_count' must be a whole number"),
    ({"carriage_speed": 0}, "'carriage_speed' must be a finite number > 0"),
    ({"steady_window": [0, 1]}, "takes no 'steady_window'"),
    ({"terrain": "runs/rig.csv"}, "take no 'terrain' key"),
])
def test_bad_rig_entries_are_refused_naming_the_run(tmp_path, change, message):
    entry = {k: v for k, v in change.items() if v is not None}
    root = make_campaign(tmp_path, entry=entry)
    if change.get("wheel", 1) is None:
        doc = json.loads((root / "campaign.json").read_text())
        del doc["runs"][0]["wheel"]
        (root / "campaign.json").write_text(json.dumps(doc, indent=2))
    with pytest.raises(InputError) as info:
        load_campaign(root)
    assert message in str(info.value)
    assert "runs[0] (id 'rig')" in str(info.value) and info.value.line == 5  # the line of its "id"


def test_a_drawbar_run_takes_no_wheel(tmp_path):
    (tmp_path / "runs").mkdir()
    (tmp_path / "runs" / "d.csv").write_text("time\n0\n")
    root = make_campaign(tmp_path, extra_runs=[{"id": "d", "kind": "drawbar", "file": "runs/d.csv", "wheel": WHEEL}])
    with pytest.raises(InputError, match="'wheel' describes a wheel_rig run's testbed"):
        load_campaign(root)


@pytest.mark.parametrize("table, column, severity, evidence", [
    ("vertical_load,slip,drawbar_pull\n80,10,3\n80,20,5\n", "slip", "error", "looks like percent"),
    ("vertical_load,slip,drawbar_pull\n0,0.1,3\n", "vertical_load", "error", "load > 0"),
    ("vertical_load,slip,drawbar_pull,torque\n8.2,0.1,11,3\n8.2,0.3,24.5,7.2\n", "drawbar_pull", "error",
     "is the load in kg"),
    ("vertical_load,slip,drawbar_pull,torque\n8.2,0.1,1,3\n8.2,0.3,2,7.2\n", "torque", "error", "is the load in kg"),
    ("vertical_load,slip,drawbar_pull,torque\n80,0.1,11,3000\n80,0.3,24.5,7200\n", "torque", "error",
     "looks like N mm"),
    ("vertical_load,slip,drawbar_pull\n0.08,0.1,11\n0.08,0.3,24.5\n", "drawbar_pull", "error", "is the load in kN"),
    ("vertical_load,slip,drawbar_pull,sinkage\n80,0.1,3,5\n80,0.2,4,7.5\n", "sinkage", "error",
     "looks like millimetres"),
    ("vertical_load,slip,drawbar_pull,slip_angle\n80,0.1,3,10\n80,0.2,4,20\n", "slip_angle", "error",
     "looks like degrees"),
    ("vertical_load,slip,drawbar_pull,slip_angle\n80,0.1,3,0.9\n", "slip_angle", "warning", "beyond pi/4"),
    ("vertical_load,slip,drawbar_pull\n80,0.1,90\n", "drawbar_pull", "warning", "friction limits"),
])
def test_implausible_units_are_named_with_their_evidence(tmp_path, table, column, severity, evidence):
    campaign = load_campaign(make_campaign(tmp_path, table=table))
    found = [f for f in check_campaign(campaign) if f.column == column]
    assert len(found) == 1, check_campaign(campaign)
    assert found[0].severity == severity and evidence in found[0].message
    assert found[0].file == "runs/rig.csv" and "line " in found[0].message
    if severity == "error":
        with pytest.raises(PlausibilityError, match=column):
            enforce_plausibility(campaign, stream=lambda line: None)


#: Ding et al.'s smooth wheel (docs/example-rig-campaign): a slip-pull curve from rolling into traction.
DING_SMOOTH = [(80, 0.0, -6.5, 0.0), (80, 0.1, 14.0, 3.5), (80, 0.2, 20.0, 5.0), (80, 0.3, 22.0, 5.8),
               (80, 0.4, 23.0, 6.3), (80, 0.6, 24.5, 7.2)]


def rig_table(rows, pull_scale: float = 1.0, torque_scale: float = 1.0) -> str:
    body = "".join(f"{w:g},{s:g},{p * pull_scale:g},{t * torque_scale:g}\n" for w, s, p, t in rows)
    return "vertical_load,slip,drawbar_pull,torque\n" + body


def test_a_drawbar_pull_in_kn_is_named_against_the_thrust_the_torque_gives(tmp_path):
    """Over slips from rolling into traction the drawbar pull is a sizeable part of the thrust the
    torque transmits (torque / radius): under 1 % of it throughout, where a thousand times it is a
    plausible pull, is a drawbar pull in kN; an error naming the column, its largest value and "kN?"."""
    def pull_findings(name, table):
        campaign = load_campaign(make_campaign(tmp_path / name, table=table))
        return [f for f in check_campaign(campaign) if f.column == "drawbar_pull"]

    found = pull_findings("kn", rig_table(DING_SMOOTH, pull_scale=1e-3))
    assert len(found) == 1 and found[0].severity == "error", found
    assert found[0].file == "runs/rig.csv" and "kN?" in found[0].message
    assert "0.0245" in found[0].message and "line 7" in found[0].message
    assert pull_findings("newton", rig_table(DING_SMOOTH)) == []
    # A torque in N mm makes the pull a tiny part of the "thrust" too: the torque is named, not the pull.
    assert pull_findings("nmm", rig_table(DING_SMOOTH, torque_scale=1e3)) == []
    # Slips that stay in one regime (here all beyond 0.3) do not say how large the pull must be.
    assert pull_findings("one_regime", rig_table(DING_SMOOTH[3:], pull_scale=1e-3)) == []


@pytest.mark.parametrize("wheel, column", [
    ({**WHEEL, "radius": 157.35}, "wheel.radius"),
    ({**WHEEL, "width": 165.0}, "wheel.width"),
    ({**WHEEL, "lug_height": 10.0, "lug_count": 30}, "wheel.lug_height"),
    ({**WHEEL, "lug_height": 0.09, "lug_count": 30}, "wheel.lug_height"),
])
def test_a_wheel_in_millimetres_is_an_error(tmp_path, wheel, column):
    campaign = load_campaign(make_campaign(tmp_path, entry={"wheel": wheel}))
    found = [f for f in check_campaign(campaign) if f.column == column]
    assert len(found) == 1 and found[0].severity == "error" and found[0].file == "campaign.json"
    assert "'rig'" in found[0].message


def test_write_campaign_round_trips_a_rig_table_exactly(tmp_path):
    """A rig table written by write_campaign reads back bit for bit (NaN = not measured)."""
    table = {"vertical_load": np.array([80.0, 80.0, 120.0]), "slip": np.array([0.1, 1 / 3, 0.5]),
             "drawbar_pull": np.array([3.25, 7.1, np.nan]), "sinkage": np.array([0.004, 0.0071, 0.0123])}
    manifest = {"name": "w", "runs": [{"id": "a", "kind": "wheel_rig", "wheel": WHEEL}]}
    campaign = write_campaign(tmp_path / "w", manifest, {"a": table})
    back = read_rig(campaign, "a")
    for name, values in table.items():
        np.testing.assert_array_equal(back[name], values)
    assert format_rig_csv(table).splitlines()[0] == "vertical_load,slip,drawbar_pull,sinkage"


def test_a_mixed_campaign_keeps_rig_tables_out_of_the_replays(tmp_path):
    """A campaign may hold drawbar, terrain and wheel_rig runs: it loads and is checked whole; the
    diagnosis replays only the time series (the rig fit takes the tables)."""
    import shutil

    from juno.diagnose.problem import _prepared_runs

    root = tmp_path / "mixed"
    shutil.copytree(REPO / "docs" / "example-campaign", root)
    (root / "runs" / "rig.csv").write_text(GOOD_TABLE)
    doc = json.loads((root / "campaign.json").read_text())
    doc["runs"].append({"id": "rig", "kind": "wheel_rig", "file": "runs/rig.csv", "wheel": WHEEL})
    (root / "campaign.json").write_text(json.dumps(doc, indent=2))
    campaign = load_campaign(root)
    assert [r.kind for r in campaign.runs] == ["drawbar", "terrain", "wheel_rig"]
    assert [f for f in check_campaign(campaign) if f.severity == "error"] == []
    assert [p.run_id for p in _prepared_runs(campaign, None, None, "spin")] == ["dbp1"]


def test_a_missing_rig_fmu_says_how_to_build_and_give_it(tmp_path):
    from juno.wheel_rig import RigFMU

    with pytest.raises(FileNotFoundError) as info:
        RigFMU(tmp_path / "WheelRig.fmu")
    assert "cmake --build build" in str(info.value) and "--rig-fmu" in str(info.value)
    assert "JUNO_RIG_FMU" in str(info.value)


def test_juno_refuses_a_bad_table_before_any_fit(capsys, tmp_path):
    """`juno identify` and `juno report` on a rig campaign whose table breaks the format: exit 2,
    one line naming the file, line and column, nothing written."""
    from hostile_cases import refused

    make_campaign(tmp_path / "c", table="vertical_load,slip,drawbar_pull\n80,0.1,abc\n")
    needles = ["runs/rig.csv, line 2, column 'drawbar_pull'", "not a number"]
    refused(capsys, tmp_path, ["identify", "{w}/c", "--rig-fmu", "{w}/none.fmu"], needles)
    refused(capsys, tmp_path, ["report", "{w}/c", "--out", "{w}/report", "--rig-fmu", "{w}/none.fmu"], needles)


def test_juno_stops_on_a_slip_in_percent_before_any_fit(capsys, tmp_path):
    """A plausibility error stops `juno identify` (exit 2) with the file, column and evidence,
    before the rig FMU is even looked for."""
    from juno.cli import main

    make_campaign(tmp_path / "c", table="vertical_load,slip,drawbar_pull\n80,20,3\n")
    assert main(["identify", str(tmp_path / "c"), "--rig-fmu", str(tmp_path / "none.fmu")]) == 2
    err = capsys.readouterr().err
    assert "runs/rig.csv, column 'slip'" in err and "looks like percent" in err and "none.fmu" not in err


def test_the_rig_fmu_is_found_as_the_rover_fmu_is(tmp_path, monkeypatch):
    """$JUNO_RIG_FMU first; else WheelRig.fmu beside $JUNO_FMU; else the checkout's build (or the
    copy the installed package carries)."""
    from juno.wheel_rig import PACKAGED_RIG_FMU, default_rig_fmu_path

    monkeypatch.setenv("JUNO_RIG_FMU", str(tmp_path / "mine.fmu"))
    assert default_rig_fmu_path() == tmp_path / "mine.fmu"
    monkeypatch.delenv("JUNO_RIG_FMU")
    (tmp_path / "WheelRig.fmu").write_bytes(b"")
    monkeypatch.setenv("JUNO_FMU", str(tmp_path / "JunoRover.fmu"))
    assert default_rig_fmu_path() == tmp_path / "WheelRig.fmu"
    monkeypatch.delenv("JUNO_FMU")
    assert default_rig_fmu_path() in (REPO / "build" / "WheelRig.fmu", PACKAGED_RIG_FMU)


def test_a_pull_that_does_more_work_than_the_torque_puts_in_is_an_error(tmp_path):
    """The soil gives back no more power than the wheel's motor puts in: drawbar_pull (1 - slip)
    <= torque / radius in every row, braking rows included. A torque a thousand times too small
    (kN m) breaks it by far more than a tenth of the load: an error on the torque naming the row;
    Ding's table, with a braking row added, keeps it."""
    def torque_findings(name, table):
        campaign = load_campaign(make_campaign(tmp_path / name, table=table))
        return [f for f in check_campaign(campaign) if f.column == "torque"]

    found = torque_findings("knm", rig_table(DING_SMOOTH, torque_scale=1e-3))
    assert len(found) == 1 and found[0].severity == "error", found
    assert "does more work than the torque" in found[0].message and "line 4" in found[0].message
    assert torque_findings("newton", rig_table(DING_SMOOTH + [(80, -0.2, -20.0, -1.0)])) == []


def test_two_columns_written_under_each_others_names_are_named_as_swapped(tmp_path):
    """When a table passes every check with two of its columns exchanged, each finding says which."""
    table = rig_table(DING_SMOOTH).replace("drawbar_pull,torque", "torque,drawbar_pull", 1)
    found = check_campaign(load_campaign(make_campaign(tmp_path, table=table)))
    assert found and all("the columns 'drawbar_pull' and 'torque' look swapped" in f.message for f in found), found
    assert check_campaign(load_campaign(make_campaign(tmp_path / "right", table=rig_table(DING_SMOOTH)))) == []


@pytest.mark.parametrize("rows", [DING_SMOOTH[2:3], [DING_SMOOTH[2], (80, 0.2, 17.0, 4.6), (80, 0.2, 21.5, 5.1)]],
                         ids=["one row", "every row at one slip"])
def test_a_fit_needs_more_values_at_distinct_set_points_than_parameters(tmp_path, capsys, rows):
    """A table of one set point (one row, or rows repeated at one load and slip) holds two values
    (pull and torque) for the law's five parameters: the law would follow it exactly and report
    any soil with a tiny uncertainty. `juno identify` refuses it in one line before the rig FMU
    is looked for, naming the table, its set points and the parameters."""
    from hostile_cases import refused
    from juno.wheel_rig import fit_rig

    make_campaign(tmp_path / "c", table=rig_table(rows))
    line = refused(capsys, tmp_path, ["identify", "{w}/c", "--law", "volumetric", "--rig-fmu", "{w}/none.fmu"],
                   ["runs/rig.csv", "1 distinct set point", "2 measured values", "5 parameters", "soil.kh"])
    assert "none.fmu" not in line
    with pytest.raises(InputError, match="cannot determine them"):
        fit_rig(None, load_campaign(tmp_path / "c"), "wong-reece")
