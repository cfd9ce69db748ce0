"""Specification of the plausibility checks on measured data (juno.plausibility).

Each bad-data case is written into a copy of a short synthetic campaign. A case that no rover
could have produced makes the commands that read measured data stop with exit code 2 within
seconds (before any fit), naming the file, the column and the evidence; a suspicious but
possible case is a warning naming the same; no input file is ever changed. Campaigns written
by ``juno synthesize`` (every hidden effect, with and without sensor noise) raise nothing.
"""

from __future__ import annotations

import hashlib
import json
import math
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
import pytest

from harness_fixtures import run_juno_here
from juno.campaign import format_run_csv, load_campaign, read_run_csv
from juno.effects import ALTERNATIVE_FORMS, EFFECTS
from juno.plausibility import (Finding, PlausibilityError, check_campaign, enforce_plausibility,
                               outlier_threshold_k, rover_limits)
from juno.pointcloud import GRID_MARGIN, format_xyz, gross_outliers, read_xyz
from juno.sensor_noise import column_noise

pytest_plugins = ["harness_fixtures"]

#: The short synthetic campaign the bad cases are written into (shared with test_cli).
SEED = 101
#: A refusal happens right after loading: well within this (s), where a fit takes minutes.
QUICK_EXIT = 20.0


# ------------------------------------------------------------------------ writing bad copies

def edit_run(root: Path, run: str, change: Callable[[dict[str, np.ndarray]], None]) -> None:
    """Rewrites runs/<run>.csv after ``change`` edits its columns in place."""
    path = root / "runs" / f"{run}.csv"
    kind = "terrain" if run == "t3d" else "drawbar"
    columns = dict(read_run_csv(path, kind).columns)
    change(columns)
    path.write_text(format_run_csv(columns))


def scale(run: str, factor: float, *names: str) -> Callable[[Path], None]:
    def apply(root: Path) -> None:
        def change(c):
            for n in names:
                c[n] = c[n] * factor
        edit_run(root, run, change)
    return apply


def shift(run: str, delta: float, *names: str) -> Callable[[Path], None]:
    def apply(root: Path) -> None:
        def change(c):
            for n in names:
                c[n] = c[n] + delta
        edit_run(root, run, change)
    return apply


def counted_angle(run: str, name: str) -> Callable[[Path], None]:
    """Replaces a spin column by the wheel's angle counted up from 0 (rad) at the same samples, as
    an encoder logs it: the spin's running integral."""
    def apply(root: Path) -> None:
        def change(c):
            own = ~np.isnan(c[name])
            t, spin = c["time"][own], c[name][own]
            angle = np.concatenate([[0.0], np.cumsum(0.5 * (spin[1:] + spin[:-1]) * np.diff(t))])
            c[name] = c[name].copy()
            c[name][own] = angle
        edit_run(root, run, change)
    return apply


def in_every_drawbar_run(change: Callable[[str], Callable[[Path], None]]) -> Callable[[Path], None]:
    """Applies ``change(run)`` to every drawbar run of the campaign."""
    def apply(root: Path) -> None:
        for run in ("dbp1", "dbp2", "dbp3"):
            change(run)(root)
    return apply


def set_sample(run: str, name: str, k: int, value: float) -> Callable[[Path], None]:
    """Sets the k-th own sample of a column to ``value``."""
    def apply(root: Path) -> None:
        def change(c):
            idx = np.flatnonzero(~np.isnan(c[name]))
            c[name] = c[name].copy()
            c[name][idx[k]] = value
        edit_run(root, run, change)
    return apply


def add_to_sample(run: str, name: str, k: int, delta: float) -> Callable[[Path], None]:
    def apply(root: Path) -> None:
        def change(c):
            idx = np.flatnonzero(~np.isnan(c[name]))
            c[name] = c[name].copy()
            c[name][idx[k]] += delta
        edit_run(root, run, change)
    return apply


def zero_torque(run: str) -> Callable[[Path], None]:
    def apply(root: Path) -> None:
        def change(c):
            c["torque_left"] = np.where(np.isnan(c["torque_left"]), np.nan, 0.0)
        edit_run(root, run, change)
    return apply


def disconnect_imu(run: str) -> Callable[[Path], None]:
    """A disconnected IMU: the logger writes 0.0 in every sample of roll, pitch and yaw."""
    def apply(root: Path) -> None:
        def change(c):
            for name in ("roll", "pitch", "yaw"):
                c[name] = np.where(np.isnan(c[name]), np.nan, 0.0)
        edit_run(root, run, change)
    return apply


def constant(run: str, name: str, value: float) -> Callable[[Path], None]:
    """A dead sensor: the logger writes ``value`` in every sample of ``name``."""
    def apply(root: Path) -> None:
        def change(c):
            c[name] = np.where(np.isnan(c[name]), np.nan, value)
        edit_run(root, run, change)
    return apply


def freeze_position(run: str, after: float) -> Callable[[Path], None]:
    """The total station repeats its last reading before ``after`` (s) to the end of the run."""
    def apply(root: Path) -> None:
        def change(c):
            t = c["time"]
            for n in ("pos_x", "pos_y", "pos_z"):
                v = c[n].copy()
                own = np.flatnonzero(~np.isnan(v))
                last = own[t[own] < after][-1]
                later = own[t[own] >= after]
                v[later] = v[last]
                c[n] = v
        edit_run(root, run, change)
    return apply


def stop_early(run: str, after: float, *names: str) -> Callable[[Path], None]:
    """The sensors of ``names`` stop measuring ``after`` s into the run: their cells empty from there."""
    def apply(root: Path) -> None:
        def change(c):
            t = c["time"]
            for n in names:
                c[n] = np.where(t > t[0] + after, np.nan, c[n])
        edit_run(root, run, change)
    return apply


def dropout(run: str, start: float, end: float, *names: str) -> Callable[[Path], None]:
    """The sensors of ``names`` write nothing from ``start`` to ``end`` s into the run (empty cells)."""
    def apply(root: Path) -> None:
        def change(c):
            t = c["time"] - c["time"][0]
            for n in names:
                c[n] = np.where((t > start) & (t < end), np.nan, c[n])
        edit_run(root, run, change)
    return apply


def state_noise(noise: dict[str, float], run: str | None = None) -> Callable[[Path], None]:
    """The manifest states ``noise`` (column -> 1 sigma) for ``run``, or for the campaign (None)."""
    def apply(root: Path) -> None:
        path = root / "campaign.json"
        doc = json.loads(path.read_text())
        entry = doc if run is None else next(r for r in doc["runs"] if r["id"] == run)
        entry["sensor_noise"] = noise
        path.write_text(json.dumps(doc, indent=2))
    return apply


def low_pass_with_stated_noise(run: str, name: str, tau: float) -> Callable[[Path], None]:
    """The column passes through a first-order low-pass of ``tau`` s, and the manifest states
    the noise it had before (its estimate from the unfiltered samples)."""
    def apply(root: Path) -> None:
        def change(c):
            own = ~np.isnan(c[name])
            t, v = c["time"][own], c[name][own]
            keep = np.exp(-float(np.median(np.diff(t))) / tau)
            out, state = np.empty_like(v), v[0]
            for i, x in enumerate(v):
                state = keep * state + (1.0 - keep) * x
                out[i] = state
            state_noise({name: float(column_noise(t, v))}, run)(root)
            c[name] = c[name].copy()
            c[name][own] = out
        edit_run(root, run, change)
    return apply


def swap_columns(run: str, a: str, b: str) -> Callable[[Path], None]:
    """The file holds column ``a``'s values under ``b``'s name and the other way round."""
    def apply(root: Path) -> None:
        def change(c):
            c[a], c[b] = c[b].copy(), c[a].copy()
        edit_run(root, run, change)
    return apply


def parked(run: str) -> Callable[[Path], None]:
    """The run logged with the rover parked: spins and drive torques 0.0, the position its first."""
    def apply(root: Path) -> None:
        def change(c):
            for name in ("omega_left", "omega_right", "torque_left", "torque_right"):
                c[name] = np.where(np.isnan(c[name]), np.nan, 0.0)
            for name in ("pos_x", "pos_y", "pos_z"):
                c[name] = np.where(np.isnan(c[name]), np.nan, c[name][~np.isnan(c[name])][0])
        edit_run(root, run, change)
    return apply


def waiting_window(run: str, seconds: float) -> Callable[[Path], None]:
    """The logger starts ``seconds`` before the rover, which waits with its wheels still (a row
    every 0.1 s of its first readings, spins and torques 0.0), and the manifest's steady window is
    that wait."""
    def apply(root: Path) -> None:
        start = [0.0]

        def change(c):
            t = c["time"]
            step = 0.1
            n = int(round(seconds / step))
            for name, v in list(c.items()):
                if name != "time":
                    rest = 0.0 if name.startswith(("omega_", "torque_")) else v[~np.isnan(v)][0]
                    c[name] = np.concatenate([np.full(n, rest), v])
            c["time"] = np.concatenate([t[0] + step * np.arange(n), t + n * step])
            start[0] = float(t[0])
        edit_run(root, run, change)
        path = root / "campaign.json"
        doc = json.loads(path.read_text())
        entry = next(r for r in doc["runs"] if r["id"] == run)
        entry["steady_window"] = [start[0], start[0] + seconds]
        path.write_text(json.dumps(doc, indent=2))
    return apply


def edit_scan(change: Callable[[np.ndarray], np.ndarray]) -> Callable[[Path], None]:
    def apply(root: Path) -> None:
        path = root / "terrain" / "scan.xyz"
        path.write_text("# x y z (m)\n" + format_xyz(change(read_xyz(path))))
    return apply


def far_point(points: np.ndarray) -> np.ndarray:
    return np.vstack([points, [[1.0e6, 0.0, 0.0]]])


def spike_point(points: np.ndarray) -> np.ndarray:
    p = points.copy()
    i = int(np.argmin(np.hypot(p[:, 0] - 4.0, p[:, 1] + 0.8)))
    p[i, 2] += 5.0
    return p


def on_the_path(change: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]) -> Callable[[Path], None]:
    """Edits the scan with the terrain run's measured path in hand: ``change(points, x, y)``, x and
    y the position samples (m)."""
    def apply(root: Path) -> None:
        run = read_run_csv(root / "runs" / "t3d.csv", "terrain")
        have = ~np.isnan(run["pos_x"])
        path = root / "terrain" / "scan.xyz"
        path.write_text("# x y z (m)\n" + format_xyz(change(read_xyz(path), run["pos_x"][have], run["pos_y"][have])))
    return apply


def rover_in_scan(points: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The rover scanned where it stands at the start: the ground under its footprint hidden, its
    body and wheels' tops 0.3-0.8 m above it (as many points as the ground there had)."""
    lim = rover_limits()
    under = (np.abs(points[:, 0] - x[0]) < lim.half_length) & (np.abs(points[:, 1] - y[0]) < lim.half_width)
    rng = np.random.default_rng(5)
    n = max(int(under.sum()), 200)
    ground = float(np.median(points[under, 2]))
    body = np.column_stack([x[0] + rng.uniform(-lim.half_length, lim.half_length, n),
                            y[0] + rng.uniform(-lim.half_width, lim.half_width, n), ground + rng.uniform(0.3, 0.8, n)])
    return np.vstack([points[~under], body])


def hole_under_path(points: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """No scan point over 2 m of the path's middle, across the whole scan (a shadow, a puddle): the
    footprint stays within 1 m of the scan's points, the wheels do not."""
    middle = 0.5 * (x.min() + x.max())
    return points[np.abs(points[:, 0] - middle) > 1.0]


def crop_scan(points: np.ndarray, root: Path, share: float) -> np.ndarray:
    """The scan without the part beyond where the rover is after ``share`` of the terrain run."""
    run = read_run_csv(root / "runs" / "t3d.csv", "terrain")
    t, x = run.time[~np.isnan(run["pos_x"])], run["pos_x"][~np.isnan(run["pos_x"])]
    # The footprint reaches half_length ahead of the prism, and counts as on the scan within
    # GRID_MARGIN of a scan point: it leaves the cropped scan at ``share`` of the run.
    x_cut = float(np.interp(t[0] + share * (t[-1] - t[0]), t, x)) + rover_limits().half_length - GRID_MARGIN
    return points[points[:, 0] < x_cut]


def cropped(share: float) -> Callable[[Path], None]:
    def apply(root: Path) -> None:
        path = root / "terrain" / "scan.xyz"
        path.write_text("# x y z (m)\n" + format_xyz(crop_scan(read_xyz(path), root, share)))
    return apply


@dataclass(frozen=True)
class Case:
    """A bad-data case: how to write it, and the finding it must raise."""

    name: str
    write: Callable[[Path], None]
    severity: str
    file: str
    column: str
    words: tuple[str, ...]


ERRORS = [
    Case("pitch in degrees", scale("t3d", 180 / math.pi, "pitch"), "error", "runs/t3d.csv", "pitch",
         ("degrees", "> 1.2 rad")),
    Case("roll in degrees", scale("t3d", 180 / math.pi, "roll"), "error", "runs/t3d.csv", "roll", ("degrees",)),
    Case("spins in rpm", scale("dbp1", 60 / (2 * math.pi), "omega_left"), "error", "runs/dbp1.csv", "omega_left",
         ("looks like rpm", "no-load spin")),
    Case("spins in degrees per second", scale("dbp1", 180 / math.pi, "omega_left"), "error", "runs/dbp1.csv",
         "omega_left", ("looks like degrees per second", "no-load spin")),
    Case("the wheel's angle logged as its spin", counted_angle("dbp1", "omega_left"), "error", "runs/dbp1.csv",
         "omega_left", ("angle counted up", "rate of change")),
    Case("the wheel's angle logged as its spin on a terrain run", counted_angle("t3d", "omega_right"), "error",
         "runs/t3d.csv", "omega_right", ("angle counted up", "rate of change")),
    Case("positions in millimetres", scale("dbp2", 1000.0, "pos_x", "pos_y", "pos_z"), "error", "runs/dbp2.csv",
         "pos_x", ("millimetres", "top speed")),
    Case("time in milliseconds", scale("t3d", 1000.0, "time"), "error", "runs/t3d.csv", "time",
         ("milliseconds",)),
    Case("all-zero torque while pulling", zero_torque("dbp3"), "error", "runs/dbp3.csv", "torque_left",
         ("zero in every sample", "drawbar")),
    Case("a disconnected IMU writing 0.0", disconnect_imu("dbp2"), "error", "runs/dbp2.csv", "pitch",
         ("0 rad in every sample", "while the wheels turn", "IMU")),
    Case("a load cell stuck at one reading", constant("dbp1", "drawbar_force", 412.0), "error", "runs/dbp1.csv",
         "drawbar_force", ("412 N in every sample", "while the wheels turn", "load cell")),
    Case("one absurd torque sample", set_sample("dbp3", "torque_right", 100, 1e300), "error", "runs/dbp3.csv",
         "torque_right", ("1e+300", "electrical maximum")),
    Case("one absurd yaw sample", set_sample("dbp1", "yaw", 200, 1e300), "error", "runs/dbp1.csv", "yaw",
         ("1e+300", "far from its neighbours", "line")),
    Case("torque beyond the motors", scale("dbp2", 6.0, "torque_left"), "error", "runs/dbp2.csv", "torque_left",
         ("electrical maximum", "stall torque")),
    Case("drawbar force beyond the wheels", scale("dbp1", 40.0, "drawbar_force"), "error", "runs/dbp1.csv",
         "drawbar_force", ("the wheels could push",)),
    Case("torques at the motor shaft", scale("dbp3", 0.85 / 129.0, "torque_left", "torque_right"), "error",
         "runs/dbp3.csv", "torque_left", ("times the power", "gearbox", "motor.gearRatio")),
    Case("torques logged as the motor current in A", scale("dbp3", 1.0 / (0.85 * 129.0 * 0.0465), "torque_left",
                                                          "torque_right"), "error", "runs/dbp3.csv", "torque_left",
         ("the torques are too small", "looks like the motor current in A", "5.099 N m per A")),
    Case("torques in kN m", scale("dbp2", 1e-3, "torque_left", "torque_right"), "error", "runs/dbp2.csv",
         "torque_left", ("times the power", "kN m")),
    Case("spins in rev/s", scale("dbp2", 1 / (2 * math.pi), "omega_left", "omega_right"), "error", "runs/dbp2.csv",
         "omega_left", ("rims roll", "rev/s")),
    Case("drawbar force in kN in every run", in_every_drawbar_run(lambda r: scale(r, 1e-3, "drawbar_force")),
         "error", "runs/dbp2.csv", "drawbar_force", ("looks like kN", "in every drawbar run", "torques push")),
    Case("heights from a map's datum", in_every_drawbar_run(lambda r: shift(r, 312.0, "pos_z")), "error",
         "runs/dbp1.csv", "pos_z", ("another datum", "flat ground at z = 0", "312.")),
    Case("path far off the scan", cropped(0.5), "error", "runs/t3d.csv", "pos_x",
         ("run 't3d'", "leaves the scan terrain/scan.xyz during", "s (")),
    Case("a drawbar run logged with the rover parked", parked("dbp2"), "error", "runs/dbp2.csv", "omega_left",
         ("median |spin| over the run is 0 rad/s", "a drawbar test drives the rover", "encoders")),
    Case("a steady window while the rover waits at the start", waiting_window("dbp1", 1.0), "error", "campaign.json",
         "steady_window", ("run 'dbp1'", "steady_window 0-1 s", "standing still", "give the span where it does")),
    Case("drawbar heights with z pointing down", scale("dbp2", -1.0, "pos_z"), "error", "runs/dbp2.csv", "pos_z",
         ("the median pos_z is -0.", "rover.pivotHeight", "does z point down")),
    Case("drawbar heights of the y axis (a y-up frame)", swap_columns("dbp3", "pos_y", "pos_z"), "error",
         "runs/dbp3.csv", "pos_z", ("flat ground at z = 0", "another axis (a y-up frame)")),
    Case("terrain torques of the other sign", scale("t3d", -1.0, "torque_left", "torque_right"), "error",
         "runs/t3d.csv", "torque_left", ("of work over the run", "against its weight", "where they only take energy",
                                         "sign reversed")),
    Case("terrain heights with z pointing down", scale("t3d", -1.0, "pos_z"), "error", "runs/t3d.csv", "pos_z",
         ("pos_z falls where the ground under the wheels in terrain/scan.xyz rises", "z points down")),
    Case("a scan with z pointing down", edit_scan(lambda p: p * [1.0, 1.0, -1.0]), "error", "runs/t3d.csv", "pos_z",
         ("pos_z falls where the ground under the wheels in terrain/scan.xyz rises", "z points down")),
    Case("a scan's heights from a map's datum", edit_scan(lambda p: p + [0.0, 0.0, 312.0]), "error", "runs/t3d.csv",
         "pos_z", ("m above the ground under its wheels in terrain/scan.xyz", "-311.", "below that",
                   "different datums")),
    Case("terrain heights from a total station's datum", shift("t3d", 45.0, "pos_z"), "error", "runs/t3d.csv",
         "pos_z", ("45.", "above that", "different datums")),
    Case("a scan's heights in millimetres", edit_scan(lambda p: p * [1.0, 1.0, 1000.0]), "error",
         "terrain/scan.xyz", "z", ("steeper than the soil's friction angle", "its heights look like millimetres",
                                   "write every coordinate in metres")),
    Case("a scan with y and z swapped", edit_scan(lambda p: p[:, [0, 2, 1]]), "error", "terrain/scan.xyz", "z",
         ("typically slopes 90 deg", "steeper than the soil's friction angle soil.phi = 30 deg",
          "y and z exchanged", "write the columns x y z, z up")),
    Case("a scan with x and z swapped", edit_scan(lambda p: p[:, [2, 1, 0]]), "error", "terrain/scan.xyz", "z",
         ("steeper than the soil's friction angle", "x and z exchanged")),
    Case("a scan with the rover in it", on_the_path(rover_in_scan), "error", "terrain/scan.xyz", "z",
         ("under the wheels of run runs/t3d.csv during 0", "rover.pivotHeight", "the rover itself",
          "remove those points")),
    Case("a hole in the scan under the path", on_the_path(hole_under_path), "error", "runs/t3d.csv", "pos_x",
         ("a wheel has no point of the scan terrain/scan.xyz within its radius", "not measured", "has a hole there")),
    Case("a scan too sparse for the wheels", edit_scan(lambda p: p[::250]), "error", "runs/t3d.csv", "pos_x",
         ("within its radius", "too sparse for the wheels")),
    Case("a wheel encoder that stops before the run ends", stop_early("t3d", 3.0, "omega_left"), "error",
         "runs/t3d.csv", "omega_left", ("stops", "before the run's last row", "driven by omega_left",
                                        "cut the run's rows to t = ")),
    Case("a height noise stated in millimetres", state_noise({"pos_z": 3.0}), "error", "runs/dbp1.csv", "pos_z",
         ("the manifest states a sensor noise of 3 m (1 sigma)", "more than the column's whole range in this run",
          "another unit")),
]

WARNINGS = [
    Case("torque beyond the drive's limit", scale("dbp2", 2.5, "torque_left"), "warning", "runs/dbp2.csv",
         "torque_left", ("drive's limit",)),
    Case("drawbar force beyond the drive", scale("dbp1", 15.0, "drawbar_force"), "warning", "runs/dbp1.csv",
         "drawbar_force", ("torque limit pushes",)),
    Case("drawbar force in kN in one run (or a run without load)", scale("dbp3", 1e-3, "drawbar_force"), "warning",
         "runs/dbp3.csv", "drawbar_force", ("looks like kN",)),
    Case("frozen total station", freeze_position("t3d", 2.0), "warning", "runs/t3d.csv", "pos_x",
         ("frozen", "while the wheels turn")),
    Case("one glitch of the total station", add_to_sample("t3d", "pos_x", 12, 1.0), "warning", "runs/t3d.csv",
         "pos_x", ("far from its neighbours", "line")),
    Case("a scan point a kilometre off", edit_scan(far_point), "warning", "terrain/scan.xyz", "x",
         ("1 of", "gross outliers", "dropped", "1e+06")),
    Case("a 5 m spike in the scan", edit_scan(spike_point), "warning", "terrain/scan.xyz", "z",
         ("gross outliers", "dropped")),
    Case("path briefly off the scan", cropped(1.0), "warning", "runs/t3d.csv", "pos_x",
         ("run 't3d'", "leaves the scan")),
    Case("a total station that stops before the run ends", stop_early("t3d", 3.0, "pos_x", "pos_y", "pos_z"),
         "warning", "runs/t3d.csv", "pos_x", ("stops", "before the run's last row", "stopped measuring",
                                              "compared only where it has samples")),
    Case("a dropout of a wheel encoder inside the run", dropout("dbp1", 2.0, 4.0, "omega_right"), "warning",
         "runs/dbp1.csv", "omega_right", ("has no sample for 2", "a dropout", "straight line across the gap")),
    Case("a filtered motor current with its sensor's noise stated", low_pass_with_stated_noise("dbp2", "torque_left", 0.15),
         "warning", "runs/dbp2.csv", "torque_left",
         ("sensor noise stated in the manifest", "N m) is under 1/3 of the stated", "filtered")),
    Case("a noise stated far below the column's", state_noise({"omega_right": 1e-5}, "dbp3"), "warning",
         "runs/dbp3.csv", "omega_right", ("over 3 times the stated 1e-05 rad/s", "noisier than stated")),
]


def case_named(name: str) -> Case:
    return next(c for c in ERRORS + WARNINGS if c.name == name)


def checksums(root: Path) -> dict[str, str]:
    return {p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def base(small_campaign) -> Path:
    return small_campaign(SEED).path


def bad_copy(base: Path, tmp_path: Path, case: Case) -> Path:
    root = tmp_path / "campaign"
    shutil.copytree(base, root)
    case.write(root)
    return root


def matching(findings: list[Finding], case: Case) -> list[Finding]:
    return [f for f in findings if f.severity == case.severity and f.file == case.file and f.column == case.column
            and all(w in f.message for w in case.words)]


# ------------------------------------------------------------------------------- the cases

@pytest.mark.parametrize("case", ERRORS, ids=lambda c: c.name)
def test_identify_refuses_impossible_data_at_once(base, tmp_path, case, capsys) -> None:
    """``juno identify`` exits 2 within seconds, naming file, column and evidence, files untouched."""
    root = bad_copy(base, tmp_path, case)
    before = checksums(root)
    start = time.perf_counter()
    proc = run_juno_here(capsys, "identify", root, "--quiet")
    elapsed = time.perf_counter() - start
    assert proc.returncode == 2, f"exit {proc.returncode}\n{proc.stderr}"
    assert "Traceback" not in proc.stderr
    assert elapsed < QUICK_EXIT, f"the refusal took {elapsed:.1f} s"
    line = next((ln for ln in proc.stderr.splitlines() if f"{case.file}, column '{case.column}'" in ln), None)
    assert line is not None, proc.stderr
    assert all(w in line for w in case.words), line
    assert "--force" in proc.stderr
    assert "np.float64" not in proc.stderr
    assert checksums(root) == before


@pytest.mark.parametrize("case", ERRORS + WARNINGS, ids=lambda c: c.name)
def test_each_case_is_found_with_its_severity(base, tmp_path, case) -> None:
    root = bad_copy(base, tmp_path, case)
    before = checksums(root)
    findings = check_campaign(load_campaign(root))
    assert matching(findings, case), "\n".join(f"{f.severity}: {f}" for f in findings)
    if case.severity == "warning":
        assert not [f for f in findings if f.severity == "error"], [str(f) for f in findings]
    assert checksums(root) == before


@pytest.mark.parametrize("command", ["validate", "report", "diagnose"])
def test_every_command_reading_measured_data_refuses(base, tmp_path, command, capsys) -> None:
    root = bad_copy(base, tmp_path, case_named("pitch in degrees"))
    extra = ["--out", str(tmp_path / "report")] if command == "report" else []
    proc = run_juno_here(capsys, command, root, *extra, "--quiet")
    assert proc.returncode == 2, proc.stderr
    assert "runs/t3d.csv, column 'pitch'" in proc.stderr
    assert not (tmp_path / "report").exists()


def test_simulate_of_a_campaign_refuses_and_force_goes_on(base, tmp_path, capsys) -> None:
    """--force turns the errors into warnings: the run is simulated, the evidence still printed."""
    root = bad_copy(base, tmp_path, case_named("pitch in degrees"))
    proc = run_juno_here(capsys, "simulate", "--campaign", root, "--run", "dbp1", "--quiet")
    assert proc.returncode == 2 and "runs/t3d.csv, column 'pitch'" in proc.stderr
    proc = run_juno_here(capsys, "simulate", "--campaign", root, "--run", "dbp1", "--quiet", "--force")
    assert proc.returncode == 0, proc.stderr
    assert "warning (--force): runs/t3d.csv, column 'pitch'" in proc.stderr
    assert "run dbp1" in proc.stdout


def test_warnings_print_one_line_each_and_go_on(base, tmp_path, capsys) -> None:
    root = bad_copy(base, tmp_path, case_named("frozen total station"))
    proc = run_juno_here(capsys, "simulate", "--campaign", root, "--run", "dbp1", "--quiet")
    assert proc.returncode == 0, proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("warning: runs/t3d.csv, column 'pos_x'"), proc.stderr


def test_every_error_is_listed_at_once(base, tmp_path) -> None:
    root = bad_copy(base, tmp_path, case_named("pitch in degrees"))
    case_named("spins in rpm").write(root)
    lines: list[str] = []
    with pytest.raises(PlausibilityError) as err:
        enforce_plausibility(load_campaign(root), stream=lines.append)
    assert "runs/t3d.csv, column 'pitch'" in str(err.value) and "runs/dbp1.csv, column 'omega_left'" in str(err.value)
    assert "2 errors" in str(err.value)


# ------------------------------------------------------------------- the scan and gridding

def test_gridding_drops_the_far_point(base, tmp_path) -> None:
    """A 1e6 m point would stretch the grid over a kilometre; it is dropped and said so."""
    from juno.validate import grid_terrain

    root = bad_copy(base, tmp_path, case_named("a scan point a kilometre off"))
    campaign = load_campaign(root)
    said: list[str] = []
    _, grid = grid_terrain(campaign, campaign.run("t3d"), tmp_path, say=said.append)
    xmin, xmax, _, _ = grid.extent
    assert xmax - xmin < 12.0
    assert len(said) == 1 and "dropped 1 gross outlier" in said[0]


def test_gross_outliers_keeps_a_steep_real_mound() -> None:
    """A 0.5 m mound with 5 mm noise and no outliers has none; a 0.3 m spike is one."""
    rng = np.random.default_rng(3)
    xy = rng.uniform(-3, 3, size=(20000, 2))
    exact = 0.5 * np.exp(-(xy ** 2).sum(axis=1) / (2 * 0.5 ** 2))
    assert not gross_outliers(np.column_stack([xy, exact])).any()
    pts = np.column_stack([xy, exact + rng.normal(0, 0.005, len(xy))])
    assert not gross_outliers(pts).any()
    pts[7, 2] += 0.3
    assert np.flatnonzero(gross_outliers(pts)).tolist() == [7]


def test_outlier_k_gives_the_stated_false_alarm_rate() -> None:
    """k(n) = Phi^-1(1 - p / 2n): n Gaussian samples exceed it with probability about p."""
    assert outlier_threshold_k(2000, 1e-4) == pytest.approx(5.45, abs=0.01)
    p_one = math.erfc(outlier_threshold_k(2000, 1e-4) / math.sqrt(2))
    assert 2000 * p_one == pytest.approx(1e-4, rel=1e-6)


def test_a_drawbar_force_beyond_the_thrust_of_the_torques_is_an_error(base, tmp_path) -> None:
    """A wheel's thrust is at most its torque over its radius: the pull check holds on a plausible
    run and refuses its torques divided by the torque per ampere (a motor current in A)."""
    from juno.plausibility.sensors import check_pull
    limits = rover_limits()
    assert limits.torque_per_amp == pytest.approx(0.85 * 129.0 * 0.0465)
    root = bad_copy(base, tmp_path, case_named("torques logged as the motor current in A"))
    as_measured = read_run_csv(base / "runs" / "dbp3.csv", "drawbar")
    as_current = read_run_csv(root / "runs" / "dbp3.csv", "drawbar")
    assert check_pull(as_measured, "runs/dbp3.csv", limits) == []
    [finding] = check_pull(as_current, "runs/dbp3.csv", limits)
    assert finding.severity == "error" and finding.column == "torque_left"
    assert "holds back" in finding.message and "motor current in A" in finding.message


def test_limits_follow_from_the_motor_constants() -> None:
    lim = rover_limits()
    assert lim.stall_torque == pytest.approx(0.85 * 129 * 0.0465 * 24 / 0.2)
    assert lim.drive_torque == 400.0
    assert lim.top_speed == pytest.approx(24 / (0.0465 * 129) * 0.2794)
    assert rover_limits({"motor.voltage": 48.0}).no_load_spin == pytest.approx(2 * lim.no_load_spin)


# ----------------------------------------------------------------- synthetic data is clean

#: Every catalog effect (with "none"), twice with sensor noise and once without for three of them,
#: and every alternative form once: each is physics a rover could meet, so none may raise a finding.
SYNTHETIC = ([(e, 4101 + 10 * i + k, 1.0) for i, e in enumerate(EFFECTS) for k in (0, 1)]
             + [(e, 4201 + 10 * i, 0.0) for i, e in enumerate(EFFECTS) if e in ("none", "soil_patch", "terrain_offset")]
             + [(e, 4401 + 10 * i, 1.0) for i, e in enumerate(ALTERNATIVE_FORMS)])


@pytest.mark.parametrize("effect,seed,noise", SYNTHETIC, ids=[f"{e}-{s}-noise{n:g}" for e, s, n in SYNTHETIC])
def test_synthetic_campaigns_raise_nothing(small_campaign, effect, seed, noise) -> None:
    """Campaigns as ``juno synthesize`` writes them (short runs) are what a rover produces: no
    finding at all, with every hidden effect, with and without sensor noise."""
    c = small_campaign(seed, effect, noise)
    findings = check_campaign(c.campaign)
    assert findings == [], "\n".join(f"{f.severity}: {f}" for f in findings)


def test_a_synthetic_campaign_with_a_heavy_run_raises_nothing(tmp_path, harness_fmu) -> None:
    """The heavy drawbar run (80 % throttle, about 70 % slip) stays within the motors' limits."""
    from juno.synthesize import synthesize

    path = synthesize(tmp_path / "heavy", effect="grouser", seed=4301, time_scale=0.25, heavy_run=True,
                      fmu=harness_fmu)
    findings = check_campaign(load_campaign(path))
    assert findings == [], "\n".join(f"{f.severity}: {f}" for f in findings)


# ------------------------------------------------------------ a terrain run that turns

@pytest.fixture(scope="module")
def turning_campaign(tmp_path_factory, harness_fmu) -> Path:
    """An alternative-design campaign, whose terrain run turns about the ridge by differential
    spin (the default design's hardly turns)."""
    from juno.synthesize import synthesize

    return synthesize(tmp_path_factory.mktemp("turning") / "campaign", effect="none", seed=4501, design="alt",
                      fmu=harness_fmu)


def test_a_terrain_run_that_turns_with_its_wheels_raises_nothing(turning_campaign) -> None:
    findings = check_campaign(load_campaign(turning_campaign))
    assert findings == [], "\n".join(f"{f.severity}: {f}" for f in findings)


@pytest.mark.parametrize("mistake", ["spin columns swapped", "yaw clockwise"])
def test_a_rover_that_turns_against_its_wheels_is_refused(turning_campaign, tmp_path, mistake) -> None:
    """A skid-steered rover turns towards its slower side; with the spin columns swapped, or a yaw
    measured clockwise, the measured yaw rate follows the spin difference with the wrong sign.
    The error names the run's file and the swap it suspects."""
    root = tmp_path / "campaign"
    shutil.copytree(turning_campaign, root)

    def change(c):
        if mistake == "spin columns swapped":
            c["omega_left"], c["omega_right"] = c["omega_right"], c["omega_left"]
        else:
            c["yaw"] = -c["yaw"]
    edit_run(root, "t3d", change)
    errors = [f for f in check_campaign(load_campaign(root)) if f.severity == "error"]
    assert [(f.file, f.column) for f in errors] == [("runs/t3d.csv", "omega_left")], errors
    assert "turns against its wheels" in errors[0].message and "swapped" in errors[0].message


def test_spin_differences_too_small_to_steer_are_not_judged_whatever_the_yaw_does(turning_campaign, tmp_path) -> None:
    """On a slope the load shifts between the sides, their spins differ by a few percent, and the
    slope itself turns the rover, either way: differences under a tenth of the mean spin say
    nothing about which way the rover steers, so a yaw that turns against them is no error
    (the same run's spins differing as they do, swapped, is: the test above)."""
    root = tmp_path / "campaign"
    shutil.copytree(turning_campaign, root)

    def change(c):
        mean = 0.5 * (c["omega_left"] + c["omega_right"])
        difference = c["omega_right"] - c["omega_left"]
        # at most 6 % of the spin, and turned against the measured yaw as a swap would turn it
        small = -0.06 * np.abs(mean) * np.tanh(difference / 0.05)
        c["omega_left"], c["omega_right"] = mean - 0.5 * small, mean + 0.5 * small
    edit_run(root, "t3d", change)
    findings = check_campaign(load_campaign(root))
    assert not any("turns against its wheels" in f.message for f in findings), findings


def test_a_yaw_in_degrees_is_refused_where_the_rover_turns(turning_campaign, tmp_path) -> None:
    """A yaw logged in degrees turns the rover 57 times faster than its wheels' spin difference
    can: the error names the run's file, the yaw column and the unit it suspects."""
    root = tmp_path / "campaign"
    shutil.copytree(turning_campaign, root)

    def change(c):
        c["yaw"] = np.degrees(c["yaw"])
    edit_run(root, "t3d", change)
    errors = [f for f in check_campaign(load_campaign(root)) if f.severity == "error"]
    assert [(f.file, f.column) for f in errors] == [("runs/t3d.csv", "yaw")], errors
    assert "looks like degrees" in errors[0].message


def test_a_yaw_that_never_moves_while_the_wheels_steer_is_refused(turning_campaign, tmp_path) -> None:
    """A disconnected IMU writing 0.0 in every yaw sample, on a run whose spins steer the rover:
    the error names the run's file and the yaw column.  (A yaw holding still on a straight run
    is plausible: the format's example campaign, above.)"""
    root = tmp_path / "campaign"
    shutil.copytree(turning_campaign, root)
    constant("t3d", "yaw", 0.0)(root)
    errors = [f for f in check_campaign(load_campaign(root)) if f.severity == "error"]
    assert [(f.file, f.column) for f in errors] == [("runs/t3d.csv", "yaw")], errors
    assert "0 rad in every sample" in errors[0].message and "IMU" in errors[0].message


# ----------------------------------------------------- a heading against the path it drove

HEADING_MISTAKES = {
    "yaw in degrees on a run that hardly turns": lambda yaw: np.degrees(yaw),
    "a compass heading (clockwise from north)": lambda yaw: 0.5 * np.pi - yaw,
    "yaw from another reference direction": lambda yaw: yaw + 1.0,
}


@pytest.mark.parametrize("mistake", HEADING_MISTAKES)
def test_a_yaw_that_does_not_point_where_the_rover_goes_is_refused(base, tmp_path, mistake) -> None:
    """A rover driving forward moves along its heading, within the side slip of a skid-steered
    rover (under 0.3 rad in the median over any synthetic terrain run). A yaw that differs from
    the measured direction of travel by more than pi/4 in the median would have the rover moving
    more sideways than forward: the error names the terrain run's file, the yaw column and the
    likely mistakes, whether or not the run turns."""
    root = tmp_path / "campaign"
    shutil.copytree(base, root)

    def change(c):
        c["yaw"] = HEADING_MISTAKES[mistake](c["yaw"])
    edit_run(root, "t3d", change)
    errors = [f for f in check_campaign(load_campaign(root)) if f.severity == "error"]
    assert ("runs/t3d.csv", "yaw") in [(f.file, f.column) for f in errors], errors
    heading = next(f for f in errors if f.column == "yaw")
    assert "direction of travel" in heading.message and "degrees" in heading.message
    assert "compass heading" in heading.message


def straight_terrain_run(tmp_path: Path, speed: float, heading: float, yaw: Callable[[np.ndarray], np.ndarray]):
    """20 s driving straight at ``speed`` (m/s; < 0 backward, the wheels turning backward) along
    ``heading`` (rad), its total station at 5 Hz with 2 mm of noise, its yaw ``yaw(heading)``."""
    rng = np.random.default_rng(11)
    t = np.round(np.arange(0.0, 20.0, 0.01), 10)
    at_5_hz = np.arange(len(t)) % 20 == 0
    travelled = speed * t
    columns = {"time": t, "torque_left": np.full(len(t), 30.0), "torque_right": np.full(len(t), 30.0),
               "omega_left": np.full(len(t), speed / 0.2794), "omega_right": np.full(len(t), speed / 0.2794),
               "pos_x": np.where(at_5_hz, travelled * math.cos(heading) + rng.normal(0, 0.002, len(t)), np.nan),
               "pos_y": np.where(at_5_hz, travelled * math.sin(heading) + rng.normal(0, 0.002, len(t)), np.nan),
               "pos_z": np.where(at_5_hz, 0.5 + rng.normal(0, 0.002, len(t)), np.nan),
               "yaw": yaw(heading + rng.normal(0, 0.005, len(t)))}
    path = tmp_path / "t3d.csv"
    path.write_text(format_run_csv(columns))
    return read_run_csv(path, "terrain")


@pytest.mark.parametrize("speed", [0.3, -0.2], ids=["forward", "backward"])
def test_the_heading_check_follows_the_direction_the_wheels_drive(tmp_path, speed) -> None:
    """Driving backward, a rover moves against its heading; its yaw is right, and the check says
    nothing. The same yaw in degrees is refused either way (at 2.5 rad: 143 degrees, read as
    radians, point 2.5 rad away)."""
    from juno.plausibility.motion import check_heading

    assert check_heading(straight_terrain_run(tmp_path, speed, 2.5, lambda a: a), "runs/t3d.csv", rover_limits()) == []
    refused = check_heading(straight_terrain_run(tmp_path, speed, 2.5, np.degrees), "runs/t3d.csv", rover_limits())
    assert [(f.severity, f.column) for f in refused] == [("error", "yaw")]


def drawbar_run_on_a_unix_clock(tmp_path: Path, spike: tuple[str, int, float]) -> object:
    """20 s of a steady drawbar run at 50 Hz whose clock reads Unix time (1.7e9 s at its start),
    as a logger's clock does, with one sample of column ``spike[0]`` at row ``spike[1]`` set to
    ``spike[2]``."""
    rng = np.random.default_rng(5)
    t = 1_700_004_321.0 + np.arange(0.0, 20.0, 0.02)
    columns = {"time": t, "torque_left": 150 + rng.normal(0, 3, len(t)), "torque_right": 150 + rng.normal(0, 3, len(t)),
               "omega_left": np.full(len(t), 1.5), "omega_right": np.full(len(t), 1.5),
               "pos_x": 0.3 * (t - t[0]) + rng.normal(0, 0.002, len(t)), "pos_y": rng.normal(0, 0.002, len(t)),
               "pos_z": 0.39 + rng.normal(0, 0.002, len(t)), "drawbar_force": 300 + rng.normal(0, 5, len(t)),
               "pitch": -0.03 + rng.normal(0, 0.002, len(t))}
    name, row, value = spike
    columns[name][row] = value
    path = tmp_path / "dbp1.csv"
    path.write_text(format_run_csv(columns))
    return read_run_csv(path, "drawbar")


@pytest.mark.parametrize("spike", [("torque_left", 202, 2.742e5), ("pitch", 202, -0.2)],
                         ids=["beyond a limit", "an outlier"])
def test_a_message_locates_a_sample_on_a_unix_clock_to_the_millisecond(tmp_path, spike) -> None:
    """A clock that does not start at zero still locates the sample: its time is written to the
    millisecond the rows are logged at (1700004325.04 s), not to four digits (1.7e+09 s, the
    time of every row of the run alike)."""
    from juno.plausibility import check_run

    run = drawbar_run_on_a_unix_clock(tmp_path, spike)
    found = [f for f in check_run(run, "runs/dbp1.csv", rover_limits()) if f.column == spike[0]]
    assert found, "the spike is not reported"
    assert "line 204 (t = 1700004325.04 s)" in found[0].message


def pitch_at_25_hz_rocking_at_the_start(tmp_path: Path, glitch: dict[int, float]) -> object:
    """A drawbar run's pitch logged at 25 Hz (10 s): at the start the rover rocks back and forth
    at 2.2 Hz (0.025 rad, dying out in about a second, as a start against a load rocks it), then
    holds -0.015 rad, with 0.4 mrad of noise; the samples at the rows in ``glitch`` are moved by
    their values."""
    rng = np.random.default_rng(11)
    t = np.arange(0.0, 10.0, 0.04)
    pitch = -0.015 - 0.025 * np.exp(-1.5 * t) * np.sin(2 * np.pi * 2.2 * t) + rng.normal(0, 4e-4, len(t))
    for row, jump in glitch.items():
        pitch[row] += jump
    from juno.campaign import RunData
    return RunData(tmp_path / "dbp1.csv", "drawbar", {"time": t, "pitch": pitch}, lines=np.arange(2, len(t) + 2))


@pytest.mark.parametrize("glitch, flagged", [({}, []), ({150: 0.012}, [150]), ({5: 0.02, 6: 0.02}, [5, 6])],
                         ids=["the rocking alone", "a lone spike later", "a two-sample glitch in the rocking"])
def test_a_swing_a_few_samples_wide_is_motion_and_a_glitch_on_it_is_not(tmp_path, glitch, flagged) -> None:
    """The median of five clips the swing's extremes (its residual at the first trough exceeds
    the limit), but a quadratic through the neighbours follows them: no outlier. A spike, or a
    glitch two samples long on the swing itself, lies off both and is reported (at its rows)."""
    from juno.plausibility.outliers import _median_of_five, check_outliers

    run = pitch_at_25_hz_rocking_at_the_start(tmp_path, glitch)
    found = check_outliers(run, "runs/dbp1.csv", ["pitch"], rover_limits())
    if not flagged:
        pitch = run.columns["pitch"]
        clipped = np.max(np.abs(pitch - _median_of_five(pitch))[:30])
        assert clipped > 5 * np.std(pitch[-100:]), "the swing must be one the median alone would flag"
        assert found == []
        return
    assert len(found) == 1 and found[0].column == "pitch"
    lines = [int(row) + 2 for row in flagged]     # a header line, then 1-based rows
    assert any(f"line {line} " in found[0].message for line in lines), found[0].message


def yaw_wrapped_as_an_imu_logs_it(tmp_path: Path, glitch: dict[int, float]) -> object:
    """A terrain run's yaw logged at 100 Hz (10 s) by an IMU that reports it in (-pi, pi]: the
    rover turns at 0.15 rad/s from 2.8 rad, through pi at about 2.3 s (where the column jumps by
    -2 pi), with 5 mrad of noise; the samples at the rows in ``glitch`` are moved by their values."""
    rng = np.random.default_rng(12)
    t = np.arange(0.0, 10.0, 0.01)
    yaw = 2.8 + 0.15 * t + rng.normal(0, 0.005, len(t))
    for row, jump in glitch.items():
        yaw[row] += jump
    from juno.campaign import RunData
    return RunData(tmp_path / "t3d.csv", "terrain", {"time": t, "yaw": np.angle(np.exp(1j * yaw))},
                   lines=np.arange(2, len(t) + 2))


@pytest.mark.parametrize("glitch, flagged", [({}, []), ({600: 0.6}, [600]), ({229: 0.6}, [229])],
                         ids=["the turn alone", "a glitch after the wrap", "a glitch at the wrap"])
def test_a_heading_wrapping_through_pi_is_motion_and_a_glitch_on_it_is_not(tmp_path, glitch, flagged) -> None:
    """A heading that passes +-pi jumps by 2 pi in the column, the same angle on either side: the
    samples beside the jump are where the rover pointed, not outliers. A glitch on the heading,
    at the wrap or away from it, is still reported (at its row)."""
    from juno.plausibility.outliers import check_outliers

    run = yaw_wrapped_as_an_imu_logs_it(tmp_path, glitch)
    found = check_outliers(run, "runs/t3d.csv", ["yaw"], rover_limits())
    if not flagged:
        assert found == [], "\n".join(f"{f.severity}: {f}" for f in found)
        return
    assert len(found) == 1 and found[0].column == "yaw", found
    assert f"line {flagged[0] + 2} " in found[0].message, found[0].message


@pytest.mark.parametrize("rover, column, says", [
    ({"wheel.radius": 4.0}, "wheel.radius", "front and rear wheels would overlap"),
    ({"wheel.width": 1.5}, "wheel.width", "left and right wheels would overlap"),
])
def test_a_rover_whose_wheels_overlap_is_the_one_error(base, tmp_path, rover, column, says) -> None:
    """A length of the manifest's rover in another unit that still lies within the FMU's range (a
    wheel radius of 4 for 4 inches) makes wheels that overlap: the one error, on campaign.json and
    the key given, asking for metres; the runs' checks, whose limits all derive from the rover,
    are not made."""
    root = tmp_path / "campaign"
    shutil.copytree(base, root)
    manifest = json.loads((root / "campaign.json").read_text())
    manifest["rover"] = rover
    (root / "campaign.json").write_text(json.dumps(manifest))
    findings = check_campaign(load_campaign(root))
    assert len(findings) == 1, [str(f) for f in findings]
    f = findings[0]
    assert (f.severity, f.file, f.column) == ("error", "campaign.json", column)
    assert says in f.message and "is it in metres?" in f.message


def test_a_span_of_one_sample_is_named_by_its_time():
    """Findings name the times of what they found; a span of a single sample is its time, not a
    span from that time to itself."""
    from juno.plausibility.findings import _format_spans
    assert _format_spans([(0.5, 2.0), (3.25, 3.25)]) == "0.5-2 s, 3.25 s (one sample)"
    assert _format_spans([(float(i), i + 0.5) for i in range(6)]) == "0-0.5 s, 1-1.5 s, 2-2.5 s, 3-3.5 s and 2 more"
