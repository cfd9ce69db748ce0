"""Errors raised for bad input files, and the strict number parser shared by the readers.

Every refusal of a user's file is an :class:`InputError`; its text names the file, the line
(1-based) and the column where known, for example::

    runs/dbp1.csv, line 17, column 'omega_left': not a number: 'abc'
"""

from __future__ import annotations

from pathlib import Path

import math
import os
import re
from typing import Optional, Union

PathLike = Union[str, "os.PathLike[str]"]

__all__ = ["InputError", "parse_finite", "NUMBER_RE"]


class InputError(ValueError):
    """A user's input file (or value read from one) breaks the documented format.

    Attributes:
        message: what is wrong, without the location.
        path: the file, as given by the caller (``None`` if not from a file).
        line: 1-based line number in that file, or ``None``.
        column: column / key name, or ``None``.
    """

    def __init__(
        self,
        message: str,
        path: Optional[PathLike] = None,
        line: Optional[int] = None,
        column: Optional[str] = None,
    ) -> None:
        super().__init__(message, path, line, column)
        self.message = str(message)
        self.path = None if path is None else os.fspath(path)
        self.line = None if line is None else int(line)
        self.column = None if column is None else str(column)

    def __str__(self) -> str:
        where = []
        if self.path is not None:
            where.append(str(self.path))
        if self.line is not None:
            where.append(f"line {self.line}")
        if self.column is not None:
            where.append(f"column {self.column!r}")
        if not where:
            return self.message
        return f"{', '.join(where)}: {self.message}"


# A plain decimal number: no 'nan', 'inf', hex, underscores or non-ASCII digits
# (all of which Python's float() would accept).
NUMBER_RE = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")


def parse_finite(
    text: str,
    path: Optional[PathLike] = None,
    line: Optional[int] = None,
    column: Optional[str] = None,
) -> float:
    """Parse ``text`` (surrounding spaces allowed) as a finite decimal number.

    Raises:
        InputError: "not a number: 'abc'" or "not finite: 'nan'" located at path/line/column.
    """
    s = text.strip()
    if NUMBER_RE.fullmatch(s) is None:
        low = s.lower().lstrip("+-")
        if low in ("nan", "inf", "infinity"):
            raise InputError(f"not finite: {text!r}", path, line, column)
        raise InputError(f"not a number: {_shorten(text)!r}", path, line, column)
    value = float(s)
    if not math.isfinite(value):
        raise InputError(f"not finite (overflows a double): {_shorten(text)!r}", path, line, column)
    return value


def _shorten(text: str, limit: int = 60) -> str:
    return text if len(text) <= limit else text[:limit] + "..."


def read_input_bytes(path: "Path") -> bytes:
    """The bytes of an input file, or an InputError naming it (missing, a directory, unreadable)."""
    try:
        return path.read_bytes()
    except FileNotFoundError:
        raise InputError("file not found", path) from None
    except IsADirectoryError:
        raise InputError("is a directory, not a file", path) from None
    except OSError as e:
        raise InputError(f"cannot read: {e.strerror or e}", path) from None


#: What to do with a text file in another encoding than UTF-8.
SAVE_AS_UTF8 = "save it as UTF-8 (in Excel: 'CSV UTF-8'; in other programs: encoding UTF-8)"


def decode_input_text(path: "Path", data: bytes) -> str:
    """UTF-8 (BOM allowed); refuse other bytes naming the line of the first bad byte.

    A file in another encoding is named as such with what to do: UTF-16 (a byte-order mark, or
    the NUL bytes its ASCII characters carry without one, as Excel's 'Unicode Text' saves it) and
    a one-byte encoding (Windows-1252, Latin-1: a byte beyond ASCII that is no UTF-8, in a file
    without NUL bytes, which a binary file would hold)."""
    if data[:2] in (b"\xff\xfe", b"\xfe\xff"):
        raise InputError(f"UTF-16 text (as Excel's 'Unicode Text' saves it), not UTF-8: {SAVE_AS_UTF8}", path, 1)
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        line = data[: e.start].count(b"\n") + 1
        hint = "" if b"\x00" in data else f": another encoding than UTF-8 (Windows-1252, Latin-1); {SAVE_AS_UTF8}"
        raise InputError(f"not UTF-8 text (byte {data[e.start]:#04x}){hint}", path, line) from None
    nul = text.find("\x00")
    if nul >= 0:
        raise InputError("holds NUL bytes, which no text file has: UTF-16 text without a byte-order mark (as some "
                         f"loggers write it), or not a text file; {SAVE_AS_UTF8}", path, text.count("\n", 0, nul) + 1)
    return text

