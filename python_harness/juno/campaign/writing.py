"""Writing a campaign: CSV text of a run or a testbed table with exact decimals, and a whole
campaign folder written atomically and read back before it is put in place
(:func:`write_campaign`)."""

from __future__ import annotations

import copy
import json
import re
from pathlib import PurePosixPath
from typing import Any, Mapping, Optional, Union

import numpy as np
from numpy.typing import ArrayLike

from ..atomic import atomic_directory
from ..errors import InputError
from ..pointcloud import format_xyz, read_xyz
from .manifest import load_campaign
from .records import MANIFEST_NAME, Campaign, PathLike
from .tables import read_any

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
    arrays = _checked_columns(columns, names)
    n = len(arrays[0])
    for name, a in zip(names, arrays):
        if len(a) != n:
            raise ValueError(f"column {name!r} has {len(a)} values, 'time' has {n}")
    return _csv_text(names, arrays)


def format_rig_csv(columns: Mapping[str, ArrayLike]) -> str:
    """CSV text of a wheel_rig table, columns in the given order (shortest round-trip decimals;
    NaN becomes an empty cell).

    Raises:
        ValueError: unequal lengths, infinite values, bad column names.
    """
    names = list(columns)
    arrays = _checked_columns(columns, names)
    if not arrays or any(len(a) != len(arrays[0]) for a in arrays):
        raise ValueError("a wheel_rig table needs columns of equal length")
    return _csv_text(names, arrays)


def _checked_columns(columns: Mapping[str, ArrayLike], names: list[str]) -> list[np.ndarray]:
    """The ``names`` columns as 1-D float arrays; a name a CSV header cannot hold as it is (empty,
    padded, with a comma, a quote or a line break) or an infinite value is a ValueError."""
    arrays = []
    for name in names:
        if not isinstance(name, str) or not name or name != name.strip() or _BAD_NAME_CHARS.search(name):
            raise ValueError(f"bad column name {name!r}")
        a = np.asarray(columns[name], dtype=float).reshape(-1)
        if np.any(np.isinf(a)):
            raise ValueError(f"column {name!r} holds infinite values")
        arrays.append(a)
    return arrays


def _csv_text(names: list[str], arrays: list[np.ndarray]) -> str:
    """The header and rows of equal-length columns, each number the shortest decimal that reads
    back to the same double, NaN an empty cell."""
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
