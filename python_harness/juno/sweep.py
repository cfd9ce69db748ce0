"""Parameter sweeps: one scenario simulated over a grid of FMU parameter values.

``juno sweep --scenario drawbar --vary soil.kh=1e5,2.5e5,5e5 --vary soil.eta=0.3:0.7:3``
simulates the 9 combinations (the last ``--vary`` changes fastest) as parallel tasks
(juno.parallel: local processes, or a Dask cluster with ``--scheduler``) and writes one row
per point: the varied values, then summary outputs over the final window of the run (default
its last quarter: means of speed, wheel spins, drive torques, slips and sinkages; the final
pose).  A point the FMU refuses (a parameter out of its range) or that diverges is kept, with
its error and empty outputs.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from typing import Callable, Mapping, Sequence

import numpy as np

from .errors import InputError
from .parallel import FMUHandle, map_tasks
from .simulator import WHEELS, InputSignals, JunoFMU, SimulationError

#: Outputs averaged over the summary window.
MEAN_OUTPUTS = ("vx", "omegaLeft", "omegaRight", "torqueLeftApplied", "torqueRightApplied") + \
    tuple(f"wheel{w}.{s}" for s in ("slip", "sinkage") for w in WHEELS)
#: Outputs taken at the end of the run.
FINAL_OUTPUTS = ("x", "y", "yaw")
SUMMARY_COLUMNS = tuple(f"mean.{n}" for n in MEAN_OUTPUTS) + tuple(f"final.{n}" for n in FINAL_OUTPUTS)


@dataclass
class SweepPoint:
    """One simulated point: the varied parameters, the summary (NaN if it failed), the error."""

    params: dict[str, float]
    summary: dict[str, float] = field(default_factory=dict)
    error: str | None = None


def parse_values(spec: str) -> list[float]:
    """Values of one ``--vary``: ``v1,v2,...`` or ``start:stop:n`` (n evenly spaced, ends included)."""
    text = spec.strip()
    try:
        if ":" in text:
            parts = text.split(":")
            if len(parts) != 3:
                raise ValueError
            start, stop, n = float(parts[0]), float(parts[1]), int(parts[2])
            if n < 1:
                raise ValueError
            values = np.linspace(start, stop, n).tolist()
        else:
            values = [float(v) for v in text.split(",")]
    except ValueError:
        raise InputError(f"values '{spec}' must be v1,v2,... or start:stop:n (n >= 1)") from None
    if not values or not all(math.isfinite(v) for v in values):
        raise InputError(f"values '{spec}' must be finite numbers")
    return values


def grid(vary: Mapping[str, Sequence[float]]) -> list[dict[str, float]]:
    """Every combination of the varied values, the last parameter changing fastest."""
    names = list(vary)
    return [dict(zip(names, combo)) for combo in itertools.product(*(vary[n] for n in names))]


def summarize(result: Mapping[str, np.ndarray], window: tuple[float, float]) -> dict[str, float]:
    """Means over ``window`` (s, both ends included) and final values of one simulation."""
    t = result["time"]
    sel = (t >= window[0] - 1e-9) & (t <= window[1] + 1e-9)
    out = {f"mean.{n}": float(np.mean(result[n][sel])) for n in MEAN_OUTPUTS}
    out.update({f"final.{n}": float(result[n][-1]) for n in FINAL_OUTPUTS})
    return out


def _point_task(args) -> SweepPoint:
    handle, fixed, point, inputs, stop_time, output_interval, window = args
    try:
        sim = handle.get().simulate({**fixed, **point}, inputs, stop_time, output_interval,
                                    outputs=MEAN_OUTPUTS + FINAL_OUTPUTS)
    except SimulationError as exc:
        return SweepPoint(dict(point), {c: float("nan") for c in SUMMARY_COLUMNS}, str(exc))
    return SweepPoint(dict(point), summarize(sim, window))


def sweep(fmu: JunoFMU, points: Sequence[Mapping[str, float]], fixed: Mapping[str, object],
          inputs: InputSignals | None, stop_time: float, output_interval: float = 0.05,
          window: float | None = None, workers: int | None = None, scheduler: str | None = None,
          progress: Callable[[str], None] | None = None) -> list[SweepPoint]:
    """Simulates ``fixed`` parameters updated by each of ``points`` from 0 to ``stop_time`` (s)
    and summarizes the last ``window`` seconds (default: the last quarter of the run).

    One task per point (juno.parallel); results in the order of ``points``, identical whatever
    runs them.  Unknown parameter names raise KeyError before anything is simulated.
    """
    for name in {n for p in points for n in p} | set(fixed):
        if name not in fmu.variables:
            raise KeyError(f"the FMU has no variable '{name}'")
    if not (math.isfinite(stop_time) and stop_time > 0):
        raise InputError(f"stop time {stop_time} must be a positive number of seconds")
    span = stop_time / 4 if window is None else float(window)
    if not (math.isfinite(span) and 0 < span <= stop_time):
        raise InputError(f"summary window {window} s must be positive and at most the run ({stop_time} s)")
    handle = FMUHandle(fmu)
    jobs = [(handle, dict(fixed), dict(p), inputs, stop_time, output_interval, (stop_time - span, stop_time))
            for p in points]

    def done(i: int, point: SweepPoint) -> None:
        if progress and (point.error or (i + 1) % max(1, len(jobs) // 10) == 0 or i + 1 == len(jobs)):
            progress(f"point {i + 1}/{len(jobs)}" + (f": {point.error}" if point.error else ""))
    return map_tasks(_point_task, jobs, workers=workers, scheduler=scheduler, on_result=done)


def format_csv(points: Sequence[SweepPoint]) -> str:
    """One row per point: varied parameters, summary columns, error (empty if none).  Numbers
    are written with repr (they read back exactly)."""
    names = list(points[0].params) if points else []
    lines = [",".join(names + list(SUMMARY_COLUMNS) + ["error"])]
    for p in points:
        cells = [repr(float(p.params[n])) for n in names]
        cells += ["" if not math.isfinite(p.summary.get(c, float("nan"))) else repr(p.summary[c])
                  for c in SUMMARY_COLUMNS]
        error = (p.error or "").replace('"', "'")
        cells.append(f'"{error}"' if error else "")
        lines.append(",".join(cells))
    return "\n".join(lines) + "\n"
