"""Specification of the JunoRover FMU as an FMI 2.0 Co-Simulation component (its public interface).

What a co-simulation master and the juno harness rely on: the model description, the names, types,
causalities and units of the public variables, the FMU state (get/set, serialise, into another
instance), independent instances, reset, and clear errors that name the culprit.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
import zipfile

import numpy as np
import pytest
from fmpy import simulate_fmu
from fmpy.validation import validate_fmu

from fmu_helpers import (
    FMICallException,
    LogCapture,
    Rover,
    WHEELS,
    WHEEL_QUANTITIES,
    bumpy_grid,
    output_names,
    run,
    variables,
)

# ---------------------------------------------------------------------------------------------
# The public interface: name -> (causality, type, unit)
# ---------------------------------------------------------------------------------------------

PARAMETERS = {
    "soil.kh": ("Real", None),            # N/m^(2+eta): a unit, but not an SI product
    "soil.eta": ("Real", "1"),
    "soil.gamma": ("Real", "1"),
    "soil.Kvx": ("Real", "1"),
    "soil.cohesion": ("Real", "Pa"),
    "soil.phi": ("Real", "rad"),
    "wheel.radius": ("Real", "m"),
    "wheel.width": ("Real", "m"),
    "wheel.mass": ("Real", "kg"),
    "rover.mass": ("Real", "kg"),
    "terrain.file": ("String", None),
    "drive.mode": ("Integer", None),
    "init.x": ("Real", "m"),
    "init.y": ("Real", "m"),
    "init.yaw": ("Real", "rad"),
    "init.vx": ("Real", "m/s"),
}
INPUTS = {
    "drawbarForce": "N",
    "torqueLeft": "N.m",
    "torqueRight": "N.m",
    "omegaRefLeft": "rad/s",
    "omegaRefRight": "rad/s",
    "throttleLeft": "1",
    "throttleRight": "1",
}
WHEEL_UNITS = {"sinkage": "m", "slip": "1", "Fn": "N", "Ft": "N", "Fx": "N", "Fy": "N", "Fz": "N"}
OUTPUTS = {
    "x": "m", "y": "m", "z": "m",
    "roll": "rad", "pitch": "rad", "yaw": "rad",
    "vx": "m/s",
    "omegaLeft": "rad/s", "omegaRight": "rad/s",
    "torqueLeftApplied": "N.m", "torqueRightApplied": "N.m",
    **{f"wheel{w}.{q}": WHEEL_UNITS[q] for w in WHEELS for q in WHEEL_QUANTITIES},
}
# Paper Table 2 (run 2) and the Juno rover's data (assumptions where the paper is silent): the
# documented defaults.
DEFAULTS = {
    "soil.kh": 1.58e5, "soil.eta": 0.501, "soil.gamma": 0.0813, "soil.Kvx": 0.819,
    "wheel.radius": 0.2794, "wheel.width": 0.254, "wheel.mass": 9.6, "rover.mass": 317.7,
}


def _md_root(fmu_path):
    with zipfile.ZipFile(fmu_path) as zf:
        return ET.fromstring(zf.read("modelDescription.xml"))


def _bits(a) -> bytes:
    """Exact bytes of a float array: equality of these is bit-for-bit equality (NaN and -0.0 too)."""
    return np.ascontiguousarray(np.asarray(a, dtype=np.float64)).tobytes()


def _assert_bit_identical(a, b, what: str):
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    assert a.shape == b.shape, f"{what}: shapes {a.shape} and {b.shape} differ"
    if _bits(a) != _bits(b):
        diff = np.argwhere(~((a == b) | (np.isnan(a) & np.isnan(b))))
        i = tuple(diff[0]) if len(diff) else None
        raise AssertionError(
            f"{what}: not bit-identical; {len(diff)} of {a.size} values differ, first at {i}: "
            f"{a[i]!r} vs {b[i]!r}"
        )


# A busy scenario for the state tests: bumpy terrain, PID drive (with its integral state), a
# varying drawbar force and unequal, changing wheel-spin references (skid steering).
def _busy_inputs(t, last=None):
    return {
        "drawbarForce": 150.0 + 100.0 * math.sin(0.9 * t),
        "omegaRefLeft": 1.0 + 0.3 * math.sin(0.7 * t),
        "omegaRefRight": 1.2 - 0.2 * math.cos(0.5 * t),
    }


@pytest.fixture(scope="module")
def busy_params(tmp_path_factory):
    path = tmp_path_factory.mktemp("terrain") / "bumpy.asc"
    bumpy_grid(seed=11, amplitude=0.04, x_range=(-2.0, 6.0), y_range=(-3.0, 3.0), flat_start=0.8).write(path)
    return {"drive.mode": 1, "terrain.file": str(path), "soil.kh": 1.7e5}


# ---------------------------------------------------------------------------------------------
# Model description
# ---------------------------------------------------------------------------------------------

def test_fmpy_validation_finds_no_problems(fmu_path):
    problems = validate_fmu(fmu_path)
    assert problems == [], "fmpy.validation.validate_fmu found problems:\n" + "\n".join(problems)


def test_model_description_header(fmu_path):
    root = _md_root(fmu_path)
    assert root.get("fmiVersion") == "2.0"
    assert root.get("modelName") == "JunoRover"
    assert root.get("variableNamingConvention") == "structured"
    cs = root.find("CoSimulation")
    assert cs is not None, "no <CoSimulation> element: the FMU must be Co-Simulation"
    assert cs.get("modelIdentifier") == "JunoRover"
    assert cs.get("canGetAndSetFMUstate") == "true"
    assert cs.get("canSerializeFMUstate") == "true"
    de = root.find("DefaultExperiment")
    assert de is not None and float(de.get("stopTime")) == pytest.approx(30.0)


def test_every_real_variable_has_a_defined_unit(fmu_path):
    root = _md_root(fmu_path)
    defined = {u.get("name") for u in root.iter("Unit")}
    types = {t.get("name"): t.find("Real") for t in root.iter("SimpleType") if t.find("Real") is not None}
    missing, undefined = [], []
    for sv in root.find("ModelVariables"):
        real = sv.find("Real")
        if real is None:
            continue
        unit = real.get("unit")
        if unit is None and real.get("declaredType") in types:
            unit = types[real.get("declaredType")].get("unit")
        if not unit:
            missing.append(sv.get("name"))
        elif unit not in defined:
            undefined.append(f"{sv.get('name')} ({unit})")
    assert not missing, f"Real variables without a unit: {missing}"
    assert not undefined, f"units used but not in <UnitDefinitions>: {undefined}"


@pytest.mark.parametrize("name", sorted(PARAMETERS))
def test_public_parameter(fmu_unzipped, name):
    vs = variables(fmu_unzipped)
    assert name in vs, f"parameter {name!r} is missing"
    v = vs[name]
    type_, unit = PARAMETERS[name]
    assert v.causality == "parameter", f"{name}: causality {v.causality!r}, expected 'parameter'"
    assert v.type == type_, f"{name}: type {v.type}, expected {type_}"
    if unit is not None:
        assert v.unit == unit, f"{name}: unit {v.unit!r}, expected {unit!r}"
    elif type_ == "Real":
        assert v.unit, f"{name}: no unit"
    if name in DEFAULTS:
        assert float(v.start) == pytest.approx(DEFAULTS[name], rel=1e-12), f"{name}: start {v.start}"


def test_drive_mode_and_terrain_defaults(fmu_unzipped):
    vs = variables(fmu_unzipped)
    assert int(vs["drive.mode"].start) in (0, 1, 2)
    assert (vs["terrain.file"].start or "") == "", "default terrain must be flat ground (empty terrain.file)"


@pytest.mark.parametrize("name", sorted(INPUTS))
def test_public_input(fmu_unzipped, name):
    vs = variables(fmu_unzipped)
    assert name in vs, f"input {name!r} is missing"
    v = vs[name]
    assert v.causality == "input", f"{name}: causality {v.causality!r}, expected 'input'"
    assert v.type == "Real"
    assert v.unit == INPUTS[name], f"{name}: unit {v.unit!r}, expected {INPUTS[name]!r}"
    assert v.start is not None, f"{name}: an input needs a start value"


@pytest.mark.parametrize("name", sorted(OUTPUTS))
def test_public_output(fmu_unzipped, name):
    vs = variables(fmu_unzipped)
    assert name in vs, f"output {name!r} is missing"
    v = vs[name]
    assert v.causality == "output", f"{name}: causality {v.causality!r}, expected 'output'"
    assert v.type == "Real"
    assert v.unit == OUTPUTS[name], f"{name}: unit {v.unit!r}, expected {OUTPUTS[name]!r}"


# ---------------------------------------------------------------------------------------------
# Running
# ---------------------------------------------------------------------------------------------

def test_simulate_fmu_default_experiment_is_finite(fmu_path):
    result = simulate_fmu(fmu_path)
    assert result["time"][-1] == pytest.approx(30.0)
    names = [n for n in result.dtype.names if n != "time"]
    assert set(OUTPUTS) <= set(names), f"outputs missing from the result: {set(OUTPUTS) - set(names)}"
    bad = [n for n in names if not np.all(np.isfinite(result[n]))]
    assert not bad, f"non-finite values in {bad}"
    # the default experiment drives (throttle 0.45 against the 400 N default drawbar): it moves
    assert result["x"][-1] > 0.5, f"default experiment moved only {result['x'][-1]:.3f} m"


def test_initial_pose_follows_init_parameters(fmu_unzipped):
    r = run(fmu_unzipped, {"init.x": 1.5, "init.y": -2.0, "init.yaw": 0.7, "drive.mode": 0},
            {"drawbarForce": 0.0}, stop_time=0.0, outputs=["x", "y", "yaw", "vx"])
    assert r["x"][0] == pytest.approx(1.5, abs=1e-9)
    assert r["y"][0] == pytest.approx(-2.0, abs=1e-9)
    assert r["yaw"][0] == pytest.approx(0.7, abs=1e-9)
    assert r["vx"][0] == pytest.approx(0.0, abs=1e-12)


# ---------------------------------------------------------------------------------------------
# FMU state
# ---------------------------------------------------------------------------------------------

H = 0.01


def test_get_set_fmu_state_replays_bit_for_bit(fmu_unzipped, busy_params):
    names = output_names(fmu_unzipped)
    with Rover(fmu_unzipped) as r:
        r.setup(busy_params, initial_inputs=_busy_inputs(0.0))
        r.advance(200, H, _busy_inputs, names)                   # 0 .. 2 s
        state = r.fmu.getFMUstate()
        t_saved = r.time
        first = r.advance(300, H, _busy_inputs, names)           # 2 .. 5 s
        assert np.ptp(first[:, names.index("x")]) > 0.1, "the scenario should move the rover"
        r.fmu.setFMUstate(state)
        r.time = t_saved
        again = r.advance(300, H, _busy_inputs, names)
        r.fmu.freeFMUstate(state)
    _assert_bit_identical(first, again, "outputs after fmi2SetFMUstate")


def test_serialized_state_replays_bit_for_bit_in_same_and_second_instance(fmu_unzipped, busy_params):
    names = output_names(fmu_unzipped)
    with Rover(fmu_unzipped, instance_name="A") as a, Rover(fmu_unzipped, instance_name="B") as b:
        a.setup(busy_params, initial_inputs=_busy_inputs(0.0))
        a.advance(200, H, _busy_inputs, names)
        state = a.fmu.getFMUstate()
        blob = a.fmu.serializeFMUstate(state)
        a.fmu.freeFMUstate(state)
        assert isinstance(blob, bytes) and len(blob) > 0
        t_saved = a.time
        first = a.advance(300, H, _busy_inputs, names)

        # back into the same instance, through the bytes
        restored = a.fmu.deSerializeFMUstate(blob)
        a.fmu.setFMUstate(restored)
        a.fmu.freeFMUstate(restored)
        a.time = t_saved
        same = a.advance(300, H, _busy_inputs, names)

        # into a second, initialised instance of the same FMU (same parameters and terrain)
        b.setup(busy_params, initial_inputs=_busy_inputs(0.0))
        b.advance(7, H, {"drawbarForce": 900.0, "omegaRefLeft": -1.0})  # disturb it first
        restored_b = b.fmu.deSerializeFMUstate(blob)
        b.fmu.setFMUstate(restored_b)
        b.fmu.freeFMUstate(restored_b)
        b.time = t_saved
        other = b.advance(300, H, _busy_inputs, names)
    _assert_bit_identical(first, same, "same instance after deSerializeFMUstate")
    _assert_bit_identical(first, other, "second instance after deSerializeFMUstate")


def test_corrupted_serialized_state_is_refused(fmu_unzipped):
    log = LogCapture()
    with Rover(fmu_unzipped, log=log) as r:
        r.setup({"drive.mode": 0})
        state = r.fmu.getFMUstate()
        blob = bytearray(r.fmu.serializeFMUstate(state))
        r.fmu.freeFMUstate(state)
        blob[len(blob) // 2] ^= 0xFF
        with pytest.raises(FMICallException):
            r.fmu.deSerializeFMUstate(bytes(blob))
        with pytest.raises(FMICallException):
            r.fmu.deSerializeFMUstate(bytes(blob[:-3]))
    assert log.errors(), "a refused state must be explained in the log"


def test_two_instances_interleaved_equal_each_run_alone(fmu_unzipped, busy_params):
    names = output_names(fmu_unzipped)
    pa = dict(busy_params)
    pb = {"drive.mode": 2, "soil.gamma": 0.3, "soil.kh": 1.2e5, "init.yaw": 0.4}
    ua = _busy_inputs
    ub = {"drawbarForce": 300.0, "throttleLeft": 0.5, "throttleRight": 0.4}
    n = 250
    with Rover(fmu_unzipped, instance_name="A") as a, Rover(fmu_unzipped, instance_name="B") as b:
        a.setup(pa, initial_inputs=ua(0.0))
        b.setup(pb, initial_inputs=ub)
        ya, yb = np.empty((n, len(names))), np.empty((n, len(names)))
        for i in range(n):
            t = i * H          # the same communication points as run() uses
            ya[i] = a.step_at(t, H, ua, names)
            yb[i] = b.step_at(t, H, ub, names)
    alone_a = run(fmu_unzipped, pa, ua, stop_time=n * H, step=H, outputs=names)
    alone_b = run(fmu_unzipped, pb, ub, stop_time=n * H, step=H, outputs=names)
    _assert_bit_identical(ya, np.column_stack([alone_a[k][1:] for k in names]), "instance A interleaved vs alone")
    _assert_bit_identical(yb, np.column_stack([alone_b[k][1:] for k in names]), "instance B interleaved vs alone")
    assert not np.array_equal(ya, yb), "different parameters must give different results"


def test_importer_tolerance_leaves_the_internal_step_to_solver_tolerance(fmu_unzipped):
    """fmi2SetupExperiment's tolerance (relative, the importer's) does not set the automatic step's
    tolerance (solver.tolerance, absolute, in m/s): the same parameters give bit-identical runs
    whatever tolerance an importer passes, and the FMU logs (logEvents) that it does not use it."""
    names = output_names(fmu_unzipped)
    params = {"drive.mode": 2}
    inputs = {"drawbarForce": 300.0, "throttleLeft": 0.5, "throttleRight": 0.4}
    n = 100

    def outputs_after(tolerance, solver_tolerance=None, log=None):
        p = dict(params, **({"solver.tolerance": solver_tolerance} if solver_tolerance is not None else {}))
        with Rover(fmu_unzipped, log=log, logging_on=log is not None) as r:
            r.setup(p, initial_inputs=inputs, tolerance=tolerance)
            return r.advance(n, H, inputs, names)

    log = LogCapture()
    undefined = outputs_after(None)
    for tolerance in (1e-9, 1e-4, 0.5):
        _assert_bit_identical(outputs_after(tolerance, log=log if tolerance == 1e-4 else None), undefined,
                              f"importer tolerance {tolerance} vs none")
    # the check can fail: the automatic step is in use and follows solver.tolerance
    assert not np.array_equal(outputs_after(None, solver_tolerance=1e-5), undefined)
    notes = [text for _, category, text in log.messages if category == "logEvents" and "fmi2SetupExperiment" in text]
    assert any("0.0001" in t and "not used" in t and "solver" in t for t in notes), log.text()


def test_reset_returns_to_the_start(fmu_unzipped, busy_params):
    names = output_names(fmu_unzipped)
    with Rover(fmu_unzipped) as r:
        r.setup(busy_params, initial_inputs=_busy_inputs(0.0))
        y0_first = r.get(names)
        first = r.advance(200, H, _busy_inputs, names)
        r.fmu.terminate()
        r.fmu.reset()
        r.time = 0.0
        r.setup(busy_params, initial_inputs=_busy_inputs(0.0))
        y0_again = r.get(names)
        again = r.advance(200, H, _busy_inputs, names)
        _assert_bit_identical(y0_first, y0_again, "state at t = 0 after fmi2Reset")
        _assert_bit_identical(first, again, "outputs after fmi2Reset")

        # reset also forgets every parameter (back to the start values), including terrain.file
        r.fmu.reset()
        r.time = 0.0
        r.setup({})
        after_reset_defaults = r.get(names)
        assert r.get_one("terrain.file") in ("", b"")
    fresh = run(fmu_unzipped, {}, None, stop_time=0.0, outputs=names)
    _assert_bit_identical(after_reset_defaults, [fresh[k][0] for k in names], "reset + defaults vs a fresh instance")


def test_reset_recovers_from_a_failed_initialisation(fmu_unzipped):
    log = LogCapture()
    with Rover(fmu_unzipped, log=log) as r:
        with pytest.raises(FMICallException):
            r.setup({"soil.eta": 0.0})
        r.fmu.reset()
        r.setup({"drive.mode": 0})
        r.advance(10, H, {"drawbarForce": 0.0})
        assert np.isfinite(r.get(["z"])[0])


def test_parameters_cannot_change_after_initialisation(fmu_unzipped):
    log = LogCapture()
    with Rover(fmu_unzipped, log=log) as r:
        r.setup({"drive.mode": 0})
        with pytest.raises(FMICallException):
            r.set({"soil.kh": 2.0e5})
        assert any("soil.kh" in m for m in log.errors()), log.text()
        assert r.get_one("soil.kh") == pytest.approx(1.58e5)


# ---------------------------------------------------------------------------------------------
# Errors name the culprit
# ---------------------------------------------------------------------------------------------

BAD_PARAMETERS = [
    ("soil.eta", 0.0),
    ("soil.eta", -0.5),
    ("soil.gamma", 1.5),
    ("soil.gamma", -0.1),
    ("rover.mass", 0.0),
    ("rover.mass", -10.0),
    ("soil.kh", 0.0),
    ("soil.kh", -1.0e5),
    ("wheel.radius", 0.0),
    ("wheel.radius", -0.2),
]


@pytest.mark.parametrize("name,value", BAD_PARAMETERS, ids=[f"{n}={v}" for n, v in BAD_PARAMETERS])
def test_bad_parameter_is_refused_naming_it(fmu_unzipped, name, value):
    """Refused at fmi2SetReal (outside the declared range) or at fmi2ExitInitializationMode
    (inside the range but physically invalid); either way fmi2Error and a message naming it."""
    log = LogCapture()
    with Rover(fmu_unzipped, log=log) as r:
        with pytest.raises(FMICallException) as exc:
            r.setup({name: value})
    assert exc.value.function in ("fmi2SetReal", "fmi2ExitInitializationMode"), exc.value.function
    assert exc.value.status == 3, "expected fmi2Error"
    errors = log.errors()
    assert errors, "the FMU logged no error message"
    assert any(name in m for m in errors), f"no error message names {name!r}: {errors}"


@pytest.mark.parametrize("name", ["drawbarForce", "torqueLeft"])
@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf], ids=["nan", "inf", "-inf"])
def test_non_finite_input_is_refused_naming_it(fmu_unzipped, name, value):
    log = LogCapture()
    with Rover(fmu_unzipped, log=log) as r:
        r.setup({"drive.mode": 0})
        r.advance(2, H, {"drawbarForce": 0.0})
        with pytest.raises(FMICallException) as exc:
            r.set({name: value})
            r.advance(1, H)
    assert exc.value.status == 3, "expected fmi2Error"
    errors = log.errors()
    assert any(name in m for m in errors), f"no error message names {name!r}: {errors}"


def test_missing_terrain_file_fails_initialisation_naming_it(fmu_unzipped, tmp_path):
    missing = tmp_path / "no_such_terrain.asc"
    log = LogCapture()
    with Rover(fmu_unzipped, log=log) as r:
        with pytest.raises(FMICallException) as exc:
            r.setup({"terrain.file": str(missing)})
    assert exc.value.function == "fmi2ExitInitializationMode"
    errors = log.errors()
    assert any("no_such_terrain.asc" in m for m in errors), f"no error message names the file: {errors}"
