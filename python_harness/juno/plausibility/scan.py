"""Checks of a terrain run's scan against the path the rover drove.

The scan (terrain runs): gross outliers are found by :func:`juno.pointcloud.gross_outliers`
(a warning naming them: the gridding drops them), and the measured path, widened by the wheel
footprint, must lie on the gridded scan (:func:`path_off_scan`): off it for more than
``OFF_SCAN_ERROR`` (10 %) of the run's position samples is an error (the replay would be
compared with the measurements over unmeasured ground for a significant part of the run), a
briefer excursion a warning; both name the run and the time spans.

The heights (terrain runs with pos_z): the chassis reference point rides ``wheel.radius +
rover.pivotHeight`` above the ground its wheels rest on, less their sinkage (:mod:`.limits`,
"Ride height"). :func:`ground_under_wheels` gives that ground from the scan at each position
sample, and two errors follow from it:

* **z reversed.** Where the ground under the wheels varies (its standard deviation over the
  path at least ``GROUND_VARIES`` (2) times the noise of pos_z), the measured height follows it
  (synthetic runs, misregistered scans included, correlate at 0.85-0.999). A correlation below
  ``REVERSED_CORRELATION`` (-0.5) is a z axis pointing down in pos_z or in the scan (they then
  correlate at -0.85 to -0.999).
* **Height datum.** The chassis reference point's median height above that ground must lie
  between ``rover.pivotHeight`` (the wheels sunk to their axles) and ``DATUM_LIMIT`` times the
  centre of gravity's height, the band drawbar runs are held to on flat ground (:mod:`.sensors`,
  "Ground datum"): outside it, pos_z and the scan are measured from different height datums, or
  one of them is not in metres.
"""

from __future__ import annotations

import math
from typing import Optional

import numpy as np
from numpy.typing import NDArray

from ..campaign import Campaign, RunData, RunSpec, aligned, read_terrain_points
from ..pointcloud import GRID_MARGIN, gross_outliers
from .findings import FloatArray, Finding, _format_spans, _g, _own, _spans
from .limits import RoverLimits

#: Path off the scan for more than this fraction of the run's position samples: an error.
OFF_SCAN_ERROR = 0.10
#: The heights (module docstring): the scan's heights nearest a wheel's hub that give the ground
#: under it (their median), the ground's variation over the path (in units of the noise of
#: pos_z) above which the measured heights must follow it, and the correlation below which they
#: run against it; the fewest position samples the test is made on.
GROUND_POINTS = 8
GROUND_VARIES = 2.0
REVERSED_CORRELATION = -0.5
HEIGHT_SAMPLES = 10


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
    if np.mean(off) <= OFF_SCAN_ERROR:
        out += check_heights(run, points, limits, spec.file, scan_file)
    if off.any():
        spans = _spans(t, off)
        share = float(np.mean(off))
        severity = "error" if share > OFF_SCAN_ERROR else "warning"
        hint = _off_scan_hint(run, points, limits) if severity == "error" else ""
        out.append(Finding(severity, spec.file, "pos_x", f"run {spec.id!r}: the rover's wheel footprint leaves the "
                           f"scan {scan_file} during {_format_spans(spans)} ({share:.0%} of the position samples; "
                           f"more than {OFF_SCAN_ERROR:.0%} is an error): the terrain there is not measured{hint}"))
    return out


def ground_under_wheels(run: RunData, points: FloatArray, limits: RoverLimits
                        ) -> Optional[tuple[FloatArray, FloatArray, FloatArray]]:
    """The scan's ground under the rover's wheels at each position sample of a run: (times (s),
    measured pos_z (m), mean ground height under the four hubs (m)), for the samples whose every
    hub has a scan point within ``GRID_MARGIN``; None without pos_z.

    The hubs lie half the wheelbase ahead and behind the chassis reference point along the
    heading (the measured yaw, else the direction of the track: juno.heading) and half the track
    to either side; the ground under a hub is the median height of the ``GROUND_POINTS`` scan
    points nearest it.
    """
    from scipy.spatial import cKDTree

    from ..heading import track_headings

    if not run.has("pos_z"):
        return None
    t, x, _ = _own(run, "pos_x")
    at = aligned(run, ["pos_y", "pos_z"], t)
    y, z = at["pos_y"], at["pos_z"]
    heading = aligned(run, "yaw", t)["yaw"] if run.has("yaw") else track_headings(t, x, y)
    c, s = np.cos(heading)[:, None], np.sin(heading)[:, None]
    fore = 0.5 * limits.wheelbase * np.array([1.0, -1.0, 1.0, -1.0])
    side = 0.5 * limits.track * np.array([1.0, 1.0, -1.0, -1.0])
    hx, hy = x[:, None] + c * fore - s * side, y[:, None] + s * fore + c * side
    k = min(GROUND_POINTS, len(points))
    dist, idx = cKDTree(points[:, :2]).query(np.column_stack([hx.ravel(), hy.ravel()]), k=k)
    dist, idx = dist.reshape(len(t), 4, k), idx.reshape(len(t), 4, k)
    ground = np.median(points[idx, 2], axis=2).mean(axis=1)
    on_scan = np.all(dist[:, :, 0] <= GRID_MARGIN, axis=1) & np.isfinite(z)
    return t[on_scan], z[on_scan], ground[on_scan]


def check_heights(run: RunData, points: FloatArray, limits: RoverLimits, file: str, scan_file: str
                  ) -> list[Finding]:
    """pos_z against the scan's ground under the wheels (module docstring, "z reversed" and
    "Height datum")."""
    from ..sensor_noise import column_noise
    from .sensors import DATUM_LIMIT

    found = ground_under_wheels(run, points, limits)
    if found is None or len(found[0]) < HEIGHT_SAMPLES:
        return []
    t, z, ground = found
    noise = column_noise(*_own(run, "pos_z")[:2])
    spread = float(np.std(ground))
    if spread > 0 and spread >= GROUND_VARIES * noise and np.std(z) > 0:
        r = float(np.corrcoef(z, ground)[0, 1])
        if r < REVERSED_CORRELATION:
            return [Finding("error", file, "pos_z", f"pos_z falls where the ground under the wheels in {scan_file} "
                            f"rises (correlation {r:.2f} over {len(t)} position samples, where that ground varies "
                            f"by {_g(spread)} m, 1 sigma): the rover rides on the ground, so z points down in pos_z "
                            "or in the scan (the format's z is up)")]
    height = float(np.median(z - ground))
    top = DATUM_LIMIT * limits.cg_height
    if limits.pivot_height <= height <= top:
        return []
    where = "below" if height < limits.pivot_height else "above"
    return [Finding("error", file, "pos_z", f"the chassis reference point is typically (median over {len(t)} position "
                    f"samples) {_g(height)} m above the ground under its wheels in {scan_file}, where it rides about "
                    f"wheel.radius + rover.pivotHeight = {_g(limits.ride_height)} m and stays between "
                    f"{_g(limits.pivot_height)} m (the wheels sunk to their axles) and {_g(top)} m ({DATUM_LIMIT:g} "
                    f"times its centre of gravity's height); {where} that, pos_z and the scan's heights are measured "
                    "from different datums (a total station's, a map's), or one is not in metres or has z pointing "
                    "down: give both in one frame, z up, in metres")]


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
