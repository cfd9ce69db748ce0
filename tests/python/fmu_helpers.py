"""Helpers for the JunoRover FMU tests: drive the FMU with fmpy's FMU2Slave directly, capture its
log messages, and write ESRI ASCII terrain grids.

Nothing here knows the physics: it only moves numbers in and out of the FMU by the variable names of
the FMU's modelDescription.xml.
"""

from __future__ import annotations

import functools
import math
import os
from dataclasses import dataclass, field
from typing import Callable, Iterable, Mapping

import numpy as np
from fmpy import read_model_description
from fmpy.fmi1 import FMICallException  # noqa: F401  (re-exported for the tests)
from fmpy.fmi2 import (
    FMU2Slave,
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
)
from fmpy import calloc, free

G = 9.81
WHEELS = ("FL", "RL", "FR", "RR")
WHEEL_QUANTITIES = ("sinkage", "slip", "Fn", "Ft", "Fx", "Fy", "Fz")


# ---------------------------------------------------------------------------------------------
# Model description
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Variable:
    name: str
    vr: int
    type: str          # "Real", "Integer", "Boolean", "String"
    causality: str
    unit: str | None
    start: object


@functools.lru_cache(maxsize=None)
def model_description(fmu_unzipped: str):
    return read_model_description(str(fmu_unzipped))


@functools.lru_cache(maxsize=None)
def variables(fmu_unzipped: str) -> dict[str, Variable]:
    md = model_description(str(fmu_unzipped))
    return {
        v.name: Variable(v.name, v.valueReference, v.type, v.causality, v.unit or (v.declaredType.unit if v.declaredType else None), v.start)
        for v in md.modelVariables
    }


def output_names(fmu_unzipped: str) -> list[str]:
    return [v.name for v in variables(str(fmu_unzipped)).values() if v.causality == "output"]


# ---------------------------------------------------------------------------------------------
# Logging
# ---------------------------------------------------------------------------------------------

@dataclass
class LogCapture:
    """Collects the FMU's log messages as (status, category, text) tuples."""

    messages: list[tuple[int, str, str]] = field(default_factory=list)
    echo: bool = False

    def __post_init__(self):
        def _logger(env, instance_name, status, category, message):  # noqa: ARG001
            text = message.decode("utf-8", "replace") if message else ""
            cat = category.decode("utf-8", "replace") if category else ""
            self.messages.append((int(status), cat, text))
            if self.echo:
                print(f"[FMU {status} {cat}] {text}")

        self._logger = fmi2CallbackLoggerTYPE(_logger)
        self._alloc = fmi2CallbackAllocateMemoryTYPE(calloc)
        self._free = fmi2CallbackFreeMemoryTYPE(free)
        self.callbacks = fmi2CallbackFunctions()
        self.callbacks.logger = self._logger
        self.callbacks.allocateMemory = self._alloc
        self.callbacks.freeMemory = self._free

    def errors(self) -> list[str]:
        """Texts of the messages logged with status fmi2Error (3) or worse."""
        return [text for status, _, text in self.messages if status >= 3]

    def text(self) -> str:
        return "\n".join(text for _, _, text in self.messages)

    def clear(self) -> None:
        self.messages.clear()


# ---------------------------------------------------------------------------------------------
# An FMU instance with name-based access
# ---------------------------------------------------------------------------------------------

class Rover:
    """One instance of the FMU, addressed by variable names.

    rover = Rover(fmu_unzipped); rover.setup(params); rover.step(...); rover.get([...]); rover.free()
    """

    def __init__(self, fmu_unzipped, instance_name: str = "rover", log: LogCapture | None = None,
                 logging_on: bool = False):
        self.dir = str(fmu_unzipped)
        self.md = model_description(self.dir)
        self.vars = variables(self.dir)
        self.log = log if log is not None else LogCapture()
        self.fmu = FMU2Slave(
            guid=self.md.guid,
            unzipDirectory=self.dir,
            modelIdentifier=self.md.coSimulation.modelIdentifier,
            instanceName=instance_name,
        )
        self.fmu.instantiate(callbacks=self.log.callbacks, loggingOn=logging_on)
        self.time = 0.0
        self._freed = False
        self._initialised = False   # exitInitializationMode succeeded (fmi2Terminate is legal)

    # --- variable access ---------------------------------------------------------------------

    def var(self, name: str) -> Variable:
        try:
            return self.vars[name]
        except KeyError:
            raise KeyError(f"the FMU has no variable named {name!r}") from None

    def set(self, values: Mapping[str, object]) -> None:
        """Sets variables by name, each with the setter of its type."""
        for name, value in values.items():
            v = self.var(name)
            if v.type == "Real":
                self.fmu.setReal([v.vr], [float(value)])
            elif v.type in ("Integer", "Enumeration"):
                self.fmu.setInteger([v.vr], [int(value)])
            elif v.type == "Boolean":
                self.fmu.setBoolean([v.vr], [bool(value)])
            elif v.type == "String":
                self.fmu.setString([v.vr], [str(value)])
            else:  # pragma: no cover
                raise TypeError(f"{name}: unsupported type {v.type}")

    def get(self, names: Iterable[str]) -> list[float]:
        names = list(names)
        vrs = [self.var(n).vr for n in names]
        return list(self.fmu.getReal(vrs))

    def get_one(self, name: str):
        v = self.var(name)
        if v.type == "Real":
            return self.fmu.getReal([v.vr])[0]
        if v.type in ("Integer", "Enumeration"):
            return self.fmu.getInteger([v.vr])[0]
        if v.type == "String":
            return self.fmu.getString([v.vr])[0]
        return self.fmu.getBoolean([v.vr])[0]

    # --- life cycle --------------------------------------------------------------------------

    def setup(self, params: Mapping[str, object] | None = None, start_time: float = 0.0,
              stop_time: float | None = None, initial_inputs: Mapping[str, float] | None = None,
              tolerance: float | None = None) -> None:
        """setupExperiment (with toleranceDefined when a tolerance is given), enterInitializationMode,
        parameters, exitInitializationMode."""
        self._initialised = False
        self.fmu.setupExperiment(tolerance=tolerance, startTime=start_time, stopTime=stop_time)
        self.fmu.enterInitializationMode()
        if params:
            self.set(params)
        if initial_inputs:
            self.set(initial_inputs)
        self.fmu.exitInitializationMode()
        self._initialised = True
        self.time = start_time

    def initial_values(self, names: list[str], *changes: Mapping[str, object]) -> list[dict[str, float]]:
        """In Initialization Mode, after each of ``changes`` (parameters and inputs set in turn),
        the values of ``names``; then after exitInitializationMode, once more."""
        self._initialised = False
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        read = []
        for change in changes:
            self.set(change)
            read.append(dict(zip(names, self.get(names))))
        self.fmu.exitInitializationMode()
        self._initialised = True
        self.time = 0.0
        return read + [dict(zip(names, self.get(names)))]

    def step(self, h: float) -> None:
        self.fmu.doStep(currentCommunicationPoint=self.time, communicationStepSize=h)
        self.time = self.time + h

    def advance(self, n: int, h: float, inputs: InputSpec = None, names: Iterable[str] | None = None) -> np.ndarray:
        """n communication steps of h from the current time; returns the outputs `names` (default:
        every output) after each step as an (n, len(names)) array.  Communication points are
        t0 + i*h, so that two instances driven alike see bit-identical times."""
        names = list(names) if names is not None else output_names(self.dir)
        t0 = self.time
        out = np.empty((n, len(names)))
        last: dict = {}
        for i in range(n):
            t = t0 + i * h
            u = _inputs_at(inputs, t, last)
            if u:
                self.set(u)
            self.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)
            self.time = t0 + (i + 1) * h
            out[i] = self.get(names)
            last = dict(zip(names, out[i]))
        return out

    def step_at(self, t: float, h: float, inputs: InputSpec = None, names: Iterable[str] | None = None,
                last: dict | None = None) -> np.ndarray:
        """One communication step from the communication point t (inputs evaluated at t);
        returns the outputs `names` after it."""
        names = list(names) if names is not None else output_names(self.dir)
        u = _inputs_at(inputs, t, last or {})
        if u:
            self.set(u)
        self.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)
        self.time = t + h
        return np.asarray(self.get(names), dtype=float)

    def free(self) -> None:
        if not self._freed:
            self._freed = True
            if self._initialised:
                try:
                    self.fmu.terminate()
                except Exception:   # e.g. the instance is in the Error state after a failed step
                    pass
            self.fmu.freeInstance()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.free()
        return False


# ---------------------------------------------------------------------------------------------
# A whole run
# ---------------------------------------------------------------------------------------------

InputSpec = Mapping[str, "float | Callable[[float], float]"] | Callable[[float, dict], Mapping[str, float]] | None


def _inputs_at(inputs: InputSpec, t: float, last: dict) -> dict[str, float]:
    if inputs is None:
        return {}
    if callable(inputs):
        return dict(inputs(t, last))
    return {k: (v(t) if callable(v) else v) for k, v in inputs.items()}


def run(fmu_unzipped, params: Mapping[str, object] | None = None, inputs: InputSpec = None,
        stop_time: float = 1.0, step: float = 0.01, outputs: Iterable[str] | None = None,
        terrain: str | os.PathLike | None = None, *, stop_when: Callable[[dict], bool] | None = None,
        rover: Rover | None = None, log: LogCapture | None = None) -> dict[str, np.ndarray]:
    """Runs the FMU from t = 0 to stop_time with a fixed communication step.

    params   parameters by name (Real, Integer or String, typed from the model description)
    inputs   {name: value or f(t)}, or a function f(t, last_outputs) -> {name: value}; evaluated
             at the start of every communication step (and at t = 0, before initialisation ends)
    outputs  names to record (default: every output); the record has a "time" array too, and
             sample 0 is the state right after initialisation
    terrain  path of an ESRI ASCII grid (sets terrain.file)
    stop_when  optional predicate on the latest sample dict; the run ends early when it is true

    Returns a dict of numpy arrays, one per recorded name plus "time".
    """
    params = dict(params or {})
    if terrain is not None:
        params["terrain.file"] = str(terrain)
    names = list(outputs) if outputs is not None else output_names(fmu_unzipped)
    own = rover is None
    r = rover if rover is not None else Rover(fmu_unzipped, log=log)
    try:
        u0 = _inputs_at(inputs, 0.0, {})
        r.setup(params, stop_time=stop_time, initial_inputs=u0)
        n = int(round(stop_time / step))
        rec = {k: [] for k in ["time"] + names}

        def record():
            vals = r.get(names)
            sample = dict(zip(names, vals))
            sample["time"] = r.time
            for k in rec:
                rec[k].append(sample[k])
            return sample

        last = record()
        for i in range(n):
            t = i * step
            u = _inputs_at(inputs, t, last)
            if u:
                r.set(u)
            r.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=step)
            r.time = (i + 1) * step
            last = record()
            if stop_when is not None and stop_when(last):
                break
        return {k: np.asarray(v, dtype=float) for k, v in rec.items()}
    finally:
        if own:
            r.free()


# ---------------------------------------------------------------------------------------------
# Terrain grids (ESRI ASCII)
# ---------------------------------------------------------------------------------------------

def write_asc(path, z, x0: float, y0: float, cell: float, nodata: float | None = None) -> str:
    """Writes an ESRI ASCII grid.

    z[j, i] is the elevation of node (column i, row j) with row 0 the SOUTHERNMOST row, at world
    x = x0 + i*cell, y = y0 + j*cell (x0, y0 = centre of the south-west cell, written as
    xllcenter/yllcenter).  The file lists rows from north to south, as the format requires.
    """
    z = np.asarray(z, dtype=float)
    nrows, ncols = z.shape
    lines = [
        f"ncols {ncols}",
        f"nrows {nrows}",
        f"xllcenter {float(x0)!r}",
        f"yllcenter {float(y0)!r}",
        f"cellsize {float(cell)!r}",
    ]
    if nodata is not None:
        lines.append(f"NODATA_value {float(nodata)!r}")
    for j in range(nrows - 1, -1, -1):
        lines.append(" ".join(repr(float(v)) for v in z[j]))
    path = os.fspath(path)
    with open(path, "w", encoding="ascii") as f:
        f.write("\n".join(lines) + "\n")
    return path


@dataclass
class Grid:
    z: np.ndarray       # rows south-first
    x0: float
    y0: float
    cell: float

    def write(self, path) -> str:
        return write_asc(path, self.z, self.x0, self.y0, self.cell)

    def height(self, x: float, y: float) -> float:
        """Bilinear elevation, clamped at the edges (the FMU's convention)."""
        nr, nc = self.z.shape
        u = min(max((x - self.x0) / self.cell, 0.0), nc - 1.0)
        v = min(max((y - self.y0) / self.cell, 0.0), nr - 1.0)
        i, j = min(int(u), nc - 2), min(int(v), nr - 2)
        fx, fy = u - i, v - j
        z = self.z
        return float((1 - fy) * ((1 - fx) * z[j, i] + fx * z[j, i + 1])
                     + fy * ((1 - fx) * z[j + 1, i] + fx * z[j + 1, i + 1]))


def slope_grid(degrees: float, x_range=(-10.0, 10.0), y_range=(-3.0, 3.0), cell: float = 0.25) -> Grid:
    """A plane rising along +x at the given angle: z = tan(degrees) * x."""
    xs = np.arange(x_range[0], x_range[1] + 0.5 * cell, cell)
    ys = np.arange(y_range[0], y_range[1] + 0.5 * cell, cell)
    X, _ = np.meshgrid(xs, ys)
    return Grid(math.tan(math.radians(degrees)) * X, float(xs[0]), float(ys[0]), cell)


def bumpy_grid(seed: int, amplitude: float = 0.04, x_range=(-2.0, 8.0), y_range=(-2.0, 2.0),
               cell: float = 0.05, bump_sigma: float = 0.25, bumps_per_m2: float = 2.0,
               flat_start: float | None = None) -> Grid:
    """Seeded random bumps and dips: a sum of Gaussian bumps of width bump_sigma (m) with random
    signs, scaled so that the largest |z| equals amplitude (m).

    flat_start: if given, the ground is flat (z = 0) for x < flat_start and the bumps fade in over
    the next metre, so that a rover starting at x = 0 starts on level ground."""
    rng = np.random.default_rng(seed)
    xs = np.arange(x_range[0], x_range[1] + 0.5 * cell, cell)
    ys = np.arange(y_range[0], y_range[1] + 0.5 * cell, cell)
    X, Y = np.meshgrid(xs, ys)
    area = (x_range[1] - x_range[0]) * (y_range[1] - y_range[0])
    n = max(1, int(round(bumps_per_m2 * area)))
    cx = rng.uniform(x_range[0], x_range[1], n)
    cy = rng.uniform(y_range[0], y_range[1], n)
    sign = rng.choice([-1.0, 1.0], n) * rng.uniform(0.5, 1.0, n)
    z = np.zeros_like(X)
    for a, b, s in zip(cx, cy, sign):
        z += s * np.exp(-((X - a) ** 2 + (Y - b) ** 2) / (2 * bump_sigma ** 2))
    if flat_start is not None:
        u = np.clip((X - flat_start) / 1.0, 0.0, 1.0)
        z *= u * u * (3 - 2 * u)
    z *= amplitude / np.max(np.abs(z))
    return Grid(z, float(xs[0]), float(ys[0]), cell)


def wheel_names(quantity: str) -> list[str]:
    return [f"wheel{w}.{quantity}" for w in WHEELS]
