"""Where each sensor has samples in a run: a sensor that starts late, stops early or drops out.

A run's columns are each used from their own samples (docs/campaign-format.md, "Sensors at
different rates"): interpolated between them, never extrapolated beyond the first and the last.
A column without samples over a span of the run longer than ``SILENT_SPAN`` (1 s) and
``SILENT_STEPS`` (5) of its own typical sample intervals has stopped measuring there, which a
logger's own rate does not explain:

* **Inputs of the replays** (``omega_left``, ``omega_right``, and ``drawbar_force`` in a drawbar
  run) drive every replay from the run's first row to its last. Before their first sample or
  after their last one, the replay would be driven by the end value held, which nobody measured:
  an error that says which rows to cut. A dropout inside the run is a warning: the replay is
  driven by the straight line across it.
* **Compared columns** (positions, torques, attitude, ...) are compared only where they have
  samples, so a late start, an early stop or a dropout costs comparisons and no more: a warning
  that says so.
"""

from __future__ import annotations

import numpy as np

from ..campaign import RunData
from .findings import Finding, _g, _own, _time

#: A span without samples longer than both of these (s; and typical sample intervals of the
#: column) is the sensor not measuring.
SILENT_SPAN = 1.0
SILENT_STEPS = 5.0


def replay_inputs(run: RunData) -> tuple[str, ...]:
    """The columns that drive a replay of ``run``."""
    return ("omega_left", "omega_right", "drawbar_force") if run.kind == "drawbar" else ("omega_left", "omega_right")


def check_coverage(run: RunData, file: str, columns: tuple[str, ...]) -> list[Finding]:
    """Each of ``columns`` that ``run`` has: a late start, an early stop or a dropout (module
    docstring)."""
    first, last = float(run.time[0]), float(run.time[-1])
    inputs = replay_inputs(run)
    found = []
    for name in columns:
        if not run.has(name):
            continue
        ts, _, lines = _own(run, name)
        if len(ts) < 2:
            continue
        steps = np.diff(ts)
        allowed = max(SILENT_SPAN, SILENT_STEPS * float(np.median(steps)))
        ends = []
        if ts[0] - first > allowed:
            ends.append(f"starts {_g(ts[0] - first)} s after the run's first row (its first sample at line "
                        f"{int(lines[0])}, t = {_time(ts[0])} s)")
        if last - ts[-1] > allowed:
            ends.append(f"stops {_g(last - ts[-1])} s before the run's last row (its last sample at line "
                        f"{int(lines[-1])}, t = {_time(ts[-1])} s)")
        if ends and name in inputs:
            found.append(Finding("error", file, name, f"{' and '.join(ends)}: every replay of the run is driven by "
                                 f"{name} from the run's first row to its last, and beyond its samples it would be "
                                 f"driven by a value nobody measured; cut the run's rows to t = {_time(ts[0])}-"
                                 f"{_time(ts[-1])} s, where {name} has samples"))
        elif ends:
            found.append(Finding("warning", file, name, f"{' and '.join(ends)}: the sensor stopped measuring; "
                                 f"{name} is compared only where it has samples"))
        gap = int(np.argmax(steps))
        if steps[gap] > allowed:
            what = ("every replay is driven by the straight line across the gap" if name in inputs
                    else f"{name} is compared only where it has samples")
            found.append(Finding("warning", file, name, f"has no sample for {_g(steps[gap])} s, from line "
                                 f"{int(lines[gap])} (t = {_time(ts[gap])} s) to line {int(lines[gap + 1])} "
                                 f"(t = {_time(ts[gap + 1])} s), where its samples are typically "
                                 f"{_g(float(np.median(steps)))} s apart: a dropout; {what}"))
    return found
