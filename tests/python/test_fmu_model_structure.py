"""The FMU's ModelStructure tells importers the truth: no output depends directly on an input
(dependencies=""), so a controller that reads omegaLeft and writes throttleLeft forms no
algebraic loop.  Checked against the declaration and against a numerical probe."""

from __future__ import annotations

import numpy as np
import pytest
from fmpy import read_model_description

from fmu_helpers import FMICallException, LogCapture, Rover


def _outputs_and_inputs(fmu_unzipped):
    md = read_model_description(fmu_unzipped)
    outputs = [v for v in md.modelVariables if v.causality == "output"]
    inputs = [v for v in md.modelVariables if v.causality == "input"]
    return md, outputs, inputs


def test_every_output_is_declared_without_direct_feedthrough(fmu_unzipped):
    md, outputs, inputs = _outputs_and_inputs(fmu_unzipped)
    assert inputs and outputs
    assert [u.variable.name for u in md.outputs] == [v.name for v in outputs]
    for unknown in md.outputs:
        assert unknown.dependencies == [], f"{unknown.variable.name} declares {unknown.dependencies}"


def test_changing_inputs_changes_no_output_before_the_next_step(fmu_unzipped):
    """Probe: after a few steps, set every input far from its value and read every output before
    stepping (unchanged), then step once (the inputs do act: some outputs change)."""
    _, outputs, inputs = _outputs_and_inputs(fmu_unzipped)
    names = [v.name for v in outputs]
    with Rover(fmu_unzipped) as rover:
        rover.setup({"drive.mode": 0})
        rover.set({"torqueLeft": 40.0, "torqueRight": 40.0, "drawbarForce": 100.0})
        for _ in range(5):
            rover.step(0.01)
        before = np.array(rover.get(names))
        rover.set({v.name: 300.0 if "torque" in v.name else 0.9 if "throttle" in v.name else 2.0 if "omega" in v.name
                   else 800.0 for v in inputs})
        probed = np.array(rover.get(names))
        np.testing.assert_array_equal(probed, before)
        rover.step(0.01)
        after = np.array(rover.get(names))
        changed = [n for n, a, b in zip(names, after, probed) if a != b]
        assert "torqueLeftApplied" in changed and "vx" in changed


def test_the_fmu_says_its_licence_version_and_authors(fmu_path, fmu_unzipped):
    """modelDescription.xml names the licence, copyright, authors and version (the harness's
    version: one release), and the FMU carries the licence text."""
    from pathlib import Path

    import juno
    md = read_model_description(fmu_path)
    assert md.version == juno.__version__
    assert md.license.startswith("BSD-2-Clause") and md.copyright and md.author
    text = (Path(fmu_unzipped) / "documentation" / "licenses" / "LICENSE.txt").read_text()
    assert text == (Path(__file__).resolve().parents[2] / "LICENSE").read_text()


def _initial_unknowns(fmu_unzipped) -> list[str]:
    return [u.variable.name for u in read_model_description(fmu_unzipped).initialUnknowns]


def test_initial_unknowns_read_in_initialization_mode_are_the_initial_values(fmu_unzipped):
    """In Initialization Mode an importer may read every InitialUnknown (the outputs and the
    calculated parameters: standard, 4.2.4) to initialise what it connects them to; the values
    are those the instance starts from, computed from the parameters and inputs set so far, and
    a change of either is seen by the next read."""
    names = _initial_unknowns(fmu_unzipped)
    assert "z" in names and "soil.A1" in names and "wheelFL.Fn" in names
    with Rover(fmu_unzipped) as rover:
        soft, stiff, after = rover.initial_values(
            names, {"soil.kh": 1.2e5, "drive.mode": 2, "throttleLeft": 0.3, "throttleRight": 0.3}, {"soil.kh": 2.4e5})
    assert stiff == after
    assert soft["wheelFL.sinkage"] > stiff["wheelFL.sinkage"] > 0.0
    assert soft["z"] < stiff["z"]


def test_reading_an_output_in_initialization_mode_reports_a_failing_initialisation(fmu_unzipped, tmp_path):
    """The values cannot be computed when the parameters do not initialise: the read fails with
    the cause, as fmi2ExitInitializationMode would."""
    log = LogCapture()
    missing = str(tmp_path / "no such grid.asc")
    with Rover(fmu_unzipped, log=log) as rover:
        rover.fmu.setupExperiment(startTime=0.0)
        rover.fmu.enterInitializationMode()
        rover.set({"terrain.file": missing})
        assert rover.get(["soil.kh"]) == [158000.0]     # a parameter reads as set, no initialisation
        with pytest.raises(FMICallException):
            rover.get(["z"])
    assert any("fmi2GetReal" in m and missing in m for m in log.errors()), log.text()
