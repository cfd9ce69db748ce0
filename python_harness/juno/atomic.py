"""Write outputs whole or not at all.

Everything is first written to a hidden temporary sibling of the target (same directory, hence
same file system) and then renamed into place with :func:`os.replace`, which is atomic on POSIX.
If the writer raises, the temporary is removed and the target is left as it was.

- :func:`atomic_write_bytes`, :func:`atomic_write_text`: a file's full contents at once.
- :func:`atomic_save`: anything that writes to a path itself (``fig.savefig``, ``np.save``...);
  the temporary path keeps the target's suffix so format detection by extension still works.
- :func:`atomic_directory`: a whole folder (a campaign, a report) built in a temporary sibling
  directory and renamed into place on success.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from pathlib import Path
from typing import Callable, Iterator, Union

PathLike = Union[str, "os.PathLike[str]"]

__all__ = ["atomic_write_bytes", "atomic_write_text", "atomic_save", "atomic_directory"]


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _fsync_dir(directory: Path) -> None:
    """Best effort: make the rename durable (ignored where directories cannot be opened)."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _temp_sibling(path: Path) -> Path:
    """A new, empty, hidden file next to ``path`` keeping its suffix."""
    fd, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=f".tmp{path.suffix}", dir=path.parent)
    os.close(fd)
    os.chmod(name, 0o666 & ~_umask())
    return Path(name)


def atomic_write_bytes(path: PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (parent directories are created). Returns the path."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = _temp_sibling(target)
    try:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        raise
    _fsync_dir(target.parent)
    return target


def atomic_write_text(path: PathLike, text: str, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically, encoded (UTF-8 by default), newlines untranslated."""
    return atomic_write_bytes(path, text.encode(encoding))


def atomic_save(path: PathLike, writer: Callable[[Path], object]) -> Path:
    """Let ``writer(tmp_path)`` write a file, then move it to ``path`` atomically.

    ``tmp_path`` is a hidden sibling with the same suffix as ``path`` (e.g. ``.png``), so
    ``atomic_save("fig.png", fig.savefig)`` works. If the writer raises or writes nothing,
    nothing appears at ``path`` and an existing file there is untouched.
    """
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = _temp_sibling(target)
    try:
        writer(tmp)
        if not tmp.is_file():
            raise OSError(f"{target}: the writer left no file at {tmp}")
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        raise
    _fsync_dir(target.parent)
    return target


def _remove_tree(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        with contextlib.suppress(FileNotFoundError):
            path.unlink()


@contextlib.contextmanager
def atomic_directory(final_path: PathLike, overwrite: bool = False) -> Iterator[Path]:
    """Build a directory in a temporary sibling and rename it to ``final_path`` on success.

    Usage::

        with atomic_directory("out/campaign") as tmp:
            (tmp / "campaign.json").write_text(...)

    - If the body raises, the temporary directory is deleted and ``final_path`` is untouched.
    - An existing empty directory at ``final_path`` is replaced. An existing non-empty one is
      refused with :class:`FileExistsError` before anything is written, unless
      ``overwrite=True``; then it is replaced only after the body succeeded (moved aside,
      the new one renamed in, the old one deleted; restored if the rename fails).
    - An existing file (not a directory) at ``final_path`` is always refused.
    """
    final = Path(final_path)
    parent = final.parent
    parent.mkdir(parents=True, exist_ok=True)

    def check_target() -> None:
        if final.is_symlink() or (final.exists() and not final.is_dir()):
            raise FileExistsError(f"{final}: exists and is not a directory; refusing to replace it")
        if final.is_dir() and any(final.iterdir()) and not overwrite:
            raise FileExistsError(
                f"{final}: directory exists and is not empty; refusing to overwrite it (use overwrite=True)"
            )

    check_target()
    tmp = Path(tempfile.mkdtemp(prefix=f".{final.name}.tmp-", dir=parent))
    os.chmod(tmp, 0o777 & ~_umask())
    try:
        yield tmp
        check_target()  # the target may have appeared while the body ran
        if final.exists():
            backup = Path(tempfile.mkdtemp(prefix=f".{final.name}.old-", dir=parent))
            os.rmdir(backup)
            os.rename(final, backup)
            try:
                os.rename(tmp, final)
            except BaseException:
                os.rename(backup, final)
                raise
            _remove_tree(backup)
        else:
            os.rename(tmp, final)
    except BaseException:
        _remove_tree(tmp)
        raise
    _fsync_dir(parent)
