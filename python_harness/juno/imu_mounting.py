"""The IMU's mounting: a constant angle in the measured pitch, one per mounting, that a fit
takes as a nuisance parameter of the instrument rather than of the soil.

The IMU measures the chassis's pitch against its own mounting, which is known to a fraction of a
degree at best (a degree is 17 mrad, six times the pitch sensor's noise scale).  A fit that holds
the offset at none bends the soil to pitch the rover by it, since the pitch is one of the
compared signals on every sample.  A free offset is least squares' own answer: it is profiled
out of the residuals (variable projection), so every fit of the soil is the fit of the soil and
the offset together, and the finite-difference Jacobian of the projected residuals is that of
the fit with the offset free.

The residuals are scaled, each by its run's noise of the signal, which differs from run to run
where the noise is estimated from each run (a sensor noisier than the nominal scale).  One
mounting is one angle, so the offset is the noise-weighted least-squares constant of the unscaled
residuals, and each scaled residual loses it over its own run's scale: a mounting bias leaves
nothing in any run, where a mean of the scaled residuals would leave a constant of opposite signs
in runs of different noise.

An IMU taken off and mounted again between runs has an angle per mounting: the campaign's
manifest names each run's (``imu_mount``, RunSpec.imu_mount), and each mounting's angle is
estimated on its own drawbar runs and taken off its own runs.  Only the drawbar runs' replays
compare the pitch (identify.TERRAIN_SIGNALS has none), so a mounting with no drawbar run has no
pitch residual to take anything off.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Mapping, Optional, Sequence

import numpy as np

from .campaign import DEFAULT_IMU_MOUNT

if TYPE_CHECKING:     # the fits (juno.identify) import this module
    from .identify.replay import PreparedRun

#: The replayed signals measured against a mounting: the IMU's pitch.
MOUNTED_SIGNALS = ("pitch",)


@dataclass(frozen=True)
class MountedResiduals:
    """A mounted signal's residuals on one IMU mounting, within the residuals of a list of
    prepared runs (their targets in order): the indices of all of them and their scales (the
    signal's units per scaled unit), and the same of those its offset is estimated on."""

    signal: str
    mount: str
    every: np.ndarray
    every_scale: np.ndarray
    estimated_on: np.ndarray
    estimated_on_scale: np.ndarray

    def offset(self, r: np.ndarray) -> Optional[float]:
        """The offset (the signal's units) that the scaled residuals ``r`` hold: the weighted
        least-squares constant of the unscaled residuals over the finite ones it is estimated
        on, each weighted by its scale's inverse square; None where none is finite."""
        values = r[self.estimated_on]
        finite = np.isfinite(values)
        if not np.any(finite):
            return None
        scale = self.estimated_on_scale[finite]
        return float(np.sum(values[finite] / scale) / np.sum(1.0 / scale ** 2))


def mounted_residuals(prepared: Sequence[PreparedRun], mounts: Mapping[str, str],
                      estimate_on: Optional[np.ndarray] = None) -> list[MountedResiduals]:
    """Every mounted signal the ``prepared`` runs compare, on every IMU mounting (``mounts``:
    run id -> mounting, DEFAULT_IMU_MOUNT for a run not named), in MOUNTED_SIGNALS' order and then
    the mountings' order of first appearance.  Each offset is estimated on the drawbar runs'
    residuals where ``estimate_on`` (a mask over the concatenated residuals) is True, on all of
    them when it is None."""
    groups: dict[tuple[str, str], dict[str, list[np.ndarray]]] = {}
    start = 0
    for p in prepared:
        mount = mounts.get(p.run_id, DEFAULT_IMU_MOUNT)
        for column, (ts, _values, _output, sigma, _lag) in p.targets.items():
            index = np.arange(start, start + len(ts))
            start += len(ts)
            if column not in MOUNTED_SIGNALS:
                continue
            group = groups.setdefault((column, mount), {"every": [], "scale": [], "on": [], "on_scale": []})
            group["every"].append(index)
            group["scale"].append(np.full(len(ts), float(sigma)))
            if p.kind == "drawbar":
                on = index if estimate_on is None else index[estimate_on[index]]
                group["on"].append(on)
                group["on_scale"].append(np.full(len(on), float(sigma)))
    ordered = sorted(groups, key=lambda key: MOUNTED_SIGNALS.index(key[0]))
    return [MountedResiduals(signal, mount, np.concatenate(groups[signal, mount]["every"]),
                             np.concatenate(groups[signal, mount]["scale"]), _joined(groups[signal, mount]["on"], int),
                             _joined(groups[signal, mount]["on_scale"], float))
            for signal, mount in ordered]


def mounting_offsets(mounted: Sequence[MountedResiduals], r: np.ndarray) -> dict[str, dict[str, float]]:
    """The offsets the scaled residuals ``r`` (measured - simulated) hold: signal -> mounting ->
    offset in the signal's units (the pitch's in rad); a mounting with no finite residual to
    estimate it on is left out."""
    found: dict[str, dict[str, float]] = {}
    for m in mounted:
        offset = m.offset(r)
        if offset is not None:
            found.setdefault(m.signal, {})[m.mount] = offset
    return found


def without_offsets(mounted: Sequence[MountedResiduals], r: np.ndarray) -> np.ndarray:
    """A copy of ``r`` with each mounting's offset taken off every one of its residuals, over
    each residual's own scale.  A residual that is not finite stays so, and a mounting with no
    finite residual to estimate its offset on keeps its residuals."""
    out = np.array(r, dtype=float, copy=True)
    for m in mounted:
        offset = m.offset(out)
        if offset is not None:
            out[m.every] -= offset / m.every_scale
    return out


def offsets_text(offsets: Mapping[str, float]) -> str:
    """The pitch's offsets (mounting -> rad) in words: degrees and mrad, each mounting named
    unless the campaign has only its one (DEFAULT_IMU_MOUNT)."""
    one = list(offsets) == [DEFAULT_IMU_MOUNT]
    return ", ".join(f"{np.degrees(v):+.2f} deg ({v * 1e3:+.2f} mrad)" + ("" if one else f" on the mounting {k}")
                     for k, v in offsets.items())


def _joined(parts: list[np.ndarray], dtype: type) -> np.ndarray:
    """``parts`` end to end; an empty array of ``dtype`` where there are none."""
    return np.concatenate(parts) if parts else np.zeros(0, dtype)
