"""Single-wheel testbed: simulate a wheel_rig table through WheelRig.fmu and fit the soil to it.

A single-wheel testbed drives one wheel under a constant vertical load along a soil bin at set
slips and measures drawbar pull, driving torque and sinkage (:mod:`juno.campaign`, kind
``wheel_rig``).  Each point of such a table is a steady state: :func:`simulate_points` runs the
rig FMU at the point's load, slip and slip angle until the wheel has rolled ``ROLL_RADII``
wheel radii, and averages its outputs over the last ``AVERAGE_FRACTION`` of that run (the
contact memory, maximum sinkage and the hub's settling, has then died out: see ROLL_RADII).  One FMU instance
serves every point (reset between points), as :class:`juno.simulator.JunoFMU` does.

:func:`fit_rig` identifies the soil of one contact law on the wheel_rig runs of a campaign by
weighted least squares:

* residuals ``(simulated - measured) / sigma`` of every measured value (drawbar pull, torque,
  sinkage, lateral force), with ``sigma`` the table's per-point standard deviation
  (``<column>_std``) where given.  A column without one gets a noise scale estimated from the
  data: the root-mean-square residual of that column at a first fit (equal relative weights),
  with the degrees of freedom the fit used up shared over the columns; the fit is then repeated
  with those scales.  The result says which columns were weighted how.
* in transformed parameters that keep the search inside the FMU's ranges (log for positive
  scales, a logistic map onto the range for bounded ones), trust-region Gauss-Newton.
* the covariance from the Jacobian, ``pinv(J^T J)`` times the reduced chi-square when that
  exceeds 1 (the data scatter more than their stated deviations: model error), and the
  identifiability of each parameter from its relative uncertainty
  (:func:`juno.identify.classify`).
* a fit whose simulations failed is an error (:class:`juno.identify.FitError`), never a result.

The fitted parameters per contact law (``contact.model``): volumetric (0): the foundation
stiffness ``soil.kh``, its exponent ``soil.eta``, the rebound ``soil.gamma``, the traction
modulus ``soil.Kvx`` and the friction angle ``soil.phi``; Wong-Reece (1): the Bekker exponent
``wongReece.n``, frictional modulus ``wongReece.kphi``, shear modulus ``wongReece.K`` and
``soil.phi``.  The friction angle is fitted because a testbed measures directly the drawbar
pull where the traction saturates, which the shear strength sets.  The lugs' extra thrust
(``grouser.thrustGain``, applied to the lugged wheels only) is fitted when the campaign holds
both smooth and lugged wheels on the same soil: on lugged wheels alone it multiplies the shear
strength exactly as the friction angle does, so the two could not be told apart, and it is then
held at 0.  The lug height (``grouser.lugHeight``) is the manifest's.

Testbeds measure the sinkage rising with slip (the wheel digs itself in), which neither law's
steady rolling reproduces: ``slip_sinkage=True`` fits the rover model's slip-sinkage extension
(``slipSinkage.coefficient``, k_h / (1 + c |slip|)) with the volumetric law as well.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Mapping, Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from .campaign import RIG_MEASURED, Campaign, RigSetup, RigTable, read_rig
from .errors import InputError
from .identify import EVALUATION_LIMIT, FAILED_RESIDUAL, EvaluationLog, classify
from .simulator import InputSignals, JunoFMU, SimulationError

FloatArray = NDArray[np.float64]

__all__ = [
    "RigFMU", "default_rig_fmu_path", "RigPoints", "RigSimulation", "simulate_points",
    "LAWS", "law_parameters", "RigRun", "rig_runs", "RigFitResult", "fit_rig", "predict", "rig_base_parameters",
]

#: Where an installed package carries the rig FMU (next to JunoRover.fmu, see juno.simulator).
PACKAGED_RIG_FMU = Path(__file__).resolve().parent / "data" / "WheelRig.fmu"
RIG_FMU_HINT = ("build it in the source checkout (cmake -S . -B build && cmake --build build), then give "
                "its path with --rig-fmu or the environment variable JUNO_RIG_FMU")

#: The FMU output of each measured column.
OUTPUT_OF = {"drawbar_pull": "rig.drawbarPull", "torque": "rig.torque", "sinkage": "rig.sinkage",
             "lateral_force": "rig.lateralForce"}
#: Distance the wheel rolls per simulated point, in wheel radii, by contact.model, and the final
#: fraction of the run whose outputs are averaged.  The volumetric law's sinkage creeps towards
#: its rolling value over a few contact lengths (the contact memory); the Wong-Reece law settles
#: within one.  Measured on the three published testbed wheels (radius 0.085-0.157 m) at slips
#: 0-0.6: the averages lie within 0.03 % of a roll of 20 radii at a 1 ms step.
ROLL_RADII = {0: 8.0, 1: 2.0}
AVERAGE_FRACTION = 0.4
#: Carriage speed of the simulation (m/s).  The model's soil is rate-independent at speeds above
#: the shear law's slip-velocity floor (contact.slipVelocityEps, 0.05 m/s): below it the slip is
#: regularised into a viscous law.  Testbeds run slower (about 0.01 m/s), at which the soil is
#: equally rate-independent; the simulation therefore runs at this speed whatever the carriage
#: speed of the manifest (which is kept with the data).
SIM_SPEED = 0.1
#: Integration step (s) and communication interval (s) of a point's simulation.  The FMU
#: integrates implicitly: 5 ms damps the hub's start-up oscillation on the soil faster than 1 ms
#: (the steady values agree within the tolerance above) at a fifth of the cost.
SIM_STEP = 5e-3
SIM_INTERVAL = 0.02


def default_rig_fmu_path() -> Path:
    """Path of the rig FMU: $JUNO_RIG_FMU; else WheelRig.fmu next to $JUNO_FMU if that is set
    and the file exists; else build/WheelRig.fmu of this checkout, if built; else the copy the
    installed package carries."""
    env = os.environ.get("JUNO_RIG_FMU")
    if env:
        return Path(env)
    rover = os.environ.get("JUNO_FMU")
    if rover and (Path(rover).parent / "WheelRig.fmu").is_file():
        return Path(rover).parent / "WheelRig.fmu"
    checkout = Path(__file__).resolve().parents[2] / "build" / "WheelRig.fmu"
    if checkout.is_file() or not PACKAGED_RIG_FMU.is_file():
        return checkout
    return PACKAGED_RIG_FMU


class RigFMU(JunoFMU):
    """The extracted WheelRig FMU and one reusable instance of it (see JunoFMU)."""

    def __init__(self, fmu_path: str | os.PathLike | None = None, solver_step: float | None = None):
        path = Path(fmu_path) if fmu_path else default_rig_fmu_path()
        if not path.is_file():
            raise FileNotFoundError(f"{path}: rig FMU not found: {RIG_FMU_HINT}")
        super().__init__(path, solver_step)


# --------------------------------------------------------------------------------------------
# Simulation of points
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class RigPoints:
    """Set points of a testbed: vertical load (N), slip (-) and slip angle (rad), one per point."""

    load: FloatArray
    slip: FloatArray
    slip_angle: FloatArray

    @staticmethod
    def of(load: Sequence[float] | float, slip: Sequence[float],
           slip_angle: Sequence[float] | float = 0.0) -> "RigPoints":
        s = np.atleast_1d(np.asarray(slip, float))
        return RigPoints(np.broadcast_to(np.asarray(load, float), s.shape).copy(), s,
                         np.broadcast_to(np.asarray(slip_angle, float), s.shape).copy())

    @staticmethod
    def of_table(table: RigTable) -> "RigPoints":
        return RigPoints(np.array(table["vertical_load"]), np.array(table["slip"]), np.array(table.slip_angle))

    def __len__(self) -> int:
        return int(self.slip.shape[0])

    def subset(self, index: NDArray[np.intp]) -> "RigPoints":
        return RigPoints(self.load[index], self.slip[index], self.slip_angle[index])


@dataclass
class RigSimulation:
    """Steady outputs of each point: column name -> array (``drawbar_pull`` N, ``torque`` N m,
    ``sinkage`` m, ``lateral_force`` N, ``vertical_force`` N), and ``unsteady`` (the largest
    change of an averaged output between the two halves of the averaging window, relative to
    the output or, near zero, to 5 % of the load (forces; times the radius for the torque) and
    0.1 mm (sinkage))."""

    values: dict[str, FloatArray]
    unsteady: float = 0.0

    def __getitem__(self, name: str) -> FloatArray:
        return self.values[name]


#: The scales RigSimulation.unsteady compares an output's drift with near zero: a fraction of the
#: load (forces; times the radius for the torque) and a sinkage (m).
UNSTEADY_LOAD_FRACTION = 0.05
UNSTEADY_SINKAGE = 1e-4


def wheel_parameters(setup: RigSetup) -> dict[str, float]:
    """The FMU parameters of a testbed wheel: radius and width (m), the lug height (m)."""
    return {"wheel.radius": setup.radius, "wheel.width": setup.width, "grouser.lugHeight": setup.lug_height}


def _check_points(points: RigPoints) -> None:
    for name, v in (("load", points.load), ("slip", points.slip), ("slip_angle", points.slip_angle)):
        if not np.all(np.isfinite(v)):
            raise ValueError(f"rig point {name} must be finite, got {v.tolist()}")
    if np.any(points.load <= 0):
        raise ValueError(f"rig point loads must be > 0 N, got {points.load.tolist()}")
    if np.any(points.slip >= 1):
        raise ValueError(f"rig point slips must be < 1, got {points.slip.tolist()}")
    if np.any(np.abs(points.slip_angle) >= math.pi / 2):
        raise ValueError(f"rig point slip angles must lie within +-pi/2 rad, got {points.slip_angle.tolist()}")


def simulate_points(fmu: JunoFMU, setup: RigSetup, points: RigPoints,
                    parameters: Mapping[str, object] | None = None) -> RigSimulation:
    """Steady drawbar pull, torque, sinkage, lateral and vertical force at each point.

    ``parameters``: FMU parameters (soil, contact law) on top of the FMU's defaults; the wheel
    comes from ``setup``.  Each point is one run of ``ROLL_RADII`` radii at SIM_SPEED with the
    slip set (rig.driveMode 0), averaged over its last AVERAGE_FRACTION.

    Raises:
        ValueError: a point out of range (load <= 0, slip >= 1, |slip angle| >= pi/2).
        SimulationError: the FMU refused a parameter or a run failed (its message, the point).
    """
    _check_points(points)
    law = int((parameters or {}).get("contact.model", 0))  # type: ignore[call-overload]
    duration = ROLL_RADII[law] * setup.radius / SIM_SPEED
    n_steps = max(int(round(duration / SIM_INTERVAL)), 10)
    interval = duration / n_steps
    tail = max(int(round(AVERAGE_FRACTION * n_steps)), 2)
    names = ("drawbar_pull", "torque", "sinkage", "lateral_force", "vertical_force")
    outputs = tuple(OUTPUT_OF.get(n, "rig.verticalForce") for n in names)
    values = {n: np.empty(len(points)) for n in names}
    unsteady = 0.0
    base = {**(parameters or {}), **wheel_parameters(setup), "rig.driveMode": 0, "solver.step": SIM_STEP}
    for i in range(len(points)):
        params = {**base, "rig.load": float(points.load[i])}
        inputs = InputSignals.constant(**{"rig.slip": float(points.slip[i]), "rig.vx": SIM_SPEED,
                                          "rig.slipAngle": float(points.slip_angle[i])})
        try:
            sim = fmu.simulate(params, inputs, duration, interval, outputs=outputs)
        except SimulationError as exc:
            raise SimulationError(f"rig point {i + 1} (load {points.load[i]:.4g} N, slip {points.slip[i]:.4g}, "
                                  f"slip angle {points.slip_angle[i]:.4g} rad): {exc.what}", exc.messages,
                                  exc.time) from None
        for n, o in zip(names, outputs):
            last = sim[o][-tail:]
            values[n][i] = float(np.mean(last))
            half = len(last) // 2
            floor = UNSTEADY_SINKAGE if n == "sinkage" else \
                UNSTEADY_LOAD_FRACTION * float(points.load[i]) * (setup.radius if n == "torque" else 1.0)
            scale = max(abs(values[n][i]), floor)
            unsteady = max(unsteady, abs(float(np.mean(last[half:]) - np.mean(last[:half]))) / scale)
    return RigSimulation(values, unsteady)


# --------------------------------------------------------------------------------------------
# Fit
# --------------------------------------------------------------------------------------------

#: Contact laws: name -> contact.model.
LAWS = {"volumetric": 0, "wong-reece": 1}

#: A fitted parameter: (transform, lower bound, upper bound, initial value).  "log": a scale,
#: searched as a logistic map onto (log lower, log upper), i.e. in log near its middle;
#: "logistic": searched on the open interval (lower, upper).  So the search never leaves the
#: FMU's ranges (the bounds; a scale's lower bound is the range's, or 1e-6 of the default where the
#: range starts at 0).  The initial values are the FMU's defaults (the paper's soil), but for the
#: thrust gain.
PARAMETER_SPACE = {
    "soil.kh": ("log", 1e-3, 1e8, 1.58e5),
    "soil.eta": ("logistic", 1e-3, 2.0, 0.501),
    "soil.gamma": ("logistic", 0.0, 1.0, 0.0813),
    "soil.Kvx": ("log", 1e-6, 100.0, 0.819),
    "soil.phi": ("logistic", 0.0, math.pi / 2, 0.5236),
    "wongReece.n": ("logistic", 0.1, 2.5, 1.1),
    "wongReece.pressure1cm": ("log", 10.0, 1e5, 1.528e6 * 0.01 ** 1.1),
    "wongReece.K": ("log", 1e-6, 10.0, 0.010),
    "grouser.thrustGain": ("logistic", 0.0, 5.0, 0.5),
    "slipSinkage.coefficient": ("logistic", 0.0, 50.0, 1.0),
}
#: Bekker's k_phi is searched as the pressure it gives at a sinkage of 1 cm, k_phi (0.01 m)^n (Pa):
#: k_phi's unit N/m^(n+2) changes with n, so that k_phi and n trade off over orders of magnitude
#: along a curved valley (a fit of published data ran k_phi into the FMU's bound of 1e10);
#: the pressure at a testbed's typical sinkage is nearly independent of n.  The Bekker exponent
#: is searched in (0.1, 2.5), beyond the exponents measured on soils (0.5-1.5) yet where k_phi of
#: a pressure up to 1e5 Pa stays within the FMU's range.
SEARCH_ALIAS = {"wongReece.kphi": "wongReece.pressure1cm"}
REFERENCE_SINKAGE = 0.01
_LAW_PARAMETERS = {
    "volumetric": ("soil.kh", "soil.eta", "soil.gamma", "soil.Kvx", "soil.phi"),
    "wong-reece": ("wongReece.n", "wongReece.kphi", "wongReece.K", "soil.phi"),
}
THRUST_GAIN = "grouser.thrustGain"
#: FMU parameters of the campaign's ``rover`` entry that describe the soil and so apply to the
#: rig too (the wheel is the run's).
SOIL_PREFIXES = ("soil.", "wongReece.", "slipSinkage.", "contact.method", "contact.slipVelocityEps")


SLIP_SINKAGE = "slipSinkage.coefficient"


def law_parameters(law: str, lugged_and_smooth: bool, slip_sinkage: bool = False) -> tuple[str, ...]:
    """The parameters fitted for a contact law; the thrust gain when the campaign holds both
    smooth and lugged wheels; the slip-sinkage coefficient with ``slip_sinkage`` (volumetric law
    only: the FMU applies it to k_h; see the module docstring)."""
    if law not in LAWS:
        raise ValueError(f"unknown contact law {law!r} (one of {', '.join(LAWS)})")
    if slip_sinkage and law != "volumetric":
        raise ValueError("the slip-sinkage extension acts on the volumetric law only")
    return _LAW_PARAMETERS[law] + ((THRUST_GAIN,) if lugged_and_smooth else ()) + \
        ((SLIP_SINKAGE,) if slip_sinkage else ())


def _interval(name: str) -> tuple[str, float, float]:
    """(kind, a, b): the parameter, or its log for a scale, lies in the open interval (a, b)."""
    kind, lo, hi, _ = PARAMETER_SPACE[name]
    return (kind, math.log(lo), math.log(hi)) if kind == "log" else (kind, lo, hi)


def _search_names(names: Sequence[str]) -> list[str]:
    return [SEARCH_ALIAS.get(n, n) for n in names]


def _to_fmu(values: Mapping[str, float]) -> dict[str, float]:
    """Search-space values (SEARCH_ALIAS) -> FMU parameters."""
    out = dict(values)
    if "wongReece.pressure1cm" in out:
        n = out.get("wongReece.n", PARAMETER_SPACE["wongReece.n"][3])
        out["wongReece.kphi"] = min(out.pop("wongReece.pressure1cm") / REFERENCE_SINKAGE ** n, 1e10)
    return out


def _from_fmu(names: Sequence[str], values: Mapping[str, float]) -> dict[str, float]:
    """FMU parameters -> the search-space values of ``names`` (FMU names)."""
    out = {}
    for n in names:
        if n == "wongReece.kphi":
            e = float(values.get("wongReece.n", PARAMETER_SPACE["wongReece.n"][3]))
            out[SEARCH_ALIAS[n]] = float(values[n]) * REFERENCE_SINKAGE ** e
        else:
            out[n] = float(values[n])
    return out


def _physical(names: Sequence[str], x: Sequence[float]) -> dict[str, float]:
    """Search vector -> the FMU parameters ``names``."""
    return _to_fmu(_from_search(_search_names(names), x))


def _physical_jacobian(names: Sequence[str], x: FloatArray) -> FloatArray:
    """d(FMU parameters ``names``)/d(search vector), by central differences."""
    T = np.empty((len(names), len(x)))
    for j in range(len(x)):
        h = 1e-6 * max(1.0, abs(float(x[j])))
        up, down = x.copy(), x.copy()
        up[j] += h
        down[j] -= h
        a, b = _physical(names, up), _physical(names, down)
        T[:, j] = [(a[n] - b[n]) / (2 * h) for n in names]
    return T


def _to_search(names: Sequence[str], values: Mapping[str, float]) -> FloatArray:
    x = []
    for n in names:
        kind, a, b = _interval(n)
        v = math.log(float(values[n])) if kind == "log" else float(values[n])
        u = min(max((v - a) / (b - a), 1e-12), 1 - 1e-12)
        x.append(math.log(u / (1 - u)))
    return np.array(x)


def _from_search(names: Sequence[str], x: Sequence[float]) -> dict[str, float]:
    out = {}
    for n, xi in zip(names, x):
        kind, a, b = _interval(n)
        v = a + (b - a) / (1.0 + math.exp(-float(np.clip(xi, -700.0, 700.0))))
        # exp(log(hi)) may exceed hi by an ulp: clipped, so the FMU's range check passes
        out[n] = min(max(math.exp(v), PARAMETER_SPACE[n][1]), PARAMETER_SPACE[n][2]) if kind == "log" else v
    return out


@dataclass
class RigRun:
    """A wheel_rig run ready to fit: its setup, points and measured values (NaN: not measured),
    and the per-point standard deviations where the table gives them."""

    run_id: str
    file: str
    setup: RigSetup
    points: RigPoints
    measured: dict[str, FloatArray]
    std: dict[str, FloatArray]

    def subset(self, index: NDArray[np.intp]) -> "RigRun":
        return RigRun(self.run_id, self.file, self.setup, self.points.subset(index),
                      {k: v[index] for k, v in self.measured.items()}, {k: v[index] for k, v in self.std.items()})


def rig_runs(campaign: Campaign, run_ids: Sequence[str] | None = None) -> list[RigRun]:
    """The campaign's wheel_rig runs (or those named), read and checked; InputError when there
    are none."""
    specs = [campaign.run(r) for r in run_ids] if run_ids else campaign.runs_of_kind("wheel_rig")
    if not specs:
        raise InputError("the campaign has no wheel_rig run: the testbed fit needs one", campaign.manifest_path)
    out = []
    for spec in specs:
        if spec.kind != "wheel_rig" or spec.rig is None:
            raise InputError(f"run {spec.id!r} is a {spec.kind} run, not a wheel_rig table", campaign.manifest_path)
        table = read_rig(campaign, spec)
        measured = {c: np.array(table[c]) for c in RIG_MEASURED if table.has(c)}
        std = {c: np.array(table.std(c)) for c in measured if table.std(c) is not None}
        out.append(RigRun(spec.id, spec.file, spec.rig, RigPoints.of_table(table), measured, std))
    return out


def rig_base_parameters(campaign: Campaign) -> dict[str, object]:
    """The soil parameters of the campaign's ``rover`` entry that apply to the rig (numbers)."""
    return {k: v for k, v in campaign.rover.items() if k.startswith(SOIL_PREFIXES) and not isinstance(v, str)}


@dataclass
class RigFitResult:
    """A contact law fitted to wheel_rig runs.

    ``params``: the fitted parameters; ``fixed``: the FMU parameters held (contact law, the
    campaign's soil entries, a thrust gain held at 0); ``std``, ``relative_std``: 1 sigma
    (physical units; inf when the data does not see the parameter); ``identifiability``: per
    parameter (juno.identify.classify, or "at the bound of its search range");
    ``singular_values``: of the scaled residuals' Jacobian in the search space; ``correlation``: of the parameters; ``cost``: mean
    squared scaled residual; ``chi2`` and ``dof``; ``noise``: per measured column, how its
    sigma was set ("per-point std", or the estimated scale in its unit); ``noise_scale``: that
    estimated scale (its unit), None where the table gives standard deviations; ``rms``: per column, the
    root-mean-square error of the fit in its unit; ``status``: "ok", "not identified" when a
    parameter is not seen or the fit did not move, or EVALUATION_LIMIT when the search used its
    whole budget without converging; ``doubts``: why the values may be wrong even
    with status "ok" (:data:`MISFIT_P`); ``evaluations``, ``failed_evaluations``."""

    law: str
    params: dict[str, float]
    fixed: dict[str, object]
    std: dict[str, float]
    relative_std: dict[str, float]
    identifiability: dict[str, str]
    correlation: FloatArray
    cost: float
    chi2: float
    dof: int
    noise: dict[str, str]
    noise_scale: dict[str, float | None]
    rms: dict[str, float]
    runs: list[str]
    evaluations: int
    failed_evaluations: int
    wall_time: float
    status: str = "ok"
    unsteady: float = 0.0
    singular_values: list[float] = field(default_factory=list)
    doubts: list[str] = field(default_factory=list)

    def model_parameters(self) -> dict[str, object]:
        """Every FMU parameter of the fitted model (fixed and fitted), for :func:`predict`."""
        return {**self.fixed, **self.params}


def predict(fmu: JunoFMU, run: RigRun, parameters: Mapping[str, object]) -> RigSimulation:
    """The model's steady outputs at a run's points; the thrust gain only on a lugged wheel."""
    params = dict(parameters)
    if not run.setup.lugged:
        params.pop(THRUST_GAIN, None)
    return simulate_points(fmu, run.setup, run.points, params)


class _Residuals:
    """Search vector -> scaled residuals of every run (FAILED_RESIDUAL everywhere when a point
    fails, recorded in ``log``)."""

    def __init__(self, fmu: JunoFMU, runs: Sequence[RigRun], names: Sequence[str], fixed: Mapping[str, object],
                 sigma: Mapping[str, Mapping[str, FloatArray]]):
        self.fmu, self.runs, self.names, self.fixed, self.sigma = fmu, list(runs), list(names), dict(fixed), sigma
        self.log = EvaluationLog()
        self.size = sum(int(np.sum(~np.isnan(v))) for r in self.runs for v in r.measured.values())
        self.unsteady = 0.0

    def simulate(self, x: Sequence[float]) -> list[RigSimulation]:
        params = {**self.fixed, **_physical(self.names, x)}
        return [predict(self.fmu, r, params) for r in self.runs]

    def raw(self, sims: Sequence[RigSimulation]) -> dict[tuple[str, str], FloatArray]:
        """(run id, column) -> simulated - measured at the measured points."""
        out = {}
        for r, s in zip(self.runs, sims):
            for c, m in r.measured.items():
                ok = ~np.isnan(m)
                out[(r.run_id, c)] = s[c][ok] - m[ok]
        return out

    def __call__(self, x: np.ndarray) -> np.ndarray:
        try:
            sims = self.simulate(x)
        except SimulationError as exc:
            self.log.record(str(exc))
            return np.full(self.size, FAILED_RESIDUAL)
        parts = []
        for (run_id, c), d in self.raw(sims).items():
            parts.append(d / self.sigma[run_id][c])
        r = np.concatenate(parts) if parts else np.zeros(0)
        if not np.all(np.isfinite(r)):
            self.log.record(f"non-finite rig outputs at {_params_text(_physical(self.names, x))}")
            return np.full(self.size, FAILED_RESIDUAL)
        self.log.record(None)
        self.unsteady = max(self.unsteady, max(s.unsteady for s in sims))
        return r


#: A fit is doubtful when the residuals of the values with stated standard deviations are larger
#: than those deviations explain: their chi-square beyond the quantile 1 - MISFIT_P for their share
#: of the degrees of freedom.  The data then hold something the law does not (a sensor's offset
#: or gain, a soil that changed between runs, a model error); the uncertainties are scaled up for
#: the scatter, but a bias in the values is not in them.
MISFIT_P = 1e-3


def _misfit_doubts(runs: Sequence[RigRun], raw: Mapping[tuple[str, str], FloatArray],
                   sigmas: Mapping[str, Mapping[str, FloatArray]], n_values: int, n_params: int) -> list[str]:
    """The doubt of :data:`MISFIT_P` (empty when the stated deviations explain the residuals, or
    no column states them), with each column's rms residual over its deviation."""
    from scipy.stats import chi2 as chi2_distribution

    scaled: dict[str, list[FloatArray]] = {}
    for (rid, c), d in raw.items():
        if c in _run(runs, rid).std:
            scaled.setdefault(c, []).append(d / sigmas[rid][c])
    if not scaled:
        return []
    per_column = {c: np.concatenate(v) for c, v in scaled.items()}
    n_stated = sum(v.size for v in per_column.values())
    chi2 = float(sum(np.sum(v * v) for v in per_column.values()))
    dof = n_stated * max(n_values - n_params, 1) / n_values
    p = float(chi2_distribution.sf(chi2, dof))
    if p >= MISFIT_P:
        return []
    ratio = ", ".join(f"{c} {float(np.sqrt(np.mean(v * v))):.3g}" for c, v in per_column.items())
    return [f"the residuals exceed the stated standard deviations (chi-square {chi2:.4g} on {dof:.4g} degrees of "
            f"freedom, p = {p:.2g}; rms residual over deviation: {ratio}): the law does not follow these data (a "
            "sensor offset or gain, a soil that changed between runs, a model error; the fit spreads the misfit over "
            "every quantity, so the largest ratio need not be the faulty one); the uncertainties are scaled up for "
            "the scatter, not for a bias in the values"]


def _params_text(p: Mapping[str, float]) -> str:
    return ", ".join(f"{k} = {v:.4g}" for k, v in p.items())


def _sigmas(runs: Sequence[RigRun], scale: Mapping[str, float]) -> dict[str, dict[str, FloatArray]]:
    """Each run's per-point sigma of each measured column (measured points only): the table's
    std where given, else the column's ``scale``."""
    out: dict[str, dict[str, FloatArray]] = {}
    for r in runs:
        out[r.run_id] = {}
        for c, m in r.measured.items():
            ok = ~np.isnan(m)
            out[r.run_id][c] = r.std[c][ok] if c in r.std else np.full(int(ok.sum()), scale[c])
    return out


def fit_rig(fmu: JunoFMU, campaign: Campaign | None = None, law: str = "volumetric",
            runs: Sequence[RigRun] | None = None, initial: Mapping[str, float] | None = None,
            fixed: Mapping[str, object] | None = None, parameters: Sequence[str] | None = None,
            slip_sinkage: bool = False, max_evaluations: int = 400,
            progress: Callable[[str], None] | None = None) -> RigFitResult:
    """Fits a contact law to the wheel_rig runs of ``campaign`` (or to ``runs``); see the module
    docstring.

    ``initial``: starting values (default: the FMU's, thrust gain 0.5); ``fixed``: FMU
    parameters held besides the campaign's soil entries; ``parameters``: the fitted names
    (default :func:`law_parameters`, with ``slip_sinkage``).

    Raises:
        InputError: no wheel_rig run, or no measured value.
        juno.identify.FitError: the model cannot be simulated at the optimum, or more than
            juno.identify.MAX_FAILED_FRACTION of a pass's evaluations failed.
    """
    start = time.perf_counter()
    if law not in LAWS:
        raise ValueError(f"unknown contact law {law!r} (one of {', '.join(LAWS)})")
    unknown = [n for n in (parameters or ()) if SEARCH_ALIAS.get(n, n) not in PARAMETER_SPACE]
    if unknown:
        fittable = [n for n in PARAMETER_SPACE if n not in SEARCH_ALIAS.values()] + list(SEARCH_ALIAS)
        raise ValueError(f"cannot fit {unknown[0]!r}: the rig fit searches {', '.join(fittable)}")
    if runs is None:
        if campaign is None:
            raise ValueError("fit_rig needs a campaign or runs")
        runs = rig_runs(campaign)
    runs = list(runs)
    lugged = {r.setup.lugged for r in runs}
    names = list(parameters) if parameters is not None else \
        list(law_parameters(law, lugged == {True, False}, slip_sinkage))
    held: dict[str, object] = {**(rig_base_parameters(campaign) if campaign is not None else {}), **(fixed or {}),
                               "contact.model": LAWS[law]}
    if THRUST_GAIN not in names:
        held.setdefault(THRUST_GAIN, 0.0)
    for n in names:
        held.pop(n, None)
    columns = sorted({c for r in runs for c in r.measured}, key=RIG_MEASURED.index)
    n_values = sum(int(np.sum(~np.isnan(v))) for r in runs for v in r.measured.values())
    if n_values == 0:
        raise InputError("the wheel_rig runs hold no measured value", campaign.manifest_path if campaign else None)
    check_determined(runs, names, law, campaign.manifest_path if campaign else None)
    start_values = {n: PARAMETER_SPACE[n][3] for n in _search_names(names)}
    given = {k: float(v) for k, v in (initial or {}).items() if k in names}
    start_values.update(_from_fmu([k for k in names if k in given], {**_to_fmu(start_values), **given}))
    x0 = _to_search(_search_names(names), start_values)
    label = f"rig fit ({law}) of " + ", ".join(f"'{r.run_id}'" for r in runs)

    # Noise scales of the columns without per-point std: first equal relative weights (the
    # spread of the column's values), then the rms residual of a first fit.
    missing = [c for c in columns if any(c in r.measured and c not in r.std for r in runs)]
    scale = {c: _spread(runs, c) for c in columns}
    evaluations = failed = 0
    passes = 2 if missing else 1
    x = x0
    for k in range(passes):
        fun = _Residuals(fmu, runs, names, held, _sigmas(runs, scale))
        ls = least_squares(fun, x, method="trf", diff_step=1e-3, max_nfev=max_evaluations, xtol=1e-8, ftol=1e-10)
        optimum_failed = bool(np.all(ls.fun == FAILED_RESIDUAL))
        fun.log.check(label, optimum_failed)
        evaluations += fun.log.count
        failed += fun.log.failed
        x = ls.x
        if progress:
            progress(f"{label}: pass {k + 1}/{passes}, cost {float(np.mean(ls.fun ** 2)):.4g} after "
                     f"{fun.log.count} evaluations")
        if k + 1 < passes:
            sims = fun.simulate(x)
            raw = fun.raw(sims)
            dof_share = max(n_values - len(names), 1) / n_values
            for c in missing:
                d = np.concatenate([v for (rid, cc), v in raw.items() if cc == c and c not in _run(runs, rid).std])
                rms = float(np.sqrt(np.mean(d * d) / dof_share)) if d.size else scale[c]
                scale[c] = max(rms, 1e-6 * max(scale[c], 1e-12))
    r = np.asarray(ls.fun, float)
    J = np.asarray(ls.jac, float)
    physical = _physical(names, x)
    params = {n: physical[n] for n in names}
    dof = max(len(r) - len(names), 1)
    chi2 = float(np.sum(r * r))
    factor = max(chi2 / dof, 1.0)
    try:
        cov_search = np.linalg.pinv(J.T @ J) * factor
    except np.linalg.LinAlgError:
        cov_search = np.full((len(names), len(names)), np.inf)
    T = _physical_jacobian(names, np.asarray(x, float))
    cov = T @ cov_search @ T.T
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    norms = np.linalg.norm(J, axis=0)
    seen = (norms > 1e-12 * norms.max()) if np.all(np.isfinite(norms)) and norms.max() > 0 else np.zeros(len(names), bool)
    moved = bool(np.any(x != x0))
    seen = seen & moved
    std = np.where(seen, std, np.inf)
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(std, std)
    rel = {n: float(std[i] / abs(params[n])) if params[n] != 0 else float("inf") for i, n in enumerate(names)}
    identifiability = {n: classify(v) for n, v in rel.items()}
    # A parameter the search pushed against an end of its interval (the logistic map within 0.1 %
    # of it) is where the data would take it beyond the range searched: its uncertainty, from a
    # saturated map, says nothing.
    u = 1.0 / (1.0 + np.exp(-np.clip(np.asarray(x, float), -700, 700)))
    for i, n in enumerate(names):
        if min(u[i], 1 - u[i]) < 1e-3:
            identifiability[n] = "at the bound of its search range"
            std[i] = np.inf
            rel[n] = float("inf")
    sv = np.linalg.svd(J, compute_uv=False) if J.size else np.zeros(0)
    sims = fun.simulate(x)
    raw = fun.raw(sims)
    rms = {c: float(np.sqrt(np.mean(np.concatenate([v for (_rid, cc), v in raw.items() if cc == c]) ** 2)))
           for c in columns}
    doubts = _misfit_doubts(runs, raw, _sigmas(runs, scale), n_values, len(names))
    # A search that used its whole budget without meeting a convergence test stopped where it was
    # (least_squares' status 0): its values are not the optimum (identify's EVALUATION_LIMIT).
    at_limit = ls.status == 0
    if at_limit:
        doubts.append(f"the search stopped at its limit of {max_evaluations} iterations without meeting its "
                      "convergence tests: the values are where it stopped, not the optimum, and their "
                      "uncertainty is the curvature there")
    noise, noise_scale = {}, {}
    for c in columns:
        given = all(c in rr.std for rr in runs if c in rr.measured)
        noise[c] = "per-point std" if given else f"estimated {scale[c]:.3g}"
        noise_scale[c] = None if given else scale[c]
    return RigFitResult(law=law, params=params, fixed=held, std=dict(zip(names, std.tolist())), relative_std=rel,
                        identifiability=identifiability, correlation=corr, singular_values=sv.tolist(),
                        cost=float(np.mean(r * r)), chi2=chi2, dof=dof, noise=noise, noise_scale=noise_scale, rms=rms,
                        runs=[rr.run_id for rr in runs], evaluations=evaluations, failed_evaluations=failed,
                        wall_time=time.perf_counter() - start, status=_status(seen, identifiability, at_limit),
                        unsteady=fun.unsteady, doubts=doubts)


def distinct_values(runs: Sequence[RigRun]) -> tuple[int, int]:
    """(distinct set points, measured values at distinct set points) of testbed runs: a set point
    is a run's (load, slip, slip angle), and a quantity measured at it, however often, is one
    value. Rows repeated at one set point measure its scatter, not how the soil's response
    changes with load and slip, which is what the law's parameters describe."""
    points = values = 0
    for r in runs:
        keys = np.column_stack([r.points.load, r.points.slip, r.points.slip_angle])
        _, which = np.unique(keys, axis=0, return_inverse=True)
        which = which.reshape(-1)
        points += int(which.max()) + 1
        for v in r.measured.values():
            values += np.unique(which[~np.isnan(v)]).size
    return points, values


def check_determined(runs: Sequence[RigRun], names: Sequence[str], law: str, manifest: Path | None) -> None:
    """A fit needs more measured values at distinct set points than the parameters it fits
    (:func:`distinct_values`): with as many or fewer the law follows any table exactly, its
    residuals say nothing of the noise and its uncertainties nothing of the soil.

    Raises:
        InputError: too few values, naming the tables, their set points and the parameters.
    """
    points, values = distinct_values(runs)
    if values > len(names):
        return
    slips = sorted({float(s) for r in runs for s in r.points.slip})
    loads = sorted({float(w) for r in runs for w in r.points.load})
    tables = f"table{'s' if len(runs) > 1 else ''} {', '.join(r.file for r in runs)}"
    raise InputError(f"the wheel_rig {tables} hold{'s' if len(runs) == 1 else ''} {points} distinct set point"
                     f"{'s' if points != 1 else ''} (load, slip and slip angle; slips "
                     f"{', '.join(f'{v:g}' for v in slips[:8])}{' ...' if len(slips) > 8 else ''}; loads "
                     f"{', '.join(f'{v:g}' for v in loads[:8])}{' ...' if len(loads) > 8 else ''} N) with {values} "
                     f"measured value{'s' if values != 1 else ''} among them, not more than the {len(names)} "
                     f"parameters the {law} law fits ({', '.join(names)}): the fit cannot determine them; measure "
                     "at more slips (rows repeated at one set point count once)", manifest)


def _status(seen: NDArray[np.bool_], identifiability: Mapping[str, str], at_limit: bool = False) -> str:
    """"ok" when the data sees every parameter, none lies at a bound of its search range and the
    search converged; EVALUATION_LIMIT when it used its whole budget instead."""
    if not np.all(seen) or any(v == "at the bound of its search range" for v in identifiability.values()):
        return "not identified"
    return EVALUATION_LIMIT if at_limit else "ok"


def _run(runs: Sequence[RigRun], run_id: str) -> RigRun:
    return next(r for r in runs if r.run_id == run_id)


def _spread(runs: Sequence[RigRun], column: str) -> float:
    """A column's typical magnitude for the first pass's weights: the standard deviation of its
    values over every run, or their mean magnitude when they are all equal."""
    v = np.concatenate([r.measured[column][~np.isnan(r.measured[column])] for r in runs if column in r.measured])
    s = float(np.std(v))
    return s if s > 0 else max(float(np.mean(np.abs(v))), 1e-9)
