"""Hostile surroundings for the JunoRover FMU: a terrain path that is not a file, a rover parked
beyond the edge of its terrain grid, slopes too steep for the soil.

- `terrain.file` naming a directory, a device (/dev/zero) or a FIFO is refused at once, with a
  message naming the path and what it is (opening a FIFO for reading would wait for a writer,
  reading /dev/zero would never end);
- beyond the grid the ground is level: a rover parked there, wheels free, stays put;
- on a slope steeper than the soil's friction angle the failure names the terrain, not the soil's
  stiffness.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fmu_helpers import FMICallException, Grid, LogCapture, Rover, slope_grid

HERE = Path(__file__).resolve().parent
ERROR = 3   # fmi2Error

# A child process sets terrain.file and initialises; it prints what happened as JSON.  Run apart
# so that an FMU that blocks on the path (the FIFO) or reads forever (/dev/zero) fails the test
# by the timeout instead of hanging the suite.
_CHILD = r"""
import json, sys, time
sys.path.insert(0, sys.argv[1])
from fmu_helpers import FMICallException, LogCapture, Rover
log = LogCapture()
t0 = time.monotonic()
with Rover(sys.argv[2], log=log) as r:
    try:
        r.setup({"terrain.file": sys.argv[3]})
        outcome = {"status": 0, "function": None}
    except FMICallException as e:
        outcome = {"status": e.status, "function": e.function}
outcome["seconds"] = time.monotonic() - t0
outcome["errors"] = log.errors()
print(json.dumps(outcome))
"""


def _initialise_apart(fmu_unzipped, path: str, timeout: float = 20.0) -> dict:
    try:
        proc = subprocess.run([sys.executable, "-c", _CHILD, str(HERE), str(fmu_unzipped), path],
                              capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        pytest.fail(f"initialising with terrain.file = {path} did not return within {timeout} s")
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _special_path(kind: str, tmp_path: Path) -> str:
    if kind == "directory":
        path = tmp_path / "a directory.asc"
        path.mkdir()
    elif kind == "FIFO":
        path = tmp_path / "pipe.asc"
        os.mkfifo(path)
    else:
        path = Path("/dev/zero")
    return str(path)


@pytest.mark.skipif(os.name != "posix" or not os.path.exists("/dev/zero"), reason="POSIX special files")
@pytest.mark.parametrize("kind", ["directory", "device", "FIFO"])
def test_a_terrain_path_that_is_not_a_regular_file_is_refused_at_once(fmu_unzipped, tmp_path, kind):
    """fmi2ExitInitializationMode fails within a second, naming the path and its kind."""
    path = _special_path(kind, tmp_path)
    outcome = _initialise_apart(fmu_unzipped, path)
    assert outcome["function"] == "fmi2ExitInitializationMode" and outcome["status"] == ERROR, outcome
    assert outcome["seconds"] < 1.0, outcome
    message = outcome["errors"][-1]
    assert path in message and "not a regular file" in message and kind in message, message


def test_a_parked_rover_beyond_the_edge_of_a_tilted_grid_stays_put(fmu_unzipped, tmp_path):
    """A 10 deg grid spans x in [-10, 10] m; the rover stands at x = 12 m, all four wheels beyond
    its east edge, free to roll (torque drive at 0 N m, no drawbar).  Beyond the grid the ground is
    level, so in 10 s it moves less than 1 mm.  (With the edge's slope carried beyond the grid it
    rolled about 1 m.)"""
    grid = slope_grid(10.0)
    path = grid.write(tmp_path / "tilted.asc")
    with Rover(fmu_unzipped) as r:
        r.setup({"terrain.file": path, "drive.mode": 0, "init.x": 12.0},
                initial_inputs={"torqueLeft": 0.0, "torqueRight": 0.0, "drawbarForce": 0.0})
        start = np.array(r.get(["x", "y"]))
        z0 = r.get(["z"])[0]
        out = r.advance(100, 0.1, names=["x", "y", "z"])
    moved = np.hypot(*(out[:, :2] - start).T)
    assert moved.max() < 1e-3, f"the parked rover moved {moved.max():.4f} m"
    # it stands on the clamped edge height (tan 10 deg * 10 m = 1.76 m), not on an extrapolated plane
    assert abs(out[-1, 2] - z0) < 1e-3
    # on the edge's height, tan(10 deg) 10 m: the chassis point is rover.pivotHeight + wheel.radius
    # above the ground, less the static sinkage (about 2 cm)
    clearance = z0 - grid.height(10.0, 0.0)
    assert 0.15 + 0.2794 - 0.05 < clearance < 0.15 + 0.2794, clearance


def _cliff(tmp_path: Path, degrees: float) -> str:
    """Level ground for x < 1 m, then a slope falling at `degrees` to x = 6 m."""
    cell = 0.05
    xs = np.arange(-3.0, 6.0 + cell / 2, cell)
    ys = np.arange(-2.0, 2.0 + cell / 2, cell)
    X, _ = np.meshgrid(xs, ys)
    z = np.where(X < 1.0, 0.0, -math.tan(math.radians(degrees)) * (X - 1.0))
    return Grid(z, float(xs[0]), float(ys[0]), cell).write(tmp_path / f"cliff{degrees:g}.asc")


def test_a_rover_driven_down_a_60_degree_slope_diverges_naming_the_terrain(fmu_unzipped, tmp_path):
    """Driven (motors, throttle 0.45) from level ground over the brink of a 60 deg slope, the
    rover tumbles and a wheel hits the ground faster than it could fall from its own radius
    height; the failed step says so and points at the terrain, not at the soil's stiffness."""
    log = LogCapture()
    with Rover(fmu_unzipped, log=log) as r:
        r.setup({"terrain.file": _cliff(tmp_path, 60.0), "init.x": 0.5})
        with pytest.raises(FMICallException) as exc:
            r.advance(1000, 0.01, names=["x"])
        message = log.errors()[-1]
    assert exc.value.function == "fmi2DoStep" and exc.value.status == ERROR
    assert "diverged" in message and "terrain" in message, message
    assert "soil.kh" not in message and "too soft" not in message, message


def test_a_rover_placed_on_a_60_degree_slope_is_refused_naming_the_slope(fmu_unzipped, tmp_path):
    """On a plane at 60 deg, steeper than the soil's friction angle (soil.phi = 30 deg), no
    static equilibrium exists; the message gives the slope and the friction angle."""
    path = slope_grid(60.0).write(tmp_path / "slope60.asc")
    log = LogCapture()
    with Rover(fmu_unzipped, log=log) as r:
        with pytest.raises(FMICallException) as exc:
            r.setup({"terrain.file": path})
    assert exc.value.function == "fmi2ExitInitializationMode"
    message = log.errors()[-1]
    assert "60.0 deg" in message and "soil.phi = 30.0 deg" in message and "too steep" in message, message
    assert "soil.kh" not in message, message
