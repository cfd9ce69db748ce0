"""Reading and checking a campaign's manifest, ``campaign.json`` (:func:`load_campaign`): strict
JSON (no duplicate keys, no NaN), each run's keys, and the files it names inside the folder."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path, PurePosixPath
from typing import Any, Optional, Union

from ..errors import InputError, decode_input_text, read_input_bytes
from .records import (_ID_RE, COLUMN_UNITS, DEFAULT_IMU_MOUNT, KINDS, MANIFEST_NAME, NOISE_COLUMNS, RIG_WHEEL_KEYS,
                      Campaign, PathLike, RigSetup, RunSpec)

#: How a manifest may say the IMU's mounting is known (Campaign.imu_mounting).
IMU_MOUNTINGS = ("free", "calibrated")


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
        link = ""
        if ".." not in rel.parts:
            # Inside by its path, outside once resolved: a symbolic link on the way leads out.
            link = (f" (a symbolic link to {resolved}); the harness keeps its outputs off the campaign folder and "
                    "everything in it, so a file it reads must lie inside: copy the file into the folder")
        raise InputError(f"{where} {value!r} points outside the campaign folder {root}{link}", manifest, line)
    if not resolved.exists():
        raise InputError(f"{where}: file not found: {full}", manifest, line)
    if not resolved.is_file():
        raise InputError(f"{where}: not a regular file: {full}", manifest, line)
    return value


def _parse_sensor_noise(manifest: Path, value: Any, label: str, line: Optional[int]) -> dict[str, float]:
    """A ``sensor_noise`` object (of the run ``label`` names, "" for the campaign's): measured
    column -> its sensor noise, 1 sigma in the column's units, a finite number > 0."""
    if not isinstance(value, dict):
        raise InputError(f"{label}'sensor_noise' must be an object of measured columns and their sensor noise "
                         f"(1 sigma, in the column's units), e.g. {{\"torque_left\": 3.2}}; got {json.dumps(value)}",
                         manifest, line)
    out: dict[str, float] = {}
    for column, sigma in value.items():
        if column not in NOISE_COLUMNS:
            raise InputError(f"{label}'sensor_noise' has no column {column!r}: a sensor noise is stated for a "
                             f"measured column of the run CSVs ({', '.join(NOISE_COLUMNS)})", manifest, line)
        f = _finite_number(sigma)
        if f is None or f <= 0:
            raise InputError(f"{label}'sensor_noise.{column}' must be a finite number > 0 (1 sigma, in "
                             f"{COLUMN_UNITS[column]}), got {json.dumps(sigma)}", manifest, line)
        out[column] = f
    return out


def _parse_run(root: Path, manifest: Path, text: str, i: int, entry: Any, seen: dict[str, int],
               campaign_noise: dict[str, float]) -> RunSpec:
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
    noise: dict[str, float] = {}
    if kind == "wheel_rig":
        if "sensor_noise" in entry:
            raise InputError(f"{label}: a wheel_rig table takes no 'sensor_noise': give each value's standard "
                             "deviation in its column's '_std' column", manifest, line)
    else:
        noise = {**campaign_noise, **_parse_sensor_noise(manifest, entry.get("sensor_noise", {}), f"{label}: ", line)}
    mount = DEFAULT_IMU_MOUNT
    if "imu_mount" in entry:
        mount = entry["imu_mount"]
        if kind == "wheel_rig":
            raise InputError(f"{label}: a wheel_rig table has no IMU and takes no 'imu_mount'", manifest, line)
        if not isinstance(mount, str) or _ID_RE.fullmatch(mount) is None:
            raise InputError(f"{label}: 'imu_mount' must name the IMU's mounting in the run, a non-empty string of "
                             f"letters, digits, '_', '.', '-' (runs naming the same one share its pitch offset), "
                             f"got {mount!r}", manifest, line)
    known = ("id", "kind", "file", "steady_window", "terrain", "wheel", "carriage_speed", "sensor_noise", "imu_mount")
    extra = {k: v for k, v in entry.items() if k not in known}
    return RunSpec(id=run_id, kind=kind, file=file, steady_window=window, terrain=terrain, extra=extra, rig=rig,
                   sensor_noise=noise, imu_mount=mount)


def _check_one_file_per_run(root: Path, manifest: Path, text: str, specs: tuple[RunSpec, ...]) -> None:
    """Refuse two runs whose 'file' is the same file (however the paths are written): one measured
    run listed twice would count its held-out blocks twice in every paired test and weigh its
    soil twice in every fit, a confidence the data do not give."""
    owner: dict[Path, int] = {}
    for i, spec in enumerate(specs):
        path = (root / spec.file).resolve()
        if path in owner:
            first = specs[owner[path]]
            raise InputError(f"runs[{i}] (id {spec.id!r}): 'file' {spec.file!r} is the file of runs[{owner[path]}] "
                             f"(id {first.id!r}): each run needs its own measured data", manifest,
                             _line_of_run(text, spec.id))
        owner[path] = i


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
    ``rover`` maps names to finite numbers or strings; ``name`` is a string; ``sensor_noise``, of
    the campaign and of a drawbar or terrain run, maps measured columns to finite numbers > 0;
    ``imu_mounting`` is "free" (the default) or "calibrated".
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
    noise = _parse_sensor_noise(manifest, doc.get("sensor_noise", {}), "", None)
    mounting = doc.get("imu_mounting", "free")
    if mounting not in IMU_MOUNTINGS:
        raise InputError(f"'imu_mounting' must be one of {', '.join(map(repr, IMU_MOUNTINGS))} ('calibrated': the "
                         f"pitch is measured against a mounting calibrated on the rover), got {json.dumps(mounting)}",
                         manifest)
    seen: dict[str, int] = {}
    specs = tuple(_parse_run(root, manifest, text, i, entry, seen, noise) for i, entry in enumerate(runs))
    _check_one_file_per_run(root, manifest, text, specs)
    rover = _parse_rover(manifest, doc.get("rover", {}))
    extra = {k: v for k, v in doc.items() if k not in ("name", "runs", "rover", "sensor_noise", "imu_mounting")}
    return Campaign(root=root, name=name, runs=specs, rover=rover, extra=extra, sensor_noise=noise,
                    imu_mounting=mounting)
