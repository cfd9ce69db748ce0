"""Checks of one run's columns against the rover's limits (:mod:`.limits`): units (degrees, rpm,
millimetres, milliseconds, kN), reversed signs, another datum, dead or frozen sensors.

* **Ground datum.** Drawbar runs are on flat ground at z = 0; the chassis rides at about its
  centre of gravity's height (wheel radius + ``rover.cgHeight``, 0.53 m) above it, less the
  sinkage. A drawbar run whose median pos_z lies more than ``DATUM_LIMIT`` (2) times that height
  above the ground is measured from another datum (a total station's or a map's: a UTM height
  of hundreds of metres), an error: compared with the model's flat ground, such heights would
  bend every fit. Below the ground's ``rover.pivotHeight`` (0.15 m), where the chassis
  reference point is with the wheels sunk to their axles (:mod:`.limits`, "Ride height"), no
  rover drives: a z axis pointing down, or pos_z holding another axis (a y-up frame), is an
  error too. The fits compare pos_z with the model's height.
* **Attitude.** The static tip-over angles are ``atan(half track / CG height)`` in roll and
  ``atan(half wheelbase / CG height)`` in pitch (CG height = wheel radius + ``rover.cgHeight``):
  0.91 and 0.66 rad. Beyond them a warning; beyond 1.2 rad (69 degrees, the rover on its side)
  an error: such angles are degrees.
* **Dead sensors.** A torque equal in every sample while the wheels turn is an error in a
  drawbar run (pulling a load takes drive torque), a warning otherwise. A roll or pitch equal in
  every sample while the wheels turn is an error in any run: the fits and the scan test compare
  them with the model's, and an IMU that measures has noise in its last digits (a disconnected
  one writes 0.0, which on flat ground bends the soil fitted to the pitch). A yaw may hold still
  on a straight run (a heading logged in hundredths of a degree): :mod:`.motion` judges it
  against the steering and the direction of travel. A
  ``drawbar_force`` equal in every sample while the wheels turn is an error in a drawbar run (a
  load cell that measures has noise, and a pulled load varies; a frozen one would be fitted as
  a constant pull), a warning otherwise. A position (pos_x and
  pos_y) repeated exactly for over ``FROZEN_SPAN`` s while the wheels turn is a warning: a
  total station that updates has noise in its last digits.
* **Spin or angle.** A wheel's spin in a drive goes up and down with its load and its
  sensor's noise; a wheel's angle counted up by its encoder only grows while the rover drives.
  A spin column that moves the same way in at least ``ANGLE_SHARE`` (95 %) of its steps and by
  more than ``ANGLE_RISE`` (1 rad) over the run is an error: the angle logged in the spin's
  place (its rate of change, which the message gives, is the spin). A measured spin goes up and
  down with its noise; a noise-free one holds still once it has reached its speed, and a drive
  test is driven at speed for most of its run: either moves one way in far fewer steps.
* **Drawbar force.** The wheels push at most the drive torque of both sides over the wheel
  radius: the same margins as the torque, times 2 / radius. At the other end, a load cell read
  in kN gives a drawbar force a thousand times too small: a run whose largest |drawbar_force|
  is under ``KILONEWTON_SHARE`` (1 %) of the thrust its torques give (their medians' sum over
  the wheel radius) while a thousand times it is a force the wheels can push. One such run is a
  warning (a run without load reads only the load cell's noise and the start's pull); every
  drawbar run of a campaign so is an error: drawbar tests load the rover.
* **Power.** On flat ground the hitch cannot take more power than the drive torques put into
  the wheels: the soil and the drivetrain only dissipate, and what the rover's speeding up
  stores it gives back when it slows. A drawbar run whose median power at the hitch
  (``drawbar_force`` times the speed of the positions over 1 s) exceeds the median power of its
  drive torques (``torque_left * omega_left + torque_right * omega_right``), over the windows
  where the wheels drive forward, is an error: the torques are too small. The message says
  when they look like the motor shaft's torque (before the ``motor.gearRatio`` gearbox) or kN m.
  Synthetic drawbar runs give 0.13-0.32.
* **Pull.** A wheel pushes the soil back with the shear under it, at its rim or, with lugs,
  further out: its thrust is at most its torque over its radius, and the drawbar pull, the
  thrust less the soil's resistance, is less still. A drawbar run whose median drawbar force
  times ``wheel.radius`` exceeds the median of ``torque_left + torque_right``, over the windows
  where the wheels drive forward, is an error: the torques are too small. The message says when
  they look like the motor current in A (the wheel torque over ``motor.efficiency *
  motor.gearRatio * motor.kt``, 5.1 N m per A with the defaults), the motor shaft's torque or
  kN m. 108 drawbar runs of 31 synthetic campaigns (every effect, both designs, the heavy run)
  give 0.23-0.66; with their torques as motor currents, every one exceeds 1. Stricter than the
  power bound by the wheels' slip, so it sees the motor current where the power does not.
* **Rolling.** A wheel that pulls a load slips: the rover moves slower than its rims roll, and
  lugs reach beyond the rim by at most half the radius (the largest lugs the FMU accepts). A
  drawbar run whose median speed (of the positions, over 1 s) exceeds ``ROLLING_LIMIT`` (1.5)
  times the median rim speed ``wheel.radius * (omega_left + omega_right) / 2``, over the windows
  where the wheels drive forward against the load, is an error: spins in rev/s (the message says so when 2 pi
  times them keeps the bound), or a ``wheel.radius`` too small. 147 synthetic drawbar runs give
  0.12-0.83 (the slip of the load); with their spins in rev/s, 128 of them exceed 1.5 (the rest
  slip by over 76 %, where 2 pi times too slow a spin still rolls faster than the rover).
* **Energy (terrain runs).** The drive torques' work over a run, the integral of
  ``torque_left * omega_left + torque_right * omega_right``, is what the rover gains in height
  (its weight times the rise of pos_z from the first to the last sample) and in speed, plus what
  the soil and the drivetrain dissipate, which is never negative. A run whose drive work falls
  short of the height it gains by more than the kinetic energy of the rover at its top speed and
  ``WORK_MARGIN`` (10 %) of the integral of each side's power's magnitude is an error: the torques' sign
  is reversed against the spins' (synthetic terrain runs dissipate 1.5-6 kJ; reversed, they fall
  short by as much). Drawbar runs are judged by their signs directly (below).
* **Driving in the steady window.** A drawbar test drives the rover against its load, and the
  paper-style fit compares the steady drive over the run's ``steady_window`` (the whole run
  without one): its weights divide by the rover's speed over the radius plus the wheels' spin. A
  drawbar run whose wheels' mean spin over that window lies within ``TURNING`` of zero (a window
  before the rover starts, a run logged with the rover parked, spins never written) is an error.
* **Time.** The rover's sensors sample at 5-100 Hz and a run lasts seconds to minutes: rows
  typically 10 s or more apart, or a run over an hour whose rows are typically half a second or
  more apart, are milliseconds (error); a run over an hour alone is a warning. A single gap of
  over an hour between rows typically less than half a second apart is an error (not one run).
"""

from __future__ import annotations

import math
from typing import Optional

import numpy as np

from ..campaign import RunData, aligned
from .findings import FloatArray, Finding, _format_spans, _g, _largest, _own, _spans, _time
from .limits import RoverLimits
from .windows import travel_over_windows

#: Torque (and drawbar force) warning: beyond this times the drive's limit, min(stall,
#: drive.torqueMax): the current sensor's noise (1.5 N m + 1 %) and the motor constants'
#: uncertainty stay well inside 20 %.
TORQUE_MARGIN = 1.2
#: Spin warning / error, as multiples of the no-load spin.
SPIN_WARN = 1.25
SPIN_ERROR = 3.0
#: A spin column moving one way in at least this share of its steps, by more than this many
#: radians, is a wheel angle (module docstring, "Spin or angle").
ANGLE_SHARE = 0.95
ANGLE_RISE = 1.0
#: Positions: typical (median) speed over SPEED_WINDOW s beyond this times the top speed.
SPEED_ERROR = 2.0
SPEED_WINDOW = 1.0
#: Attitude beyond which the rover would lie on its side (rad).
ANGLE_ERROR = 1.2
#: Time: longest plausible run (s), typical row step that no rover log has (s).
LONGEST_RUN = 3600.0
SLOW_STEP = 0.5
ABSURD_STEP = 10.0
#: A frozen position: the same pos_x and pos_y repeated for longer than this (s) while the
#: wheels turn faster than TURNING (rad/s). A total station that updates has noise in its last
#: digits; exact repeats over seconds mean it stopped updating.
FROZEN_SPAN = 2.0
TURNING = 0.2
#: A drawbar run's median drive torque of the wrong sign is an error beyond this share of the
#: drive torque per side: a reversed sensor sign, not a sensor offset.
SIGN_MATERIAL = 0.05
#: A drawbar run's median drawbar force of the wrong sign is an error beyond this share of the
#: thrust its measured torques give (their medians' sum over the wheel radius): a reversed sign,
#: not a load cell's offset on a run with a load near zero.
DRAWBAR_SIGN_MATERIAL = 0.25
#: A drawbar run whose largest |drawbar_force| stays below this share of the thrust its measured
#: torques give looks like a load cell read in kN (module docstring, "Drawbar force").
KILONEWTON_SHARE = 0.01
#: The power check: the hitch's and the wheels' power over POWER_WINDOW s, in POWER_WINDOWS or
#: more windows where the wheels drive forward (module docstring, "Power").
POWER_WINDOW = 1.0
POWER_WINDOWS = 10
#: A unit mistake is named for torques too small where undoing it brings the power or the pull
#: ratio within (UNDONE_FLOOR, 1]: synthetic drawbar runs give 0.13-0.32 and 0.23-0.66.
UNDONE_FLOOR = 0.05
#: A drawbar run moving faster than this times its wheels' rim speed is an error (module
#: docstring, "Rolling").
ROLLING_LIMIT = 1.5
#: The energy check: the share of the sides' drive power's integrated magnitude a run's drive work may
#: fall short of its gain in height by, beyond the kinetic energy at the top speed.
WORK_MARGIN = 0.1
#: A drawbar run's median pos_z beyond this multiple of the rover's centre-of-gravity height
#: (above or below its flat ground at z = 0) is measured from another datum.
DATUM_LIMIT = 2.0

RPM_PER_RAD_S = 60.0 / (2.0 * math.pi)


def check_time(run: RunData, file: str) -> list[Finding]:
    """Time in milliseconds: duration and typical row step (module docstring)."""
    t = run.time
    if len(t) < 2:
        return []
    duration = float(t[-1] - t[0])
    steps = np.diff(t)
    step = float(np.median(steps))
    gap = int(np.argmax(steps))
    lines = run.lines if run.lines is not None else np.arange(len(t)) + 2
    if steps[gap] > LONGEST_RUN and step < SLOW_STEP:
        return [Finding("error", file, "time", f"{_g(steps[gap])} s pass between line {int(lines[gap])} "
                        f"(t = {_time(t[gap])} s) and line {int(lines[gap + 1])} (t = {_time(t[gap + 1])} s), where rows "
                        f"are typically {_g(step)} s apart: not one run")]
    if step >= ABSURD_STEP:
        return [Finding("error", file, "time", f"rows are typically {_g(step)} s apart (the rover's sensors sample "
                        f"at 5-100 Hz): time looks like milliseconds")]
    if duration > LONGEST_RUN:
        evidence = f"the run lasts {_g(duration)} s ({_g(duration / 3600)} h) with rows typically {_g(step)} s apart"
        if step >= SLOW_STEP:
            return [Finding("error", file, "time", f"{evidence} (the rover's sensors sample at 5-100 Hz): "
                            "time looks like milliseconds")]
        return [Finding("warning", file, "time", f"{evidence}: longer than an hour; is time in milliseconds?")]
    return []


def check_angles(run: RunData, file: str, limits: RoverLimits) -> list[Finding]:
    """Roll and pitch: degrees (> ANGLE_ERROR rad), beyond the tip-over angle, or a dead IMU."""
    out = []
    for name, tip in (("roll", limits.roll_tip), ("pitch", limits.pitch_tip)):
        if not run.has(name):
            continue
        peak, _, vs, lines, i = _largest(run, name)
        if peak > ANGLE_ERROR:
            beyond = int(np.sum(np.abs(vs) > ANGLE_ERROR))
            hint = ": looks like degrees" if math.radians(peak) <= tip else ""
            out.append(Finding("error", file, name, f"|{name}| reaches {_g(peak)} (> {ANGLE_ERROR} rad, the rover "
                               f"on its side) at line {int(lines[i])}; {beyond} of {len(vs)} samples beyond "
                               f"{ANGLE_ERROR} rad{hint}"))
        elif peak > tip:
            out.append(Finding("warning", file, name, f"|{name}| reaches {_g(peak)} rad at line {int(lines[i])}, "
                               f"beyond the rover's static tip-over angle of {_g(tip)} rad"))
        spinning = _turning(run)
        if len(vs) > 1 and np.all(vs == vs[0]) and spinning > TURNING:
            out.append(Finding("error", file, name, f"is {_g(vs[0])} rad in every sample ({len(vs)} samples) while "
                               f"the wheels turn (median spin {_g(spinning)} rad/s): an IMU that measures has noise in "
                               "its last digits and the rover rocks as it drives; is the IMU connected? The analysis "
                               f"compares {name} with the model's: leave the column out if there is no IMU"))
    return out


def check_spins(run: RunData, file: str, limits: RoverLimits) -> list[Finding]:
    """Wheel spins beyond the motors' no-load spin (rpm instead of rad/s)."""
    out = []
    w0 = limits.no_load_spin
    for name in ("omega_left", "omega_right"):
        if not run.has(name):
            continue
        angle = _counted_angle(run, name)
        if angle:
            out.append(Finding("error", file, name, angle))
            continue
        peak, where, _, _, _ = _largest(run, name)
        hint = ""
        if peak / RPM_PER_RAD_S <= SPIN_WARN * w0:
            hint = f": looks like rpm ({_g(peak)} rpm = {_g(peak / RPM_PER_RAD_S)} rad/s)"
        elif math.radians(peak) <= SPIN_WARN * w0:
            hint = f": looks like degrees per second ({_g(peak)} deg/s = {_g(math.radians(peak))} rad/s)"
        if peak > SPIN_ERROR * w0:
            out.append(Finding("error", file, name, f"|{name}| reaches {_g(peak)} rad/s at {where}, more than "
                               f"{SPIN_ERROR:g} times the motors' no-load spin of {_g(w0)} rad/s{hint}"))
        elif peak > SPIN_WARN * w0:
            out.append(Finding("warning", file, name, f"|{name}| reaches {_g(peak)} rad/s at {where}, beyond the "
                               f"motors' no-load spin of {_g(w0)} rad/s{hint or ' (the wheel overran the motor)'}"))
    return out


def _counted_angle(run: RunData, name: str) -> str:
    """Why spin column ``name`` is a wheel's angle counted up over the run (module docstring,
    "Spin or angle"), or "" when it is not."""
    ts, vs, _ = _own(run, name)
    steps = np.diff(vs)
    total = float(vs[-1] - vs[0]) if len(vs) else 0.0
    if len(steps) < 2 or not abs(total) > ANGLE_RISE:
        return ""
    share = float(np.mean(np.sign(steps) == np.sign(total)))
    if share < ANGLE_SHARE:
        return ""
    rate = total / float(ts[-1] - ts[0])
    return (f"moves the same way in {share:.0%} of its steps and by {_g(total)} rad from t = {_time(ts[0])} to "
            f"{_time(ts[-1])} s: a wheel's angle counted up by its encoder, not its spin (a spin goes up and down "
            f"with the load and the sensor's noise); the format's {name} is the spin in rad/s, the angle's rate of "
            f"change (here {_g(rate)} rad/s on average)")


def _turning(run: RunData) -> float:
    """Median |spin| (rad/s) over both wheels' samples, 0 without spins."""
    vals = [np.abs(_own(run, n)[1]) for n in ("omega_left", "omega_right") if run.has(n)]
    return float(np.median(np.concatenate(vals))) if vals else 0.0


def check_torques(run: RunData, file: str, limits: RoverLimits) -> list[Finding]:
    """Drive torques beyond what the motors can give; an all-zero (or constant) torque."""
    out = []
    warn, error = TORQUE_MARGIN * limits.drive_torque, limits.plugging_torque
    spinning = _turning(run)
    for name in ("torque_left", "torque_right"):
        if not run.has(name):
            continue
        peak, where, vs, _, _ = _largest(run, name)
        if peak > error:
            out.append(Finding("error", file, name, f"|{name}| reaches {_g(peak)} N m at {where}, beyond the motors' "
                               f"electrical maximum of {_g(error)} N m (twice the stall torque "
                               f"eff * n * kt * V / Ra = {_g(limits.stall_torque)} N m)"))
        elif peak > warn:
            out.append(Finding("warning", file, name, f"|{name}| reaches {_g(peak)} N m at {where}, beyond "
                               f"{TORQUE_MARGIN:g} times the drive's limit of {_g(limits.drive_torque)} N m"))
        if np.all(vs == vs[0]) and spinning > TURNING:
            what = "is zero in every sample" if vs[0] == 0 else f"is {_g(vs[0])} N m in every sample"
            if run.kind == "drawbar":
                out.append(Finding("error", file, name, f"{what} while the wheels turn (median spin "
                                   f"{_g(spinning)} rad/s): pulling a drawbar load takes drive torque; is the "
                                   "torque sensor connected?"))
            else:
                out.append(Finding("warning", file, name, f"{what} while the wheels turn (median spin "
                                   f"{_g(spinning)} rad/s): is the torque sensor connected?"))
    return out


def _forward_spin(run: RunData) -> float:
    """Median spin (rad/s) of both sides' samples, signed (forward > 0); 0 without spins."""
    vals = [_own(run, n)[1] for n in ("omega_left", "omega_right") if run.has(n)]
    return float(np.median(np.concatenate(vals))) if vals else 0.0


def check_signs(run: RunData, file: str, limits: RoverLimits) -> list[Finding]:
    """Sign conventions of a drawbar run, from physics: on flat ground, a rover whose wheels
    drive forward while it pulls a load takes driving torque (torque and spin of one sign) and
    the load cell holds it back (``drawbar_force`` > 0).  A median of the other sign beyond
    SIGN_MATERIAL of the drive torque, or DRAWBAR_SIGN_MATERIAL of the thrust the measured
    torques give, is a reversed sign."""
    if run.kind != "drawbar" or _forward_spin(run) <= TURNING:
        return []
    out = []
    for name in ("torque_left", "torque_right"):
        if run.has(name):
            median = float(np.median(_own(run, name)[1]))
            if median < -SIGN_MATERIAL * limits.drive_torque:
                out.append(Finding("error", file, name, f"the median {name} is {_g(median)} N m while the wheels "
                                   f"drive forward (median spin {_g(_forward_spin(run))} rad/s): pulling a load on "
                                   "flat ground takes driving torque, of the spin's sign; is the sign reversed?"))
    torque = sum(abs(float(np.median(_own(run, n)[1]))) for n in ("torque_left", "torque_right") if run.has(n))
    if run.has("drawbar_force"):
        median = float(np.median(_own(run, "drawbar_force")[1]))
        if median < -DRAWBAR_SIGN_MATERIAL * torque / limits.wheel_radius:
            out.append(Finding("error", file, "drawbar_force", f"the median drawbar_force is {_g(median)} N while "
                               "the wheels drive forward: the load cell's force holds the rover back and is "
                               "positive then (docs/campaign-format.md); is the sign reversed?"))
    return out


def check_energy(run: RunData, file: str, limits: RoverLimits) -> list[Finding]:
    """A terrain run whose drive torques do less work than the rover gains in height (module
    docstring, "Energy")."""
    names = ("torque_left", "torque_right", "omega_left", "omega_right", "pos_z")
    if run.kind != "terrain" or not all(run.has(n) for n in names) or len(run.time) < 2:
        return []
    t = np.linspace(float(run.time[0]), float(run.time[-1]), max(2, min(20 * len(run.time), 20000)))
    at = aligned(run, list(names), t)
    left, right = at["torque_left"] * at["omega_left"], at["torque_right"] * at["omega_right"]
    dt = np.diff(t)

    def integral(power: FloatArray) -> float:
        return float(np.sum(0.5 * (power[1:] + power[:-1]) * dt))
    work = integral(left + right)
    spent = integral(np.abs(left) + np.abs(right))
    _, z, _ = _own(run, "pos_z")
    rise = limits.weight * float(z[-1] - z[0])
    kinetic = 0.5 * limits.mass * limits.top_speed ** 2
    if work - rise >= -(kinetic + WORK_MARGIN * spent):
        return []
    return [Finding("error", file, "torque_left", f"the drive torques do {_g(work)} J of work over the run (the integral "
                    f"of torque_left x omega_left + torque_right x omega_right) while the rover rises by "
                    f"{_g(float(z[-1] - z[0]))} m, {_g(rise)} J against its weight: the soil and the drivetrain would "
                    f"have given {_g(rise - work)} J, where they only take energy; is the torques' sign reversed (a "
                    "driving torque has the spin's sign)?")]


def check_steady_drive(run: RunData, file: str, window: Optional[tuple[float, float]],
                       manifest: str = "campaign.json") -> list[Finding]:
    """A drawbar run whose wheels do not turn, over the whole run or over its steady window,
    ``window`` (s; None: the whole run) (module docstring, "Driving in the steady window")."""
    if run.kind != "drawbar" or not (run.has("omega_left") and run.has("omega_right")) or len(run.time) < 2:
        return []
    whole = _turning(run)
    if whole <= TURNING:
        return [Finding("error", file, "omega_left", f"the wheels' median |spin| over the run is {_g(whole)} rad/s "
                        f"(within {TURNING:g} rad/s of standing still): a drawbar test drives the rover against its "
                        "load, and the fits compare that drive; is this the run's file, and are the wheels' "
                        "encoders connected?")]
    if window is None:
        return []
    a, b = window
    at = aligned(run, ["omega_left", "omega_right"], np.linspace(a, b, 101))
    spin = float(np.mean(0.5 * (at["omega_left"] + at["omega_right"])))
    if abs(spin) > TURNING:
        return []
    return [Finding("error", manifest, "steady_window", f"run {run.run_id!r}: the wheels' mean spin over its "
                    f"steady_window {_time(a)}-{_time(b)} s is {_g(spin)} rad/s (within {TURNING:g} rad/s of "
                    f"standing still; {file}): the steady window is where the rover drives steadily against its "
                    "load, which the paper-style fit averages; give the span where it does")]


def check_drawbar(run: RunData, file: str, limits: RoverLimits) -> list[Finding]:
    """Drawbar force beyond what the wheels of both sides can push."""
    name = "drawbar_force"
    if not run.has(name):
        return []
    peak, where, vs, _, _ = _largest(run, name)
    warn = 2.0 * TORQUE_MARGIN * limits.drive_torque / limits.wheel_radius
    error = 2.0 * limits.plugging_torque / limits.wheel_radius
    out = []
    if peak > error:
        out.append(Finding("error", file, name, f"|{name}| reaches {_g(peak)} N at {where}, beyond the {_g(error)} N "
                           "the wheels could push at the motors' electrical maximum"))
    elif peak > warn:
        out.append(Finding("warning", file, name, f"|{name}| reaches {_g(peak)} N at {where}, beyond "
                           f"{TORQUE_MARGIN:g} times the {_g(warn / TORQUE_MARGIN)} N the drive's torque limit pushes"))
    spinning = _turning(run)
    if len(vs) > 1 and np.all(vs == vs[0]) and spinning > TURNING:
        what = f"is {_g(vs[0])} N in every sample ({len(vs)} samples) while the wheels turn (median spin {_g(spinning)} rad/s)"
        if run.kind == "drawbar":
            out.append(Finding("error", file, name, f"{what}: a load cell that measures has noise in its last digits "
                               "and a drawbar load varies as the rover pulls it; is the load cell connected or frozen? "
                               "The drawbar fits compare the force with the model's"))
        else:
            out.append(Finding("warning", file, name, f"{what}: is the load cell connected?"))
    return out


def check_power(run: RunData, file: str, limits: RoverLimits) -> list[Finding]:
    """A drawbar run whose hitch takes more power than its drive torques give (module
    docstring, "Power")."""
    names = ("drawbar_force", "torque_left", "torque_right", "omega_left", "omega_right", "pos_x", "pos_y")
    if run.kind != "drawbar" or not all(run.has(n) for n in names):
        return []
    t, speed = _speed_over_windows(run, POWER_WINDOW)
    if t is None:
        return []
    at = aligned(run, [n for n in names if not n.startswith("pos_")], t)
    wheels = at["torque_left"] * at["omega_left"] + at["torque_right"] * at["omega_right"]
    hitch = at["drawbar_force"] * speed
    driving = (0.5 * (at["omega_left"] + at["omega_right"]) > TURNING) & (wheels > 0) & np.isfinite(hitch)
    driving &= np.logical_and.reduce(list(at.coverage.values()))
    if int(np.sum(driving)) < POWER_WINDOWS:
        return []
    ratio = float(np.median(hitch[driving]) / np.median(wheels[driving]))
    if not ratio > 1.0:
        return []
    hint = _small_torque_hint(ratio, limits)
    return [Finding("error", file, "torque_left", f"the hitch takes {_g(ratio)} times the power the drive torques "
                    f"put into the wheels (median drawbar_force x speed against median torque_left x omega_left + "
                    f"torque_right x omega_right over the {int(np.sum(driving))} {_g(POWER_WINDOW)} s windows where "
                    f"the wheels drive forward); on flat ground the soil only takes power: the torques are too "
                    f"small{hint}")]


def _small_torque_hint(ratio: float, limits: RoverLimits) -> str:
    """The mistakes that make drive torques too small by ``ratio`` (the power or the pull bound
    over 1), each named where undoing it brings the ratio to one drawbar runs give: at most 1
    and over ``UNDONE_FLOOR``."""
    mistakes = [what for what, factor in (
        (f"the motor current in A (the torque at the wheels is motor.efficiency x motor.gearRatio x motor.kt = "
         f"{_g(limits.torque_per_amp)} N m per A times it)", limits.torque_per_amp),
        (f"the motor shaft's torque, before the 1:{_g(limits.gear_ratio)} gearbox (motor.gearRatio; the format's "
         "torques are at the wheels)", limits.gear_ratio),
        ("kN m", 1000.0)) if factor > 0 and UNDONE_FLOOR < ratio / factor <= 1.0]
    return f": looks like {' or '.join(mistakes)}" if mistakes else ""


def check_pull(run: RunData, file: str, limits: RoverLimits) -> list[Finding]:
    """A drawbar run whose drawbar force exceeds the thrust its drive torques can give (module
    docstring, "Pull")."""
    names = ("drawbar_force", "torque_left", "torque_right", "omega_left", "omega_right")
    if run.kind != "drawbar" or not all(run.has(n) for n in names) or len(run.time) < 2:
        return []
    t = np.arange(float(run.time[0]) + 0.5 * POWER_WINDOW, float(run.time[-1]) - 0.5 * POWER_WINDOW,
                  0.5 * POWER_WINDOW)
    if not t.size:
        return []
    at = aligned(run, list(names), t)
    torque = at["torque_left"] + at["torque_right"]
    driving = (0.5 * (at["omega_left"] + at["omega_right"]) > TURNING) & (torque > 0)
    driving &= np.logical_and.reduce(list(at.coverage.values()))
    if int(np.sum(driving)) < POWER_WINDOWS:
        return []
    ratio = float(np.median(at["drawbar_force"][driving]) * limits.wheel_radius / np.median(torque[driving]))
    if not ratio > 1.0:
        return []
    hint = _small_torque_hint(ratio, limits)
    return [Finding("error", file, "torque_left", f"the drawbar force holds back {_g(ratio)} times the thrust the drive "
                    f"torques can give (median drawbar_force x wheel.radius = {_g(limits.wheel_radius)} m against "
                    f"median torque_left + torque_right over the {int(np.sum(driving))} {_g(POWER_WINDOW)} s windows "
                    f"where the wheels drive forward); a wheel's thrust is at most its torque over its radius: the "
                    f"torques are too small{hint}")]


def check_rolling(run: RunData, file: str, limits: RoverLimits) -> list[Finding]:
    """A drawbar run whose rover moves faster than its wheels roll (module docstring, "Rolling")."""
    names = ("omega_left", "omega_right", "pos_x", "pos_y", "drawbar_force")
    if run.kind != "drawbar" or not all(run.has(n) for n in names):
        return []
    t, speed = _speed_over_windows(run, POWER_WINDOW)
    if t is None:
        return []
    at = aligned(run, ["omega_left", "omega_right", "drawbar_force"], t)
    forward = 0.5 * (at["omega_left"] + at["omega_right"])
    # Forward by sign alone, not by TURNING: spins in another unit are what this check is for.
    # Only where the load holds the rover back: a towed wheel (the hitch pulling) rolls faster
    # than its rim.
    driving = (forward > 0) & (at["drawbar_force"] > 0) & np.isfinite(speed)
    driving &= np.logical_and.reduce(list(at.coverage.values()))
    if int(np.sum(driving)) < POWER_WINDOWS:
        return []
    ratio = float(np.median(speed[driving]) / (np.median(forward[driving]) * limits.wheel_radius))
    if not ratio > ROLLING_LIMIT:
        return []
    hint = ": looks like rev/s (the format's spins are in rad/s)" if ratio / (2 * math.pi) <= ROLLING_LIMIT else ""
    return [Finding("error", file, "omega_left", f"the rover moves {_g(ratio)} times as fast as its wheels' rims roll "
                    f"(the median speed of pos_x, pos_y over {_g(POWER_WINDOW)} s against wheel.radius = "
                    f"{_g(limits.wheel_radius)} m times the median of (omega_left + omega_right) / 2, over the "
                    f"{int(np.sum(driving))} windows where the wheels drive forward); a wheel pulling a load slips "
                    f"and moves slower than its rim: are the spins in another unit, or wheel.radius too small?{hint}")]


def _speed_over_windows(run: RunData, window: float) -> tuple[Optional[FloatArray], FloatArray]:
    """Times every half ``window`` (s) and the speed (m/s) of pos_x, pos_y over ``window``
    centred on each; (None, empty) for a run shorter than two windows."""
    travel = travel_over_windows(run, window)
    if travel is None:
        return None, np.empty(0)
    t, dx, dy = travel
    return t, np.hypot(dx, dy) / window


def drawbar_in_kilonewtons(run: RunData, limits: RoverLimits) -> Optional[str]:
    """The evidence (a sentence) that a drawbar run's ``drawbar_force`` is in kN (module
    docstring, "Drawbar force"), or None."""
    torques = [n for n in ("torque_left", "torque_right") if run.has(n)]
    if run.kind != "drawbar" or not run.has("drawbar_force") or not torques:
        return None
    thrust = sum(abs(float(np.median(_own(run, n)[1]))) for n in torques) / limits.wheel_radius
    peak, where, _, _, _ = _largest(run, "drawbar_force")
    pushable = 2.0 * limits.plugging_torque / limits.wheel_radius
    if not (thrust > 0 and peak < KILONEWTON_SHARE * thrust and 0 < 1000.0 * peak <= pushable):
        return None
    return (f"|drawbar_force| is at most {_g(peak)} N ({where}) while the measured torques push {_g(thrust)} N "
            f"(their medians over the wheel radius), under {KILONEWTON_SHARE:.0%} of it: looks like kN "
            f"({_g(1000.0 * peak)} N)")


def check_positions(run: RunData, file: str, limits: RoverLimits) -> list[Finding]:
    """Positions in millimetres (typical speed far beyond the top speed); a frozen position."""
    out = []
    for name in ("pos_x", "pos_y", "pos_z"):
        if not run.has(name):
            continue
        ts, vs, _ = _own(run, name)
        if len(ts) < 2 or ts[-1] - ts[0] < SPEED_WINDOW:
            continue
        j = np.searchsorted(ts, ts + SPEED_WINDOW)
        ok = j < len(ts)
        with np.errstate(over="ignore", invalid="ignore"):
            speed = np.abs(vs[j[ok]] - vs[ok]) / (ts[j[ok]] - ts[ok])
        typical = float(np.median(speed))
        if typical > SPEED_ERROR * limits.top_speed:
            hint = ": looks like millimetres" if typical / 1000.0 <= SPEED_ERROR * limits.top_speed else ""
            out.append(Finding("error", file, name, f"{name} changes typically by {_g(typical)} m/s (median over "
                               f"{SPEED_WINDOW:g} s), more than {SPEED_ERROR:g} times the rover's top speed of "
                               f"{_g(limits.top_speed)} m/s{hint}"))
    if run.has("pos_x") and run.has("pos_y"):
        out += _check_frozen(run, file)
    return out + check_ground_datum(run, file, limits)


def check_ground_datum(run: RunData, file: str, limits: RoverLimits) -> list[Finding]:
    """A drawbar run's heights measured from a datum other than its flat ground (module
    docstring, "Ground datum")."""
    if run.kind != "drawbar" or not run.has("pos_z"):
        return []
    height = float(np.median(_own(run, "pos_z")[1]))
    bound = DATUM_LIMIT * limits.cg_height
    if height < limits.pivot_height:
        return [Finding("error", file, "pos_z", f"the median pos_z is {_g(height)} m: drawbar runs are on flat "
                        "ground at z = 0 (docs/campaign-format.md), where the chassis reference point (the rocker "
                        f"pivots) rides about wheel.radius + rover.pivotHeight = {_g(limits.ride_height)} m high, "
                        f"and {_g(limits.pivot_height)} m (rover.pivotHeight) with the wheels sunk to their axles: "
                        "does z point down (the format's z is up), or does pos_z hold another axis (a y-up "
                        "frame)?")]
    if abs(height) <= bound:
        return []
    return [Finding("error", file, "pos_z", f"the median pos_z is {_g(height)} m: drawbar runs are on flat ground at "
                    f"z = 0 (docs/campaign-format.md), where the chassis stays within {_g(bound)} m of the ground "
                    f"({DATUM_LIMIT:g} times its centre of gravity's height of {_g(limits.cg_height)} m); measured from "
                    "another datum (a total station's, a map's): subtract the ground's height")]


def _check_frozen(run: RunData, file: str) -> list[Finding]:
    tx, x, _ = _own(run, "pos_x")
    if len(tx) < 2:
        return []
    y = aligned(run, "pos_y", tx, method="nearest")["pos_y"]
    same = (np.diff(x) == 0) & (np.diff(y) == 0)
    if not same.any():
        return []
    spins = [aligned(run, n, tx)[n] for n in ("omega_left", "omega_right") if run.has(n)]
    turning = np.max(np.abs(spins), axis=0) if spins else np.zeros(len(tx))
    held = same & (np.minimum(turning[:-1], turning[1:]) > TURNING)
    out = []
    for a, b in _spans(tx[:-1], held):
        k = int(np.searchsorted(tx, b)) + 1
        end = float(tx[min(k, len(tx) - 1)])
        if end - a > FROZEN_SPAN:
            out.append((a, end))
    if not out:
        return []
    total = sum(b - a for a, b in out)
    return [Finding("warning", file, "pos_x", f"the position (pos_x, pos_y) stays exactly the same for {_g(total)} s "
                    f"({_format_spans(out)}) while the wheels turn: the total station looks frozen")]
