"""Hidden effects for synthetic campaigns: what the paper's volumetric model leaves out.

Each effect changes the synthetic truth in one physical way.  ``--strength``
S in (0, 1] scales it linearly; S = 1 is the top of the documented range.

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
================  =========================================================  =======================

An effect acts through the truth simulation's FMU parameters
(``Truth.sim``), through the LIDAR scan (``scan_transform``), or both;
``Truth.extension`` holds the FMU parameters with which the extended
model reproduces the truth (what ``diagnose`` should find).  Several effects
can be hidden at once, each with its own strength (``juno synthesize --effect A
--strength SA --effect B --strength SB``).
"""

from __future__ import annotations

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
}


def effect_parameters(effect: str, strength: float, rng: np.random.Generator) -> tuple[dict[str, float], dict[str, float]]:
    """FMU parameters of one hidden effect at ``strength`` in [0, 1]: ``(extension, sim)``.

    ``extension`` is what the extended model needs to reproduce the truth (what ``diagnose``
    should find); ``sim`` is what the truth simulation itself is given (a registration error
    lives in the scan, not in the world, so ``terrain_offset`` gives the simulation nothing).
    """
    if effect not in EFFECTS:
        raise ValueError(f"unknown effect '{effect}'; known: {', '.join(EFFECTS)}")
    s = float(strength)
    if not (0.0 <= s <= 1.0):
        raise ValueError(f"--strength {s} must lie in [0, 1]")
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
    return ext, ({} if effect == "terrain_offset" else dict(ext))


def apply_effects_to_truth(truth, rng: np.random.Generator) -> None:
    """Fills ``truth.sim`` (truth-simulation parameters) and ``truth.extension`` from
    ``truth.effects``, a sequence of (effect id, strength); several effects act together (their
    FMU parameters are disjoint, so the union is well defined)."""
    names = [e for e, _ in truth.effects]
    if len(set(names)) != len(names):
        raise ValueError(f"an effect is hidden twice: {', '.join(names)}")
    if "none" in names and len(names) > 1:
        raise ValueError("'none' cannot be combined with other effects")
    truth.extension, truth.sim = {}, {}
    for effect, strength in truth.effects:
        ext, sim = effect_parameters(effect, strength, rng)
        truth.extension.update(ext)
        truth.sim.update(sim)


def scan_transform(truth) -> Callable[[np.ndarray], np.ndarray] | None:
    """How the LIDAR scan misplaces true points, or None.

    The extended model moves the grid by (offsetX, offsetY, offsetZ, offsetYaw)
    (grid point q appears at o + Rz(yaw) q), so the scan reports a true point
    p at Rz(-yaw) (p - o).
    """
    if "terrain.offsetX" not in truth.extension:
        return None
    ox, oy = truth.extension["terrain.offsetX"], truth.extension["terrain.offsetY"]
    oz, yaw = truth.extension["terrain.offsetZ"], truth.extension["terrain.offsetYaw"]
    c, s = np.cos(yaw), np.sin(yaw)

    def transform(points: np.ndarray) -> np.ndarray:
        dx, dy = points[:, 0] - ox, points[:, 1] - oy
        return np.column_stack([c * dx + s * dy, -s * dx + c * dy, points[:, 2] - oz])
    return transform
