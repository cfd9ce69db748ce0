"""Checks of how a run's rover moves against how its wheels turn: turning against the wheels,
a yaw in degrees, a heading that is not the direction of travel.

* **Turning.** A skid-steered rover turns towards its slower side: its yaw rate has the sign
  of ``omega_right - omega_left`` (whichever way it drives), less what slopes add. Where a run
  has ``yaw`` and both spins, the yaw rate over ``TURN_WINDOW`` (1 s) is correlated with the
  spin difference over the windows where that steers: at least ``TURN_SPIN_DIFFERENCE`` (0.05
  rad/s, ten times the spin sensors' noise) and at least ``TURN_SPIN_SHARE`` (a tenth) of the
  mean spin. Smaller differences come from the load shifting between the sides on a slope,
  where the slope turns the rover too, either way: of 25 synthetic terrain runs driven at equal
  throttles (15 of the default design, 10 of the alternative), one went against its spin
  differences of 5-8 % (correlation -0.97 over 11 windows, a clean campaign refused), while
  every run with ten or more windows of a tenth or more (14) followed the steering sign
  (correlation 0.94-0.99). At least ``TURN_WINDOWS`` (10) windows with a correlation below
  ``-TURN_CORRELATION`` (-0.7) is an error: the spin columns swapped, or a clockwise yaw. A
  run that hardly turns is not judged (swapped torque columns cannot be told at all). A yaw equal
  in every sample over those ten or more windows is an error: the spins steered the rover and the
  yaw never moved (a disconnected IMU writing 0.0). On a straight run a yaw may hold still (a
  heading logged in hundredths of a degree); the heading check below sees a dead one there if the
  rover travels another way.
* **Yaw units.** Over the same windows, where the yaw rate follows the spin difference
  (correlation above ``YAW_CORRELATION``, 0.3), the least-squares slope of the yaw rate against
  the kinematic rate ``wheel.radius * (omega_right - omega_left) / rover.track`` says how fast
  the rover turns for its spins; a yaw in degrees multiplies it by 57.3. Of 28 synthetic
  campaigns (every effect, both designs; over the windows where the spins differ by 0.05 rad/s
  or more), the 25 whose terrain run turns gave slopes of -0.02
  to 2.9 (1.2-1.7 where the correlation exceeds 0.9; the mound's flanks turn the rover too);
  with their yaw in degrees, 22 passed the correlation and gave 23-152. A slope above
  ``YAW_DEGREES_SLOPE`` (10, between the two) is an error: a rover that turned ten times faster
  than its spin difference drives it would be sliding sideways, not steering. A run that hardly
  turns is not judged here (the heading check below sees its yaw).
* **Heading.** A rover driving forward moves along its heading, within its side slip; driving
  backward, against it. Where a run has ``yaw``, positions and both spins, the direction of travel
  over ``TURN_WINDOW`` (1 s, from pos_x and pos_y; reversed where the wheels turn backward) is
  compared with the yaw in the windows where the rover moved ``HEADING_MOVE`` (0.1 m, ten times a
  total station's noise) or more with its wheels turning one way. A median disagreement beyond
  ``HEADING_ERROR`` (pi/4) is an error: the rover would be moving more sideways than forward over
  half its path. It catches a yaw in degrees whether or not the run turns, a compass heading
  (clockwise from north), a yaw from another reference direction (a magnetometer's), and
  positions in a frame the yaw is not measured in. Measured on 42 synthetic campaigns (every
  effect and decoy, both designs): 0.006-0.032 rad on the drawbar runs, 0.03-0.29 rad on the
  terrain runs (they slide on the mound's and ridge's flanks); with the yaw in degrees, 39 of the
  42 terrain runs gave 0.87-2.13 rad; the other 3 went unseen: a heading h in degrees, read as
  radians, is 57.3 h, which for some headings lies within pi/4 of h on the circle (at h = 2 rad,
  0.51 rad from it). As a compass heading, 1.44-1.79 rad on every run.
"""

from __future__ import annotations

import math

import numpy as np

from ..campaign import RunData, aligned
from .findings import Finding, _g
from .limits import RoverLimits
from .sensors import TURNING
from .windows import travel_over_windows

#: The turning check: yaw rates over TURN_WINDOW s against the sides' spin difference, in the
#: windows (TURN_WINDOWS or more) where it is at least TURN_SPIN_DIFFERENCE rad/s (ten times the
#: spin sensors' noise); a correlation below -TURN_CORRELATION is an error.
TURN_WINDOW = 1.0
TURN_SPIN_DIFFERENCE = 0.05
#: ... and at least this share of the sides' mean spin (module docstring, "Turning").
TURN_SPIN_SHARE = 0.1
TURN_WINDOWS = 10
TURN_CORRELATION = 0.7
#: The yaw-units check: a slope of the yaw rate against the kinematic rate r (omega_right -
#: omega_left) / track above this is an error (module docstring, "Yaw units").
YAW_DEGREES_SLOPE = 10.0
YAW_CORRELATION = 0.3
#: The heading check: the yaw against the direction of travel over TURN_WINDOW s, in the windows
#: (TURN_WINDOWS or more) where the rover moved HEADING_MOVE m or more and its wheels turn one way;
#: a median disagreement beyond HEADING_ERROR (the rover moving more sideways than forward) is an
#: error (module docstring, "Heading").
HEADING_MOVE = 0.1
HEADING_ERROR = math.pi / 4


def check_turning(run: RunData, file: str, limits: RoverLimits) -> list[Finding]:
    """A rover that turns against its wheels, or ``yaw`` in degrees (module docstring,
    "Turning" and "Yaw units")."""
    names = ("yaw", "omega_left", "omega_right")
    if not all(run.has(n) for n in names):
        return []
    ty, yaw = run.samples("yaw")
    if len(ty) < 2 or ty[-1] - ty[0] <= 2 * TURN_WINDOW:
        return []
    t = np.arange(ty[0] + TURN_WINDOW, ty[-1] - TURN_WINDOW, 0.5 * TURN_WINDOW)
    unwrapped = np.unwrap(yaw)
    rate = (np.interp(t + 0.5 * TURN_WINDOW, ty, unwrapped) - np.interp(t - 0.5 * TURN_WINDOW, ty, unwrapped)) \
        / TURN_WINDOW
    spins = aligned(run, ["omega_left", "omega_right"], t)
    difference = spins["omega_right"] - spins["omega_left"]
    mean_spin = 0.5 * np.abs(spins["omega_right"] + spins["omega_left"])
    with np.errstate(invalid="ignore"):
        material = np.isfinite(difference) & (np.abs(difference) >= np.maximum(TURN_SPIN_DIFFERENCE,
                                                                                TURN_SPIN_SHARE * mean_spin))
    material &= spins.coverage["omega_left"] & spins.coverage["omega_right"]
    steering = int(np.sum(material))
    if steering >= TURN_WINDOWS and np.all(yaw == yaw[0]):
        return [Finding("error", file, "yaw", f"is {_g(yaw[0])} rad in every sample ({len(yaw)} samples) while the "
                        f"sides' spins differ by {_g(TURN_SPIN_DIFFERENCE)} rad/s and {TURN_SPIN_SHARE:.0%} of their "
                        f"mean or more over {steering} {_g(TURN_WINDOW)} s windows, which turn a skid-steered rover: "
                        "is the IMU connected? The analysis compares yaw with the model's: leave the column out "
                        "if there is no IMU")]
    if steering < TURN_WINDOWS or np.std(rate[material]) == 0 or np.std(difference[material]) == 0:
        return []
    correlation = float(np.corrcoef(rate[material], difference[material])[0, 1])
    if correlation > YAW_CORRELATION:
        return _check_yaw_units(rate[material], difference[material], file, limits)
    if not correlation < -TURN_CORRELATION:
        return []
    return [Finding("error", file, "omega_left", f"the rover turns against its wheels: its yaw rate follows "
                    f"omega_right - omega_left with correlation {correlation:.2f} over the {int(np.sum(material))} "
                    f"{_g(TURN_WINDOW)} s windows where the sides' spins differ by {_g(TURN_SPIN_DIFFERENCE)} rad/s "
                    f"and {TURN_SPIN_SHARE:.0%} of their mean or more, and a skid-steered rover turns towards its "
                    "slower side: are omega_left and "
                    "omega_right swapped, or is yaw clockwise?")]


def _check_yaw_units(rate: np.ndarray, difference: np.ndarray, file: str, limits: RoverLimits) -> list[Finding]:
    """``yaw`` in degrees: the yaw rate (rad/s as read) against the kinematic rate of the spin
    difference (rad/s) over the turning windows (module docstring, "Yaw units")."""
    kinematic = limits.wheel_radius * difference / limits.track
    slope = float(np.sum(rate * kinematic) / np.sum(kinematic ** 2))
    if slope <= YAW_DEGREES_SLOPE:
        return []
    return [Finding("error", file, "yaw", f"the rover turns {_g(slope)} times as fast as its wheels' spin difference "
                    f"drives it (the least-squares slope of the yaw rate against wheel.radius * (omega_right - "
                    f"omega_left) / rover.track over {len(rate)} {_g(TURN_WINDOW)} s windows; a skid-steered rover "
                    f"gives about 1-2, over {_g(YAW_DEGREES_SLOPE)} it would be sliding sideways): looks like "
                    f"degrees (in radians: {_g(slope * np.pi / 180.0)})")]


def check_heading(run: RunData, file: str, limits: RoverLimits) -> list[Finding]:
    """``yaw`` that does not point where the rover goes: degrees, a compass heading, another
    reference direction, or positions in another frame (module docstring, "Heading")."""
    names = ("yaw", "pos_x", "pos_y", "omega_left", "omega_right")
    if not all(run.has(n) for n in names):
        return []
    travel = travel_over_windows(run, TURN_WINDOW)
    if travel is None:
        return []
    t, dx, dy = travel
    spins = aligned(run, ["omega_left", "omega_right"], t)
    forward = 0.5 * (spins["omega_left"] + spins["omega_right"])
    # The yaw as its sines and cosines: interpolating those needs no unwrapping, so one absurd
    # sample spoils only its own window.
    ty, yaw = run.samples("yaw")
    with np.errstate(invalid="ignore"):
        heading = np.arctan2(np.interp(t, ty, np.sin(yaw)), np.interp(t, ty, np.cos(yaw)))
    direction = np.arctan2(dy, dx) + np.where(forward < 0, np.pi, 0.0)
    moving = np.isfinite(heading) & (np.hypot(dx, dy) >= HEADING_MOVE) & (np.abs(forward) >= TURNING)
    moving &= spins.coverage["omega_left"] & spins.coverage["omega_right"] & (t >= ty[0]) & (t <= ty[-1])
    if int(np.sum(moving)) < TURN_WINDOWS:
        return []
    off = np.abs(np.angle(np.exp(1j * (heading[moving] - direction[moving]))))
    median = float(np.median(off))
    if median <= HEADING_ERROR:
        return []
    return [Finding("error", file, "yaw", f"the rover's heading (yaw) and its direction of travel (pos_x, pos_y "
                    f"over {_g(TURN_WINDOW)} s) differ by {_g(median)} rad in the median over the "
                    f"{int(np.sum(moving))} windows where it moved {_g(HEADING_MOVE)} m or more with its wheels "
                    f"turning one way: more than {_g(HEADING_ERROR)} rad, so it would be moving more sideways than "
                    "forward. Is yaw in degrees, a compass heading (clockwise from north), or measured from "
                    "another direction than the x axis of pos_x, pos_y?")]
