"""The verdict: a catalog cause, none or unexplained, from what the search named and the residual
structure its models leave (juno/diagnose/verdict.py)."""

from __future__ import annotations

from juno.residual_structure import Covariate, ResidualStructure, SignalStructure
from juno.diagnose.verdict import EXPLAINED_SHARE, explanation, verdict


def _structure(**ratios: float) -> ResidualStructure:
    """A structure test in which each named signal has structure of that size (x its noise)."""
    signals = [SignalStructure(name, "N m", 10, 2.0, 2.0 * r, r, 1e-12 if r > 0 else 0.5, r > 0,
                               [Covariate("constant", 0.9, 2.0 * r, "N m")] if r > 0 else [])
               for name, r in ratios.items()]
    return ResidualStructure(signals, 0.01 / max(len(signals), 1), 20, ["dbp1", "dbp2"])


def test_nothing_named_and_nothing_left_is_none():
    v = verdict([], _structure(torque_left=0.0, pitch=0.0), None)
    assert (v.cause, v.causes, v.unexplained) == ("none", [], None)
    assert "consistent with sensor noise" in explanation(v, "")


def test_nothing_named_but_structure_left_is_unexplained_with_the_signals():
    v = verdict([], _structure(torque_left=0.0, pitch=4.0), None)
    assert v.cause == "unexplained" and v.causes == []
    assert [s.signal for s in v.unexplained.signals] == ["pitch"]
    assert v.unexplained.model == "base" and v.unexplained.absorbed_by == []
    assert "pitch" in explanation(v, "") and "constant" in explanation(v, "")


def test_a_cause_whose_model_leaves_nothing_is_named():
    v = verdict(["drivetrain_loss"], _structure(torque_left=2.0), _structure(torque_left=0.0))
    assert (v.cause, v.causes, v.unexplained) == ("drivetrain_loss", ["drivetrain_loss"], None)


def test_a_cause_that_removes_most_of_the_structure_is_named_with_the_rest_reported():
    base, after = _structure(torque_left=2.0, pitch=1.0), _structure(torque_left=0.0, pitch=1.0)
    v = verdict(["grouser"], base, after)
    assert v.cause == "grouser" and v.causes == ["grouser"]
    assert v.unexplained.share_removed == 1 - 1.0 / 5.0 >= EXPLAINED_SHARE
    assert [s.signal for s in v.unexplained.signals] == ["pitch"]
    assert "remains" in explanation(v, "lugs add thrust")


def test_a_cause_that_removes_less_than_half_is_not_named():
    base, after = _structure(torque_left=2.0, torque_right=2.0), _structure(torque_left=1.8, torque_right=1.8)
    v = verdict(["soil_patch"], base, after)
    assert v.cause == "unexplained" and v.causes == []
    assert v.unexplained.absorbed_by == ["soil_patch"]
    assert v.unexplained.share_removed < EXPLAINED_SHARE
    assert "soil_patch would remove only" in explanation(v, "a weaker patch")
