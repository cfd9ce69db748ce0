"""``juno`` installed from a wheel runs outside the checkout: the wheel carries the FMU as
package data, and the command finds it without --fmu or JUNO_FMU."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PACKAGED = ROOT / "python_harness" / "juno" / "data" / "JunoRover.fmu"


def test_a_wheel_carries_the_fmu_and_runs_outside_the_checkout(tmp_path, fmu_path):
    if not PACKAGED.is_file():
        pytest.skip("scripts/setup.sh has not copied the FMU into the package (python_harness/juno/data)")
    # The package data is the FMU this checkout built.
    assert PACKAGED.read_bytes() == Path(fmu_path).read_bytes(), "run scripts/setup.sh again"
    # A wheel built from a copy of python_harness (no build folders, nothing of the checkout).
    src = tmp_path / "src"
    shutil.copytree(ROOT / "python_harness", src, ignore=shutil.ignore_patterns("*.egg-info", "__pycache__"))
    build = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp_path / "dist"),
                            str(src)], capture_output=True, text=True, timeout=600)
    assert build.returncode == 0, build.stderr[-2000:]
    wheel = next((tmp_path / "dist").glob("juno-*.whl"))
    with zipfile.ZipFile(wheel) as z:
        assert "juno/data/JunoRover.fmu" in z.namelist()
    target = tmp_path / "site"
    install = subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(target),
                              str(wheel)], capture_output=True, text=True, timeout=300)
    assert install.returncode == 0, install.stderr[-2000:]
    # Run from elsewhere, the installed package first on the path (before this checkout's).
    env = {k: v for k, v in os.environ.items() if k != "JUNO_FMU"}
    env["PYTHONPATH"] = os.pathsep.join([str(target), sysconfig.get_paths()["purelib"]])
    run = subprocess.run([sys.executable, "-c", "import juno.cli, sys; print(juno.cli.__file__); "
                          "sys.exit(juno.cli.main(['simulate', '--scenario', 'rest', '--stop-time', '0.5', '--quiet']))"],
                         capture_output=True, text=True, cwd=tmp_path, env=env, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.splitlines()[0].startswith(str(target)), run.stdout
    assert "scenario rest" in run.stdout
