"""LIDAR point clouds and terrain elevation grids.

- :func:`read_xyz` / :func:`write_xyz`: scattered points ``x y z`` (m, world frame); read from
  text, PLY or LAS files (the formats: :mod:`juno.scan_formats`), written as text, one point per
  line.
- :func:`grid_from_points`: scattered points -> regular elevation :class:`Grid` (linear
  interpolation inside the convex hull, nearest-neighbour fill outside it).
- :func:`write_esri_ascii` / :func:`read_esri_ascii`: the ESRI ASCII grid (``.asc``) that the
  FMU's ``terrain.file`` parameter reads (``fmu_src/terrain.h``).

Grid convention (same as the FMU): ``z[row, col]`` with row 0 the southernmost row (smallest y)
and col 0 the westernmost (smallest x); ``(x0, y0)`` is the centre of cell (row 0, col 0);
cell centres are at ``x0 + col*cell``, ``y0 + row*cell``. Outside the grid the edge values
extend flat (clamped), as in the FMU.
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Optional, Union

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .atomic import atomic_write_text
from .errors import InputError, decode_input_text, parse_finite, read_input_bytes
from .scan_formats import parse_scan

PathLike = Union[str, "os.PathLike[str]"]

__all__ = [
    "Grid",
    "read_xyz",
    "write_xyz",
    "format_xyz",
    "check_points",
    "gross_outliers",
    "grid_from_points",
    "write_esri_ascii",
    "read_esri_ascii",
    "MAX_GRID_CELLS",
    "GRID_MARGIN",
]

GRID_MARGIN = 1.0
"""Border (m) by which a terrain run's scan is gridded beyond its points (nearest edge height), so
that the rover's wheels may hang over an edge of the scan; the path's wheel footprint must stay
within it (:func:`juno.plausibility.path_off_scan`)."""

MAX_GRID_CELLS = 40_000_000
"""Largest grid :func:`grid_from_points` builds (cells); beyond that the cell size is surely wrong."""


# --------------------------------------------------------------------------------------------
# Point clouds
# --------------------------------------------------------------------------------------------

def read_xyz(path: PathLike) -> NDArray[np.float64]:
    """Read a LIDAR point cloud; returns an (N, 3) float array of x, y, z in m.

    The file is text, ``x y z`` per line (further fields and a first line naming them allowed,
    a Leica ``.pts`` point count allowed first), PLY (ASCII or binary) or uncompressed LAS
    1.0-1.4; the format is told by the file's first bytes, then by its suffix
    (:mod:`juno.scan_formats`). LAZ, E57 and other formats are refused with what to do.

    Raises:
        InputError: the file breaks its format (naming file and line, or byte offset), an empty
            cloud, or fewer than 3 non-collinear points in x-y.
    """
    p = Path(path)
    points = parse_scan(p, read_input_bytes(p))
    check_points(points, p)
    return points


def check_points(points: ArrayLike, path: Optional[PathLike] = None) -> NDArray[np.float64]:
    """Check an (N, 3) finite cloud spanning an area in x-y; returns it as a float array.

    Raises:
        InputError: empty cloud, wrong shape, non-finite values, fewer than 3 non-collinear
            points in x-y.
    """
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise InputError(f"points must be an (N, 3) array, got shape {pts.shape}", path)
    if pts.shape[0] == 0:
        raise InputError("empty point cloud (no points)", path)
    if not np.all(np.isfinite(pts)):
        raise InputError("point cloud holds non-finite values", path)
    xy = pts[:, :2] - pts[:, :2].mean(axis=0)
    scale = float(np.abs(xy).max()) if xy.size else 0.0
    if pts.shape[0] < 3 or scale == 0.0:
        raise InputError(f"need at least 3 non-collinear points in x-y, got {pts.shape[0]} points", path)
    s = np.linalg.svd(xy / scale, compute_uv=False)
    if s[-1] <= 1e-9 * s[0]:
        raise InputError("all points are collinear in x-y: they do not span a terrain area (points on a vertical "
                         "plane: are two axes swapped? the columns are x y z, z up)", path)
    return pts


def gross_outliers(points: ArrayLike, false_alarm: float = 1e-2, neighbours: int = 8,
                   min_step: float = 0.25) -> NDArray[np.bool_]:
    """Mask of the gross outliers of an (N, 3) cloud (m): points no terrain explains.

    Two robust tests, each with threshold ``k * 1.4826 * MAD`` (1.4826 * MAD is the standard
    deviation for Gaussian data) and ``k`` chosen so that N Gaussian values exceed it with
    probability ``false_alarm`` (two-sided: ``k = Phi^-1(1 - false_alarm / (2 N))``, 5.3 for
    25 000 points):

    * x and y, each against the cloud's median: points far outside the bulk of the scan
      (a uniformly scanned strip reaches 1.7 MAD-sigmas from its median, far inside k).
    * z against the local surface: the residual of z from the median height of the point's
      ``neighbours`` nearest points in x-y, against the residuals' own MAD. The point must also
      stand more than ``min_step`` (m) off its neighbours: a step smaller than a wheel's
      radius within a few point spacings is terrain for the gridding to average, not a
      point to drop, and it keeps a noise-free scan (MAD = 0) from flagging its own curvature.

    With MAD = 0 (more than half the values equal) x or y is not tested, and z only against
    ``min_step``.
    """
    from statistics import NormalDist

    from scipy.spatial import cKDTree

    pts = np.asarray(points, dtype=float)
    n = len(pts)
    bad = np.zeros(n, dtype=bool)
    if n < neighbours + 2:
        return bad
    k = NormalDist().inv_cdf(1.0 - false_alarm / (2.0 * n))
    for j in (0, 1):
        v = pts[:, j]
        med = np.median(v)
        dev = np.abs(v - med)
        scale = 1.4826 * float(np.median(dev))
        if scale > 0:
            bad |= dev > k * scale
    good = ~bad
    tree = cKDTree(pts[good, :2])
    # Every point's neighbours, searched on every core: most of a large scan's check (a million
    # points: 5.5 s on one core of the slowest machine the suite runs on, 2.5 s on two), made
    # where no worker is busy (the checks before any computation, the gridding before the fits),
    # and the same neighbours whatever the threads.
    _, idx = tree.query(pts[:, :2], k=min(neighbours + 1, int(good.sum())), workers=-1)
    zg = pts[good, 2]
    nz = zg[idx]
    # Leave the point itself out of its neighbourhood (it is its own nearest neighbour when kept).
    own = np.flatnonzero(good)[idx] == np.arange(n)[:, None]
    nz = np.where(own, np.nan, nz)
    with np.errstate(over="ignore", invalid="ignore"):
        r = pts[:, 2] - np.nanmedian(nz, axis=1)
        scale = 1.4826 * float(np.nanmedian(np.abs(r[good] - np.nanmedian(r[good]))))
        bad |= (np.abs(r) > max(k * scale, min_step)) | ~np.isfinite(r)
    return bad


def format_xyz(points: ArrayLike) -> str:
    """Text of an (N, 3) cloud, one ``x y z`` per line, shortest round-trip decimal (exact)."""
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must be an (N, 3) array, got shape {pts.shape}")
    if not np.all(np.isfinite(pts)):
        raise ValueError("points must be finite")
    r = float.__repr__
    return "".join(f"{r(x)} {r(y)} {r(z)}\n" for x, y, z in pts.tolist())


def write_xyz(path: PathLike, points: ArrayLike) -> Path:
    """Write an (N, 3) cloud as ``x y z`` text (m), atomically, exact to the last bit."""
    return atomic_write_text(path, "# x y z (m)\n" + format_xyz(points))


# --------------------------------------------------------------------------------------------
# Grids
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class Grid:
    """Regular elevation grid, row 0 = south, col 0 = west.

    Attributes:
        x0, y0: centre of the south-west cell (m).
        cell: cell size = resolution (m), the same in x and y.
        z: (nrows, ncols) elevations (m).
        filled: optional (nrows, ncols) bool mask of cells not measured directly but filled by
            nearest neighbour (outside the scan's convex hull, or NODATA in a file).
    """

    x0: float
    y0: float
    cell: float
    z: NDArray[np.float64]
    filled: Optional[NDArray[np.bool_]] = dataclasses.field(default=None, repr=False)

    def __post_init__(self) -> None:
        z = np.asarray(self.z, dtype=float)
        if z.ndim != 2 or z.shape[0] < 1 or z.shape[1] < 1:
            raise ValueError(f"Grid.z must be a non-empty 2-D array, got shape {z.shape}")
        if not (np.isfinite(self.cell) and self.cell > 0):
            raise ValueError(f"Grid.cell must be > 0, got {self.cell}")
        object.__setattr__(self, "z", np.ascontiguousarray(z))
        object.__setattr__(self, "x0", float(self.x0))
        object.__setattr__(self, "y0", float(self.y0))
        object.__setattr__(self, "cell", float(self.cell))

    @property
    def nrows(self) -> int:
        return int(self.z.shape[0])

    @property
    def ncols(self) -> int:
        return int(self.z.shape[1])

    @property
    def resolution(self) -> float:
        """Cell size (m)."""
        return self.cell

    @property
    def x(self) -> NDArray[np.float64]:
        """Cell-centre x coordinates (m), west to east."""
        return self.x0 + self.cell * np.arange(self.ncols)

    @property
    def y(self) -> NDArray[np.float64]:
        """Cell-centre y coordinates (m), south to north."""
        return self.y0 + self.cell * np.arange(self.nrows)

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """(xmin, xmax, ymin, ymax) of the cell centres (m)."""
        return (self.x0, self.x0 + self.cell * (self.ncols - 1), self.y0, self.y0 + self.cell * (self.nrows - 1))

    def height(self, x: ArrayLike, y: ArrayLike) -> NDArray[np.float64]:
        """Bilinear elevation (m) at world (x, y) (m), vectorised; clamped to the edges outside;
        NaN where x or y is NaN.

        Returns an array of the broadcast shape of x and y (a NumPy float for scalars).
        """
        xa, ya = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
        ncols, nrows = self.ncols, self.nrows
        u = np.clip((xa - self.x0) / self.cell, 0.0, ncols - 1)
        v = np.clip((ya - self.y0) / self.cell, 0.0, nrows - 1)
        # The cell's lower-left corner: u and v are >= 0 here, so truncation is the floor.
        i0 = np.minimum(u.astype(np.intp), max(ncols - 2, 0))
        j0 = np.minimum(v.astype(np.intp), max(nrows - 2, 0))
        fu = u - i0
        fv = v - j0
        gu = 1 - fu
        gv = 1 - fv
        # The four corners by their index in the flattened grid; on a grid one cell wide (or high)
        # the next column (row) is the same one, as the clamping says.  A NaN coordinate has no
        # cell (its index is clipped into the grid) and its weights make the height NaN.
        z = self._flat_z
        k00 = j0 * ncols
        k00 += i0
        k10 = k00 + (ncols if nrows > 1 else 0)
        right = 1 if ncols > 1 else 0
        return (
            z.take(k00, mode="clip") * gu * gv
            + z.take(k00 + right, mode="clip") * fu * gv
            + z.take(k10, mode="clip") * gu * fv
            + z.take(k10 + right, mode="clip") * fu * fv
        )

    @property
    def _flat_z(self) -> NDArray[np.float64]:
        """The elevations in row-major order (a view when ``z`` is C-contiguous, as it is made)."""
        return self.z.reshape(-1)


def _average_duplicates(pts: NDArray[np.float64], quantum: float) -> NDArray[np.float64]:
    """Merge points whose x-y agree to ``quantum`` (m), averaging their z."""
    keys = np.round(pts[:, :2] / quantum).astype(np.int64)
    _, first, inverse, counts = np.unique(keys, axis=0, return_index=True, return_inverse=True, return_counts=True)
    if len(first) == len(pts):
        return pts
    inverse = inverse.reshape(-1)
    zsum = np.bincount(inverse, weights=pts[:, 2])
    out = pts[first].copy()
    out[:, 2] = zsum / counts
    return out


#: The local origin a scan is gridded about is its centre rounded to this (m): see grid_from_points.
LOCAL_ORIGIN_STEP = 1000.0


def grid_from_points(
    points: ArrayLike,
    cell: float = 0.05,
    margin: float = 0.0,
    method: str = "linear",
    max_cells: int = MAX_GRID_CELLS,
) -> Grid:
    """Grid a scattered cloud onto a regular elevation grid.

    Args:
        points: (N, 3) x, y, z (m).
        cell: grid resolution (m), > 0.
        margin: extra border around the points' x-y bounding box (m), >= 0; filled by nearest
            neighbour.
        method: scipy ``griddata`` method inside the convex hull: "linear" (default), "cubic"
            or "nearest".
        max_cells: refuse grids larger than this.

    Points with the same x-y (to 1e-6 cell) are merged, their z averaged. Cells outside the
    convex hull (or otherwise NaN) are filled from the nearest point; :attr:`Grid.filled`
    marks them. The grid has at least 2 x 2 cells (the FMU's reader needs that).

    Raises:
        InputError: bad cloud (see :func:`check_points`).
        ValueError: bad cell / margin / method or a grid larger than ``max_cells``.
    """
    from scipy.interpolate import griddata
    from scipy.spatial import cKDTree
    from threadpoolctl import threadpool_limits

    if not (np.isfinite(cell) and cell > 0):
        raise ValueError(f"grid cell size must be a positive number of metres, got {cell!r}")
    if not (np.isfinite(margin) and margin >= 0):
        raise ValueError(f"grid margin must be >= 0 m, got {margin!r}")
    if method not in ("linear", "cubic", "nearest"):
        raise ValueError(f"grid method must be 'linear', 'cubic' or 'nearest', got {method!r}")
    pts = check_points(points)
    pts = _average_duplicates(pts, quantum=cell * 1e-6)
    xmin, ymin = pts[:, :2].min(axis=0) - margin
    xmax, ymax = pts[:, :2].max(axis=0) + margin
    ncols_f = np.ceil((xmax - xmin) / cell - 1e-9) + 1
    nrows_f = np.ceil((ymax - ymin) / cell - 1e-9) + 1
    if ncols_f * nrows_f > max_cells:
        raise ValueError(
            f"a {cell} m grid over {xmax - xmin:.3g} x {ymax - ymin:.3g} m would have "
            f"{int(ncols_f)} x {int(nrows_f)} cells, more than the cap of {max_cells}: choose a larger cell"
        )
    ncols, nrows = max(int(ncols_f), 2), max(int(nrows_f), 2)
    # Centre the grid on the data when it overhangs the bounding box.
    x0 = 0.5 * (xmin + xmax) - 0.5 * cell * (ncols - 1)
    y0 = 0.5 * (ymin + ymax) - 0.5 * cell * (nrows - 1)
    # Triangulated about a local origin: the scan's centre rounded to the kilometre.  The
    # triangulation's in-circle tests lose precision with the coordinates' size (a scan in map
    # coordinates 5,400 km from the origin gridded up to 0.18 m off), and a subtraction of a
    # number within a factor of two is exact: a scan within 500 m of the origin grids as given,
    # a scan in map coordinates as if it lay there.
    origin = LOCAL_ORIGIN_STEP * np.round(0.5 * np.array([xmin + xmax, ymin + ymax]) / LOCAL_ORIGIN_STEP)
    local = pts[:, :2] - origin
    gx = (x0 - origin[0]) + cell * np.arange(ncols)
    gy = (y0 - origin[1]) + cell * np.arange(nrows)
    X, Y = np.meshgrid(gx, gy)
    if len(pts) >= 3 and method != "nearest":
        # One BLAS thread: the interpolation's small solves gain nothing from threads, and
        # OpenBLAS's spinning threads took five times the CPU of the interpolation itself.
        try:
            with threadpool_limits(limits=1, user_api="blas"):
                z = griddata(local, pts[:, 2], (X, Y), method=method)
        except Exception as e:  # Qhull failure on a nearly degenerate cloud
            raise InputError(f"cannot triangulate the point cloud: {str(e).splitlines()[0]}") from None
    else:
        z = np.full(X.shape, np.nan)
    holes = ~np.isfinite(z)
    if holes.any():
        tree = cKDTree(local)
        _, idx = tree.query(np.column_stack([X[holes], Y[holes]]))
        z[holes] = pts[idx, 2]
    return Grid(x0=float(x0), y0=float(y0), cell=float(cell), z=z, filled=holes)


# --------------------------------------------------------------------------------------------
# ESRI ASCII grids
# --------------------------------------------------------------------------------------------

NODATA = -9999.0


def write_esri_ascii(path: PathLike, grid: Grid, nodata: float = NODATA) -> Path:
    """Write ``grid`` as an ESRI ASCII grid (``.asc``) atomically.

    Header ``ncols, nrows, xllcenter, yllcenter, cellsize, NODATA_value``; then rows from north
    to south; numbers in shortest round-trip decimal (exact). NaN cells are written as NODATA.

    Raises:
        ValueError: a grid smaller than 2 x 2 (the FMU refuses it) or a value equal to NODATA.
    """
    if grid.nrows < 2 or grid.ncols < 2:
        raise ValueError(f"ESRI grid must be at least 2 x 2 cells, got {grid.ncols} x {grid.nrows}")
    z = np.asarray(grid.z, dtype=float)
    if np.any(z == nodata):
        raise ValueError(f"grid holds the NODATA value {nodata}; choose another nodata")
    if np.any(np.isinf(z)):
        raise ValueError("grid holds infinite values")
    r = float.__repr__
    nd = r(float(nodata))
    lines = [
        f"ncols {grid.ncols}",
        f"nrows {grid.nrows}",
        f"xllcenter {r(grid.x0)}",
        f"yllcenter {r(grid.y0)}",
        f"cellsize {r(grid.cell)}",
        f"NODATA_value {nd}",
    ]
    for row in z[::-1].tolist():
        lines.append(" ".join(nd if v != v else r(v) for v in row))
    return atomic_write_text(path, "\n".join(lines) + "\n")


_HEADER_KEYS = ("ncols", "nrows", "xllcorner", "xllcenter", "yllcorner", "yllcenter", "cellsize", "nodata_value")


def read_esri_ascii(path: PathLike) -> Grid:
    """Read an ESRI ASCII grid strictly, as the FMU's ``terrain_load`` does.

    Header keys (case-insensitive, any order, each once): ``ncols``, ``nrows``,
    ``xllcorner`` or ``xllcenter``, ``yllcorner`` or ``yllcenter``, ``cellsize``, optional
    ``NODATA_value``; then ``nrows * ncols`` numbers, rows from north to south. NODATA cells
    are filled from the nearest valid cell and marked in :attr:`Grid.filled`.

    Raises:
        InputError naming file and line: unreadable file, bad or missing header key,
        non-numeric or non-finite value, too few / too many values, grid smaller than 2 x 2,
        all cells NODATA.
    """
    p = Path(path)
    text = decode_input_text(p, read_input_bytes(p))
    lines = text.splitlines()
    header: dict[str, tuple[float, int]] = {}
    k = 0
    while k < len(lines):
        tok = lines[k].split()
        if not tok:
            k += 1
            continue
        key = tok[0].lower()
        if key not in _HEADER_KEYS:
            if tok[0][:1] in "+-.0123456789":
                break  # first data line
            raise InputError(f"unknown header key {tok[0]!r}", p, k + 1)
        if len(tok) != 2:
            raise InputError(f"header line must be 'key value', got {lines[k].strip()[:60]!r}", p, k + 1)
        if key in header:
            raise InputError(f"header key {tok[0]!r} given twice", p, k + 1)
        header[key] = (parse_finite(tok[1], p, k + 1, tok[0]), k + 1)
        k += 1
    for a, b in (("xllcorner", "xllcenter"), ("yllcorner", "yllcenter")):
        if a in header and b in header:
            raise InputError(f"header gives both {a} and {b}", p, header[b][1])
    for need in ("ncols", "nrows", "cellsize"):
        if need not in header:
            raise InputError(f"header lacks {need!r}", p, k + 1 if k < len(lines) else len(lines))
    for a, b in (("xllcorner", "xllcenter"), ("yllcorner", "yllcenter")):
        if a not in header and b not in header:
            raise InputError(f"header lacks {a!r} or {b!r}", p, k + 1 if k < len(lines) else len(lines))
    dims = {}
    for key in ("ncols", "nrows"):
        value, line = header[key]
        if value != int(value) or value < 1:
            raise InputError(f"{key} must be a positive integer, got {value}", p, line)
        dims[key] = int(value)
    ncols, nrows = dims["ncols"], dims["nrows"]
    if ncols < 2 or nrows < 2:
        raise InputError(f"grid must be at least 2 x 2 cells, got {ncols} x {nrows}", p, header["nrows"][1])
    if ncols * nrows > MAX_GRID_CELLS:
        raise InputError(f"grid of {ncols} x {nrows} cells exceeds the cap of {MAX_GRID_CELLS}", p, header["nrows"][1])
    cell, cell_line = header["cellsize"]
    if cell <= 0:
        raise InputError(f"cellsize must be > 0, got {cell}", p, cell_line)
    x0 = header["xllcenter"][0] if "xllcenter" in header else header["xllcorner"][0] + 0.5 * cell
    y0 = header["yllcenter"][0] if "yllcenter" in header else header["yllcorner"][0] + 0.5 * cell
    nodata = header.get("nodata_value", (None, 0))[0]

    n = ncols * nrows
    values: list[float] = []
    count = 0
    last_line = k
    for lineno in range(k + 1, len(lines) + 1):
        tok = lines[lineno - 1].split()
        if not tok:
            continue
        if count + len(tok) > n:
            raise InputError(f"too many values: the header announces {ncols} x {nrows} = {n}", p, lineno)
        values.extend(parse_finite(t, p, lineno) for t in tok)
        count += len(tok)
        last_line = lineno
    if count < n:
        raise InputError(f"too few values: {count} of {ncols} x {nrows} = {n}", p, max(last_line, 1))
    z = np.array(values, dtype=float).reshape(nrows, ncols)[::-1].copy()  # file is north to south; row 0 = south
    missing = np.zeros(z.shape, dtype=bool) if nodata is None else (z == nodata)
    if missing.all():
        raise InputError("every cell is NODATA", p)
    if missing.any():
        from scipy.spatial import cKDTree

        jj, ii = np.nonzero(~missing)
        tree = cKDTree(np.column_stack([jj, ii]))
        mj, mi = np.nonzero(missing)
        _, idx = tree.query(np.column_stack([mj, mi]))
        z[mj, mi] = z[jj[idx], ii[idx]]
    return Grid(x0=float(x0), y0=float(y0), cell=float(cell), z=z, filled=missing)
