"""Signals of a run whose sensors sample at different rates: columns resampled onto common times
(:func:`aligned`), steady averages (:func:`steady_average`) and the forward speed from the
total-station positions (:func:`forward_speed`)."""

from __future__ import annotations

from typing import Sequence, Union

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import InputError
from .records import ANGLE_COLUMNS, AlignedColumns, FloatArray, RunData

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
    direction = travel_direction(tx, x, ty, y, t, heading_window)
    if direction is None:
        return vx  # never moves: any direction gives noise around zero
    return vx * direction[0] + vy * direction[1]


def travel_direction(tx: FloatArray, x: FloatArray, ty: FloatArray, y: FloatArray, t: FloatArray,
                     window: float) -> tuple[FloatArray, FloatArray] | None:
    """The unit vector of the direction of travel at times ``t`` (s) of a track (``x`` at ``tx``,
    ``y`` at ``ty``; m): the local least-squares velocity over ``window`` s; where the rover moves
    slower than 1 mm/s, the direction at the nearest time it moved.  None if it never moves."""
    ux = _local_slope(tx, x, t, window)
    uy = _local_slope(ty, y, t, window)
    norm = np.hypot(ux, uy)
    moving = norm > 1e-3
    if not moving.any():
        return None
    src = _nearest_true(t, moving)
    return ux[src] / norm[src], uy[src] / norm[src]


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
