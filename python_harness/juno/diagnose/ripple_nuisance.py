"""A ripple in the wheel angle as a nuisance of the fits.

When the base model's drive torques ripple with the wheel angle at N per revolution
(juno.periodic_structure, on its held-out samples: lugs entering the soil one by one), no catalog
candidate can make that ripple, and it is in every model's residuals. It does not stay there
alike: the drawbar runs are replayed following the measured spins, which ripple with it, and a
model forced to follow a spin ripple its soil does not make answers with a torque ripple of its
own, whose size depends on the soil's shear stiffness. Least squares then bends the soil to
shrink the mismatch: on a synthetic campaign with rippling lugs, the catalog grouser's fit ended
with gamma at the bound of its search, and its training loss was lower there than at the truth
without the ripple; a drivetrain loss, whose soil was not bent, was named instead.

So, once the base model's torques are found to ripple, every fit's loss is taken on residuals
from which that component is removed (:func:`nuisance_free`): in every 4 s block of a drawbar
run, each drive torque's residuals are projected off cos and sin of h N theta (h in HARMONICS;
theta: the side's wheel angle, the measured spin integrated), by least squares within the block
(a lug ripple's amplitude follows the load, which changes from run to run and block to block,
and a block's fit sees no other block's samples, so the training loss looks at no held-out
sample). What the candidates are judged on, the held-out block means, is unchanged (they average
the ripple away), and the residuals the models report, and which the structure test reads, keep
their ripple: it is still reported as what no catalog candidate explains. Four of a block's 200
torque samples (at 50 Hz) are spent on it. Without a ripple found, nothing changes.
"""

from __future__ import annotations

import numpy as np

from ..periodic_structure import wheel_angle
from .problem import BLOCK, Problem

#: Harmonics of the lug count removed: the fundamental and its first overtone (a lug's push is
#: not a sinusoid).
HARMONICS = (1, 2)
#: Which replay input is each drive torque's side's spin.
SPIN_INPUT = {"torque_left": "omegaRefLeft", "torque_right": "omegaRefRight"}


def nuisance_free(problem: Problem, r: np.ndarray) -> np.ndarray:
    """``r`` (residuals over ``problem``'s runs, in its order) with the ripple at
    ``problem.ripple_lugs`` per wheel revolution removed from each drive torque's residuals of
    the drawbar runs, block by block (module docstring); ``r`` itself when no ripple is set."""
    if not problem.ripple_lugs:
        return r
    out = np.array(r, dtype=float, copy=True)
    for index, basis in _bases(problem):
        values = out[index]
        if np.all(np.isfinite(values)):
            out[index] = values - basis @ (basis.T @ values)
    return out


def _bases(problem: Problem) -> list[tuple[np.ndarray, np.ndarray]]:
    """For every block of every drawbar run's drive torque: the indices of its residuals, and an
    orthonormal basis of the ripple's harmonics at their wheel angles (kept with the problem)."""
    if problem.ripple_bases is not None:
        return problem.ripple_bases
    bases, start = [], 0
    n = problem.ripple_lugs
    for p in problem.prepared:
        for column, (ts, *_rest) in p.targets.items():
            index = np.arange(start, start + len(ts))
            start += len(ts)
            spin = SPIN_INPUT.get(column)
            if p.kind != "drawbar" or spin not in p.inputs.values:
                continue
            theta = wheel_angle(p.inputs.time, p.inputs.values[spin], ts)
            block = np.floor(ts / BLOCK).astype(int)
            for b in np.unique(block):
                mine = block == b
                if np.sum(mine) < 4 * len(HARMONICS):
                    continue
                angle = n * theta[mine]
                design = np.column_stack([f(h * angle) for h in HARMONICS for f in (np.cos, np.sin)])
                q, _ = np.linalg.qr(design)
                bases.append((index[mine], q))
    problem.ripple_bases = bases
    return bases
