"""The grouser candidate carries the lug ripple the drive torques show (juno/diagnose/ripple_nuisance.py:
with_lug_ripple, lug_phases): lugs make both a thrust and its ripple at the lug-passing frequency,
and where the soil absorbs the mean thrust the ripple is the lugs' only mark.  The lug count and
each drawbar run's and side's phase are found on the base model's training blocks; one amplitude
is fitted and charged; a model whose lugs ripple is fitted on its whole residuals, a model without a ripple
takes it as a nuisance."""

from __future__ import annotations

import numpy as np

from juno.diagnose import FitResult, build_problem
from juno.diagnose.candidates import CANDIDATES, parameters_of_a_new_run
from juno.diagnose.problem import all_residuals
from juno.diagnose import ripple_nuisance
from juno.diagnose.ripple_nuisance import lug_phases, makes_lug_ripple, nuisance_free, with_lug_ripple
from juno.diagnose.search import _with_ripple_as_nuisance, ripple_of
from juno.periodic_structure import PeriodicBases

from harness_fixtures import NOISY_SEED, NOISY_TIME_SCALE, make_campaign
from test_diagnose_ripple_nuisance import one_drawbar_run

pytest_plugins = ["harness_fixtures"]

AMPLITUDE = "grouser.rippleAmplitude@db1"
PHASE = "grouser.lugPhaseLeft@db1"


def _wrapped(angle: float) -> float:
    """``angle`` in (-pi, pi]."""
    return float(np.angle(np.exp(1j * angle)))


def test_a_model_whose_lugs_ripple_is_fitted_on_its_whole_residuals_and_one_without_takes_it_as_a_nuisance():
    problem, r, _levels = one_drawbar_run(lugs=18, amplitude=2.0)
    assert makes_lug_ripple({AMPLITUDE: -0.2}) and nuisance_free(problem, r, {AMPLITUDE: -0.2}) is r
    for still in ({AMPLITUDE: 0.0}, {"grouser.thrustGain": 0.3}, None):
        assert not makes_lug_ripple(still)
        assert nuisance_free(problem, r, still) is not r


def test_the_grouser_carries_the_ripple_with_one_charged_amplitude_for_the_drawbar_runs(monkeypatch):
    problem, r, _levels = one_drawbar_run(lugs=18, amplitude=2.0)
    monkeypatch.setattr(ripple_nuisance, "lug_phases", lambda *_args: {PHASE: 0.4})
    catalog = CANDIDATES["grouser"]
    grouser = with_lug_ripple(catalog, problem, {}, r)
    assert [e.name for e in grouser.params] == ["grouser.thrustGain", "grouser.lugHeight", AMPLITUDE]
    assert grouser.params[-1].start > 0.0, "a start at none would sit where the loss steps"
    assert dict(grouser.fixed) == {"grouser.lugCount": 18, PHASE: 0.4}
    fitted = {"grouser.thrustGain": 0.2, "grouser.lugHeight": 0.01, AMPLITUDE: 0.2, **dict(grouser.fixed)}
    assert catalog.parameters_in(fitted) == 3, "the amplitude is charged, the measured count and phase are not"
    assert catalog.parameters_in({"grouser.thrustGain": 0.2, "grouser.lugHeight": 0.01}) == 2
    assert catalog.acts({"grouser.thrustGain": 0.0, "grouser.lugHeight": 0.0, AMPLITUDE: 0.2})
    off = catalog.switched_off(fitted)
    assert off[AMPLITUDE] == 0.0 and not makes_lug_ripple(off) and not catalog.acts(off)
    problem.ripple_lugs = None
    assert with_lug_ripple(catalog, problem, {}, r) is catalog


def test_a_run_outside_the_campaign_gets_only_the_parameters_applied_to_every_run():
    fitted = {"soil.kh": 2e5, "grouser.lugCount": 18.0, PHASE: 0.4, AMPLITUDE: -0.2, "drive.friction": 3.0}
    assert parameters_of_a_new_run(fitted) == {"soil.kh": 2e5, "grouser.lugCount": 18.0,
                                               "drive.frictionLeft": 3.0, "drive.frictionRight": 3.0}


def test_on_a_lug_ripple_campaign_the_phases_found_let_the_true_lugs_remove_the_ripple(harness_fmu, fmu_path, tmp_path):
    """On the lug_ripple campaign, through the model with the true soil and the true lugs' thrust
    (no ripple), each drawbar run's and side's phase is found from the training blocks alone
    (held-out torques changed leave it as it is), and the true ripple at those phases leaves no
    ripple at 18 per revolution in the drive torques, where without it the torques ripple.  The
    replay's phase is not the truth's own 0: at 0 the true ripple leaves one (the replay follows
    the measured spins through a controller, which lags).  Through the base model (the true soil
    alone, which the diagnosis has before any candidate) the phases found are within 0.8 rad of
    those: a base model without the lugs' thrust answers a ripple with another lag."""
    c = make_campaign(tmp_path / "ripple", harness_fmu, NOISY_SEED, 1.0, NOISY_TIME_SCALE, effect="lug_ripple")
    hidden = c.truth["hidden"]["sim"]
    problem = build_problem(c.campaign, fmu_path, None)
    base = FitResult("base", dict(c.soil), 1.0, 1.0, all_residuals(harness_fmu, problem, dict(c.soil)), 1, 0.0)
    _with_ripple_as_nuisance(c.campaign, problem, base, PeriodicBases(), lambda _m: None, 1)
    assert problem.ripple_lugs == 18
    lugs = {**c.soil, **{k: hidden[k] for k in ("grouser.thrustGain", "grouser.lugHeight")}}
    at_lugs = all_residuals(harness_fmu, problem, lugs)
    phases = lug_phases(problem, lugs, at_lugs)
    drawbar = [p.run_id for p in problem.prepared if p.kind == "drawbar"]
    assert sorted(phases) == sorted(f"grouser.lugPhase{side}@{run}" for run in drawbar for side in ("Left", "Right"))
    torques = np.isin(problem.meta["signal"], ["torque_left", "torque_right"]) & ~problem.train
    assert lug_phases(problem, lugs, at_lugs + 5.0 * torques) == phases
    from_base = lug_phases(problem, base.params, base.residuals)
    assert max(abs(_wrapped(from_base[k] - v)) for k, v in phases.items()) < 0.8
    ripple = {"grouser.lugCount": 18, "grouser.rippleAmplitude": hidden["grouser.rippleAmplitude"]}
    for params, ripples in ((lugs, True), ({**lugs, **ripple, **phases}, False),
                            ({**lugs, **ripple, "grouser.lugPhaseLeft": 0.0, "grouser.lugPhaseRight": 0.0}, True)):
        r = all_residuals(harness_fmu, problem, params)
        found = ripple_of(c.campaign, problem, FitResult("m", params, 1.0, 1.0, r, 1, 0.0), PeriodicBases())
        assert found.significant == ripples
