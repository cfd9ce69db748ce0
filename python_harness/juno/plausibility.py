"""Plausibility of measured data: say clearly what is wrong before any fit.

A campaign that reads without a format error can still hold data that no rover produced: angles
in degrees, spins in rpm, positions in millimetres, time in milliseconds, a torque sensor that
was never connected, a frozen total station, a single absurd sample, a scan with a point a
kilometre away or a scan that does not cover the path. :func:`check_campaign` reads every run
(and every terrain run's scan) and returns :class:`Finding` s, each naming the file, the column
and the evidence::

    runs/t3d.csv, column 'pitch': |pitch| reaches 9.448 (> 1.2 rad, the rover on its side) at
    line 1518; 516 of 750 samples beyond 1.2 rad: looks like degrees

Severity follows one rule: **error** where no rover could have produced the data (beyond a
physical limit of the rover with a margin), **warning** where the data may be legitimate but
is suspicious. :func:`enforce_plausibility` is what the commands that read measured data run
right after loading the campaign: errors stop them (all errors listed at once) unless forced.

The limits are the rover's own physics, from its FMU parameters (defaults below, overridden by
the campaign's ``rover`` entry):

* **Motor torque.** A DC motor gives its largest steady torque at stall, at full voltage:
  ``T_stall = eff * n * kt * V / Ra`` per side (612 N m with the defaults); the drive controller
  further limits it to ``drive.torqueMax`` (400 N m). The electrical maximum of all is plugging,
  full voltage against the back-EMF of a wheel turning backwards at no-load speed: twice the
  stall torque. Torque beyond ``TORQUE_MARGIN`` times the drive's limit is a warning, beyond the
  plugging bound an error.
* **Spin.** The no-load spin ``omega_0 = V / (kt * n)`` (4.0 rad/s) is the fastest the motors
  turn a wheel; a wheel may overrun it a little downhill (warning beyond ``SPIN_WARN`` times it)
  but not three times over (error beyond ``SPIN_ERROR`` times it: the rover pushed at three
  times its top speed). rpm are 9.55 times rad/s.
* **Speed.** The top speed is ``omega_0 * wheel.radius`` (1.1 m/s). Positions whose typical
  speed over 1 s exceeds twice that are not in metres.
* **Turning.** A skid-steered rover turns towards its slower side: its yaw rate has the sign
  of ``omega_right - omega_left`` (whichever way it drives), less what slopes add. Where a run
  has ``yaw`` and both spins, the yaw rate over ``TURN_WINDOW`` (1 s) is correlated with the
  spin difference over the windows where that is at least ``TURN_SPIN_DIFFERENCE`` (0.05
  rad/s); at least ``TURN_WINDOWS`` (10) of them with a correlation below
  ``-TURN_CORRELATION`` (-0.7) is an error: the spin columns swapped, or a clockwise yaw. A
  run that hardly turns is not judged (swapped torque columns cannot be told at all).
* **Yaw units.** Over the same windows, where the yaw rate follows the spin difference
  (correlation above ``YAW_CORRELATION``, 0.3), the least-squares slope of the yaw rate against
  the kinematic rate ``wheel.radius * (omega_right - omega_left) / rover.track`` says how fast
  the rover turns for its spins; a yaw in degrees multiplies it by 57.3. Of 28 synthetic
  campaigns (every effect, both designs), the 25 whose terrain run turns gave slopes of -0.02
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
  42 terrain runs gave 0.87-2.13 rad (the rest head almost along x, where degrees and radians
  nearly agree); as a compass heading, 1.44-1.79 rad on every run.
* **Ground datum.** Drawbar runs are on flat ground at z = 0; the chassis rides at about its
  centre of gravity's height (wheel radius + ``rover.cgHeight``, 0.53 m) above it, less the
  sinkage. A drawbar run whose median pos_z lies more than ``DATUM_LIMIT`` (2) times that height
  from the ground is measured from another datum (a total station's or a map's: a UTM height
  of hundreds of metres), an error: compared with the model's flat ground, such heights would
  bend every fit.
* **Attitude.** The static tip-over angles are ``atan(half track / CG height)`` in roll and
  ``atan(half wheelbase / CG height)`` in pitch (CG height = wheel radius + ``rover.cgHeight``):
  0.91 and 0.66 rad. Beyond them a warning; beyond 1.2 rad (69 degrees, the rover on its side)
  an error: such angles are degrees.
* **Dead sensors.** A torque equal in every sample while the wheels turn is an error in a
  drawbar run (pulling a load takes drive torque), a warning otherwise. A position (pos_x and
  pos_y) repeated exactly for over ``FROZEN_SPAN`` s while the wheels turn is a warning: a
  total station that updates has noise in its last digits.
* **Drawbar force.** The wheels push at most the drive torque of both sides over the wheel
  radius: the same margins as the torque, times 2 / radius. At the other end, a load cell read
  in kN gives a drawbar force a thousand times too small: a run whose largest |drawbar_force|
  is under ``KILONEWTON_SHARE`` (1 %) of the thrust its torques give (their medians' sum over
  the wheel radius) while a thousand times it is a force the wheels can push. One such run is a
  warning (a run without load reads only the load cell's noise and the start's pull); every
  drawbar run of a campaign so is an error: drawbar tests load the rover.
* **Time.** The rover's sensors sample at 5-100 Hz and a run lasts seconds to minutes: rows
  typically 10 s or more apart, or a run over an hour whose rows are typically half a second or
  more apart, are milliseconds (error); a run over an hour alone is a warning. A single gap of
  over an hour between rows typically less than half a second apart is an error (not one run).
* **Single absurd samples** (any known column): each sample is compared with the median of the
  five samples around it (its column's own samples; a step or a monotone transient has no
  residual, a lone spike has). The noise's standard deviation is estimated robustly from the
  second differences, which cancel a linear trend: for white Gaussian noise of deviation s they
  have deviation s * sqrt(6), and 1.4826 * MAD is the standard deviation of Gaussian data, so
  ``s = 1.4826 * MAD(d2) / sqrt(6)`` (exact zeros left out: they are held samples, not noise).
  The residual from the median of five then has the tails of a Gaussian of deviation
  ``RESIDUAL_TAIL * s`` (1.14: the other four samples' median has a variance of 0.3 s^2;
  measured 1.09 over 2 million samples). A sample is an outlier when its residual exceeds both
  ``k * RESIDUAL_TAIL * s`` and a quarter of the column's robust span (the range of the
  running median of five, which no lone spike reaches). ``k`` is chosen so that Gaussian noise
  over the column's n samples raises a false alarm with probability ``FALSE_ALARM``:
  ``k = Phi^-1(1 - FALSE_ALARM / (2 n))``, with Student's t in place of Phi at the MAD's
  0.37 n degrees of freedom because s is itself estimated (5.5 for 2000 samples, 9.4 for the
  28 samples of a 5 Hz column over 5.5 s). The span term keeps noise-free data (MAD = 0) from
  flagging its own curvature. An outlier is an error when its residual exceeds ten times the
  column's span (nothing the run measured), else a warning.

A single-wheel testbed table (wheel_rig runs, :func:`check_rig`) is checked against the wheel
of its manifest entry and against friction:

* **Slip** is a fraction: a slip of 1 or more (the wheel spinning infinitely fast at the
  carriage's speed) is an error, "looks like percent" when the slips lie within 0-100.
* **Load and forces.** The soil's shear strength limits what a wheel transmits: drawbar pull,
  lateral force and the torque over the radius are at most about (tan phi + c A / W) times the
  load, below 1 for every soil simulant (phi < 45 degrees). A ratio beyond ``RIG_FORCE_ERROR``
  (2) is an error (a load in kg, or forces in another unit), beyond ``RIG_FORCE_WARN`` (1) a
  warning. A load that is not > 0 is an error.
* **Sinkage** beyond the wheel radius (the axle under the surface) is an error, "looks like
  millimetres" when a thousandth of it fits.
* **Slip angle** beyond pi/2 is an error ("looks like degrees"), beyond ``RIG_ANGLE_WARN``
  (pi/4, beyond testbed practice) a warning.
* **The wheel** (manifest): a radius beyond 5 m, a width beyond 1 m, lugs beyond 0.1 m or beyond
  half the radius are errors (millimetres), the FMU's own parameter ranges.

The scan (terrain runs): gross outliers are found by :func:`juno.pointcloud.gross_outliers`
(a warning naming them: the gridding drops them), and the measured path, widened by the wheel
footprint, must lie on the gridded scan (:func:`path_off_scan`): off it for more than
``OFF_SCAN_ERROR`` (10 %) of the run's position samples is an error (the replay would be
compared with the measurements over unmeasured ground for a significant part of the run), a
briefer excursion a warning; both name the run and the time spans.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from pathlib import Path
from statistics import NormalDist
from typing import Callable, Iterable, Mapping, Optional, TextIO, Union

import numpy as np
from numpy.typing import NDArray

from .campaign import (KNOWN_COLUMNS, Campaign, RigTable, RunData, RunSpec, aligned, read_rig, read_run,
                       read_terrain_points)
from .errors import InputError
from .pointcloud import GRID_MARGIN, gross_outliers
from .rover_model import fmu_defaults

FloatArray = NDArray[np.float64]

__all__ = [
    "Finding",
    "RoverLimits",
    "rover_limits",
    "check_run",
    "check_signs",
    "check_scan",
    "check_rig",
    "path_off_scan",
    "check_campaign",
    "enforce_plausibility",
    "PlausibilityError",
    "outlier_threshold_k",
]

#: The FMU parameters the limits derive from: the FMU's defaults (juno.rover_model), which the
#: campaign's ``rover`` overrides.
ROVER_PARAMETERS = ("wheel.radius", "wheel.width", "rover.track", "rover.wheelbase", "rover.cgHeight",
                    "motor.voltage", "motor.kt", "motor.resistance", "motor.gearRatio", "motor.efficiency",
                    "drive.torqueMax")

#: Torque (and drawbar force) warning: beyond this times the drive's limit, min(stall,
#: drive.torqueMax): the current sensor's noise (1.5 N m + 1 %) and the motor constants'
#: uncertainty stay well inside 20 %.
TORQUE_MARGIN = 1.2
#: Spin warning / error, as multiples of the no-load spin.
SPIN_WARN = 1.25
SPIN_ERROR = 3.0
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
#: Probability that Gaussian noise over one column raises an outlier finding.
FALSE_ALARM = 1e-4
#: Gaussian efficiency of the MAD as a scale estimate (degrees of freedom per sample).
MAD_EFFICIENCY = 0.37
#: Tail deviation of a white Gaussian sample's residual from its median of five, per unit noise.
RESIDUAL_TAIL = math.sqrt(1.3)
#: An outlier's residual must also exceed this fraction of the column's robust span.
SPAN_FRACTION = 0.25
#: ... and is an error beyond this multiple of the span.
ABSURD_SPAN = 10.0
#: The turning check: yaw rates over TURN_WINDOW s against the sides' spin difference, in the
#: windows (TURN_WINDOWS or more) where it is at least TURN_SPIN_DIFFERENCE rad/s (ten times the
#: spin sensors' noise); a correlation below -TURN_CORRELATION is an error.
TURN_WINDOW = 1.0
TURN_SPIN_DIFFERENCE = 0.05
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
#: A drawbar run's median pos_z beyond this multiple of the rover's centre-of-gravity height
#: (above or below its flat ground at z = 0) is measured from another datum.
DATUM_LIMIT = 2.0
#: Path off the scan for more than this fraction of the run's position samples: an error.
OFF_SCAN_ERROR = 0.10

#: Single-wheel testbed: force (drawbar pull, lateral force, torque / radius) over the load
#: beyond which a table is a warning / an error (module docstring).
RIG_FORCE_WARN = 1.0
RIG_FORCE_ERROR = 2.0
#: Slip angle beyond which a testbed point is a warning (rad); beyond pi/2 an error.
RIG_ANGLE_WARN = math.pi / 4
#: The rig wheel's dimensions the FMU accepts (m): radius, width, lug height.
RIG_WHEEL_LIMITS = {"radius": 5.0, "width": 1.0, "lug_height": 0.1}

RPM_PER_RAD_S = 60.0 / (2.0 * math.pi)


@dataclass(frozen=True)
class Finding:
    """One implausibility of the measured data.

    Attributes:
        severity: "error" (no rover could have produced it) or "warning" (may be legitimate).
        file: the file, relative to the campaign folder (``runs/dbp1.csv``).
        column: the column (``pitch``), or the coordinate of a scan (``z``).
        message: what is wrong and the evidence, with units.
    """

    severity: str
    file: str
    column: str
    message: str

    def __str__(self) -> str:
        return f"{self.file}, column '{self.column}': {self.message}"


class PlausibilityError(InputError):
    """The measured data hold errors (every error finding is in the message)."""


@dataclass(frozen=True)
class RoverLimits:
    """Physical limits of the rover (SI units), derived from its parameters (module docstring)."""

    stall_torque: float      # N m per side at full voltage, zero spin
    drive_torque: float      # N m per side: min(stall, drive.torqueMax)
    no_load_spin: float      # rad/s
    top_speed: float         # m/s
    wheel_radius: float      # m
    half_length: float       # m: wheelbase / 2 + wheel radius (footprint ahead / behind)
    half_width: float        # m: track / 2 + wheel width / 2
    roll_tip: float          # rad
    pitch_tip: float         # rad
    cg_height: float = 0.0   # m: wheel radius + rover.cgHeight, the CG over flat ground
    track: float = 0.0       # m: rover.track, between the wheels' centre planes

    @property
    def plugging_torque(self) -> float:
        """Electrical maximum (N m per side): full voltage against the no-load back-EMF."""
        return 2.0 * self.stall_torque


def rover_limits(rover: Optional[Mapping[str, object]] = None) -> RoverLimits:
    """The limits of the rover with the FMU defaults overridden by ``rover`` (numbers only)."""
    defaults = fmu_defaults()
    p = {k: defaults[k] for k in ROVER_PARAMETERS}
    for k, v in (rover or {}).items():
        if k in p and isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v > 0:
            p[k] = float(v)
    n, kt, volt, ra = p["motor.gearRatio"], p["motor.kt"], p["motor.voltage"], p["motor.resistance"]
    stall = p["motor.efficiency"] * n * kt * volt / ra
    omega0 = volt / (kt * n)
    r = p["wheel.radius"]
    cg = r + p["rover.cgHeight"]
    return RoverLimits(
        stall_torque=stall, drive_torque=min(stall, p["drive.torqueMax"]), no_load_spin=omega0,
        top_speed=omega0 * r, wheel_radius=r, half_length=0.5 * p["rover.wheelbase"] + r,
        half_width=0.5 * p["rover.track"] + 0.5 * p["wheel.width"],
        roll_tip=math.atan2(0.5 * p["rover.track"], cg), pitch_tip=math.atan2(0.5 * p["rover.wheelbase"], cg),
        cg_height=cg, track=p["rover.track"])


# --------------------------------------------------------------------------------------------
# Helpers
# --------------------------------------------------------------------------------------------

def outlier_threshold_k(n: int, false_alarm: float = FALSE_ALARM, scale_samples: Optional[int] = None) -> float:
    """k such that n Gaussian samples exceed k sigma (two-sided) with probability ~false_alarm.

    With ``scale_samples``, sigma is itself estimated from that many samples by a MAD: k is then
    Student's t quantile with ``MAD_EFFICIENCY * scale_samples`` degrees of freedom (the MAD's
    Gaussian efficiency is 37 %), so that a scale estimated from a few samples (a 5 Hz column of
    a short run) does not raise false alarms when it comes out low.
    """
    p = 1.0 - false_alarm / (2.0 * max(n, 1))
    if scale_samples is None:
        return float(NormalDist().inv_cdf(p))
    from scipy.stats import t as student

    return float(student.ppf(p, max(MAD_EFFICIENCY * scale_samples, 1.0)))


def _g(x: float) -> str:
    """A number for a message: 4 significant digits, plain float."""
    return f"{float(x):.4g}"


def _own(run: RunData, name: str) -> tuple[FloatArray, FloatArray, NDArray[np.int64]]:
    """(times, values, file lines) of a column's own samples."""
    v = run.columns[name]
    ok = ~np.isnan(v)
    lines = run.lines if run.lines is not None else np.arange(len(v)) + 2
    return run.time[ok], v[ok], np.asarray(lines)[ok]


def _largest(run: RunData, name: str) -> tuple[float, str, FloatArray, NDArray[np.int64], int]:
    """The largest |value| of a column's own samples, where it is ("line L (t = T s)"), the
    values, their file lines and its index."""
    ts, vs, lines = _own(run, name)
    i = int(np.argmax(np.abs(vs)))
    return abs(float(vs[i])), f"line {int(lines[i])} (t = {_g(ts[i])} s)", vs, lines, i


def _at(ts: FloatArray, vs: FloatArray, lines: NDArray[np.int64], i: int) -> str:
    return f"{_g(vs[i])} at line {int(lines[i])} (t = {_g(ts[i])} s)"


def _median_of_five(v: FloatArray) -> FloatArray:
    """Running median over 5 samples; the ends padded by odd reflection (a trend continues)."""
    if len(v) < 5:
        return np.full(len(v), np.median(v))
    with np.errstate(over="ignore", invalid="ignore"):
        pad = np.concatenate([2 * v[0] - v[2:0:-1], v, 2 * v[-1] - v[-2:-4:-1]])
    windows = np.lib.stride_tricks.sliding_window_view(pad, 5)
    return np.median(windows, axis=1)


def _spans(t: FloatArray, mask: NDArray[np.bool_]) -> list[tuple[float, float]]:
    """(start, end) times of the runs of consecutive True in mask."""
    out = []
    idx = np.flatnonzero(mask)
    if idx.size == 0:
        return out
    breaks = np.flatnonzero(np.diff(idx) > 1)
    starts = np.concatenate([[idx[0]], idx[breaks + 1]])
    ends = np.concatenate([idx[breaks], [idx[-1]]])
    return [(float(t[a]), float(t[b])) for a, b in zip(starts, ends)]


def _format_spans(spans: list[tuple[float, float]], limit: int = 4) -> str:
    text = ", ".join(f"{_g(a)}-{_g(b)} s" for a, b in spans[:limit])
    return text + (f" and {len(spans) - limit} more" if len(spans) > limit else "")


# --------------------------------------------------------------------------------------------
# Checks of one run, one column at a time
# --------------------------------------------------------------------------------------------

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
                        f"(t = {_g(t[gap])} s) and line {int(lines[gap + 1])} (t = {_g(t[gap + 1])} s), where rows "
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
    """Roll and pitch: degrees (> ANGLE_ERROR rad) or beyond the tip-over angle."""
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
    return out


def check_spins(run: RunData, file: str, limits: RoverLimits) -> list[Finding]:
    """Wheel spins beyond the motors' no-load spin (rpm instead of rad/s)."""
    out = []
    w0 = limits.no_load_spin
    for name in ("omega_left", "omega_right"):
        if not run.has(name):
            continue
        peak, where, _, _, _ = _largest(run, name)
        hint = ""
        if peak / RPM_PER_RAD_S <= SPIN_WARN * w0:
            hint = f": looks like rpm ({_g(peak)} rpm = {_g(peak / RPM_PER_RAD_S)} rad/s)"
        if peak > SPIN_ERROR * w0:
            out.append(Finding("error", file, name, f"|{name}| reaches {_g(peak)} rad/s at {where}, more than "
                               f"{SPIN_ERROR:g} times the motors' no-load spin of {_g(w0)} rad/s{hint}"))
        elif peak > SPIN_WARN * w0:
            out.append(Finding("warning", file, name, f"|{name}| reaches {_g(peak)} rad/s at {where}, beyond the "
                               f"motors' no-load spin of {_g(w0)} rad/s{hint or ' (the wheel overran the motor)'}"))
    return out


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


def check_drawbar(run: RunData, file: str, limits: RoverLimits) -> list[Finding]:
    """Drawbar force beyond what the wheels of both sides can push."""
    name = "drawbar_force"
    if not run.has(name):
        return []
    peak, where, _, _, _ = _largest(run, name)
    warn = 2.0 * TORQUE_MARGIN * limits.drive_torque / limits.wheel_radius
    error = 2.0 * limits.plugging_torque / limits.wheel_radius
    if peak > error:
        return [Finding("error", file, name, f"|{name}| reaches {_g(peak)} N at {where}, beyond the {_g(error)} N "
                        "the wheels could push at the motors' electrical maximum")]
    if peak > warn:
        return [Finding("warning", file, name, f"|{name}| reaches {_g(peak)} N at {where}, beyond {TORQUE_MARGIN:g} "
                        f"times the {_g(warn / TORQUE_MARGIN)} N the drive's torque limit pushes")]
    return []


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
    material = np.isfinite(difference) & (np.abs(difference) >= TURN_SPIN_DIFFERENCE)
    if int(np.sum(material)) < TURN_WINDOWS or np.std(rate[material]) == 0 or np.std(difference[material]) == 0:
        return []
    correlation = float(np.corrcoef(rate[material], difference[material])[0, 1])
    if correlation > YAW_CORRELATION:
        return _check_yaw_units(rate[material], difference[material], file, limits)
    if not correlation < -TURN_CORRELATION:
        return []
    return [Finding("error", file, "omega_left", f"the rover turns against its wheels: its yaw rate follows "
                    f"omega_right - omega_left with correlation {correlation:.2f} over the {int(np.sum(material))} "
                    f"{_g(TURN_WINDOW)} s windows where the sides' spins differ by {_g(TURN_SPIN_DIFFERENCE)} rad/s "
                    "or more, and a skid-steered rover turns towards its slower side: are omega_left and "
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


def check_heading(run: RunData, file: str) -> list[Finding]:
    """``yaw`` that does not point where the rover goes: degrees, a compass heading, another
    reference direction, or positions in another frame (module docstring, "Heading")."""
    names = ("yaw", "pos_x", "pos_y", "omega_left", "omega_right")
    if not all(run.has(n) for n in names):
        return []
    tx = run.samples("pos_x")[0]
    if len(tx) < 2 or tx[-1] - tx[0] <= 2 * TURN_WINDOW:
        return []
    t = np.arange(tx[0] + 0.5 * TURN_WINDOW, tx[-1] - 0.5 * TURN_WINDOW, 0.5 * TURN_WINDOW)
    ends = aligned(run, ["pos_x", "pos_y"], np.concatenate([t - 0.5 * TURN_WINDOW, t + 0.5 * TURN_WINDOW]))
    dx, dy = (np.diff(ends[n].reshape(2, -1), axis=0)[0] for n in ("pos_x", "pos_y"))
    spins = aligned(run, ["omega_left", "omega_right"], t)
    forward = 0.5 * (spins["omega_left"] + spins["omega_right"])
    # The yaw as its sines and cosines: interpolating those needs no unwrapping, so one absurd
    # sample spoils only its own window.
    ty, yaw = run.samples("yaw")
    with np.errstate(invalid="ignore"):
        heading = np.arctan2(np.interp(t, ty, np.sin(yaw)), np.interp(t, ty, np.cos(yaw)))
    travel = np.arctan2(dy, dx) + np.where(forward < 0, np.pi, 0.0)
    moving = np.isfinite(heading) & (np.hypot(dx, dy) >= HEADING_MOVE) & (np.abs(forward) >= TURNING)
    if int(np.sum(moving)) < TURN_WINDOWS:
        return []
    off = np.abs(np.angle(np.exp(1j * (heading[moving] - travel[moving]))))
    median = float(np.median(off))
    if median <= HEADING_ERROR:
        return []
    return [Finding("error", file, "yaw", f"the rover's heading (yaw) and its direction of travel (pos_x, pos_y "
                    f"over {_g(TURN_WINDOW)} s) differ by {_g(median)} rad in the median over the "
                    f"{int(np.sum(moving))} windows where it moved {_g(HEADING_MOVE)} m or more with its wheels "
                    f"turning one way: more than {_g(HEADING_ERROR)} rad, so it would be moving more sideways than "
                    "forward. Is yaw in degrees, a compass heading (clockwise from north), or measured from "
                    "another direction than the x axis of pos_x, pos_y?")]


def check_ground_datum(run: RunData, file: str, limits: RoverLimits) -> list[Finding]:
    """A drawbar run's heights measured from a datum other than its flat ground (module
    docstring, "Ground datum")."""
    if run.kind != "drawbar" or not run.has("pos_z"):
        return []
    height = float(np.median(_own(run, "pos_z")[1]))
    bound = DATUM_LIMIT * limits.cg_height
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


def check_outliers(run: RunData, file: str, columns: Iterable[str], limits: RoverLimits) -> list[Finding]:
    """Single absurd samples, column by column (robust test of the module docstring).

    A position sample must also lie farther from the median of the five around it than the
    rover travels at its top speed over two sample periods: closer, it may be where the rover
    was (noise-free positions bounce by a centimetre at 5 Hz as the chassis settles).
    """
    out = []
    for name in columns:
        if not run.has(name):
            continue
        ts, vs, lines = _own(run, name)
        if len(vs) < 5:
            continue
        with np.errstate(over="ignore", invalid="ignore"):
            smooth = _median_of_five(vs)
            r = vs - smooth
            r = np.where(np.isfinite(r), r, np.sign(vs) * np.inf)
            lo, hi = float(np.min(smooth)), float(np.max(smooth))
            span = hi - lo if np.isfinite(hi - lo) else np.inf
            d2 = vs[2:] - 2.0 * vs[1:-1] + vs[:-2]
            d2 = d2[d2 != 0]  # exact zeros are held samples (a frozen stretch), not noise
            if d2.size == 0:
                d2 = np.zeros(1)
            scale = RESIDUAL_TAIL * 1.4826 * float(np.median(np.abs(d2))) / math.sqrt(6.0)
        limit = max(outlier_threshold_k(len(vs), scale_samples=len(d2)) * scale, SPAN_FRACTION * span)
        if name.startswith("pos_"):
            limit = max(limit, 2.0 * limits.top_speed * float(np.median(np.diff(ts))))
        bad = np.flatnonzero(np.abs(r) > limit)
        if bad.size == 0:
            continue
        worst = int(bad[np.argmax(np.abs(r[bad]))])
        absurd = bool(np.abs(r[worst]) > ABSURD_SPAN * max(span, scale))
        listed = ", ".join(_at(ts, vs, lines, int(i)) for i in bad[:3])
        if bad.size > 3:
            listed += f" and {bad.size - 3} more"
        what = f"{bad.size} samples far from their" if bad.size > 1 else "1 sample far from its"
        out.append(Finding("error" if absurd else "warning", file, name,
                           f"{what} neighbours: {listed} (the column's other samples span {_g(lo)} to {_g(hi)}; "
                           f"a sample more than {_g(limit)} from the median of the five around it is an outlier)"))
    return out


def check_run(run: RunData, file: str, limits: RoverLimits) -> list[Finding]:
    """Every check of one run's columns; a column with an error gets no outlier warning on top."""
    found = (check_time(run, file) + check_angles(run, file, limits) + check_spins(run, file, limits)
             + check_torques(run, file, limits) + check_drawbar(run, file, limits)
             + check_signs(run, file, limits) + check_positions(run, file, limits)
             + check_turning(run, file, limits))
    with_error = {f.column for f in found if f.severity == "error"}
    if not with_error & {"yaw", "pos_x", "pos_y", "omega_left", "omega_right"}:
        found += check_heading(run, file)
    with_error = {f.column for f in found if f.severity == "error"}
    columns = [c for c in KNOWN_COLUMNS if c != "time" and c not in with_error]
    return found + check_outliers(run, file, columns, limits)


# --------------------------------------------------------------------------------------------
# Single-wheel testbed tables
# --------------------------------------------------------------------------------------------

def _rig_at(table: RigTable, i: int) -> str:
    lines = table.lines if table.lines is not None else np.arange(len(table)) + 2
    return f"line {int(lines[i])}"


def check_rig_wheel(spec: RunSpec, manifest: str = "campaign.json") -> list[Finding]:
    """The wheel of a wheel_rig run entry in metres (module docstring)."""
    rig = spec.rig
    if rig is None:
        return []
    out = []
    for key, limit in RIG_WHEEL_LIMITS.items():
        v = getattr(rig, key)
        if v > limit:
            hint = ": looks like millimetres" if v / 1000.0 <= limit else ""
            out.append(Finding("error", manifest, f"wheel.{key}", f"run {spec.id!r}: the wheel's {key} is {_g(v)} m, "
                               f"beyond the {_g(limit)} m a testbed wheel has{hint}"))
    if rig.lug_height > 0.5 * rig.radius and not any(f.column == "wheel.lug_height" for f in out):
        out.append(Finding("error", manifest, "wheel.lug_height", f"run {spec.id!r}: lugs of {_g(rig.lug_height)} m "
                           f"on a wheel of radius {_g(rig.radius)} m: more than half the radius"))
    return out


def check_rig(table: RigTable, spec: RunSpec, file: str) -> list[Finding]:
    """Units and physical limits of a wheel_rig table (module docstring)."""
    out: list[Finding] = []
    slip, load = table["slip"], table["vertical_load"]
    high = np.flatnonzero(slip >= 1.0)
    if high.size:
        i = int(high[np.argmax(slip[high])])
        hint = ": looks like percent (a slip of 0.2 is 20 %)" if np.all(np.abs(slip) <= 100.0) else ""
        out.append(Finding("error", file, "slip", f"slip reaches {_g(slip[i])} at {_rig_at(table, i)}; a slip is "
                           f"below 1 (1 - v / (omega R)){hint}"))
    bad = np.flatnonzero(load <= 0)
    if bad.size:
        i = int(bad[0])
        out.append(Finding("error", file, "vertical_load", f"vertical_load is {_g(load[i])} N at {_rig_at(table, i)}; "
                           "the testbed presses the wheel on the soil with a load > 0"))
    else:
        radius = spec.rig.radius if spec.rig is not None else None
        forces = [(n, np.abs(table[n]) / load) for n in ("drawbar_pull", "lateral_force") if table.has(n)]
        if table.has("torque") and radius:
            forces.append(("torque", np.abs(table["torque"]) / (radius * load)))
        for name, ratio in forces:
            if not np.any(ratio > RIG_FORCE_WARN):
                continue
            i = int(np.nanargmax(ratio))
            what = f"|{name}| / (radius x vertical_load)" if name == "torque" else f"|{name}| / vertical_load"
            severity = "error" if ratio[i] > RIG_FORCE_ERROR else "warning"
            hint = ": is the load in kg? (1 kg weighs 9.81 N)" if severity == "error" else ""
            out.append(Finding(severity, file, name, f"{what} reaches {_g(ratio[i])} at {_rig_at(table, i)}; the "
                               f"soil's friction limits it to below about 1 (more than {RIG_FORCE_ERROR:g} is an "
                               f"error){hint}"))
    if table.has("sinkage") and spec.rig is not None:
        z = table["sinkage"]
        i = int(np.nanargmax(np.abs(z)))
        if abs(z[i]) > spec.rig.radius:
            hint = ": looks like millimetres" if abs(z[i]) / 1000.0 <= spec.rig.radius else ""
            out.append(Finding("error", file, "sinkage", f"|sinkage| reaches {_g(z[i])} m at {_rig_at(table, i)}, "
                               f"beyond the wheel radius of {_g(spec.rig.radius)} m (the axle under the "
                               f"surface){hint}"))
    if "slip_angle" in table.columns:
        a = np.abs(table["slip_angle"])
        i = int(np.argmax(a))
        if a[i] > math.pi / 2:
            hint = ": looks like degrees" if a[i] <= 90.0 else ""
            out.append(Finding("error", file, "slip_angle", f"|slip_angle| reaches {_g(a[i])} rad at "
                               f"{_rig_at(table, i)}, beyond pi/2 (the wheel across the carriage){hint}"))
        elif a[i] > RIG_ANGLE_WARN:
            out.append(Finding("warning", file, "slip_angle", f"|slip_angle| reaches {_g(a[i])} rad at "
                               f"{_rig_at(table, i)}, beyond pi/4 ({_g(math.degrees(a[i]))} degrees if radians)"))
    return out


# --------------------------------------------------------------------------------------------
# The scan
# --------------------------------------------------------------------------------------------

def footprint_offsets(limits: RoverLimits) -> FloatArray:
    """Outline of the wheel footprint in the rover frame (m): (8, 2), x ahead, y left.

    A rectangle ``half_length`` ahead and behind the chassis reference point (the wheels'
    radius beyond the axles) and ``half_width`` to either side (beyond the wheels' outer
    edges): its corners and the midpoints of its sides.
    """
    a, b = limits.half_length, limits.half_width
    return np.array([[a, b], [a, 0.0], [a, -b], [0.0, -b], [-a, -b], [-a, 0.0], [-a, b], [0.0, b]])


def path_off_scan(run: RunData, points: FloatArray, limits: RoverLimits) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Which position samples put part of the wheel footprint off the scan.

    The footprint (:func:`footprint_offsets`) is placed at each position sample, turned by the
    measured yaw (without a yaw column it is turned to every heading: a disc of its
    half-diagonal, sampled at 16 headings). A footprint point is on the gridded scan when a scan
    point lies within ``GRID_MARGIN`` (1 m) of it: the gridding extends the scan by that margin
    with its nearest edge height, so that wheels may hang over an edge of the scan; farther from
    every scan point (beyond the grid, where the simulation clamps the edge height, or in a hole
    of the scan wider than twice the margin) the ground under the wheel is not measured at all.
    (Closer to the edge the synthetic campaigns' wheels do leave the scanned area for the last
    seconds of a full-length run: their scan ends 0.7 m ahead of where the rover stops.)

    Returns:
        (times of the position samples (s), True where part of the footprint is off the scan).
    """
    from scipy.spatial import cKDTree

    t, x, _ = _own(run, "pos_x")
    y = aligned(run, "pos_y", t)["pos_y"]
    tree = cKDTree(points[:, :2])
    if run.has("yaw"):
        yaw = aligned(run, "yaw", t)["yaw"]
        off = footprint_offsets(limits)
        c, s = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
        px = x[:, None] + c * off[None, :, 0] - s * off[None, :, 1]
        py = y[:, None] + s * off[None, :, 0] + c * off[None, :, 1]
    else:
        radius = math.hypot(limits.half_length, limits.half_width)
        ang = np.linspace(0.0, 2 * np.pi, 16, endpoint=False)
        px = x[:, None] + radius * np.cos(ang)[None, :]
        py = y[:, None] + radius * np.sin(ang)[None, :]
    dist, _ = tree.query(np.column_stack([px.ravel(), py.ravel()]), distance_upper_bound=2 * GRID_MARGIN)
    off_scan = (dist > GRID_MARGIN).reshape(px.shape).any(axis=1)
    return t, off_scan


def check_scan(campaign: Campaign, spec: RunSpec, run: RunData, limits: RoverLimits) -> list[Finding]:
    """Gross outliers of a terrain run's scan (warning: dropped before gridding) and the path's
    coverage: an error when the footprint is off the scan for more than OFF_SCAN_ERROR of the
    run's position samples, a warning for a briefer excursion."""
    points = read_terrain_points(campaign, spec)
    scan_file = str(spec.terrain)
    out = []
    bad = gross_outliers(points)
    if bad.any():
        idx = np.flatnonzero(bad)
        shown = "; ".join(f"no. {int(i) + 1} ({_g(points[i, 0])}, {_g(points[i, 1])}, {_g(points[i, 2])})"
                          for i in idx[:5]) + (f"; and {idx.size - 5} more" if idx.size > 5 else "")
        axes = "".join(a for a, on in zip("xyz", _outlier_axes(points, bad)) if on) or "z"
        out.append(Finding("warning", scan_file, axes, f"{idx.size} of {len(points)} scan points are gross outliers "
                           f"and are dropped before gridding: {shown} (x, y, z in m)"))
        points = points[~bad]
    if not (run.has("pos_x") and run.has("pos_y")):
        return out
    t, off = path_off_scan(run, points, limits)
    if off.any():
        spans = _spans(t, off)
        share = float(np.mean(off))
        severity = "error" if share > OFF_SCAN_ERROR else "warning"
        hint = _off_scan_hint(run, points, limits) if severity == "error" else ""
        out.append(Finding(severity, spec.file, "pos_x", f"run {spec.id!r}: the rover's wheel footprint leaves the "
                           f"scan {scan_file} during {_format_spans(spans)} ({share:.0%} of the position samples; "
                           f"more than {OFF_SCAN_ERROR:.0%} is an error): the terrain there is not measured{hint}"))
    return out


#: Length units a scan may be written in by mistake, with the factor to metres.
SCAN_UNITS = (("millimetres", 1e-3), ("centimetres", 1e-2), ("feet", 0.3048))


def _off_scan_hint(run: RunData, points: FloatArray, limits: RoverLimits) -> str:
    """Why a path lies mostly off its scan: the scan in another length unit (the path lies on
    the scan once it is converted to metres), or else the two extents, to compare frames."""
    for unit, to_m in SCAN_UNITS:
        _, off = path_off_scan(run, points * to_m, limits)
        if np.mean(off) <= OFF_SCAN_ERROR:
            return (f"; the scan looks like it is in {unit}: converted to metres, the path lies on it "
                    "(the format's lengths are in m)")
    _, x, _ = _own(run, "pos_x")
    _, y, _ = _own(run, "pos_y")
    lo, hi = points[:, :2].min(axis=0), points[:, :2].max(axis=0)
    return (f"; the scan spans x {lo[0]:.2f} to {hi[0]:.2f} m, y {lo[1]:.2f} to {hi[1]:.2f} m, the path x "
            f"{np.nanmin(x):.2f} to {np.nanmax(x):.2f} m, y {np.nanmin(y):.2f} to {np.nanmax(y):.2f} m: are both in "
            "the same world frame?")


def _outlier_axes(points: FloatArray, bad: NDArray[np.bool_]) -> tuple[bool, bool, bool]:
    """Which coordinates make the dropped points odd: far beyond the others' range."""
    good = points[~bad]
    lo, hi = good.min(axis=0), good.max(axis=0)
    far = (points[bad] < lo - (hi - lo)) | (points[bad] > hi + (hi - lo))
    return tuple(bool(v) for v in far.any(axis=0))  # type: ignore[return-value]


# --------------------------------------------------------------------------------------------
# The campaign
# --------------------------------------------------------------------------------------------

def check_campaign(campaign: Campaign) -> list[Finding]:
    """Reads every run (and every terrain run's scan) and returns every finding, errors first.

    Raises:
        InputError: a file breaks the format (see :func:`juno.campaign.read_run`).
    """
    limits = rover_limits(campaign.rover)
    found: list[Finding] = []
    kilonewtons: list[tuple[str, Optional[str]]] = []
    for spec in campaign.runs:
        if spec.kind == "wheel_rig":
            found += check_rig_wheel(spec, campaign.manifest_path.name)
            found += check_rig(read_rig(campaign, spec), spec, spec.file)
            continue
        run = read_run(campaign, spec)
        found += check_run(run, spec.file, limits)
        if spec.terrain is not None:
            found += check_scan(campaign, spec, run, limits)
        if run.kind == "drawbar" and run.has("drawbar_force"):
            kilonewtons.append((spec.file, drawbar_in_kilonewtons(run, limits)))
    every_run = all(evidence is not None for _, evidence in kilonewtons)
    found += [Finding("error" if every_run else "warning", file, "drawbar_force",
                      evidence + (" in every drawbar run" if every_run and len(kilonewtons) > 1 else ""))
              for file, evidence in kilonewtons if evidence is not None]
    return [f for f in found if f.severity == "error"] + [f for f in found if f.severity != "error"]


def enforce_plausibility(campaign: Campaign, force: bool = False,
                         stream: Optional[Union[TextIO, Callable[[str], None]]] = None,
                         fmu: Optional[Union[str, Path]] = None) -> list[Finding]:
    """Runs :func:`check_campaign` before any computation, after the campaign's ``rover``
    overrides are checked against the FMU ``fmu`` (default: the project's FMU): a name the FMU
    does not have, or a value outside its range, raises InputError (``force`` does not pass it:
    the FMU would refuse it).

    Warnings are written one line each to ``stream`` (default stderr; a callable gets each line).
    Errors raise :class:`PlausibilityError` listing every error finding, unless ``force``: then
    they are written as warnings too and the command goes on. Returns the findings.
    """
    from .fmu_parameters import check_rover_overrides

    check_rover_overrides(campaign.rover, campaign.manifest_path, fmu)
    findings = check_campaign(campaign)
    if stream is None:
        stream = sys.stderr
    write = stream if callable(stream) else (lambda line: print(line, file=stream, flush=True))
    errors = [f for f in findings if f.severity == "error"]
    for f in findings:
        if f.severity != "error":
            write(f"warning: {f}")
    if errors and not force:
        lines = "\n".join(f"  {f}" for f in errors)
        count = f"{len(errors)} error{'s' if len(errors) > 1 else ''}"
        raise PlausibilityError(f"the measured data of {campaign.root} are implausible ({count}; "
                                f"--force goes on anyway):\n{lines}")
    for f in errors:
        write(f"warning (--force): {f}")
    return findings
