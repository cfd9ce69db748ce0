"""The JunoRover FMU in more than one importer.

- libcosim (DNV's co-simulation library, PyPI package libcosimpy; scripts/checks.sh installs it
  into .venv) loads and steps build/JunoRover.fmu and gives fmpy's results: bit for bit when fmpy
  is driven on libcosim's clock, to 1e-9 on fmpy's own.
- fmpy validates the model description (schema, names, model structure), also of the source-code
  FMU without binaries.
- fmpy compiles the source-code FMU (a copy stripped of binaries) into a binary that gives the
  CMake-built binary's results bit for bit.
"""

from __future__ import annotations

import re
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract
from fmpy.validation import validate_fmu

from fmu_helpers import Rover, bumpy_grid, output_names, run, variables

H = 0.01
N = 200

# A busy scenario: PID drive (integral state), a terrain grid, inputs that jump during the run.
PARAMS = {"drive.mode": 1, "soil.kh": 1.7e5, "soil.gamma": 0.12, "init.yaw": 0.2}


def inputs(t, last=None):
    return {
        "drawbarForce": 150.0 if t < 1.0 else 350.0,
        "omegaRefLeft": 1.0,
        "omegaRefRight": 1.3 if t >= 0.5 else 1.0,
    }


@pytest.fixture(scope="module")
def terrain(tmp_path_factory):
    path = tmp_path_factory.mktemp("importers") / "bumpy terrain.asc"   # a space in the path
    bumpy_grid(seed=5, amplitude=0.03, x_range=(-2.0, 5.0), y_range=(-2.0, 3.0), flat_start=0.6).write(path)
    return str(path)


@pytest.fixture(scope="module")
def libcosim():
    pytest.importorskip("libcosimpy", reason="libcosimpy is not installed (scripts/checks.sh installs it)")
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level

    log_output_level(CosimLogLevel.ERROR)
    import libcosimpy.CosimExecution as execution
    import libcosimpy.CosimManipulator as manipulator
    import libcosimpy.CosimObserver as observer
    import libcosimpy.CosimSlave as slave

    return execution, slave, observer, manipulator


def _libcosim_run(libcosim, fmu_path, fmu_unzipped, params, terrain, n=N, h=H):
    """Steps the FMU n times in a libcosim execution with step h; inputs through an override
    manipulator before each step (initial values before the first).  Returns (n, outputs)."""
    execution, slave, observer, manipulator = libcosim
    vs = variables(fmu_unzipped)
    names = output_names(fmu_unzipped)
    step_ns = int(round(h * 1e9))
    ex = execution.CosimExecution.from_step_size(step_size=step_ns)   # nanoseconds (0 crashes libcosim)
    local = slave.CosimLocalSlave(fmu_path=fmu_path, instance_name="rover")
    idx = ex.add_local_slave(local)
    assert idx >= 0, "libcosim could not load the FMU"
    seen = {v.name.decode() if isinstance(v.name, bytes) else v.name for v in ex.slave_variables(idx)}
    assert seen >= set(names), f"libcosim does not see the outputs {set(names) - seen}"
    last = observer.CosimObserver.create_last_value()
    ex.add_observer(last)
    override = manipulator.CosimManipulator.create_override()
    ex.add_manipulator(override)
    for name, value in params.items():
        if vs[name].type == "Integer":
            assert ex.integer_initial_value(idx, vs[name].vr, int(value))
        else:
            assert ex.real_initial_value(idx, vs[name].vr, float(value))
    assert ex.string_initial_value(idx, vs["terrain.file"].vr, terrain)
    for name, value in inputs(0.0).items():
        assert ex.real_initial_value(idx, vs[name].vr, value)
    vrs = [vs[k].vr for k in names]
    out = np.empty((n, len(names)))
    for i in range(n):
        if i > 0:
            u = inputs(i * h)
            assert override.slave_real_values(idx, [vs[k].vr for k in u], list(u.values()))
        assert ex.step(1), f"libcosim step {i} failed: {ex.status()}"
        out[i] = last.last_real_values(idx, vrs)
    status = ex.status()
    assert status.current_time == n * step_ns
    return out


def _fmpy_run(fmu_unzipped, params, terrain, clock="fmpy", n=N, h=H):
    """The same run with fmpy's FMU2Slave.  clock="fmpy": communication points i*h and steps h;
    clock="libcosim": libcosim's (t_i = i*h_ns/1e9, step t_{i+1} - t_i, as it converts its
    integer nanoseconds to seconds)."""
    names = output_names(fmu_unzipped)
    p = dict(params, **{"terrain.file": terrain})
    h_ns = int(round(h * 1e9))
    out = np.empty((n, len(names)))
    with Rover(fmu_unzipped) as r:
        r.setup(p, initial_inputs=inputs(0.0))
        for i in range(n):
            r.set(inputs(i * h))
            if clock == "fmpy":
                t, dt = i * h, h
            else:
                t = (i * h_ns) / 1e9
                dt = ((i + 1) * h_ns) / 1e9 - t
            r.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=dt)
            out[i] = r.get(names)
    return out


def _describe_difference(a, b, names):
    d = np.abs(a - b)
    i, j = np.unravel_index(np.argmax(d), d.shape)
    return f"max |difference| {d.max():.3g} at step {i}, output {names[j]}: {a[i, j]!r} vs {b[i, j]!r}"


# ---------------------------------------------------------------------------------------------
# libcosim
# ---------------------------------------------------------------------------------------------

def test_libcosim_gives_fmpys_results(libcosim, fmu_path, fmu_unzipped, terrain):
    names = output_names(fmu_unzipped)
    cosim = _libcosim_run(libcosim, fmu_path, fmu_unzipped, PARAMS, terrain)
    assert np.all(np.isfinite(cosim))
    assert np.ptp(cosim[:, names.index("x")]) > 0.05, "the scenario should move the rover"

    same_clock = _fmpy_run(fmu_unzipped, PARAMS, terrain, clock="libcosim")
    assert np.array_equal(cosim, same_clock), "libcosim vs fmpy on libcosim's clock: " + \
        _describe_difference(cosim, same_clock, names)

    # fmpy's own clock (i*h, steps of exactly h) differs from libcosim's in the last bit of the
    # step size, which the dynamics carry along: still 1e-9
    own_clock = _fmpy_run(fmu_unzipped, PARAMS, terrain, clock="fmpy")
    scale = np.maximum(1.0, np.abs(own_clock))
    assert np.all(np.abs(cosim - own_clock) <= 1e-9 * scale), "libcosim vs fmpy: " + \
        _describe_difference(cosim, own_clock, names)


def test_libcosim_runs_the_default_experiment(libcosim, fmu_path, fmu_unzipped):
    execution, slave, observer, _ = libcosim
    vs = variables(fmu_unzipped)
    ex = execution.CosimExecution.from_step_size(step_size=20_000_000)   # 20 ms
    idx = ex.add_local_slave(slave.CosimLocalSlave(fmu_path=fmu_path, instance_name="default"))
    series = observer.CosimObserver.create_time_series()
    ex.add_observer(series)
    assert series.start_time_series(idx, vs["x"].vr, _real_type())
    assert ex.simulate_until(target_time=5_000_000_000), ex.status()
    times, steps, xs = series.time_series_real_samples(idx, vs["x"].vr, 1, 250)
    assert len(xs) == 250 and steps[-1] == 250 and times[-1] == 5_000_000_000
    assert np.all(np.isfinite(xs)) and xs[-1] > 0.05, f"the default experiment moved {xs[-1]} m in 5 s"
    ref = run(str(fmu_unzipped), {}, None, stop_time=5.0, step=0.02, outputs=["x"])
    assert abs(xs[-1] - ref["x"][-1]) <= 1e-9 * max(1.0, abs(ref["x"][-1]))


def _real_type():
    from libcosimpy.CosimEnums import CosimVariableType

    return CosimVariableType.REAL


# ---------------------------------------------------------------------------------------------
# fmpy validate
# ---------------------------------------------------------------------------------------------

def _strip_binaries(fmu_path, target: Path) -> Path:
    with zipfile.ZipFile(fmu_path) as zin, zipfile.ZipFile(target, "w", zipfile.ZIP_DEFLATED) as zout:
        for item in zin.infolist():
            if not item.filename.startswith("binaries/"):
                zout.writestr(item, zin.read(item.filename))
    return target


def test_fmpy_validate_with_schema_and_model_structure(fmu_path, tmp_path):
    # validate_fmu: XML schema, variable names (structured), ModelStructure, start values, units
    assert validate_fmu(fmu_path) == []
    assert validate_fmu(str(_strip_binaries(fmu_path, tmp_path / "JunoRover-source.fmu"))) == []


def test_source_fmu_holds_every_source_and_header(fmu_path):
    with zipfile.ZipFile(fmu_path) as zf:
        files = {Path(n).name for n in zf.namelist() if n.startswith("sources/") and not n.endswith("/")}
        md = zf.read("modelDescription.xml").decode()
        listed = re.findall(r'<File name="([^"]+)"', md)
        assert listed and set(listed) <= files, f"modelDescription lists sources that are missing: {set(listed) - files}"
        missing = []
        for name in sorted(files):
            text = zf.read(f"sources/{name}").decode("utf-8", "replace")
            for inc in re.findall(r'^\s*#\s*include\s+"([^"]+)"', text, re.M):
                if Path(inc).name not in files:
                    missing.append(f"{name} includes {inc}")
    assert "juno_guid.h" in files
    assert not missing, "the sources/ folder is not self-contained: " + "; ".join(missing)


# ---------------------------------------------------------------------------------------------
# fmpy compile
# ---------------------------------------------------------------------------------------------

def test_fmpy_compile_of_the_source_fmu_gives_identical_results(fmu_path, fmu_unzipped, tmp_path, terrain):
    if shutil.which("cmake") is None:
        pytest.fail("fmpy compile needs cmake on PATH (scripts/setup.sh installs it)")
    from fmpy.build import build_platform_binary

    stripped = _strip_binaries(fmu_path, tmp_path / "JunoRover-source.fmu")
    unzipdir = Path(extract(str(stripped), unzipdir=str(tmp_path / "compiled")))
    assert not (unzipdir / "binaries").exists()
    build_platform_binary(unzipdir, build_dir=None)
    built = list((unzipdir / "binaries").rglob("JunoRover.*"))
    assert built, "fmpy compile produced no binary"

    names = output_names(fmu_unzipped)
    cmake_built = _fmpy_run(fmu_unzipped, PARAMS, terrain)
    fmpy_built = _fmpy_run(str(unzipdir), PARAMS, terrain)
    assert np.array_equal(cmake_built, fmpy_built), "fmpy-compiled vs CMake-built binary: " + \
        _describe_difference(fmpy_built, cmake_built, names)
