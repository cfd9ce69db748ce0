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

So every model is fitted and judged on residuals from which the campaign's pitch offset is
taken off (:func:`offset_free`): the mean of the model's pitch residuals over the drawbar runs'
training blocks, one value for the campaign (one IMU, one mounting), taken off every pitch
residual.  It is least squares' own answer for a free offset (the mean, projected out), and it
is estimated on the training blocks alone, so the held-out blocks judge it as they judge a
fitted parameter.  With the offset held at none instead, a base model bends the soil to pitch
the rover, and a candidate that pitches it otherwise is credited with repairing what the bent
soil spoils: on an alternative-design campaign with a pitch bias of 1.3 degrees, a multi-pass
rut of 80 % of the front wheels' sinkage on soil softened to a quarter gained 41 % of the
held-out error and was named.

What the models report, and what the residual structure test reads, keep the offset: a pitch
bias stays in every model's pitch residuals alike, where the structure test finds it as pitch
structure that follows a constant (``unexplained``).  Only the drawbar runs measure the pitch
among the replayed signals (identify.TERRAIN_SIGNALS has none), so the offset is the drawbar
runs' and there is none to take off elsewhere.
"""

from __future__ import annotations

import numpy as np

from .problem import Problem

#: The replayed signals measured against a mounting: the IMU's pitch.
MOUNTED_SIGNALS = ("pitch",)


def offset_free(problem: Problem, r: np.ndarray) -> np.ndarray:
    """``r`` (residuals over ``problem``'s runs, in its order) with each mounted signal's
    campaign offset taken off every one of its residuals: the mean of its finite residuals on
    the drawbar runs' training blocks (``problem.train``).  A signal with no such residual keeps
    its residuals; so does a residual that is not finite (a run the model could not simulate);
    and so does every residual where the campaign's mounting is calibrated
    (``problem.pitch_offset_free`` False)."""
    out = np.array(r, dtype=float, copy=True)
    if not problem.pitch_offset_free:
        return out
    for every, training in _indices(problem):
        values = out[training]
        values = values[np.isfinite(values)]
        if values.size:
            out[every] -= values.mean()
    return out


def _signals(problem: Problem) -> list[str]:
    """The mounted signals ``problem``'s runs measure, in the order _indices gives them."""
    present = {column for p in problem.prepared for column in p.targets}
    return [s for s in MOUNTED_SIGNALS if s in present]


def _indices(problem: Problem) -> list[tuple[np.ndarray, np.ndarray]]:
    """For every mounted signal _signals gives: the indices of all its residuals, and of those on
    the drawbar runs' training blocks."""
    every: dict[str, list[np.ndarray]] = {s: [] for s in _signals(problem)}
    training: dict[str, list[np.ndarray]] = {s: [] for s in every}
    start = 0
    for p in problem.prepared:
        for column, (ts, *_rest) in p.targets.items():
            index = np.arange(start, start + len(ts))
            start += len(ts)
            if column not in every:
                continue
            every[column].append(index)
            if p.kind == "drawbar":
                training[column].append(index[problem.train[index]])
    return [(np.concatenate(every[s]), np.concatenate(training[s]) if training[s] else np.zeros(0, int))
            for s in every]
