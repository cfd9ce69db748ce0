"""The IMU's mounting in the diagnosis: every fit and every judgement takes the pitch's offset
on each mounting off the residuals (juno.imu_mounting), estimated on the drawbar runs' training
blocks alone, so that the held-out blocks judge it as they judge a fitted parameter.

A mounting bias is a fact of the instrument, not of the soil, and it shows as no cause of the
catalog does: the same angle from the first sample, at rest and at any load, in every run on the
mounting alike.  The causes that pitch the rover do not act so.  A multi-pass rut lifts the rear
wheels' sinkage only once they roll in the front wheels' rut, a wheelbase after the rover starts,
and by as much as the rut, which follows each run's load; slip-sinkage follows the slip; a soil
patch is where the rover crosses it.  What a constant angle explains, a cause is not credited
with.  With the offset held at none instead, a base model bends the soil to pitch the rover, and
a candidate that pitches it otherwise is credited with repairing what the bent soil spoils: on an
alternative-design campaign with a pitch bias of 1.3 degrees, a multi-pass rut of 80 % of the
front wheels' sinkage on soil softened to a quarter gained 41 % of the held-out error and was
named.

What the models report, and what the residual structure test reads, keep the offset: a pitch
bias stays in every model's pitch residuals alike, where the structure test finds it as pitch
structure that follows a constant (``unexplained``); the report gives each model's offsets
(:func:`mounting_offsets`).
"""

from __future__ import annotations

import numpy as np

from ..imu_mounting import MOUNTED_SIGNALS, MountedResiduals, mounted_residuals, without_offsets
from ..imu_mounting import mounting_offsets as _offsets
from .problem import Problem

__all__ = ["MOUNTED_SIGNALS", "offset_free", "mounting_offsets"]


def offset_free(problem: Problem, r: np.ndarray) -> np.ndarray:
    """``r`` (scaled residuals over ``problem``'s runs, in its order) with the pitch's offset on
    each IMU mounting (:func:`mounting_offsets`) taken off every one of its residuals on that
    mounting, over each residual's own scale.  A mounting with no finite pitch residual on the
    drawbar runs' training blocks keeps its residuals; so does a residual that is not finite (a
    run the model could not simulate); and so does every residual where the campaign's mounting
    is calibrated (``problem.pitch_offset_free`` False)."""
    if not problem.pitch_offset_free:
        return np.array(r, dtype=float, copy=True)
    return without_offsets(_mounted(problem), r)


def mounting_offsets(problem: Problem, r: np.ndarray) -> dict[str, dict[str, float]]:
    """The offsets the scaled residuals ``r`` (measured - simulated) hold on the drawbar runs'
    training blocks: signal -> IMU mounting -> offset in the signal's units (the pitch's in rad),
    the weighted least-squares constant of the unscaled residuals (juno.imu_mounting).  It is what
    offset_free takes off where the mounting is free, and what a model's residuals hold whatever
    the mounting; a mounting with no such residual is left out."""
    return _offsets(_mounted(problem), r)


def _mounted(problem: Problem) -> list[MountedResiduals]:
    """The pitch's residuals on every mounting of ``problem``, each offset estimated on the
    training blocks."""
    return mounted_residuals(problem.prepared, problem.imu_mounts, problem.train)
