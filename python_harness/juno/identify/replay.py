"""A measured run made ready to replay in the model: its inputs (the measured spins imposed,
or the measured torque through a motor), the restarts of a segmented replay, the compared
signals and their scales (:func:`prepare_run`), and its scaled residuals (:func:`run_residuals`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from ..campaign import Campaign, RunData, RunSpec, read_run
from ..heading import start_heading
from ..sensor_noise import residual_scale
from ..simulator import InputSignals, JunoFMU, SimulationError
from .base import IDENTIFY_STEP, base_parameters

#: Signals compared in the joint fit, with each residual's nominal scale (1 sigma, about the
#: paper's instruments' noise): a residual is divided by the larger of it and the sensor noise
#: estimated from the run (_targets, sensor_noise.residual_scale).
#: The model follows the measured wheel spins, so the spins are inputs and the
#: drive torque it needs is compared with the torque from the motor current.
#: Positions enter as increments over ``POSITION_LAG`` (a speed without smoothing lag),
#: so the start-up transient does not leave a constant offset behind.
JOINT_SIGNALS = {
    "torque_left": ("torqueLeftApplied", 3.0), "torque_right": ("torqueRightApplied", 3.0),
    "pos_x": ("x", 0.005), "pos_y": ("y", 0.005), "pos_z": ("z", 0.003), "pitch": ("pitch", 0.003),
}
TERRAIN_SIGNALS = {
    "torque_left": ("torqueLeftApplied", 5.0), "torque_right": ("torqueRightApplied", 5.0),
    "pos_x": ("x", 0.01), "pos_y": ("y", 0.01), "pos_z": ("z", 0.01),
}
INCREMENT_SIGNALS = ("pos_x", "pos_y")
#: A stiff PID so the model's spins follow the measured ones without lag (the
#: default gains lag during the start-up and leave a speed error of a few %).
SPIN_TRACKER = {"drive.Kp": 2000.0, "drive.Ki": 2.0e4, "drive.torqueMax": 2000.0}
POSITION_LAG = 1.0     # s
SETTLING_TIME = 2.0    # s: residuals start after the PID has caught the measured spins

#: How a replay drives the wheels (prepare_run's ``drive``):
#: - ``"spin"``: the stiff PID (SPIN_TRACKER) imposes the measured wheel spins; the model's drive
#:   torque is compared with the measured one.
#: - ``"torque"``: the measured drive torque drives each side, and a damping on the spin error,
#:   K (omega_measured - omega) with K = REPLAY_SPIN_DAMPING, keeps the spins on the measured
#:   ones, as a DC motor's back-EMF does at a constant throttle.  It is done with the FMU's own
#:   DC motor (``drive.mode = 2``, REPLAY_MOTOR) at the throttle that makes its torque
#:   T_measured + K (omega_measured - omega) exactly (torque_replay_throttle): what the rover's
#:   controller did.  The compared torque is then K (omega - omega_measured) off the measured
#:   one, so the torque residual still says how much more or less torque the model needs.
#:   Why: imposing the spins is ill-conditioned where the rover climbs a mound at high slip.
#:   Measured on a noise-free synthetic terrain run (drivetrain loss 0.25 and slip-sinkage 1.43,
#:   the campaign tests/python/test_torque_replay.py builds): replayed with the spins imposed, even at the truth's own 1 ms step, a front wheel
#:   lifted off for 10 s and the torque was 60 N m rms off (5 ms: 10 N m); replayed by torque it
#:   is exact at 1 ms and 3.2 N m rms off at 5 ms.  On drawbar runs the spin replay is the better
#:   conditioned one (at slips of 0.6 the traction hardly changes with spin, so a small traction
#:   error moves a torque-driven wheel's spin a lot: 6.9 N m rms at 5 ms against 0.85 N m).
REPLAY_DRIVES = ("spin", "torque")
#: The DC motor the torque replay runs through: a harness choice, set in full on the FMU, so it
#: does not follow the FMU's defaults.  The constants of the FMU's assumed Juno motor, with a
#: supply voltage ten times the real one, so that the throttle stays well inside [-1, 1] up to
#: about 6000 N m per side (the voltage does not enter K).  K = efficiency gearRatio^2 kt^2 /
#: resistance.
REPLAY_MOTOR = {"motor.voltage": 240.0, "motor.kt": 0.0465, "motor.resistance": 0.2,
                "motor.gearRatio": 129.0, "motor.efficiency": 0.85}
REPLAY_SPIN_DAMPING = (REPLAY_MOTOR["motor.efficiency"]
                       * (REPLAY_MOTOR["motor.gearRatio"] * REPLAY_MOTOR["motor.kt"]) ** 2
                       / REPLAY_MOTOR["motor.resistance"])   # N m s/rad, about 153


def torque_replay_throttle(torque: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """Throttle of REPLAY_MOTOR at which its torque is ``torque`` (N m per side, the measured
    drive torque) when the wheels spin at ``omega`` (rad/s, the measured spin), so that at any
    other spin w it gives torque + REPLAY_SPIN_DAMPING (omega - w)."""
    m = REPLAY_MOTOR
    per_volt = m["motor.efficiency"] * m["motor.gearRatio"] * m["motor.kt"] / m["motor.resistance"]
    return (torque / per_volt + m["motor.kt"] * m["motor.gearRatio"] * omega) / m["motor.voltage"]


#: A run replayed in segments (prepare_run's ``segment``) is not compared for this long after
#: each restart: the spin tracker catches the measured spins and the suspension settles.  At
#: least POSITION_LAG, so that each position increment lies within one segment.
SEGMENT_SETTLE = 1.5   # s
#: The restart speed is the measured path's over this half-window around the restart.
SEGMENT_SPEED_WINDOW = 0.25   # s


@dataclass
class Segment:
    """One piece of a run replayed in segments: simulated from ``start`` to ``stop`` (s from
    the run's start) with the FMU parameters ``init`` (the measured pose and speed) on top."""

    start: float
    stop: float
    init: dict[str, float]


@dataclass
class PreparedRun:
    """A measured run ready to be simulated: inputs, parameters and the samples to compare."""

    run_id: str
    kind: str
    duration: float
    inputs: InputSignals
    params: dict[str, object]
    targets: dict[str, tuple[np.ndarray, np.ndarray, str, float, float]]
    # column -> (t, value, output, sigma, lag): compare value(t) - value(t - lag) when lag > 0
    segments: list[Segment] = field(default_factory=list)   # empty: one replay of the whole run
    file: str | None = None     # the run's data file (as in the manifest), named in failures


def _column_signal(data: RunData, name: str, grid: np.ndarray) -> np.ndarray:
    t, v = data.samples(name)
    return np.interp(grid, t, v)


def restart_segments(data: RunData, duration: float, length: float) -> list[Segment]:
    """Segments of ``length`` s covering a run of ``duration`` s: the first starts as the run
    does (at rest, at the first measured pose); each later one restarts the rover at the
    measured position, heading (``yaw``) and forward speed at its start.  A last piece too short
    to compare anything after SEGMENT_SETTLE joins the one before it."""
    if not (np.isfinite(length) and length > SEGMENT_SETTLE):
        raise ValueError(f"a replay segment must be longer than {SEGMENT_SETTLE} s, got {length}")
    if not data.has("yaw"):
        raise ValueError(f"run '{data.run_id or data.path}': a run replayed in segments needs its measured "
                         f"heading (column 'yaw'), and it has none")
    t0 = data.time[0]
    tx, x = data.samples("pos_x")
    ty, y = data.samples("pos_y")
    tw, yaw = data.samples("yaw")
    yaw = np.unwrap(yaw)     # an IMU's heading wraps at +-pi: interpolated across the jump it would point anywhere
    tx, ty, tw = tx - t0, ty - t0, tw - t0
    starts = [0.0]
    while starts[-1] + length + SEGMENT_SETTLE + 1.0 < duration:
        starts.append(starts[-1] + length)
    segments = []
    for i, start in enumerate(starts):
        stop = starts[i + 1] if i + 1 < len(starts) else duration
        init: dict[str, float] = {}
        if start > 0:
            lo, hi = max(start - SEGMENT_SPEED_WINDOW, 0.0), min(start + SEGMENT_SPEED_WINDOW, duration)
            vx = (np.interp(hi, tx, x) - np.interp(lo, tx, x)) / (hi - lo)
            vy = (np.interp(hi, ty, y) - np.interp(lo, ty, y)) / (hi - lo)
            heading = float(np.interp(start, tw, yaw))
            init = {"init.x": float(np.interp(start, tx, x)), "init.y": float(np.interp(start, ty, y)),
                    "init.yaw": heading, "init.vx": float(vx * np.cos(heading) + vy * np.sin(heading))}
        segments.append(Segment(start, stop, init))
    return segments


def prepare_run(campaign: Campaign, run: RunSpec, data: RunData | None = None,
                terrain_file: str | None = None, stride: int = 1, segment: float | None = None,
                drive: str = "spin", scales: str = "data") -> PreparedRun:
    """Inputs and comparison targets of a measured run.

    Why the spins drive the model: with both drive torque and drawbar force
    imposed, any imbalance integrates into a speed drift (1 % of the drawbar
    force is 0.5 m/s after 30 s), so a replay driven by the torque alone
    diverges even at the true parameters.  With the measured wheel spins imposed by the PID
    (``drive.mode = 1``), the rover settles at the slip where traction
    balances the load, as the real one did; the torque the model needs is
    then compared with the measured one.  Drawbar runs are on flat ground
    with the measured drawbar force; terrain runs on ``terrain_file``.  The
    rover starts at rest at the first measured pose.

    ``segment`` (s, terrain runs only): replay the run in pieces of that
    length, each later one restarted at the measured pose and speed
    (restart_segments), and leave out the SEGMENT_SETTLE s after each
    restart.  Why: over the terrain the spin-following replay drifts in
    heading, and a drift of a few degrees puts the rover on another part of
    a mound; measured, at the true parameters the 30 s replay of some
    synthetic campaigns ended 0.3-0.5 m off the measured path
    (docs/diagnosis.md, ``--terrain-segments``).

    ``scales``: what each residual is divided by: ``"data"``, the sensor noise estimated from
    the run, never below the nominal scale (_targets), or ``"nominal"``, the nominal scales of
    JOINT_SIGNALS and TERRAIN_SIGNALS alone (the diagnosis's, whose thresholds are calibrated
    on them).

    ``drive``: ``"spin"`` (the spins imposed, as above) or ``"torque"`` (the
    measured torque drives the wheels, and a damping towards the measured
    spins, as a DC motor's, keeps them from drifting; REPLAY_DRIVES says when
    each is the better conditioned).
    """
    if drive not in REPLAY_DRIVES:
        raise ValueError(f"run '{run.id}': unknown replay drive '{drive}' (one of {', '.join(REPLAY_DRIVES)})")
    data = data or read_run(campaign, run)
    t = data.time
    grid = np.arange(t[0], t[-1] + 1e-9, 0.01)
    start_pose = {"init.x": float(data.samples("pos_x")[1][0]), "init.y": float(data.samples("pos_y")[1][0]),
                  "init.yaw": start_heading(data, run.id).value}
    params: dict[str, object] = {**base_parameters(campaign), **start_pose, "solver.step": IDENTIFY_STEP,
                                 "solver.tolerance": 0.0, "drive.mode": 1, **SPIN_TRACKER}
    drawbar = (_column_signal(data, "drawbar_force", grid) if run.kind == "drawbar" and data.has("drawbar_force")
               else np.zeros(len(grid)))
    omega_left, omega_right = _column_signal(data, "omega_left", grid), _column_signal(data, "omega_right", grid)
    inputs = InputSignals(grid - t[0], {"drawbarForce": drawbar, "omegaRefLeft": omega_left,
                                        "omegaRefRight": omega_right})
    if drive == "torque":
        inputs.values.update(_replay_throttles(run, data, grid, {"left": omega_left, "right": omega_right}))
        params.update({"drive.mode": 2, **REPLAY_MOTOR})
    duration = float(t[-1] - t[0])
    segments = restart_segments(data, duration, segment) if segment is not None and run.kind == "terrain" else []
    if run.kind == "drawbar":
        signals = JOINT_SIGNALS
    else:
        if terrain_file is None:
            raise ValueError(f"run '{run.id}': a terrain run needs a gridded terrain file")
        params["terrain.file"] = terrain_file
        signals = TERRAIN_SIGNALS
    if scales not in ("data", "nominal"):
        raise ValueError(f"run '{run.id}': unknown residual scales '{scales}' (data or nominal)")
    targets = _targets(data, signals, segments, stride, from_data=scales == "data")
    return PreparedRun(run.id, run.kind, duration, inputs, params, targets, segments, run.file)


def _replay_throttles(run: RunSpec, data: RunData, grid: np.ndarray,
                      omega: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The throttle inputs (``throttleLeft``, ``throttleRight``) of a torque-driven replay on the
    time ``grid`` (s, the run's clock), from the measured drive torques and the spins ``omega``
    (side -> rad/s on the grid); ValueError when a torque column is missing or a throttle would
    exceed the replay motor's range."""
    throttles = {}
    for side in ("left", "right"):
        if not data.has(f"torque_{side}"):
            raise ValueError(f"run '{run.id}': a torque-driven replay needs the measured drive torque "
                             f"(column 'torque_{side}'), and it has none")
        throttle = torque_replay_throttle(_column_signal(data, f"torque_{side}", grid), omega[side])
        worst = int(np.argmax(np.abs(throttle)))
        if abs(throttle[worst]) > 1.0:
            raise ValueError(f"run '{run.id}': at t = {grid[worst] - data.time[0]:.2f} s the measured "
                             f"torque_{side} and omega_{side} are beyond what the torque replay's motor can "
                             f"give (throttle {throttle[worst]:.2f})")
        throttles[f"throttle{side.capitalize()}"] = throttle
    return throttles


def _targets(data: RunData, signals: dict[str, tuple[str, float]], segments: Sequence[Segment],
             stride: int, from_data: bool = True) -> dict[str, tuple]:
    """The comparison targets of a run: measured column -> (times s from the run's start, values,
    FMU output, sigma, lag s), every ``stride``-th sample after SETTLING_TIME, leaving out
    SEGMENT_SETTLE s after each restart of a segmented replay; a position column becomes its
    increments over POSITION_LAG.  sigma is the compared quantity's sensor noise, stated in the
    manifest or estimated from the run, never below the signal's nominal scale
    (sensor_noise.residual_scale); the nominal scale alone unless ``from_data``."""
    targets = {}
    for column, (output, nominal) in signals.items():
        if not data.has(column):
            continue
        ts, vs = data.samples(column)
        ts = ts - data.time[0]
        lag = POSITION_LAG if column in INCREMENT_SIGNALS else 0.0
        sigma = (residual_scale(ts, vs, nominal, increment=lag > 0, stated=data.stated_noise.get(column))
                 if from_data else nominal)
        if lag > 0:
            vs = vs - np.interp(ts - lag, ts, vs)
        keep = ts >= max(SETTLING_TIME, lag + ts[0])
        for seg in segments[1:]:
            keep &= ~((ts >= seg.start) & (ts < seg.start + SEGMENT_SETTLE))
        targets[column] = (ts[keep][::stride], vs[keep][::stride], output, sigma, lag)
    return targets


def run_residuals(fmu: JunoFMU, prepared: PreparedRun, soil: dict[str, float],
                  extra: dict[str, object] | None = None, output_interval: float = 0.05) -> np.ndarray:
    """Scaled residuals (measured - simulated) / sigma of one prepared run, all signals
    concatenated.  A failed simulation raises SimulationError naming the run and its file."""
    outputs = sorted({target[2] for target in prepared.targets.values()})
    params = {**prepared.params, **soil, **(extra or {})}
    pieces = prepared.segments or [Segment(0.0, prepared.duration, {})]
    try:
        sims = [fmu.simulate({**params, **seg.init}, prepared.inputs, seg.stop, output_interval, outputs=outputs,
                             start_time=seg.start) for seg in pieces]
    except SimulationError as exc:
        raise exc.located(prepared.run_id, prepared.file) from exc
    parts = []
    for column, (ts, vs, out, sigma, lag) in prepared.targets.items():
        model = np.empty(len(ts))
        for i, (seg, sim) in enumerate(zip(pieces, sims)):
            last = i == len(pieces) - 1
            inside = (ts >= seg.start) & ((ts < seg.stop) | last)
            model[inside] = np.interp(ts[inside], sim["time"], sim[out])
            if lag > 0:     # within the same piece: SEGMENT_SETTLE >= lag
                model[inside] -= np.interp(ts[inside] - lag, sim["time"], sim[out])
        parts.append((vs - model) / sigma)
    return np.concatenate(parts)
