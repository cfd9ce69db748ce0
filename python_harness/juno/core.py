"""Small services every part of the harness shares: progress messages and JSON output.

- :func:`progress_printer`: a ``say(message)`` function that prints elapsed seconds and the
  message to standard error (or nothing, when quiet).  Library functions take such a function
  as their ``progress`` argument and never print progress themselves.
- :func:`to_jsonable` and :func:`write_json`: every machine-readable result goes through them,
  so NumPy scalars are numbers, arrays are lists, dataclasses are objects and NaN/inf are null.
"""

from __future__ import annotations

import json
import sys
import time
from typing import Any, Callable

import numpy as np

from .atomic import atomic_write_text

__all__ = ["Progress", "progress_printer", "to_jsonable", "write_json"]

#: A progress reporter: called with one line of text.
Progress = Callable[[str], None]


def progress_printer(quiet: bool = False) -> Progress:
    """A reporter printing ``[elapsed s] message`` to standard error; silent when ``quiet``."""
    start = time.perf_counter()

    def say(message: str) -> None:
        if not quiet:
            print(f"[{time.perf_counter() - start:7.1f} s] {message}", file=sys.stderr, flush=True)
    return say


def to_jsonable(obj: Any) -> Any:
    """A JSON-safe copy of ``obj``: tuples and arrays as lists, NumPy scalars as numbers,
    NaN and infinities as null, dataclasses as objects of their fields."""
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (np.floating, float)):
        return float(obj) if np.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    if hasattr(obj, "__dataclass_fields__"):
        return to_jsonable({k: getattr(obj, k) for k in obj.__dataclass_fields__})
    return obj


def write_json(path: str | None, payload: Any, command: str = "") -> None:
    """Write ``payload`` (made JSON-safe) to ``path`` whole or not at all; nothing when ``path`` is None.
    A dict payload gets ``written_by`` ("juno VERSION COMMAND") first, which lets a later run
    replace the file and nothing else (:func:`juno.outputs.written_by_juno`)."""
    if path:
        data = to_jsonable(payload)
        if isinstance(data, dict):
            from . import __version__
            from .outputs import WRITTEN_BY

            data = {WRITTEN_BY: " ".join(filter(None, ("juno", __version__, command))), **data}
        atomic_write_text(path, json.dumps(data, indent=2) + "\n")
