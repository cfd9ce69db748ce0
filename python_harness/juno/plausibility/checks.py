"""Every check of a campaign: :func:`check_run` (one run's columns), :func:`check_campaign`
(every run and scan), and :func:`enforce_plausibility`, what the commands run before any fit."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Callable, Optional, TextIO, Union

from ..campaign import KNOWN_COLUMNS, Campaign, RunData, read_rig, read_run
from .findings import Finding, PlausibilityError
from .coverage import check_coverage
from .limits import RoverLimits, check_rover, rover_limits
from .motion import check_heading, check_turning
from .noise import check_stated_noise
from .outliers import check_outliers
from .rig import check_rig, check_rig_wheel
from .scan import check_scan
from .sensors import (check_angles, check_drawbar, check_positions, check_signs, check_spins, check_time,
                      check_energy, check_power, check_pull, check_rolling, check_steady_drive, check_torques,
                      drawbar_in_kilonewtons)


def check_run(run: RunData, file: str, limits: RoverLimits) -> list[Finding]:
    """Every check of one run's columns; a column with an error gets no outlier warning on top."""
    found = (check_time(run, file) + check_angles(run, file, limits) + check_spins(run, file, limits)
             + check_torques(run, file, limits) + check_drawbar(run, file, limits)
             + check_signs(run, file, limits) + check_energy(run, file, limits) + check_positions(run, file, limits)
             + check_turning(run, file, limits) + check_stated_noise(run, file)
             + check_coverage(run, file, tuple(c for c in KNOWN_COLUMNS if c != "time")))
    # The checks that compare columns with each other run on columns without an error of their
    # own, so that one mistake gets one message: spins in rev/s, say, would also make the
    # drive's power too small.
    for check, columns in ((check_heading, {"yaw", "pos_x", "pos_y", "omega_left", "omega_right"}),
                           (check_rolling, {"omega_left", "omega_right", "pos_x", "pos_y"}),
                           (check_power, {"drawbar_force", "torque_left", "torque_right", "omega_left", "omega_right",
                                          "pos_x", "pos_y"}),
                           (check_pull, {"drawbar_force", "torque_left", "torque_right", "omega_left", "omega_right"})):
        if not columns & {f.column for f in found if f.severity == "error"}:
            found += check(run, file, limits)
    with_error = {f.column for f in found if f.severity == "error"}
    columns = [c for c in KNOWN_COLUMNS if c != "time" and c not in with_error]
    return found + check_outliers(run, file, columns, limits)


def check_campaign(campaign: Campaign) -> list[Finding]:
    """Reads every run (and every terrain run's scan) and returns every finding, errors first.

    Raises:
        InputError: a file breaks the format (see :func:`juno.campaign.read_run`).
    """
    rover = check_rover(campaign.rover, campaign.manifest_path.name)
    if rover:
        # Every limit derives from the rover's geometry: with the rover wrong, the runs' findings
        # would each repeat the one mistake.
        return rover
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
        found += check_steady_drive(run, spec.file, spec.steady_window, campaign.manifest_path.name)
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
    from ..fmu_parameters import check_rover_overrides

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
