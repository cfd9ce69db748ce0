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
from typing import Any, Optional

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
#: The axes check (:func:`scan_slope`): the fewest points of a cell that has a normal, and the
#: fewest such cells of a scan that has a typical slope.
SLOPE_POINTS = 4
SLOPE_CELLS = 10


def footprint_offsets(limits: RoverLimits) -> FloatArray:
    """Outline of the wheel footprint in the rover frame (m): (8, 2), x ahead, y left.

    A rectangle ``half_length`` ahead and behind the chassis reference point (the wheels'
    radius beyond the axles) and ``half_width`` to either side (beyond the wheels' outer
    edges): its corners and the midpoints of its sides.
    """
    a, b = limits.half_length, limits.half_width
    return np.array([[a, b], [a, 0.0], [a, -b], [0.0, -b], [-a, -b], [-a, 0.0], [-a, b], [0.0, b]])


def xy_tree(points: FloatArray) -> Any:
    """The search tree of a scan's points in x-y (scipy's cKDTree), which every check of a run
    against its scan queries: built once for them all."""
    from scipy.spatial import cKDTree
    return cKDTree(points[:, :2])


def path_off_scan(run: RunData, points: FloatArray, limits: RoverLimits, tree: Any = None
                  ) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Which position samples put part of the wheel footprint off the scan (``tree``: the
    points' x-y search tree, :func:`xy_tree`, built here when not given).

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
    t, x, _ = _own(run, "pos_x")
    y = aligned(run, "pos_y", t)["pos_y"]
    tree = tree if tree is not None else xy_tree(points)
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


def scan_slope(points: FloatArray, cell: float) -> float:
    """The typical slope (rad) of a scan's surface: the median, over square cells of ``cell`` m
    in x-y, of the angle between the vertical and the normal of the cell's points (the direction
    in which they spread least: their smallest principal axis). NaN when fewer than
    ``SLOPE_CELLS`` cells hold a surface.

    A cell holds a surface when it has at least ``SLOPE_POINTS`` points that spread in two
    directions, the lesser at least half as far as across a cell filled evenly: points along one
    scan line, or all at one place, have no normal. The principal axes do not depend on how the
    surface lies, so a wall (a scan whose z and y are swapped) gives its horizontal normal as
    well as level ground its vertical one; noise of the same size in every direction leaves them
    unchanged.
    """
    pts = np.asarray(points, dtype=float)
    if len(pts) < SLOPE_POINTS:
        return math.nan
    local = pts - pts.mean(axis=0)
    ij = np.floor((local[:, :2] - local[:, :2].min(axis=0)) / cell).astype(np.int64)
    _, cell_of, counts = np.unique(ij[:, 0] * (int(ij[:, 1].max()) + 1) + ij[:, 1], return_inverse=True,
                                   return_counts=True)
    cell_of = cell_of.reshape(-1)
    m = len(counts)
    mean = np.column_stack([np.bincount(cell_of, weights=local[:, a], minlength=m) for a in range(3)]) / counts[:, None]
    d = local - mean[cell_of]
    cov = np.empty((m, 3, 3))
    for a in range(3):
        for b in range(a, 3):
            cov[:, a, b] = cov[:, b, a] = np.bincount(cell_of, weights=d[:, a] * d[:, b], minlength=m)
    cov /= counts[:, None, None]
    full = counts >= SLOPE_POINTS
    spread, axes = np.linalg.eigh(cov[full])
    surface = spread[:, 1] >= 0.25 * cell * cell / 12.0
    if int(surface.sum()) < SLOPE_CELLS:
        return math.nan
    return float(np.median(np.arccos(np.clip(np.abs(axes[surface, 2, 0]), 0.0, 1.0))))


def typical_slope(points: FloatArray, limits: RoverLimits) -> float:
    """:func:`scan_slope` over cells of a wheel's radius (the scale of the ground a wheel rests
    on), widened up to eight times where the scan is too sparse to hold enough such cells."""
    cell = limits.wheel_radius
    for _ in range(4):
        slope = scan_slope(points, cell)
        if not math.isnan(slope):
            return slope
        cell *= 2.0
    return math.nan


#: The scan's columns read another way round, for the axes check's hint.
SWAPPED_AXES = (("y and z", [0, 2, 1]), ("x and z", [2, 1, 0]))


def check_axes(points: FloatArray, limits: RoverLimits, scan_file: str) -> list[Finding]:
    """A scan whose surface typically slopes more steeply than the soil's friction angle is not
    ground that soil rests on (limits, "Slope"): its axes are read wrongly, the heights in
    another column (a wall, where a y-z swap puts the ground) or in another unit than x and y,
    named as such when reading them from another column, or in millimetres, centimetres or feet,
    gives a slope the soil holds."""
    slope = typical_slope(points, limits)
    if not slope > limits.friction_angle:
        return []
    readings = [(f"its axes look swapped, {which} exchanged (with them exchanged", points[:, order],
                 "write the columns x y z, z up") for which, order in SWAPPED_AXES]
    readings += [(f"its heights look like {unit} (read as {unit}", points * [1.0, 1.0, to_m],
                  "write every coordinate in metres") for unit, to_m in SCAN_UNITS]
    for said, other_points, fix in readings:
        other = typical_slope(other_points, limits)
        if other <= limits.friction_angle:
            hint = f": {said}, the ground slopes {math.degrees(other):.0f} deg): {fix}"
            break
    else:
        hint = ": are its columns x y z, z up, in metres?"
    lo, hi = points.min(axis=0), points.max(axis=0)
    return [Finding("error", scan_file, "z", f"the scan's ground typically slopes {math.degrees(slope):.0f} deg (the "
                    f"median over cells of a wheel's radius), steeper than the soil's friction angle soil.phi = "
                    f"{math.degrees(limits.friction_angle):.0f} deg, at which soil no longer rests; it spans x "
                    f"{lo[0]:.2f} to {hi[0]:.2f} m, y {lo[1]:.2f} to {hi[1]:.2f} m, z {lo[2]:.2f} to {hi[2]:.2f} m{hint}")]


def check_scan(campaign: Campaign, spec: RunSpec, run: RunData, limits: RoverLimits) -> list[Finding]:
    """A terrain run's scan: its axes (:func:`check_axes`; an error there is the only finding),
    its gross outliers (warning: dropped before gridding) and the path's coverage: an error when
    the footprint is off the scan for more than OFF_SCAN_ERROR of the run's position samples, a
    warning for a briefer excursion; then the heights (:func:`check_heights`) and the ground
    under the wheels (:func:`hubs_unmeasured`: an error for more than OFF_SCAN_ERROR of the
    samples, which the footprint's own excursions are then part of, else a warning)."""
    points = read_terrain_points(campaign, spec)
    scan_file = str(spec.terrain)
    axes = check_axes(points, limits, scan_file)
    if axes:
        return axes
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
    tree = xy_tree(points)
    t, off = path_off_scan(run, points, limits, tree)
    if np.mean(off) <= OFF_SCAN_ERROR:
        heights = check_heights(run, points, limits, spec.file, scan_file, tree)
        if any(f.file == scan_file for f in heights):
            # Something standing in the scan: the ground points around it stand out against its
            # points, so an outlier warning would name the same mistake; it is checked again
            # once those points are removed.
            return heights
        out += heights
        unmeasured = _check_unmeasured(run, points, limits, spec, off, tree)
        if any(f.severity == "error" for f in unmeasured):
            # The wheels off measured ground for much of the run: the footprint's brief
            # excursions beyond the scan's margin are part of the same gap.
            return out + unmeasured
        out += unmeasured
    if off.any():
        spans = _spans(t, off)
        share = float(np.mean(off))
        severity = "error" if share > OFF_SCAN_ERROR else "warning"
        hint = _off_scan_hint(run, points, limits) if severity == "error" else ""
        out.append(Finding(severity, spec.file, "pos_x", f"run {spec.id!r}: the rover's wheel footprint leaves the "
                           f"scan {scan_file} during {_format_spans(spans)} ({share:.0%} of the position samples; "
                           f"more than {OFF_SCAN_ERROR:.0%} is an error): the terrain there is not measured{hint}"))
    return out


def hub_positions(run: RunData, limits: RoverLimits) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(times of the position samples (s), x and y of the four wheel hubs (m), each (n, 4)): half
    the wheelbase ahead and behind the chassis reference point along the heading (the measured
    yaw, else the direction of the track: juno.heading) and half the track to either side."""
    from ..heading import track_headings

    t, x, _ = _own(run, "pos_x")
    y = aligned(run, "pos_y", t)["pos_y"]
    heading = aligned(run, "yaw", t)["yaw"] if run.has("yaw") else track_headings(t, x, y)
    c, s = np.cos(heading)[:, None], np.sin(heading)[:, None]
    fore = 0.5 * limits.wheelbase * np.array([1.0, -1.0, 1.0, -1.0])
    side = 0.5 * limits.track * np.array([1.0, 1.0, -1.0, -1.0])
    return t, x[:, None] + c * fore - s * side, y[:, None] + s * fore + c * side


def hubs_unmeasured(run: RunData, points: FloatArray, limits: RoverLimits, tree: Any = None
                    ) -> tuple[FloatArray, NDArray[np.bool_], FloatArray]:
    """Which position samples put a wheel on ground the scan did not measure but the gridding
    makes up: a hub inside the convex hull of the scan's points in x-y, where the gridding
    interpolates linearly between them, with no scan point within a wheel's radius of it, the
    farthest a wheel touches the ground from its hub (a hole in the scan, or a scan too sparse
    for the wheels). Beyond the hull the gridding extends the nearest edge's height, and how far
    the wheels may go there is :func:`path_off_scan`'s to judge. ``tree``: the points' x-y
    search tree (:func:`xy_tree`), built here when not given.

    Returns:
        (times of the position samples (s), True where such a hub is, the distance (m) from each
        sample's farthest such hub to its nearest scan point, 0 where there is none).
    """
    from scipy.spatial import ConvexHull

    t, hx, hy = hub_positions(run, limits)
    centre = points[:, :2].mean(axis=0)
    hubs = np.column_stack([hx.ravel(), hy.ravel()]) - centre
    finite = np.all(np.isfinite(hubs), axis=1)
    try:
        facets = ConvexHull(points[:, :2] - centre).equations
    except Exception:  # Qhull refuses a degenerate cloud, which check_points has refused already
        return t, np.zeros(len(t), dtype=bool), np.zeros(len(t))
    inside = np.zeros(len(hubs), dtype=bool)
    inside[finite] = np.all(hubs[finite] @ facets[:, :2].T + facets[:, 2] <= 1e-9, axis=1)
    dist = np.zeros(len(hubs))
    dist[inside], _ = (tree if tree is not None else xy_tree(points)).query(hubs[inside] + centre)
    far = dist.reshape(hx.shape).max(axis=1)
    return t, far > limits.wheel_radius, far


def _check_unmeasured(run: RunData, points: FloatArray, limits: RoverLimits, spec: RunSpec,
                      off: NDArray[np.bool_], tree: Any) -> list[Finding]:
    """The samples on the scan whose wheels rest on unmeasured ground (:func:`hubs_unmeasured`):
    an error for more than OFF_SCAN_ERROR of the run's position samples, else a warning; the
    scan's typical point spacing tells a hole from a scan too sparse for the wheels."""
    t, unmeasured, far = hubs_unmeasured(run, points, limits, tree)
    unmeasured &= ~off
    if not unmeasured.any():
        return []
    share = float(np.mean(unmeasured))
    severity = "error" if share > OFF_SCAN_ERROR else "warning"
    spacing = float(np.median(tree.query(points[:, :2], k=2)[0][:, 1]))
    cause = (f"the scan's points lie {_g(spacing)} m apart (the median distance to the nearest), so it has a hole "
             "there (a gap in the scan, or a scanner's shadow behind a mound or ridge: scan it from another side "
             "too)" if spacing <= 0.5 * limits.wheel_radius else
             f"the scan's points lie {_g(spacing)} m apart (the median distance to the nearest): too sparse for "
             f"the wheels; scan the ground at least every {_g(0.5 * limits.wheel_radius)} m")
    return [Finding(severity, spec.file, "pos_x", f"run {spec.id!r}: during {_format_spans(_spans(t, unmeasured))} "
                    f"({share:.0%} of the position samples; more than {OFF_SCAN_ERROR:.0%} is an error) a wheel has no "
                    f"point of the scan {spec.terrain} within its radius ({_g(limits.wheel_radius)} m) of its hub, up to "
                    f"{_g(float(np.max(far[unmeasured])))} m away: the ground it rests on there is interpolated from "
                    f"points beyond its reach, not measured; {cause}")]


def ground_under_wheels(run: RunData, points: FloatArray, limits: RoverLimits, tree: Any = None
                        ) -> Optional[tuple[FloatArray, FloatArray, FloatArray]]:
    """The scan's ground under the rover's wheels at each position sample of a run: (times (s),
    measured pos_z (m), mean ground height under the four hubs (m)), for the samples whose every
    hub has a scan point within ``GRID_MARGIN``; None without pos_z.

    The hubs lie half the wheelbase ahead and behind the chassis reference point along the
    heading (the measured yaw, else the direction of the track: juno.heading) and half the track
    to either side; the ground under a hub is the median height of the ``GROUND_POINTS`` scan
    points nearest it.
    """
    if not run.has("pos_z"):
        return None
    t, hx, hy = hub_positions(run, limits)
    z = aligned(run, "pos_z", t)["pos_z"]
    k = min(GROUND_POINTS, len(points))
    tree = tree if tree is not None else xy_tree(points)
    dist, idx = tree.query(np.column_stack([hx.ravel(), hy.ravel()]), k=k)
    dist, idx = dist.reshape(len(t), 4, k), idx.reshape(len(t), 4, k)
    ground = np.median(points[idx, 2], axis=2).mean(axis=1)
    on_scan = np.all(dist[:, :, 0] <= GRID_MARGIN, axis=1) & np.isfinite(z)
    return t[on_scan], z[on_scan], ground[on_scan]


def check_heights(run: RunData, points: FloatArray, limits: RoverLimits, file: str, scan_file: str,
                  tree: Any = None) -> list[Finding]:
    """pos_z against the scan's ground under the wheels (module docstring, "z reversed" and
    "Height datum")."""
    from ..sensor_noise import column_noise
    from .sensors import DATUM_LIMIT

    found = ground_under_wheels(run, points, limits, tree)
    if found is None or len(found[0]) < HEIGHT_SAMPLES:
        return []
    t, z, ground = found
    standing = _standing_in_scan(t, z - ground, limits, file, scan_file)
    if standing:
        return standing
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


def _standing_in_scan(t: FloatArray, height: FloatArray, limits: RoverLimits, file: str, scan_file: str
                      ) -> list[Finding]:
    """Where the run rides at its height above the scan's ground for the most part (the upper
    quartile of ``height``, m, within the datum band: a short run may drive over what stands in
    the scan for half its samples) but the scan's ground under the wheels rises to less than
    ``rover.pivotHeight`` below the chassis reference point for some position samples (at least
    two): the wheels would be sunk past their axles there, which the FMU stops at, so the scan
    holds something that stood on the ground when it was scanned (the rover itself, scanned at
    its start; a person, a box) and that the rover drove through."""
    from .sensors import DATUM_LIMIT

    typical = float(np.percentile(height, 75))
    if not limits.pivot_height <= typical <= DATUM_LIMIT * limits.cg_height:
        return []
    low = height < limits.pivot_height
    if int(low.sum()) < 2:
        return []
    least = float(np.min(height))
    rise = typical - least
    where = f"{_g(-least)} m above" if least < 0 else f"to {_g(least)} m below"
    return [Finding("error", scan_file, "z", f"under the wheels of run {file} during {_format_spans(_spans(t, low))} "
                    f"({int(low.sum())} of {len(t)} position samples) the scan's ground rises {where} the chassis "
                    f"reference point, {_g(rise)} m higher than the run rides above it typically, closer than "
                    f"rover.pivotHeight = {_g(limits.pivot_height)} m (the wheels sunk to their axles): the "
                    "scan holds something that stood there when it was scanned, the rover itself (a scan taken with "
                    "the rover at its start) or an object it did not drive over: remove those points from the scan; "
                    "or the scan is placed far off the positions' frame, a feature of the ground where the rover "
                    "did not drive: register them to one frame")]


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
