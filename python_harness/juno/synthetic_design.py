"""Designs of synthetic campaigns: which runs, at which throttle, over which terrain, measured
by which sensors at which rates, noise levels and clocks.

``default`` is the paper's campaign (three drawbar runs at 45 % throttle, a 0.5 m mound, the
paper's instruments; the module docstring of :mod:`juno.synthesize` tables it).  ``alt`` is a
campaign the diagnosis was not shaped on, so that a method tuned on ``default`` can be tested
on data laid out differently:

* four drawbar runs (about 26, 30, 24 and 28 s) at one throttle drawn in 50-60 %, held loads
  of about 260, 430, 600 and 780 N (+-30 N) in a random order;
* a diagonal ridge 0.25-0.4 m high instead of the mound, with its own undulations (another
  seed family), and a 22 s terrain run starting at x = 0.5 m;
* other instruments: load cell 50 Hz 6 N; motor current 20 Hz 2.5 N m + 2 %; encoders 20 Hz
  0.01 rad/s; total station 10 Hz 3 mm horizontal, 4 mm vertical; IMU 50 Hz 0.005 rad roll and
  pitch, 0.008 rad yaw; LIDAR 800 points/m^2, 8 mm vertical;
* each run's clock starts where a data logger's clock happened to be (100-5000 s), with the
  steady windows in that clock;
* the columns in another order (IMU first, time still the first column as the format writes
  it) and an extra column the harness does not use (``battery_voltage``, V, 2 Hz, sagging
  with the drive current).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np


@dataclass(frozen=True)
class Sensor:
    """One measured column: ``column`` samples the truth output ``source`` at ``rate`` (Hz) from
    ``offset`` (s) with Gaussian noise of deviation ``sigma + relative |value|`` at noise 1.
    ``clock`` names the instrument's clock (``motor``, ``imu``, ``station``, ``loadcell``)."""

    column: str
    source: str
    rate: float
    sigma: float
    offset: float
    clock: str
    relative: float = 0.0
    drawbar_only: bool = False


Surface = Callable[[np.ndarray, np.ndarray, int], np.ndarray]


def mound_surface(x: np.ndarray, y: np.ndarray, rng_seed: int) -> np.ndarray:
    """True elevation (m): a 0.5 m mound plus gentle undulations of about 1 cm."""
    rng = np.random.default_rng(rng_seed + 7919)
    z = 0.5 * np.exp(-((x - 4.0) ** 2 / (2 * 0.9**2) + (y - 0.35) ** 2 / (2 * 0.7**2)))
    for _ in range(4):
        kx, ky = rng.uniform(1.0, 3.0, 2)
        phase = rng.uniform(0, 2 * np.pi)
        z = z + 0.004 * np.sin(kx * x + ky * y + phase)
    return z


def ridge_surface(x: np.ndarray, y: np.ndarray, rng_seed: int) -> np.ndarray:
    """True elevation (m): a ridge 0.25-0.4 m high (Gaussian profile, sigma 0.5-0.8 m) crossing
    the test area at 3.5-5 m along x, 20-40 degrees off the y axis, plus undulations of about
    1.5 cm (a seed family of its own, so no draw is shared with the mound)."""
    rng = np.random.default_rng(rng_seed + 104729)
    height, width = rng.uniform(0.25, 0.4), rng.uniform(0.5, 0.8)
    x_cross = rng.uniform(3.5, 5.0)
    angle = np.radians(rng.uniform(20.0, 40.0)) * rng.choice([-1.0, 1.0])
    distance = (x - x_cross) * np.cos(angle) - y * np.sin(angle)   # across the ridge's crest line
    z = height * np.exp(-distance**2 / (2 * width**2))
    for _ in range(5):
        kx, ky = rng.uniform(0.8, 2.5, 2)
        phase = rng.uniform(0, 2 * np.pi)
        z = z + 0.006 * np.sin(kx * x + ky * y + phase)
    return z


@dataclass(frozen=True)
class Design:
    """Everything about a synthetic campaign that is not the truth: runs, loads, throttle,
    terrain, instruments and clocks (times in s at ``time_scale`` 1, loads in N)."""

    name: str
    drawbar_runs: tuple[tuple[str, float, tuple[float, float]], ...]   # (id, duration, steady window)
    held_loads: tuple[float, ...]        # one per drawbar run, shuffled
    load_jitter: float                   # each load +- this, uniform
    throttle: tuple[float, float]        # drawn uniformly once per campaign (equal ends: fixed)
    surface: Surface
    terrain_duration: float
    terrain_start: tuple[float, float]   # (init.x, init.y) of the terrain run, m
    sensors: tuple[Sensor, ...]          # in column order
    scan_density: float                  # LIDAR points per m^2
    scan_sigma: float                    # LIDAR vertical noise at noise 1, m
    clock_start: tuple[float, float] | None = None   # range of each run's first clock reading; None: 0
    extra_columns: bool = False          # add battery_voltage


PAPER_SENSORS = (
    Sensor("drawbar_force", "drawbarForce", 100, 4.0, 0.0, "loadcell", drawbar_only=True),
    Sensor("torque_left", "torqueLeftApplied", 50, 1.5, 0.002, "motor", relative=0.01),
    Sensor("torque_right", "torqueRightApplied", 50, 1.5, 0.002, "motor", relative=0.01),
    Sensor("omega_left", "omegaLeft", 50, 0.005, 0.004, "motor"),
    Sensor("omega_right", "omegaRight", 50, 0.005, 0.004, "motor"),
    Sensor("pos_x", "x", 5, 0.002, 0.013, "station"),
    Sensor("pos_y", "y", 5, 0.002, 0.013, "station"),
    Sensor("pos_z", "z", 5, 0.003, 0.013, "station"),
    Sensor("roll", "roll", 100, 0.003, 0.001, "imu"),
    Sensor("pitch", "pitch", 100, 0.003, 0.001, "imu"),
    Sensor("yaw", "yaw", 100, 0.005, 0.001, "imu"),
)

ALT_SENSORS = (
    Sensor("pitch", "pitch", 50, 0.005, 0.003, "imu"),
    Sensor("roll", "roll", 50, 0.005, 0.003, "imu"),
    Sensor("yaw", "yaw", 50, 0.008, 0.003, "imu"),
    Sensor("pos_z", "z", 10, 0.004, 0.031, "station"),
    Sensor("pos_y", "y", 10, 0.003, 0.031, "station"),
    Sensor("pos_x", "x", 10, 0.003, 0.031, "station"),
    Sensor("omega_right", "omegaRight", 20, 0.01, 0.007, "motor"),
    Sensor("omega_left", "omegaLeft", 20, 0.01, 0.007, "motor"),
    Sensor("torque_right", "torqueRightApplied", 20, 2.5, 0.011, "motor", relative=0.02),
    Sensor("torque_left", "torqueLeftApplied", 20, 2.5, 0.011, "motor", relative=0.02),
    Sensor("drawbar_force", "drawbarForce", 50, 6.0, 0.005, "loadcell", drawbar_only=True),
)

DESIGNS: dict[str, Design] = {
    "default": Design(
        name="default",
        drawbar_runs=(("dbp1", 22.0, (8.0, 18.0)), ("dbp2", 35.0, (15.0, 25.0)), ("dbp3", 32.0, (15.0, 25.0))),
        held_loads=(320.0, 520.0, 720.0), load_jitter=40.0, throttle=(0.45, 0.45),
        surface=mound_surface, terrain_duration=30.0, terrain_start=(0.8, 0.0),
        sensors=PAPER_SENSORS, scan_density=25000 / 20.8, scan_sigma=0.005),
    "alt": Design(
        name="alt",
        drawbar_runs=(("dbp1", 26.0, (10.0, 22.0)), ("dbp2", 30.0, (12.0, 26.0)), ("dbp3", 24.0, (10.0, 20.0)),
                      ("dbp4", 28.0, (12.0, 24.0))),
        held_loads=(260.0, 430.0, 600.0, 780.0), load_jitter=30.0, throttle=(0.5, 0.6),
        surface=ridge_surface, terrain_duration=22.0, terrain_start=(0.5, 0.0),
        sensors=ALT_SENSORS, scan_density=800.0, scan_sigma=0.008,
        clock_start=(100.0, 5000.0), extra_columns=True),
}


def design_named(name: str) -> Design:
    """The design called ``name`` (ValueError naming the known ones otherwise)."""
    if name not in DESIGNS:
        raise ValueError(f"unknown design '{name}'; known: {', '.join(DESIGNS)}")
    return DESIGNS[name]


def battery_voltage(rng: np.random.Generator, t: np.ndarray, torque_left: np.ndarray,
                    torque_right: np.ndarray, noise: float) -> np.ndarray:
    """A 24 V pack's terminal voltage (V) at times ``t`` (s): 25.2 V sagging by 4 mV per N m of
    total drive torque (the drive current through the pack's resistance), 20 mV noise."""
    return 25.2 - 0.004 * (np.abs(torque_left) + np.abs(torque_right)) + noise * 0.02 * rng.standard_normal(len(t))
