"""The IMU's mounting: a constant offset of the measured pitch, a nuisance of every fit and of
every judgement of the diagnosis.

The IMU measures the chassis's pitch against its own mounting, and a mounting is known to a
fraction of a degree at best: a bias of one degree is 17 mrad, six times the pitch sensor's
noise scale.  Such a bias is a fact of the instrument, not of the soil, and it shows as no
cause of the catalog does: the same angle from the first sample, at rest and at any load, in
every run alike.  The causes that pitch the rover do not act so.  A multi-pass rut lifts the
rear wheels' sinkage only once they roll in the front wheels' rut, a wheelbase after the rover
starts, and by as much as the rut, which follows each run's load; slip-sinkage follows the slip;
a soil patch is where the rover crosses it.  What a constant angle over the whole campaign
explains, a cause is not credited with.

So every model is fitted and judged on residuals from which the campaign's pitch offset is taken
off (:func:`offset_free`): one angle for the campaign (one IMU, one mounting), estimated on the
drawbar runs' training blocks and taken off every pitch residual. It is least squares' own
answer for a free offset: the residuals are scaled by each run's pitch noise, which differs from
run to run where the noise is estimated from each run (a sensor noisier than the nominal scale),
so the angle is the noise-weighted mean of the unscaled residuals (:func:`mounting_offsets`),
and each residual loses the angle over its own run's scale. (A mean of the scaled residuals
would take a different angle off each such run, and leave a constant of the opposite sign in
each, which a cause that pitches the runs differently could be credited with.) It is estimated
on the training blocks alone, so the held-out blocks judge it as they judge a fitted parameter.
An IMU taken off and mounted again between runs has one angle per mounting: the manifest names
each run's (``imu_mount``, Problem.imu_mounts), and each mounting's angle is estimated and taken
off on its own runs alike; a mounting with no drawbar run keeps its pitch residuals (only the
drawbar runs' replay compares the pitch). With the offset held at none instead, a base model
bends the soil to pitch the rover, and a candidate that pitches it otherwise is credited with
repairing what the bent soil spoils: on an alternative-design campaign with a pitch bias of 1.3
degrees, a multi-pass rut of 80 % of the front wheels' sinkage on soil softened to a quarter
gained 41 % of the held-out error and was named.

What the models report, and what the residual structure test reads, keep the offset: a pitch
bias stays in every model's pitch residuals alike, where the structure test finds it as pitch
structure that follows a constant (``unexplained``).  Only the drawbar runs measure the pitch
among the replayed signals (identify.TERRAIN_SIGNALS has none), so the offset is the drawbar
runs' and there is none to take off elsewhere.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..campaign import DEFAULT_IMU_MOUNT
from .problem import Problem

#: The replayed signals measured against a mounting: the IMU's pitch.
MOUNTED_SIGNALS = ("pitch",)


def offset_free(problem: Problem, r: np.ndarray) -> np.ndarray:
    """``r`` (scaled residuals over ``problem``'s runs, in its order) with each mounted signal's
    offset on each mounting (:func:`mounting_offsets`, in the signal's units) taken off every one
    of its residuals on that mounting, over each residual's own scale.  A mounting with no finite
    residual of the signal on the drawbar runs' training blocks keeps its residuals; so does a
    residual that is not finite (a run the model could not simulate); and so does every residual
    where the campaign's mounting is calibrated (``problem.pitch_offset_free`` False)."""
    out = np.array(r, dtype=float, copy=True)
    if not problem.pitch_offset_free:
        return out
    for mounted in _mounted(problem):
        offset = _offset(mounted, out)
        if offset is not None:
            out[mounted.every] -= offset / mounted.every_scale
    return out


def mounting_offsets(problem: Problem, r: np.ndarray) -> dict[str, dict[str, float]]:
    """Each mounted signal's offset on each IMU mounting, in the signal's units (the pitch's in
    rad), in the scaled residuals ``r`` (measured - simulated, over each residual's scale):
    signal -> mounting (RunSpec.imu_mount) -> the weighted least-squares constant of the unscaled
    residuals over the mounting's drawbar runs' finite training residuals, each weighted by its
    scale's inverse square.  It is what offset_free takes off where the mounting is free, and what
    a model's residuals hold whatever the mounting; a mounting with no such residual is left out."""
    found: dict[str, dict[str, float]] = {}
    for mounted in _mounted(problem):
        offset = _offset(mounted, r)
        if offset is not None:
            found.setdefault(mounted.signal, {})[mounted.mount] = offset
    return found


@dataclass(frozen=True)
class _Mounted:
    """A mounted signal's residuals on one IMU mounting in a problem: the indices of all of them
    and their scales (the signal's units per scaled unit), and the same of those on the drawbar
    runs' training blocks."""

    signal: str
    mount: str
    every: np.ndarray
    every_scale: np.ndarray
    training: np.ndarray
    training_scale: np.ndarray


def _offset(mounted: _Mounted, r: np.ndarray) -> float | None:
    """The weighted least-squares constant (mounting_offsets) of ``r`` on ``mounted``'s training
    residuals; None where none is finite."""
    values = r[mounted.training]
    finite = np.isfinite(values)
    if not np.any(finite):
        return None
    scale = mounted.training_scale[finite]
    return float(np.sum(values[finite] / scale) / np.sum(1.0 / scale ** 2))


def _mounted(problem: Problem) -> list[_Mounted]:
    """Every mounted signal ``problem``'s runs measure on every mounting, in MOUNTED_SIGNALS' order
    and then the mountings' order of first appearance, with the indices and scales of its
    residuals."""
    groups: dict[tuple[str, str], dict[str, list[np.ndarray]]] = {}
    start = 0
    for p in problem.prepared:
        mount = problem.imu_mounts.get(p.run_id, DEFAULT_IMU_MOUNT)
        for column, (ts, _values, _output, sigma, _lag) in p.targets.items():
            index = np.arange(start, start + len(ts))
            start += len(ts)
            if column not in MOUNTED_SIGNALS:
                continue
            group = groups.setdefault((column, mount), {"every": [], "scale": [], "training": [], "training_scale": []})
            group["every"].append(index)
            group["scale"].append(np.full(len(ts), float(sigma)))
            if p.kind == "drawbar":
                mine = problem.train[index]
                group["training"].append(index[mine])
                group["training_scale"].append(np.full(int(np.sum(mine)), float(sigma)))
    ordered = sorted(groups, key=lambda key: MOUNTED_SIGNALS.index(key[0]))
    return [_Mounted(signal, mount, np.concatenate(groups[signal, mount]["every"]),
                     np.concatenate(groups[signal, mount]["scale"]), _joined(groups[signal, mount]["training"], int),
                     _joined(groups[signal, mount]["training_scale"], float))
            for signal, mount in ordered]


def _joined(parts: list[np.ndarray], dtype: type) -> np.ndarray:
    """``parts`` end to end; an empty array of ``dtype`` where there are none."""
    return np.concatenate(parts) if parts else np.zeros(0, dtype)
