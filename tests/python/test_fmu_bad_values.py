"""Bad values into the JunoRover FMU: every one ends in a clear fmi2Error whose message names the
variable, the file (and line) or the cause, and nothing crashes or returns non-finite numbers.

- every parameter of the generated modelDescription.xml outside its declared [min, max], at its
  bounds, and at absurd finite values (+-1e30, 1e-300) inside them;
- NaN and +-Inf for every Real parameter and input; calculated parameters and outputs set;
- terrain grids that are missing, unreadable, empty, truncated or malformed;
- states that diverge (a huge drive torque on wheels of tiny inertia, an absurd speed or load).
"""

from __future__ import annotations

import math
import os
import stat

import numpy as np
import pytest
from fmpy import read_model_description

from fmu_helpers import FMICallException, LogCapture, Rover

H = 0.01
ERROR = 3   # fmi2Error


def _model_variables(fmu_unzipped):
    return read_model_description(str(fmu_unzipped)).modelVariables


def _parameters(fmu_unzipped):
    return [v for v in _model_variables(fmu_unzipped)
            if v.causality == "parameter" and v.type in ("Real", "Integer")]


def _bound(v, which):
    x = getattr(v, which)
    return None if x is None else float(x)


def _out_of_range_cases(fmu_unzipped):
    cases = []
    for v in _parameters(fmu_unzipped):
        lo, hi = _bound(v, "min"), _bound(v, "max")
        if v.type == "Integer":
            if lo is not None:
                cases.append((v.name, v.type, int(lo) - 1))
            if hi is not None:
                cases.append((v.name, v.type, int(hi) + 1))
        else:
            if lo is not None:
                cases.append((v.name, v.type, lo - max(1.0, abs(lo)) * 0.5))
                cases.append((v.name, v.type, math.nextafter(lo, -math.inf)))
            if hi is not None:
                cases.append((v.name, v.type, hi + max(1.0, abs(hi)) * 0.5))
                cases.append((v.name, v.type, math.nextafter(hi, math.inf)))
    return cases


def _in_range_extreme_cases(fmu_unzipped):
    cases = []
    for v in _parameters(fmu_unzipped):
        lo, hi = _bound(v, "min"), _bound(v, "max")
        values = []
        if v.type == "Integer":
            values = [int(lo), int(hi)] if lo is not None and hi is not None else []
        else:
            values.append(lo if lo is not None else -1e30)
            values.append(hi if hi is not None else 1e30)
            if (lo is None or lo <= 1e-300) and (hi is None or hi >= 1e-300):
                values.append(1e-300)
        cases += [(v.name, v.type, x, x in (lo, hi)) for x in values]
    return cases


def _set_param(rover, name, type_, value):
    if type_ == "Integer":
        rover.fmu.setInteger([rover.var(name).vr], [int(value)])
    else:
        rover.fmu.setReal([rover.var(name).vr], [float(value)])


def test_the_table_has_parameters_with_ranges(fmu_unzipped):
    params = _parameters(fmu_unzipped)
    assert len(params) >= 30
    assert len(_out_of_range_cases(fmu_unzipped)) >= 60


def test_every_parameter_outside_its_declared_range_is_refused_naming_it(fmu_unzipped):
    """Refused by fmi2SetReal/fmi2SetInteger, before and during initialisation, with the name."""
    cases = _out_of_range_cases(fmu_unzipped)
    problems = []
    for name, type_, value in cases:
        for during_init in (False, True):
            log = LogCapture()
            with Rover(fmu_unzipped, log=log) as r:
                if during_init:
                    r.fmu.setupExperiment(startTime=0.0)
                    r.fmu.enterInitializationMode()
                try:
                    _set_param(r, name, type_, value)
                    problems.append(f"{name} = {value!r} was accepted")
                    continue
                except FMICallException as e:
                    if e.status != ERROR:
                        problems.append(f"{name} = {value!r}: status {e.status}")
                if not any(name in m and "range" in m for m in log.errors()):
                    problems.append(f"{name} = {value!r}: no message naming it and its range: {log.errors()}")
                # the refused value was not stored
                default = r.get_one(name) if during_init else None
                if during_init and default == value:
                    problems.append(f"{name} = {value!r} was stored although refused")
    assert not problems, f"{len(problems)} of {2 * len(cases)} cases:\n" + "\n".join(problems)


def test_absurd_parameters_inside_their_range_end_cleanly(fmu_unzipped):
    """Bounds and absurd finite values inside the declared ranges: the FMU either runs with finite
    outputs, or refuses with fmi2Error and a message (naming the parameter when the value is a
    declared bound, or the cause: no static equilibrium, divergence, singular matrix)."""
    outcomes = {"ran": 0, "refused at initialisation": 0, "failed in a step": 0}
    problems = []
    for name, type_, value, is_bound in _in_range_extreme_cases(fmu_unzipped):
        log = LogCapture()
        with Rover(fmu_unzipped, log=log) as r:
            try:
                r.fmu.setupExperiment(startTime=0.0)
                r.fmu.enterInitializationMode()
                _set_param(r, name, type_, value)
            except FMICallException as e:
                problems.append(f"{name} = {value!r} inside its range refused by {e.function}: {log.errors()}")
                continue
            try:
                r.fmu.exitInitializationMode()
                r._initialised = True
            except FMICallException as e:
                outcomes["refused at initialisation"] += 1
                msgs = log.errors()
                if e.status != ERROR or not msgs or not msgs[-1].strip():
                    problems.append(f"{name} = {value!r}: refused without a message (status {e.status})")
                elif is_bound and name not in msgs[-1]:
                    problems.append(f"{name} = {value!r} (a declared bound): message does not name it: {msgs[-1]}")
                continue
            try:
                out = r.advance(20, H)
            except FMICallException as e:
                outcomes["failed in a step"] += 1
                msgs = log.errors()
                if e.status != ERROR or not msgs or not msgs[-1].strip():
                    problems.append(f"{name} = {value!r}: step failed without a message (status {e.status})")
                continue
            outcomes["ran"] += 1
            if not np.all(np.isfinite(out)):
                problems.append(f"{name} = {value!r}: fmi2OK but non-finite outputs")
    print("in-range extremes:", outcomes)
    assert outcomes["ran"] > 0 and outcomes["refused at initialisation"] > 0
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf], ids=["nan", "inf", "-inf"])
def test_non_finite_values_are_refused_for_every_real_parameter_and_input(fmu_unzipped, value):
    problems = []
    names = [v.name for v in _model_variables(fmu_unzipped)
             if v.type == "Real" and v.causality in ("parameter", "input")]
    for name in names:
        log = LogCapture()
        with Rover(fmu_unzipped, log=log) as r:
            try:
                r.set({name: value})
                problems.append(f"{name} = {value} accepted")
            except FMICallException as e:
                if e.status != ERROR or not any(name in m and "finite" in m for m in log.errors()):
                    problems.append(f"{name} = {value}: {e.status}, {log.errors()}")
    assert len(names) > 30
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf, 1.5, -1.5], ids=["nan", "inf", "-inf", "1.5", "-1.5"])
def test_bad_inputs_between_steps_are_refused_and_the_run_goes_on(fmu_unzipped, value):
    """During the run: refused (every input for non-finite values, the throttles for values
    outside [-1, 1]); the state is unchanged and the next step works."""
    inputs = [v.name for v in _model_variables(fmu_unzipped) if v.causality == "input"]
    assert len(inputs) == 7
    log = LogCapture()
    with Rover(fmu_unzipped, log=log) as r:
        r.setup({"drive.mode": 2})
        r.advance(5, H)
        for name in inputs:
            if math.isfinite(value) and not name.startswith("throttle"):
                continue
            before = r.get_one(name)
            with pytest.raises(FMICallException) as exc:
                r.set({name: value})
            assert exc.value.status == ERROR
            assert any(name in m for m in log.errors()), log.text()
            assert r.get_one(name) == before
        out = r.advance(5, H)
        assert np.all(np.isfinite(out))


def test_calculated_parameters_and_outputs_cannot_be_set(fmu_unzipped):
    targets = [v.name for v in _model_variables(fmu_unzipped)
               if v.causality in ("calculatedParameter", "output") and v.type == "Real"]
    assert "soil.A1" in targets and "x" in targets
    for name in targets:
        log = LogCapture()
        with Rover(fmu_unzipped, log=log) as r:
            with pytest.raises(FMICallException):
                r.set({name: 1.0})
            assert any(name in m for m in log.errors()), (name, log.text())


# ---------------------------------------------------------------------------------------------
# Terrain grids
# ---------------------------------------------------------------------------------------------

HEADER = "ncols 3\nnrows 3\nxllcenter -1\nyllcenter -1\ncellsize 1\n"
GOOD = HEADER + "0 0 0\n0 0.1 0\n0 0 0\n"

BAD_GRIDS = {
    # name: (file contents, fragments the message must hold besides the file name)
    "empty": ("", ["empty"]),
    "header_only": (HEADER, ["line 5", "found 0"]),
    "truncated_row": (HEADER + "0 0 0\n0 0 0\n0 0\n", ["line 8", "short"]),
    "truncated_rows": (HEADER + "0 0 0\n", ["line 6", "ends before"]),
    "truncated_mid_number": (HEADER + "0 0 0\n0 0 0\n0 0 1e", ["line 8", "not a number"]),
    "extra_value": (HEADER + "0 0 0\n0 0 0\n0 0 0 7\n", ["line 8", "extra value"]),
    "non_numeric": (HEADER + "0 0 0\n0 x 0\n0 0 0\n", ["line 7", "'x'"]),
    "nan_value": (HEADER + "0 0 0\n0 nan 0\n0 0 0\n", ["line 7", "not finite"]),
    "inf_value": (HEADER + "0 0 0\n0 0 0\n0 0 inf\n", ["line 8", "not finite"]),
    "comma_decimal": (HEADER + "0 0 0\n0 0,5 0\n0 0 0\n", ["line 7", "'0,5'"]),
    "unknown_key": ("ncols 3\nnrows 3\nxllcenter -1\nyllcenter -1\ncellsiz 1\n0 0 0\n", ["line 5", "cellsiz"]),
    "missing_cellsize": ("ncols 2\nnrows 2\nxllcenter 0\nyllcenter 0\n1 2\n3 4\n", ["cellsize"]),
    "duplicate_key": ("ncols 2\nncols 2\nnrows 2\nxllcenter 0\nyllcenter 0\ncellsize 1\n1 2\n3 4\n", ["line 2", "duplicate"]),
    "corner_and_center": ("ncols 2\nnrows 2\nxllcorner 0\nxllcenter 0\nyllcenter 0\ncellsize 1\n1 2\n3 4\n", ["line 4", "conflicts"]),
    "negative_cellsize": ("ncols 2\nnrows 2\nxllcenter 0\nyllcenter 0\ncellsize -1\n1 2\n3 4\n", ["cellsize"]),
    "fractional_ncols": ("ncols 2.5\nnrows 2\nxllcenter 0\nyllcenter 0\ncellsize 1\n1 2\n3 4\n", ["line 1", "ncols"]),
    "one_cell": ("ncols 1\nnrows 1\nxllcenter 0\nyllcenter 0\ncellsize 1\n5\n", ["2 x 2"]),
    "huge_dimensions": ("ncols 20000\nnrows 20000\nxllcenter 0\nyllcenter 0\ncellsize 1\n1 2\n", ["too large"]),
    "all_nodata": ("ncols 2\nnrows 2\nxllcenter 0\nyllcenter 0\ncellsize 1\nNODATA_value -9999\n"
                   "-9999 -9999\n-9999 -9999\n", ["NODATA"]),
    "binary_garbage": (None, []),
}


def _terrain_failure(fmu_unzipped, path):
    log = LogCapture()
    with Rover(fmu_unzipped, log=log) as r:
        with pytest.raises(FMICallException) as exc:
            r.setup({"terrain.file": str(path)})
        # the failed initialisation left the Error state: fmi2Reset recovers
        r.fmu.reset()
        r.setup({})
        assert np.isfinite(r.get(["z"])[0])
    assert exc.value.function == "fmi2ExitInitializationMode" and exc.value.status == ERROR
    errors = log.errors()
    assert errors, "no error message"
    return errors[0]


def test_a_good_grid_loads(fmu_unzipped, tmp_path):
    path = tmp_path / "good.asc"
    path.write_text(GOOD)
    with Rover(fmu_unzipped) as r:
        r.setup({"terrain.file": str(path)})
        r.advance(3, H)


@pytest.mark.parametrize("case", sorted(BAD_GRIDS))
def test_bad_terrain_grid_fails_initialisation_naming_file_and_line(fmu_unzipped, tmp_path, case):
    text, fragments = BAD_GRIDS[case]
    path = tmp_path / f"bad {case}.asc"    # a space in the name, too
    if text is None:
        path.write_bytes(bytes(np.random.default_rng(7).integers(0, 256, 4000, dtype=np.uint8)))
    else:
        path.write_text(text)
    message = _terrain_failure(fmu_unzipped, path)
    assert str(path) in message, f"the message does not name the file: {message}"
    for fragment in fragments:
        assert fragment in message, f"{fragment!r} not in: {message}"


def test_missing_terrain_file(fmu_unzipped, tmp_path):
    path = tmp_path / "no such dir" / "terrain.asc"
    message = _terrain_failure(fmu_unzipped, path)
    assert str(path) in message and "cannot open" in message, message


def test_terrain_path_that_is_a_directory(fmu_unzipped, tmp_path):
    """Refused before it is opened, and the FMU recovers after fmi2Reset (test_fmu_hostile.py
    has the devices and FIFOs)."""
    path = tmp_path / "a directory.asc"
    path.mkdir()
    message = _terrain_failure(fmu_unzipped, path)
    assert str(path) in message and "not a regular file (a directory)" in message, message


@pytest.mark.skipif(os.name != "posix", reason="POSIX permissions")
def test_unreadable_terrain_file(fmu_unzipped, tmp_path):
    path = tmp_path / "locked.asc"
    path.write_text(GOOD)
    path.chmod(0)
    try:
        if os.access(path, os.R_OK):
            pytest.skip("running as root (CI does): a chmod 000 file is still readable; "
                        "test_terrain_path_that_is_a_directory covers an unreadable path")
        message = _terrain_failure(fmu_unzipped, path)
        assert str(path) in message and "Permission denied" in message, message
    finally:
        path.chmod(stat.S_IRUSR | stat.S_IWUSR)


# ---------------------------------------------------------------------------------------------
# Diverging states
# ---------------------------------------------------------------------------------------------

DIVERGING = {
    "huge torque, tiny wheel inertia": ({"drive.mode": 0, "wheel.inertia": 1e-6},
                                        {"torqueLeft": 1e6, "torqueRight": 1e6, "drawbarForce": 0.0}),
    "huge torque, tiny rover": ({"drive.mode": 0}, {"torqueLeft": 1e9, "torqueRight": -1e9}),
    "absurd drawbar force": ({"drive.mode": 0}, {"drawbarForce": 1e12}),
    "absurd start speed": ({"init.vx": 1e6}, {}),
}


@pytest.mark.parametrize("case", sorted(DIVERGING))
def test_diverging_state_fails_the_step_naming_the_cause(fmu_unzipped, case):
    params, inputs = DIVERGING[case]
    log = LogCapture()
    with Rover(fmu_unzipped, log=log) as r:
        r.setup(params, initial_inputs={k: 0.0 for k in inputs})
        with pytest.raises(FMICallException) as exc:
            r.advance(300, H, inputs)
        assert exc.value.function == "fmi2DoStep" and exc.value.status == ERROR
        message = log.errors()[-1]
        assert "diverged" in message and "t = " in message, message
        # the outputs of the last good step stay readable and finite; stepping is refused
        assert np.all(np.isfinite(r.get(["x", "z", "vx"])))
        with pytest.raises(FMICallException):
            r.step(H)


@pytest.mark.parametrize("kh", [1e-3, 1.0])
def test_absurdly_soft_soil_is_refused_with_the_cause(fmu_unzipped, kh):
    """soil.kh at or near its declared min is accepted as a value; the rover cannot stand on it."""
    log = LogCapture()
    with Rover(fmu_unzipped, log=log) as r:
        with pytest.raises(FMICallException) as exc:
            r.setup({"soil.kh": kh})
    assert exc.value.function == "fmi2ExitInitializationMode"
    assert "soil too soft" in log.errors()[-1], log.errors()
