"""Specification of the measured-campaign format as read by juno.campaign."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from juno.campaign import (
    DEFAULT_IMU_MOUNT,
    aligned,
    forward_speed,
    format_run_csv,
    load_campaign,
    read_run,
    read_run_csv,
    read_terrain_points,
    steady_average,
    write_campaign,
)
from juno.errors import InputError
from juno.sensor_noise import column_noise, sensor_noise

RNG_SEED = 20130815


# ---------------------------------------------------------------------------------------------
# A small synthetic campaign: 100 Hz motors, 50 Hz load cell, 5 Hz total station, 20 Hz IMU.
# ---------------------------------------------------------------------------------------------

def make_run(kind: str, duration: float = 6.0, seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = np.round(np.arange(0.0, duration, 0.01), 10)
    n = len(t)
    every = lambda k: (np.arange(n) % k) == 0  # noqa: E731
    run = {
        "time": t,
        "torque_left": 40.0 + rng.normal(0, 0.5, n),
        "torque_right": 41.0 + rng.normal(0, 0.5, n),
        "omega_left": 1.2 + 0.01 * np.sin(t),
        "omega_right": 1.19 + 0.01 * np.cos(t),
        "pos_x": np.where(every(20), 0.3 * t, np.nan),
        "pos_y": np.where(every(20), 0.01 * t, np.nan),
        "pos_z": np.where(every(20), 0.75, np.nan),
        "yaw": np.where(every(5), 0.0333, np.nan),
        "battery_volts": np.full(n, 48.1),  # unknown column: kept, ignored
    }
    if kind == "drawbar":
        run["drawbar_force"] = np.where(every(2), 250.0 + rng.normal(0, 2, n), np.nan)
    return run


def make_manifest() -> dict:
    return {
        "name": "test-campaign",
        "runs": [
            {"id": "dbp1", "kind": "drawbar", "file": "runs/dbp1.csv", "steady_window": [2.0, 5.0]},
            {"id": "dbp2", "kind": "drawbar", "file": "runs/dbp2.csv", "operator": "kept"},
            {"id": "t3d", "kind": "terrain", "file": "runs/t3d.csv", "terrain": "scan"},
        ],
        "rover": {"wheel.width": 0.254, "drive.mode": 1, "terrain.file": ""},
    }


def make_terrain(seed: int = 1, points: int = 500) -> np.ndarray:
    rng = np.random.default_rng(seed)
    xy = rng.uniform(-2.0, 2.0, size=(points, 2))
    z = 0.5 * np.exp(-(xy ** 2).sum(axis=1) / 0.5)
    return np.column_stack([xy, z])


def make_runs() -> dict[str, dict[str, np.ndarray]]:
    return {"dbp1": make_run("drawbar", seed=1), "dbp2": make_run("drawbar", seed=2), "t3d": make_run("terrain", seed=3)}


@pytest.fixture()
def campaign_dir(tmp_path: Path) -> Path:
    root = tmp_path / "camp"
    write_campaign(root, make_manifest(), make_runs(), {"scan": make_terrain()})
    return root


def snapshot(root: Path) -> dict[str, tuple[bytes, int]]:
    return {str(p.relative_to(root)): (p.read_bytes(), p.stat().st_mtime_ns) for p in sorted(root.rglob("*")) if p.is_file()}


def load_and_read_all(root: Path) -> None:
    c = load_campaign(root)
    for spec in c.runs:
        read_run(c, spec)


def assert_refused(root: Path, *, file: str, line: int | None = None, column: str | None = None, says: str = "") -> InputError:
    """Loading the campaign raises InputError naming file/line/column, and changes no file."""
    before = snapshot(root)
    with pytest.raises(InputError) as info:
        load_and_read_all(root)
    err = info.value
    msg = str(err)
    assert file in msg, msg
    if line is not None:
        assert err.line == line, msg
        assert f"line {line}" in msg, msg
    if column is not None:
        assert err.column == column, msg
        assert f"column '{column}'" in msg, msg
    assert says in msg, msg
    assert snapshot(root) == before, "a refused input was modified"
    return err


def edit_csv(path: Path, row: int, column: str, value: str) -> int:
    """Set the cell of data row ``row`` (0-based) in ``column``; returns its 1-based line."""
    lines = path.read_text(encoding="utf-8").splitlines()
    header = lines[0].split(",")
    cells = lines[row + 1].split(",")
    cells[header.index(column)] = value
    lines[row + 1] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return row + 2


# ---------------------------------------------------------------------------------------------
# Round trip
# ---------------------------------------------------------------------------------------------

def test_round_trip_is_exact(tmp_path: Path) -> None:
    root = tmp_path / "camp"
    runs = make_runs()
    runs["dbp1"]["torque_left"][7] = 1.0 / 3.0  # needs all 17 digits
    terrain = make_terrain()
    returned = write_campaign(root, make_manifest(), runs, {"scan": terrain}, extra_files={"truth.json": "{}"})

    c = load_campaign(root)
    assert c == returned
    assert c.name == "test-campaign"
    assert [r.id for r in c.runs] == ["dbp1", "dbp2", "t3d"]
    assert c.run("dbp1").steady_window == (2.0, 5.0)
    assert c.run("dbp2").steady_window is None
    assert c.run("dbp2").extra == {"operator": "kept"}
    assert c.run("t3d").terrain == "terrain/scan.xyz"
    assert c.rover == {"wheel.width": 0.254, "drive.mode": 1, "terrain.file": ""}
    assert isinstance(c.rover["drive.mode"], int)
    assert (root / "truth.json").read_text() == "{}"
    assert load_campaign(root / "campaign.json") == c

    for rid, cols in runs.items():
        data = read_run(c, rid)
        assert data.run_id == rid and data.kind == c.run(rid).kind
        for name, values in cols.items():
            got = data.extra[name] if name == "battery_volts" else data[name]
            np.testing.assert_array_equal(got, values)  # NaN where NaN, bit-exact elsewhere
        assert "battery_volts" not in data.columns
        np.testing.assert_array_equal(data.time, cols["time"])
        assert data.lines[0] == 2 and data.lines[-1] == len(cols["time"]) + 1
    np.testing.assert_array_equal(read_terrain_points(c, "t3d"), terrain)


def test_a_run_is_read_once_per_loaded_campaign_until_its_file_changes(campaign_dir: Path,
                                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    """The phases of an analysis each read the runs they need: the loaded campaign keeps a run
    once read (its arrays read-only, so no reader changes what the next is given), reads it again
    when its file has changed, and a pickled campaign (sent to a worker) does not carry them."""
    import pickle

    import juno.campaign.tables as tables
    parsed: list[str] = []
    real = tables.read_run_csv
    monkeypatch.setattr(tables, "read_run_csv", lambda path, *a, **k: parsed.append(Path(path).name) or real(path, *a, **k))
    c = load_campaign(campaign_dir)
    first = read_run(c, "dbp1")
    assert read_run(c, c.run("dbp1")) is first and parsed == ["dbp1.csv"]
    with pytest.raises(ValueError, match="read-only"):
        first["torque_left"][0] = 0.0
    assert load_campaign(campaign_dir) == c and read_run(load_campaign(campaign_dir), "dbp1") is not first

    shipped = pickle.dumps(c)
    assert len(shipped) < 2000, "a pickled campaign carries its runs"
    assert pickle.loads(shipped) == c

    path = campaign_dir / "runs" / "dbp1.csv"
    text = path.read_text()
    path.write_text(text.replace("\n2", "\n 2", 1))   # a cell with a space: the same samples, another file
    again = read_run(c, "dbp1")
    assert again is not first and parsed[-1] == "dbp1.csv" and len(parsed) == 3
    np.testing.assert_array_equal(again["torque_left"], first["torque_left"])


def test_write_campaign_refuses_to_overwrite_and_leaves_nothing_on_failure(tmp_path: Path, campaign_dir: Path) -> None:
    before = snapshot(campaign_dir)
    with pytest.raises(FileExistsError):
        write_campaign(campaign_dir, make_manifest(), make_runs(), {"scan": make_terrain()})
    bad = make_run("drawbar")
    bad["time"] = bad["time"][::-1].copy()  # would be refused on reading
    with pytest.raises(ValueError):
        write_campaign(tmp_path / "new", {"runs": [{"id": "a", "kind": "drawbar"}]}, {"a": bad})
    assert not (tmp_path / "new").exists()
    assert [p.name for p in tmp_path.iterdir()] == ["camp"], "temporary folders left behind"
    assert snapshot(campaign_dir) == before


def test_csv_text_format() -> None:
    text = format_run_csv({"pos_x": [np.nan, 0.1], "time": [0.0, 0.5]})
    assert text == "time,pos_x\n0.0,\n0.5,0.1\n"


def test_reads_quoted_cells_crlf_bom_and_spaces(tmp_path: Path) -> None:
    p = tmp_path / "r.csv"
    p.write_bytes(
        b"\xef\xbb\xbftime, torque_left,torque_right,omega_left,omega_right,pos_x,pos_y,pos_z,drawbar_force,note\r\n"
        b'0.0,"1.5",2,3,4,5,6,7,8,hello\r\n'
        b"0.1, 1.5e0 ,2,3,4,,,,,world\r\n\r\n"
    )
    run = read_run_csv(p, "drawbar")
    np.testing.assert_array_equal(run["torque_left"], [1.5, 1.5])
    np.testing.assert_array_equal(run["pos_x"], [5.0, np.nan])
    assert list(run.extra["note"]) == ["hello", "world"]


# ---------------------------------------------------------------------------------------------
# Refusals: each names the file, the line and the column, and changes nothing
# ---------------------------------------------------------------------------------------------

def test_missing_required_column(campaign_dir: Path) -> None:
    p = campaign_dir / "runs/dbp2.csv"
    lines = p.read_text().splitlines()
    header = lines[0].split(",")
    k = header.index("omega_right")
    p.write_text("\n".join(",".join(c for j, c in enumerate(l.split(",")) if j != k) for l in lines) + "\n")
    assert_refused(campaign_dir, file="dbp2.csv", line=1, column="omega_right", says="missing required column")


def test_drawbar_run_needs_drawbar_force(tmp_path: Path) -> None:
    p = tmp_path / "x.csv"
    p.write_text(format_run_csv(make_run("terrain")))
    assert read_run_csv(p, "terrain").kind == "terrain"
    with pytest.raises(InputError) as info:
        read_run_csv(p, "drawbar")
    assert info.value.column == "drawbar_force" and info.value.line == 1


def test_time_going_backwards(campaign_dir: Path) -> None:
    line = edit_csv(campaign_dir / "runs/dbp1.csv", 100, "time", "0.5")
    assert_refused(campaign_dir, file="dbp1.csv", line=line, column="time", says="time goes backwards")


def test_repeated_time(campaign_dir: Path) -> None:
    line = edit_csv(campaign_dir / "runs/dbp1.csv", 100, "time", "0.99")
    assert_refused(campaign_dir, file="dbp1.csv", line=line, column="time", says="time repeats")


def _rewrite_rows(path: Path, change) -> None:
    lines = path.read_text(encoding="utf-8").splitlines()
    path.write_text("\n".join(change(lines)) + "\n", encoding="utf-8")


def test_a_run_pasted_twice_is_refused_where_its_time_starts_again(campaign_dir: Path) -> None:
    path = campaign_dir / "runs/dbp1.csv"
    rows = len(path.read_text().splitlines())
    _rewrite_rows(path, lambda lines: lines + lines[1:])
    assert_refused(campaign_dir, file="dbp1.csv", line=rows + 1, column="time",
                   says="back to the run's start at 0.0 s (line 2): the rows from here on look like the run again, "
                        "or another run; a file holds one run: cut it here")


def test_rows_out_of_order_are_refused_with_sort_them(campaign_dir: Path) -> None:
    def swap(lines):
        lines[60], lines[61] = lines[61], lines[60]
        return lines
    _rewrite_rows(campaign_dir / "runs/dbp1.csv", swap)
    assert_refused(campaign_dir, file="dbp1.csv", line=62, column="time",
                   says="time goes backwards: 0.59 s after 0.6 s (line 61): a run's rows are in time order; sort them")


def test_a_row_written_twice_is_refused_as_such(campaign_dir: Path) -> None:
    _rewrite_rows(campaign_dir / "runs/dbp1.csv", lambda lines: lines[:50] + [lines[49]] + lines[50:])
    assert_refused(campaign_dir, file="dbp1.csv", line=51, column="time",
                   says="time repeats: the row repeats line 50 cell for cell (a row written twice): delete one")


def test_two_rows_of_one_time_with_other_values_are_refused_with_one_row_a_time(campaign_dir: Path) -> None:
    line = edit_csv(campaign_dir / "runs/dbp1.csv", 100, "time", "0.99")
    assert_refused(campaign_dir, file="dbp1.csv", line=line, column="time",
                   says="with other values: a time's samples go on one row")


def test_a_run_file_linked_from_outside_the_folder_is_refused_with_copy_it_in(campaign_dir: Path,
                                                                               tmp_path: Path) -> None:
    outside = tmp_path / "raw" / "dbp1.csv"
    outside.parent.mkdir()
    (campaign_dir / "runs/dbp1.csv").rename(outside)
    (campaign_dir / "runs/dbp1.csv").symlink_to(outside)
    assert_refused(campaign_dir, file="campaign.json",
                   says=f"'runs/dbp1.csv' points outside the campaign folder {campaign_dir} (a symbolic link to "
                        f"{outside}); the harness keeps its outputs off the campaign folder")


def test_empty_time_cell(campaign_dir: Path) -> None:
    line = edit_csv(campaign_dir / "runs/t3d.csv", 3, "time", "")
    assert_refused(campaign_dir, file="t3d.csv", line=line, column="time", says="time is empty")


@pytest.mark.parametrize("cell", ["nan", "NaN", "inf", "-Infinity", "1e999"])
def test_non_finite_cell(campaign_dir: Path, cell: str) -> None:
    line = edit_csv(campaign_dir / "runs/dbp1.csv", 15, "omega_left", cell)
    assert_refused(campaign_dir, file="dbp1.csv", line=line, column="omega_left", says="not finite")


@pytest.mark.parametrize("cell", ["NaN", "nan", "NA", "#N/A", "null", "-"])
def test_a_missing_sample_written_as_a_mark_is_refused_with_leave_the_cell_empty(campaign_dir: Path, cell: str) -> None:
    line = edit_csv(campaign_dir / "runs/dbp1.csv", 15, "omega_left", cell)
    assert_refused(campaign_dir, file="dbp1.csv", line=line, column="omega_left",
                   says=f"{cell!r} marks a missing sample: leave the cell empty")


@pytest.mark.parametrize("cell", ["abc", "1,5", "0x10", "1_000", "--1", "1.2.3", "٣"])
def test_text_in_number_cell(campaign_dir: Path, cell: str) -> None:
    line = edit_csv(campaign_dir / "runs/dbp1.csv", 15, "omega_left", f'"{cell}"')
    err = assert_refused(campaign_dir, file="dbp1.csv", line=line, column="omega_left", says="not a number")
    assert str(err) == f"{campaign_dir / 'runs/dbp1.csv'}, line {line}, column 'omega_left': not a number: {cell!r}"


def test_row_with_too_many_cells(campaign_dir: Path) -> None:
    p = campaign_dir / "runs/dbp1.csv"
    lines = p.read_text().splitlines()
    lines[41] += ",1.0"
    p.write_text("\n".join(lines) + "\n")
    assert_refused(campaign_dir, file="dbp1.csv", line=42, says="cells, the header has")


def test_row_with_too_few_cells(campaign_dir: Path) -> None:
    p = campaign_dir / "runs/dbp1.csv"
    lines = p.read_text().splitlines()
    lines[9] = lines[9].rsplit(",", 1)[0]
    p.write_text("\n".join(lines) + "\n")
    assert_refused(campaign_dir, file="dbp1.csv", line=10, says="cells, the header has")


def test_a_trailing_comma_on_every_line_is_named_as_such(campaign_dir: Path) -> None:
    """An export that ends every line with a separator makes an empty last column: named as a
    trailing separator, with what to do."""
    p = campaign_dir / "runs/dbp1.csv"
    p.write_text("".join(line + ",\n" for line in p.read_text().splitlines()))
    err = assert_refused(campaign_dir, file="dbp1.csv", line=1, says="is an empty column name")
    assert "trailing comma" in str(err) and "remove it" in str(err)


def test_a_decimal_comma_is_named_as_such(campaign_dir: Path) -> None:
    """Numbers written 1,5 split each number into two cells: the row is longer than the header,
    holds no decimal point, and the refusal says it looks like a decimal comma."""
    p = campaign_dir / "runs/dbp1.csv"
    lines = p.read_text().splitlines()
    lines[1:] = [line.replace(",", ";").replace(".", ",").replace(";", ",") for line in lines[1:]]
    p.write_text("\n".join(lines) + "\n")
    err = assert_refused(campaign_dir, file="dbp1.csv", line=2, says="cells, the header has")
    assert "decimal comma" in str(err)


@pytest.mark.parametrize("separator, says", [(";", "separated by semicolons"), ("\t", "separated by tabs")])
def test_a_file_not_separated_by_commas_is_named_as_such(campaign_dir: Path, separator: str, says: str) -> None:
    """A spreadsheet's export with another separator is refused with the reason, not as a file
    missing its columns."""
    p = campaign_dir / "runs/dbp1.csv"
    p.write_text(p.read_text().replace(",", separator))
    assert_refused(campaign_dir, file="dbp1.csv", line=1, column="time", says=says)


@pytest.mark.parametrize("written, column", [("time [s]", "time"), ("omega_left (rad/s)", "omega_left"),
                                             ("pos_x/m", "pos_x"), ("Torque_Left", "torque_left"),
                                             ("yaw [rad]", "yaw")])
def test_a_column_named_with_its_unit_or_in_capitals_is_refused_with_the_name_it_needs(
        campaign_dir: Path, written: str, column: str) -> None:
    """The units are fixed by the format: a known column written with its unit (or in another
    case) is refused, naming the column it should be, even when the column is optional (kept as
    an extra column, it would be left out without a word)."""
    p = campaign_dir / "runs/dbp1.csv"
    lines = p.read_text().splitlines()
    header = lines[0].split(",")
    assert column in header
    header[header.index(column)] = written
    p.write_text("\n".join([",".join(header)] + lines[1:]) + "\n")
    assert_refused(campaign_dir, file="dbp1.csv", line=1, column=column, says=f"column {written!r}")


@pytest.mark.parametrize("shift, scale, says", [
    (1000.0, 1.0, "the run's own clock, which starts at 1000.0 s: counted from the start, it is [1002.0, 1005.0]"),
    (0.0, 1000.0, "is the time column in milliseconds?"),
    (1.7e12, 1000.0, "over an hour: is the time column in milliseconds (from 1700000000000.0)?")])
def test_a_steady_window_off_its_run_names_the_likely_mistake(campaign_dir: Path, shift: float, scale: float,
                                                             says: str) -> None:
    """A steady window [2, 5] s that holds no sample of its run says why when the cause is
    plain: the run's clock does not start at zero, or its time is in milliseconds (counted from
    zero, or a logger's Unix time in milliseconds with the window counted from the start)."""
    p = campaign_dir / "runs/dbp1.csv"
    header, *rows = p.read_text().splitlines()
    assert header.startswith("time,")
    rows = [f"{float(r.split(',', 1)[0]) * scale + shift!r},{r.split(',', 1)[1]}" for r in rows]
    p.write_text("\n".join([header, *rows]) + "\n")
    line = 1 + next(i for i, l in enumerate((campaign_dir / "campaign.json").read_text().splitlines()) if '"dbp1"' in l)
    assert_refused(campaign_dir, file="campaign.json", line=line, says="steady_window [2.0, 5.0] s holds no samples")
    assert_refused(campaign_dir, file="campaign.json", line=line, says=says)


@pytest.mark.parametrize("keep, says", [
    (lambda t: t <= 4.0, "reaches past the run's end: the run spans 0.0 to 4.0 s"),
    (lambda t: t >= 3.0, "starts before the run: the run spans 3.0 to 5.99 s")])
def test_a_steady_window_reaching_beyond_its_run_is_refused(campaign_dir: Path, keep, says: str) -> None:
    """A run whose file was cut short (or starts late) holds only part of its steady window
    [2, 5] s: the window's averages and the replays over its length would cover less than the
    manifest says, so the manifest's run entry is refused with the window and the run's span."""
    p = campaign_dir / "runs/dbp1.csv"
    header, *rows = p.read_text().splitlines()
    rows = [r for r in rows if keep(float(r.split(",", 1)[0]))]
    p.write_text("\n".join([header, *rows]) + "\n")
    line = 1 + next(i for i, l in enumerate((campaign_dir / "campaign.json").read_text().splitlines()) if '"dbp1"' in l)
    assert_refused(campaign_dir, file="campaign.json", line=line, says="run 'dbp1': steady_window [2.0, 5.0] s")
    assert_refused(campaign_dir, file="campaign.json", line=line, says=says)


def test_a_steady_window_may_end_within_one_row_interval_of_the_last_row(campaign_dir: Path) -> None:
    """A window whose end lies between the last row and where the logger's next row would come
    (5.0 s after a last row at 4.995 s, rows every 10 ms) holds the run's steady part as the
    manifest means it."""
    p = campaign_dir / "runs/dbp1.csv"
    header, *rows = p.read_text().splitlines()
    rows = [r for r in rows if float(r.split(",", 1)[0]) <= 4.995]
    p.write_text("\n".join([header, *rows]) + "\n")
    load_and_read_all(campaign_dir)


def test_duplicate_column_name(campaign_dir: Path) -> None:
    p = campaign_dir / "runs/dbp1.csv"
    p.write_text(p.read_text().replace("battery_volts", "pos_x", 1))
    assert_refused(campaign_dir, file="dbp1.csv", line=1, column="pos_x", says="duplicate column")


@pytest.mark.parametrize("content", ["", "\n\n", "time,torque_left,torque_right,omega_left,omega_right,pos_x,pos_y,pos_z,drawbar_force\n"])
def test_empty_or_header_only_file(campaign_dir: Path, content: str) -> None:
    (campaign_dir / "runs/dbp1.csv").write_text(content)
    assert_refused(campaign_dir, file="dbp1.csv", line=1)


def test_missing_header_line(campaign_dir: Path) -> None:
    p = campaign_dir / "runs/dbp1.csv"
    p.write_text("\n".join(p.read_text().splitlines()[1:]) + "\n")
    assert_refused(campaign_dir, file="dbp1.csv", line=1, says="header")


def test_required_column_without_samples(campaign_dir: Path) -> None:
    p = campaign_dir / "runs/t3d.csv"
    run = make_run("terrain")
    run["pos_z"][:] = np.nan
    p.write_text(format_run_csv(run))
    assert_refused(campaign_dir, file="t3d.csv", column="pos_z", says="no samples")


def test_blank_line_inside_data(campaign_dir: Path) -> None:
    p = campaign_dir / "runs/dbp1.csv"
    lines = p.read_text().splitlines()
    lines.insert(5, "")
    p.write_text("\n".join(lines) + "\n")
    assert_refused(campaign_dir, file="dbp1.csv", line=6, says="empty line")


def test_not_utf8(campaign_dir: Path) -> None:
    p = campaign_dir / "runs/dbp1.csv"
    data = p.read_bytes().split(b"\n")
    data[3] = data[3] + b"\xff"
    p.write_bytes(b"\n".join(data))
    assert_refused(campaign_dir, file="dbp1.csv", line=4, says="UTF-8")


@pytest.mark.parametrize("encoding, says", [
    ("utf-16", "UTF-16 text (as Excel's 'Unicode Text' saves it), not UTF-8: save it as UTF-8"),
    ("utf-16-le", "holds NUL bytes, which no text file has: UTF-16 text without a byte-order mark"),
])
@pytest.mark.parametrize("name", ["runs/dbp1.csv", "campaign.json"])
def test_a_file_in_utf16_is_named_as_such_with_save_it_as_utf8(campaign_dir: Path, encoding: str, says: str,
                                                                name: str) -> None:
    p = campaign_dir / name
    p.write_bytes(p.read_text().encode(encoding))
    assert_refused(campaign_dir, file=name, line=1, says=says)


def test_a_file_in_a_one_byte_encoding_is_named_as_such_with_save_it_as_utf8(campaign_dir: Path) -> None:
    p = campaign_dir / "runs/dbp1.csv"
    lines = p.read_text().splitlines()
    lines = [lines[0] + ",note"] + [row + ",20 \u00b0C" for row in lines[1:]]
    p.write_bytes(("\n".join(lines) + "\n").encode("latin-1"))
    assert_refused(campaign_dir, file="dbp1.csv", line=2, says="not UTF-8 text (byte 0xb0): another encoding than "
                   "UTF-8 (Windows-1252, Latin-1); save it as UTF-8")


def test_comment_lines_are_refused_as_such(campaign_dir: Path) -> None:
    p = campaign_dir / "runs/dbp1.csv"
    text = p.read_text()
    p.write_text("# logger export v2\n" + text)
    assert_refused(campaign_dir, file="dbp1.csv", line=1, says="the first line is a comment ('#')")
    header, rest = text.split("\n", 1)
    p.write_text(header + "\n# units: SI\n" + rest)
    assert_refused(campaign_dir, file="dbp1.csv", line=2, says="a comment line ('#'): a CSV has no comment lines")


def rewrite_manifest(root: Path, edit) -> None:
    doc = json.loads((root / "campaign.json").read_text())
    edit(doc)
    (root / "campaign.json").write_text(json.dumps(doc, indent=2))


def test_manifest_names_missing_run_file(campaign_dir: Path) -> None:
    rewrite_manifest(campaign_dir, lambda d: d["runs"][1].update(file="runs/missing.csv"))
    err = assert_refused(campaign_dir, file="campaign.json", says="missing.csv")
    assert "'dbp2'" in str(err) and "'file'" in str(err) and "not found" in str(err)
    assert err.line is not None and '"dbp2"' in (campaign_dir / "campaign.json").read_text().splitlines()[err.line - 1]


def test_manifest_bad_kind(campaign_dir: Path) -> None:
    rewrite_manifest(campaign_dir, lambda d: d["runs"][0].update(kind="drawbars"))
    err = assert_refused(campaign_dir, file="campaign.json", says="'kind'")
    assert "'dbp1'" in str(err) and "'drawbars'" in str(err)


def test_manifest_duplicate_run_ids(campaign_dir: Path) -> None:
    def edit(d: dict) -> None:
        d["runs"][2].update(id="dbp1", kind="drawbar")
        del d["runs"][2]["terrain"]

    rewrite_manifest(campaign_dir, edit)
    err = assert_refused(campaign_dir, file="campaign.json", says="duplicate run id 'dbp1'")
    lines = (campaign_dir / "campaign.json").read_text().splitlines()
    assert err.line is not None and '"dbp1"' in lines[err.line - 1]
    assert err.line > [i for i, l in enumerate(lines, 1) if '"dbp1"' in l][0], "should point at the second one"


def test_manifest_two_runs_with_one_data_file(campaign_dir: Path) -> None:
    """One measured run listed under two ids would count its held-out blocks twice in the
    diagnosis's paired tests: refused, at the second entry, however the path is written."""
    def edit(d: dict) -> None:
        d["runs"][1].update(file="./" + d["runs"][0]["file"])

    rewrite_manifest(campaign_dir, edit)
    err = assert_refused(campaign_dir, file="campaign.json", says="is the file of runs[0] (id 'dbp1')")
    assert "runs[1] (id 'dbp2')" in str(err)
    assert err.line is not None and '"dbp2"' in (campaign_dir / "campaign.json").read_text().splitlines()[err.line - 1]


def test_manifest_bad_json_names_the_line(campaign_dir: Path) -> None:
    p = campaign_dir / "campaign.json"
    lines = p.read_text().splitlines()
    k = next(i for i, l in enumerate(lines) if l.rstrip().endswith('"drawbar",'))
    lines[k] = lines[k].rstrip()[:-1]  # drop a comma: the error is reported on the next line
    p.write_text("\n".join(lines) + "\n")
    assert_refused(campaign_dir, file="campaign.json", line=k + 2, says="invalid JSON")


@pytest.mark.parametrize(
    "edit, says",
    [
        (lambda d: d["runs"][0].update(steady_window=[5.0, 2.0]), "steady_window"),
        (lambda d: d["runs"][0].update(steady_window=[1.0]), "steady_window"),
        (lambda d: d["runs"][0].update(steady_window=[1.0, "2"]), "steady_window"),
        (lambda d: d["runs"][0].update(steady_window=[100.0, 200.0]), "holds no samples"),
        (lambda d: d["runs"][0].update(file="../outside.csv"), "outside the campaign folder"),
        (lambda d: d["runs"][0].update(file="/etc/passwd"), "relative"),
        (lambda d: d["runs"][0].update(file="runs"), "not a regular file"),
        (lambda d: d["runs"][2].pop("terrain"), "'terrain'"),
        (lambda d: d["runs"][2].update(terrain="terrain/none.xyz"), "none.xyz"),
        (lambda d: d["runs"][0].update(terrain="terrain/scan.xyz"), "flat ground"),
        (lambda d: d["runs"][0].pop("id"), "'id'"),
        (lambda d: d["runs"][0].update(id="a b"), "'id'"),
        (lambda d: d.update(runs=[]), "'runs'"),
        (lambda d: d.pop("runs"), "'runs'"),
        (lambda d: d.update(rover={"wheel.width": [1]}), "wheel.width"),
        (lambda d: d.update(rover={"wheel.width": True}), "wheel.width"),
        (lambda d: d.update(name=3), "'name'"),
    ],
)
def test_manifest_checks(campaign_dir: Path, edit, says: str) -> None:
    (campaign_dir.parent / "outside.csv").write_text("x")
    rewrite_manifest(campaign_dir, edit)
    assert_refused(campaign_dir, file="campaign.json", says=says)


def test_a_stated_sensor_noise_holds_for_every_run_and_a_run_may_state_its_own(campaign_dir: Path) -> None:
    """``sensor_noise`` of the campaign holds for each drawbar and terrain run; a run's own
    ``sensor_noise`` replaces it column by column.  A stated column's noise is the stated value,
    every other column's is estimated from its samples."""
    def edit(d: dict) -> None:
        d["sensor_noise"] = {"torque_left": 0.5, "pos_z": 0.003}
        d["runs"][1]["sensor_noise"] = {"torque_left": 0.8, "drawbar_force": 2}

    rewrite_manifest(campaign_dir, edit)
    c = load_campaign(campaign_dir)
    assert c.sensor_noise == {"torque_left": 0.5, "pos_z": 0.003}
    assert "sensor_noise" not in c.extra and "sensor_noise" not in c.run("dbp2").extra
    assert read_run(c, "dbp1").stated_noise == {"torque_left": 0.5, "pos_z": 0.003}
    assert read_run(c, "t3d").stated_noise == {"torque_left": 0.5, "pos_z": 0.003}
    dbp2 = read_run(c, "dbp2")
    assert dbp2.stated_noise == {"torque_left": 0.8, "pos_z": 0.003, "drawbar_force": 2.0}
    assert sensor_noise(dbp2, "torque_left") == 0.8
    assert sensor_noise(dbp2, "torque_right") == column_noise(*dbp2.samples("torque_right"))
    assert sensor_noise(dbp2, "torque_right") == pytest.approx(0.5, rel=0.1)   # make_run's noise


@pytest.mark.parametrize(
    "edit, says",
    [
        (lambda d: d.update(sensor_noise={"torque_lft": 3.2}),
         "'sensor_noise' has no column 'torque_lft': a sensor noise is stated for a measured column"),
        (lambda d: d["runs"][1].update(sensor_noise={"time": 0.001}),
         "runs[1] (id 'dbp2'): 'sensor_noise' has no column 'time'"),
        (lambda d: d.update(sensor_noise={"torque_left": 0}),
         "'sensor_noise.torque_left' must be a finite number > 0 (1 sigma, in N m), got 0"),
        (lambda d: d["runs"][0].update(sensor_noise={"pitch": -0.003}),
         "runs[0] (id 'dbp1'): 'sensor_noise.pitch' must be a finite number > 0 (1 sigma, in rad), got -0.003"),
        (lambda d: d.update(sensor_noise={"pos_x": "2 mm"}), "'sensor_noise.pos_x' must be a finite number > 0"),
        (lambda d: d.update(sensor_noise={"pos_x": True}), "'sensor_noise.pos_x' must be a finite number > 0"),
        (lambda d: d.update(sensor_noise=3.2), "'sensor_noise' must be an object of measured columns"),
        (lambda d: d["runs"][1].update(kind="wheel_rig", wheel={"radius": 0.1, "width": 0.1},
                                       sensor_noise={"torque": 0.1}),
         "runs[1] (id 'dbp2'): a wheel_rig table takes no 'sensor_noise'"),
    ],
)
def test_a_stated_sensor_noise_is_checked_when_the_manifest_is_loaded(campaign_dir: Path, edit, says: str) -> None:
    rewrite_manifest(campaign_dir, edit)
    assert_refused(campaign_dir, file="campaign.json", says=says)


def test_a_stated_sensor_noise_beyond_a_double_is_refused_as_not_finite(campaign_dir: Path) -> None:
    rewrite_manifest(campaign_dir, lambda d: d.update(sensor_noise={"drawbar_force": 12345}))
    path = campaign_dir / "campaign.json"
    path.write_text(path.read_text().replace("12345", "1e999"))
    assert_refused(campaign_dir, file="campaign.json", says="'sensor_noise.drawbar_force' must be a finite number > 0")


def test_a_calibrated_imu_mounting_is_read_from_the_manifest_and_anything_else_refused(campaign_dir: Path) -> None:
    """``imu_mounting``: "free" unless the manifest says "calibrated" (the pitch measured against a
    mounting calibrated on the rover); any other value is refused, naming the key."""
    assert load_campaign(campaign_dir).imu_mounting == "free"
    rewrite_manifest(campaign_dir, lambda d: d.update(imu_mounting="calibrated"))
    c = load_campaign(campaign_dir)
    assert c.imu_mounting == "calibrated" and "imu_mounting" not in c.extra
    rewrite_manifest(campaign_dir, lambda d: d.update(imu_mounting="levelled"))
    assert_refused(campaign_dir, file="campaign.json", says="'imu_mounting' must be one of 'free', 'calibrated'")


def test_each_run_may_name_the_imu_mounting_it_was_measured_with(campaign_dir: Path) -> None:
    """``imu_mount`` on a run: runs that name the same mounting share one pitch offset in the
    diagnosis; a run that names none is on the campaign's mounting.  A name that is not a plain
    label is refused, naming the run and the key."""
    assert {r.imu_mount for r in load_campaign(campaign_dir).runs} == {DEFAULT_IMU_MOUNT}

    def mount(d, value):
        d["runs"][0]["imu_mount"] = value
    rewrite_manifest(campaign_dir, lambda d: mount(d, "day2"))
    c = load_campaign(campaign_dir)
    assert c.runs[0].imu_mount == "day2" and "imu_mount" not in c.runs[0].extra
    assert {r.imu_mount for r in c.runs[1:]} == {DEFAULT_IMU_MOUNT}
    for bad in ("", 2, "day 2/remounted"):
        rewrite_manifest(campaign_dir, lambda d: mount(d, bad))
        assert_refused(campaign_dir, file="campaign.json", says="'imu_mount' must name the IMU's mounting in the run")
    rewrite_manifest(campaign_dir, lambda d: (mount(d, "day1"), d["runs"][1].update(
        kind="wheel_rig", wheel={"radius": 0.1, "width": 0.1}, imu_mount="day1")))
    assert_refused(campaign_dir, file="campaign.json", says="runs[1] (id 'dbp2'): a wheel_rig table has no IMU")


@pytest.mark.parametrize("text, says", [('{"runs": [], "runs": []}', "twice"), ('{"name": NaN}', "NaN"), ("[1, 2]", "object")])
def test_manifest_json_strictness(campaign_dir: Path, text: str, says: str) -> None:
    (campaign_dir / "campaign.json").write_text(text)
    assert_refused(campaign_dir, file="campaign.json", says=says)


def test_missing_manifest(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="campaign.json.*not found"):
        load_campaign(tmp_path)
    with pytest.raises(InputError, match="no such campaign"):
        load_campaign(tmp_path / "nowhere")


# ---------------------------------------------------------------------------------------------
# Multi-rate signals and derived signals
# ---------------------------------------------------------------------------------------------

def test_alignment_reproduces_a_linear_signal_exactly(tmp_path: Path) -> None:
    rng = np.random.default_rng(RNG_SEED)
    t = np.cumsum(rng.uniform(0.005, 0.02, 800))  # irregular base clock
    run = make_run("drawbar", duration=1.0)
    n = len(t)
    cols = {k: np.resize(v, n) for k, v in run.items()}
    cols["time"] = t
    # Each sensor keeps a different random subset of rows.
    for name, keep in (("pos_x", 0.05), ("omega_left", 0.5), ("drawbar_force", 0.2)):
        mask = rng.uniform(size=n) < keep
        mask[[10, n - 10]] = True
        cols[name] = np.where(mask, 2.0 - 3.0 * t, np.nan) if name != "omega_left" else np.where(mask, 0.5 + 4.0 * t, np.nan)
    p = tmp_path / "r.csv"
    p.write_text(format_run_csv(cols))
    data = read_run_csv(p, "drawbar")

    grid = np.linspace(t[0] - 1.0, t[-1] + 1.0, 3001)
    out = aligned(data, ["pos_x", "omega_left", "drawbar_force"], grid)
    for name, f in (("pos_x", lambda x: 2.0 - 3.0 * x), ("omega_left", lambda x: 0.5 + 4.0 * x), ("drawbar_force", lambda x: 2.0 - 3.0 * x)):
        ts, vs = data.samples(name)
        inside = (grid >= ts[0]) & (grid <= ts[-1])
        np.testing.assert_array_equal(out.coverage[name], inside)
        np.testing.assert_allclose(out[name][inside], f(grid[inside]), rtol=0, atol=1e-12)
        # no extrapolation: the end values are held
        np.testing.assert_array_equal(out[name][grid < ts[0]], vs[0])
        np.testing.assert_array_equal(out[name][grid > ts[-1]], vs[-1])
    assert not out.coverage["pos_x"].all()

    prev = aligned(data, "pos_x", grid, method="previous")["pos_x"]
    ts, vs = data.samples("pos_x")
    k = np.searchsorted(ts, grid[1500], side="right") - 1
    assert prev[1500] == vs[k]
    with pytest.raises(InputError, match="no column 'roll'"):
        aligned(data, "roll", grid)


def test_yaw_is_unwrapped_before_interpolation(tmp_path: Path) -> None:
    run = make_run("terrain", duration=1.0)
    run["yaw"] = np.full(len(run["time"]), np.nan)
    run["yaw"][0], run["yaw"][50] = math.pi - 0.1, -math.pi + 0.1
    p = tmp_path / "r.csv"
    p.write_text(format_run_csv(run))
    yaw = aligned(read_run_csv(p, "terrain"), "yaw", [0.25])["yaw"]
    assert yaw[0] == pytest.approx(math.pi, abs=1e-9)


def test_steady_average(campaign_dir: Path) -> None:
    c = load_campaign(campaign_dir)
    data = read_run(c, "dbp1")
    t, v = data.samples("drawbar_force")
    inside = (t >= 2.0) & (t <= 5.0)
    assert steady_average(data, "drawbar_force", c.run("dbp1").steady_window) == pytest.approx(v[inside].mean(), rel=1e-12)
    assert steady_average(data, "omega_left", (2.0, 2.0005)) == pytest.approx(1.2 + 0.01 * np.sin(2.0))
    with pytest.raises(InputError, match="no samples of 'pos_x' inside"):
        steady_average(data, "pos_x", (2.01, 2.1))


def straight_run(speed: float, heading: float, with_yaw: bool, seed: int) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = np.round(np.arange(0.0, 20.0, 0.01), 10)
    n = len(t)
    ts_mask = np.zeros(n, dtype=bool)
    ts_mask[::20] = True  # 5 Hz total station
    s = speed * t
    noise = lambda: rng.normal(0.0, 0.002, n)  # noqa: E731  2 mm
    run = {
        "time": t,
        "torque_left": np.full(n, 30.0),
        "torque_right": np.full(n, 30.0),
        "omega_left": np.full(n, speed / 0.2794),
        "omega_right": np.full(n, speed / 0.2794),
        "pos_x": np.where(ts_mask, 1.0 + s * math.cos(heading) + noise(), np.nan),
        "pos_y": np.where(ts_mask, -2.0 + s * math.sin(heading) + noise(), np.nan),
        "pos_z": np.where(ts_mask, 0.75 + noise(), np.nan),
    }
    if with_yaw:
        run["yaw"] = np.where(np.arange(n) % 5 == 0, heading + rng.normal(0, 0.005, n), np.nan)
    return run


@pytest.mark.parametrize("with_yaw", [False, True])
def test_forward_speed_of_a_straight_run(tmp_path: Path, with_yaw: bool) -> None:
    p = tmp_path / "r.csv"
    p.write_text(format_run_csv(straight_run(0.3, math.radians(30.0), with_yaw, seed=7)))
    data = read_run_csv(p, "terrain")
    times = np.arange(0.0, 19.8, 0.01)
    v = forward_speed(data, times)
    assert v.shape == times.shape and np.all(np.isfinite(v))
    assert abs(v.mean() - 0.3) < 0.003  # no bias
    assert np.mean(np.abs(v - 0.3)) < 0.01
    # irregular (jittered, with drop-outs) sampling is handled
    run = straight_run(0.3, math.radians(-120.0), with_yaw, seed=8)
    drop = np.random.default_rng(9).uniform(size=len(run["time"])) < 0.3
    for k in ("pos_x", "pos_y", "pos_z"):
        run[k][drop] = np.nan
    p.write_text(format_run_csv(run))
    v = forward_speed(read_run_csv(p, "terrain"), times)
    assert np.mean(np.abs(v - 0.3)) < 0.015


def test_forward_speed_is_signed_by_yaw_when_reversing(tmp_path: Path) -> None:
    run = straight_run(-0.2, 0.0, True, seed=3)
    p = tmp_path / "r.csv"
    p.write_text(format_run_csv(run))
    v = forward_speed(read_run_csv(p, "terrain"), np.arange(1.0, 19.0, 0.1))
    assert abs(v.mean() + 0.2) < 0.01


# ---------------------------------------------------------------------------------------------
# Plausibility of the values (juno.plausibility)
# ---------------------------------------------------------------------------------------------

def wide_terrain() -> np.ndarray:
    """make_terrain spread over +-3.2 m: the runs' wheels (0.7 m ahead of the 1.8 m the rover
    reaches, 0.8 m to the side) stay on it, with a scan point within a wheel's radius of every
    hub (50 points a square metre)."""
    pts = make_terrain(points=2000)
    return np.column_stack([1.6 * pts[:, :2], pts[:, 2]])


def test_a_plausible_campaign_raises_no_finding(tmp_path: Path) -> None:
    """The format's example campaign (SI units, a rover at 0.3 m/s on a mound scanned wide enough
    for its wheels) is plausible."""
    from juno.plausibility import check_campaign

    root = tmp_path / "camp"
    write_campaign(root, make_manifest(), make_runs(), {"scan": wide_terrain()})
    assert check_campaign(load_campaign(root)) == []


def test_implausible_values_are_named_by_file_column_and_evidence(tmp_path: Path) -> None:
    """Spins written in rpm (a warning: 11.4 could be a wheel overrunning downhill) and a pitch in
    degrees (an error: the rover would lie on its side), naming the file, the column and the value."""
    from juno.plausibility import check_campaign

    runs = make_runs()
    runs["dbp2"]["omega_right"] = runs["dbp2"]["omega_right"] * 60 / (2 * math.pi)
    runs["t3d"]["pitch"] = np.where(runs["t3d"]["time"] < 3.0, 12.5, 12.0)
    root = tmp_path / "camp"
    write_campaign(root, make_manifest(), runs, {"scan": wide_terrain()})
    found = {(f.severity, f.file, f.column): f.message for f in check_campaign(load_campaign(root))}
    assert set(found) == {("warning", "runs/dbp2.csv", "omega_right"), ("error", "runs/t3d.csv", "pitch")}
    assert "looks like rpm" in found[("warning", "runs/dbp2.csv", "omega_right")]
    assert "12.5" in found[("error", "runs/t3d.csv", "pitch")] and "degrees" in found[("error", "runs/t3d.csv", "pitch")]


@pytest.mark.parametrize("column", ["torque_left", "drawbar_force"])
def test_a_reversed_sign_on_a_drawbar_run_is_an_error(tmp_path: Path, column: str) -> None:
    """Wheels driving forward while pulling a load take driving torque, and the load cell holds
    the rover back: a drive torque or a drawbar force of the other sign is a reversed sensor."""
    from juno.plausibility import check_campaign

    runs = make_runs()
    runs["dbp1"][column] = -runs["dbp1"][column]
    root = tmp_path / "camp"
    write_campaign(root, make_manifest(), runs, {"scan": wide_terrain()})
    found = check_campaign(load_campaign(root))
    assert [(f.severity, f.file, f.column) for f in found] == [("error", "runs/dbp1.csv", column)]
    assert "is the sign reversed?" in found[0].message


def test_a_drawbar_run_without_a_load_is_no_sign_error(tmp_path: Path) -> None:
    """A load cell reading a few newtons below zero on a run without a load is its offset, not a
    reversed sign.  (It reads its noise about the offset: one reading in every sample is a
    frozen cell, an error of its own.)"""
    from juno.plausibility import check_campaign

    runs = make_runs()
    noise = np.random.default_rng(7).normal(0.0, 0.5, len(runs["dbp1"]["time"]))
    runs["dbp1"]["drawbar_force"] = -8.0 + noise
    root = tmp_path / "camp"
    write_campaign(root, make_manifest(), runs, {"scan": wide_terrain()})
    assert check_campaign(load_campaign(root)) == []


def test_a_scan_too_small_for_the_path_names_the_run_and_the_time(tmp_path: Path) -> None:
    """On a scan of +-1 m the front wheels' footprint (0.69 m ahead of the prism) passes the
    gridded margin (1 m beyond the last scan point) when the rover reaches x = 1.3 m, at about
    4.4 s, and stays off to the end (5.8 s): over 10 % of the run, an error naming the run and
    the time span."""
    from juno.plausibility import check_campaign

    pts = make_terrain()
    small = np.column_stack([0.5 * pts[:, :2], pts[:, 2]])
    root = tmp_path / "camp"
    write_campaign(root, make_manifest(), make_runs(), {"scan": small})
    found = check_campaign(load_campaign(root))
    assert [(f.severity, f.file, f.column) for f in found] == [("error", "runs/t3d.csv", "pos_x")]
    message = found[0].message
    assert message.startswith("run 't3d': the rover's wheel footprint leaves the scan terrain/scan.xyz during ")
    start, end = message.split(" during ")[1].split(" s ")[0].split("-")
    assert 4.0 <= float(start) <= 4.8 and float(end) == 5.8


@pytest.mark.parametrize("unit, to_m", [("millimetres", 1e-3), ("centimetres", 1e-2)])
def test_a_scan_in_another_length_unit_is_named_as_such(tmp_path: Path, unit: str, to_m: float) -> None:
    """A scan written in mm or cm leaves the path off it: the error says which unit puts the
    path back on the scan."""
    from juno.plausibility import check_campaign

    root = tmp_path / "camp"
    write_campaign(root, make_manifest(), make_runs(), {"scan": make_terrain() / to_m})
    errors = [f for f in check_campaign(load_campaign(root)) if f.severity == "error"]
    assert [(f.file, f.column) for f in errors] == [("runs/t3d.csv", "pos_x")]
    assert f"the scan looks like it is in {unit}" in errors[0].message


def test_a_scan_in_another_frame_shows_both_extents(tmp_path: Path) -> None:
    """A scan in map coordinates (UTM) beside a path in a local frame: the error gives both
    extents, to compare the frames."""
    from juno.plausibility import check_campaign

    pts = make_terrain() + np.array([500000.0, 5400000.0, 0.0])
    root = tmp_path / "camp"
    write_campaign(root, make_manifest(), make_runs(), {"scan": pts})
    errors = [f for f in check_campaign(load_campaign(root)) if f.severity == "error"]
    assert len(errors) == 1
    assert "the same world frame?" in errors[0].message and "y 5399998" in errors[0].message
    assert "looks like it is in" not in errors[0].message
