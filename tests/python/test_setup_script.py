"""scripts/setup.sh on a machine where it cannot install: it names the missing Debian packages
and how to install them, and stops before doing anything else."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_without_root_or_sudo_setup_names_the_missing_packages_and_stops(tmp_path):
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    for tool in ("bash", "dirname", "cat"):        # what the script needs before its checks
        os.symlink(shutil.which(tool), bin_dir / tool)
    os.symlink(sys.executable, bin_dir / "python3")
    (bin_dir / "id").write_text("#!/bin/sh\necho 1000\n")   # not root; no sudo, cmake, cc or ninja
    (bin_dir / "id").chmod(0o755)
    venv_before = sorted(p.name for p in (ROOT / ".venv").iterdir()) if (ROOT / ".venv").is_dir() else None
    proc = subprocess.run([str(bin_dir / "bash"), str(ROOT / "scripts" / "setup.sh")], capture_output=True,
                          text=True, env={"PATH": str(bin_dir), "HOME": str(tmp_path)}, timeout=60)
    assert proc.returncode == 1, proc.stderr
    assert "missing: cmake gcc ninja-build" in proc.stderr
    assert "sudo apt-get update && sudo apt-get install -y cmake gcc ninja-build" in proc.stderr
    assert "installing" not in proc.stdout and "creating .venv" not in proc.stdout
    if venv_before is not None:
        assert sorted(p.name for p in (ROOT / ".venv").iterdir()) == venv_before
