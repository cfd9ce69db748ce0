"""The WheelRig FMU (build/WheelRig.fmu) as an importer sees it: a valid FMI 2.0 Co-Simulation FMU whose
modelDescription lists exactly its variable table, which loads in fmpy, runs its default experiment to
the load it carries, replays a restored or serialised state bit for bit, accepts every value in its
declared ranges and refuses the rest naming the variable, and exports the FMI functions only.

The physics of the rig (equilibrium, rolling resistance, the drawbar curve, torque signs, lateral
force) is specified in tests/c/test_wheel_rig.c; here one steady point checks that the FMU's outputs
are the model's.
"""

from __future__ import annotations

import math
import re
import shutil
import subprocess
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.validation import validate_fmu

from conftest import BUILD, REPO, _build_fmu
from fmu_helpers import FMICallException, LogCapture, Rover, output_names
from test_fmu_binary import FMI2_CS_FUNCTIONS
from test_fmu_ranges import PHYSICAL_OUTCOMES, _try, _values, _walked_variables

RIG_FMU = BUILD / "WheelRig.fmu"
TABLE = REPO / "modelDescription" / "wheel_rig_variables.h"
#: The contact law's rows, which the rig's table and the rover's both include.
SHARED_TABLE = REPO / "modelDescription" / "contact_variables.h"
H = 0.05
CAUSALITY = {"PARAM": "parameter", "CALC": "calculatedParameter", "INPUT": "input", "OUTPUT": "output"}


@pytest.fixture(scope="module")
def rig_path() -> str:
    """build/WheelRig.fmu, built (with the rover's FMU) if it is missing."""
    if not RIG_FMU.is_file():
        _build_fmu()
    assert RIG_FMU.is_file(), f"the build did not make {RIG_FMU}"
    return str(RIG_FMU)


@pytest.fixture(scope="module")
def rig_dir(rig_path, tmp_path_factory) -> str:
    return extract(rig_path, unzipdir=str(tmp_path_factory.mktemp("WheelRig_fmu")))


def _table() -> dict[str, tuple[int, str, str]]:
    """name -> (value reference, type, causality) from the X-macro table and the shared contact rows
    it includes, read as text."""
    text = TABLE.read_text() + SHARED_TABLE.read_text()
    rows = re.findall(r'\b(REAL|INT |STR)\(\s*(\d+),\s*"([^"]+)",\s*(PARAM|CALC|INPUT|OUTPUT)\b', text)
    types = {"REAL": "Real", "INT ": "Integer", "STR": "String"}
    return {name: (int(vr), types[kind], CAUSALITY[causality]) for kind, vr, name, causality in rows}


def test_fmpy_validation_finds_no_problems(rig_path):
    assert validate_fmu(rig_path) == []


def test_model_description_lists_exactly_the_variable_table(rig_path):
    md = read_model_description(rig_path)
    assert md.coSimulation.modelIdentifier == "WheelRig" and md.modelName == "WheelRig"
    declared = {v.name: (v.valueReference, v.type, v.causality) for v in md.modelVariables}
    table = _table()
    assert len(table) >= 40, f"the table was not read: {sorted(table)}"
    assert declared == table
    for name in ("rig.load", "rig.mass", "rig.driveMode", "rig.slip", "rig.vx", "rig.omega", "rig.slipAngle",
                 "rig.drawbarPull", "rig.verticalForce", "rig.torque", "rig.sinkage", "rig.lateralForce",
                 "rig.slipActual", "soil.kh", "contact.model", "wongReece.n", "wheel.radius", "grouser.lugHeight",
                 "grouser.thrustGain", "slipSinkage.coefficient", "solver.step"):
        assert name in declared, f"the interface names {name}"


def test_variables_shared_with_the_rover_keep_its_declaration(rig_path, fmu_path):
    """A parameter both FMUs have means the same in both: same value reference, unit, start and range.
    solver.step is each model's own integrator's and is left out."""
    rover = {v.name: v for v in read_model_description(fmu_path).modelVariables}
    shared = [v for v in read_model_description(rig_path).modelVariables if v.name in rover and v.name != "solver.step"]
    assert len(shared) >= 25
    for v in shared:
        r = rover[v.name]
        assert (v.valueReference, v.type, v.causality, v.unit, v.start, v.min, v.max) == \
               (r.valueReference, r.type, r.causality, r.unit, r.start, r.min, r.max), v.name


def test_default_experiment_carries_the_load(rig_path):
    md = read_model_description(rig_path)
    ex = md.defaultExperiment
    res = simulate_fmu(rig_path, stop_time=float(ex.stopTime), output_interval=float(ex.stepSize))
    for name in res.dtype.names:
        assert np.all(np.isfinite(res[name])), name
    last = res[res["time"] >= 0.8 * float(ex.stopTime)]
    assert np.mean(last["rig.verticalForce"]) == pytest.approx(779.0, rel=2e-3)
    assert np.all(last["rig.slipActual"] == pytest.approx(0.2, abs=1e-12))
    assert np.all(last["rig.torque"] > 0), "driving at slip 0.2 takes a positive torque"


def test_the_fmu_outputs_are_the_soil_force_and_its_moment(rig_dir):
    """Drawbar pull and vertical force are the force's components along the carriage and up; the
    torque is the traction times the shear radius (the wheel radius without lugs)."""
    with Rover(rig_dir, instance_name="rig") as r:
        r.setup(initial_inputs={"rig.slip": 0.3, "rig.slipAngle": 0.0})
        r.advance(int(4.0 / H), H)
        torque, traction, normal, vertical, drawbar = r.get(
            ["rig.torque", "rig.tractionForce", "rig.normalForce", "rig.verticalForce", "rig.drawbarPull"])
        radius = r.get_one("wheel.radius")
    assert torque == pytest.approx(radius * traction, rel=1e-12)
    # with the force tilted by alpha: drawbar = Ft cos a - Fn sin a, vertical = Fn cos a + Ft sin a
    assert math.hypot(drawbar, vertical) == pytest.approx(math.hypot(traction, normal), rel=1e-12)


def test_initial_unknowns_read_in_initialization_mode_are_the_initial_values(rig_dir):
    """As the rover's (test_fmu_model_structure.py): in Initialization Mode the outputs and the
    calculated parameters read as the values the rig starts from, after each change of a
    parameter or an input."""
    names = [u.variable.name for u in read_model_description(rig_dir).initialUnknowns]
    assert "rig.sinkage" in names and "rig.verticalForce" in names and "rig.movingMass" in names
    with Rover(rig_dir, instance_name="rig") as r:
        light, heavy, after = r.initial_values(names, {"rig.load": 600.0, "rig.slip": 0.2}, {"rig.load": 900.0})
    assert heavy == after
    assert light["rig.verticalForce"] == pytest.approx(600.0) and heavy["rig.verticalForce"] == pytest.approx(900.0)
    assert 0.0 < light["rig.sinkage"] < heavy["rig.sinkage"]


def test_state_round_trip_is_exact(rig_dir):
    """getFMUstate/setFMUstate and serialize/deserialize (into a second instance) continue bit for bit."""
    names = output_names(rig_dir)
    schedule = {"rig.slip": lambda t: 0.1 + 0.05 * math.sin(t), "rig.slipAngle": lambda t: 0.1 * math.cos(2 * t)}
    start = {name: f(0.0) for name, f in schedule.items()}
    with Rover(rig_dir, instance_name="A") as a, Rover(rig_dir, instance_name="B") as b:
        a.setup(params={"contact.model": 0, "grouser.lugHeight": 0.01}, initial_inputs=start)
        a.advance(40, H, schedule, names)
        state = a.fmu.getFMUstate()
        blob = a.fmu.serializeFMUstate(state)
        t_saved = a.time
        first = a.advance(40, H, schedule, names)
        a.fmu.setFMUstate(state)
        a.fmu.freeFMUstate(state)
        a.time = t_saved
        again = a.advance(40, H, schedule, names)
        b.setup(params={"contact.model": 0, "grouser.lugHeight": 0.01}, initial_inputs=start)
        b.advance(3, H, {"rig.slip": 0.7})
        restored = b.fmu.deSerializeFMUstate(blob)
        b.fmu.setFMUstate(restored)
        b.fmu.freeFMUstate(restored)
        b.time = t_saved
        other = b.advance(40, H, schedule, names)
    assert np.ptp(first[:, names.index("rig.lateralForce")]) > 1.0, "the inputs should move the outputs"
    assert first.tobytes() == again.tobytes(), "outputs after fmi2SetFMUstate differ"
    assert first.tobytes() == other.tobytes(), "outputs in a second instance after deserialisation differ"


def test_a_rover_state_is_refused_by_the_rig(rig_dir, fmu_unzipped):
    """Two models, one FMI layer: a JunoRover state is not a WheelRig state."""
    with Rover(fmu_unzipped, instance_name="rover") as rover:
        rover.setup()
        state = rover.fmu.getFMUstate()
        blob = rover.fmu.serializeFMUstate(state)
        rover.fmu.freeFMUstate(state)
    log = LogCapture()
    with Rover(rig_dir, instance_name="rig", log=log) as r:
        r.setup()
        with pytest.raises(FMICallException):
            r.fmu.deSerializeFMUstate(blob)
    assert any("serialized state has" in m for m in log.errors()), log.errors()


@pytest.mark.parametrize("name, value", [("rig.load", 0.0), ("rig.mass", -1.0), ("rig.slip", 1.0),
                                         ("rig.vx", -0.1), ("soil.kh", 0.0), ("rig.driveMode", 2)])
def test_bad_value_is_refused_naming_it(rig_dir, name, value):
    log = LogCapture()
    with Rover(rig_dir, instance_name="rig", log=log) as r:
        r.fmu.setupExperiment(startTime=0.0)
        r.fmu.enterInitializationMode()
        with pytest.raises(FMICallException):
            r.set({name: value})
    assert any(name in m and "outside its range" in m for m in log.errors()), log.errors()


@pytest.mark.parametrize("value", [math.nan, math.inf], ids=["nan", "inf"])
def test_non_finite_input_between_steps_is_refused_and_the_run_goes_on(rig_dir, value):
    log = LogCapture()
    with Rover(rig_dir, instance_name="rig", log=log) as r:
        r.setup()
        r.advance(2, H)
        with pytest.raises(FMICallException):
            r.set({"rig.slip": value})
        assert r.get_one("rig.slip") == 0.2
        r.advance(2, H)
    assert any("rig.slip" in m and "not a finite number" in m for m in log.errors()), log.errors()


def test_parameters_cannot_change_after_initialisation(rig_dir):
    log = LogCapture()
    with Rover(rig_dir, instance_name="rig", log=log) as r:
        r.setup()
        with pytest.raises(FMICallException):
            r.set({"rig.load": 500.0})
        r.set({"rig.slip": 0.5})             # an input may change
        r.advance(1, H)
    assert any("rig.load" in m and "cannot be set" in m for m in log.errors()), log.errors()


def test_soil_too_soft_for_the_load_fails_initialisation_with_the_cause(rig_dir):
    log = LogCapture()
    with Rover(rig_dir, instance_name="rig", log=log) as r:
        with pytest.raises(FMICallException):
            r.setup(params={"soil.kh": 1.0})
    assert any("no static equilibrium" in m and "rig.load" in m for m in log.errors()), log.errors()


def test_every_value_in_every_declared_range_is_accepted(rig_dir):
    """As for the rover (tests/python/test_fmu_ranges.py): each bound and a point inside, the other
    variables at their start values, initialised and stepped once; only a physical outcome may stop
    a bound, and every point inside runs."""
    walked = _walked_variables(rig_dir)
    assert len(walked) >= 30, len(walked)
    problems, ran = [], 0
    for v in walked:
        for value, where in _values(v):
            outcome, message = _try(rig_dir, v, value)
            if outcome == "ran":
                ran += 1
                continue
            what = f"{v.name} = {value!r} ({where} of [{v.min}, {v.max}])"
            if outcome == "set refused" or " must " in message:
                problems.append(f"{what} refused: {message}")
            elif where == "inside":
                problems.append(f"{what}, a point inside its range, does not run: {message}")
            elif not any(p in message for p in PHYSICAL_OUTCOMES):
                problems.append(f"{what}: {outcome} without a physical cause: {message}")
    assert not problems, f"{len(problems)} values inside their declared ranges:\n" + "\n".join(problems)
    assert ran > 3 * len(walked) // 2


def test_the_binary_exports_exactly_the_fmi2_functions(rig_path, tmp_path):
    nm = shutil.which("nm")
    if nm is None:
        pytest.skip("nm (binutils) is not installed")
    with zipfile.ZipFile(rig_path) as z:
        names = [n for n in z.namelist() if n.startswith("binaries/") and n.endswith(".so")]
        assert len(names) == 1 and Path(names[0]).name == "WheelRig.so", names
        z.extract(names[0], tmp_path)
    out = subprocess.run([nm, "-D", "--defined-only", str(tmp_path / names[0])], capture_output=True, text=True,
                         check=True).stdout
    exported = {line.split()[-1] for line in out.splitlines() if line.split()[1:2] and line.split()[1] in "TDBR"}
    assert exported == FMI2_CS_FUNCTIONS


def test_the_fmu_carries_its_sources_and_documentation(rig_path):
    """Sources self-contained (every quoted include is there), the licence, and an index.html naming
    every variable of the table."""
    with zipfile.ZipFile(rig_path) as z:
        files = {Path(n).name: n for n in z.namelist() if n.startswith("sources/") and not n.endswith("/")}
        missing = []
        for name, path in files.items():
            for inc in re.findall(r'#include\s+"([^"]+)"', z.read(path).decode()):
                if inc not in files:
                    missing.append(f"{name} includes {inc}")
        html = z.read("documentation/index.html").decode()
        assert "documentation/licenses/LICENSE.txt" in z.namelist()
    assert {"fmi2_cs.c", "wheel_rig.c", "wheel_soil.c", "contact.c", "juno_guid.h"} <= set(files)
    assert not missing, missing
    for name in _table():
        assert f"<code>{name}</code>" in html, name


def test_fmpy_compile_of_the_source_fmu_gives_identical_results(rig_path, rig_dir, tmp_path):
    """The sources alone build the rig (the generated juno_guid.h names its model and table, no
    compile definitions needed), and the binary fmpy compiles runs exactly as CMake's."""
    if shutil.which("cmake") is None:
        pytest.fail("fmpy compile needs cmake on PATH (scripts/setup.sh installs it)")
    from fmpy.build import build_platform_binary

    stripped = tmp_path / "WheelRig-source.fmu"
    with zipfile.ZipFile(rig_path) as zin, zipfile.ZipFile(stripped, "w", zipfile.ZIP_DEFLATED) as zout:
        for item in zin.infolist():
            if not item.filename.startswith("binaries/"):
                zout.writestr(item, zin.read(item.filename))
    unzipdir = Path(extract(str(stripped), unzipdir=str(tmp_path / "compiled")))
    build_platform_binary(unzipdir, build_dir=None)
    assert list((unzipdir / "binaries").rglob("WheelRig.*")), "fmpy compile produced no binary"

    def steady(directory) -> np.ndarray:
        with Rover(directory, instance_name="rig") as r:
            r.setup(params={"contact.model": 1}, initial_inputs={"rig.slip": 0.4, "rig.slipAngle": 0.1})
            return r.advance(20, H)

    assert steady(rig_dir).tobytes() == steady(str(unzipdir)).tobytes()
