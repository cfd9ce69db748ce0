"""``juno`` installed from a wheel runs outside the checkout: the wheel carries both FMUs (the rover's
JunoRover.fmu and the single-wheel rig's WheelRig.fmu) as package data, and the commands find them
without --fmu, --rig-fmu, JUNO_FMU or JUNO_RIG_FMU."""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "python_harness" / "juno" / "data"
PACKAGED = DATA / "JunoRover.fmu"
PACKAGED_RIG = DATA / "WheelRig.fmu"
BUILT_RIG = ROOT / "build" / "WheelRig.fmu"
EXAMPLE_RIG_CAMPAIGN = ROOT / "docs" / "example-rig-campaign"


@pytest.fixture(scope="module")
def installed(tmp_path_factory, fmu_path) -> tuple[Path, dict[str, str], Path]:
    """A wheel built from a copy of python_harness (no build folders, nothing of the checkout) and
    installed into a folder of its own: (that folder, an environment that puts it first on the
    path with no FMU variables set, a working folder outside the checkout)."""
    if not PACKAGED.is_file() or not PACKAGED_RIG.is_file():
        pytest.skip("scripts/setup.sh has not copied the FMUs into the package (python_harness/juno/data)")
    # The package data is what this checkout built.
    assert PACKAGED.read_bytes() == Path(fmu_path).read_bytes(), "run scripts/setup.sh again"
    assert BUILT_RIG.is_file() and PACKAGED_RIG.read_bytes() == BUILT_RIG.read_bytes(), "run scripts/setup.sh again"
    tmp_path = tmp_path_factory.mktemp("installed")
    src = tmp_path / "src"
    shutil.copytree(ROOT / "python_harness", src, ignore=shutil.ignore_patterns("*.egg-info", "__pycache__"))
    build = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp_path / "dist"),
                            str(src)], capture_output=True, text=True, timeout=600)
    assert build.returncode == 0, build.stderr[-2000:]
    wheel = next((tmp_path / "dist").glob("juno-*.whl"))
    with zipfile.ZipFile(wheel) as z:
        names = set(z.namelist())
        assert {"juno/data/JunoRover.fmu", "juno/data/WheelRig.fmu"} <= names, sorted(n for n in names if "data" in n)
    target = tmp_path / "site"
    install = subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(target),
                              str(wheel)], capture_output=True, text=True, timeout=300)
    assert install.returncode == 0, install.stderr[-2000:]
    env = {k: v for k, v in os.environ.items() if k not in ("JUNO_FMU", "JUNO_RIG_FMU")}
    env["PYTHONPATH"] = os.pathsep.join([str(target), sysconfig.get_paths()["purelib"]])
    work = tmp_path / "work"
    work.mkdir()
    return target, env, work


def run_installed(installed, code: str) -> subprocess.CompletedProcess:
    """Runs Python code with the installed package first on the path, from the working folder."""
    _, env, work = installed
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=work, env=env,
                          timeout=300)


def test_a_wheel_carries_the_fmu_and_runs_outside_the_checkout(installed):
    """`juno simulate` from the installed package simulates with the rover FMU it carries."""
    target = installed[0]
    run = run_installed(installed, "import juno.cli, sys; print(juno.cli.__file__); "
                        "sys.exit(juno.cli.main(['simulate', '--scenario', 'rest', '--stop-time', '0.5', '--quiet']))")
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.splitlines()[0].startswith(str(target)), run.stdout
    assert "scenario rest" in run.stdout


def test_the_installed_package_fits_a_single_wheel_testbed_with_the_rig_fmu_it_carries(installed):
    """The rig FMU the installed package finds by default is the one it carries, and `juno identify`
    of the example testbed campaign (its volumetric fit, about 10 s) works from it: both runs
    fitted, no failed simulation, every parameter finite, and the law following the measurements
    to within their estimated noise (chi-square at most twice its degrees of freedom, about four
    standard deviations above its mean for 30 degrees of freedom)."""
    target = installed[0]
    campaign = installed[2] / "example-rig-campaign"
    shutil.copytree(EXAMPLE_RIG_CAMPAIGN, campaign)
    out = installed[2] / "fit.json"
    run = run_installed(installed, "import juno.cli, juno.wheel_rig, sys; "
                        "print(juno.wheel_rig.default_rig_fmu_path()); "
                        f"sys.exit(juno.cli.main(['identify', {str(campaign)!r}, '--law', 'volumetric', "
                        f"'--json', {str(out)!r}, '--quiet']))")
    assert run.returncode == 0, run.stderr[-2000:]
    assert Path(run.stdout.splitlines()[0]) == target / "juno" / "data" / "WheelRig.fmu", run.stdout
    fit = json.loads(out.read_text())["rig"]["volumetric"]
    assert fit["status"] == "ok" and fit["failed_evaluations"] == 0, fit["status"]
    assert sorted(fit["runs"]) == ["lug10", "smooth"]
    assert fit["params"] and all(math.isfinite(v) for v in fit["params"].values()), fit["params"]
    assert fit["chi2"] <= 2 * fit["dof"], (fit["chi2"], fit["dof"], fit["rms"])
