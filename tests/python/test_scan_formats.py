"""Specification of the scan file formats read_xyz reads: text, Leica .pts, PLY (ASCII and binary)
and LAS; and of the refusals of what it cannot read."""

from __future__ import annotations

import struct
from pathlib import Path
from typing import Optional, Sequence

import numpy as np
import pytest

from juno.campaign import load_campaign, read_terrain_points, write_campaign
from juno.errors import InputError
from juno.pointcloud import format_xyz, grid_from_points, read_xyz
from juno.scan_formats import LAS_MIN_RECORD_LENGTH, PLY_TYPES
from test_campaign import make_manifest, make_runs, wide_terrain


def cloud(n: int = 300, seed: int = 4, noise: float = 0.003) -> np.ndarray:
    """A mound scanned at n points over +-2 m with ``noise`` (m), every value a float32 (so that
    a float PLY holds it exactly)."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(-2.0, 2.0, size=(n, 2))
    z = 0.4 * np.exp(-(xy ** 2).sum(axis=1) / 0.8) + rng.normal(0.0, noise, n)
    return np.column_stack([xy, z]).astype(np.float32).astype(np.float64)


# ---------------------------------------------------------------------------------------------
# Writers of the test files (the library writes only text)
# ---------------------------------------------------------------------------------------------

STRUCT_CODES = {"i1": "b", "u1": "B", "i2": "h", "u2": "H", "i4": "i", "u4": "I", "f4": "f", "f8": "d"}

#: The values written for the properties that are not coordinates.
EXTRA_VALUES = {"intensity": 0.25, "red": 200, "green": 17, "blue": 3, "nx": 0.0, "ny": 0.0, "nz": 1.0}


def ply_bytes(points: np.ndarray, *, order: str = "<", properties: Sequence[tuple[str, str]] = (),
              leading: Optional[tuple[str, bytes]] = None, faces: bool = False, fmt: Optional[str] = None) -> bytes:
    """A binary PLY of ``points``: the vertex element's ``properties`` as (type, name) (x, y, z
    float by default), each coordinate's value from the points, the others from EXTRA_VALUES;
    ``leading`` an element (its header lines, its body) before the vertices; ``faces`` one
    triangle after them."""
    properties = list(properties) or [("float", "x"), ("float", "y"), ("float", "z")]
    fmt = fmt or ("binary_little_endian" if order == "<" else "binary_big_endian")
    head = ["ply", f"format {fmt} 1.0", "comment written by the test"]
    body = b""
    if leading is not None:
        head.append(leading[0])
        body += leading[1]
    head.append(f"element vertex {len(points)}")
    head += [f"property {t} {name}" for t, name in properties]
    if faces:
        head += ["element face 1", "property list uchar int vertex_indices"]
    head.append("end_header")
    codes = order + "".join(STRUCT_CODES[PLY_TYPES[t]] for t, _ in properties)
    for p in points.tolist():
        values = [p["xyz".index(name)] if name in ("x", "y", "z") else EXTRA_VALUES[name] for _, name in properties]
        values = [v if PLY_TYPES[t][0] == "f" else int(v) for (t, _), v in zip(properties, values)]
        body += struct.pack(codes, *values)
    if faces:
        body += struct.pack(order + "B3i", 3, 0, 1, 2)
    return ("\n".join(head) + "\n").encode("ascii") + body


def ascii_ply_text(points: np.ndarray) -> str:
    return ("ply\nformat ascii 1.0\nelement vertex %d\nproperty float x\nproperty float y\nproperty double z\n"
            "property uchar red\nend_header\n" % len(points)) + "".join(f"{x!r} {y!r} {z!r} 9\n" for x, y, z in points.tolist())


LAS_HEADER_SIZE = {0: 227, 1: 227, 2: 227, 3: 235, 4: 375}


def las_bytes(points: np.ndarray, *, minor: int = 2, format_id: int = 1, scale=(0.001, 0.001, 0.001),
              offset=(0.0, 0.0, 0.0), record_length: Optional[int] = None, legacy_count: Optional[int] = None,
              count64: Optional[int] = None) -> bytes:
    """An uncompressed LAS 1.``minor`` file of ``points`` (m) in point data record format
    ``format_id``, the coordinates stored as X = round((x - offset) / scale), with one variable
    length record (a projection's, not read) before the points."""
    size = LAS_HEADER_SIZE[minor]
    record_length = record_length or LAS_MIN_RECORD_LENGTH[format_id]
    vlr = struct.pack("<H16sHH32s", 0, b"LASF_Projection", 34735, 8, b"GeoKeyDirectoryTag") + bytes(8)
    n = len(points)
    if legacy_count is None:
        legacy_count = n if format_id < 6 else 0
    header = bytearray(size)
    header[0:4] = b"LASF"
    struct.pack_into("<BB32s32s", header, 24, 1, minor, b"test", b"test_scan_formats")
    struct.pack_into("<HIIBHI", header, 94, size, size + len(vlr), 1, format_id, record_length, legacy_count)
    struct.pack_into("<6d", header, 131, *scale, *offset)
    lo, hi = points.min(axis=0), points.max(axis=0)
    struct.pack_into("<6d", header, 179, hi[0], lo[0], hi[1], lo[1], hi[2], lo[2])
    if minor >= 4:
        struct.pack_into("<Q", header, 247, n if count64 is None else count64)
    ints = np.round((points - np.asarray(offset)) / np.asarray(scale)).astype(np.int64)
    records = b"".join(struct.pack("<3i", *row) + bytes(record_length - 12) for row in ints.tolist())
    return bytes(header) + vlr + records


def write(path: Path, content) -> Path:
    if isinstance(content, str):
        path.write_text(content)
    else:
        path.write_bytes(content)
    return path


# ---------------------------------------------------------------------------------------------
# The same cloud from every format
# ---------------------------------------------------------------------------------------------

XYZ_FLOAT = [("float", "x"), ("float", "y"), ("float", "z")]
MIXED = [("float", "intensity"), ("double", "z"), ("uchar", "red"), ("double", "x"), ("uchar", "green"),
         ("uchar", "blue"), ("double", "y")]
FAR = np.array([512345.0, 5412345.0, 100.0])  # map (UTM) coordinates

# name, file name, the file's content from the cloud, how far a point may lie from it (m)
FORMATS = [
    ("text", "scan.xyz", lambda p: format_xyz(p), 0.0),
    ("pts with intensity and colour", "scan.pts",
     lambda p: f"{len(p)}\n" + "".join(f"{x!r} {y!r} {z!r} -1200 210 180 150\n" for x, y, z in p.tolist()), 0.0),
    ("ascii ply", "scan.ply", ascii_ply_text, 0.0),
    ("binary ply, little-endian float", "scan.ply", lambda p: ply_bytes(p, order="<", properties=XYZ_FLOAT), 0.0),
    ("binary ply, big-endian float", "scan.ply", lambda p: ply_bytes(p, order=">", properties=XYZ_FLOAT), 0.0),
    ("binary ply, little-endian double among intensity and colour", "scan.ply",
     lambda p: ply_bytes(p, order="<", properties=MIXED), 0.0),
    ("binary ply, big-endian double among intensity and colour", "scan.ply",
     lambda p: ply_bytes(p, order=">", properties=MIXED), 0.0),
    ("binary ply, float32 names, normals, faces after", "scan.ply",
     lambda p: ply_bytes(p, properties=[("float32", "x"), ("float32", "y"), ("float32", "z"), ("float32", "nx"),
                                        ("float32", "ny"), ("float32", "nz")], faces=True), 0.0),
    ("binary ply, a fixed-size element before the vertices", "scan.ply",
     lambda p: ply_bytes(p, order=">", leading=("element camera 2\nproperty double view_x\nproperty uchar id",
                                                struct.pack(">dBdB", 1.5, 1, 2.5, 2))), 0.0),
    ("binary ply, a list element before the vertices", "scan.ply",
     lambda p: ply_bytes(p, leading=("element range_grid 3\nproperty list uchar int vertex_indices\nproperty short row",
                                     struct.pack("<B2ih", 2, 5, 6, 0) + struct.pack("<Bh", 0, 1)
                                     + struct.pack("<B3ih", 3, 7, 8, 9, 2))), 0.0),
    ("las 1.0 format 0", "scan.las", lambda p: las_bytes(p, minor=0, format_id=0), 0.0005),
    ("las 1.2 format 1, offsets", "scan.las",
     lambda p: las_bytes(p, format_id=1, offset=(-1.25, 2.5, 0.125)), 0.0005),
    ("las 1.3 format 3, scale 0.01 mm", "scan.las",
     lambda p: las_bytes(p, minor=3, format_id=3, scale=(1e-5, 1e-5, 1e-5)), 5e-6),
    ("las 1.4 format 6", "scan.las", lambda p: las_bytes(p, minor=4, format_id=6, offset=(10.0, -20.0, 3.0)), 0.0005),
    ("las 1.4 format 10 with extra bytes, no suffix", "scan",
     lambda p: las_bytes(p, minor=4, format_id=10, record_length=LAS_MIN_RECORD_LENGTH[10] + 6), 0.0005),
]


@pytest.mark.parametrize("name, filename, make, tolerance", FORMATS, ids=[f[0] for f in FORMATS])
def test_the_same_cloud_reads_alike_from_every_format(tmp_path: Path, name: str, filename: str, make,
                                                      tolerance: float) -> None:
    """A scan written as text, .pts, PLY (ASCII, binary of both byte orders, float or double
    coordinates among other properties, elements before and after the vertices) or LAS (formats
    0-10, scales and offsets) reads as the same points: exactly, or to half the LAS scale."""
    points = cloud()
    path = write(tmp_path / filename, make(points))
    got = read_xyz(path)
    assert got.shape == points.shape and got.dtype == np.float64
    assert np.max(np.abs(got - points)) <= tolerance * (1 + 1e-9), name


def test_a_las_scan_in_map_coordinates_reads_to_the_millimetre_and_grids_as_its_text(tmp_path: Path) -> None:
    """A scan in map (UTM) coordinates, stored as LAS in millimetres about an offset at the site,
    reads to half a millimetre, and its grid's heights are those of its text's grid to 1.5 mm: the
    half millimetre in z, in x-y times the mound's slope (up to 0.4), and the triangles the
    moved points make (2,000 points on the mound, without noise)."""
    points = cloud(n=2000, noise=0.0) + FAR
    las = write(tmp_path / "scan.las", las_bytes(points, minor=4, format_id=6, offset=(512000.0, 5412000.0, 0.0)))
    text = write(tmp_path / "scan.xyz", format_xyz(points))
    from_las, from_text = read_xyz(las), read_xyz(text)
    assert np.max(np.abs(from_las - from_text)) <= 0.0005 + 1e-9
    a, b = grid_from_points(from_las, cell=0.1), grid_from_points(from_text, cell=0.1)
    assert a.z.shape == b.z.shape
    assert abs(a.x0 - b.x0) <= 0.0005 + 1e-9 and abs(a.y0 - b.y0) <= 0.0005 + 1e-9
    inside = ~(a.filled | b.filled)
    assert inside.mean() > 0.8
    X, Y = np.meshgrid(b.x, b.y)
    assert np.max(np.abs(a.height(X, Y) - b.z)[inside]) < 0.0015


@pytest.mark.parametrize("order", ["<", ">"])
@pytest.mark.parametrize("ply_type", sorted(PLY_TYPES))
def test_every_ply_scalar_type_holds_the_coordinates(tmp_path: Path, ply_type: str, order: str) -> None:
    """x, y, z of any PLY scalar type, in either byte order, read as their values."""
    points = np.array([[0, 0, 1], [1, 0, 2], [0, 1, 3], [2, 2, 0], [3, 1, 5]], dtype=float)
    props = [("uchar", "red"), (ply_type, "y"), (ply_type, "x"), ("ushort", "green"), (ply_type, "z")]
    path = write(tmp_path / "ints.ply", ply_bytes(points, order=order, properties=props))
    np.testing.assert_array_equal(read_xyz(path), points)


def test_a_pts_file_of_one_point_per_line_needs_no_count(tmp_path: Path) -> None:
    """A .pts file without its count line is text like any other."""
    points = cloud(20)
    path = write(tmp_path / "scan.pts", "".join(f"{x!r} {y!r} {z!r} 12\n" for x, y, z in points.tolist()))
    np.testing.assert_array_equal(read_xyz(path), points)


# ---------------------------------------------------------------------------------------------
# Refusals: the file and the fault
# ---------------------------------------------------------------------------------------------

def refusal(path: Path) -> str:
    """The message of read_xyz's refusal of ``path``, which must name it, and leave it as it was."""
    before = path.read_bytes()
    with pytest.raises(InputError) as info:
        read_xyz(path)
    message = str(info.value)
    assert message.startswith(str(path)), message
    assert path.read_bytes() == before
    return message


@pytest.mark.parametrize("count, says", [(5, "announces 5 points (a .pts point count), the file holds 4 point lines"),
                                         (3, "announces 3 points (a .pts point count), the file holds 4 point lines")])
def test_a_pts_count_other_than_its_lines_is_refused_naming_both(tmp_path: Path, count: int, says: str) -> None:
    path = write(tmp_path / "scan.pts", f"{count}\n0 0 0 1\n1 0 0 1\n0 1 0 1\n1 1 1 1\n")
    message = refusal(path)
    assert says in message and ", line 1:" in message, message


def test_a_pts_file_with_a_broken_line_is_refused_at_that_line(tmp_path: Path) -> None:
    path = write(tmp_path / "scan.pts", "4\n0 0 0 1\n1 0 0\n0 1 0 1\n1 1 1 1\n")
    message = refusal(path)
    assert "line 3: expected 4 fields, as the first point's line has, found 3" in message, message


def test_a_count_line_after_the_first_line_is_a_broken_line(tmp_path: Path) -> None:
    path = write(tmp_path / "scan.xyz", "0 0 0\n3\n1 0 0\n0 1 0\n")
    assert "line 2: expected 3 fields" in refusal(path)


def test_a_truncated_binary_ply_names_the_vertices_announced_and_found(tmp_path: Path) -> None:
    """20 vertices of three floats announced, the body cut after 8 and a half."""
    data = ply_bytes(cloud(20))
    path = write(tmp_path / "cut.ply", data[: len(data) - 11 * 12 - 6])
    message = refusal(path)
    assert "PLY file ends early: 20 vertices of 12 bytes announced from byte offset" in message, message
    assert "(240 bytes), the file holds 102 bytes from there (8 whole vertices)" in message, message


def test_a_binary_ply_cut_in_an_element_before_the_vertices_is_refused(tmp_path: Path) -> None:
    data = ply_bytes(cloud(3)[:0], leading=("element range_grid 2\nproperty list uchar int vertex_indices",
                                             struct.pack("<B2i", 2, 5, 6) + struct.pack("<B3i", 3, 7, 8, 9)))
    path = write(tmp_path / "cut.ply", data[:-4])
    message = refusal(path)
    assert "element 'range_grid' announces 2 records" in message and "ends in record 2" in message, message


@pytest.mark.parametrize(
    "header, says",
    [("property list uchar float x\nproperty float y\nproperty float z",
      "line 5: PLY vertex element has a list property 'x', which is not read"),
     ("property int64 x\nproperty float y\nproperty float z", "line 5: PLY property type 'int64' is unknown"),
     ("property float x\nproperty float y", "line 4: PLY vertex element lacks properties ['z']")],
)
def test_a_binary_ply_vertex_element_it_cannot_read_is_refused_at_its_header_line(tmp_path: Path, header: str,
                                                                                   says: str) -> None:
    text = f"ply\nformat binary_little_endian 1.0\ncomment x\nelement vertex 1\n{header}\nend_header\n"
    path = write(tmp_path / "odd.ply", text.encode("ascii") + bytes(16))
    message = refusal(path)
    assert says in message, message


def test_a_non_finite_binary_ply_vertex_is_refused_with_its_byte_offset(tmp_path: Path) -> None:
    points = cloud(3)
    points[1, 2] = np.nan
    data = ply_bytes(points)
    path = write(tmp_path / "nan.ply", data)
    body = len(data) - 36
    assert f"PLY vertex 2 of 3 (byte offset {body + 12}) has a non-finite coordinate" in refusal(path)


def las_edit(data: bytes, offset: int, fmt: str, *values) -> bytes:
    out = bytearray(data)
    struct.pack_into(fmt, out, offset, *values)
    return bytes(out)


LAS_REFUSALS = [
    ("not LAS", lambda d: b"LASG" + d[4:], "not a LAS file: it starts with b'LASG', not the signature b'LASF'"),
    ("compressed", lambda d: las_edit(d, 104, "<B", 0x80 | 1),
     "the point data format id 129 has LASzip's compression bit set: the file is LAZ (compressed LAS), which is not "
     "read: decompress it to LAS first (e.g. `laszip"),
    ("unknown format", lambda d: las_edit(d, 104, "<B", 11), "LAS point data record format 11 is unknown"),
    ("short record", lambda d: las_edit(d, 105, "<H", 20),
     "the point data record length is 20 bytes, shorter than point data record format 1's 28"),
    ("cut", lambda d: d[:-30],
     "LAS file ends early: 50 point records of 28 bytes announced from byte offset 289 (1400 bytes), the file holds "
     "1370 bytes from there (48 whole records)"),
    ("version", lambda d: las_edit(d, 24, "<BB", 2, 0), "LAS version 2.0 is not read (1.0-1.4 are)"),
    ("header size", lambda d: las_edit(d, 94, "<H", 200), "the LAS 1.2 header size is 200 bytes, less than the format's 227"),
    ("points in the header", lambda d: las_edit(d, 96, "<I", 100),
     "the offset to point data, byte 100, lies inside the 227-byte public header"),
    ("zero scale", lambda d: las_edit(d, 139, "<d", 0.0), "the y scale factor and offset must be finite and the scale nonzero"),
    ("header cut", lambda d: d[:200], "LAS file ends in its public header: it holds 200 bytes, the header alone 227"),
]


@pytest.mark.parametrize("fault, edit, says", LAS_REFUSALS, ids=[r[0] for r in LAS_REFUSALS])
def test_a_las_file_it_cannot_read_is_refused_naming_the_fault(tmp_path: Path, fault: str, edit, says: str) -> None:
    path = write(tmp_path / "scan.las", edit(las_bytes(cloud(50))))
    message = refusal(path)
    assert says in message, message


def test_las_1_4_point_counts_that_disagree_are_refused(tmp_path: Path) -> None:
    path = write(tmp_path / "scan.las", las_bytes(cloud(50), minor=4, format_id=1, legacy_count=50, count64=49))
    assert "the LAS header's point counts disagree: legacy 50, 64-bit 49" in refusal(path)


def test_las_1_4_reads_the_64_bit_count_where_the_legacy_count_is_zero(tmp_path: Path) -> None:
    points = cloud(50)
    path = write(tmp_path / "scan.las", las_bytes(points, minor=4, format_id=1, legacy_count=0))
    assert read_xyz(path).shape == (50, 3)


@pytest.mark.parametrize("filename, content, says", [
    ("scan.laz", b"LASF" + bytes(400), "LAZ (compressed LAS) is not read: decompress it to LAS first"),
    ("scan.e57", b"ASTM-E57" + bytes(100), "E57 is not read: export the scan as LAS, PLY or 'x y z' text"),
    ("scan.bin", b"ASTM-E57" + bytes(100), "E57 is not read"),
    ("scan.dat", b"\x00\x01\xff\xfe" * 10, "line 1: not UTF-8 text (byte 0xff): a scan is read from LAS, PLY or 'x y z' text files"),
])
def test_a_format_it_does_not_read_is_refused_saying_what_to_do(tmp_path: Path, filename: str, content: bytes,
                                                                says: str) -> None:
    path = write(tmp_path / filename, content)
    message = refusal(path)
    assert says in message, message


# ---------------------------------------------------------------------------------------------
# A campaign whose scan is LAS
# ---------------------------------------------------------------------------------------------

def las_campaign(root: Path, points: np.ndarray, shift: tuple[float, float] = (0.0, 0.0)) -> None:
    """The test campaign with its scan written as LAS 1.4, format 6, and the terrain run's
    positions moved by ``shift`` (m)."""
    manifest = make_manifest()
    manifest["runs"][2]["terrain"] = "terrain/scan.las"
    runs = make_runs()
    runs["t3d"]["pos_x"] = runs["t3d"]["pos_x"] + shift[0]
    runs["t3d"]["pos_y"] = runs["t3d"]["pos_y"] + shift[1]
    write_campaign(root, manifest, runs, extra_files={
        "terrain/scan.las": las_bytes(points, minor=4, format_id=6, offset=(0.0, 0.0, 0.0))})


def test_a_campaign_whose_scan_is_las_loads_and_passes_the_scan_checks(tmp_path: Path) -> None:
    """The manifest's terrain key names a LAS file: the campaign loads, its scan reads to the
    millimetre, and the plausibility checks (the scan's outliers, the path on the scan) find nothing."""
    from juno.plausibility import check_campaign

    points = wide_terrain()
    las_campaign(tmp_path / "camp", points)
    campaign = load_campaign(tmp_path / "camp")
    assert campaign.run("t3d").terrain == "terrain/scan.las"
    assert np.max(np.abs(read_terrain_points(campaign, "t3d") - points)) <= 0.0005 + 1e-9
    assert check_campaign(campaign) == []


def test_a_las_scan_in_feet_is_named_as_such_by_the_scan_check(tmp_path: Path) -> None:
    """A LAS file's lengths are its coordinate system's, metres or feet; they are read as metres.
    A site 360 m from its frame's origin scanned in feet lies 1,180 "m" from it, off the path
    measured in metres: the plausibility error says the scan looks like it is in feet."""
    from juno.plausibility import check_campaign

    site = np.array([300.0, 200.0, 0.0])
    las_campaign(tmp_path / "camp", (wide_terrain() + site) / 0.3048, shift=(site[0], site[1]))
    errors = [f for f in check_campaign(load_campaign(tmp_path / "camp")) if f.severity == "error"]
    assert [(f.file, f.column) for f in errors] == [("runs/t3d.csv", "pos_x")]
    assert "terrain/scan.las" in errors[0].message and "the scan looks like it is in feet" in errors[0].message


# ---------------------------------------------------------------------------------------------
# A text scan read as one table: the points of the line-by-line reading, bit for bit
# ---------------------------------------------------------------------------------------------

def shortest(points: np.ndarray) -> list[str]:
    """Each point's coordinates as the shortest decimals that round-trip (17 significant digits
    at most), the hardest for a reader to get bit for bit."""
    return [" ".join(repr(float(v)) for v in p) for p in points]


def _exact_cloud() -> np.ndarray:
    rng = np.random.default_rng(11)
    return cloud(200) + rng.normal(0.0, 1e-7, (200, 3)) * 10.0 ** rng.uniform(-3, 6, (200, 1))


TABLES = {
    "spaces and extra fields": lambda p: "\n".join(f"{line} 120 7 8 9" for line in shortest(p)) + "\n",
    "an x y z header": lambda p: "//X Y Z Intensity\n" + "\n".join(f"{line} 0.5" for line in shortest(p)),
    "a pts count and a header": lambda p: f"{len(p)}\nx y z\n" + "\n".join(shortest(p)) + "\n",
    "commas and spaces around them": lambda p: "\n".join(", ".join(line.split()) for line in shortest(p)),
    "Windows line ends, tabs": lambda p: "\r\n".join("\t".join(line.split()) for line in shortest(p)) + "\r\n",
    "comments and blank lines inside": lambda p: "\n\n".join(f"{line}  # ok" for line in shortest(p)),
    "comment and blank lines first": lambda p: "# x y z (m)\n\n# site 4\n" + "\n".join(shortest(p)) + "\n",
    "a blank line first": lambda p: "\n" + "\n".join(shortest(p)) + "\n",
}


@pytest.mark.parametrize("form", TABLES)
def test_a_plain_text_table_is_read_at_once_as_line_by_line(form: str) -> None:
    """A scan of millions of points is read by NumPy's table reader in one pass; where it reads
    the file at all, its points are the line-by-line reading's to the last bit."""
    from juno.scan_formats import _parse_text_lines, _parse_text_table, parse_text
    points = _exact_cloud()
    text = TABLES[form](points)
    table = _parse_text_table(text)
    assert table is not None, "the table reader declined a plain table"
    lines = _parse_text_lines(Path("scan.xyz"), text)
    assert table.tobytes() == lines.tobytes() == np.ascontiguousarray(points).tobytes()
    assert parse_text(Path("scan.xyz"), text).tobytes() == lines.tobytes()


DECLINED = {
    # what the table reader cannot read alike: the line-by-line reading reads it, or names the line
    "old Mac line ends": ("1 2 3\r4 5 6\r", None),
    "commas on one line, spaces on the next": ("1,2,3\n4 5 6\n", None),
    "a comment line first, then commas and spaces": ("# x y z\n1,2,3\n4 5 6\n", None),
    "digits of another script": ("\u0661 2 3\n4 5 6\n", "not a number"),
    "a digit separator": ("1_000 2 3\n", "not a number"),
    "a point short of a field": ("1 2 3 9\n4 5 6\n", "expected 4 fields"),
    "a z of nan": ("1 2 3\n4 5 nan\n", "not finite"),
    "a pts count off by one": ("3\n1 2 3\n4 5 6\n", "announces 3 points"),
    "only two columns": ("1 2\n3 4\n", "expected 3 numbers"),
}


@pytest.mark.parametrize("form", DECLINED)
def test_a_text_the_table_reader_would_misread_is_read_line_by_line(form: str) -> None:
    """Line breaks other than a newline, mixed separators, what float() reads and the format's
    numbers are not, and every fault: the table reader declines, and the line-by-line reading
    reads the points or names the line at fault."""
    from juno.scan_formats import _parse_text_table, parse_text
    text, says = DECLINED[form]
    assert _parse_text_table(text) is None
    if says is None:
        assert parse_text(Path("scan.xyz"), text).tolist() == [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]
    else:
        with pytest.raises(InputError, match=says):
            parse_text(Path("scan.xyz"), text)
