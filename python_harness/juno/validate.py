"""Validation on 3-D terrain (the paper's Figures 12-14).

The LIDAR scan of a terrain run is gridded (ESRI ASCII, resolution stated),
the rover is simulated on it with the identified soil parameters while a
PID on the drive torque makes it follow the measured wheel spins
(``drive.mode = 1``), and position, forward speed, wheel spins and drive
torques are compared with the measurements.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from .campaign import Campaign, RunData, RunSpec, forward_speed, read_run, read_terrain_points
from .heading import start_heading
from .identify import SPIN_TRACKER, base_parameters
from .pointcloud import GRID_MARGIN, Grid, grid_from_points, gross_outliers, write_esri_ascii
from .sensor_noise import sensor_noise
from .simulator import InputSignals, JunoFMU, SimulationError

#: Default terrain grid resolution (m).
#: Measured on the synthetic campaign (5 mm point noise, ~1200 points per m^2): at 5 cm cells
#: the gridded slope is noisy (0.07 rad RMS), and on the terrain run the drive-torque residual
#: with the true soil and registration stayed at 3x the sensor noise; at 10 cm it is at 1.3x,
#: and the 0.5 m mound and 2-6 m undulations are resolved the same.
GRID_CELL = 0.10
#: Seconds at the start of a run left out of the RMS errors (PID settling).
SETTLING = 1.0
#: Integration step of the replay: fixed 1 ms (``solver.tolerance`` 0), not the FMU's automatic
#: default.  The replay's stiff PID (identify.SPIN_TRACKER) follows measured spins whose reference
#: changes every 10 ms; there the automatic step is 1.3 times slower than a fixed 1 ms step and
#: less accurate (docs/fmu.md, "The solver step").
VALIDATE_STEP = {"solver.step": 1e-3, "solver.tolerance": 0.0}


def grid_terrain(campaign: Campaign, run: RunSpec, out_dir: str | Path, cell: float = GRID_CELL,
                 say: Callable[[str], None] | None = None) -> tuple[Path, Grid]:
    """Grids the run's LIDAR scan into ``out_dir/<terrain>.asc``; returns the path and the grid.

    The scan's gross outliers (:func:`juno.pointcloud.gross_outliers`: a point a kilometre
    away would stretch the grid, a spike would raise a bump) are dropped first; ``say`` is told
    how many. The commands report them, and check that the path lies on the scan, before any
    computation (:func:`juno.plausibility.check_scan`).
    """
    points = read_terrain_points(campaign, run)
    bad = gross_outliers(points)
    if bad.any():
        points = points[~bad]
        if say is not None:
            say(f"{run.terrain}: dropped {int(bad.sum())} gross outlier(s) of the scan before gridding")
    grid = grid_from_points(points, cell=cell, margin=GRID_MARGIN)
    path = Path(out_dir) / (Path(run.terrain).stem + f"_{int(round(cell * 1000))}mm.asc")
    write_esri_ascii(path, grid)
    return path, grid


@dataclass
class ValidationResult:
    """Measured and simulated signals of one terrain run and their RMS errors (SI units)."""

    run_id: str
    grid_file: str
    grid_cell: float
    time: np.ndarray
    measured: dict[str, np.ndarray]
    simulated: dict[str, np.ndarray]
    rms: dict[str, float] = field(default_factory=dict)
    #: Each measured column's sensor noise (1 sigma, SI units), stated in the campaign's manifest or
    #: estimated from the column itself (:func:`juno.sensor_noise.sensor_noise`); NaN for a
    #: derived signal (speed).  An RMS
    #: error near it is agreement to within the sensor's noise; many times it is model error.
    noise: dict[str, float] = field(default_factory=dict)

    def noise_ratio(self, name: str) -> float:
        """The RMS error of ``name`` in units of its sensor noise (NaN where not estimated)."""
        noise = self.noise.get(name, float("nan"))
        return self.rms[name] / noise if noise > 0 else float("nan")


#: signal -> (measured column or derived, FMU output)
COMPARED = {
    "pos_x": "x", "pos_y": "y", "pos_z": "z", "speed": "vx",
    "omega_left": "omegaLeft", "omega_right": "omegaRight",
    "torque_left": "torqueLeftApplied", "torque_right": "torqueRightApplied",
}


def simulate_terrain_run(fmu: JunoFMU, campaign: Campaign, run: RunSpec, soil: dict[str, float],
                         grid_file: str | Path, extra: dict[str, object] | None = None,
                         output_interval: float = 0.02) -> dict[str, np.ndarray]:
    """Simulates a terrain run following the measured wheel spins on ``grid_file``.  Raises
    SimulationError naming the run, its file, the simulation time and the FMU's message when
    the replay fails."""
    data = read_run(campaign, run)
    t = data.time
    grid_t = np.arange(t[0], t[-1] + 1e-9, 0.01)
    inputs = InputSignals(grid_t - t[0], {
        "drawbarForce": np.zeros(len(grid_t)),
        "omegaRefLeft": np.interp(grid_t, *data.samples("omega_left")),
        "omegaRefRight": np.interp(grid_t, *data.samples("omega_right")),
    })
    params = {**base_parameters(campaign), **soil, **SPIN_TRACKER, **VALIDATE_STEP, "drive.mode": 1,
              "terrain.file": str(grid_file),
              "init.x": float(data.samples("pos_x")[1][0]), "init.y": float(data.samples("pos_y")[1][0]),
              "init.yaw": start_heading(data, run.id).value}
    params.update(extra or {})
    try:
        return fmu.simulate(params, inputs, float(t[-1] - t[0]), output_interval,
                            outputs=tuple(COMPARED.values()) + ("pitch", "roll", "yaw"))
    except SimulationError as exc:    # a failed replay is an error naming the run, never a result
        raise exc.located(run.id, run.file) from exc


def _sampled_span(data: RunData, columns: tuple[str, ...], times: np.ndarray) -> np.ndarray:
    """True at the ``times`` (s, on the run's clock) that lie between the first and the last
    sample of every one of ``columns``."""
    inside = np.ones(len(times), dtype=bool)
    for name in columns:
        ts, _ = data.samples(name)
        inside &= (times >= ts[0]) & (times <= ts[-1])
    return inside


def validate_run(fmu: JunoFMU, campaign: Campaign, run: RunSpec | str, soil: dict[str, float],
                 out_dir: str | Path, cell: float = GRID_CELL, extra: dict[str, object] | None = None,
                 grid_file: str | Path | None = None) -> ValidationResult:
    """Grids the scan (unless ``grid_file`` is given), simulates and compares; see module docstring."""
    run = campaign.run(run) if isinstance(run, str) else run
    if grid_file is None:
        grid_file, _ = grid_terrain(campaign, run, out_dir, cell)
    sim = simulate_terrain_run(fmu, campaign, run, soil, grid_file, extra)
    data = read_run(campaign, run)
    t0 = float(data.time[0])
    times = np.arange(0.0, float(data.time[-1] - t0) + 1e-9, 0.1)
    measured, simulated, rms, noise = {}, {}, {}, {}
    for name, output in COMPARED.items():
        if name == "speed":
            m = forward_speed(data, times + t0)
            noise[name] = float("nan")
            measured_at = _sampled_span(data, ("pos_x", "pos_y"), times + t0)
        else:
            ts, vs = data.samples(name)
            m = np.interp(times, ts - t0, vs)
            noise[name] = sensor_noise(data, name)
            measured_at = _sampled_span(data, (name,), times + t0)
        # A sensor that starts late or stops early has measured nothing beyond its own samples:
        # there the interpolation would only hold its end value, which is no measurement.
        m = np.where(measured_at, m, np.nan)
        s = np.interp(times, sim["time"], sim[output])
        measured[name], simulated[name] = m, s
        # The first SETTLING s are the PID catching the measured spins (the paper's settling
        # phase): plotted, but not in the RMS.
        compared = (times >= SETTLING) & measured_at
        rms[name] = float(np.sqrt(np.mean((m[compared] - s[compared]) ** 2))) if compared.any() else float("nan")
    return ValidationResult(run.id, str(grid_file), cell, times, measured, simulated, rms, noise)
