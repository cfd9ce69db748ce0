"""The file formats a LIDAR scan is read from: text (and Leica ``.pts``), PLY and LAS.

:func:`parse_scan` turns a scan file's bytes into an (N, 3) float array of x, y, z (m). The
reader is chosen by the file's first bytes, and only where they name no format by its suffix:

- ``LASF`` (the LAS signature) at byte 0, or a name ending ``.las``: LAS (ASPRS) 1.0-1.4,
  uncompressed, point data record formats 0-10 (:func:`parse_las`). A name ending ``.laz`` or a
  point data format id with bit 7 or 6 set (LASzip's mark of a compressed file) is LAZ: refused,
  to be decompressed first.
- a first line ``ply``, or a name ending ``.ply``: PLY, ASCII or binary of either byte order
  (:func:`parse_ply`).
- ``ASTM-E57`` at byte 0, or a name ending ``.e57``: E57, refused with what to export instead.
- anything else: text, ``x y z`` per line (:func:`parse_text`), a Leica ``.pts`` count line
  allowed first.

Every refusal is an :class:`~juno.errors.InputError` naming the file and where the fault lies:
the line of a text file or of a header, the byte offset in a binary body.
"""

from __future__ import annotations

import io
import math
import re
import struct
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

import numpy as np
from numpy.typing import NDArray

from .errors import InputError, decode_input_text, parse_finite

__all__ = ["parse_scan", "parse_text", "parse_ply", "parse_las", "LAS_MIN_RECORD_LENGTH"]

FloatArray = NDArray[np.float64]

#: What to do with a scan in a format that is not read.
_CONVERT = "export the scan as LAS, PLY or 'x y z' text (e.g. with CloudCompare or `pdal translate`)"


def parse_scan(path: Path, data: bytes) -> FloatArray:
    """The (N, 3) points (m) of a scan file's bytes, by its format (see the module's docstring).

    Raises:
        InputError: the file breaks its format, or is in a format not read.
    """
    suffix = path.suffix.lower()
    if suffix == ".laz":
        raise InputError(f"LAZ (compressed LAS) is not read: {_DECOMPRESS}", path)
    if data[:4] == b"LASF" or suffix == ".las":
        return parse_las(path, data)
    if data[:4] in (b"ply\n", b"ply\r") or suffix == ".ply":
        return parse_ply(path, data)
    if data[:8] == b"ASTM-E57" or suffix == ".e57":
        raise InputError(f"E57 is not read: {_CONVERT}", path)
    try:
        text = decode_input_text(path, data)
    except InputError as e:
        raise InputError(f"{e.message}: a scan is read from LAS, PLY or 'x y z' text files", path, e.line) from None
    return parse_text(path, text)


# --------------------------------------------------------------------------------------------
# Text: x y z per line; Leica .pts
# --------------------------------------------------------------------------------------------

_SEP_RE = re.compile(r"\s*,\s*|\s+")
_COUNT_RE = re.compile(r"[0-9]{1,15}")
#: The ASCII line breaks str.splitlines splits at besides a newline.
_OTHER_LINE_BREAK = re.compile("[\r\x0b\x0c\x1c\x1d\x1e]")


def parse_text(path: Path, text: str) -> FloatArray:
    """x, y, z (m) from the first three fields of every line.

    Exports often add fields (intensity, colour) and a header line naming them (``//X Y Z
    Intensity``): the first line may be such a header, and fields beyond the third are left out,
    as extra CSV columns are; every point's line must have as many fields as the first, so a
    broken line is not read as a point. A Leica ``.pts`` file starts with a line holding the
    number of points alone: a first line that is a single non-negative integer is read as that
    count, and the file must then hold exactly that many point lines.

    A scan of millions of points is read by NumPy's table reader in one pass (about a tenth of
    the time of a line at a time in Python) wherever the file is a plain table of finite numbers;
    anything else is read line by line, which gives the same points and names the line at fault.
    """
    whole = _parse_text_table(text)
    return whole if whole is not None else _parse_text_lines(path, text)


def _parse_text_table(text: str) -> Optional[FloatArray]:
    """parse_text's points read as one table (np.loadtxt), or None wherever the line-by-line
    reading must decide: a first line parse_text reads otherwise that is not the count or the
    header it skips, separators the table reader does not split alike (commas on some lines,
    spaces on others), fields it does not read as numbers, a changing number of fields, a
    non-finite x, y or z, or a count line the points do not match.  Where it reads the file, it
    reads every number as Python's float() does, so the points are those of the line-by-line
    reading bit for bit."""
    if "\r\n" in text:
        text = text.replace("\r\n", "\n")
    if not text.isascii() or _OTHER_LINE_BREAK.search(text):
        # Digits of other scripts (which float() reads and the format's numbers are not), and
        # line breaks other than a newline, which the line-by-line reading splits at and the
        # table reader does not.
        return None

    def line_at(start: int) -> tuple[list[str], int]:
        """The fields of the line starting at ``start`` (its comment left out), and where the
        next line starts."""
        end = text.find("\n", start)
        line = (text[start:] if end < 0 else text[start:end]).split("#", 1)[0].strip()
        return (_SEP_RE.split(line) if line else []), (len(text) if end < 0 else end + 1)

    start, announced = 0, None
    tokens, after = line_at(start)
    # Blank and comment lines before the first (as ``juno synthesize`` and many exporters start a
    # file with "# x y z"): the line-by-line reading skips them, and so does this one.
    while not tokens and after < len(text):
        start = after
        tokens, after = line_at(start)
    if len(tokens) == 1 and _COUNT_RE.fullmatch(tokens[0]):
        announced, start = int(tokens[0]), after
        tokens, after = line_at(start)
    if not tokens:
        return None      # a blank or comment line after a count: the line-by-line reading decides
    if _is_xyz_header(tokens):
        start = after
    body = text[start:]
    end = body.find("\n")
    delimiter = "," if "," in (body if end < 0 else body[:end]) else None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")          # "input contained no data" among them
            table = np.loadtxt(io.StringIO(body), dtype=float, delimiter=delimiter, comments="#", ndmin=2)
    except (ValueError, UserWarning):
        return None
    if table.shape[1] < 3 or not table.shape[0] or not np.isfinite(table[:, :3]).all():
        return None
    if announced is not None and announced != table.shape[0]:
        return None
    return np.ascontiguousarray(table[:, :3])


def _parse_text_lines(path: Path, text: str) -> FloatArray:
    """parse_text one line at a time: the reading that names the line at fault."""
    rows: list[tuple[float, float, float]] = []
    fields: Optional[int] = None
    announced: Optional[tuple[int, int]] = None  # (the count line's number of points, its line)
    first = True
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        tokens = _SEP_RE.split(line)
        if first and len(tokens) == 1 and _COUNT_RE.fullmatch(tokens[0]):
            announced = (int(tokens[0]), lineno)
            first = False
            continue
        first = False
        if fields is None and not rows and _is_xyz_header(tokens):
            continue
        if len(tokens) < 3 or (fields is not None and len(tokens) != fields):
            expected = "3 numbers 'x y z'" if fields is None else f"{fields} fields, as the first point's line has"
            raise InputError(f"expected {expected}, found {len(tokens)} fields: {line[:60]!r}", path, lineno)
        fields = len(tokens)
        x, y, z = (parse_finite(t, path, lineno, name) for t, name in zip(tokens, "xyz"))
        rows.append((x, y, z))
    if announced is not None and announced[0] != len(rows):
        raise InputError(
            f"the first line announces {announced[0]} points (a .pts point count), the file holds {len(rows)} point lines",
            path, announced[1],
        )
    return np.array(rows, dtype=float).reshape(-1, 3)


def _is_xyz_header(tokens: list[str]) -> bool:
    """Whether a line's fields name the columns, the first three x, y and z (any case, a leading
    ``//`` as some exporters write it)."""
    names = [tok.lstrip("/").strip().lower() for tok in tokens]
    return len(names) >= 3 and names[:3] == ["x", "y", "z"]


# --------------------------------------------------------------------------------------------
# PLY
# --------------------------------------------------------------------------------------------

#: PLY's scalar types, both spellings, as NumPy type codes without the byte order.
PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}

_PLY_FORMATS = ("ascii", "binary_little_endian", "binary_big_endian")


@dataclass
class _PlyProperty:
    """A property of a PLY element: a scalar (``count_type`` None) or a list."""

    name: str
    type: str
    count_type: Optional[str]
    line: int


@dataclass
class _PlyElement:
    name: str
    count: int
    line: int
    properties: list[_PlyProperty] = field(default_factory=list)


@dataclass
class _PlyHeader:
    format: str
    elements: list[_PlyElement]
    body: int  # byte offset of the body
    lines: int  # number of header lines, ``end_header`` included


def parse_ply(path: Path, data: bytes) -> FloatArray:
    """The vertex element's x, y, z of a PLY file, ASCII or binary (either byte order).

    The vertex properties may be of any PLY scalar type, in any order, among others (intensity,
    colour, normals). Elements before the vertices are skipped (in a binary file, a list
    property's records are walked through); elements after them (faces) are not read.
    """
    header = _ply_header(path, data)
    if header.format == "ascii":
        return _ply_ascii(path, data, header)
    return _ply_binary(path, data, header)


def _ply_header(path: Path, data: bytes) -> _PlyHeader:
    """The header's format and elements; the header ends at the line ``end_header``."""
    body = None
    pos = 0
    while pos < len(data):
        nl = data.find(b"\n", pos)
        end = len(data) if nl < 0 else nl
        if data[pos:end].rstrip(b"\r").strip() == b"end_header":
            body = end + 1
            break
        pos = end + 1
    if not data.startswith(b"ply") or body is None:
        raise InputError("not a PLY file (needs a 'ply' first line and 'end_header')", path, 1)
    lines = decode_input_text(path, data[:body]).splitlines()
    elements: list[_PlyElement] = []
    fmt = None
    for lineno, raw in enumerate(lines, start=1):
        tok = raw.split()
        if not tok or tok[0] in ("ply", "comment", "obj_info", "end_header"):
            continue
        if tok[0] == "format":
            fmt = tok[1] if len(tok) > 1 else ""
            if fmt not in _PLY_FORMATS:
                raise InputError(f"PLY format {fmt!r} is not read (ascii, binary_little_endian and "
                                 f"binary_big_endian are): {_CONVERT}", path, lineno)
        elif tok[0] == "element" and len(tok) == 3 and re.fullmatch(r"[0-9]{1,12}", tok[2]):
            elements.append(_PlyElement(tok[1], int(tok[2]), lineno))
        elif tok[0] == "property" and elements and len(tok) == 3:
            elements[-1].properties.append(_PlyProperty(tok[2], tok[1], None, lineno))
        elif tok[0] == "property" and elements and len(tok) == 5 and tok[1] == "list":
            elements[-1].properties.append(_PlyProperty(tok[4], tok[3], tok[2], lineno))
        else:
            raise InputError(f"bad PLY header line: {raw.strip()[:60]!r}", path, lineno)
    if fmt is None:
        raise InputError("PLY header has no 'format' line", path)
    return _PlyHeader(fmt, elements, body, len(lines))


def _xyz_columns(path: Path, vertex: _PlyElement) -> list[int]:
    """The indices of x, y and z among the vertex element's properties."""
    names = [prop.name for prop in vertex.properties]
    missing = [c for c in "xyz" if c not in names]
    if missing:
        raise InputError(f"PLY vertex element lacks properties {missing}", path, vertex.line)
    return [names.index(c) for c in "xyz"]


def _ply_ascii(path: Path, data: bytes, header: _PlyHeader) -> FloatArray:
    """ASCII PLY: a record per line; the lines of elements before the vertices are skipped."""
    lines = decode_input_text(path, data[header.body:]).splitlines()
    body_start_line = header.lines + 1
    skip = 0
    for element in header.elements:
        if element.name != "vertex":
            skip += element.count
            continue
        idx = _xyz_columns(path, element)
        count = element.count
        if len(lines) < skip + count:
            raise InputError(f"PLY file ends early: {count} vertices announced", path, body_start_line + len(lines))
        out = np.empty((count, 3))
        for k in range(count):
            lineno = body_start_line + skip + k
            tok = lines[skip + k].split()
            if len(tok) != len(element.properties):
                raise InputError(f"expected {len(element.properties)} vertex values, found {len(tok)}", path, lineno)
            for j, (i, c) in enumerate(zip(idx, "xyz")):
                out[k, j] = parse_finite(tok[i], path, lineno, c)
        return out
    raise InputError("PLY file has no 'element vertex'", path)


def _ply_type(path: Path, name: str, line: int, order: str) -> np.dtype:
    """The NumPy type of a PLY scalar type name, in the body's byte order."""
    code = PLY_TYPES.get(name)
    if code is None:
        raise InputError(f"PLY property type {name!r} is unknown (PLY's are {', '.join(PLY_TYPES)})", path, line)
    return np.dtype(order + code)


def _ply_binary(path: Path, data: bytes, header: _PlyHeader) -> FloatArray:
    """Binary PLY: elements before the vertices skipped, then the vertices' x, y, z."""
    order = "<" if header.format == "binary_little_endian" else ">"
    offset = header.body
    for element in header.elements:
        if element.name == "vertex":
            return _ply_binary_vertices(path, data, element, offset, order)
        offset = _skip_ply_element(path, data, element, offset, order)
    raise InputError("PLY file has no 'element vertex'", path)


def _skip_ply_element(path: Path, data: bytes, element: _PlyElement, offset: int, order: str) -> int:
    """The byte offset just past an element's records in a binary body.  Records of scalars have
    one size; a list property's record holds its own length, so those records are walked."""
    sizes = [_ply_type(path, p.type, p.line, order).itemsize for p in element.properties]
    lists = [p for p in element.properties if p.count_type is not None]
    if not lists:
        end = offset + element.count * sum(sizes)
        if end > len(data):
            raise InputError(
                f"PLY file ends early: element {element.name!r} announces {element.count} records of {sum(sizes)} "
                f"bytes from byte offset {offset} ({end - offset} bytes), the file holds {len(data) - offset}", path)
        return end
    counts = {p.name: _ply_type(path, p.count_type, p.line, order) for p in lists}
    pos = offset
    for k in range(element.count):
        for prop, size in zip(element.properties, sizes):
            if prop.count_type is None:
                pos += size
                continue
            ctype = counts[prop.name]
            if pos + ctype.itemsize > len(data):
                pos = len(data) + 1
                break
            n = int(np.frombuffer(data, ctype, count=1, offset=pos)[0])
            if n < 0:
                raise InputError(f"PLY element {element.name!r}, record {k + 1}: list {prop.name!r} has a negative "
                                 f"length {n} (byte offset {pos})", path)
            pos += ctype.itemsize + n * size
        if pos > len(data):
            raise InputError(
                f"PLY file ends early: element {element.name!r} announces {element.count} records from byte offset "
                f"{offset}, the file ends in record {k + 1} (the file holds {len(data)} bytes)", path)
    return pos


def _ply_binary_vertices(path: Path, data: bytes, vertex: _PlyElement, offset: int, order: str) -> FloatArray:
    """The vertices' x, y, z (as float64) from a binary body starting at ``offset``."""
    idx = _xyz_columns(path, vertex)
    for prop in vertex.properties:
        if prop.count_type is not None:
            raise InputError(f"PLY vertex element has a list property {prop.name!r}, which is not read: "
                             f"{_CONVERT}", path, prop.line)
    types = [_ply_type(path, p.type, p.line, order) for p in vertex.properties]
    record = np.dtype({"names": [f"p{i}" for i in range(len(types))], "formats": types})
    count, size = vertex.count, record.itemsize
    need, held = count * size, len(data) - offset
    if held < need:
        raise InputError(
            f"PLY file ends early: {count} vertices of {size} bytes announced from byte offset {offset} "
            f"({need} bytes), the file holds {held} bytes from there ({held // size} whole vertices)", path)
    if count == 0:
        return np.empty((0, 3))
    body = np.frombuffer(data, record, count=count, offset=offset)
    points = np.column_stack([body[f"p{i}"].astype(np.float64) for i in idx])
    bad = ~np.isfinite(points).all(axis=1)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise InputError(f"PLY vertex {k + 1} of {count} (byte offset {offset + k * size}) has a non-finite "
                         f"coordinate: {points[k].tolist()}", path)
    return points


# --------------------------------------------------------------------------------------------
# LAS
# --------------------------------------------------------------------------------------------

#: The shortest point data record (bytes) of each LAS point data record format, 0-10.
LAS_MIN_RECORD_LENGTH = (20, 28, 26, 34, 57, 63, 30, 36, 38, 59, 67)

#: The public header's size (bytes) in LAS 1.0-1.4, by minor version.
_LAS_HEADER_SIZE = {0: 227, 1: 227, 2: 227, 3: 235, 4: 375}

_DECOMPRESS = "decompress it to LAS first (e.g. `laszip -i scan.laz -o scan.las` or `pdal translate scan.laz scan.las`)"


def parse_las(path: Path, data: bytes) -> FloatArray:
    """x, y, z (m) of an uncompressed LAS 1.0-1.4 file, point data record formats 0-10.

    Every record starts with X, Y, Z as little-endian int32; a coordinate is ``X * scale +
    offset``, with the header's scale factor and offset of its axis. The number of records is
    the header's legacy 32-bit count, or in LAS 1.4 its 64-bit count (the two must agree where
    both are given). The lengths are the coordinate system's units, which the file states (if at
    all) in a variable length record that is not read: the harness takes them as metres.
    """
    if data[:4] != b"LASF":
        raise InputError(f"not a LAS file: it starts with {data[:4]!r}, not the signature b'LASF'", path)
    if len(data) < _LAS_HEADER_SIZE[0]:
        raise InputError(f"LAS file ends in its public header: it holds {len(data)} bytes, the header alone "
                         f"{_LAS_HEADER_SIZE[0]}", path)
    major, minor = data[24], data[25]
    if major != 1 or minor not in _LAS_HEADER_SIZE:
        raise InputError(f"LAS version {major}.{minor} is not read (1.0-1.4 are): {_CONVERT}", path)
    header_size, point_offset = struct.unpack_from("<HI", data, 94)
    format_id, record_length, legacy_count = struct.unpack_from("<BHI", data, 104)
    scale = struct.unpack_from("<3d", data, 131)
    offset = struct.unpack_from("<3d", data, 155)
    if format_id & 0xC0:
        raise InputError(f"the point data format id {format_id} has LASzip's compression bit set: the file is LAZ "
                         f"(compressed LAS), which is not read: {_DECOMPRESS}", path)
    if format_id >= len(LAS_MIN_RECORD_LENGTH):
        raise InputError(f"LAS point data record format {format_id} is unknown (LAS 1.4 defines 0-10)", path)
    least = _LAS_HEADER_SIZE[minor]
    if header_size < least:
        raise InputError(f"the LAS {major}.{minor} header size is {header_size} bytes, less than the format's {least}", path)
    if len(data) < header_size:
        raise InputError(f"LAS file ends in its public header: it holds {len(data)} bytes, the header says "
                         f"{header_size}", path)
    count = legacy_count
    if minor >= 4:
        (count64,) = struct.unpack_from("<Q", data, 247)
        if count64 and legacy_count and count64 != legacy_count:
            raise InputError(f"the LAS header's point counts disagree: legacy {legacy_count}, 64-bit {count64}", path)
        count = count64 or legacy_count
    minimum = LAS_MIN_RECORD_LENGTH[format_id]
    if record_length < minimum:
        raise InputError(f"the point data record length is {record_length} bytes, shorter than point data record "
                         f"format {format_id}'s {minimum}", path)
    if point_offset < header_size:
        raise InputError(f"the offset to point data, byte {point_offset}, lies inside the {header_size}-byte "
                         "public header", path)
    for axis, s, o in zip("xyz", scale, offset):
        if not (math.isfinite(s) and s != 0.0 and math.isfinite(o)):
            raise InputError(f"the {axis} scale factor and offset must be finite and the scale nonzero, got "
                             f"{s!r} and {o!r}", path)
    need, held = count * record_length, len(data) - point_offset
    if held < need:
        raise InputError(
            f"LAS file ends early: {count} point records of {record_length} bytes announced from byte offset "
            f"{point_offset} ({need} bytes), the file holds {max(held, 0)} bytes from there "
            f"({max(held, 0) // record_length} whole records)", path)
    if count == 0:
        return np.empty((0, 3))
    record = np.dtype({"names": ["X", "Y", "Z"], "formats": ["<i4"] * 3, "offsets": [0, 4, 8],
                       "itemsize": record_length})
    body = np.frombuffer(data, record, count=count, offset=point_offset)
    points = np.empty((count, 3))
    for j, name in enumerate("XYZ"):
        points[:, j] = body[name] * scale[j] + offset[j]
    return points
