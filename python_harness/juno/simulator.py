"""Running the JunoRover FMU through fmpy.

The FMU is extracted once per :class:`JunoFMU`; one FMI instance is created
lazily and reused for every simulation (``fmi2Reset`` between runs), so a
cost function can call :meth:`JunoFMU.simulate` hundreds of times cheaply.

Inputs are given as sampled signals and applied sample-and-hold at each
communication point (the value at the start of the step), which is what a
co-simulation master does.
"""

from __future__ import annotations

import ctypes
import os
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Mapping, Sequence

import numpy as np
import fmpy
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE
from fmpy.fmi2 import fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE

from .rover_model import SOIL_PARAMETERS  # noqa: F401  (re-exported: the names the harness fits)

WHEELS = ("FL", "RL", "FR", "RR")
WHEEL_SIGNALS = ("sinkage", "slip", "Fn", "Ft", "Fx", "Fy", "Fz")

#: Outputs recorded when the caller does not choose.
DEFAULT_OUTPUTS = (
    "x", "y", "z", "roll", "pitch", "yaw", "vx", "omegaLeft", "omegaRight",
    "torqueLeftApplied", "torqueRightApplied", "rocker",
) + tuple(f"wheel{w}.{s}" for w in WHEELS for s in WHEEL_SIGNALS)


#: What to do when the FMU is not where it was looked for (every "FMU not found" says it).
FMU_HINT = ("build it in the source checkout (cmake -S . -B build && cmake --build build), then give "
            "its path with --fmu or the environment variable JUNO_FMU")


#: Where an installed package carries its FMU (scripts/setup.sh copies the built FMU there, and
#: pyproject.toml ships it as package data), so that ``juno`` runs outside the checkout.
PACKAGED_FMU = Path(__file__).resolve().parent / "data" / "JunoRover.fmu"


def default_fmu_path() -> Path:
    """Path of the FMU: $JUNO_FMU; else build/JunoRover.fmu of the checkout this package is in,
    if built; else the FMU the installed package carries (PACKAGED_FMU)."""
    env = os.environ.get("JUNO_FMU")
    if env:
        return Path(env)
    checkout = Path(__file__).resolve().parents[2] / "build" / "JunoRover.fmu"
    if checkout.is_file() or not PACKAGED_FMU.is_file():
        return checkout
    return PACKAGED_FMU


class SimulationError(RuntimeError):
    """The FMU refused a parameter or input, or the simulation diverged.

    ``what`` says which step failed, ``messages`` holds what the FMU logged (its reasons),
    ``time`` the simulation time (s) at which it stopped (None before the first step), and
    ``run`` / ``file`` the measured run being replayed and its data file, once a caller that
    knows them has attached them (:meth:`located`).  The text reads, for example::

        run 'dbp1' (runs/dbp1.csv): simulation stopped at t = 3.250 s: Wheel FL sank below ...
    """

    def __init__(self, what: str, messages: Sequence[str], time: float | None = None,
                 run: str | None = None, file: str | None = None):
        self.what = str(what)
        self.messages = [str(m) for m in messages]
        self.time = None if time is None else float(time)
        self.run = run
        self.file = file
        super().__init__(self._text())

    def _text(self) -> str:
        detail = "; ".join(self.messages[-3:]) if self.messages else "no message logged"
        where = ""
        if self.run is not None:
            where = f"run '{self.run}'" + (f" ({self.file})" if self.file else "") + ": "
        elif self.file:
            where = f"{self.file}: "
        return f"{where}{self.what}: {detail}"

    def located(self, run: str | None, file: str | None) -> "SimulationError":
        """A copy naming the measured run ``run`` and its data file ``file``."""
        return SimulationError(self.what, self.messages, self.time, run, file)

    def __reduce__(self):
        # Rebuilt from its fields when it crosses a process boundary (a task's error).
        return (SimulationError, (self.what, self.messages, self.time, self.run, self.file))


@dataclass
class InputSignals:
    """Sampled FMU inputs: ``time`` (s, ascending) and FMU input name -> values."""

    time: np.ndarray
    values: dict[str, np.ndarray] = field(default_factory=dict)

    def at(self, t: float) -> dict[str, float]:
        """Linear interpolation of every input at time ``t`` (s), held at the ends."""
        return {name: float(np.interp(t, self.time, v)) for name, v in self.values.items()}

    @staticmethod
    def constant(**values: float) -> "InputSignals":
        """Inputs held at constant values."""
        return InputSignals(np.array([0.0, 1.0]), {k: np.array([v, v], float) for k, v in values.items()})


class JunoFMU:
    """One extracted JunoRover FMU and a reusable instance of it."""

    def __init__(self, fmu_path: str | os.PathLike | None = None, solver_step: float | None = None):
        self.fmu_path = Path(fmu_path) if fmu_path else default_fmu_path()
        if not self.fmu_path.is_file():
            raise FileNotFoundError(f"{self.fmu_path}: FMU not found: {FMU_HINT}")
        self.model_description = read_model_description(str(self.fmu_path))
        self._tmp = tempfile.mkdtemp(prefix="juno-fmu-")
        self.unzip_dir = extract(str(self.fmu_path), unzipdir=self._tmp)
        self.variables = {v.name: v for v in self.model_description.modelVariables}
        self.solver_step = solver_step
        self._slave: FMU2Slave | None = None
        self._messages: list[str] = []
        self._callbacks = None
        self._raw: _RawFMI | None = None
        self._initialised_once = False

    # -- life cycle -------------------------------------------------------
    def close(self) -> None:
        if self._slave is not None:
            try:
                self._slave.freeInstance()
            except Exception:
                pass
            self._slave = None
        shutil.rmtree(self._tmp, ignore_errors=True)

    def __enter__(self) -> "JunoFMU":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __getstate__(self):
        """Pickle as just the path (for process pools): each process extracts its own copy."""
        return {"fmu_path": str(self.fmu_path), "solver_step": self.solver_step}

    def __setstate__(self, state):
        self.__init__(state["fmu_path"], state["solver_step"])

    def _log(self, component, instance_name, status, category, message):
        """The FMU's logger: keeps the messages of status error or worse.  The FMU passes each
        message whole, as a printf format without arguments, so only its '%%' need reading."""
        text = message.decode("utf-8", "replace") if isinstance(message, bytes) else str(message)
        text = text.replace("%%", "%")
        if status >= 2:  # discard, error, fatal
            self._messages.append(text)

    def _instance(self) -> FMU2Slave:
        if self._slave is None:
            md = self.model_description
            slave = FMU2Slave(guid=md.guid, unzipDirectory=self.unzip_dir,
                              modelIdentifier=md.coSimulation.modelIdentifier, instanceName="juno")
            callbacks = fmi2CallbackFunctions()
            callbacks.logger = fmi2CallbackLoggerTYPE(self._log)
            callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(_calloc)
            callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(_free)
            # No fmpy logger proxy: it keeps one logger per process, so a second instance would
            # receive this one's messages.  The FMU formats its messages itself (_log).
            self._callbacks = callbacks
            slave.instantiate(callbacks=callbacks)
            self._raw = _RawFMI(slave.dll)
            self._slave = slave
        else:
            self._slave.reset()
        return self._slave

    def _call(self, what: str, fn, *args, time: float | None = None):
        try:
            return fn(*args)
        except Exception as exc:  # fmpy raises on fmi2Error
            raise SimulationError(what, self._messages or [str(exc)], time) from exc

    # -- variables --------------------------------------------------------
    def _set(self, slave: FMU2Slave, values: Mapping[str, object]) -> None:
        reals, ints, strs = {}, {}, {}
        for name, value in values.items():
            var = self.variables.get(name)
            if var is None:
                raise KeyError(f"the FMU has no variable '{name}'")
            try:
                if var.type == "Real":
                    reals[var.valueReference] = float(value)
                elif var.type == "Integer":
                    ints[var.valueReference] = int(value)
            except (TypeError, ValueError):
                raise ValueError(f"parameter '{name}' needs a number, got {value!r}") from None
            if var.type in ("Real", "Integer"):
                pass
            elif var.type == "String":
                strs[var.valueReference] = str(value)
            else:
                raise KeyError(f"variable '{name}' has unsupported type {var.type}")
        if reals:
            self._call("setting parameters",
                       slave.setReal, list(reals), list(reals.values()))
        if ints:
            self._call("setting integers", slave.setInteger, list(ints), list(ints.values()))
        if strs:
            self._call("setting strings", slave.setString, list(strs), list(strs.values()))

    def real_vrs(self, names: Iterable[str]) -> list[int]:
        out = []
        for n in names:
            var = self.variables.get(n)
            if var is None or var.type != "Real":
                raise KeyError(f"the FMU has no Real variable '{n}'")
            out.append(var.valueReference)
        return out

    # -- simulation -------------------------------------------------------
    def simulate(self, parameters: Mapping[str, object], inputs: InputSignals | None,
                 stop_time: float, output_interval: float = 0.05,
                 outputs: Iterable[str] = DEFAULT_OUTPUTS, start_time: float = 0.0) -> dict[str, np.ndarray]:
        """Simulates from ``start_time`` to ``stop_time`` (s).

        ``parameters``: FMU parameter name -> value (set before initialisation).
        ``inputs``: sampled inputs, or None for the FMU's start values.
        Returns output name -> array at the communication points, plus ``time``.
        Raises :class:`SimulationError` with the FMU's message on failure.
        """
        self._messages.clear()
        slave = self._instance()
        params = dict(parameters)
        if self.solver_step is not None and "solver.step" not in params:
            params["solver.step"] = self.solver_step
        if not (np.isfinite(output_interval) and output_interval > 0):
            raise ValueError(f"output_interval must be a positive number of seconds, got {output_interval}")
        n_steps = int(round((stop_time - start_time) / output_interval))
        if n_steps < 1:
            raise ValueError(f"stop_time {stop_time} must exceed start_time {start_time} by an output interval")
        names = list(outputs)
        out_vrs = self.real_vrs(names)
        in_names = list(inputs.values) if inputs is not None else []
        in_vrs = self.real_vrs(in_names)
        times = start_time + output_interval * np.arange(n_steps + 1)
        data = np.empty((n_steps + 1, len(names)))
        if inputs is not None:
            in_table = np.column_stack([np.interp(times, inputs.time, inputs.values[n]) for n in in_names])
        self._call("setupExperiment", slave.setupExperiment, None, start_time, time=start_time)
        self._set(slave, params)
        if inputs is not None:
            self._call("setting inputs", slave.setReal, in_vrs, list(in_table[0]))
        self._call("initialisation", slave.enterInitializationMode, time=start_time)
        self._call("initialisation", slave.exitInitializationMode, time=start_time)
        # The stepping loop calls the FMI functions through ctypes directly (_RawFMI): fmpy's
        # getReal/setReal build ctypes arrays and Python lists on every call.  Outputs go straight
        # into their row of `data`; an input row equal to the one already set (sample-and-hold of
        # a held signal) is not set again, which leaves the FMU's inputs as they are either way.
        # The loop itself is plain Python over precomputed lists (the step's start times as floats,
        # the address of each input row and output row): about a tenth of a drawbar run's
        # simulation is this loop, so nothing is converted or copied per step.
        raw = self._raw
        comp = slave.component
        n_out, n_in = len(out_vrs), len(in_vrs)
        out_vr = (ctypes.c_uint * n_out)(*out_vrs)
        in_vr = (ctypes.c_uint * n_in)(*in_vrs)
        row0, row_bytes = data.ctypes.data, data.strides[0]
        if n_out and raw.get_real(comp, out_vr, n_out, row0) > _FMI2_WARNING:
            raise SimulationError("reading outputs after initialisation", self._messages, start_time)
        step_starts = times[:n_steps].tolist()
        out_rows = [row0 + (k + 1) * row_bytes for k in range(n_steps)] if n_out else [0] * n_steps
        in_rows = [0] * n_steps                 # 0: the inputs are as they were (nothing to set)
        if inputs is not None:
            in_table = np.ascontiguousarray(in_table, dtype=np.float64)
            changed = np.any(in_table[1:n_steps] != in_table[:n_steps - 1], axis=1)   # row 0 is set already
            in0, in_bytes = in_table.ctypes.data, in_table.strides[0]
            for k in np.flatnonzero(changed).tolist():
                in_rows[k + 1] = in0 + (k + 1) * in_bytes
        do_step, get_real, set_real = raw.do_step, raw.get_real, raw.set_real
        for k, (t, in_row, out_row) in enumerate(zip(step_starts, in_rows, out_rows)):
            if in_row and set_real(comp, in_vr, n_in, in_row) > _FMI2_WARNING:
                raise SimulationError(f"simulation stopped at t = {t:.3f} s", self._messages, t)
            if do_step(comp, t, output_interval, 1) > _FMI2_WARNING:
                raise SimulationError(f"simulation stopped at t = {t:.3f} s", self._messages, t)
            if n_out and get_real(comp, out_vr, n_out, out_row) > _FMI2_WARNING:
                raise SimulationError(f"reading outputs at t = {times[k + 1]:.3f} s", self._messages, times[k + 1])
        self._call("terminate", slave.terminate)
        result = {"time": times}
        for i, n in enumerate(names):
            result[n] = data[:, i]
        return result


_FMI2_WARNING = 1   # fmi2Status: OK 0, Warning 1, Discard 2, Error 3, Fatal 4, Pending 5


class _RawFMI:
    """fmi2SetReal, fmi2DoStep and fmi2GetReal of an instance's shared library as plain ctypes
    functions (the stepping loop's; fmpy's wrappers convert lists on every call).  Each returns
    the fmi2Status; value arrays are passed as addresses."""

    # Own prototypes (not dll.fmi2GetReal, the object fmpy configures for itself).
    _ARRAY_CALL = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p)
    _DO_STEP = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_int)

    def __init__(self, dll: ctypes.CDLL):
        self.set_real = self._ARRAY_CALL(("fmi2SetReal", dll))
        self.get_real = self._ARRAY_CALL(("fmi2GetReal", dll))
        self.do_step = self._DO_STEP(("fmi2DoStep", dll))


def _calloc(nobj, size):
    """The FMU's allocateMemory: the C library's calloc, as fmpy finds it on this platform
    (the C runtime on Windows, libc elsewhere)."""
    return fmpy.calloc(nobj, size)


def _free(ptr):
    """The FMU's freeMemory: the C library's free (see _calloc)."""
    fmpy.free(ptr)
