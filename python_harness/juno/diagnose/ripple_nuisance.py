"""A ripple in the wheel angle: a nuisance of the fits of the models that do not make it, and
part of the grouser candidate, whose lugs do.

When the base model's drive torques ripple with the wheel angle at N per revolution
(juno.periodic_structure, on its held-out samples: lugs entering the soil one by one), the
ripple is in the residuals of every model that does not make it. It does not stay there alike:
the drawbar runs are replayed following the measured spins, which ripple with it, and a model
forced to follow a spin ripple its soil does not make answers with a torque ripple of its own,
whose size depends on the soil's shear stiffness. Least squares then bends the soil to shrink
the mismatch: on a synthetic campaign with rippling lugs, the catalog grouser's fit ended with
gamma at the bound of its search, and its training loss was lower there than at the truth
without the ripple; a drivetrain loss, whose soil was not bent, was named instead.

So, once the base model's torques are found to ripple, the loss of every fit of a model without
the ripple is taken on residuals from which that component is removed (:func:`nuisance_free`):
in every 4 s block of a drawbar run, each drive torque's residuals are projected off cos and sin
of h N theta (h in HARMONICS; theta: the side's wheel angle, the measured spin integrated), by
least squares within the block (a lug ripple's amplitude follows the load, which changes from
run to run and block to block, and a block's fit sees no other block's samples, so the training
loss looks at no held-out sample). Four of a block's 200 torque samples (at 50 Hz) are spent on
it. What the candidates are judged on, the held-out residuals, and what the models report, and
the structure test reads, keep the ripple. Without a ripple found, nothing changes.

Lugs make the ripple, and the grouser candidate, whose cause is lugs, then carries it
(:func:`with_lug_ripple`): the FMU's lug ripple at the lug count found, one amplitude fitted for
the drawbar runs, each drawbar run's and side's phase found through the base model
(:func:`lug_phases`). A model whose lugs ripple (an amplitude other than none,
:func:`makes_lug_ripple`) is fitted and compared on its whole residuals: the ripple is what it is
there to explain. Why the grouser needs it: the soil absorbs the lugs' mean thrust, and a
ripple in the traction shifts the mean the replay answers the rippling spins with, so on
alternative-design campaigns hiding the ``lug_ripple`` form at strengths 0.73-0.84 the catalog
grouser at the truth's own thrust and lug height bought -2 to +1 % of the drawbar runs' held-out
error, with the ripple 21-28 %.
"""

from __future__ import annotations

import numpy as np

from ..periodic_structure import wheel_angle
from .candidates import Candidate, ExtParam, for_runs, unqualified
from .problem import BLOCK, Problem

#: Harmonics of the lug count removed: the fundamental and its first overtone (a lug's push is
#: not a sinusoid).
HARMONICS = (1, 2)
#: Which replay input is each drive torque's side's spin.
SPIN_INPUT = {"torque_left": "omegaRefLeft", "torque_right": "omegaRefRight"}
#: Each drive torque's side's lug phase in the FMU.
LUG_PHASE = {"torque_left": "grouser.lugPhaseLeft", "torque_right": "grouser.lugPhaseRight"}
#: The FMU's lug ripple amplitude, and the bound of its search: the traction limit pulsing by
#: up to nine tenths of itself.
RIPPLE_AMPLITUDE, RIPPLE_BOUND = "grouser.rippleAmplitude", 0.9
#: The ripple lug_phases replays a model with: small enough for the residuals to move linearly
#: with it, large enough to stand far above the replay's round-off.
PROBE_AMPLITUDE = 0.1
#: Where the amplitude's search starts: a tenth, not none, since a model without a ripple takes it
#: as a nuisance and one with a ripple does not, so the loss steps there (makes_lug_ripple).
RIPPLE_START = 0.1


def makes_lug_ripple(params: dict[str, object] | None) -> bool:
    """Whether the model ``params`` makes a lug ripple: a lug ripple amplitude other than none
    on some run."""
    return bool(params) and any(unqualified(k) == RIPPLE_AMPLITUDE and v != 0 for k, v in params.items())


def nuisance_free(problem: Problem, r: np.ndarray, params: dict[str, object] | None = None) -> np.ndarray:
    """``r`` (residuals over ``problem``'s runs, in its order) with the ripple at
    ``problem.ripple_lugs`` per wheel revolution removed from each drive torque's residuals of
    the drawbar runs, block by block (module docstring); ``r`` itself when no ripple is set, or
    when the model ``params`` makes the ripple (makes_lug_ripple)."""
    if not problem.ripple_lugs or makes_lug_ripple(params):
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


def lug_phases(problem: Problem, params: dict[str, object], residuals: np.ndarray) -> dict[str, float]:
    """Where each drawbar run's lugs are, side by side, for the model ``params`` (without a
    ripple), whose residuals are ``residuals``: the phase at which that model's own lug ripple
    (N ``problem.ripple_lugs``) best cancels the residuals' ripple on the training blocks, as the
    FMU parameter of the side's lug phase applied to that run (for_runs).

    The model is replayed twice with a small ripple (PROBE_AMPLITUDE) on every side, at phase 0
    and a quarter period on; to first order its residuals then move by a ripple a cos(phi) times
    the first change plus -a sin(phi) times the second, and per run and side (its drive torque's
    training samples, each block's mean taken out) the two weights that best cancel the
    residuals give phi.  Why through the model: the replay follows the measured spins through a
    controller, and the torque it answers a traction ripple with lags that ripple by a phase
    that grows with the spin; the residuals' own phase is off the lugs' by that lag (0.3-0.8 rad
    on a synthetic campaign whose lugs start at phase 0).  Why per run: the wheel angle counts
    from where each run starts, wherever the lugs then are.  {} without a ripple set, or if a
    probe cannot be replayed."""
    n = problem.ripple_lugs
    if not n:
        return {}
    from ..simulator import JunoFMU
    from .problem import residuals_for
    kinds = ("drawbar",)
    drawbar = np.concatenate([np.full(sum(len(v[0]) for v in p.targets.values()), p.kind == "drawbar")
                              for p in problem.prepared])
    probes = []
    with JunoFMU(problem.fmu_path) as fmu:
        for phase in (0.0, -np.pi / 2):
            probe = {**params, "grouser.lugCount": float(n), RIPPLE_AMPLITUDE: PROBE_AMPLITUDE,
                     LUG_PHASE["torque_left"]: phase, LUG_PHASE["torque_right"]: phase}
            r = residuals_for(fmu, problem, probe, kinds)
            if r is None:
                return {}
            probes.append(r - residuals[drawbar])
    base, train, block = residuals[drawbar], problem.train[drawbar], problem.meta["block"][drawbar]
    phases, start = {}, 0
    for p in (p for p in problem.prepared if p.kind == "drawbar"):
        for column, (ts, *_rest) in p.targets.items():
            index = np.arange(start, start + len(ts))
            start += len(ts)
            if column not in LUG_PHASE:
                continue
            mine = index[train[index]]
            columns = [base[mine], probes[0][mine], probes[1][mine]]
            for b in np.unique(block[mine]):
                inside = block[mine] == b
                for c in columns:
                    c[inside] -= c[inside].mean()
            if not all(np.all(np.isfinite(c)) for c in columns) or len(mine) < 3:
                continue
            x, y = np.linalg.lstsq(np.column_stack(columns[1:]), -columns[0], rcond=None)[0]
            phases[for_runs(LUG_PHASE[column], [p.run_id])] = float(np.arctan2(-y, x))
    return phases


def with_lug_ripple(grouser: Candidate, problem: Problem, base_params: dict[str, object],
                    base_residuals: np.ndarray) -> Candidate:
    """The grouser candidate carrying the lug ripple the base model's drive torques show
    (``problem.ripple_lugs`` per revolution; the base model ``base_params``, its residuals
    ``base_residuals``): the FMU's lug count at N, each drawbar run's and side's lug phase
    (lug_phases), both fixed, and one amplitude for every drawbar run fitted with the rest.  The
    terrain runs get no ripple: a run replayed off its measured spins drifts from the lugs'
    phase, and a ripple out of phase doubles what it should remove.  ``grouser`` itself when no
    ripple is set (or its phases cannot be found).  The amplitude is charged as any fitted
    parameter (Candidate.parameters_in); the count and the phases, found on the training blocks
    of the base model, are not: they say where the lugs stood when each run started, which is
    the setup's, as the wheel count is, not the cause's."""
    phases = lug_phases(problem, base_params, base_residuals) if problem.ripple_lugs else {}
    if not phases:
        return grouser
    drawbar = [p.run_id for p in problem.prepared if p.kind == "drawbar"]
    amplitude = ExtParam(for_runs(RIPPLE_AMPLITUDE, drawbar), RIPPLE_START, 0.0, RIPPLE_BOUND)
    fixed = (("grouser.lugCount", float(problem.ripple_lugs)),) + tuple(phases.items())
    return Candidate(grouser.name, grouser.cause, grouser.params + (amplitude,), grouser.fixed + fixed,
                     grouser.needs_terrain, grouser.grid, grouser.active, grouser.short_fits, grouser.refine_terrain,
                     grouser.soil_restart, grouser.ripples_with_wheel_angle)
