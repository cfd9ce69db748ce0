"""Session fixtures for the JunoRover FMU tests."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
BUILD = REPO / "build"
FMU = BUILD / "JunoRover.fmu"


def _build_fmu() -> None:
    cmake = shutil.which("cmake")
    ninja = shutil.which("ninja")
    if cmake is None or ninja is None:
        pytest.fail(f"{FMU} is missing and cannot be built: cmake or ninja not on PATH", pytrace=False)
    steps = [
        [cmake, "-S", str(REPO), "-B", str(BUILD), "-G", "Ninja"],
        [ninja, "-C", str(BUILD)],
    ]
    for cmd in steps:
        proc = subprocess.run(cmd, capture_output=True, text=True)
        if proc.returncode != 0:
            pytest.fail(
                f"building the FMU failed: {' '.join(cmd)} exited with {proc.returncode}\n"
                f"--- stdout ---\n{proc.stdout[-4000:]}\n--- stderr ---\n{proc.stderr[-4000:]}",
                pytrace=False,
            )
    if not FMU.is_file():
        pytest.fail(f"the build finished but {FMU} does not exist", pytrace=False)


@pytest.fixture(scope="session")
def fmu_path() -> str:
    """Path of build/JunoRover.fmu, built once with cmake + ninja if it is missing."""
    if not FMU.is_file():
        _build_fmu()
    return str(FMU)


@pytest.fixture(scope="session")
def fmu_unzipped(fmu_path, tmp_path_factory) -> str:
    """The FMU extracted once into a temporary directory."""
    from fmpy import extract

    target = tmp_path_factory.mktemp("JunoRover_fmu")
    return extract(fmu_path, unzipdir=str(target))
