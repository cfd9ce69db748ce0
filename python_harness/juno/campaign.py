"""Measured campaigns: read, check, align, derive, write.

A campaign is a folder::

    campaign.json          manifest
    runs/NAME.csv          one file per experiment run
    terrain/NAME.xyz       LIDAR points, "x y z" per line (m)
    runs/RIG.csv           a single-wheel testbed table (kind ``wheel_rig``)

Reading is strict: anything that breaks the format is refused with an
:class:`~juno.errors.InputError` naming the file, the line (1-based, the CSV header is line 1)
and the column or key. Input files are only ever read, never written.

Run CSV columns (SI units): ``time`` (s, strictly increasing, never empty), ``torque_left``,
``torque_right`` (N m per side), ``omega_left``, ``omega_right`` (rad/s), ``pos_x``, ``pos_y``,
``pos_z`` (m, total station), ``drawbar_force`` (N, drawbar runs), optional IMU ``roll``,
``pitch``, ``yaw`` (rad), ``acc_*``, ``gyro_*``. An empty cell means "no sample at this time"
(sensors run at different rates) and becomes NaN. Every cell of a known column is empty or a
finite decimal number. Unknown columns are kept in :attr:`RunData.extra` and otherwise ignored:
as float arrays when every cell is empty or a finite number, else as the raw text.

A ``wheel_rig`` run is a single-wheel testbed's table, one row per steady point, not a time
series (:func:`read_rig_csv`): ``vertical_load`` (N), ``slip`` (-), ``drawbar_pull`` (N), optional
``torque`` (N m), ``sinkage`` (m), ``slip_angle`` (rad), ``lateral_force`` (N) and a standard
deviation ``<column>_std`` of each measured column; the wheel is described in the manifest
(:class:`RigSetup`).
"""

from __future__ import annotations

import copy
import csv
import io
import json
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from typing import Any, Callable, Mapping, Optional, Sequence, Union

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .atomic import atomic_directory
from .errors import NUMBER_RE, InputError, parse_finite, decode_input_text, read_input_bytes
from .pointcloud import format_xyz, read_xyz

PathLike = Union[str, "os.PathLike[str]"]
FloatArray = NDArray[np.float64]

__all__ = [
    "KINDS",
    "REQUIRED_COLUMNS",
    "KNOWN_COLUMNS",
    "ANGLE_COLUMNS",
    "MANIFEST_NAME",
    "RunSpec",
    "Campaign",
    "RunData",
    "AlignedColumns",
    "load_campaign",
    "read_run",
    "read_run_csv",
    "read_terrain_points",
    "RigSetup",
    "RigTable",
    "RIG_INPUTS",
    "RIG_MEASURED",
    "read_rig_csv",
    "read_rig",
    "read_any",
    "format_rig_csv",
    "aligned",
    "steady_average",
    "forward_speed",
    "format_run_csv",
    "write_campaign",
]

MANIFEST_NAME = "campaign.json"
KINDS = ("drawbar", "terrain", "wheel_rig")
#: The kinds whose CSV is a time series (read_run_csv); a wheel_rig run is a table (read_rig_csv).
TIME_SERIES_KINDS = ("drawbar", "terrain")
BASE_REQUIRED = ("time", "torque_left", "torque_right", "omega_left", "omega_right", "pos_x", "pos_y", "pos_z")
REQUIRED_COLUMNS: dict[str, tuple[str, ...]] = {
    "drawbar": BASE_REQUIRED + ("drawbar_force",),
    "terrain": BASE_REQUIRED,
}
OPTIONAL_COLUMNS = (
    "roll", "pitch", "yaw",
    "acc_x", "acc_y", "acc_z", "gyro_x", "gyro_y", "gyro_z",
)
KNOWN_COLUMNS = BASE_REQUIRED + ("drawbar_force",) + OPTIONAL_COLUMNS
ANGLE_COLUMNS = ("roll", "pitch", "yaw")
"""Columns unwrapped (made continuous) before interpolation by :func:`aligned`."""

#: A wheel_rig table: the testbed's set point of each row (inputs of the simulation, a value in
#: every row) and the measured columns (an empty cell: not measured at that point), each of which
#: may carry a per-point standard deviation ``<column>_std`` in the same unit.
RIG_INPUTS = ("vertical_load", "slip", "slip_angle")
RIG_REQUIRED = ("vertical_load", "slip", "drawbar_pull")
RIG_MEASURED = ("drawbar_pull", "torque", "sinkage", "lateral_force")
RIG_STD_SUFFIX = "_std"
RIG_COLUMNS = RIG_INPUTS + RIG_MEASURED + tuple(c + RIG_STD_SUFFIX for c in RIG_MEASURED)
#: Keys of a wheel_rig run's "wheel" object (m, m, m, count); the first two are required.
RIG_WHEEL_KEYS = ("radius", "width", "lug_height", "lug_count")

_ID_RE = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]*")


# --------------------------------------------------------------------------------------------
# Data classes
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class RigSetup:
    """The single-wheel testbed of a ``wheel_rig`` run (manifest keys ``wheel`` and
    ``carriage_speed``).

    Attributes:
        radius: wheel radius (m), to the rim (lugs not included).
        width: wheel width (m).
        lug_height: height of the lugs (grousers) beyond the rim (m); 0 for a smooth wheel.
        lug_count: number of lugs around the rim; 0 for a smooth wheel.
        carriage_speed: the carriage's forward speed (m/s), or None when not given.
    """

    radius: float
    width: float
    lug_height: float = 0.0
    lug_count: int = 0
    carriage_speed: Optional[float] = None

    @property
    def lugged(self) -> bool:
        return self.lug_height > 0.0


@dataclass(frozen=True)
class RunSpec:
    """One run of the manifest.

    Attributes:
        id: run id (letters, digits, ``_ . -``; unique in the campaign).
        kind: "drawbar", "terrain" or "wheel_rig".
        file: CSV path relative to the campaign folder, as written in the manifest.
        steady_window: (start, end) in s where the averaged identification looks, or None.
        terrain: LIDAR file relative to the campaign folder (terrain runs), else None.
        extra: any other keys of the run's manifest entry, kept as read.
        rig: the testbed's wheel and carriage (wheel_rig runs), else None.
    """

    id: str
    kind: str
    file: str
    steady_window: Optional[tuple[float, float]] = None
    terrain: Optional[str] = None
    extra: dict[str, Any] = field(default_factory=dict)
    rig: Optional[RigSetup] = None


@dataclass(frozen=True)
class Campaign:
    """A loaded, checked manifest.

    Attributes:
        root: the campaign folder.
        name: campaign name (the folder's name when the manifest has none).
        runs: the runs in manifest order.
        rover: FMU parameter overrides by FMU name (``{"wheel.width": 0.254}``); numbers stay
            int or float as written, strings stay strings.
        extra: other top-level manifest keys, kept as read.
    """

    root: Path
    name: str
    runs: tuple[RunSpec, ...]
    rover: dict[str, Union[float, int, str]] = field(default_factory=dict)
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def manifest_path(self) -> Path:
        return self.root / MANIFEST_NAME

    def run(self, run_id: str) -> RunSpec:
        """The run with this id (KeyError if none)."""
        for spec in self.runs:
            if spec.id == run_id:
                return spec
        raise KeyError(f"{self.manifest_path}: no run with id {run_id!r} (runs: {[r.id for r in self.runs]})")

    def runs_of_kind(self, kind: str) -> list[RunSpec]:
        """Runs of kind "drawbar", "terrain" or "wheel_rig", in manifest order."""
        return [r for r in self.runs if r.kind == kind]

    def run_path(self, run: Union[RunSpec, str]) -> Path:
        """Absolute path of a run's CSV."""
        spec = self.run(run) if isinstance(run, str) else run
        return self.root / spec.file

    def terrain_path(self, run: Union[RunSpec, str]) -> Optional[Path]:
        """Path of a run's LIDAR file, or None (drawbar runs)."""
        spec = self.run(run) if isinstance(run, str) else run
        return None if spec.terrain is None else self.root / spec.terrain


class _ColumnTable:
    """Access by column name to a table whose ``columns`` map names to float arrays (NaN = no
    value in that row): what a run's samples and a testbed's points share."""

    columns: dict[str, FloatArray]

    def __contains__(self, name: object) -> bool:
        return name in self.columns

    def __getitem__(self, name: str) -> FloatArray:
        return self.columns[name]

    def has(self, name: str) -> bool:
        """True when the column exists and has at least one value."""
        return name in self.columns and bool(np.any(~np.isnan(self.columns[name])))


@dataclass
class RunData(_ColumnTable):
    """The samples of one run CSV.

    Attributes:
        path: the CSV file.
        kind: "drawbar" or "terrain".
        columns: known column name -> float array (one entry per row, NaN = no sample),
            including ``time``; columns absent from the file are absent here.
        extra: unknown columns, kept as read (float arrays, or str arrays if not all numeric).
        lines: 1-based line number of each row in the file (for messages).
        run_id: the manifest id, when read through :func:`read_run`.
    """

    path: Path
    kind: str
    columns: dict[str, FloatArray]
    extra: dict[str, np.ndarray] = field(default_factory=dict)
    lines: Optional[NDArray[np.int64]] = None
    run_id: Optional[str] = None

    @property
    def time(self) -> FloatArray:
        """Row times (s), strictly increasing, no NaN."""
        return self.columns["time"]

    def __len__(self) -> int:
        return int(self.time.shape[0])

    def samples(self, name: str) -> tuple[FloatArray, FloatArray]:
        """(times, values) of the column's own non-empty samples.

        Raises:
            InputError: the column is absent or has no samples.
        """
        if name not in self.columns:
            raise InputError(f"the run has no column {name!r}", self.path, None, name)
        v = self.columns[name]
        ok = ~np.isnan(v)
        if not ok.any():
            raise InputError(f"column {name!r} has no samples", self.path, None, name)
        return self.time[ok], v[ok]


@dataclass
class RigTable(_ColumnTable):
    """The points of one wheel_rig table (:func:`read_rig_csv`).

    Attributes:
        path: the CSV file.
        columns: known column name -> float array (one entry per row; NaN = not measured at
            that point). The inputs ``vertical_load`` and ``slip`` are always present and have
            a value in every row; ``slip_angle`` too when the file has it.
        extra: unknown columns, kept as read (float arrays, or str arrays if not all numeric).
        lines: 1-based line number of each row in the file (for messages).
        run_id: the manifest id, when read through :func:`read_run`.
    """

    path: Path
    columns: dict[str, FloatArray]
    extra: dict[str, np.ndarray] = field(default_factory=dict)
    lines: Optional[NDArray[np.int64]] = None
    run_id: Optional[str] = None
    kind: str = "wheel_rig"

    def __len__(self) -> int:
        return int(self.columns["slip"].shape[0])

    @property
    def slip_angle(self) -> FloatArray:
        """Slip angle of each point (rad); zeros when the file has no such column."""
        return self.columns.get("slip_angle", np.zeros(len(self)))

    def std(self, name: str) -> Optional[FloatArray]:
        """The per-point standard deviations of a measured column, or None when not given."""
        return self.columns.get(name + RIG_STD_SUFFIX)


class AlignedColumns(dict):
    """Result of :func:`aligned`: column name -> values on the requested times.

    ``coverage[name]`` is a bool array, True where the requested time lies between the column's
    first and last sample (outside, the end value is held, not extrapolated).
    """

    def __init__(self) -> None:
        super().__init__()
        self.coverage: dict[str, NDArray[np.bool_]] = {}


# --------------------------------------------------------------------------------------------
# Small helpers
# --------------------------------------------------------------------------------------------





def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _finite_number(value: Any) -> Optional[float]:
    """float(value) if value is a finite JSON number (not a bool), else None."""
    if not _is_number(value):
        return None
    try:
        f = float(value)
    except OverflowError:
        return None
    return f if math.isfinite(f) else None


# --------------------------------------------------------------------------------------------
# Manifest
# --------------------------------------------------------------------------------------------

class _DuplicateKey(Exception):
    pass


def _no_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in pairs:
        if k in out:
            raise _DuplicateKey(k)
        out[k] = v
    return out


def _refuse_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a valid JSON number")


def _parse_json(path: Path, text: str) -> Any:
    try:
        return json.loads(text, object_pairs_hook=_no_duplicates, parse_constant=_refuse_constant)
    except json.JSONDecodeError as e:
        raise InputError(f"invalid JSON: {e.msg} (at column {e.colno})", path, e.lineno) from None
    except _DuplicateKey as e:
        raise InputError(f"invalid manifest: key {e.args[0]!r} appears twice in one object", path) from None
    except RecursionError:
        raise InputError("invalid JSON: nested too deeply", path) from None
    except ValueError as e:  # NaN/Infinity constants, huge integers
        raise InputError(f"invalid JSON: {e}", path) from None


def _line_of_run(text: str, run_id: Any, occurrence: int = 0) -> Optional[int]:
    """Best-effort line of the ``occurrence``-th ``"id": "<run_id>"`` in the manifest text."""
    if not isinstance(run_id, str):
        return None
    pattern = re.compile(r'"id"\s*:\s*' + re.escape(json.dumps(run_id)))
    for k, m in enumerate(pattern.finditer(text)):
        if k == occurrence:
            return text.count("\n", 0, m.start()) + 1
    return None


def _check_relative_file(root: Path, manifest: Path, value: Any, where: str, line: Optional[int]) -> str:
    """Check that ``value`` names an existing regular file inside ``root``; return it."""
    if not isinstance(value, str) or not value.strip():
        raise InputError(f"{where} must be a file path (string) relative to the campaign folder, got {value!r}", manifest, line)
    if "\x00" in value or "\\" in value:
        raise InputError(f"{where} must be a '/'-separated relative path, got {value!r}", manifest, line)
    rel = PurePosixPath(value)
    if rel.is_absolute() or re.match(r"[A-Za-z]:", value):
        raise InputError(f"{where} must be relative to the campaign folder, got {value!r}", manifest, line)
    full = root / value
    try:
        resolved = full.resolve()
        inside = resolved.is_relative_to(root.resolve())
    except (OSError, RuntimeError, ValueError):
        raise InputError(f"{where}: cannot resolve {value!r}", manifest, line) from None
    if not inside:
        raise InputError(f"{where} {value!r} points outside the campaign folder {root}", manifest, line)
    if not resolved.exists():
        raise InputError(f"{where}: file not found: {full}", manifest, line)
    if not resolved.is_file():
        raise InputError(f"{where}: not a regular file: {full}", manifest, line)
    return value


def _parse_run(root: Path, manifest: Path, text: str, i: int, entry: Any, seen: dict[str, int]) -> RunSpec:
    if not isinstance(entry, dict):
        raise InputError(f"runs[{i}] must be an object, got {type(entry).__name__}", manifest)
    run_id = entry.get("id")
    line = _line_of_run(text, run_id, occurrence=1 if isinstance(run_id, str) and run_id in seen else 0)
    label = f"runs[{i}]" + (f" (id {run_id!r})" if isinstance(run_id, str) else "")
    for key in ("id", "kind", "file"):
        if key not in entry:
            raise InputError(f"{label}: required key {key!r} is missing", manifest, line)
    if not isinstance(run_id, str) or _ID_RE.fullmatch(run_id) is None:
        raise InputError(
            f"{label}: 'id' must be a non-empty string of letters, digits, '_', '.', '-', got {run_id!r}", manifest, line
        )
    if run_id in seen:
        raise InputError(f"{label}: duplicate run id {run_id!r} (also runs[{seen[run_id]}])", manifest, line)
    seen[run_id] = i
    kind = entry["kind"]
    if kind not in KINDS:
        raise InputError(f"{label}: 'kind' must be 'drawbar', 'terrain' or 'wheel_rig', got {kind!r}", manifest, line)
    file = _check_relative_file(root, manifest, entry["file"], f"{label}: 'file'", line)

    window = None
    if kind == "wheel_rig" and "steady_window" in entry:
        raise InputError(f"{label}: a wheel_rig run is a table of steady points and takes no 'steady_window'",
                         manifest, line)
    if "steady_window" in entry:
        w = entry["steady_window"]
        vals = [_finite_number(v) for v in w] if isinstance(w, list) else []
        if len(vals) != 2 or any(v is None for v in vals):
            raise InputError(f"{label}: 'steady_window' must be two finite numbers [start, end] in s, got {w!r}", manifest, line)
        a, b = vals  # type: ignore[misc]
        if not a < b:  # type: ignore[operator]
            raise InputError(f"{label}: 'steady_window' start must be before its end, got {w!r}", manifest, line)
        window = (float(a), float(b))  # type: ignore[arg-type]

    terrain = None
    if kind == "terrain":
        if "terrain" not in entry:
            raise InputError(f"{label}: terrain runs need a 'terrain' key naming the LIDAR file", manifest, line)
        terrain = _check_relative_file(root, manifest, entry["terrain"], f"{label}: 'terrain'", line)
    elif "terrain" in entry:
        raise InputError(f"{label}: {kind} runs are on flat ground and take no 'terrain' key", manifest, line)

    rig = None
    if kind == "wheel_rig":
        rig = _parse_rig(manifest, entry, label, line)
    else:
        for key in ("wheel", "carriage_speed"):
            if key in entry:
                raise InputError(f"{label}: {key!r} describes a wheel_rig run's testbed; a {kind} run uses the "
                                 "campaign's 'rover'", manifest, line)
    known = ("id", "kind", "file", "steady_window", "terrain", "wheel", "carriage_speed")
    extra = {k: v for k, v in entry.items() if k not in known}
    return RunSpec(id=run_id, kind=kind, file=file, steady_window=window, terrain=terrain, extra=extra, rig=rig)


def _parse_rig(manifest: Path, entry: dict[str, Any], label: str, line: Optional[int]) -> RigSetup:
    """The ``wheel`` object and the optional ``carriage_speed`` of a wheel_rig run entry."""
    wheel = entry.get("wheel")
    if not isinstance(wheel, dict):
        got = "it has none" if "wheel" not in entry else f"got {json.dumps(wheel)}"
        raise InputError(f"{label}: a wheel_rig run needs a 'wheel' object {{\"radius\": m, \"width\": m, "
                         f"\"lug_height\": m, \"lug_count\": n}}; {got}", manifest, line)
    unknown = [k for k in wheel if k not in RIG_WHEEL_KEYS]
    if unknown:
        raise InputError(f"{label}: 'wheel' has no key {unknown[0]!r} (its keys: {', '.join(RIG_WHEEL_KEYS)}; "
                         "lengths in m)", manifest, line)
    values: dict[str, float] = {}
    for key in ("radius", "width", "lug_height"):
        if key not in wheel:
            if key == "lug_height":
                values[key] = 0.0
                continue
            raise InputError(f"{label}: 'wheel' needs {key!r} (m)", manifest, line)
        v = _finite_number(wheel[key])
        if v is None or v < 0 or (v == 0 and key != "lug_height"):
            need = "a finite number >= 0" if key == "lug_height" else "a finite number > 0"
            raise InputError(f"{label}: 'wheel.{key}' must be {need} (m), got {wheel[key]!r}", manifest, line)
        values[key] = v
    count = wheel.get("lug_count", 0)
    if isinstance(count, float) and count.is_integer():
        count = int(count)
    if not isinstance(count, int) or isinstance(count, bool) or count < 0:
        raise InputError(f"{label}: 'wheel.lug_count' must be a whole number >= 0, got {count!r}", manifest, line)
    if (values["lug_height"] > 0) != (count > 0):
        raise InputError(f"{label}: 'wheel' has lug_height {values['lug_height']!r} m and lug_count {count!r}: a "
                         "lugged wheel has both > 0, a smooth one both 0", manifest, line)
    speed = None
    if "carriage_speed" in entry:
        speed = _finite_number(entry["carriage_speed"])
        if speed is None or speed <= 0:
            raise InputError(f"{label}: 'carriage_speed' must be a finite number > 0 (m/s), got "
                             f"{entry['carriage_speed']!r}", manifest, line)
    return RigSetup(radius=values["radius"], width=values["width"], lug_height=values["lug_height"],
                    lug_count=count, carriage_speed=speed)


def _parse_rover(manifest: Path, rover: Any) -> dict[str, Union[float, int, str]]:
    if not isinstance(rover, dict):
        raise InputError(f"'rover' must be an object of FMU parameter overrides, got {type(rover).__name__}", manifest)
    out: dict[str, Union[float, int, str]] = {}
    for k, v in rover.items():
        if not k.strip():
            raise InputError("'rover': empty parameter name", manifest)
        if isinstance(v, str):
            out[k] = v
        elif _finite_number(v) is not None:
            out[k] = v
        else:
            raise InputError(f"'rover': parameter {k!r} must be a finite number or a string, got {v!r}", manifest)
    return out


def load_campaign(path: PathLike) -> Campaign:
    """Load and check a campaign manifest.

    Args:
        path: the campaign folder, or its ``campaign.json``.

    Checks: valid UTF-8 JSON (syntax errors give line and column), no duplicate keys, a
    non-empty ``runs`` list; each run has ``id`` (unique), ``kind`` in {drawbar, terrain,
    wheel_rig}, ``file`` naming an existing file inside the folder; terrain runs name an existing
    ``terrain`` file (the others none); ``steady_window`` is two increasing finite numbers (not
    for wheel_rig runs); a wheel_rig run has a ``wheel`` object (radius, width > 0 m; lug_height
    >= 0 m and lug_count >= 0, both 0 or both > 0) and optionally ``carriage_speed`` > 0 m/s;
    ``rover`` maps names to finite numbers or strings; ``name`` is a string.
    Run CSV contents are checked by :func:`read_run`.

    Raises:
        InputError naming ``campaign.json``, and the run / key.
    """
    p = Path(path)
    if not p.exists():
        raise InputError("no such campaign folder or manifest", p)
    manifest = p / MANIFEST_NAME if p.is_dir() else p
    root = manifest.parent
    text = decode_input_text(manifest, read_input_bytes(manifest))
    doc = _parse_json(manifest, text)
    if not isinstance(doc, dict):
        raise InputError(f"the manifest must be a JSON object, got {type(doc).__name__}", manifest, 1)
    if "runs" not in doc:
        raise InputError("required key 'runs' is missing", manifest)
    name = doc.get("name", root.resolve().name)
    if not isinstance(name, str) or not name.strip():
        raise InputError(f"'name' must be a non-empty string, got {name!r}", manifest)
    runs = doc["runs"]
    if not isinstance(runs, list) or not runs:
        raise InputError("'runs' must be a non-empty list of run objects", manifest)
    seen: dict[str, int] = {}
    specs = tuple(_parse_run(root, manifest, text, i, entry, seen) for i, entry in enumerate(runs))
    rover = _parse_rover(manifest, doc.get("rover", {}))
    extra = {k: v for k, v in doc.items() if k not in ("name", "runs", "rover")}
    return Campaign(root=root, name=name, runs=specs, rover=rover, extra=extra)


# --------------------------------------------------------------------------------------------
# Run CSV
# --------------------------------------------------------------------------------------------

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
    _check_time(p, columns["time"], line_arr)
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
    for j, name in enumerate(names):
        cells = [row[j] for row in rows]
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
            if len(row) != ncols:
                raise InputError(f"row has {len(row)} cells, the header has {ncols}", p, lineno)
            rows.append(row)
            lines.append(lineno)
    except csv.Error as e:
        raise InputError(f"malformed CSV: {e}", p, reader.line_num) from None
    if not rows:
        raise InputError("no data rows: the file holds only a header", p, 1)
    return names, rows, lines


def _check_header(path: Path, names: list[str], required: Sequence[str], kind: str,
                  known: Sequence[str]) -> None:
    """Column names: present, unique, the ``required`` ones there.  A name that is a ``known``
    column written with its unit or in another case is refused, not kept as an extra column the
    harness would silently leave out."""
    if all(NUMBER_RE.fullmatch(n) for n in names if n) and any(names):
        raise InputError("the first line must be a header of column names; it holds numbers", path, 1)
    seen: set[str] = set()
    for j, name in enumerate(names):
        if not name:
            raise InputError(f"header cell {j + 1} is an empty column name", path, 1)
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
        that is not > 0; a measured column without any value. Physical ranges (a load > 0, a
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
    return RigTable(path=p, columns=columns, extra=extra, lines=np.asarray(lines, dtype=np.int64), run_id=run_id)


def _check_rig_header(path: Path, names: list[str]) -> None:
    _check_header(path, names, RIG_REQUIRED, "wheel_rig", RIG_COLUMNS)
    present = set(names)
    for name in names:
        if name.endswith(RIG_STD_SUFFIX) and name in RIG_COLUMNS and name[: -len(RIG_STD_SUFFIX)] not in present:
            raise InputError(f"a standard deviation column without its measured column "
                             f"{name[: -len(RIG_STD_SUFFIX)]!r}", path, 1, name)


def _parse_column(path: Path, name: str, cells: list[str], lines: list[int]) -> FloatArray:
    out = np.full(len(cells), np.nan)
    for i, cell in enumerate(cells):
        s = cell.strip()
        if s:
            out[i] = parse_finite(cell, path, lines[i], name)
    return out


def _parse_extra(cells: list[str]) -> np.ndarray:
    stripped = [c.strip() for c in cells]
    if all(not s or NUMBER_RE.fullmatch(s) for s in stripped):
        vals = np.array([float(s) if s else np.nan for s in stripped])
        if not np.any(np.isinf(vals)):
            return vals
    return np.array(stripped, dtype=str)


def _check_time(path: Path, t: FloatArray, lines: NDArray[np.int64]) -> None:
    empty = np.flatnonzero(np.isnan(t))
    if empty.size:
        raise InputError("time is empty: every row needs a time", path, int(lines[empty[0]]), "time")
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        what = "time goes backwards" if t[i] < t[i - 1] else "time repeats"
        raise InputError(f"{what}: {t[i]!r} s after {t[i - 1]!r} s (line {lines[i - 1]})", path, int(lines[i]), "time")


def read_run(campaign: Campaign, run: Union[RunSpec, str]) -> RunData:
    """Read a run of a loaded campaign (by :class:`RunSpec` or id) and check it.

    Besides :func:`read_run_csv`'s checks, a ``steady_window`` must overlap the run's time.
    A wheel_rig run is a table, not a time series: an InputError says so (:func:`read_rig`).
    """
    spec = campaign.run(run) if isinstance(run, str) else run
    if spec.kind not in TIME_SERIES_KINDS:
        raise InputError(f"run {spec.id!r} is a {spec.kind} table of steady points, not a time series: "
                         "'juno identify' fits it", campaign.manifest_path,
                         _line_of_run(decode_input_text(campaign.manifest_path,
                                                        read_input_bytes(campaign.manifest_path)), spec.id))
    data = read_run_csv(campaign.run_path(spec), spec.kind, run_id=spec.id)
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
    return data


def _steady_window_hint(a: float, b: float, t0: float, t1: float) -> str:
    """The likely mistake behind a steady window [a, b] (s) outside a run spanning [t0, t1] (s):
    a window counted from the run's start on a clock that does not start at zero, or a time
    column in milliseconds."""
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


# --------------------------------------------------------------------------------------------
# Multi-rate signals
# --------------------------------------------------------------------------------------------

def _as_times(times: ArrayLike) -> FloatArray:
    t = np.atleast_1d(np.asarray(times, dtype=float))
    if t.ndim != 1 or not np.all(np.isfinite(t)):
        raise ValueError("times must be a 1-D array of finite values (s)")
    return t


def aligned(
    run: RunData,
    columns: Union[str, Sequence[str]],
    times: ArrayLike,
    method: str = "linear",
) -> AlignedColumns:
    """Resample columns onto a common time grid, each from its own non-empty samples.

    Args:
        run: the run.
        columns: a name or names of columns (known or numeric extra columns).
        times: requested times (s), 1-D, any order.
        method: "linear" (default), "previous" (zero-order hold) or "nearest".

    Returns:
        :class:`AlignedColumns` (a dict name -> array like ``times``) with ``.coverage``:
        True where the time lies within the column's first..last sample. Beyond those ends
        the end value is held, never extrapolated. Angle columns (roll, pitch, yaw) are
        unwrapped before interpolation and returned continuous (not wrapped to +-pi).

    Raises:
        InputError: a column is absent or has no samples.
    """
    if method not in ("linear", "previous", "nearest"):
        raise ValueError(f"method must be 'linear', 'previous' or 'nearest', got {method!r}")
    names = [columns] if isinstance(columns, str) else list(columns)
    t = _as_times(times)
    out = AlignedColumns()
    for name in names:
        ts, vs = _column_samples(run, name)
        if name in ANGLE_COLUMNS:
            vs = np.unwrap(vs)
        out[name] = _resample(ts, vs, t, method)
        out.coverage[name] = (t >= ts[0]) & (t <= ts[-1])
    return out


def _column_samples(run: RunData, name: str) -> tuple[FloatArray, FloatArray]:
    if name not in run.columns and name in run.extra and run.extra[name].dtype.kind == "f":
        v = run.extra[name]
        ok = ~np.isnan(v)
        if ok.any():
            return run.time[ok], v[ok]
    return run.samples(name)


def _resample(ts: FloatArray, vs: FloatArray, t: FloatArray, method: str) -> FloatArray:
    if method == "linear":
        return np.interp(t, ts, vs)
    if method == "previous":
        i = np.clip(np.searchsorted(ts, t, side="right") - 1, 0, len(ts) - 1)
        return vs[i]
    j = np.clip(np.searchsorted(ts, t), 1, max(len(ts) - 1, 1))
    if len(ts) == 1:
        return np.full(t.shape, vs[0])
    left_closer = (t - ts[j - 1]) <= (ts[j] - t)
    return np.where(left_closer, vs[j - 1], vs[j])


def steady_average(run: RunData, column: str, window: Sequence[float]) -> float:
    """Mean of a column's own samples with start <= t <= end (window in s).

    Raises:
        InputError: the column is absent or has no sample inside the window.
    """
    a, b = (float(w) for w in window)
    if not a < b:
        raise ValueError(f"window start must be before its end, got {window!r}")
    ts, vs = _column_samples(run, column)
    inside = (ts >= a) & (ts <= b)
    if not inside.any():
        raise InputError(f"no samples of {column!r} inside the window [{a}, {b}] s", run.path, None, column)
    return float(vs[inside].mean())


def _local_slope(ts: FloatArray, vs: FloatArray, t: FloatArray, window: float, min_samples: int = 3) -> FloatArray:
    """Slope of a least-squares line fitted to the samples within +-window/2 of each t.

    Irregular sampling is handled by the regression. Where fewer than ``min_samples`` lie in
    the window (sparse data, ends), the ``min_samples`` samples nearest in index are used.
    """
    n = len(ts)
    k = min(min_samples, n)
    tc = ts - ts.mean()
    vc = vs - vs.mean()
    lo = np.searchsorted(ts, t - 0.5 * window, side="left")
    hi = np.searchsorted(ts, t + 0.5 * window, side="right")
    few = (hi - lo) < k
    if few.any():
        c = np.searchsorted(ts, t[few])
        lo_f = np.clip(c - k // 2, 0, n - k)
        lo[few] = lo_f
        hi[few] = lo_f + k

    def window_sum(x: FloatArray) -> FloatArray:
        cs = np.concatenate(([0.0], np.cumsum(x)))
        return cs[hi] - cs[lo]

    s0 = (hi - lo).astype(float)
    s1 = window_sum(tc)
    s2 = window_sum(tc * tc)
    sv = window_sum(vc)
    stv = window_sum(tc * vc)
    den = s0 * s2 - s1 * s1
    return (s0 * stv - s1 * sv) / den


def forward_speed(
    run: RunData,
    times: ArrayLike,
    window: float = 0.8,
    heading_window: float = 3.0,
) -> FloatArray:
    """Forward speed (m/s) along the heading, from the total-station positions.

    The velocity (m/s) of ``pos_x`` and ``pos_y`` (each from its own samples) is the slope of a
    local least-squares line over ``window`` s (default 0.8 s: 4 samples at 5 Hz) centred on
    each requested time; irregular sampling is handled, and at least 3 samples are always used.
    It is projected on the heading: the ``yaw`` column (rad, from +x towards +y) when the run has
    it, otherwise the direction of travel over the wider ``heading_window`` (s) (the rover is
    assumed to drive forwards; at standstill the last known direction is kept).

    Args:
        run: the run.
        times: requested times (s).
        window: differentiation window (s), > 0.
        heading_window: window (s) for the direction of travel when there is no yaw.

    Raises:
        InputError: fewer than 2 position samples.
    """
    if not (window > 0 and heading_window > 0):
        raise ValueError("window and heading_window must be > 0 s")
    t = _as_times(times)
    tx, x = run.samples("pos_x")
    ty, y = run.samples("pos_y")
    for name, ts in (("pos_x", tx), ("pos_y", ty)):
        if len(ts) < 2:
            raise InputError(f"need at least 2 samples of {name!r} to differentiate", run.path, None, name)
    vx = _local_slope(tx, x, t, window)
    vy = _local_slope(ty, y, t, window)
    if run.has("yaw"):
        yaw = aligned(run, "yaw", t)["yaw"]
        return vx * np.cos(yaw) + vy * np.sin(yaw)
    ux = _local_slope(tx, x, t, heading_window)
    uy = _local_slope(ty, y, t, heading_window)
    norm = np.hypot(ux, uy)
    moving = norm > 1e-3
    if not moving.any():
        return vx  # never moves: any direction gives noise around zero
    src = _nearest_true(t, moving)
    return vx * ux[src] / norm[src] + vy * uy[src] / norm[src]


def _nearest_true(t: FloatArray, mask: NDArray[np.bool_]) -> NDArray[np.intp]:
    """For each t[i]: i if mask[i], else the index of the nearest-in-time t[j] with mask[j]."""
    idx = np.flatnonzero(mask)
    order = np.argsort(t[idx], kind="stable")
    mt, mi = t[idx][order], idx[order]
    if len(mt) == 1:
        src = np.full(len(t), mi[0])
    else:
        j = np.clip(np.searchsorted(mt, t), 1, len(mt) - 1)
        left = (t - mt[j - 1]) <= (mt[j] - t)
        src = np.where(left, mi[j - 1], mi[j])
    return np.where(mask, np.arange(len(t)), src)


# --------------------------------------------------------------------------------------------
# Writing
# --------------------------------------------------------------------------------------------

_BAD_NAME_CHARS = re.compile(r"[,\"\r\n]")


def format_run_csv(columns: Mapping[str, ArrayLike]) -> str:
    """CSV text of a run: ``time`` first, then the other columns in the given order.

    Numbers are written in the shortest decimal that reads back to the same double (exact
    round trip); NaN becomes an empty cell.

    Raises:
        ValueError: no ``time``, unequal lengths, infinite values, bad column names.
    """
    if "time" not in columns:
        raise ValueError("a run needs a 'time' column")
    names = ["time"] + [c for c in columns if c != "time"]
    arrays = []
    for name in names:
        if not isinstance(name, str) or not name or name != name.strip() or _BAD_NAME_CHARS.search(name):
            raise ValueError(f"bad column name {name!r}")
        a = np.asarray(columns[name], dtype=float).reshape(-1)
        if np.any(np.isinf(a)):
            raise ValueError(f"column {name!r} holds infinite values")
        arrays.append(a)
    n = len(arrays[0])
    for name, a in zip(names, arrays):
        if len(a) != n:
            raise ValueError(f"column {name!r} has {len(a)} values, 'time' has {n}")
    r = float.__repr__
    cols = [["" if v != v else r(v) for v in a.tolist()] for a in arrays]
    body = "".join(",".join(cells) + "\n" for cells in zip(*cols))
    return ",".join(names) + "\n" + body


def format_rig_csv(columns: Mapping[str, ArrayLike]) -> str:
    """CSV text of a wheel_rig table, columns in the given order (shortest round-trip decimals;
    NaN becomes an empty cell).

    Raises:
        ValueError: unequal lengths, infinite values, bad column names.
    """
    names = list(columns)
    arrays = []
    for name in names:
        if not isinstance(name, str) or not name or name != name.strip() or _BAD_NAME_CHARS.search(name):
            raise ValueError(f"bad column name {name!r}")
        a = np.asarray(columns[name], dtype=float).reshape(-1)
        if np.any(np.isinf(a)):
            raise ValueError(f"column {name!r} holds infinite values")
        arrays.append(a)
    if not arrays or any(len(a) != len(arrays[0]) for a in arrays):
        raise ValueError("a wheel_rig table needs columns of equal length")
    r = float.__repr__
    cols = [["" if v != v else r(v) for v in a.tolist()] for a in arrays]
    return ",".join(names) + "\n" + "".join(",".join(cells) + "\n" for cells in zip(*cols))


def _safe_relpath(value: str, what: str) -> str:
    rel = PurePosixPath(value)
    if not value or rel.is_absolute() or ".." in rel.parts or "\\" in value:
        raise ValueError(f"{what}: {value!r} must be a relative path inside the campaign folder")
    return str(rel)


def _json_default(o: Any) -> Any:
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, tuple):
        return list(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def write_campaign(
    root: PathLike,
    campaign: Mapping[str, Any],
    runs: Mapping[str, Mapping[str, ArrayLike]],
    terrains: Optional[Mapping[str, ArrayLike]] = None,
    extra_files: Optional[Mapping[str, Union[str, bytes]]] = None,
    overwrite: bool = False,
) -> Campaign:
    """Write a whole campaign folder atomically and return it loaded.

    Args:
        root: the campaign folder to create (see :func:`juno.atomic.atomic_directory`: an
            existing non-empty folder is refused unless ``overwrite``).
        campaign: the manifest as a dict (``name``, ``runs`` [{id, kind, ...}], ``rover``...).
            A run without ``file`` gets ``runs/<id>.csv``. A terrain run's ``terrain`` may
            name a key of ``terrains``. The dict is not modified.
        runs: run id -> {column name -> 1-D array}; NaN = empty cell; ``time`` required
            (a wheel_rig run: its table's columns, :func:`format_rig_csv`).
        terrains: terrain name -> (N, 3) points (m). A name with a '/' is used as the path
            inside the folder; otherwise the file is ``terrain/<name>`` (``.xyz`` added if the
            name has no suffix).
        extra_files: relative path -> text or bytes, written in the same atomic step
            (e.g. ``{"truth.json": ...}``).
        overwrite: replace an existing non-empty folder (only once everything is written).

    The written folder is loaded and every run and terrain read back before it is renamed into
    place, so an invalid campaign is never left behind (ValueError instead). Numbers are
    written exactly (shortest round-trip decimal).
    """
    manifest = copy.deepcopy(dict(campaign))
    entries = manifest.get("runs")
    if not isinstance(entries, list) or not all(isinstance(e, dict) and "id" in e for e in entries):
        raise ValueError("campaign['runs'] must be a list of run objects with an 'id'")
    terrains = dict(terrains or {})
    terrain_files = {}
    for name in terrains:
        if "/" in name:
            rel = name
        else:
            rel = f"terrain/{name}" + ("" if PurePosixPath(name).suffix else ".xyz")
        terrain_files[name] = _safe_relpath(rel, f"terrain {name!r}")
    ids = [e["id"] for e in entries]
    if sorted(map(str, ids)) != sorted(map(str, runs)) or len(set(ids)) != len(ids):
        raise ValueError(f"manifest run ids {ids} and data for runs {list(runs)} must match one to one")
    written: dict[str, str] = {}
    for e in entries:
        e.setdefault("file", f"runs/{e['id']}.csv")
        e["file"] = _safe_relpath(e["file"], f"run {e['id']!r} file")
        if isinstance(e.get("terrain"), str) and e["terrain"] in terrain_files:
            e["terrain"] = terrain_files[e["terrain"]]
        if "steady_window" in e:
            e["steady_window"] = [float(v) for v in e["steady_window"]]
        fmt = format_rig_csv if e.get("kind") == "wheel_rig" else format_run_csv
        written[e["file"]] = fmt(runs[e["id"]])
    for name, rel in terrain_files.items():
        written[rel] = "# x y z (m)\n" + format_xyz(terrains[name])
    extras: dict[str, bytes] = {}
    for rel, content in (extra_files or {}).items():
        rel = _safe_relpath(rel, "extra file")
        if rel == MANIFEST_NAME or rel in written:
            raise ValueError(f"extra file {rel!r} would overwrite a campaign file")
        extras[rel] = content.encode("utf-8") if isinstance(content, str) else bytes(content)
    manifest_text = json.dumps(manifest, indent=2, allow_nan=False, default=_json_default) + "\n"

    with atomic_directory(root, overwrite=overwrite) as tmp:
        files = {MANIFEST_NAME: manifest_text.encode("utf-8")}
        files.update({rel: text.encode("utf-8") for rel, text in written.items()})
        files.update(extras)
        for rel, data in files.items():
            target = tmp / rel
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_bytes(data)
        try:
            check = load_campaign(tmp)
            for spec in check.runs:
                read_any(check, spec)
                if spec.terrain is not None:
                    read_xyz(tmp / spec.terrain)
        except InputError as e:
            raise ValueError(f"write_campaign: the data would make an invalid campaign: {e}") from None
    return load_campaign(root)
