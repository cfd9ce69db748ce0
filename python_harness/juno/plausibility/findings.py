"""What a plausibility check reports: a :class:`Finding` (file, column, evidence), the error
that stops a command, and the helpers that put a column's evidence into words (its own samples,
where a value is, spans of time)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..campaign import RunData
from ..errors import InputError

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Finding:
    """One implausibility of the measured data.

    Attributes:
        severity: "error" (no rover could have produced it) or "warning" (may be legitimate).
        file: the file, relative to the campaign folder (``runs/dbp1.csv``).
        column: the column (``pitch``), or the coordinate of a scan (``z``).
        message: what is wrong and the evidence, with units.
    """

    severity: str
    file: str
    column: str
    message: str

    def __str__(self) -> str:
        return f"{self.file}, column '{self.column}': {self.message}"


class PlausibilityError(InputError):
    """The measured data hold errors (every error finding is in the message)."""


def _g(x: float) -> str:
    """A number for a message: 4 significant digits, plain float."""
    return f"{float(x):.4g}"


def _time(t: float) -> str:
    """A time for a message, to the millisecond the loggers write: a clock that reads Unix time
    (1.7e9 s) still tells one row from another, which four significant digits would not."""
    text = f"{float(t):.3f}".rstrip("0").rstrip(".")
    return "0" if text in ("", "-0") else text


def _own(run: RunData, name: str) -> tuple[FloatArray, FloatArray, NDArray[np.int64]]:
    """(times, values, file lines) of a column's own samples."""
    v = run.columns[name]
    ok = ~np.isnan(v)
    lines = run.lines if run.lines is not None else np.arange(len(v)) + 2
    return run.time[ok], v[ok], np.asarray(lines)[ok]


def _largest(run: RunData, name: str) -> tuple[float, str, FloatArray, NDArray[np.int64], int]:
    """The largest |value| of a column's own samples, where it is ("line L (t = T s)"), the
    values, their file lines and its index."""
    ts, vs, lines = _own(run, name)
    i = int(np.argmax(np.abs(vs)))
    return abs(float(vs[i])), f"line {int(lines[i])} (t = {_time(ts[i])} s)", vs, lines, i


def _at(ts: FloatArray, vs: FloatArray, lines: NDArray[np.int64], i: int) -> str:
    return f"{_g(vs[i])} at line {int(lines[i])} (t = {_time(ts[i])} s)"


def _spans(t: FloatArray, mask: NDArray[np.bool_]) -> list[tuple[float, float]]:
    """(start, end) times of the runs of consecutive True in mask."""
    out = []
    idx = np.flatnonzero(mask)
    if idx.size == 0:
        return out
    breaks = np.flatnonzero(np.diff(idx) > 1)
    starts = np.concatenate([[idx[0]], idx[breaks + 1]])
    ends = np.concatenate([idx[breaks], [idx[-1]]])
    return [(float(t[a]), float(t[b])) for a, b in zip(starts, ends)]


def _format_spans(spans: list[tuple[float, float]], limit: int = 4) -> str:
    """Time spans (s) as text, at most ``limit`` of them; a span of one sample as its time."""
    text = ", ".join(f"{_time(a)}-{_time(b)} s" if _time(a) != _time(b) else f"{_time(a)} s (one sample)"
                     for a, b in spans[:limit])
    return text + (f" and {len(spans) - limit} more" if len(spans) > limit else "")
