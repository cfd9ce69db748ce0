"""Reading and checking a run's CSV: a time series (:func:`read_run_csv`, :func:`read_run`) or
a single-wheel testbed's table (:func:`read_rig_csv`, :func:`read_rig`), and a terrain run's
LIDAR points (:func:`read_terrain_points`).  Every refusal names the file, the line and the
column."""

from __future__ import annotations

import csv
import io
import re
from pathlib import Path
from typing import Callable, Optional, Sequence, Union

import numpy as np
from numpy.typing import NDArray

from ..errors import NUMBER_RE, InputError, decode_input_text, parse_finite, read_input_bytes
from ..pointcloud import read_xyz
from .manifest import _line_of_run
from .records import (KNOWN_COLUMNS, REQUIRED_COLUMNS, RIG_COLUMNS, RIG_INPUTS, RIG_MEASURED,
                      RIG_REQUIRED, RIG_STD_SUFFIX, TIME_SERIES_KINDS, Campaign, FloatArray, PathLike,
                      RigTable, RunData, RunSpec)

def read_run_csv(path: PathLike, kind: str = "drawbar", run_id: Optional[str] = None) -> RunData:
    """Read and check one run CSV.

    Args:
        path: the CSV file.
        kind: "drawbar" (``drawbar_force`` required) or "terrain".
        run_id: stored in the result, for messages.

    Raises:
        InputError naming file, line (header = line 1) and column: missing header or data,
        missing required column, duplicate or empty column name, a row with the wrong number
        of cells, a known-column cell that is not a finite number, an empty time cell, time
        not strictly increasing ("time goes backwards"), a required column without samples.
    """
    if kind not in TIME_SERIES_KINDS:
        raise ValueError(f"kind must be 'drawbar' or 'terrain' (a wheel_rig table: read_rig_csv), got {kind!r}")
    p = Path(path)
    columns, extra, lines = _read_columns(p, lambda names: _check_header(p, names, REQUIRED_COLUMNS[kind], kind,
                                                                         KNOWN_COLUMNS), KNOWN_COLUMNS)
    line_arr = np.asarray(lines, dtype=np.int64)
    _check_time(p, columns["time"], line_arr, [*columns.values(), *extra.values()])
    for name in REQUIRED_COLUMNS[kind]:
        if np.all(np.isnan(columns[name])):
            raise InputError(f"required column {name!r} has no samples (every cell is empty)", p, 1, name)
    return RunData(path=p, kind=kind, columns=columns, extra=extra, lines=line_arr, run_id=run_id)


def _read_columns(p: Path, check_header: Callable[[list[str]], None], known: Sequence[str]
                  ) -> tuple[dict[str, FloatArray], dict[str, np.ndarray], list[int]]:
    """The columns of the CSV file ``p`` (header checked by ``check_header`` first): the ``known``
    ones as checked numbers, the others as they are (``extra``), and the data rows' 1-based lines."""
    text = decode_input_text(p, read_input_bytes(p))
    names, rows, lines = _read_table(p, text, check_header)
    columns: dict[str, FloatArray] = {}
    extra: dict[str, np.ndarray] = {}
    for name, cells in zip(names, map(list, zip(*rows))):
        if name in known:
            columns[name] = _parse_column(p, name, cells, lines)
        else:
            extra[name] = _parse_extra(cells)
    return columns, extra, lines


def _read_table(p: Path, text: str, check_header: Callable[[list[str]], None]
                ) -> tuple[list[str], list[list[str]], list[int]]:
    """(header names, data rows, their 1-based lines) of a CSV text; the header is checked by
    ``check_header`` before any row is read."""
    if not text.strip():
        raise InputError("empty file: a header line and data rows are required", p, 1)
    reader = csv.reader(io.StringIO(text, newline=""), strict=True)
    try:
        header = next(reader)
        names = [h.strip() for h in header]
        check_header(names)
        ncols = len(names)
        rows: list[list[str]] = []
        lines: list[int] = []
        blank_at: Optional[int] = None
        for row in reader:
            lineno = reader.line_num
            if not row or (len(row) == 1 and not row[0].strip()):
                blank_at = blank_at or lineno
                continue
            if blank_at is not None:
                raise InputError("empty line inside the data", p, blank_at)
            if len(row) != ncols and row[0].lstrip().startswith("#"):
                raise InputError("a comment line ('#'): a CSV has no comment lines; remove it", p, lineno)
            if len(row) != ncols:
                raise InputError(f"row has {len(row)} cells, the header has {ncols}{_cells_hint(row, ncols)}", p,
                                 lineno)
            rows.append(row)
            lines.append(lineno)
    except csv.Error as e:
        raise InputError(f"malformed CSV: {e}", p, reader.line_num) from None
    if not rows:
        raise InputError("no data rows: the file holds only a header", p, 1)
    return names, rows, lines


def _cells_hint(row: list[str], ncols: int) -> str:
    """Why a row has more cells than the header: numbers written with a decimal comma (``1,5``
    is two cells), told by a row whose numbers hold no decimal point while some are split into a
    whole part and digits after it."""
    if len(row) <= ncols:
        return ""
    cells = [c.strip() for c in row]
    if any("." in c for c in cells) or not any(c.lstrip("+-").isdigit() for c in cells):
        return ""
    return (": no number in it has a decimal point, so it looks written with a decimal comma (1,5 for 1.5), "
            "which splits each number in two; the format is comma-separated with '.' as the decimal point")


def _check_header(path: Path, names: list[str], required: Sequence[str], kind: str,
                  known: Sequence[str]) -> None:
    """Column names: present, unique, the ``required`` ones there.  A name that is a ``known``
    column written with its unit or in another case is refused, not kept as an extra column the
    harness would silently leave out."""
    if names and names[0].startswith("#"):
        raise InputError("the first line is a comment ('#'): the format's first line is the header of column names, "
                         "and a CSV has no comment lines; remove them (keep notes in the manifest or a column of "
                         "your own)", path, 1)
    if all(NUMBER_RE.fullmatch(n) for n in names if n) and any(names):
        raise InputError("the first line must be a header of column names; it holds numbers", path, 1)
    seen: set[str] = set()
    for j, name in enumerate(names):
        if not name:
            hint = (": the header ends in a separator; a trailing comma at the end of each line (some exports "
                    "write one) makes an empty last column: remove it") if j == len(names) - 1 and j > 0 else ""
            raise InputError(f"header cell {j + 1} is an empty column name{hint}", path, 1)
        if name in seen:
            raise InputError("duplicate column name in the header", path, 1, name)
        seen.add(name)
    for name in required:
        if name not in seen:
            raise InputError(
                f"missing required column (a {kind} run needs {', '.join(required)})"
                + _missing_column_hint(names, name), path, 1, name
            )
    for name in known:
        hint = "" if name in seen else _missing_column_hint(names, name)
        if hint:
            raise InputError(f"column {name!r} is not read{hint}", path, 1, name)


#: A unit written into a column name: "time [s]", "pos_x (m)", "torque_left/Nm".
_UNIT_SUFFIX_RE = re.compile(r"\s*(\[[^\]]*\]|\([^)]*\)|/\s*\S+)\s*$")


def _missing_column_hint(names: Sequence[str], wanted: str) -> str:
    """Why ``wanted`` may be missing from a header ``names`` that has something like it: the
    file is not comma-separated, a column name carries its unit, or differs in case."""
    if len(names) == 1:
        for sep, what in ((";", "semicolons"), ("\t", "tabs"), ("|", "vertical bars")):
            if sep in names[0]:
                return (f"; the header is one cell, separated by {what}: the format is comma-separated with "
                        f"'.' as the decimal point (docs/campaign-format.md)")
    for name in names:
        bare = _UNIT_SUFFIX_RE.sub("", name)
        if bare != name and bare.strip().lower() == wanted:
            return (f"; column {name!r} looks like {wanted!r} with its unit: the format fixes every unit (SI) and "
                    f"names the column {wanted!r} alone (docs/campaign-format.md)")
        if name.lower() == wanted:
            return f"; column {name!r} differs only in case: column names are lower case ({wanted!r})"
    return ""


def read_rig_csv(path: PathLike, run_id: Optional[str] = None) -> RigTable:
    """Read and check a wheel_rig table: one row per steady point of a single-wheel testbed.

    Columns (SI units, any order): ``vertical_load`` (N), ``slip`` (-), ``drawbar_pull`` (N),
    optional ``torque`` (N m), ``sinkage`` (m), ``slip_angle`` (rad), ``lateral_force`` (N), and
    ``<measured column>_std`` (same unit) for any measured column present. Unknown columns are
    kept in :attr:`RigTable.extra`.

    Raises:
        InputError naming file, line (header = line 1) and column: the format errors of
        :func:`read_run_csv`; an empty cell of a set-point column (``vertical_load``, ``slip``,
        ``slip_angle``); a ``_std`` column without its measured column; a measured value without
        its standard deviation when the file has that ``_std`` column, or a standard deviation
        that is not > 0; a measured column without any value; a row equal cell for cell to an
        earlier one (the line of each). Physical ranges (a load > 0, a
        slip < 1) are checked with the units by :mod:`juno.plausibility`.
    """
    p = Path(path)
    columns, extra, lines = _read_columns(p, lambda names: _check_rig_header(p, names), RIG_COLUMNS)
    for name in RIG_INPUTS:
        if name in columns:
            empty = np.flatnonzero(np.isnan(columns[name]))
            if empty.size:
                raise InputError(f"{name} is empty: it is the testbed's set point, every row needs one", p,
                                 lines[int(empty[0])], name)
    for name in RIG_MEASURED:
        if name not in columns:
            continue
        if np.all(np.isnan(columns[name])):
            raise InputError(f"column {name!r} has no values (every cell is empty)", p, 1, name)
        std = columns.get(name + RIG_STD_SUFFIX)
        if std is None:
            continue
        missing = np.flatnonzero(~np.isnan(columns[name]) & np.isnan(std))
        if missing.size:
            raise InputError(f"{name} is measured here but its standard deviation is empty (a file with a "
                             f"{name}{RIG_STD_SUFFIX} column gives one for every {name} value)", p,
                             lines[int(missing[0])], name + RIG_STD_SUFFIX)
        bad = np.flatnonzero(std <= 0)
        if bad.size:
            raise InputError(f"a standard deviation must be > 0, got {std[bad[0]]!r}", p, lines[int(bad[0])],
                             name + RIG_STD_SUFFIX)
    _check_no_repeated_row(p, [*columns.values(), *extra.values()], lines)
    return RigTable(path=p, columns=columns, extra=extra, lines=np.asarray(lines, dtype=np.int64), run_id=run_id)


def _check_no_repeated_row(path: Path, columns: list[np.ndarray], lines: list[int]) -> None:
    """A testbed table's rows are steady points in any order, so it has no clock to repeat; its
    counterpart of a rover run's repeated time is a row equal cell for cell to another (numbers
    by value, an empty cell equal to an empty cell), which counts one point twice in the fit."""
    cells = [[None if isinstance(v, float) and v != v else v for v in column.tolist()] for column in columns]
    first: dict[tuple, int] = {}
    for i, row in enumerate(zip(*cells)):
        seen = first.setdefault(row, lines[i])
        if seen != lines[i]:
            raise InputError(f"the row repeats line {seen} cell for cell, which counts one point twice; a set "
                             f"point measured twice differs in its measured values, or in a column of your own "
                             f"(a 'repeat' number)", path, lines[i])


def _check_rig_header(path: Path, names: list[str]) -> None:
    _check_header(path, names, RIG_REQUIRED, "wheel_rig", RIG_COLUMNS)
    present = set(names)
    for name in names:
        if name.endswith(RIG_STD_SUFFIX) and name in RIG_COLUMNS and name[: -len(RIG_STD_SUFFIX)] not in present:
            raise InputError(f"a standard deviation column without its measured column "
                             f"{name[: -len(RIG_STD_SUFFIX)]!r}", path, 1, name)


# A whole column of plain decimal numbers or empty cells, one per line: one regex call checks a
# column, where a call per cell would cost more than the rest of reading the file.
_COLUMN_RE = re.compile(rf"(?:{NUMBER_RE.pattern})?(?:\n(?:{NUMBER_RE.pattern})?)*")


#: What loggers and spreadsheets write for a sample they do not have, where the format has an
#: empty cell.
MISSING_MARKS = ("nan", "-nan", "na", "n/a", "#n/a", "null", "none", "-")


def _parse_column(path: Path, name: str, cells: list[str], lines: list[int]) -> FloatArray:
    """A known column's cells as numbers (NaN for an empty cell).  A column that is not plain
    decimal numbers throughout is read cell by cell, so the error names the first bad cell."""
    stripped = [c.strip() for c in cells]
    joined = "\n".join(stripped)
    if joined.count("\n") == len(stripped) - 1 and _COLUMN_RE.fullmatch(joined) is not None:
        out = np.full(len(stripped), np.nan)
        filled = np.fromiter((bool(s) for s in stripped), dtype=bool, count=len(stripped))
        out[filled] = np.fromiter(map(float, (s for s in stripped if s)), dtype=float, count=int(filled.sum()))
        if np.all(np.isfinite(out[filled])):
            return out
    out = np.full(len(cells), np.nan)
    for i, cell in enumerate(cells):
        if cell.strip().lower() in MISSING_MARKS:
            raise InputError(f"not finite: {cell.strip()!r} marks a missing sample: leave the cell empty, which the format reads as "
                             "no sample (docs/campaign-format.md)", path, lines[i], name)
        if cell.strip():
            out[i] = parse_finite(cell, path, lines[i], name)
    return out


def _parse_extra(cells: list[str]) -> np.ndarray:
    stripped = [c.strip() for c in cells]
    if all(not s or NUMBER_RE.fullmatch(s) for s in stripped):
        vals = np.array([float(s) if s else np.nan for s in stripped])
        if not np.any(np.isinf(vals)):
            return vals
    return np.array(stripped, dtype=str)


def _check_time(path: Path, t: FloatArray, lines: NDArray[np.int64], columns: Sequence[np.ndarray]) -> None:
    """Every row has a time, strictly increasing.  A refusal says what the file most likely holds:
    a run that starts again (time back at or before its first row: the run pasted twice, or two
    runs in one file), rows out of order, a row written twice (equal cell for cell to the one
    before it, ``columns`` every column of the file), or two rows of one time."""
    empty = np.flatnonzero(np.isnan(t))
    if empty.size:
        raise InputError("time is empty: every row needs a time", path, int(lines[empty[0]]), "time")
    bad = np.flatnonzero(np.diff(t) <= 0)
    if not bad.size:
        return
    i = int(bad[0]) + 1
    now, last, first = float(t[i]), float(t[i - 1]), float(t[0])
    before = f"{now!r} s after {last!r} s (line {lines[i - 1]})"
    if now < last and now <= first:
        what = (f"time goes backwards: {before}, back to the run's start at {first!r} s (line {lines[0]}): the rows "
                "from here on look like the run again, or another run; a file holds one run: cut it here")
    elif now < last:
        what = f"time goes backwards: {before}: a run's rows are in time order; sort them by time"
    elif all(_same_cell(c[i], c[i - 1]) for c in columns):
        what = (f"time repeats: the row repeats line {lines[i - 1]} cell for cell (a row written twice): "
                "delete one of them")
    else:
        what = (f"time repeats: {before}, with other values: a time's samples go on one row (an empty cell "
                "where a sensor has none); two readings at one time cannot be ordered")
    raise InputError(what, path, int(lines[i]), "time")


def _same_cell(a: object, b: object) -> bool:
    """Two cells of a column read alike: equal, or both empty."""
    return bool(a == b) or (isinstance(a, float) and isinstance(b, float) and a != a and b != b)


def read_run(campaign: Campaign, run: Union[RunSpec, str]) -> RunData:
    """Read a run of a loaded campaign (by :class:`RunSpec` or id) and check it.

    Besides :func:`read_run_csv`'s checks, a ``steady_window`` must hold samples and lie within the
    run's time (:func:`_steady_window_beyond_run`).
    A wheel_rig run is a table, not a time series: an InputError says so (:func:`read_rig`).
    """
    spec = campaign.run(run) if isinstance(run, str) else run
    if spec.kind not in TIME_SERIES_KINDS:
        raise InputError(f"run {spec.id!r} is a {spec.kind} table of steady points, not a time series: "
                         "'juno identify' fits it", campaign.manifest_path,
                         _line_of_run(decode_input_text(campaign.manifest_path,
                                                        read_input_bytes(campaign.manifest_path)), spec.id))
    data = _read_once(campaign, campaign.run_path(spec), spec.kind, spec.id, spec.sensor_noise)
    if spec.steady_window is not None:
        a, b = spec.steady_window
        t = data.time
        if not np.any((t >= a) & (t <= b)):
            raise InputError(
                f"run {spec.id!r}: steady_window [{a}, {b}] s holds no samples; the run spans "
                f"{float(t[0])!r} to {float(t[-1])!r} s" + _steady_window_hint(a, b, float(t[0]), float(t[-1])),
                campaign.manifest_path,
                _line_of_run(decode_input_text(campaign.manifest_path, read_input_bytes(campaign.manifest_path)), spec.id),
            )
        beyond = _steady_window_beyond_run(a, b, t)
        if beyond:
            raise InputError(
                f"run {spec.id!r}: steady_window [{a}, {b}] s {beyond}: the run spans {float(t[0])!r} to "
                f"{float(t[-1])!r} s; was the file cut short, or is the window another run's?",
                campaign.manifest_path,
                _line_of_run(decode_input_text(campaign.manifest_path, read_input_bytes(campaign.manifest_path)), spec.id),
            )
    return data


def _steady_window_beyond_run(a: float, b: float, t: NDArray[np.float64]) -> str:
    """What part of a steady window [a, b] (s) lies beyond the rows ``t`` (s) of its run, or "".

    The steady averages and the replays over a window's length take it as measured throughout:
    a window reaching further than one typical row interval beyond the first or last row (where
    the logger's next row would have come) covers time the file does not hold."""
    step = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    if b > float(t[-1]) + step:
        return "reaches past the run's end"
    if a < float(t[0]) - step:
        return "starts before the run"
    return ""


def _read_once(campaign: Campaign, path: Path, kind: str, run_id: str, stated_noise: dict[str, float]) -> RunData:
    """:func:`read_run_csv` of a run of ``campaign``, read once for as long as its file is unchanged
    (the same size and modification time): every phase of an analysis reads the runs it needs, and
    a run's file is parsed and checked once.  The arrays of a run kept so are read-only, so that no
    reader changes what the next one is given.  ``stated_noise``: the manifest's sensor noise of
    the run's columns (RunData.stated_noise)."""
    try:
        st = path.stat()
        stamp: Optional[tuple[int, int, int]] = (st.st_size, st.st_mtime_ns, st.st_ino)
    except OSError:
        stamp = None          # read_run_csv says what is wrong with the file
    key = (str(path), kind, run_id)
    kept = campaign._runs_read.get(key)
    if stamp is not None and kept is not None and kept[0] == stamp:
        return kept[1]
    data = read_run_csv(path, kind, run_id=run_id)
    data.stated_noise = dict(stated_noise)
    for array in (*data.columns.values(), *data.extra.values(), data.lines):
        if array is not None:
            array.setflags(write=False)
    if stamp is not None:
        campaign._runs_read[key] = (stamp, data)
    return data


#: A run lasting longer than this (s) as written is taken for one whose time is in milliseconds
#: when that reading fits its steady window (juno.plausibility.sensors's time check draws the
#: same line: the rover's runs last seconds to minutes).
AN_HOUR = 3600.0


def _steady_window_hint(a: float, b: float, t0: float, t1: float) -> str:
    """The likely mistake behind a steady window [a, b] (s) outside a run spanning [t0, t1] (s):
    a time column in milliseconds (from zero, or from a clock that does not start at zero, such
    as a logger's Unix time, with the window counted from the run's start), or a window counted
    from the run's start on a clock that does not start at zero."""
    if t0 > 0 and t1 - t0 > AN_HOUR and 0 <= a and b <= (t1 - t0) / 1000.0:
        return (f"; the run lasts {t1 - t0:g} s as written, over an hour: is the time column in milliseconds "
                f"(from {t0!r})? In seconds the run lasts {(t1 - t0) / 1000.0:g} s, and the window counted from "
                "its start lies within it. The format's time is in seconds")
    if t0 > 0 and t0 <= a + t0 and b + t0 <= t1:
        return (f"; the window is on the run's own clock, which starts at {t0!r} s: counted from the "
                f"start, it is [{a + t0!r}, {b + t0!r}]")
    if t0 / 1000.0 <= a and b <= t1 / 1000.0:
        return "; is the time column in milliseconds? The format's time is in seconds"
    return ""


def read_rig(campaign: Campaign, run: Union[RunSpec, str]) -> RigTable:
    """Read and check the table of a wheel_rig run of a loaded campaign (:func:`read_rig_csv`)."""
    spec = campaign.run(run) if isinstance(run, str) else run
    if spec.kind != "wheel_rig":
        raise ValueError(f"run {spec.id!r} is a {spec.kind} run, not a wheel_rig table")
    return read_rig_csv(campaign.run_path(spec), run_id=spec.id)


def read_any(campaign: Campaign, run: Union[RunSpec, str]) -> Union[RunData, RigTable]:
    """:func:`read_run` for a time series, :func:`read_rig` for a wheel_rig table."""
    spec = campaign.run(run) if isinstance(run, str) else run
    return read_rig(campaign, spec) if spec.kind == "wheel_rig" else read_run(campaign, spec)


def read_terrain_points(campaign: Campaign, run: Union[RunSpec, str]) -> FloatArray:
    """The LIDAR cloud (N, 3) (m) of a terrain run (see :func:`juno.pointcloud.read_xyz`)."""
    spec = campaign.run(run) if isinstance(run, str) else run
    path = campaign.terrain_path(spec)
    if path is None:
        raise ValueError(f"run {spec.id!r} is a {spec.kind} run and has no terrain")
    return read_xyz(path)
