"""Hidden effects for synthetic campaigns (model-notes section 7).

Each effect changes the synthetic truth in one physical way.  An effect
acts through FMU extension parameters of the truth simulation
(``Truth.extension``), through the sensors (``Truth.measurement``), or
through the LIDAR scan; ``--strength`` (0 to 1, 1 = the top of the
documented range) scales it.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

EFFECTS: dict[str, str] = {
    "none": "nothing hidden: the paper's model is the truth",
}


def apply_effect_to_truth(truth, rng: np.random.Generator) -> None:
    """Fills ``truth.extension`` / ``truth.measurement`` for ``truth.effect``."""
    if truth.effect not in EFFECTS:
        raise ValueError(f"unknown effect '{truth.effect}'")


def measurement_transform(truth) -> dict:
    """Keyword arguments of :func:`juno.synthesize.measure` for the effect."""
    return {"torque_scale": float(truth.measurement.get("torque_scale", 1.0))}


def scan_transform(truth) -> Callable[[np.ndarray], np.ndarray] | None:
    """How the LIDAR scan misplaces true points, or None."""
    return None
