"""What every hostile-input test asserts of a refused ``juno`` command: exit code 2, one clean
line naming what is wrong (so it stopped before any work printed progress), no traceback or
object repr, and every file it could touch unchanged."""

from __future__ import annotations

import hashlib
from pathlib import Path

from juno.cli import main


def checksums(*roots: Path) -> dict[str, str]:
    """SHA-256 of every file below (or at) each root, keyed by its path."""
    out = {}
    for root in roots:
        files = [root] if root.is_file() else sorted(p for p in root.rglob("*") if p.is_file())
        for f in files:
            out[str(f)] = hashlib.sha256(f.read_bytes()).hexdigest()
    return out


def refused(capsys, work: Path, args: list[str], needles: list[str]) -> str:
    """``juno ARGS`` ({w} in them is ``work``) in this process, with progress on: exit 2, one
    stderr line ``juno CMD: error: ...`` naming every needle, no traceback, object repr or NumPy
    repr, every file below ``work`` unchanged.  Returns the line."""
    before = checksums(work)
    args = [a.format(w=work) for a in args]
    try:
        code = main(args)
    except SystemExit as exc:        # argparse's refusals exit
        code = exc.code
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code == 2, f"exit code {code}, stderr:\n{err}"
    assert len(lines) == 1, f"expected one line (refused before any work), got:\n{err}"
    assert lines[0].startswith(f"juno {args[0]}: error: "), lines[0]
    for needle in needles:
        assert needle.format(w=work) in lines[0], f"the message does not name {needle!r}: {lines[0]}"
    for bad in ("Traceback", "object at 0x", "np.float64(", "np.int64(", "array("):
        assert bad not in err, f"{bad} in the message: {err}"
    assert checksums(work) == before, "an input or a user's file changed"
    return lines[0]
