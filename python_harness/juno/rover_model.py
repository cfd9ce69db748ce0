"""The rover's and the soil's constants, as the JunoRover FMU declares them.

One source of truth: the start values of the FMU's parameters in its modelDescription.xml
(wheel radius, rover mass, wheelbase, track, cohesion, friction angle, gravity), read once per
FMU file and cached, and overridden by a campaign manifest's ``rover`` block where it gives
a value (the campaign's value wins, as it does in every simulation).  Nothing is read at
import: the package imports without a built FMU, and worker processes read the XML only when
they first ask for a constant.

Also here: the names of the four soil parameters the paper identifies (:data:`SOIL_PARAMETERS`)
and the paper's tangential force law, Eqn 5 of Petersen & McPhee (2013), in one function
(:func:`traction_ratio`).
"""

from __future__ import annotations

import functools
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping

import numpy as np

#: The four soil parameters the paper identifies, by FMU name: foundation stiffness k_h,
#: nonlinearity exponent eta, rebound gamma and traction modulus K_vx (Eqns 2-5).
SOIL_PARAMETERS = ("soil.kh", "soil.eta", "soil.gamma", "soil.Kvx")


@functools.lru_cache(maxsize=8)
def _start_values(fmu_path: str) -> dict[str, float]:
    """The numeric start values of the FMU at ``fmu_path``, by variable name (read once per path)."""
    from fmpy import read_model_description

    from .simulator import FMU_HINT
    if not Path(fmu_path).is_file():
        raise FileNotFoundError(f"{fmu_path}: FMU not found (the rover's constants are read from its "
                                f"modelDescription.xml): {FMU_HINT}")
    values = {}
    for v in read_model_description(fmu_path).modelVariables:
        if v.start is not None and v.type in ("Real", "Integer"):
            values[v.name] = float(v.start)
    return values


def fmu_defaults(fmu_path: str | os.PathLike | None = None) -> dict[str, float]:
    """Start value of every numeric FMU variable that has one, by FMU name (a copy).

    ``fmu_path``: the FMU; by default the harness's (juno.simulator.default_fmu_path)."""
    if fmu_path is None:
        from .simulator import default_fmu_path
        fmu_path = default_fmu_path()
    return dict(_start_values(str(Path(fmu_path).resolve())))


@dataclass(frozen=True)
class Rover:
    """The rover's and the soil's constants one computation uses (SI units)."""

    wheel_radius: float     # m, including the lugs
    wheel_width: float      # m
    mass: float             # kg, total: chassis, rockers, wheels and a stated rover.payload
    wheelbase: float        # m, front to rear axle
    track: float            # m, between left and right wheel centres
    pivot_height: float     # m, rocker pivots above the axle line
    gravity: float          # m/s^2
    cohesion: float         # Pa, Mohr-Coulomb C of Eqn 5
    friction_angle: float   # rad, internal friction angle phi of Eqn 5

    @property
    def weight(self) -> float:
        """The rover's weight (N)."""
        return self.mass * self.gravity


#: Rover field -> the FMU parameter it is read from.
_FMU_NAMES = {
    "wheel_radius": "wheel.radius", "wheel_width": "wheel.width", "mass": "rover.mass",
    "wheelbase": "rover.wheelbase", "track": "rover.track", "pivot_height": "rover.pivotHeight",
    "gravity": "env.gravity", "cohesion": "soil.cohesion", "friction_angle": "soil.phi",
}


def rover(overrides: Mapping[str, object] | None = None, fmu_path: str | os.PathLike | None = None) -> Rover:
    """The FMU's defaults, each replaced by ``overrides`` (a campaign's ``rover`` block, FMU names
    to values) where it gives one.  ``fmu_path``: as for :func:`fmu_defaults`."""
    values = {**fmu_defaults(fmu_path), **(overrides or {})}
    fields = {field: float(values[name]) for field, name in _FMU_NAMES.items()}
    fields["mass"] += float(values.get("rover.payload", 0.0))   # the mass the rover stands on
    return Rover(**fields)


def traction_ratio(slip: np.ndarray, kvx: float, normal_force: float, area: float, cohesion: float,
                   friction_angle: float) -> np.ndarray:
    """F_t / F_n of Eqn 5 (Petersen & McPhee 2013), F_t = F_taumax tanh(slip / K_vx) with
    F_taumax = A C + F_n tan(phi): at normal force ``normal_force`` (N) on a contact patch of
    ``area`` (m^2), cohesion C (Pa) and friction angle phi (rad), against longitudinal slip."""
    return (area * cohesion / normal_force + np.tan(friction_angle)) * np.tanh(slip / kvx)
