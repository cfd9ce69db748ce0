"""Where a command may write: the rules that keep a user's files safe.

Every output path a command is given (``--json FILE``, ``--out CSV``, ``--out DIR``,
``--plots DIR``, synthesize's ``OUT``) is checked here before any computation starts:

* an output never is, contains or lies inside an input (the campaign folder and every file in
  it, a ``--params`` file, the FMU): writing it would destroy what the command reads;
* a file output must not be an existing directory or special file, and its nearest existing
  parent must be a writable directory (else the failure would come only after the work); an
  existing file is replaced only when juno wrote it (:func:`written_by_juno`: a JSON result
  names its writer, a CSV has the header juno writes), so a user's file at that path is never
  lost to a mistyped option;
* a folder output (a report, residual plots) is replaced whole, so it may only be a new or
  empty folder, or one that the same command wrote before: such a folder holds a marker file
  (:data:`REPORT_MARKER`, :data:`PLOTS_MARKER`) written together with the rest of it.  A folder
  holding anything else is refused: nothing the user put there is ever deleted.

Paths are compared after resolving symbolic links and ``..`` (:func:`os.path.realpath`), so a
link or a relative spelling cannot get around a rule.  Refusals are :class:`OutputError`,
whose message names the output path (and the input it would destroy).
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path
from typing import Iterable, Iterator, Optional, Union


PathLike = Union[str, "os.PathLike[str]"]

__all__ = ["OutputError", "REPORT_MARKER", "PLOTS_MARKER", "WRITTEN_BY", "check_output_file", "check_output_dir",
           "written_by_juno",
           "check_campaign_dir", "is_synthesized_campaign", "marked_directory", "campaign_inputs"]

#: Marker file of a folder written by ``juno report``.
REPORT_MARKER = ".juno-report"
#: Marker file of a folder of residual plots written by ``juno diagnose --plots``.
PLOTS_MARKER = ".juno-plots"

#: The entries of a campaign folder written by ``juno synthesize`` (and nothing else).
_SYNTHESIZED_TOP = {"campaign.json", "truth.json", "runs", "terrain"}


class OutputError(FileExistsError):
    """An output path that would destroy an input or a user's file, or cannot be written.

    A :class:`FileExistsError` (an OSError without errno or file name: its text is the whole
    message), so that callers which refuse an existing target as such keep working."""

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""


def _real(path: PathLike) -> Path:
    return Path(os.path.realpath(os.fspath(path)))


def _within(inner: Path, outer: Path) -> bool:
    """True when ``inner`` is ``outer`` or lies inside it (both resolved)."""
    return inner == outer or outer in inner.parents


def check_not_an_input(out: PathLike, inputs: Iterable[Optional[PathLike]], what: str) -> None:
    """Refuse an output that is, contains or lies inside any of ``inputs`` (None entries skipped)."""
    target = _real(out)
    for given in inputs:
        if given is None:
            continue
        source = _real(given)
        if _within(target, source):
            relation = "is" if target == source else "lies inside"
            raise OutputError(f"{what} {os.fspath(out)} {relation} the input {os.fspath(given)}; "
                              "writing there would destroy it (choose another path)")
        if _within(source, target):
            raise OutputError(f"{what} {os.fspath(out)} contains the input {os.fspath(given)}; "
                              "writing there would destroy it (choose another path)")


def _check_parent_writable(out: Path, what: str) -> None:
    """The nearest existing ancestor of ``out`` must be a directory we may write into."""
    parent = Path(os.path.abspath(out)).parent
    while not parent.exists():
        if parent.is_symlink():  # a dangling link in the path
            raise OutputError(f"{what} {os.fspath(out)}: {parent} is a broken symbolic link")
        parent = parent.parent
    if not parent.is_dir():
        raise OutputError(f"{what} {os.fspath(out)}: {parent} is not a directory")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputError(f"{what} {os.fspath(out)}: cannot write in {parent} (permission denied)")
    # Permission bits do not tell everything (root, read-only mounts, /proc): try it.
    try:
        fd, probe = tempfile.mkstemp(prefix=".juno-probe-", dir=parent)
    except OSError as exc:
        raise OutputError(f"{what} {os.fspath(out)}: cannot write in {parent} "
                          f"({exc.strerror or type(exc).__name__})") from None
    os.close(fd)
    with contextlib.suppress(OSError):
        os.unlink(probe)


def check_output_file(out: Optional[PathLike], inputs: Iterable[Optional[PathLike]], what: str) -> None:
    """Check a file output (``--json``, ``--out CSV``) before any work: not an input nor inside or
    around one, not a directory or special file, in a writable directory.  None: nothing to check."""
    if out is None:
        return
    if os.fspath(out) == "":
        raise OutputError(f"{what}: an empty path")
    check_not_an_input(out, inputs, what)
    p = Path(out)
    if p.is_dir():
        raise OutputError(f"{what} {os.fspath(out)} is a directory; give a file name")
    if p.exists() and not p.is_file():
        raise OutputError(f"{what} {os.fspath(out)} exists and is not a regular file; refusing to replace it")
    if p.exists() and not os.access(p, os.W_OK):
        raise OutputError(f"{what} {os.fspath(out)}: permission denied")
    if p.is_file() and p.stat().st_size > 0 and not written_by_juno(p):
        raise OutputError(f"{what} {os.fspath(out)} exists and was not written by juno; it would be replaced, so "
                          "give a new path (or remove the file first)")
    _check_parent_writable(p, what)


#: The key every JSON result of juno carries, naming its writer (``"juno 0.1.0 identify"``).
WRITTEN_BY = "written_by"


def written_by_juno(path: PathLike) -> bool:
    """Whether the file at ``path`` is a result juno wrote, which a new result may replace: a JSON
    object whose WRITTEN_BY starts with "juno", or a CSV with the header of ``juno simulate --out``
    (time and simulated outputs) or ``juno sweep --out`` (parameters, summary columns, error)."""
    try:
        with open(path, "rb") as f:
            head = f.read(1 << 16)
    except OSError:
        return False
    text = head.decode("utf-8", errors="replace").lstrip()
    if text.startswith("{"):
        import json

        try:
            with open(path, encoding="utf-8") as f:
                doc = json.load(f)
        except (OSError, ValueError):
            return False
        return isinstance(doc, dict) and str(doc.get(WRITTEN_BY, "")).startswith("juno")
    header = [cell.strip() for cell in text.splitlines()[0].split(",")] if text else []
    from .simulator import DEFAULT_OUTPUTS
    from .sweep import SUMMARY_COLUMNS

    if len(header) > 1 and header[0] == "time" and set(header[1:]) <= set(DEFAULT_OUTPUTS):
        return True
    tail = list(SUMMARY_COLUMNS) + ["error"]
    return header[-len(tail):] == tail


def _folder_output(out: Optional[PathLike], inputs: Iterable[Optional[PathLike]], what: str) -> Optional[Path]:
    """The checks every folder output shares: a path (None: no output), not an input (nor inside
    or around one), and not an existing file or link."""
    if out is None:
        return None
    if os.fspath(out) == "":
        raise OutputError(f"{what}: an empty path")
    check_not_an_input(out, inputs, what)
    p = Path(out)
    if p.is_symlink() or (p.exists() and not p.is_dir()):
        raise OutputError(f"{what} {os.fspath(out)} exists and is not a directory; refusing to replace it")
    return p


def check_output_dir(out: Optional[PathLike], inputs: Iterable[Optional[PathLike]], what: str,
                     marker: str, writer: str) -> None:
    """Check a folder output that is replaced whole: not an input (nor inside or around one); new,
    empty, or holding ``marker`` (written by ``writer`` before), in a writable directory."""
    p = _folder_output(out, inputs, what)
    if p is None:
        return
    if p.is_dir() and any(p.iterdir()) and not (p / marker).is_file():
        raise OutputError(f"{what} {os.fspath(out)} holds files not written by {writer}; it would be replaced "
                          "whole, so give a new or empty folder")
    _check_parent_writable(p, what)


def is_synthesized_campaign(folder: PathLike) -> bool:
    """True when ``folder`` holds exactly what ``juno synthesize`` writes: ``campaign.json``,
    ``truth.json``, ``runs/`` of ``.csv`` files and ``terrain/`` of files, nothing else."""
    p = Path(folder)
    try:
        top = {e.name: e for e in p.iterdir()}
    except OSError:
        return False
    if not {"campaign.json", "truth.json"} <= set(top) or not set(top) <= _SYNTHESIZED_TOP:
        return False
    for name in ("campaign.json", "truth.json"):
        if top[name].is_symlink() or not top[name].is_file():
            return False
    for sub, suffix in (("runs", ".csv"), ("terrain", "")):
        if sub not in top:
            continue
        d = top[sub]
        if d.is_symlink() or not d.is_dir():
            return False
        for e in d.iterdir():
            if e.is_symlink() or not e.is_file() or not e.name.endswith(suffix):
                return False
    return True


def check_campaign_dir(out: Optional[PathLike], inputs: Iterable[Optional[PathLike]], what: str,
                       overwrite: bool) -> None:
    """Check synthesize's ``OUT``: not an input; new or empty, or (with ``overwrite``) a campaign
    that ``juno synthesize`` wrote (:func:`is_synthesized_campaign`), never another folder."""
    p = _folder_output(out, inputs, what)
    if p is None:
        return
    if p.is_dir() and any(p.iterdir()):
        if not overwrite:
            raise OutputError(f"{what} {os.fspath(out)} exists and is not empty (use --overwrite to replace a "
                              "campaign written by juno synthesize)")
        if not is_synthesized_campaign(p):
            raise OutputError(f"{what} {os.fspath(out)} holds files not written by juno synthesize; "
                              "--overwrite replaces only a synthesized campaign, so give a new or empty folder")
    _check_parent_writable(p, what)


def write_marker(folder: Path, marker: str, writer: str) -> None:
    """The marker file saying that ``writer`` wrote ``folder`` (and may replace it)."""
    (folder / marker).write_text(f"This folder was written by {writer}; {writer} replaces it whole.\n",
                                 encoding="utf-8")


@contextlib.contextmanager
def marked_directory(out: PathLike, marker: str, writer: str, inputs: Iterable[Optional[PathLike]] = (),
                     what: str = "the output folder") -> Iterator[Path]:
    """Build the folder ``out`` whole (:func:`juno.atomic.atomic_directory`) with its marker file;
    an existing ``out`` is replaced only when it is empty or holds ``marker``."""
    from .atomic import atomic_directory
    inputs = list(inputs)
    check_output_dir(out, inputs, what, marker, writer)
    with atomic_directory(out, overwrite=True) as tmp:
        tmp = Path(tmp)
        yield tmp
        write_marker(tmp, marker, writer)
        # Checked again: the folder may have been filled while the body ran.
        check_output_dir(out, inputs, what, marker, writer)


def campaign_inputs(campaign: Optional[PathLike]) -> list[Path]:
    """The input paths of a campaign argument (a folder or its ``campaign.json``): the folder,
    which holds every file of the campaign.  ``[]`` for None."""
    if campaign is None or os.fspath(campaign) == "":
        return []
    p = Path(campaign)
    return [p.parent, p] if p.is_file() else [p]
