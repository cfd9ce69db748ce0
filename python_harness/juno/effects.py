"""Hidden effects for synthetic campaigns: what the paper's volumetric model leaves out.

Each effect changes the synthetic truth in one physical way.  ``--strength``
S in (0, 1] scales it linearly; S = 1 is the top of the documented range.

**The catalog** (:data:`EFFECTS`): each effect is hidden in exactly the functional form of the
diagnosis candidate of the same name, so the extended model can reproduce the truth.

================  =========================================================  =======================
effect            what the truth does at strength S                           range (S = 0.5 .. 1)
================  =========================================================  =======================
soil_patch        a patch of weaker soil (Gaussian, sigma 0.6-0.9 m, centre   k_h x 0.7 .. 0.4,
                  1.2-2 m along the drawbar track, |y| < 0.3 m):              strength x 0.8 .. 0.6
                  k_h x (1 - 0.6 S), strength x (1 - 0.4 S)
multipass         rear wheels roll in the front wheels' rut on compacted      k_h x 1.75 .. 2.5
                  soil: k_h x (1 + 1.5 S)
slip_sinkage      the soil yields under a slipping wheel: k_h / (1 + 1.5 S s)  c = 0.75 .. 1.5
grouser           lugs shear the soil at a larger radius and add thrust beyond    gain 0.18 .. 0.35,
                  Mohr-Coulomb: F_taumax x (1 + 0.35 S), shear at R + 25 S mm  lugs 12.5 .. 25 mm
drivetrain_loss   the motor-current torque over-reads the wheel torque:       loss 12.5 .. 25 %
                  the wheels get (1 - 0.25 S) of it
terrain_offset    the LIDAR scan is misregistered by 0.25 S m in a random     0.12 .. 0.25 m,
                  direction, 3 S deg in yaw and 3 S cm in height               1.5 .. 3 deg, 1.5 .. 3 cm
payload           the rover carries 40 S kg that its manifest does not state   20 .. 40 kg
                  (rover.payload; the manifest's rover.mass is the Juno's)    (6 .. 13 % of 318 kg)
================  =========================================================  =======================

**Alternative forms** (:data:`ALTERNATIVE_FORMS`): the same mechanism as a catalog effect
(:data:`ALTERNATIVE_OF` names it), in a form its candidate does not fit exactly, as real data
would hold it.  A diagnosis should name the catalog cause of the mechanism, or say it cannot
explain the data; it cannot reproduce the truth exactly.

===================  ======================================================  ==========================
effect               what the truth does at strength S                        resembles
===================  ======================================================  ==========================
soil_strip           a band of weaker soil crossing the track (across x,      soil_patch
                     centre 1.2-2 m, half width 0.3-0.5 m, 5 cm edges):
                     k_h x (1 - 0.6 S), strength x (1 - 0.4 S)
multipass_depth      the front wheel compacts the soil in proportion to its   multipass
                     rut's depth (saturating at 2 cm, not 2 mm) and the rut
                     springs back 40 % before the rear wheel: k_h x (1 + 2 S)
slip_sinkage_power   the soil yields with the square root of slip (steeply    slip_sinkage
                     at small slip, levelling off, as measured sinkage often
                     does): k_h / (1 + 1.2 S s^0.5) (the catalog's at s = 0.64)
grouser_buildup      the lugs' extra thrust builds up with slip (the soil     grouser
                     between lugs shears first): F_taumax x (1 + 0.35 S
                     (1 - exp(-|s| / 0.15))), shear at R + 25 S mm
lug_ripple           the catalog's lug thrust, and the traction limit         grouser
                     pulsing as each of 18 lugs enters the soil: F_taumax
                     x (1 + 0.35 S) (1 + 0.3 S cos(18 theta + phi)), shear
                     at R + 25 S mm (theta the wheel angle, phi 0 front, pi
                     rear; 2-6 Hz at 0.7-2 rad/s, below a 20 Hz Nyquist)
drivetrain_friction  Coulomb plus viscous friction in each drivetrain on the   drivetrain_loss
                     wheel side: 15 S N m + 8 S N m s/rad x spin
terrain_tilt         the LIDAR scan is tilted by 1 S deg about a horizontal   terrain_offset
                     axis in a random direction through a point 2-6 m along
                     the test area (a tilt the registration's plane fits:
                     hidden through the scan, not the FMU)
scan_scale           every scanned point's distance from the scanner (1-2 m   terrain_offset
                     behind the test area, 1.5 m up) is too long or too
                     short by 3 S % (a range or photogrammetric scale error)
===================  ======================================================  ==========================

**Decoys** (:data:`DECOYS`): effects no catalog candidate models (``in_catalog`` False in
:data:`EFFECT_INFO` and in ``truth.json``); a diagnosis should call them unexplained rather
than name a catalog cause.

=============  ==========================================================================
effect         what the truth does at strength S
=============  ==========================================================================
imu_pitch_bias every IMU pitch sample reads 1.5 S deg too high or too low (a mounting bias)
side_drag      a brake drags on the left wheels: 10 S N m of Coulomb torque against their
               spin, which the motor current (the measured torque) does not see
clock_offset   the IMU and total-station clocks run 0.25 S s ahead of or behind the motor
               clock (torques, spins and drawbar force)
=============  ==========================================================================

An effect acts through the truth simulation's FMU parameters (``Truth.sim``), through the
LIDAR scan (``scan_transform``), through the instruments (``Truth.distortion``: ``imu.pitchBias``,
``clock.offset``, ``scan.tilt*``), or several of these; ``Truth.extension`` holds the FMU
parameters with which the extended model reproduces the truth (what ``diagnose`` should find),
empty for the alternative forms and decoys.  Several effects can be hidden at once, each with
its own strength (``juno synthesize --effect A --strength SA --effect B --strength SB``), when
they set different parameters.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

EFFECTS: dict[str, str] = {
    "none": "nothing hidden: the paper's model is the truth",
    "soil_patch": "soil stiffness and strength vary over the test area (a weaker patch)",
    "multipass": "rear wheels roll in the front wheels' rut, on compacted soil",
    "slip_sinkage": "sinkage grows with slip as the wheel digs in",
    "grouser": "lugged tyres shear the soil at a larger radius and gain thrust beyond the Mohr-Coulomb limit",
    "drivetrain_loss": "the torque from the motor current is larger than the torque at the wheels",
    "terrain_offset": "the scanned terrain is shifted and rotated relative to the real one",
    "payload": "the rover carries a payload its manifest does not state",
}

ALTERNATIVE_FORMS: dict[str, str] = {
    "soil_strip": "a band of weaker soil crosses the track (not a Gaussian patch)",
    "multipass_depth": "the rear wheels roll on soil compacted in proportion to the front wheels' rut depth, "
                       "in a rut that partly springs back",
    "slip_sinkage_power": "sinkage grows with the square root of slip",
    "grouser_buildup": "the lugs' extra thrust builds up with slip",
    "lug_ripple": "the lugs' extra thrust ripples as each lug enters the soil",
    "drivetrain_friction": "Coulomb and viscous friction in the drivetrains, not seen by the motor current",
    "terrain_tilt": "the scanned terrain is tilted about a horizontal axis relative to the real one",
    "scan_scale": "the scan's distances from the scanner are off by a scale factor (not a shift)",
}

#: The catalog effect whose mechanism each alternative form shares.
ALTERNATIVE_OF: dict[str, str] = {
    "soil_strip": "soil_patch", "multipass_depth": "multipass", "slip_sinkage_power": "slip_sinkage",
    "grouser_buildup": "grouser", "lug_ripple": "grouser", "drivetrain_friction": "drivetrain_loss",
    "terrain_tilt": "terrain_offset", "scan_scale": "terrain_offset",
}

DECOYS: dict[str, str] = {
    "imu_pitch_bias": "every IMU pitch sample is biased by a constant angle",
    "side_drag": "a brake drags on the left wheels; the measured motor torque does not see it",
    "clock_offset": "the IMU and total-station clocks are offset from the motor clock",
}

#: Lugs per wheel of the ``lug_ripple`` form (an assumption for the Juno's 22 in tyre).
LUG_COUNT = 18
#: Height of the scanner above the flat ground (m) in the ``scan_scale`` form: a terrestrial
#: LIDAR on its tripod.
SCANNER_HEIGHT = 1.5

#: Every effect ``juno synthesize`` can hide.
ALL_EFFECTS: dict[str, str] = {**EFFECTS, **ALTERNATIVE_FORMS, **DECOYS}


@dataclass(frozen=True)
class EffectInfo:
    """What a hidden effect is to whoever judges a diagnosis.

    ``in_catalog``: a diagnosis candidate models its mechanism (False for the decoys);
    ``catalog_cause``: that candidate (None for the decoys and ``none``);
    ``exact_form``: hidden in exactly the candidate's functional form (the catalog itself).
    """

    description: str
    in_catalog: bool
    catalog_cause: str | None
    exact_form: bool


EFFECT_INFO: dict[str, EffectInfo] = {
    **{e: EffectInfo(d, True, None if e == "none" else e, True) for e, d in EFFECTS.items()},
    **{e: EffectInfo(d, True, ALTERNATIVE_OF[e], False) for e, d in ALTERNATIVE_FORMS.items()},
    **{e: EffectInfo(d, False, None, False) for e, d in DECOYS.items()},
}


def effect_record(effect: str, strength: float) -> dict[str, object]:
    """An effect's entry in ``truth.json``: id and strength; for an effect outside the catalog's
    exact forms also ``in_catalog``, ``catalog_cause`` and ``exact_form`` (false)."""
    record: dict[str, object] = {"effect": effect, "strength": strength}
    info = EFFECT_INFO[effect]
    if not info.exact_form:
        record.update({"in_catalog": info.in_catalog, "catalog_cause": info.catalog_cause, "exact_form": False})
    return record


def _check(effect: str, strength: float) -> float:
    if effect not in ALL_EFFECTS:
        raise ValueError(f"unknown effect '{effect}'; known: {', '.join(ALL_EFFECTS)}")
    s = float(strength)
    if not (0.0 <= s <= 1.0):
        raise ValueError(f"--strength {s} must lie in [0, 1]")
    return s


def effect_parameters(effect: str, strength: float, rng: np.random.Generator) -> tuple[dict[str, float], dict[str, float]]:
    """FMU parameters of one catalog effect at ``strength`` in [0, 1]: ``(extension, sim)``.

    ``extension`` is what the extended model needs to reproduce the truth (what ``diagnose``
    should find); ``sim`` is what the truth simulation itself is given (a registration error
    lives in the scan, not in the world, so ``terrain_offset`` gives the simulation nothing).
    An alternative form or decoy has no extension: see :func:`hidden_parameters`.
    """
    s = _check(effect, strength)
    ext: dict[str, float] = {}
    if effect == "soil_patch":
        # The centre lies 1.2-2 m along the drawbar track (the drawbar runs start at the origin
        # and cover 2-3.5 m), so the runs cross the weak patch and firmer soil on both sides.
        ext = {"soilPatch.x": float(rng.uniform(1.2, 2.0)), "soilPatch.y": float(rng.uniform(-0.3, 0.3)),
               "soilPatch.radius": float(rng.uniform(0.6, 0.9)),
               "soilPatch.khFactor": 1 - 0.6 * s, "soilPatch.strengthFactor": 1 - 0.4 * s}
    elif effect == "multipass":
        ext = {"multipass.rutFraction": 1.0, "multipass.khFactor": 1 + 1.5 * s}
    elif effect == "slip_sinkage":
        ext = {"slipSinkage.coefficient": 1.5 * s}
    elif effect == "grouser":
        # Both signatures of lugs: more thrust (the gain) and shear at the lug tips,
        # beyond the rim the soil's pressure acts on (more torque per unit of thrust, and
        # thrust already where the rim speed equals the hub's).
        ext = {"grouser.thrustGain": 0.35 * s, "grouser.lugHeight": 0.025 * s}
    elif effect == "drivetrain_loss":
        ext = {"drive.lossFraction": 0.25 * s}
    elif effect == "terrain_offset":
        angle = float(rng.uniform(0, 2 * np.pi))
        ext = {"terrain.offsetX": 0.25 * s * float(np.cos(angle)), "terrain.offsetY": 0.25 * s * float(np.sin(angle)),
               "terrain.offsetZ": 0.03 * s * float(rng.choice([-1.0, 1.0])),
               "terrain.offsetYaw": float(np.radians(3.0)) * s * float(rng.choice([-1.0, 1.0]))}
    elif effect == "payload":
        ext = {"rover.payload": 40.0 * s}
    elif effect != "none":
        raise ValueError(f"'{effect}' is not a catalog effect; its parameters come from hidden_parameters")
    return ext, ({} if effect == "terrain_offset" else dict(ext))


def hidden_parameters(effect: str, strength: float, rng: np.random.Generator) -> tuple[dict[str, float], dict[str, float]]:
    """What an alternative form or decoy at ``strength`` in [0, 1] does: ``(sim, distortion)``,
    the truth simulation's FMU parameters and the instruments' errors (see the module table)."""
    s = _check(effect, strength)
    sign = float(rng.choice([-1.0, 1.0]))
    if effect == "soil_strip":
        return {"soilStrip.x": float(rng.uniform(1.2, 2.0)), "soilStrip.halfWidth": float(rng.uniform(0.3, 0.5)),
                "soilStrip.khFactor": 1 - 0.6 * s, "soilStrip.strengthFactor": 1 - 0.4 * s}, {}
    if effect == "multipass_depth":
        return {"multipass.rutFraction": 0.6, "multipass.khFactor": 1 + 2.0 * s,
                "multipass.compactionDepth": 0.02}, {}
    if effect == "slip_sinkage_power":
        # A square root, not a square: with k_h / (1 + c s^2) the sinkage grows fastest at high
        # slip, where more sinkage means more slip, and the wheels chatter and dig in at the
        # heaviest loads (measured: 5 times the high-frequency spin of the linear law at 760 N).
        return {"slipSinkage.coefficient": 1.2 * s, "slipSinkage.exponent": 0.5}, {}
    if effect == "grouser_buildup":
        return {"grouser.thrustGain": 0.35 * s, "grouser.lugHeight": 0.025 * s, "grouser.thrustSlip": 0.15}, {}
    if effect == "lug_ripple":
        # The catalog grouser's thrust and lug height, pulsing at the lug-passing frequency.  18
        # lugs: an assumed count for the Juno's 22 in tyre (a lug pitch of about 10 cm, as ATV
        # tyres of that size have 16-20).  At the campaigns' spins of 0.7-2 rad/s the ripple is at
        # 2-6 Hz, which the 50 Hz and 20 Hz torque and spin samples resolve (Nyquist 25 and 10 Hz).
        return {"grouser.thrustGain": 0.35 * s, "grouser.lugHeight": 0.025 * s, "grouser.lugCount": LUG_COUNT,
                "grouser.rippleAmplitude": 0.3 * s}, {}
    if effect == "drivetrain_friction":
        return {"drive.frictionLeft": 15.0 * s, "drive.frictionRight": 15.0 * s,
                "drive.viscousFriction": 8.0 * s}, {}
    if effect == "side_drag":
        return {"drive.frictionLeft": 10.0 * s}, {}
    if effect == "terrain_tilt":
        return {}, {"scan.tiltAngle": float(np.radians(1.0)) * s * sign,
                    "scan.tiltAxis": float(rng.uniform(0, np.pi)), "scan.tiltX": float(rng.uniform(2.0, 6.0))}
    if effect == "scan_scale":
        return {}, {"scan.scale": 0.03 * s * sign, "scan.scannerX": float(rng.uniform(-3.0, -2.0)),
                    "scan.scannerY": float(rng.uniform(-1.0, 1.0)), "scan.scannerZ": SCANNER_HEIGHT}
    if effect == "imu_pitch_bias":
        return {}, {"imu.pitchBias": float(np.radians(1.5)) * s * sign}
    if effect == "clock_offset":
        return {}, {"clock.offset": 0.25 * s * sign}
    raise ValueError(f"'{effect}' is a catalog effect; its parameters come from effect_parameters")


def apply_effects_to_truth(truth, rng: np.random.Generator) -> None:
    """Fills ``truth.sim`` (truth-simulation parameters), ``truth.extension`` and
    ``truth.distortion`` from ``truth.effects``, a sequence of (effect id, strength); several
    effects act together when they set different parameters (else ValueError)."""
    names = [e for e, _ in truth.effects]
    if len(set(names)) != len(names):
        raise ValueError(f"an effect is hidden twice: {', '.join(names)}")
    if "none" in names and len(names) > 1:
        raise ValueError("'none' cannot be combined with other effects")
    truth.extension, truth.sim, truth.distortion = {}, {}, {}
    for effect, strength in truth.effects:
        if EFFECT_INFO.get(effect, EFFECT_INFO["none"]).exact_form:
            ext, sim = effect_parameters(effect, strength, rng)
            distortion: dict[str, float] = {}
        else:
            (sim, distortion), ext = hidden_parameters(effect, strength, rng), {}
        shared = (set(sim) & set(truth.sim)) | (set(distortion) & set(truth.distortion))
        if shared:
            raise ValueError(f"effect '{effect}' sets {', '.join(sorted(shared))}, which an effect hidden with it "
                             "sets too: hide them one at a time")
        truth.extension.update(ext)
        truth.sim.update(sim)
        truth.distortion.update(distortion)


def scan_transform(truth) -> Callable[[np.ndarray], np.ndarray] | None:
    """How the LIDAR scan misplaces true points, or None.

    Registration offset (terrain_offset): the extended model moves the grid by (offsetX,
    offsetY, offsetZ, offsetYaw) (grid point q appears at o + Rz(yaw) q), so the scan reports a
    true point p at Rz(-yaw) (p - o).  Tilt (terrain_tilt): the scan reports p raised by
    tan(angle) times its distance from a horizontal axis through (tiltX, 0) at tiltAxis from x
    (a small rotation about that axis, height changed, positions kept).  Scale (scan_scale): the
    scan reports p at c + (1 + scale) (p - c), c the scanner's position.
    """
    steps: list[Callable[[np.ndarray], np.ndarray]] = []
    if "terrain.offsetX" in truth.extension:
        ox, oy = truth.extension["terrain.offsetX"], truth.extension["terrain.offsetY"]
        oz, yaw = truth.extension["terrain.offsetZ"], truth.extension["terrain.offsetYaw"]
        c, s = np.cos(yaw), np.sin(yaw)

        def shift(points: np.ndarray) -> np.ndarray:
            dx, dy = points[:, 0] - ox, points[:, 1] - oy
            return np.column_stack([c * dx + s * dy, -s * dx + c * dy, points[:, 2] - oz])
        steps.append(shift)
    distortion = getattr(truth, "distortion", {})
    if "scan.tiltAngle" in distortion:
        slope = float(np.tan(distortion["scan.tiltAngle"]))
        ax, ay = np.cos(distortion["scan.tiltAxis"]), np.sin(distortion["scan.tiltAxis"])
        x0 = distortion["scan.tiltX"]

        def tilt(points: np.ndarray) -> np.ndarray:
            across = -(points[:, 0] - x0) * ay + points[:, 1] * ax   # signed distance from the axis
            return np.column_stack([points[:, 0], points[:, 1], points[:, 2] + slope * across])
        steps.append(tilt)
    if "scan.scale" in distortion:
        factor = 1.0 + float(distortion["scan.scale"])
        scanner = np.array([distortion["scan.scannerX"], distortion["scan.scannerY"], distortion["scan.scannerZ"]])

        def scale(points: np.ndarray) -> np.ndarray:
            return scanner + factor * (points - scanner)
        steps.append(scale)
    if not steps:
        return None
    if len(steps) == 1:
        return steps[0]

    def both(points: np.ndarray) -> np.ndarray:
        for step in steps:
            points = step(points)
        return points
    return both
