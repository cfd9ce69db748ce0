"""The declared range of every variable is what the JunoRover FMU accepts.

For every parameter and input of modelDescription.xml with a declared min or max, the FMU is
instantiated, the value set during initialisation (the other variables at their start values),
initialised and stepped once.  The values: for a Real its min, its max and a point inside; for an
Integer each allowed value (or min, max and the middle when there are many).

Accepted means: fmi2SetReal/fmi2SetInteger return fmi2OK, and neither initialisation nor the step
refuses the value as a parameter ("... must be ...").  A positive quantity has a small positive
min rather than an exclusive 0.  What the physics makes of an accepted extreme (a 318 kg rover on
soil with k_h = 1e-3 N/m^2.5 has no static equilibrium) is a result, reported with its cause; the
point inside every range must run.
"""

from __future__ import annotations

import math

from fmpy import read_model_description

from fmu_helpers import FMICallException, LogCapture, Rover

H = 0.01
# What initialisation or a step may report about an accepted value: physical outcomes.
PHYSICAL_OUTCOMES = ("no static equilibrium", "diverged", "off the ground")


def _walked_variables(fmu_unzipped):
    return [v for v in read_model_description(str(fmu_unzipped)).modelVariables
            if v.causality in ("parameter", "input") and v.type in ("Real", "Integer", "Enumeration")
            and (v.min is not None or v.max is not None)]


def _values(v) -> list[tuple[float, str]]:
    """(value, where) pairs to try: the bounds and a point inside."""
    lo = None if v.min is None else float(v.min)
    hi = None if v.max is None else float(v.max)
    start = float(v.start)
    if v.type in ("Integer", "Enumeration"):
        lo_i, hi_i = int(lo), int(hi)
        if hi_i - lo_i <= 10:
            return [(k, "allowed value") for k in range(lo_i, hi_i + 1)]
        return [(lo_i, "min"), (hi_i, "max"), ((lo_i + hi_i) // 2, "inside")]
    values = []
    if lo is not None:
        values.append((lo, "min"))
    if hi is not None:
        values.append((hi, "max"))
    if lo is not None and hi is not None:
        inside = lo + 0.5 * (hi - lo)
    else:   # one-sided: twice the distance of the start value from the bound, or one unit beyond
        bound = lo if lo is not None else hi
        away = start - bound if start != bound else (1.0 if lo is not None else -1.0)
        inside = bound + 2.0 * away
    values.append((inside, "inside"))
    return values


def _try(fmu_unzipped, v, value) -> tuple[str, str]:
    """(outcome, message): outcome is 'ran', 'set refused', 'init failed' or 'step failed'."""
    log = LogCapture()
    with Rover(fmu_unzipped, log=log) as r:
        r.fmu.setupExperiment(startTime=0.0)
        r.fmu.enterInitializationMode()
        try:
            if v.type == "Real":
                r.fmu.setReal([v.valueReference], [float(value)])
            else:
                r.fmu.setInteger([v.valueReference], [int(value)])
        except FMICallException:
            return "set refused", log.text()
        try:
            r.fmu.exitInitializationMode()
            r._initialised = True
        except FMICallException:
            return "init failed", log.text()
        try:
            r.step(H)
        except FMICallException:
            return "step failed", log.text()
        return "ran", ""


def test_every_value_in_every_declared_range_is_accepted(fmu_unzipped):
    walked = _walked_variables(fmu_unzipped)
    assert len(walked) >= 50, len(walked)
    problems, counts = [], {"ran": 0, "physical outcome": 0}
    for v in walked:
        for value, where in _values(v):
            outcome, message = _try(fmu_unzipped, v, value)
            if outcome == "ran":
                counts["ran"] += 1
                continue
            what = f"{v.name} = {value!r} ({where} of [{v.min}, {v.max}])"
            if outcome == "set refused" or " must " in message:
                problems.append(f"{what} refused: {message}")
            elif where == "inside":
                problems.append(f"{what}, a point inside its range, does not run: {message}")
            elif not any(p in message for p in PHYSICAL_OUTCOMES):
                problems.append(f"{what}: {outcome} without a physical cause: {message}")
            else:
                counts["physical outcome"] += 1
    print("declared ranges walked:", counts)
    assert not problems, f"{len(problems)} values inside their declared ranges:\n" + "\n".join(problems)
    assert counts["ran"] > 3 * len(walked) // 2


def test_just_outside_a_declared_positive_min_is_refused(fmu_unzipped):
    """The other side of the rule: a value below a positive min (the old exclusive 0) is refused
    by fmi2SetReal itself, naming the variable and its range."""
    walked = [v for v in _walked_variables(fmu_unzipped)
              if v.type == "Real" and v.min is not None and float(v.min) > 0]
    assert len(walked) >= 15, [v.name for v in walked]
    for v in walked:
        for value in (0.0, math.nextafter(float(v.min), -math.inf)):
            log = LogCapture()
            with Rover(fmu_unzipped, log=log) as r:
                try:
                    r.fmu.setReal([v.valueReference], [value])
                    raise AssertionError(f"{v.name} = {value!r} below its min {v.min} was accepted")
                except FMICallException:
                    pass
            assert any(v.name in m and "range" in m for m in log.errors()), (v.name, log.errors())
