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
The limits are the rover's own physics, from its FMU parameters (:mod:`.limits`). The checks,
one concept a module:

* :mod:`.sensors`: units (degrees, rpm, millimetres, milliseconds, kN), reversed signs, another
  datum, dead or frozen sensors;
* :mod:`.motion`: how the rover moves against how its wheels turn (turning, yaw units, heading);
* :mod:`.outliers`: single absurd samples, at a stated false-alarm rate;
* :mod:`.coverage`: a sensor that starts late, stops early or drops out;
* :mod:`.noise`: a sensor noise the manifest states, against the column's range and its samples;
* :mod:`.rig`: single-wheel testbed tables;
* :mod:`.scan`: a terrain run's scan against its path;
* :mod:`.checks`: all of them over a campaign, and what the commands enforce.
"""

from __future__ import annotations

from .checks import check_campaign, check_run, enforce_plausibility
from .findings import Finding, PlausibilityError
from .limits import RoverLimits, rover_limits
from .outliers import outlier_threshold_k
from .rig import check_rig
from .scan import check_scan, path_off_scan
from .sensors import check_signs

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
