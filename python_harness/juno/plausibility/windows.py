"""A run's positions over sliding windows, which the checks comparing motion with the wheels share."""

from __future__ import annotations

from typing import Optional

import numpy as np
from numpy.typing import NDArray

from ..campaign import RunData, aligned

FloatArray = NDArray[np.float64]


def travel_over_windows(run: RunData, window: float) -> Optional[tuple[FloatArray, FloatArray, FloatArray]]:
    """Times every half ``window`` (s) and the displacement (m) of pos_x and pos_y over ``window``
    centred on each, as (times, dx, dy); None for a run shorter than two windows."""
    tx = run.samples("pos_x")[0]
    if len(tx) < 2 or tx[-1] - tx[0] <= 2 * window:
        return None
    t = np.arange(tx[0] + 0.5 * window, tx[-1] - 0.5 * window, 0.5 * window)
    ends = aligned(run, ["pos_x", "pos_y"], np.concatenate([t - 0.5 * window, t + 0.5 * window]))
    dx, dy = (np.diff(ends[n].reshape(2, -1), axis=0)[0] for n in ("pos_x", "pos_y"))
    return t, dx, dy
