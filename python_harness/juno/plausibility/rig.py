"""Checks of a single-wheel testbed table (wheel_rig runs).

A single-wheel testbed table (wheel_rig runs, :func:`check_rig`) is checked against the wheel
of its manifest entry, against friction and against the power the wheel's motor puts in; when
a table passes every check with two of its columns exchanged, each finding says so:

* **Slip** is a fraction: a slip of 1 or more (the wheel spinning infinitely fast at the
  carriage's speed) is an error, "looks like percent" when the slips lie within 0-100.
* **Load and forces.** The soil's shear strength limits what a wheel transmits: drawbar pull,
  lateral force and the torque over the radius are at most about (tan phi + c A / W) times the
  load, below 1 for every soil simulant (phi < 45 degrees). A ratio beyond ``RIG_FORCE_ERROR``
  (2) is an error (a load in kg; beyond ``RIG_UNIT_KG_LIMIT``, a load in kN, or a torque in
  N mm when the forces are in range), beyond ``RIG_FORCE_WARN`` (1) a warning. A load that is not > 0 is an error.
* **Drawbar pull and thrust.** The torque over the radius is the thrust the wheel transmits; the
  drawbar pull is that thrust less the soil's resistance. Across slips from rolling (0.1 or less)
  into traction (0.2 or more) the pull is a sizeable part of the thrust somewhere: its largest
  magnitude is 0.44-0.99 of the largest thrust on the published tables and on tables the
  WheelRig FMU made (braking included), over 40 times ``RIG_PULL_THRUST_MIN`` (1 %). A largest
  |drawbar pull| under 1 % of the largest thrust, while the torque is in range and a thousand
  times the pull stays within ``RIG_FORCE_ERROR`` loads, is an error, "kN?" (those tables in kN
  give 0.0004-0.001). Slips in one regime only (near the self-propelled point the pull is ~0) are
  not judged.
* **Power.** The soil gives back no more power than the motor puts in: the drawbar pull times
  the carriage's speed v = omega R (1 - slip) is at most the torque times the spin omega, so
  drawbar_pull (1 - slip) <= torque / radius in every row, braking rows (both negative)
  included. A row beyond that by more than ``RIG_POWER_SLACK`` (0.1) times the load, more than
  a testbed's sensors err by, is an error.
* **Sinkage** beyond the wheel radius (the axle under the surface) is an error, "looks like
  millimetres" when a thousandth of it fits.
* **Slip angle** beyond pi/2 is an error ("looks like degrees"), beyond ``RIG_ANGLE_WARN``
  (pi/4, beyond testbed practice) a warning.
* **The wheel** (manifest): a radius beyond 5 m, a width beyond 1 m, lugs beyond 0.1 m or beyond
  half the radius are errors (millimetres), the FMU's own parameter ranges.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..campaign import RIG_COLUMNS, RIG_STD_SUFFIX, RigTable, RunSpec
from .findings import Finding, _g

#: Single-wheel testbed: force (drawbar pull, lateral force, torque / radius) over the load
#: beyond which a table is a warning / an error (module docstring).
RIG_FORCE_WARN = 1.0
RIG_FORCE_ERROR = 2.0
#: The largest force-over-load ratio a load in kg gives (a plausible ratio below RIG_FORCE_ERROR
#: times 9.81); beyond it a load in kN, or a torque in N mm.
RIG_UNIT_KG_LIMIT = RIG_FORCE_ERROR * 9.81
#: The largest |drawbar pull| over the largest thrust (|torque| / radius) below which a table
#: whose slips reach from RIG_ROLLING_SLIP to RIG_TRACTION_SLIP has its pull in kN (docstring).
RIG_PULL_THRUST_MIN = 0.01
RIG_ROLLING_SLIP = 0.1
RIG_TRACTION_SLIP = 0.2
#: The power balance (module docstring): the excess of the drawbar pull times (1 - slip) over
#: the thrust the torque gives, as a fraction of the load, beyond which a row is an error.
RIG_POWER_SLACK = 0.1
#: Slip angle beyond which a testbed point is a warning (rad); beyond pi/2 an error.
RIG_ANGLE_WARN = math.pi / 4
#: The rig wheel's dimensions the FMU accepts (m): radius, width, lug height.
RIG_WHEEL_LIMITS = {"radius": 5.0, "width": 1.0, "lug_height": 0.1}


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
    """Units and physical limits of a wheel_rig table (module docstring); when the table passes
    every check with two of its columns exchanged, each finding says so."""
    out = _check_rig(table, spec, file)
    if not out:
        return out
    names = [c for c in RIG_COLUMNS if c in table.columns and not c.endswith(RIG_STD_SUFFIX)]
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            swapped = dict(table.columns, **{a: table.columns[b], b: table.columns[a]})
            if not _check_rig(dataclasses.replace(table, columns=swapped), spec, file):
                hint = (f"; the columns '{a}' and '{b}' look swapped: exchanged, the table passes these checks "
                        "(check the header's order)")
                return [dataclasses.replace(f, message=f.message + hint) for f in out]
    return out


def _check_rig(table: RigTable, spec: RunSpec, file: str) -> list[Finding]:
    """The checks of :func:`check_rig`."""
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
        force_too_large = any(np.nanmax(ratio) > RIG_FORCE_ERROR for n, ratio in forces if n != "torque")
        for name, ratio in forces:
            if not np.any(ratio > RIG_FORCE_WARN):
                continue
            i = int(np.nanargmax(ratio))
            what = f"|{name}| / (radius x vertical_load)" if name == "torque" else f"|{name}| / vertical_load"
            severity = "error" if ratio[i] > RIG_FORCE_ERROR else "warning"
            hint = ""
            if severity == "error":
                # A load in kg multiplies every ratio by 9.81, so at most by RIG_UNIT_KG_LIMIT; a
                # thousandfold one is a load in kN, or a torque in N mm when the forces are in range.
                if ratio[i] <= RIG_UNIT_KG_LIMIT:
                    hint = ": is the load in kg? (1 kg weighs 9.81 N)"
                elif name == "torque" and not force_too_large:
                    hint = ": looks like N mm (1 N m is 1000 N mm)"
                else:
                    hint = ": is the load in kN? (1 kN is 1000 N)"
            out.append(Finding(severity, file, name, f"{what} reaches {_g(ratio[i])} at {_rig_at(table, i)}; the "
                               f"soil's friction limits it to below about 1 (more than {RIG_FORCE_ERROR:g} is an "
                               f"error){hint}"))
        out += _pull_in_kilonewton(table, radius, file)
        if not out:
            out += _power_balance(table, radius, file)
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


def _pull_in_kilonewton(table: RigTable, radius: float | None, file: str) -> list[Finding]:
    """A drawbar pull too small for the thrust the torque transmits (module docstring); the
    load is > 0 in every row."""
    if not (table.has("torque") and radius):
        return []
    slip, load = table["slip"], table["vertical_load"]
    if not (np.min(slip) <= RIG_ROLLING_SLIP and np.max(slip) >= RIG_TRACTION_SLIP):
        return []
    pull, thrust = np.abs(table["drawbar_pull"]), np.abs(table["torque"]) / radius
    # A torque in N mm inflates the thrust a thousandfold too: its own check names it, not the pull.
    if np.nanmax(thrust / load) > RIG_FORCE_ERROR or np.nanmax(1000.0 * pull / load) > RIG_FORCE_ERROR:
        return []
    i, j = int(np.nanargmax(pull)), int(np.nanargmax(thrust))
    if not pull[i] < RIG_PULL_THRUST_MIN * thrust[j]:
        return []
    std = " (and drawbar_pull_std)" if table.has("drawbar_pull" + RIG_STD_SUFFIX) else ""
    return [Finding("error", file, "drawbar_pull", f"|drawbar_pull| reaches only {_g(pull[i])} at {_rig_at(table, i)}, "
                    f"under {RIG_PULL_THRUST_MIN:.0%} of the thrust the torque transmits (|torque| / radius reaches "
                    f"{_g(thrust[j])} N at {_rig_at(table, j)}) over slips from {_g(np.min(slip))} to "
                    f"{_g(np.max(slip))}, where a wheel pulls a sizeable part of its thrust; a thousand times it "
                    f"is a plausible pull: drawbar_pull{std} in kN? (1 kN is 1000 N)")]


def _power_balance(table: RigTable, radius: float | None, file: str) -> list[Finding]:
    """Rows whose drawbar pull does more work than the torque puts in (module docstring)."""
    if not (table.has("torque") and radius):
        return []
    slip, load = table["slip"], table["vertical_load"]
    pull, torque = table["drawbar_pull"], table["torque"]
    with np.errstate(invalid="ignore"):
        excess = (pull * (1.0 - slip) - torque / radius) / load
        bad = np.flatnonzero(excess > RIG_POWER_SLACK)
    if not bad.size:
        return []
    i = int(bad[np.argmax(excess[bad])])
    return [Finding("error", file, "torque", f"at {_rig_at(table, i)} the drawbar pull of {_g(pull[i])} N at slip "
                    f"{_g(slip[i])} does more work than the torque of {_g(torque[i])} N m puts in: drawbar_pull x (1 - "
                    f"slip) = {_g(pull[i] * (1 - slip[i]))} N against torque / radius = {_g(torque[i] / radius)} N "
                    f"({len(bad)} row{'s' if len(bad) > 1 else ''} beyond it by more than {RIG_POWER_SLACK:g} times "
                    "the load); the soil gives back no more power than the wheel's motor puts in (drawbar_pull x "
                    "carriage speed <= torque x spin): is the torque in another unit, or of the other sign?")]
