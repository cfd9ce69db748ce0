"""The drivetrain_loss candidate: a drivetrain's losses in their standard form.

* It fits a fraction of the measured torque (gear mesh) and one Coulomb drag (seals, bearings),
  the same on both sides: the drag is one fitted value, which every replay gives the FMU as
  drive.frictionLeft and drive.frictionRight alike, and the judging charges it once.
* No candidate fits a drag on one side only (a dragging brake on one side is outside the
  catalogue: the diagnosis must call it unexplained, not absorb it).
* A drag alone switches the candidate on; switched off, both the fraction and the drag are 0.
"""

from __future__ import annotations

import numpy as np
import pytest

from juno.diagnose import CANDIDATES, Problem
from juno.diagnose import problem as problem_module
from juno.diagnose.candidates import fmu_parameters, for_runs, run_parameters, unqualified
from juno.diagnose.problem import residuals_or_failure
from juno.identify import PAPER_INITIAL, PreparedRun

LOSS = CANDIDATES["drivetrain_loss"]
SIDES = ("drive.frictionLeft", "drive.frictionRight")


def test_the_drag_is_one_value_given_to_both_sides_of_every_replay(monkeypatch):
    """Every run is replayed with the fitted drag on both drivetrains, and the FMU is never
    given the tied parameter's own name (it is no FMU variable)."""
    seen = {}

    def replay(_fmu, p, _soil, extra):
        seen[p.run_id] = extra
        return np.zeros(1), None
    monkeypatch.setattr(problem_module, "_replay", replay)
    runs = [PreparedRun(r, "drawbar", 1.0, None, {}, {"torque_left": (np.zeros(1), np.zeros(1), "t", 3.0, 0.0)})
            for r in ("dbp1", "dbp2")]
    params = {**PAPER_INITIAL, "drive.lossFraction": 0.1, "drive.friction": 12.5}
    r, failure = residuals_or_failure(None, Problem("campaign", None, "unused.fmu", runs), params)
    assert failure is None and len(r) == 2
    expected = {"drive.lossFraction": 0.1, "drive.frictionLeft": 12.5, "drive.frictionRight": 12.5}
    assert seen == {"dbp1": expected, "dbp2": expected}


def test_a_drag_applied_to_some_runs_reaches_those_runs_only():
    """The tie keeps the runs a parameter is applied to (candidates.for_runs)."""
    params = {for_runs("drive.friction", ["dbp2"]): 4.0}
    assert fmu_parameters(params) == {for_runs(k, ["dbp2"]): 4.0 for k in SIDES}
    assert run_parameters(params, "dbp1") == {}
    assert run_parameters(params, "dbp2") == dict.fromkeys(SIDES, 4.0)


def test_two_values_for_one_side_are_refused():
    """A tied drag and a different value of one side's own are no model: an error names both."""
    with pytest.raises(ValueError, match="drive.frictionLeft.*drive.friction"):
        fmu_parameters({"drive.friction": 4.0, "drive.frictionLeft": 5.0})


def test_the_candidate_fits_a_fraction_and_one_symmetric_drag_charged_once():
    """Two parameters: the fraction and the drag (0 to 100 N m, started at neutral); neither
    side's drag is a parameter of any candidate, so a one-sided drag is left unexplained."""
    assert [(e.name, e.start, e.lower, e.upper) for e in LOSS.params] == [
        ("drive.lossFraction", 0.0, 0.0, 0.9), ("drive.friction", 0.0, 0.0, 100.0)]
    assert LOSS.parameters_in({**PAPER_INITIAL, "drive.lossFraction": 0.0, "drive.friction": 8.0}) == 2
    assert not any(unqualified(e.name) in SIDES for c in CANDIDATES.values() for e in c.params)


def test_a_drag_alone_switches_the_candidate_on():
    """Beyond 0.5 N m of drag the extension acts, with no fraction; switched off, it is the base
    model (no fraction, no drag)."""
    drag = {**PAPER_INITIAL, "drive.lossFraction": 0.0, "drive.friction": 3.0}
    assert LOSS.acts(drag)
    assert not LOSS.acts({**drag, "drive.friction": 0.3})
    off = LOSS.switched_off({**drag, "drive.lossFraction": 0.2})
    assert off["drive.lossFraction"] == 0.0 and off["drive.friction"] == 0.0 and not LOSS.acts(off)
