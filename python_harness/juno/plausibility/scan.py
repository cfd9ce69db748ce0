"""Checks of a terrain run's scan against the path the rover drove.

The scan (terrain runs): gross outliers are found by :func:`juno.pointcloud.gross_outliers`
(a warning naming them: the gridding drops them), and the measured path, widened by the wheel
footprint, must lie on the gridded scan (:func:`path_off_scan`): off it for more than
``OFF_SCAN_ERROR`` (10 %) of the run's position samples is an error (the replay would be
compared with the measurements over unmeasured ground for a significant part of the run), a
briefer excursion a warning; both name the run and the time spans.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ..campaign import Campaign, RunData, RunSpec, aligned, read_terrain_points
from ..pointcloud import GRID_MARGIN, gross_outliers
from .findings import FloatArray, Finding, _format_spans, _g, _own, _spans
from .limits import RoverLimits

#: Path off the scan for more than this fraction of the run's position samples: an error.
OFF_SCAN_ERROR = 0.10


def footprint_offsets(limits: RoverLimits) -> FloatArray:
    """Outline of the wheel footprint in the rover frame (m): (8, 2), x ahead, y left.

    A rectangle ``half_length`` ahead and behind the chassis reference point (the wheels'
    radius beyond the axles) and ``half_width`` to either side (beyond the wheels' outer
    edges): its corners and the midpoints of its sides.
    """
    a, b = limits.half_length, limits.half_width
    return np.array([[a, b], [a, 0.0], [a, -b], [0.0, -b], [-a, -b], [-a, 0.0], [-a, b], [0.0, b]])


def path_off_scan(run: RunData, points: FloatArray, limits: RoverLimits) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Which position samples put part of the wheel footprint off the scan.

    The footprint (:func:`footprint_offsets`) is placed at each position sample, turned by the
    measured yaw (without a yaw column it is turned to every heading: a disc of its
    half-diagonal, sampled at 16 headings). A footprint point is on the gridded scan when a scan
    point lies within ``GRID_MARGIN`` (1 m) of it: the gridding extends the scan by that margin
    with its nearest edge height, so that wheels may hang over an edge of the scan; farther from
    every scan point (beyond the grid, where the simulation clamps the edge height, or in a hole
    of the scan wider than twice the margin) the ground under the wheel is not measured at all.
    (Closer to the edge the synthetic campaigns' wheels do leave the scanned area for the last
    seconds of a full-length run: their scan ends 0.7 m ahead of where the rover stops.)

    Returns:
        (times of the position samples (s), True where part of the footprint is off the scan).
    """
    from scipy.spatial import cKDTree

    t, x, _ = _own(run, "pos_x")
    y = aligned(run, "pos_y", t)["pos_y"]
    tree = cKDTree(points[:, :2])
    if run.has("yaw"):
        yaw = aligned(run, "yaw", t)["yaw"]
        off = footprint_offsets(limits)
        c, s = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
        px = x[:, None] + c * off[None, :, 0] - s * off[None, :, 1]
        py = y[:, None] + s * off[None, :, 0] + c * off[None, :, 1]
    else:
        radius = math.hypot(limits.half_length, limits.half_width)
        ang = np.linspace(0.0, 2 * np.pi, 16, endpoint=False)
        px = x[:, None] + radius * np.cos(ang)[None, :]
        py = y[:, None] + radius * np.sin(ang)[None, :]
    dist, _ = tree.query(np.column_stack([px.ravel(), py.ravel()]), distance_upper_bound=2 * GRID_MARGIN)
    off_scan = (dist > GRID_MARGIN).reshape(px.shape).any(axis=1)
    return t, off_scan


def check_scan(campaign: Campaign, spec: RunSpec, run: RunData, limits: RoverLimits) -> list[Finding]:
    """Gross outliers of a terrain run's scan (warning: dropped before gridding) and the path's
    coverage: an error when the footprint is off the scan for more than OFF_SCAN_ERROR of the
    run's position samples, a warning for a briefer excursion."""
    points = read_terrain_points(campaign, spec)
    scan_file = str(spec.terrain)
    out = []
    bad = gross_outliers(points)
    if bad.any():
        idx = np.flatnonzero(bad)
        shown = "; ".join(f"no. {int(i) + 1} ({_g(points[i, 0])}, {_g(points[i, 1])}, {_g(points[i, 2])})"
                          for i in idx[:5]) + (f"; and {idx.size - 5} more" if idx.size > 5 else "")
        axes = "".join(a for a, on in zip("xyz", _outlier_axes(points, bad)) if on) or "z"
        out.append(Finding("warning", scan_file, axes, f"{idx.size} of {len(points)} scan points are gross outliers "
                           f"and are dropped before gridding: {shown} (x, y, z in m)"))
        points = points[~bad]
    if not (run.has("pos_x") and run.has("pos_y")):
        return out
    t, off = path_off_scan(run, points, limits)
    if off.any():
        spans = _spans(t, off)
        share = float(np.mean(off))
        severity = "error" if share > OFF_SCAN_ERROR else "warning"
        hint = _off_scan_hint(run, points, limits) if severity == "error" else ""
        out.append(Finding(severity, spec.file, "pos_x", f"run {spec.id!r}: the rover's wheel footprint leaves the "
                           f"scan {scan_file} during {_format_spans(spans)} ({share:.0%} of the position samples; "
                           f"more than {OFF_SCAN_ERROR:.0%} is an error): the terrain there is not measured{hint}"))
    return out


#: Length units a scan may be written in by mistake, with the factor to metres.
SCAN_UNITS = (("millimetres", 1e-3), ("centimetres", 1e-2), ("feet", 0.3048))


def _off_scan_hint(run: RunData, points: FloatArray, limits: RoverLimits) -> str:
    """Why a path lies mostly off its scan: the scan in another length unit (the path lies on
    the scan once it is converted to metres), or else the two extents, to compare frames."""
    for unit, to_m in SCAN_UNITS:
        _, off = path_off_scan(run, points * to_m, limits)
        if np.mean(off) <= OFF_SCAN_ERROR:
            return (f"; the scan looks like it is in {unit}: converted to metres, the path lies on it "
                    "(the format's lengths are in m)")
    _, x, _ = _own(run, "pos_x")
    _, y, _ = _own(run, "pos_y")
    lo, hi = points[:, :2].min(axis=0), points[:, :2].max(axis=0)
    return (f"; the scan spans x {lo[0]:.2f} to {hi[0]:.2f} m, y {lo[1]:.2f} to {hi[1]:.2f} m, the path x "
            f"{np.nanmin(x):.2f} to {np.nanmax(x):.2f} m, y {np.nanmin(y):.2f} to {np.nanmax(y):.2f} m: are both in "
            "the same world frame?")


def _outlier_axes(points: FloatArray, bad: NDArray[np.bool_]) -> tuple[bool, bool, bool]:
    """Which coordinates make the dropped points odd: far beyond the others' range."""
    good = points[~bad]
    lo, hi = good.min(axis=0), good.max(axis=0)
    far = (points[bad] < lo - (hi - lo)) | (points[bad] > hi + (hi - lo))
    return tuple(bool(v) for v in far.any(axis=0))  # type: ignore[return-value]
