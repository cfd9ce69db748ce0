"""What a fitted model's held-out residuals still contain beyond sensor noise.

The diagnosis names a cause from a catalog of model extensions.  A discrepancy that no
extension explains (a sensor bias, a dragging brake, a clock offset) must not be reported as
"none", and must not be given the name of a catalog cause that only absorbs part of it.  This
module answers the question the catalog cannot: *is there still structure in the residuals,
how large is it, and what does it follow?*

Method (docs/diagnosis.md, "What no candidate explains"):

1. **Units.** The held-out 4 s blocks of every drawbar run; in each, the mean residual of each
   compared signal.  A model that is right leaves block means that are sensor noise averaged
   over the block, plus the noise the replay picks up from the measured inputs it is driven by
   (the wheel spins and drawbar force are measured too, and the rover's path integrates their
   noise).
2. **Noise from the data.** Each measured column's sensor noise (1 sigma) is estimated from the
   column itself, by the median absolute second difference of its samples (a smooth signal's
   second differences are near zero at the sensor rates; white noise's have variance
   6 sigma^2).  No scale is assumed; where the campaign's manifest states a column's noise
   (a filtered column's, which the second differences underestimate), that value is used
   (juno.sensor_noise.sensor_noise).
3. **The null distribution by simulation** (a parametric bootstrap): REPLICAS times, the
   measured inputs and the measured start pose the replay begins from get fresh white noise at
   their sigma (a start heading taken from the track, without a yaw column, at its own
   standard error: juno.heading) and the run is replayed with
   the same parameters; the measured outputs get fresh white noise, processed as the
   comparison processes them (position increments).  The replicas' block means give, for each
   run and signal, the variance a block mean has when the model is right: this covers the
   replay's own sensitivity to input noise, which no formula gives for every design.
4. **The test.** Per signal, T = sum over held-out blocks of (block mean)^2 / null variance; if
   the model is right, T / k over the null's mean square is F(k, d)-distributed (k blocks, d
   the replicas' degrees of freedom).  A signal has structure when its p-value is below
   FALSE_ALARM / (number of signals) (Bonferroni: at most FALSE_ALARM false reports per
   campaign) *and* the structure is material: its RMS beyond the null is at least a floor,
   a fraction of the signal's sensor noise calibrated on campaigns with nothing hidden (the
   replay leaves small structure the bootstrap does not reproduce): MATERIAL_FRACTION for the
   positions and height, which integrate the replay's drift, MATERIAL_FRACTION_CONTACT for the
   torques and the pitch, which do not; and never below what a right model leaves on exact
   measurements (REPLAY_FIDELITY, with a margin), which no sensor, however quiet, takes away.
5. **What it follows.** For a signal with structure, the block means are set against the
   covariates an engineer would look at: a constant offset, time in the run, position x and y,
   the drive torque, the wheel spin, the slip, the run, and for the paired left/right signals
   the side.  Each is reported with the share of the structure it accounts for.
6. **A ripple in the wheel angle.**  Block means average away a ripple at a few Hz (a lugged
   wheel's traction pulsing at N per revolution), so the held-out torque samples themselves are
   tested for a component periodic in each side's measured wheel angle
   (juno.periodic_structure; at most FALSE_ALARM false reports per campaign of its own).
7. **A clock offset.**  Block means also average away a residual that follows the signal's own
   rate of change, as an instrument's clock offset from the replay's inputs leaves it: the
   held-out samples of the positions are tested for it against the same replicas
   (juno.timing_structure; at most FALSE_ALARM false reports per campaign of its own).

Only drawbar runs are tested: over the 3-D terrain the replay drifts from the measured path
even at the true parameters (the terrain run's block means at the truth are many times the
sensor noise on synthetic campaigns), so residual structure there is not evidence of an
unknown cause.  Assumptions: sensor noise is white at the sample rate (correlated sensor noise
slower than a block shows as structure), and its level does not change within a run.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from .campaign import Campaign, RunData, read_run
from .heading import start_heading
from .identify import PreparedRun, run_residuals
from .periodic_structure import (PeriodicBases, PeriodicSignal, PeriodicStructure, periodic_structure,
                                 series_of_residuals)
from .rover_model import SOIL_PARAMETERS
from .sensor_noise import sensor_noise
from .timing_structure import SignalOffset, TimingStructure, regressors, timing_structure
from .parallel import FMUHandle, TaskPool, map_tasks, resolve_workers
from .simulator import JunoFMU, SimulationError

#: At most this many false "structure" reports per campaign (Bonferroni over the signals).
FALSE_ALARM = 0.01
#: A structure smaller than this fraction of the sensor noise (RMS of the block means beyond the
#: null, over the per-sample sigma) in a signal of the replayed path (positions and height) is
#: not attributed to any cause.  Calibrated by simulation (scripts/structure_calibration.py,
#: docs/results/structure-calibration.md): on campaigns with nothing hidden, of both synthetic
#: designs, the fitted right model leaves structure of up to about half the noise in the
#: positions (the replay's heading drifts a little from the measured one, and the path
#: integrates the drift) that the bootstrap's input noise does not reproduce; the floor, one
#: sensor sigma, lies above that.
MATERIAL_FRACTION = 1.0
#: The floor (fraction of the sensor noise, as MATERIAL_FRACTION) for the signals the replay does
#: not integrate along its path: the drive torques and the pitch, which follow the wheels'
#: contact where the rover is, not where its replayed heading has taken it.  The same
#: calibration finds a right model leaving at most 0.15 of the noise in them (0.10 in the
#: pitch), so the positions' floor would hide there what the test resolves: a drag of 9 N m on
#: one side, with the alternative design's torque sensor (5.5 N m of noise), leaves 0.75-0.78 of
#: it in each torque at p below 1e-150.  The floor lies over three times above the most a right
#: model left.
MATERIAL_FRACTION_CONTACT = 0.5
#: What a right model's replay leaves in each signal on exact measurements, in the signal's units
#: (pos_x, pos_y: m per increment over identify's POSITION_LAG): the largest structure RMS over
#: 48 noise-free campaigns of both designs, rounded up (scripts/structure_calibration.py
#: --noises 0, docs/results/structure-calibration.md).  It is the replay's own fidelity (its
#: spin-following drive against the truth's motors, the fit's tolerance), and does not shrink with
#: the sensors' noise: with instruments much quieter than the designs', a floor that is only a
#: fraction of the noise calls it a cause.  One value for both sides, and for both horizontal
#: positions (a campaign's runs may head along y).
REPLAY_FIDELITY = {"torque_left": 0.26, "torque_right": 0.26, "pitch": 1.5e-4,
                   "pos_x": 9.3e-4, "pos_y": 9.3e-4, "pos_z": 2.4e-4}
#: The floor lies this many times above REPLAY_FIDELITY, as MATERIAL_FRACTION lies about twice
#: above the most a right model leaves in the positions relative to their noise.
FIDELITY_MARGIN = 2.0
#: The signals MATERIAL_FRACTION_CONTACT applies to (the calibrated ones: the drawbar runs compare
#: no roll).
CONTACT_SIGNALS = ("torque_left", "torque_right", "pitch")
#: Bootstrap replicas of the null (each one replay of every drawbar run).
REPLICAS = 20
#: Which measured column feeds which replay input (the spin-following drawbar replay).
INPUT_COLUMNS = {"drawbar_force": "drawbarForce", "omega_left": "omegaRefLeft", "omega_right": "omegaRefRight"}
#: The replay starts at the first measured pose (identify.prepare_run): its noise is the replica's too.
START_POSE_COLUMNS = {"pos_x": "init.x", "pos_y": "init.y", "yaw": "init.yaw"}
#: A covariate "follows" the structure when it accounts for at least this share of it.
FOLLOWS_SHARE = 0.5
OUTPUT_INTERVAL = 0.05


def residual_labels(prepared: Sequence[PreparedRun], block: float) -> dict[str, np.ndarray]:
    """The labels of the residuals of ``prepared`` concatenated in run_residuals' order: for every
    compared sample its ``run``, ``signal``, ``time`` (s from the run's start) and ``block`` (the
    number of the ``block``-second interval it falls in)."""
    runs, signals, times = [], [], []
    for p in prepared:
        for column, (ts, *_rest) in p.targets.items():
            runs += [p.run_id] * len(ts)
            signals += [column] * len(ts)
            times.append(ts)
    t = np.concatenate(times) if times else np.zeros(0)
    return {"run": np.array(runs), "signal": np.array(signals), "time": t,
            "block": np.floor(t / block).astype(int)}


def material_fraction(signal: str) -> float:
    """The materiality floor of ``signal`` (fraction of its sensor noise): MATERIAL_FRACTION_CONTACT
    for the torques and the pitch, MATERIAL_FRACTION for the replayed path."""
    return MATERIAL_FRACTION_CONTACT if signal in CONTACT_SIGNALS else MATERIAL_FRACTION


def materiality_floor(signal: str, noise: float) -> float:
    """The smallest structure RMS (``signal``'s units) the test attributes to a cause, for a
    sensor noise (1 sigma of the compared quantity) of ``noise``: material_fraction(signal) of the
    noise, and never below FIDELITY_MARGIN times the replay's fidelity on exact measurements
    (REPLAY_FIDELITY): a quieter sensor does not make the replay more exact."""
    return max(material_fraction(signal) * noise, FIDELITY_MARGIN * REPLAY_FIDELITY.get(signal, 0.0))


def floor_is_fidelity(signal: str, noise: float) -> bool:
    """Whether ``signal``'s floor at ``noise`` is the replay's fidelity rather than the fraction of
    the noise."""
    return FIDELITY_MARGIN * REPLAY_FIDELITY.get(signal, 0.0) > material_fraction(signal) * noise


@dataclass
class Covariate:
    """How much of a signal's structure one covariate accounts for: ``share`` in [0, 1] (the
    squared correlation of the block means with it; for ``constant``, the mean's share of the
    mean square), ``slope`` in the signal's units per covariate unit (``constant``: the offset)."""

    name: str
    share: float
    slope: float
    unit: str


@dataclass
class SignalStructure:
    """The structure test of one compared signal over the held-out blocks of the drawbar runs."""

    signal: str
    unit: str
    blocks: int
    noise: float                  # sensor noise, 1 sigma, signal units (stated or estimated: sensor_noise)
    structure_rms: float          # RMS of the block means beyond the null, signal units
    ratio: float                  # structure_rms / noise
    p_value: float
    significant: bool             # p below the Bonferroni level and structure_rms >= floor
    follows: list[Covariate] = field(default_factory=list)
    #: p below the Bonferroni level, whatever the size: the test tells the block means from noise
    resolved: bool = False

    @property
    def floor(self) -> float:
        """The smallest structure RMS attributed to a cause (signal units): materiality_floor."""
        return materiality_floor(self.signal, self.noise)

    def to_json(self) -> dict[str, Any]:
        return {"signal": self.signal, "unit": self.unit, "blocks": self.blocks, "noise": self.noise,
                "structure_rms": self.structure_rms, "ratio_to_noise": self.ratio, "p_value": self.p_value,
                "significant": self.significant, "resolved": self.resolved,
                "floor": self.floor, "floor_fraction": material_fraction(self.signal),
                "floor_is_fidelity": floor_is_fidelity(self.signal, self.noise),
                "follows": [{"covariate": c.name, "share": c.share, "slope": c.slope, "unit": c.unit}
                            for c in self.follows]}

    def sentence(self) -> str:
        """The finding in words: its size, and the covariate it follows best with the slope."""
        return self._with_what_it_follows(f"{self.signal} {self.structure_rms:.3g} {self.unit} RMS "
                                          f"({self.ratio:.2g} x its sensor noise)")

    def brief(self) -> str:
        """The finding in a few words (a progress line)."""
        return f"{self.signal} ({self.ratio:.2g} x noise)"

    def below_floor_sentence(self) -> str:
        """A structure resolved below its floor, in words: its size beside the floor."""
        if floor_is_fidelity(self.signal, self.noise):
            floor = f"floor {self.floor:.3g} {self.unit}, the replay's own error"
        else:
            floor = f"floor {material_fraction(self.signal):g} x"
        return self._with_what_it_follows(f"{self.signal} {self.structure_rms:.3g} {self.unit} RMS ({self.ratio:.2g} x "
                                          f"its sensor noise, {floor}; p {self.p_value:.2g})")

    def _with_what_it_follows(self, text: str) -> str:
        """``text``, then the covariate the structure follows best, with the slope."""
        if not self.follows:
            return text
        c = self.follows[0]
        slope = f" {c.slope:+.3g} {c.unit}" if c.name != "run" else ""
        return f"{text}, following {c.name}{slope} ({c.share:.0%} of it)"


@dataclass
class ResidualStructure:
    """Every signal's structure test, the drive torques' test for a ripple in the wheel angle
    (``periodic``: juno.periodic_structure) and every signal's test for a time offset from the
    replay's inputs (``timing``: juno.timing_structure), on the same held-out samples;
    ``significant`` if any signal has structure, a ripple or an offset."""

    signals: list[SignalStructure]
    level: float                  # the per-signal p threshold (FALSE_ALARM / signals)
    replicas: int
    runs: list[str]
    periodic: PeriodicStructure | None = None
    timing: TimingStructure | None = None

    @property
    def significant(self) -> bool:
        return (any(s.significant for s in self.signals) or bool(self.periodic and self.periodic.significant)
                or bool(self.timing and self.timing.significant))

    @property
    def excess(self) -> float:
        """Sum over signals of (structure RMS / noise)^2, and of (ripple RMS / noise)^2 over the
        ripples found: the structure's size, noise units."""
        return float(sum(s.ratio ** 2 for s in self.signals)) + (self.periodic.excess if self.periodic else 0.0)

    @property
    def block_excess(self) -> float:
        """Sum over signals of (structure RMS / noise)^2 of the held-out block means alone: the size
        of the structure the catalog's candidates act on (they are fitted and judged block by block,
        and none models a ripple in the wheel angle)."""
        return float(sum(s.ratio ** 2 for s in self.signals))

    def offsets(self) -> list[SignalOffset]:
        """The signals time-stamped off the replay's inputs (juno.timing_structure), clearest first."""
        return self.timing.found() if self.timing else []

    def ripples(self) -> list[PeriodicSignal]:
        """The signals with a ripple in the wheel angle, largest (relative to their noise) first."""
        return self.periodic.found() if self.periodic else []

    def structured(self) -> list[SignalStructure]:
        """The signals with structure, largest (relative to their noise) first."""
        return sorted((s for s in self.signals if s.significant), key=lambda s: -s.ratio)

    def below_floors(self) -> list[SignalStructure]:
        """The signals whose block means the test tells from sensor noise (p below the level) but
        whose structure is smaller than its floor, the most a right model's replay may leave
        (material_fraction): not attributed to any cause, and not sensor noise either; largest
        (relative to their noise) first."""
        return sorted((s for s in self.signals if s.resolved and not s.significant), key=lambda s: -s.ratio)

    def findings(self, brief: bool = False) -> list[str]:
        """Every finding in words: the signals with structure, the ripples in the wheel angle and
        the time offsets, each as its ``sentence()`` (or ``brief()``); [] when nothing is found."""
        found = [*self.structured(), *self.ripples(), *self.offsets()]
        return [f.brief() if brief else f.sentence() for f in found]

    def contact_signals(self) -> list[str]:
        """The signals tested here that MATERIAL_FRACTION_CONTACT applies to (CONTACT_SIGNALS):
        the pitch only where the drawbar runs measure it."""
        tested = {s.signal for s in self.signals}
        return [s for s in CONTACT_SIGNALS if s in tested]

    def to_json(self) -> dict[str, Any]:
        return {"significant": self.significant, "false_alarm": FALSE_ALARM, "level": self.level,
                "material_fraction": MATERIAL_FRACTION, "material_fraction_contact": MATERIAL_FRACTION_CONTACT,
                "contact_signals": self.contact_signals(), "replicas": self.replicas, "runs": self.runs,
                "signals": [s.to_json() for s in self.signals],
                "periodic": self.periodic.to_json() if self.periodic else None,
                "timing": self.timing.to_json() if self.timing else None}


UNITS = {"torque_left": "N m", "torque_right": "N m", "pos_x": "m per 1 s", "pos_y": "m per 1 s",
         "pos_z": "m", "pitch": "rad", "roll": "rad", "drawbar_force": "N"}


def _noisy_inputs(rng: np.random.Generator, prepared: PreparedRun, data: RunData,
                  noise: Mapping[str, float]) -> PreparedRun:
    """A copy of ``prepared`` whose measured inputs carry fresh white noise at each column's
    estimated sigma, drawn at the column's own sample times and resampled as prepare_run does."""
    values = dict(prepared.inputs.values)
    t0 = data.time[0]
    for column, name in INPUT_COLUMNS.items():
        if name not in values or not data.has(column) or not np.isfinite(noise.get(column, np.nan)):
            continue
        ts, _ = data.samples(column)
        e = noise[column] * rng.standard_normal(len(ts))
        values[name] = values[name] + np.interp(prepared.inputs.time, ts - t0, e)
    inputs = type(prepared.inputs)(prepared.inputs.time, values)
    params = dict(prepared.params)
    for column, name in START_POSE_COLUMNS.items():
        if name in params and np.isfinite(noise.get(column, np.nan)):
            params[name] = float(params[name]) + noise[column] * rng.standard_normal()
    return PreparedRun(prepared.run_id, prepared.kind, prepared.duration, inputs, params,
                       prepared.targets, prepared.segments, prepared.file)


def _output_noise(rng: np.random.Generator, prepared: PreparedRun, data: RunData,
                  noise: Mapping[str, float]) -> np.ndarray:
    """Fresh sensor noise on the compared samples of ``prepared`` (scaled like its residuals):
    white at each column's sample times, then processed as the comparison processes the column
    (an increment over the lag for positions)."""
    parts = []
    t0 = data.time[0]
    for column, (ts, _vs, _out, sigma, lag) in prepared.targets.items():
        tc, _ = data.samples(column)
        tc = tc - t0
        n = noise[column] * rng.standard_normal(len(tc))
        if lag > 0:
            n = n - np.interp(tc - lag, tc, n)
        parts.append(np.interp(ts, tc, n) / sigma)
    return np.concatenate(parts) if parts else np.zeros(0)


def _block_means(values: np.ndarray, keys: np.ndarray) -> np.ndarray:
    """Mean of ``values`` per integer key (0..K-1)."""
    counts = np.bincount(keys)
    return np.bincount(keys, weights=values) / np.maximum(counts, 1)


@dataclass
class _Units:
    """The held-out blocks of the tested runs: where each residual belongs."""

    index: np.ndarray        # positions in the residual vector of the held-out drawbar samples
    key: np.ndarray          # their block unit (0..K-1)
    unit_run: np.ndarray     # per unit: run id
    unit_signal: np.ndarray  # per unit: signal
    unit_block: np.ndarray   # per unit: block number
    unit_time: np.ndarray    # per unit: mid time of the block's samples, s from the run's start


def _units(meta: Mapping[str, np.ndarray], train: np.ndarray, runs: Sequence[str]) -> _Units:
    held_out = ~train & np.isin(meta["run"], list(runs))
    index = np.flatnonzero(held_out)
    labels = np.char.add(np.char.add(meta["run"][index].astype(str), "|"),
                         np.char.add(meta["signal"][index].astype(str), "|" ))
    labels = np.char.add(labels, meta["block"][index].astype(str))
    uniq, first, key = np.unique(labels, return_index=True, return_inverse=True)
    mid = _block_means(meta["time"][index], key)
    return _Units(index, key, meta["run"][index][first], meta["signal"][index][first],
                  meta["block"][index][first], mid)


def _covariate_values(campaign: Campaign, units: _Units, data: Mapping[str, RunData],
                      wheel_radius: float) -> dict[str, tuple[np.ndarray, str]]:
    """Per held-out unit, the covariates an engineer looks at: time in the run, measured
    position x and y, drive torque (mean of both sides), wheel spin (mean of both sides) and
    slip (1 - speed / (spin R)), each averaged over the unit's block."""
    from .campaign import forward_speed
    cov: dict[str, list[float]] = {k: [] for k in ("time", "x", "y", "torque", "spin", "slip")}
    for run, t_mid in zip(units.unit_run, units.unit_time):
        d = data[str(run)]
        t = d.time[0] + t_mid
        window = (t - 2.0, t + 2.0)

        def mean_of(*columns: str) -> float:
            vals = []
            for c in columns:
                if d.has(c):
                    ts, vs = d.samples(c)
                    inside = (ts >= window[0]) & (ts <= window[1])
                    if np.any(inside):
                        vals.append(float(np.mean(vs[inside])))
            return float(np.mean(vals)) if vals else np.nan

        spin = mean_of("omega_left", "omega_right")
        speed = float(np.mean(forward_speed(d, np.linspace(*window, 9)))) if d.has("pos_x") else np.nan
        cov["time"].append(t_mid)
        cov["x"].append(mean_of("pos_x"))
        cov["y"].append(mean_of("pos_y"))
        cov["torque"].append(mean_of("torque_left", "torque_right"))
        cov["spin"].append(spin)
        cov["slip"].append(1.0 - speed / (spin * wheel_radius) if spin * wheel_radius > 1e-6 else np.nan)
    units_of = {"time": "s", "x": "m", "y": "m", "torque": "N m", "spin": "rad/s", "slip": "-"}
    return {k: (np.array(v, float), units_of[k]) for k, v in cov.items()}


def _what_it_follows(means: np.ndarray, scale: float, unit: str, covariates: Mapping[str, tuple[np.ndarray, str]],
                     runs: np.ndarray, varying: bool) -> list[Covariate]:
    """What the block means ``means`` (scaled units; ``scale`` converts to the signal's units)
    follow, largest share first: a constant offset, by its share of their mean square; and, when
    they vary about their mean by a material amount (``varying``), each covariate and the run by
    their share of that variation.  Only shares of at least FOLLOWS_SHARE are listed."""
    m = means * scale
    out: list[Covariate] = []
    ms = float(np.mean(m * m))
    if ms <= 0:
        return out
    out.append(Covariate("constant", float(np.mean(m) ** 2 / ms), float(np.mean(m)), unit))
    total = float(np.sum((m - m.mean()) ** 2))
    if varying and total > 0:
        for name, (x, xunit) in covariates.items():
            ok = np.isfinite(x)
            if ok.sum() < 4 or np.ptp(x[ok]) <= 0:
                continue
            slope, intercept = np.polyfit(x[ok], m[ok], 1)
            resid = m[ok] - (slope * x[ok] + intercept)
            share = 1.0 - float(np.sum(resid ** 2)) / float(np.sum((m[ok] - m[ok].mean()) ** 2))
            out.append(Covariate(name, share, float(slope), f"{unit} per {xunit}"))
        groups = np.unique(runs)
        if len(groups) > 1:
            between = sum(np.sum(runs == g) * (m[runs == g].mean() - m.mean()) ** 2 for g in groups)
            out.append(Covariate("run", float(between / total), float("nan"), unit))
    return sorted((c for c in out if c.share >= FOLLOWS_SHARE), key=lambda c: -c.share)


def _side_covariate(signal: str, means_by_signal: Mapping[str, np.ndarray], scale: Mapping[str, float],
                    unit: str) -> Covariate | None:
    """For a left/right pair (torque_left, torque_right): the share of the variation of both
    sides' block means (about their common mean) that the side accounts for, and the left
    minus right difference of their means."""
    if not signal.endswith(("_left", "_right")):
        return None
    stem = signal.rsplit("_", 1)[0]
    left, right = means_by_signal.get(stem + "_left"), means_by_signal.get(stem + "_right")
    if left is None or right is None or len(left) == 0 or len(right) == 0:
        return None
    a, b = left * scale[stem + "_left"], right * scale[stem + "_right"]
    both = np.concatenate([a, b])
    total = float(np.sum((both - both.mean()) ** 2))
    if total <= 0:
        return None
    between = len(a) * (a.mean() - both.mean()) ** 2 + len(b) * (b.mean() - both.mean()) ** 2
    return Covariate("side", float(between / total), float(a.mean() - b.mean()), f"{unit}, left minus right")


def residual_structure(campaign: Campaign, fmu: JunoFMU, prepared: Sequence[PreparedRun],
                       meta: Mapping[str, np.ndarray], train: np.ndarray, residuals: np.ndarray,
                       params: Mapping[str, object], seed: int = 0, replicas: int = REPLICAS,
                       wheel_radius: float | None = None, workers: int | None = 1,
                       data: Mapping[str, RunData] | None = None, pool: TaskPool | None = None,
                       periodic_bases: PeriodicBases | None = None,
                       for_run: Callable[[dict[str, object], str], dict[str, object]] | None = None) -> ResidualStructure:
    """The structure test (module docstring) of the model with FMU parameters ``params``, whose
    scaled residuals over ``prepared`` (labelled by ``meta``, training blocks ``train``) are
    ``residuals``.  Deterministic for a given ``seed``, whatever ``workers`` (local processes
    simulating the replicas: juno.parallel; 1 = in this process with ``fmu``, None = one per
    core), or the tasks of ``pool``, already open.  ``data``: the measured runs (run id -> RunData)
    when the caller has read them already.  ``periodic_bases``: where the periodic test keeps what
    does not depend on the residuals, for the tests of other models on the same runs
    (juno.periodic_structure.PeriodicBases).  ``for_run(extra, run_id)``: the FMU parameters of
    run ``run_id`` from the model's parameters beyond the soil (a caller whose models give some
    parameters to some runs only, as the diagnosis's lug phases, says how); None: every run alike.  Raises SimulationError if a replica cannot be
    simulated (a model that cannot replay its own runs with noise a sensor's size)."""
    tested = [p for p in prepared if p.kind == "drawbar"]
    runs = [p.run_id for p in tested]
    if not tested:
        return ResidualStructure([], FALSE_ALARM, replicas, [])
    given = data or {}
    data = {p.run_id: given[p.run_id] if p.run_id in given else read_run(campaign, p.run_id) for p in tested}
    columns = set(INPUT_COLUMNS) | set(START_POSE_COLUMNS) | {c for p in tested for c in p.targets}
    noise = {(p.run_id, c): sensor_noise(data[p.run_id], c) for p in tested for c in columns
             if data[p.run_id].has(c)}
    for p in tested:     # a start heading taken from the track has its own error (juno.heading)
        if not data[p.run_id].has("yaw"):
            noise[(p.run_id, "yaw")] = start_heading(data[p.run_id], p.run_id).sigma
    units = _units(meta, train, runs)
    observed = _block_means(residuals[units.index], units.key)

    soil = {k: params[k] for k in SOIL_PARAMETERS}
    extra = {k: v for k, v in params.items() if k not in SOIL_PARAMETERS and not str(k).startswith("terrain.")}
    offsets = {}
    start = 0
    for p in prepared:
        n = sum(len(v[0]) for v in p.targets.values())
        offsets[p.run_id] = (start, start + n)
        start += n
    # Every replica's noise is drawn first, in one fixed order (replica, then run: its inputs,
    # then its outputs), and only then are the replays simulated, as tasks (juno.parallel): the
    # simulations draw nothing, so where and in which order they run cannot change the test.
    rng = np.random.default_rng(seed)
    draws = []
    for _i in range(replicas):
        for p in tested:
            run_noise = {c: noise[(p.run_id, c)] for c in columns if (p.run_id, c) in noise}
            noisy = _noisy_inputs(rng, p, data[p.run_id], run_noise)
            draws.append((noisy, _output_noise(rng, p, data[p.run_id], run_noise)))
    tasks = [(FMUHandle(fmu), noisy, soil, for_run(extra, noisy.run_id) if for_run else extra) for noisy, _e in draws]
    replays = pool.map(_replica_task, tasks) if pool is not None else \
        map_tasks(_replica_task, tasks, workers=resolve_workers(workers, len(draws)))
    failure = next((f for _r, f in replays if f is not None), None)
    if failure is not None:
        raise failure
    # Each replica's residuals where the model is right: the block test takes their block means,
    # the timing test the samples themselves.
    null_residuals = np.zeros((replicas, len(residuals)))
    for i in range(replicas):
        for j, p in enumerate(tested):
            k = i * len(tested) + j
            a, b = offsets[p.run_id]
            null_residuals[i, a:b] = (replays[k][0] - residuals[a:b]) + draws[k][1]
    null_means = np.array([_block_means(d[units.index], units.key) for d in null_residuals])

    sigma_of = {c: s for p in tested for c, (_t, _v, _o, s, _l) in p.targets.items()}
    means_by_signal = {str(sig): observed[units.unit_signal == sig] for sig in np.unique(units.unit_signal)}
    covariates = _covariate_values(campaign, units, data, wheel_radius or _wheel_radius(campaign, fmu))
    signals = [_test_signal(str(sig), units, observed, null_means, noise, sigma_of, covariates,
                            means_by_signal, len(np.unique(units.unit_signal)))
               for sig in np.unique(units.unit_signal)]
    periodic = periodic_structure(series_of_residuals(prepared, meta, train, residuals, data, noise), UNITS,
                                  bases=periodic_bases)
    held_out = np.zeros(len(residuals), bool)
    held_out[units.index] = True
    timing = timing_structure(meta["signal"], held_out, regressors(prepared, residuals), residuals, null_residuals)
    return ResidualStructure(signals, FALSE_ALARM / max(len(signals), 1), replicas, runs, periodic, timing)


def _replica_task(args: tuple[FMUHandle, PreparedRun, dict[str, float], dict[str, object]]
                  ) -> tuple[np.ndarray | None, SimulationError | None]:
    """One replica's replay of one run: (its scaled residuals, None), or (None, the simulation's
    failure), which the caller raises as it is (a task's error would arrive wrapped)."""
    handle, noisy, soil, extra = args
    try:
        return run_residuals(handle.get(), noisy, soil, extra, OUTPUT_INTERVAL), None
    except SimulationError as exc:
        return None, exc


def _wheel_radius(campaign: Campaign, fmu: JunoFMU) -> float:
    from .rover_model import rover
    return rover(campaign.rover, fmu.fmu_path).wheel_radius


def _test_signal(sig: str, units: _Units, observed: np.ndarray, null_means: np.ndarray,
                 noise: Mapping[tuple[str, str], float], sigma_of: Mapping[str, float],
                 covariates: Mapping[str, tuple[np.ndarray, str]], means_by_signal: Mapping[str, np.ndarray],
                 n_signals: int) -> SignalStructure:
    """The test and the size of one signal's structure (module docstring, steps 4 and 5).

    T = mean over the signal's held-out blocks of (block mean)^2 / null variance, the null
    variance pooled over each run's blocks (they are alike).  The blocks of one run are not
    independent (a replay that drifts in heading biases every later block alike), so T's null
    distribution is not F: it is taken as a scaled chi-square c chi2(nu) whose mean and variance
    are those of T over the replicas (Satterthwaite), which carries their correlation."""
    from scipy.stats import chi2
    mine = units.unit_signal == sig
    k = int(np.sum(mine))
    runs = units.unit_run[mine]
    null = null_means[:, mine]
    ref = np.empty(k)
    for run in np.unique(runs):
        ref[runs == run] = np.mean(null[:, runs == run] ** 2)
    ref = np.maximum(ref, 1e-300)
    means = observed[mine]
    statistic = float(np.mean(means * means / ref))
    replica_stats = np.mean(null * null / ref, axis=1)
    mean_t, var_t = float(np.mean(replica_stats)), float(np.var(replica_stats, ddof=1))
    c = max(var_t, 1e-12) / (2.0 * mean_t)
    nu = 2.0 * mean_t ** 2 / max(var_t, 1e-12)
    p = float(chi2.sf(statistic / c, nu))
    scale = sigma_of[sig]
    run_noise = [noise[(str(r), sig)] for r in np.unique(runs) if (str(r), sig) in noise]
    sensor = float(np.median(run_noise)) if run_noise else float("nan")
    if sig in ("pos_x", "pos_y"):      # compared as increments over a lag: their noise is sqrt(2) sigma
        sensor *= np.sqrt(2.0)
    excess = max(0.0, float(np.mean(means * means)) - float(np.mean(ref)))
    rms = float(np.sqrt(excess)) * scale
    ratio = rms / sensor if sensor > 0 else float("inf")
    level = FALSE_ALARM / max(n_signals, 1)
    floor = materiality_floor(sig, sensor) if np.isfinite(sensor) else float("inf")
    resolved = bool(p < level)
    significant = bool(resolved and rms >= floor)
    unit = UNITS.get(sig, "")
    follows: list[Covariate] = []
    if resolved:
        cov = {name: (x[mine], u) for name, (x, u) in covariates.items()}
        varying = float(np.var(means)) - float(np.mean(ref)) >= (floor / scale) ** 2
        follows = _what_it_follows(means, scale, unit, cov, runs, varying)
        side = _side_covariate(sig, means_by_signal, {s: sigma_of[s] for s in means_by_signal}, unit)
        if side is not None and side.share >= FOLLOWS_SHARE:
            follows = sorted(follows + [side], key=lambda c: -c.share)
    return SignalStructure(sig, unit, k, sensor, rms, ratio, p, significant, follows, resolved)
