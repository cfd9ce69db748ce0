"""The rover's physical limits that the checks compare measured data with, from its FMU
parameters (the FMU's defaults, overridden by the campaign's ``rover`` entry):

* **Motor torque.** A DC motor gives its largest steady torque at stall, at full voltage:
  ``T_stall = eff * n * kt * V / Ra`` per side (612 N m with the defaults); the drive controller
  further limits it to ``drive.torqueMax`` (400 N m). The electrical maximum of all is plugging,
  full voltage against the back-EMF of a wheel turning backwards at no-load speed: twice the
  stall torque. Torque beyond ``TORQUE_MARGIN`` times the drive's limit is a warning, beyond the
  plugging bound an error.
* **Spin.** The no-load spin ``omega_0 = V / (kt * n)`` (4.0 rad/s) is the fastest the motors
  turn a wheel; a wheel may overrun it a little downhill (warning beyond ``SPIN_WARN`` times it)
  but not three times over (error beyond ``SPIN_ERROR`` times it: the rover pushed at three
  times its top speed). rpm are 9.55 times rad/s, deg/s 57.3 times.
* **Ride height.** The chassis reference point (the rocker pivots) rides ``wheel.radius +
  rover.pivotHeight`` (0.43 m) above the ground its wheels rest on, less their sinkage; sunk to
  their axles (a sinkage of the radius, where the FMU stops), it is ``rover.pivotHeight`` (0.15
  m) above it.
* **Slope.** Soil does not rest on a slope steeper than its friction angle ``soil.phi`` (its
  angle of repose, without cohesion), and the FMU refuses a start where a wheel stands on one.
* **Geometry.** The front and rear wheels of a side do not overlap: their diameter is less than
  the wheelbase, and the left and right wheels' width less than the track.
* **Speed.** The top speed is ``omega_0 * wheel.radius`` (1.1 m/s). Positions whose typical
  speed over 1 s exceeds twice that are not in metres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping, Optional

from ..rover_model import fmu_defaults
from .findings import Finding, _g

#: The FMU parameters the limits derive from: the FMU's defaults (juno.rover_model), which the
#: campaign's ``rover`` overrides.
ROVER_PARAMETERS = ("wheel.radius", "wheel.width", "rover.track", "rover.wheelbase", "rover.cgHeight", "rover.pivotHeight", "rover.mass", "env.gravity",
                    "motor.voltage", "motor.kt", "motor.resistance", "motor.gearRatio", "motor.efficiency",
                    "drive.torqueMax", "soil.phi")


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
    gear_ratio: float = 1.0  # motor.gearRatio, motor : wheel
    wheelbase: float = 0.0   # m: rover.wheelbase, between the front and rear axles
    pivot_height: float = 0.0  # m: rover.pivotHeight, the rocker pivots (the chassis reference point) above the axles
    mass: float = 0.0        # kg: rover.mass (chassis, rockers and wheels)
    weight: float = 0.0      # N: rover.mass times env.gravity
    friction_angle: float = math.radians(30.0)  # rad: soil.phi, the steepest slope the soil holds
    torque_per_amp: float = 0.0  # N m per A at the wheels: motor.efficiency * motor.gearRatio * motor.kt

    @property
    def ride_height(self) -> float:
        """The chassis reference point's height (m) above the ground its wheels rest on, before
        they sink: wheel radius + rocker pivots above the axles."""
        return self.wheel_radius + self.pivot_height

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
        cg_height=cg, track=p["rover.track"], gear_ratio=n, wheelbase=p["rover.wheelbase"],
        pivot_height=p["rover.pivotHeight"], mass=p["rover.mass"], weight=p["rover.mass"] * p["env.gravity"],
        friction_angle=p["soil.phi"], torque_per_amp=p["motor.efficiency"] * n * kt)


def check_rover(rover: Optional[Mapping[str, object]], manifest: str) -> list[Finding]:
    """The campaign's rover entry against its own geometry (module docstring, "Geometry"): wheels
    that overlap are a length in another unit (a radius of 11 written for 11 inches, which lies
    within the FMU's range), named with the entry's keys, or the parameters it leaves at default."""
    if not rover:
        return []
    d = fmu_defaults()
    p = {k: rover.get(k, d[k]) for k in ("wheel.radius", "wheel.width", "rover.wheelbase", "rover.track")}
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in p.values()):
        return []
    out = []
    for size, what, span, between in (("wheel.radius", "diameter", "rover.wheelbase", "front and rear"),
                                      ("wheel.width", "width", "rover.track", "left and right")):
        if size not in rover and span not in rover:
            continue
        across = 2.0 * float(p[size]) if what == "diameter" else float(p[size])
        if across >= float(p[span]):
            given = [k for k in (size, span) if k in rover]
            out.append(Finding("error", manifest, given[0], f"rover: the wheels' {what} of {_g(across)} m ({size} = "
                               f"{_g(float(p[size]))} m) reaches {span} = {_g(float(p[span]))} m, so the {between} "
                               f"wheels would overlap; {' and '.join(given)} given in the manifest: "
                               f"{'are they' if len(given) > 1 else 'is it'} in metres?"))
    return out
