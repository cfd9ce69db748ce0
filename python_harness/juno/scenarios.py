"""The built-in scenarios of ``juno simulate`` and ``juno sweep``: constant inputs on flat ground.

Each scenario is a :class:`Scenario`: a description, its duration (s), the FMU parameters it
sets and its constant inputs (throttle 0..1, torque N m, drawbar force N).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping


@dataclass(frozen=True)
class Scenario:
    description: str
    stop_time: float                                   # s
    params: Mapping[str, object] = field(default_factory=dict)
    inputs: Mapping[str, float] = field(default_factory=dict)


SCENARIOS: dict[str, Scenario] = {
    "drawbar": Scenario("a 30 s drawbar pull test at 45 % throttle against 400 N", 30.0,
                        {"drive.mode": 2}, {"drawbarForce": 400.0, "throttleLeft": 0.45, "throttleRight": 0.45}),
    "straight": Scenario("20 s straight run at 45 % throttle, no drawbar", 20.0,
                         {"drive.mode": 2}, {"drawbarForce": 0.0, "throttleLeft": 0.45, "throttleRight": 0.45}),
    "turn": Scenario("20 s skid-steer turn: 20 % left, 60 % right throttle", 20.0,
                     {"drive.mode": 2}, {"drawbarForce": 0.0, "throttleLeft": 0.2, "throttleRight": 0.6}),
    "rest": Scenario("10 s at rest on flat ground", 10.0,
                     {"drive.mode": 0}, {"drawbarForce": 0.0, "torqueLeft": 0.0, "torqueRight": 0.0}),
}
