"""The replay's own bias at a joint fit, by a parametric bootstrap (:func:`replay_bias`).

The joint fit's covariance (identify_joint) covers the sensors' noise: how far the estimates
would scatter if the replay were the rover.  It is not: the replay follows the measured wheel
spins through a stiff PID at the fit's step, from samples of each sensor at its own rate, where
the rover's motors drove the wheels, and a signal the campaign lacks (no pitch) leaves the fit
to lean on what the replay reproduces less well.  That error moves the estimates even on exact
data, by a deterministic amount the covariance knows nothing of.

The bootstrap measures it where the fit ended.  With the fitted soil, each run the rover drove
is simulated again as the rover drove it, by the measured drive torque through a DC motor
(prepare_run's ``"torque"`` drive: the torque the rover's motors gave, and the back-EMF's
damping towards the measured spins), at half the fit's step, from the start the replay takes:
a synthetic world in which the soil is known.  It is written as a measurement with exactly the
campaign's columns, sample times and windows, the measured drawbar force as the load, and
refitted as the data were: the same replay, residual scales, optimizer, budget and start.  The
refit's offset from the fitted soil is what the replay does to a soil it should recover: the
bias.

Noise-free, on purpose: the bias is the deterministic part of the error, and a noisy synthetic
measurement would add to it one draw of the sensor noise, as large as the statistical
uncertainty already stated (counted twice in the total, and of random sign, so the offset of
one noisy refit tells bias from scatter no better than the fit itself).  The refit keeps the
fit's residual scales, estimated from the measured columns' noise: a replay's bias depends on
how the fit weighs its signals, and on noise-free columns the scales would fall to their
nominal floors and weigh them otherwise.

The bias at the fitted soil stands for the bias at the true one to first order (it changes
along the fit's offset from the truth).  It is stated as a systematic standard deviation, not
subtracted (JointResult.std_systematic, identify_joint).
"""

from __future__ import annotations

import dataclasses
import time
from typing import Sequence

import numpy as np

from ..campaign import Campaign, RunData, RunSpec
from ..parallel import FMUHandle, TaskPool
from ..simulator import JunoFMU, SimulationError
from .replay import PreparedRun, prepare_run

#: The synthetic world's fixed integration step (s): half the fit's (IDENTIFY_STEP), the step a
#: synthetic campaign's truth is simulated at (synthesize.TRUTH_STEP), so that the replay's
#: discretisation is part of the bias measured.
WORLD_STEP = {"solver.step": 1e-3, "solver.tolerance": 0.0}
#: The world's output interval (s): its inputs are the measured signals on a 10 ms grid,
#: interpolated at each output, and every sensor's samples are interpolated in its outputs.
WORLD_INTERVAL = 0.005
#: Measured column -> the FMU output a sensor of it reads.  The drawbar force is the world's load
#: as measured; the columns no fit uses (accelerations, rates) are left out of the measurement.
MEASURED_OUTPUTS = {
    "torque_left": "torqueLeftApplied", "torque_right": "torqueRightApplied",
    "omega_left": "omegaLeft", "omega_right": "omegaRight",
    "pos_x": "x", "pos_y": "y", "pos_z": "z", "roll": "roll", "pitch": "pitch", "yaw": "yaw",
}


@dataclasses.dataclass
class ReplayBias:
    """The bootstrap's refit: ``params`` its estimate of the synthetic world's soil, ``status``
    its JointResult status, its ``evaluations`` and the bootstrap's ``wall_time`` (s)."""

    params: dict[str, float]
    status: str
    evaluations: int
    wall_time: float


def synthetic_run(fmu: JunoFMU, campaign: Campaign, run: RunSpec, data: RunData, soil: dict[str, float],
                  terrain_file: str | None = None, extra: dict[str, object] | None = None) -> RunData:
    """Run ``data`` as the rover would have measured it on ``soil``: the run simulated by its
    measured drive torque (prepare_run's ``"torque"`` drive) at WORLD_STEP, each column the fit
    reads sampled at the measured column's own times, exactly (no noise), the drawbar force as
    measured.  SimulationError when the world cannot be simulated; ValueError when the measured
    torques are beyond the torque replay's motor."""
    world = prepare_run(campaign, run, data, terrain_file=terrain_file, drive="torque")
    wanted = [c for c in MEASURED_OUTPUTS if c in data.columns]
    params = {**world.params, **soil, **(extra or {}), **WORLD_STEP}
    try:
        sim = fmu.simulate(params, world.inputs, world.duration, WORLD_INTERVAL,
                           outputs=sorted({MEASURED_OUTPUTS[c] for c in wanted}))
    except SimulationError as exc:
        raise exc.located(run.id, run.file) from exc
    t = data.time
    columns = {"time": t.copy()}
    for name, values in data.columns.items():
        if name == "drawbar_force":
            columns[name] = values.copy()
        elif name in MEASURED_OUTPUTS:
            sampled = ~np.isnan(values)
            column = np.full(len(values), np.nan)
            column[sampled] = np.interp(t[sampled] - t[0], sim["time"], sim[MEASURED_OUTPUTS[name]])
            columns[name] = column
    return dataclasses.replace(data, columns=columns, extra={})


def _synthetic_task(args) -> RunData | Exception:
    handle, campaign, run, data, soil, terrain_file, extra = args
    try:
        return synthetic_run(handle.get(), campaign, run, data, soil, terrain_file, extra)
    except (SimulationError, ValueError) as exc:
        return exc


def replay_bias(fmu: JunoFMU, campaign: Campaign, runs: Sequence[RunSpec], data: dict[str, RunData],
                prepared: Sequence[PreparedRun], fitted: dict[str, float], initial: dict[str, float] | None,
                max_evaluations: int, optimizer: str, extra: dict[str, object] | None = None,
                terrain_files: dict[str, str | None] | None = None, pool: TaskPool | None = None) -> ReplayBias:
    """The parametric bootstrap of the module docstring at the ``fitted`` soil of a joint fit
    over ``runs`` (their measured ``data`` and the fit's ``prepared`` replays, whose residual
    scales the refit keeps), from the fit's ``initial`` soil (None: the paper's guess) with its
    ``max_evaluations`` and ``optimizer``.  The synthetic runs are simulated as parallel tasks on
    ``pool``, and the refit evaluates on it as the fit does.  Raises SimulationError (FitError
    among them) or ValueError when the world or the refit cannot be simulated."""
    from .joint import JointResiduals, _fit_joint
    start = time.perf_counter()
    terrain_files = terrain_files or {}
    handle = FMUHandle(fmu)
    jobs = [(handle, campaign, r, data[r.id], fitted, terrain_files.get(r.id), extra) for r in runs]
    if pool is not None and pool.parallel:
        worlds = pool.map(_synthetic_task, jobs)
    else:
        worlds = [_synthetic_task(j) for j in jobs]
    failed = next((w for w in worlds if isinstance(w, Exception)), None)
    if failed is not None:
        raise failed
    synthetic = []
    for run, world, fit_run in zip(runs, worlds, prepared):
        p = prepare_run(campaign, run, world, terrain_file=terrain_files.get(run.id))
        p.targets = {c: (ts, vs, out, fit_run.targets[c][3], lag) for c, (ts, vs, out, _s, lag) in p.targets.items()}
        synthetic.append(p)
    fun = JointResiduals.for_campaign(fmu, campaign, runs, synthetic, extra, pool)
    refit, _r = _fit_joint(fun, list(runs), synthetic, initial, max_evaluations, optimizer, None, start)
    return ReplayBias(params=refit.params, status=refit.status, evaluations=refit.evaluations,
                      wall_time=time.perf_counter() - start)
