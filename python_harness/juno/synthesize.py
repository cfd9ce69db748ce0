"""Synthetic measured campaigns like the paper's, with an optional hidden effect.

A campaign has three drawbar pull runs (about 22, 35 and 32 s, steady
windows 8-18, 15-25 and 15-25 s) and one run over about 20 m^2 of soft soil
with a 0.5 m mound.  The truth is simulated with the JunoRover FMU at a
constant throttle (``drive.mode = 2``, DC motors), the drawbar force held by
hand (it ramps up and wanders), and then measured the way the paper's
instruments measure it:

=================  ======  ==========================================
sensor             rate    noise (1 sigma, at ``noise = 1``)
=================  ======  ==========================================
load cell          100 Hz  4 N
motor current      50 Hz   1.5 N m + 1 % (torque per side)
motor encoders     50 Hz   0.005 rad/s
total station      5 Hz    2 mm horizontal, 3 mm vertical
IMU attitude       100 Hz  0.003 rad roll/pitch, 0.005 rad yaw
LIDAR scan         1202/m2 5 mm vertical, random scattered points
=================  ======  ==========================================

The total station's prism sits at the chassis reference point (the FMU's
``x, y, z``).  The truth (parameters and hidden effect) goes to
``truth.json`` only; file names, columns and order never depend on it.

That is the ``default`` design; ``design="alt"`` (:mod:`juno.synthetic_design`) lays a campaign
out differently (four drawbar runs at another throttle, a ridge, other instruments and clocks,
columns in another order), so that the diagnosis can be tested on data it was not shaped on.
"""

from __future__ import annotations

import json
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from .campaign import write_campaign
from .outputs import check_campaign_dir
from .pointcloud import Grid, write_esri_ascii
from .simulator import WHEELS, InputSignals, JunoFMU, SimulationError, default_fmu_path
from .synthetic_design import DESIGNS, Design, Surface, Sensor, battery_voltage, design_named, mound_surface

#: The paper's Table 2 values, the centre of the synthetic truth.
TABLE2 = {"soil.kh": 1.58e5, "soil.eta": 0.501, "soil.gamma": 0.0813, "soil.Kvx": 0.819}

#: Drawbar runs: (id, duration s, steady window s), as in the paper.
DRAWBAR_RUNS = DESIGNS["default"].drawbar_runs

#: Terrain area (m): x from 0 to 8, y from -1.3 to 1.3 (20.8 m^2), scanned at SCAN_DENSITY.  The
#: scan reaches farther in x where the terrain run's rover went farther (scan_extent): a survey
#: covers the ground the rover drove on.
TERRAIN_X = (0.0, 8.0)
TERRAIN_Y = (-1.3, 1.3)
#: LIDAR points per square metre (25000 over the 20.8 m^2 test area).
SCAN_DENSITY = DESIGNS["default"].scan_density
#: How far the true terrain (truth_grid) reaches in x (m): beyond any terrain run's reach, the
#: rover started at 0.8 m driving at the motors' no-load speed at THROTTLE (0.50 m/s) for 30 s.
TRUTH_X_END = 17.0
TERRAIN_DURATION = DESIGNS["default"].terrain_duration
THROTTLE = DESIGNS["default"].throttle[0]

#: Drawbar loads (N, each +-40 N drawn) of the three runs in a random order, at THROTTLE.
HELD_LOADS = DESIGNS["default"].held_loads

#: ``heavy_run=True`` (``juno synthesize --heavy-run``): two runs at these loads at THROTTLE
#: and a heavy one, in a random order.  In the heavy run the person pulls until the rover
#: settles at about HEAVY_SLIP (as the paper's operator "forced the rover to settle at a
#: constant slip"), at HEAVY_THROTTLE so that the motors do not stall first.  It is what tells a
#: larger traction limit F_taumax (a grouser's thrust) from a softer shear law (a lower K_vx):
#: below a slip of about 0.5 the two bend the tanh law nearly alike.  It targets a slip rather
#: than a force because at a fixed 1150 N a soil 10 % weaker settled at 0.93 slip, where a
#: spin-following replay at the true parameters missed the torque by 200 sigma (a multi-pass
#: campaign).  Measured: grouser found in 7 of 8 campaigns with a heavy run, multi-pass
#: in 1 of 4, so it is not the default.
HEAVY_DESIGN_LOADS = (320.0, 620.0)
HEAVY_SLIP = 0.7
HEAVY_THROTTLE = 0.8
#: Fixed integration step of the truth's runs and of steady_slip (s; ``solver.tolerance`` 0):
#: pinned, not the FMU's default, so that a campaign and a predicted steady slip are the same
#: whatever default an FMU build has.
TRUTH_STEP = {"solver.step": 1e-3, "solver.tolerance": 0.0}


@dataclass
class Truth:
    """What the synthetic world really is (written to truth.json only)."""

    effects: tuple[tuple[str, float], ...]   # (effect id, strength), in the order given
    seed: int
    soil: dict[str, float]
    extension: dict[str, float] = field(default_factory=dict)   # FMU parameters the extended model needs
    sim: dict[str, float] = field(default_factory=dict)         # FMU parameters of the truth simulation
    distortion: dict[str, float] = field(default_factory=dict)  # what the instruments get wrong (effects.py)


def _ou_process(rng: np.random.Generator, t: np.ndarray, tau: float) -> np.ndarray:
    """Unit-variance Ornstein-Uhlenbeck noise sampled at times ``t`` (s) with time constant ``tau``."""
    x = np.empty_like(t)
    x[0] = rng.standard_normal()
    for k in range(1, len(t)):
        a = np.exp(-(t[k] - t[k - 1]) / tau)
        x[k] = a * x[k - 1] + np.sqrt(1 - a * a) * rng.standard_normal()
    return x


def hand_drawbar_force(rng: np.random.Generator, duration: float, level: float) -> InputSignals:
    """Drawbar force (N) of a person holding a rope: a 3-6 s ramp to ``level``, then +-6 % wander."""
    t = np.arange(0.0, duration + 0.05, 0.05)
    ramp = float(rng.uniform(3.0, 6.0))
    s = np.clip(t / ramp, 0, 1)
    smooth = s * s * (3 - 2 * s)
    force = level * smooth * (1 + 0.06 * _ou_process(rng, t, 1.5))
    return InputSignals(t, {"drawbarForce": np.maximum(force, 0.0)})


def steady_slip(fmu: JunoFMU, params: dict[str, object], load: float, throttle: float) -> float:
    """Mean slip of the four wheels over the last 6 s of a 16 s run on flat ground at a constant
    ``throttle`` (0-1), with a drawbar ``load`` (N) ramped in over the first 4 s; 1 if the load
    stops the rover or drags it backwards, or the wheels dig in until the run fails while
    stepping.  A run that fails before its first step (parameters refused, no initial
    equilibrium) is not a stall: its SimulationError is raised.  At TRUTH_STEP unless ``params``
    sets the step."""
    params = {**TRUTH_STEP, **params}
    t = np.arange(0.0, 16.0 + 1e-9, 0.05)     # inputs are held between samples: a fine staircase
    inputs = InputSignals(t, {"drawbarForce": load * np.clip(t / 4.0, 0.0, 1.0),
                              "throttleLeft": np.full(len(t), throttle), "throttleRight": np.full(len(t), throttle)})
    wheels = tuple(f"wheel{w}.slip" for w in WHEELS)
    try:
        sim = fmu.simulate(params, inputs, 16.0, 0.05, outputs=wheels + ("vx",))
    except SimulationError as exc:
        if not exc.what.startswith("simulation stopped"):   # refused or not initialised: no stall
            raise
        return 1.0
    last = sim["time"] > 10.0
    if np.min(sim["vx"][last]) <= 0.0:
        return 1.0
    return float(np.mean([np.mean(sim[w][last]) for w in wheels]))


def load_for_slip(fmu: JunoFMU, params: dict[str, object], slip: float, throttle: float,
                  low: float = 200.0, high: float = 2200.0, iterations: int = 9) -> float:
    """The drawbar load (N) at which the rover settles at ``slip`` (steady_slip), by bisection
    between ``low`` and ``high`` (to within (high - low) / 2^iterations, 4 N by default): what an
    operator holding the rover at a slip ends up pulling."""
    for _ in range(iterations):
        mid = 0.5 * (low + high)
        if steady_slip(fmu, params, mid, throttle) < slip:
            low = mid
        else:
            high = mid
    return 0.5 * (low + high)


def truth_grid(seed: int, cell: float = 0.02, surface: Surface = mound_surface) -> Grid:
    """The true terrain (``surface``, the design's) as a fine grid: the test area with a 1 m
    margin, to TRUTH_X_END in x."""
    xs = np.arange(TERRAIN_X[0] - 1.0, TRUTH_X_END + cell / 2, cell)
    ys = np.arange(TERRAIN_Y[0] - 1.0, TERRAIN_Y[1] + 1.0 + cell / 2, cell)
    X, Y = np.meshgrid(xs, ys)
    return Grid(x0=float(xs[0]), y0=float(ys[0]), cell=cell, z=surface(X, Y, seed))


def scan_extent(path_x: np.ndarray, path_y: np.ndarray) -> tuple[tuple[float, float], tuple[float, float]]:
    """The scanned rectangle (x range, y range), m: the test area, grown where needed to hold
    the rover's whole footprint (wheel centres plus a wheel radius ahead and behind, half a wheel
    width aside) along the path of chassis positions ``path_x``, ``path_y``."""
    from .rover_model import rover
    geometry = rover()
    ahead = geometry.wheelbase / 2 + geometry.wheel_radius
    aside = geometry.track / 2 + geometry.wheel_width / 2
    x_range = (min(TERRAIN_X[0], float(np.min(path_x)) - ahead), max(TERRAIN_X[1], float(np.max(path_x)) + ahead))
    y_range = (min(TERRAIN_Y[0], float(np.min(path_y)) - aside), max(TERRAIN_Y[1], float(np.max(path_y)) + aside))
    return x_range, y_range


def lidar_scan(rng: np.random.Generator, seed: int, noise: float = 1.0,
               transform: Callable[[np.ndarray], np.ndarray] | None = None,
               extent: tuple[tuple[float, float], tuple[float, float]] = (TERRAIN_X, TERRAIN_Y),
               design: Design = DESIGNS["default"]) -> np.ndarray:
    """Scattered LIDAR points (N, 3) over ``extent`` (x range, y range; default the test area) at
    the design's density and vertical noise (SCAN_DENSITY and 5 mm by default, at ``noise = 1``).

    ``transform`` maps true points to where the scan reports them (registration errors).
    """
    (x0, x1), (y0, y1) = extent
    n_points = int(round(design.scan_density * (x1 - x0) * (y1 - y0)))
    x = rng.uniform(x0, x1, n_points)
    y = rng.uniform(y0, y1, n_points)
    z = design.surface(x, y, seed) + noise * design.scan_sigma * rng.standard_normal(n_points)
    pts = np.column_stack([x, y, z])
    return transform(pts) if transform is not None else pts


def measure(rng: np.random.Generator, sim: dict[str, np.ndarray], kind: str, noise: float,
            design: Design = DESIGNS["default"], distortion: dict[str, float] | None = None,
            clock_start: float = 0.0) -> dict[str, np.ndarray]:
    """Turns a truth simulation into the columns of a run CSV (the campaign format of
    juno.campaign: a ``time`` column and one column per sensor, in the design's order).

    Each sensor samples on its own clock; the CSV rows are the union of all
    sample times with empty cells (NaN) where a sensor has no sample.  ``distortion``
    (:func:`juno.effects.apply_effects_to_truth`) holds what the instruments get wrong:
    ``imu.pitchBias`` (rad) is added to every pitch sample; ``clock.offset`` (s) is how far the
    IMU and total-station clocks run ahead of the motor clock (their sample stamped t was taken
    at motor time t - offset).  ``clock_start`` (s) is the run clock's reading at the start.
    """
    distortion = distortion or {}
    t_end = float(sim["time"][-1])
    T = sim["time"]
    streams: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    lag = {"imu": distortion.get("clock.offset", 0.0), "station": distortion.get("clock.offset", 0.0)}

    def add(sensor: Sensor) -> None:
        t = np.round(np.arange(sensor.offset, t_end + 1e-9, 1.0 / sensor.rate), 6)
        shift = lag.get(sensor.clock, 0.0)
        v = np.interp(t - shift if shift else t, T, sim[sensor.source])
        sigma = sensor.sigma + sensor.relative * np.abs(v) if sensor.relative else sensor.sigma
        measured = v + noise * sigma * rng.standard_normal(len(t))
        if sensor.column == "pitch" and "imu.pitchBias" in distortion:
            measured = measured + distortion["imu.pitchBias"]
        streams[sensor.column] = (t, measured)

    for sensor in design.sensors:
        if kind == "drawbar" or not sensor.drawbar_only:
            add(sensor)
    if design.extra_columns:
        t = np.round(np.arange(0.0, t_end + 1e-9, 0.5), 6)
        streams["battery_voltage"] = (t, battery_voltage(rng, t, np.interp(t, T, sim["torqueLeftApplied"]),
                                                         np.interp(t, T, sim["torqueRightApplied"]), noise))

    times = np.unique(np.concatenate([t for t, _ in streams.values()]))
    columns = {"time": np.round(times + clock_start, 6) if clock_start else times}
    for name, (t, v) in streams.items():
        col = np.full(len(times), np.nan)
        col[np.searchsorted(times, t)] = v
        columns[name] = col
    return columns


TRUTH_OUTPUTS = ("x", "y", "z", "roll", "pitch", "yaw", "vx", "omegaLeft", "omegaRight",
                 "torqueLeftApplied", "torqueRightApplied")


def effect_list(effect: str | Sequence[str], strength: float | Sequence[float]) -> tuple[tuple[str, float], ...]:
    """Pairs effect ids with strengths: one strength applies to every effect, otherwise one each."""
    effects = [effect] if isinstance(effect, str) else list(effect)
    strengths = [float(strength)] if isinstance(strength, (int, float)) else [float(s) for s in strength]
    if not effects:
        raise ValueError("no effect given (use 'none' to hide nothing)")
    if len(strengths) == 1:
        strengths = strengths * len(effects)
    if len(strengths) != len(effects):
        raise ValueError(f"{len(effects)} effects but {len(strengths)} strengths: give one strength, "
                         "or one per effect")
    return tuple(zip(effects, strengths))


def draw_truth(effect: str | Sequence[str], strength: float | Sequence[float], seed: int) -> Truth:
    """The synthetic world: soil within +-10 % of Table 2 (drawn from ``seed``) and the effects."""
    rng = np.random.default_rng([seed, 1])
    soil = {k: float(v * rng.uniform(0.9, 1.1)) for k, v in TABLE2.items()}
    truth = Truth(effects=effect_list(effect, strength), seed=int(seed), soil=soil)
    from .effects import apply_effects_to_truth
    apply_effects_to_truth(truth, rng)
    return truth


def synthesize(out: str | Path, effect: str | Sequence[str] = "none", strength: float | Sequence[float] = 1.0,
               seed: int = 0,
               noise: float = 1.0, fmu: JunoFMU | None = None, time_scale: float = 1.0,
               overwrite: bool = False, progress: Callable[[str], None] | None = None,
               heavy_run: bool = False, design: str = "default") -> Path:
    """Writes a synthetic measured campaign to ``out`` and returns its path.

    ``noise`` scales every sensor's noise (0 = exact measurements).
    ``time_scale`` < 1 shortens every run (for quick tests); windows scale too.
    ``heavy_run`` makes one drawbar run a heavy one, held at a slip of about HEAVY_SLIP
    (default design only).  ``design`` names the campaign's layout
    (:data:`juno.synthetic_design.DESIGNS`: ``default``, the paper's, or ``alt``).
    The folder is written whole or not at all; ``truth.json`` holds the truth.
    ``overwrite`` replaces an existing ``out`` only when it holds exactly what this function
    writes (:func:`juno.outputs.is_synthesized_campaign`); any other non-empty folder is refused
    (:class:`juno.outputs.OutputError`) before anything is simulated.
    """
    from .effects import effect_record, scan_transform
    say = progress or (lambda msg: None)
    out_path = Path(out)
    plan = design_named(design)
    if heavy_run and plan.name != "default":
        raise ValueError(f"--heavy-run is a variant of the default design, not of design '{plan.name}'")
    # Before anything is simulated: OUT must be new, empty, or (with overwrite) a campaign this
    # function wrote; a folder holding anything else is never replaced.
    check_campaign_dir(out_path, [fmu.fmu_path if fmu is not None else default_fmu_path()], "OUT", overwrite)
    truth = draw_truth(effect, strength, seed)   # validates the effects before anything is written
    rng = np.random.default_rng([seed, 2])
    # The layout's own draws (throttle, clocks) come from a stream of their own, so that the
    # truth and the noise streams do not depend on the design's choices.
    layout_rng = np.random.default_rng([seed, 3])
    n_drawbar = len(plan.drawbar_runs)
    throttle = plan.throttle[0] if plan.throttle[0] == plan.throttle[1] else \
        round(float(layout_rng.uniform(*plan.throttle)), 3)
    clock_starts = ([round(float(c), 3) for c in layout_rng.uniform(*plan.clock_start, n_drawbar + 1)]
                    if plan.clock_start else [0.0] * (n_drawbar + 1))
    own_fmu = fmu is None
    fmu = fmu or JunoFMU()
    try:
        base = {**truth.soil, **truth.sim, "drive.mode": 2, **TRUTH_STEP}
        runs, manifest_runs = {}, []
        if heavy_run:
            heavy = load_for_slip(fmu, base, HEAVY_SLIP, HEAVY_THROTTLE)
            order = rng.permutation(3)
            levels = np.array([(*HEAVY_DESIGN_LOADS, heavy)[i] for i in order]) + rng.uniform(-40, 40, 3)
            throttles = [(THROTTLE, THROTTLE, HEAVY_THROTTLE)[i] for i in order]
        else:
            levels = rng.permutation(list(plan.held_loads)) + rng.uniform(-plan.load_jitter, plan.load_jitter,
                                                                          n_drawbar)
            throttles = [throttle] * n_drawbar
        for (run_id, duration, window), level, run_throttle, t0 in zip(plan.drawbar_runs, levels, throttles,
                                                                       clock_starts):
            duration *= time_scale
            window = (window[0] * time_scale, window[1] * time_scale)
            if t0:
                window = (window[0] + t0, window[1] + t0)
            say(f"simulating drawbar run {run_id} ({duration:.0f} s)")
            drawbar = hand_drawbar_force(rng, duration, float(level))
            inputs = InputSignals(drawbar.time, {**drawbar.values,
                                                 "throttleLeft": np.full(len(drawbar.time), run_throttle),
                                                 "throttleRight": np.full(len(drawbar.time), run_throttle)})
            sim = fmu.simulate(base, inputs, duration, 0.01, outputs=TRUTH_OUTPUTS)
            sim["drawbarForce"] = np.interp(sim["time"], drawbar.time, drawbar.values["drawbarForce"])
            runs[run_id] = measure(rng, sim, "drawbar", noise, plan, truth.distortion, t0)
            manifest_runs.append({"id": run_id, "kind": "drawbar", "file": f"runs/{run_id}.csv",
                                  "steady_window": list(window)})

        say("simulating the 3-D terrain run")
        with tempfile.TemporaryDirectory(prefix="juno-truth-") as tmp:
            grid_path = Path(tmp) / "truth.asc"
            write_esri_ascii(grid_path, truth_grid(seed, surface=plan.surface))
            params = {**base, "terrain.file": str(grid_path), "init.x": plan.terrain_start[0],
                      "init.y": plan.terrain_start[1]}
            inputs = InputSignals.constant(drawbarForce=0.0, throttleLeft=throttle, throttleRight=throttle)
            duration = plan.terrain_duration * time_scale
            sim = fmu.simulate(params, inputs, duration, 0.01, outputs=TRUTH_OUTPUTS)
        runs["t3d"] = measure(rng, sim, "terrain", noise, plan, truth.distortion, clock_starts[-1])
        manifest_runs.append({"id": "t3d", "kind": "terrain", "file": "runs/t3d.csv",
                              "terrain": "terrain/scan.xyz"})
        scan = lidar_scan(rng, seed, noise=noise, transform=scan_transform(truth),
                          extent=scan_extent(sim["x"], sim["y"]), design=plan)

        # The name must not reveal the seed (the seed regenerates the truth).
        manifest = {"name": "juno-synthetic-campaign", "runs": manifest_runs, "rover": {}}
        names = [e for e, _ in truth.effects]
        record = {"effect": "+".join(names), "strength": truth.effects[0][1],
                  "effects": [effect_record(e, s) for e, s in truth.effects],
                  "seed": truth.seed, "noise": noise, "soil": truth.soil,
                  "extension": truth.extension}
        # Keys beyond the catalog's exact forms and the default design only when they say something,
        # so that a default campaign's truth.json stays as it always was.
        if truth.distortion or any(not r.get("exact_form", True) for r in record["effects"]):
            record["hidden"] = {"sim": truth.sim, "distortion": truth.distortion}
        if plan.name != "default":
            record["design"] = {"name": plan.name, "throttle": throttle,
                                "clock_starts": dict(zip([r[0] for r in plan.drawbar_runs] + ["t3d"], clock_starts))}
        truth_json = json.dumps(record, indent=2)
        say(f"writing {out}")
        write_campaign(out, manifest, runs, {"terrain/scan.xyz": scan},
                       extra_files={"truth.json": truth_json}, overwrite=overwrite)
        return Path(out)
    finally:
        if own_fmu:
            fmu.close()
