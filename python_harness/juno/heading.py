"""The rover's heading where a run has no measured one (no ``yaw`` column).

A campaign's IMU may give pitch and roll but no heading (no magnetometer, or a gyro heading that
drifts and was left out), and its positions may be in any frame (a total station's, turned from
the rover's start). The replays start the rover at its first measured pose, so they need its
heading there; the kinematic registration poses it at every position.

* **At the start** (:func:`start_heading`): the direction of the track over its first
  ``START_TRAVEL`` of travel, from the principal axis of those positions (a line through them by
  total least squares), pointing the way the rover went, or the opposite way when the wheels
  turned backward there. Its standard error (:attr:`Heading.sigma`) is that of the line's
  direction: the positions' scatter across it over their spread along it. Assumption, named:
  the rover drives straight over that stretch and does not crab (it starts on flat ground).
  Over 0.5 m with 5 mm of position noise at 5 Hz the error is about 0.01 rad.
* **Along the run** (:func:`track_headings`): the direction of travel over ``TRACK_WINDOW`` s
  either side of each sample (the local least-squares velocity juno.campaign.forward_speed uses). It is the body's heading only where the rover does not crab: on a
  slope a skid-steered rover slides sideways, and the track's direction differs from its
  heading by a tenth of a radian or more (measured on the synthetic mound), so a kinematic pose
  from it is not as good as one from a measured heading (juno.scan_consistency leaves a run
  without one untested).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .campaign import RunData, travel_direction
from .sensor_noise import sensor_noise

#: Travel (m) over which the start heading is taken from the track.
START_TRAVEL = 0.5
#: Least travel (m) from which a start heading is taken at all: under it, the positions' noise
#: (millimetres) would turn the direction by more than a few hundredths of a radian.
LEAST_TRAVEL = 0.1
#: Half the window (s) over which the track's direction is taken along a run.
TRACK_WINDOW = 0.5


@dataclass(frozen=True)
class Heading:
    """A heading (rad), its standard error (rad) and where it comes from ("yaw" or "track")."""

    value: float
    sigma: float
    source: str


def start_heading(data: RunData, name: str = "") -> Heading:
    """The rover's heading at the start of run ``data`` (``name`` for messages): the first
    measured yaw sample, or without a ``yaw`` column the track's direction (module docstring).
    ValueError when there is no yaw and the rover travels less than LEAST_TRAVEL."""
    if data.has("yaw"):
        t, yaw = data.samples("yaw")
        return Heading(float(yaw[0]), sensor_noise(data, "yaw"), "yaw")
    tx, x = data.samples("pos_x")
    ty, y = data.samples("pos_y")
    y = np.interp(tx, ty, y)
    travel = np.hypot(x - x[0], y - y[0])
    if not np.max(travel) >= LEAST_TRAVEL:
        raise ValueError(f"run '{name or data.run_id or data.path}' has no yaw column, and its positions move only "
                         f"{np.max(travel):.3g} m from the first: its start heading cannot be told from its track "
                         f"(at least {LEAST_TRAVEL:g} m); give the heading as a yaw column")
    reach = int(np.argmax(travel >= START_TRAVEL)) if np.max(travel) >= START_TRAVEL else len(x) - 1
    px, py = x[:reach + 1], y[:reach + 1]
    centred = np.column_stack([px - px.mean(), py - py.mean()])
    _, singular, axes = np.linalg.svd(centred, full_matrices=False)
    direction = axes[0]
    if np.dot(direction, [px[-1] - px[0], py[-1] - py[0]]) < 0:
        direction = -direction
    if _backward(data, tx[0], tx[reach]):
        direction = -direction
    along, across = singular[0], singular[1] if len(singular) > 1 else 0.0
    dof = max(len(px) - 2, 1)
    sigma = float(across / np.sqrt(dof) / along) if along > 0 else float("inf")
    return Heading(float(np.arctan2(direction[1], direction[0])), sigma, "track")


def _backward(data: RunData, t0: float, t1: float) -> bool:
    """Whether the wheels turned backward (their mean spin below zero) between t0 and t1."""
    spins = []
    for column in ("omega_left", "omega_right"):
        if data.has(column):
            t, w = data.samples(column)
            inside = (t >= t0) & (t <= t1)
            spins.append(w[inside] if inside.any() else w[:1])
    return bool(spins and float(np.mean(np.concatenate(spins))) < 0)


def track_headings(t: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The direction of travel (rad, unwrapped) at each sample time ``t`` (s) of a track (m):
    juno.campaign.travel_direction over 2 TRACK_WINDOW s (where the rover stands still, the
    direction at the nearest time it moved); 0 for a track that never moves."""
    direction = travel_direction(t, x, t, y, t, 2.0 * TRACK_WINDOW)
    if direction is None:
        return np.zeros(len(t))
    return np.unwrap(np.arctan2(direction[1], direction[0]))
