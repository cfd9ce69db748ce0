"""Specification of LIDAR point clouds, terrain grids, ESRI ASCII files and atomic writing."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from juno.atomic import atomic_directory, atomic_save, atomic_write_bytes, atomic_write_text
from juno.errors import InputError
from juno.pointcloud import Grid, grid_from_points, read_esri_ascii, read_xyz, write_esri_ascii, write_xyz

NOISE = 0.003  # m, LIDAR noise of the synthetic scan
SIGMA = 0.7  # m, width of the mound


def mound(x, y):
    """A 0.5 m Gaussian mound (m)."""
    return 0.5 * np.exp(-(np.asarray(x) ** 2 + np.asarray(y) ** 2) / (2 * SIGMA**2))


def scan(n: int = 20000, half: float = 2.25, seed: int = 1) -> np.ndarray:
    rng = np.random.default_rng(seed)
    xy = rng.uniform(-half, half, size=(n, 2))
    return np.column_stack([xy, mound(xy[:, 0], xy[:, 1]) + rng.normal(0.0, NOISE, n)])


def files_in(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.iterdir())


# ---------------------------------------------------------------------------------------------
# Gridding
# ---------------------------------------------------------------------------------------------

def test_gridding_reproduces_an_analytic_surface() -> None:
    g = grid_from_points(scan(), cell=0.05)
    assert g.resolution == g.cell == 0.05
    assert (g.nrows, g.ncols) == (91, 91)
    xmin, xmax, ymin, ymax = g.extent
    assert xmin <= -2.24 and xmax >= 2.24 and ymin <= -2.24 and ymax >= 2.24
    X, Y = np.meshgrid(g.x, g.y)  # row 0 = south: Y increases with the row
    assert np.all(np.diff(g.y) > 0)
    err = (g.z - mound(X, Y))[~g.filled]
    assert (~g.filled).sum() > 0.9 * g.z.size, "most cells lie inside the hull"
    assert np.sqrt(np.mean(err**2)) < 3 * NOISE
    assert np.percentile(np.abs(err), 99) < 3 * NOISE
    assert np.abs(err).max() < 5 * NOISE
    # the peak is where it should be
    j, i = np.unravel_index(np.argmax(g.z), g.z.shape)
    assert abs(g.x[i]) <= 0.1 and abs(g.y[j]) <= 0.1
    # bilinear lookup agrees with the surface between nodes too
    rng = np.random.default_rng(5)
    q = rng.uniform(-2.0, 2.0, size=(500, 2))
    assert np.sqrt(np.mean((g.height(q[:, 0], q[:, 1]) - mound(q[:, 0], q[:, 1])) ** 2)) < 3 * NOISE


@pytest.mark.parametrize("dx, dy", [(300.0, -200.0), (512345.0, 5412345.0)])
def test_a_scan_far_from_the_origin_grids_as_it_does_at_the_origin(dx: float, dy: float) -> None:
    """A scan in a frame whose origin lies far away (a site 360 m from a total station; map
    coordinates, 5,400 km from their origin) grids to the same heights as the same scan about
    the origin, to 1e-8 m: the triangulation works about a local origin."""
    points = scan(n=4000)
    here = grid_from_points(points, cell=0.1)
    there = grid_from_points(points + np.array([dx, dy, 0.0]), cell=0.1)
    assert there.z.shape == here.z.shape
    assert there.x0 - dx == pytest.approx(here.x0, abs=1e-8) and there.y0 - dy == pytest.approx(here.y0, abs=1e-8)
    assert np.max(np.abs(there.z - here.z)) < 1e-8


def test_holes_are_filled_by_nearest_neighbour() -> None:
    rng = np.random.default_rng(2)
    xy = rng.uniform(-2.0, 2.0, size=(4000, 2))
    keep = (np.hypot(xy[:, 0], xy[:, 1]) > 1.0) & ~((xy[:, 0] > 0.5) & (xy[:, 1] > 0.5))  # ring, one corner cut
    pts = np.column_stack([xy[keep], 0.1 * xy[keep, 0]])
    g = grid_from_points(pts, cell=0.1, margin=0.5)
    assert np.all(np.isfinite(g.z))
    assert g.filled is not None and g.filled.any() and not g.filled.all()
    xmin, xmax, ymin, ymax = g.extent
    assert xmin <= -2.4 and xmax >= 2.4  # margin added
    # a filled cell takes the value of its nearest point
    j, i = np.argwhere(g.filled)[0]
    d = np.hypot(pts[:, 0] - g.x[i], pts[:, 1] - g.y[j])
    assert g.z[j, i] == pts[np.argmin(d), 2]


def test_duplicate_points_are_averaged() -> None:
    pts = np.array([[0, 0, 1.0], [0, 0, 3.0], [1, 0, 0.0], [0, 1, 0.0], [1, 1, 0.0]])
    g = grid_from_points(pts, cell=1.0)
    assert g.z.shape == (2, 2)
    assert g.z[0, 0] == pytest.approx(2.0)


def test_grid_always_at_least_2x2() -> None:
    g = grid_from_points(np.array([[0, 0, 1.0], [0.01, 0, 1.0], [0, 0.01, 1.0]]), cell=0.5)
    assert g.nrows >= 2 and g.ncols >= 2


@pytest.mark.parametrize("cell", [0.0, -0.1, float("nan")])
def test_bad_cell_refused(cell: float) -> None:
    with pytest.raises(ValueError, match="cell"):
        grid_from_points(scan(100), cell=cell)


def test_huge_grid_refused() -> None:
    pts = np.array([[0, 0, 0.0], [1000, 0, 0.0], [0, 1000, 0.0]])
    with pytest.raises(ValueError, match="cap"):
        grid_from_points(pts, cell=0.01)


def test_height_is_bilinear_and_clamped() -> None:
    x0, y0, cell = 10.0, -5.0, 0.5
    xs = x0 + cell * np.arange(6)
    ys = y0 + cell * np.arange(4)
    X, Y = np.meshgrid(xs, ys)
    plane = lambda x, y: 1.0 + 0.2 * x - 0.3 * y + 0.05 * x * y  # noqa: E731  bilinear: exact
    g = Grid(x0=x0, y0=y0, cell=cell, z=plane(X, Y))
    rng = np.random.default_rng(0)
    qx = rng.uniform(xs[0], xs[-1], (7, 9))
    qy = rng.uniform(ys[0], ys[-1], (7, 9))
    h = g.height(qx, qy)
    assert h.shape == (7, 9)
    np.testing.assert_allclose(h, plane(qx, qy), atol=1e-12)
    assert g.height(xs[-1], ys[-1]) == pytest.approx(plane(xs[-1], ys[-1]))
    assert g.height(-100.0, 100.0) == pytest.approx(plane(xs[0], ys[-1]))  # clamped outside


# ---------------------------------------------------------------------------------------------
# ESRI ASCII
# ---------------------------------------------------------------------------------------------

def test_esri_round_trip(tmp_path: Path) -> None:
    g = grid_from_points(scan(3000), cell=0.1)
    p = tmp_path / "terrain.asc"
    write_esri_ascii(p, g)
    back = read_esri_ascii(p)
    assert (back.x0, back.y0, back.cell) == (g.x0, g.y0, g.cell)
    np.testing.assert_array_equal(back.z, g.z)
    assert not back.filled.any()
    lines = p.read_text().splitlines()
    assert [l.split()[0] for l in lines[:6]] == ["ncols", "nrows", "xllcenter", "yllcenter", "cellsize", "NODATA_value"]
    assert lines[5].split()[1] in ("-9999", "-9999.0")
    assert len(lines) == 6 + g.nrows
    first = np.array(lines[6].split(), dtype=float)
    np.testing.assert_array_equal(first, g.z[-1])  # north row first


def test_esri_reader_accepts_corner_and_any_case(tmp_path: Path) -> None:
    p = tmp_path / "g.asc"
    p.write_text("NCOLS 3\nnRows 2\nXLLCORNER 0\nyllcorner 10\nCellSize 2\nnodata_value -1\n1 2 3\n4 -1 6\n")
    g = read_esri_ascii(p)
    assert (g.x0, g.y0, g.cell) == (1.0, 11.0, 2.0)
    assert g.z.shape == (2, 3)
    np.testing.assert_array_equal(g.z[1], [1, 2, 3])  # north row
    assert g.z[0, 0] == 4 and g.z[0, 2] == 6
    assert g.filled[0, 1] and g.z[0, 1] in (4.0, 6.0, 2.0)  # NODATA filled from a neighbour


@pytest.mark.parametrize(
    "text, line, says",
    [
        ("ncols 2\nnrows 2\nxllcenter 0\nyllcenter 0\ncellsize 1\n1 2\n3\n", 7, "too few"),
        ("ncols 2\nnrows 2\nxllcenter 0\nyllcenter 0\ncellsize 1\n1 2\n3 4\n5\n", 8, "too many"),
        ("ncols 2\nnrows 2\nxllcenter 0\nyllcenter 0\ncellsize 1\n1 2\n3 x\n", 7, "not a number"),
        ("ncols 2\nnrows 2\nxllcenter 0\nyllcenter 0\ncellsize 1\n1 nan\n3 4\n", 6, "not finite"),
        ("ncols 2\nnrows 2\nxllcenter 0\nyllcenter 0\ncellsize -1\n1 2\n3 4\n", 5, "cellsize"),
        ("ncols 2\nnrows 1\nxllcenter 0\nyllcenter 0\ncellsize 1\n1 2\n", 2, "2 x 2"),
        ("ncols 2.5\nnrows 2\nxllcenter 0\nyllcenter 0\ncellsize 1\n1 2\n3 4\n", 1, "integer"),
        ("ncols 2\nnrows 2\nxllcenter 0\ncellsize 1\n1 2\n3 4\n", 5, "yllcorner"),
        ("ncols 2\nnrows 2\nxllcenter 0\nyllcenter 0\ncellsize 1\nfoo 1\n1 2\n3 4\n", 6, "unknown header key"),
        ("ncols 2\nncols 2\nnrows 2\nxllcenter 0\nyllcenter 0\ncellsize 1\n1 2\n3 4\n", 2, "twice"),
    ],
)
def test_esri_reader_is_strict(tmp_path: Path, text: str, line: int, says: str) -> None:
    p = tmp_path / "bad.asc"
    p.write_text(text)
    with pytest.raises(InputError) as info:
        read_esri_ascii(p)
    msg = str(info.value)
    assert "bad.asc" in msg and f"line {line}" in msg and says in msg, msg


def test_esri_all_nodata_refused(tmp_path: Path) -> None:
    p = tmp_path / "nd.asc"
    p.write_text("ncols 2\nnrows 2\nxllcenter 0\nyllcenter 0\ncellsize 1\nNODATA_value -9999\n-9999 -9999\n-9999 -9999\n")
    with pytest.raises(InputError, match="NODATA"):
        read_esri_ascii(p)


# ---------------------------------------------------------------------------------------------
# Point cloud files
# ---------------------------------------------------------------------------------------------

def test_xyz_round_trip_and_syntax(tmp_path: Path) -> None:
    pts = scan(200)
    p = tmp_path / "scan.xyz"
    write_xyz(p, pts)
    np.testing.assert_array_equal(read_xyz(p), pts)
    q = tmp_path / "mixed.xyz"
    q.write_text("# LIDAR scan\n\n1 2 3\n4,5,6   # comment\n  7.5\t8e-1 , -9\n0 0 1\n")
    np.testing.assert_array_equal(read_xyz(q), [[1, 2, 3], [4, 5, 6], [7.5, 0.8, -9], [0, 0, 1]])


@pytest.mark.parametrize("text", ["", "\n\n", "# only comments\n# x y z\n"])
def test_empty_cloud_refused(tmp_path: Path, text: str) -> None:
    p = tmp_path / "empty.xyz"
    p.write_text(text)
    with pytest.raises(InputError, match="empty point cloud") as info:
        read_xyz(p)
    assert "empty.xyz" in str(info.value)


@pytest.mark.parametrize(
    "bad_line, says",
    [("1.0 2.0 abc", "not a number"), ("1 2", "found 2 fields"), ("1 2 3 4", "found 4 fields"), ("1 inf 3", "not finite"), ("1,,3", "not a number")],
)
def test_bad_token_refused_with_file_and_line(tmp_path: Path, bad_line: str, says: str) -> None:
    p = tmp_path / "scan.xyz"
    p.write_text(f"# header\n0 0 0\n{bad_line}\n1 1 1\n")
    before = p.read_bytes()
    with pytest.raises(InputError) as info:
        read_xyz(p)
    msg = str(info.value)
    assert str(p) in msg and "line 3" in msg and says in msg, msg
    assert info.value.line == 3
    assert p.read_bytes() == before


@pytest.mark.parametrize("header", ["", "x y z intensity\n", "//X,Y,Z,Intensity\n", "X Y Z R G B\n"])
def test_an_export_with_a_header_and_more_fields_reads_its_first_three(tmp_path: Path, header: str) -> None:
    """LIDAR exports add intensity or colour and often a header naming the fields: the points are
    the first three fields."""
    p = tmp_path / "scan.xyz"
    extra = 3 if header.count("R") else 1
    p.write_text(header + "".join(f"{x} {y} {z}" + " 7" * extra + "\n" for x, y, z in [(0, 0, 0.5), (1, 0, 0.25), (0, 1, 0.125)]))
    np.testing.assert_array_equal(read_xyz(p), [[0, 0, 0.5], [1, 0, 0.25], [0, 1, 0.125]])


def test_a_header_line_after_the_first_point_is_refused(tmp_path: Path) -> None:
    """Only the first line may name the fields: a name further down is a broken line."""
    p = tmp_path / "scan.xyz"
    p.write_text("0 0 0\nx y z\n1 1 1\n")
    with pytest.raises(InputError, match="not a number") as info:
        read_xyz(p)
    assert info.value.line == 2


@pytest.mark.parametrize("text", ["0 0 0\n1 1 1\n", "0 0 0\n1 1 1\n2 2 5\n3 3 1\n", "1 1 1\n1 1 2\n1 1 3\n"])
def test_collinear_or_too_few_points_refused(tmp_path: Path, text: str) -> None:
    p = tmp_path / "line.xyz"
    p.write_text(text)
    with pytest.raises(InputError, match="collinear"):
        read_xyz(p)


def test_ascii_ply(tmp_path: Path) -> None:
    p = tmp_path / "scan.ply"
    p.write_text(
        "ply\nformat ascii 1.0\ncomment made by a test\nelement vertex 3\nproperty float intensity\n"
        "property float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\n"
        "end_header\n9 0 0 1\n9 1 0 2\n9 0 1 3\n3 0 1 2\n"
    )
    np.testing.assert_array_equal(read_xyz(p), [[0, 0, 1], [1, 0, 2], [0, 1, 3]])
    b = tmp_path / "other.ply"
    b.write_bytes(b"ply\nformat binary_middle_endian 1.0\nelement vertex 3\nproperty float x\nend_header\n\x00\x01")
    with pytest.raises(InputError, match="other.ply, line 2: PLY format 'binary_middle_endian' is not read"):
        read_xyz(b)


# ---------------------------------------------------------------------------------------------
# Atomic writing
# ---------------------------------------------------------------------------------------------

def test_atomic_save_leaves_no_partial_file(tmp_path: Path) -> None:
    target = tmp_path / "figure.png"

    def failing_writer(tmp: Path) -> None:
        assert tmp.suffix == ".png" and tmp.parent == tmp_path
        tmp.write_bytes(b"\x89PNG partial")
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError, match="disk full"):
        atomic_save(target, failing_writer)
    assert files_in(tmp_path) == []

    target.write_bytes(b"old")
    with pytest.raises(RuntimeError):
        atomic_save(target, failing_writer)
    assert target.read_bytes() == b"old" and files_in(tmp_path) == ["figure.png"]

    atomic_save(target, lambda tmp: tmp.write_bytes(b"new"))
    assert target.read_bytes() == b"new" and files_in(tmp_path) == ["figure.png"]


def test_atomic_save_with_matplotlib(tmp_path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])
    atomic_save(tmp_path / "f.png", fig.savefig)
    plt.close(fig)
    assert (tmp_path / "f.png").read_bytes()[:4] == b"\x89PNG"
    assert files_in(tmp_path) == ["f.png"]


def test_atomic_write_text_and_bytes(tmp_path: Path) -> None:
    p = tmp_path / "sub" / "a.txt"
    atomic_write_text(p, "héllo\n")
    assert p.read_bytes() == "héllo\n".encode()
    atomic_write_bytes(p, b"x")
    assert p.read_bytes() == b"x" and files_in(p.parent) == ["a.txt"]


def test_esri_and_xyz_writers_leave_no_partial_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    target = tmp_path / "t.asc"
    target.write_text("old")

    def broken_replace(src, dst):
        raise OSError("simulated crash before rename")

    monkeypatch.setattr(os, "replace", broken_replace)
    with pytest.raises(OSError, match="simulated"):
        write_esri_ascii(target, Grid(0.0, 0.0, 1.0, np.zeros((2, 2))))
    with pytest.raises(OSError, match="simulated"):
        write_xyz(tmp_path / "p.xyz", scan(10))
    assert target.read_text() == "old"
    assert files_in(tmp_path) == ["t.asc"]


def test_atomic_directory(tmp_path: Path) -> None:
    final = tmp_path / "out"
    with pytest.raises(ValueError):
        with atomic_directory(final) as tmp:
            (tmp / "a.txt").write_text("partial")
            raise ValueError("writer failed")
    assert files_in(tmp_path) == []

    with atomic_directory(final) as tmp:
        (tmp / "a.txt").write_text("one")
    assert files_in(final) == ["a.txt"]

    with pytest.raises(FileExistsError):
        with atomic_directory(final) as tmp:
            (tmp / "b.txt").write_text("two")
    assert files_in(final) == ["a.txt"] and files_in(tmp_path) == ["out"]

    with pytest.raises(KeyError):
        with atomic_directory(final, overwrite=True) as tmp:
            (tmp / "b.txt").write_text("two")
            raise KeyError("late failure")
    assert files_in(final) == ["a.txt"] and files_in(tmp_path) == ["out"]

    with atomic_directory(final, overwrite=True) as tmp:
        (tmp / "b.txt").write_text("two")
    assert files_in(final) == ["b.txt"] and files_in(tmp_path) == ["out"]

    (tmp_path / "empty").mkdir()
    with atomic_directory(tmp_path / "empty") as tmp:
        (tmp / "c.txt").write_text("three")
    assert files_in(tmp_path / "empty") == ["c.txt"]


# ---------------------------------------------------------------------------------------------
# Gross outliers
# ---------------------------------------------------------------------------------------------

def test_gross_outliers_of_a_scan() -> None:
    """A clean scan of a mound has none; a point 1e6 m away and a 2 m spike are found, nothing else."""
    from juno.pointcloud import gross_outliers

    pts = scan()
    assert not gross_outliers(pts).any()
    pts = np.vstack([pts, [[1.0e6, 0.0, 0.0]]])
    pts[100, 2] += 2.0
    assert np.flatnonzero(gross_outliers(pts)).tolist() == [100, len(pts) - 1]
