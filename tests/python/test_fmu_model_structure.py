"""The FMU's ModelStructure tells importers the truth: no output depends directly on an input
(dependencies=""), so a controller that reads omegaLeft and writes throttleLeft forms no
algebraic loop.  Checked against the declaration and against a numerical probe."""

from __future__ import annotations

import numpy as np
from fmpy import read_model_description

from fmu_helpers import Rover


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
