"""The numbers of the diagnosis's result: the base model's fit, where it is wrong, the model with
every named cause and what it gains on the held-out blocks, assembled into a DiagnosisResult."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import numpy as np

from ..simulator import SOIL_PARAMETERS
from .candidates import CANDIDATES
from .fitting import FitResult
from .judging import capped_square
from .problem import Problem
from ..residual_structure import ResidualStructure
from .results import (Baseline, CauseGain, Criteria, DiagnosisResult, Duel, ExtendedModel, GainStep, JudgedCandidate,
                      NoCauseGain, PlotData, ResidualAnalysis, SignalGain)
from .sensor_offset import mounting_offsets, offset_free
from .verdict import Verdict, explanation, ripple_between_tied

if TYPE_CHECKING:
    from .search import Outcome


def per_signal_rms(problem: Problem, r: np.ndarray, scale: bool = True,
                   mask: np.ndarray | None = None) -> dict[str, float]:
    """Held-out RMS of each signal, in the signal's own units (scaled residual x sigma; with
    ``scale`` False, in sigma), over the residuals in ``mask`` (default: all)."""
    test = ~problem.train if mask is None else (~problem.train & mask)
    sigmas = {}
    for p in problem.prepared:
        for column, (_t, _v, _o, sigma, _lag) in p.targets.items():
            sigmas[column] = sigma
    out = {}
    for sig in np.unique(problem.meta["signal"]):
        here = test & (problem.meta["signal"] == sig)
        if np.any(here):
            out[str(sig)] = float(np.sqrt(np.mean(r[here] ** 2)) * (sigmas[str(sig)] if scale else 1.0))
    return out


def residual_analysis(problem: Problem, r: np.ndarray) -> ResidualAnalysis:
    """Where the residuals ``r`` (the base model's) are wrong: mean and RMS by run and signal,
    and the overall mean square."""
    meta = problem.meta
    by = {}
    for run in np.unique(meta["run"]):
        for sig in np.unique(meta["signal"]):
            m = (meta["run"] == run) & (meta["signal"] == sig)
            if np.any(m):
                by[f"{run}/{sig}"] = {"mean": float(np.mean(r[m])), "rms": float(np.sqrt(np.mean(r[m] ** 2)))}
    return ResidualAnalysis(by, float(np.mean(r ** 2)))


def baseline(problem: Problem, base: FitResult) -> Baseline:
    """The base model's fit as reported."""
    return Baseline({k: base.params[k] for k in SOIL_PARAMETERS}, base.test_mse, base.train_mse,
                    per_signal_rms(problem, base.residuals), base.status, base.failed_evaluations,
                    mounting_offsets(problem, base.residuals).get("pitch", {}))


def extended_model(problem: Problem, run_kind: np.ndarray, causes: list[str], res: FitResult) -> ExtendedModel:
    """The model with every named cause (``res``, its fit) as reported, with its held-out RMS per
    signal on every kind of run."""
    judged = np.isin(run_kind, sorted(set(run_kind.tolist())))
    return ExtendedModel("+".join(causes), causes, {k: res.params[k] for k in SOIL_PARAMETERS},
                         {k: v for k, v in res.params.items() if k not in SOIL_PARAMETERS}, res.test_mse,
                         per_signal_rms(problem, res.residuals, mask=judged),
                         mounting_offsets(problem, res.residuals).get("pitch", {}))


def cause_gain(problem: Problem, run_kind: np.ndarray, base: FitResult, outcome: Outcome) -> CauseGain:
    """What the model with every named cause gains over ``base`` on the held-out blocks of every
    run, as each cause was judged (judging.judge): overall, per step (each cause against its
    reference) and per signal, the IMU's pitch offset taken off (sensor_offset.offset_free); with
    the registration's pose evidence when it is a cause."""
    res, causes = outcome.chosen[-1], [r.name for r in outcome.chosen]
    base_r, res_r = offset_free(problem, base.residuals), offset_free(problem, res.residuals)
    judged_on = sorted(set(run_kind.tolist()))
    judged = np.isin(run_kind, judged_on)
    test = ~problem.train
    before = float(np.nanmean(capped_square(base_r[test & judged])))
    after_mse = float(np.mean(capped_square(res_r[test & judged])))
    after = per_signal_rms(problem, res_r, mask=judged)
    before_judged = per_signal_rms(problem, base_r, mask=judged)
    steps = [outcome.best] + ([outcome.second_round[0]] if len(outcome.chosen) > 1 else [])
    per_signal = {k: SignalGain(before_judged[k], after.get(k, float("nan")),
                                1 - after.get(k, np.nan) / before_judged[k] if before_judged[k] > 0 else 0.0)
                  for k in before_judged}
    pose_judged = next((c.kinematic for c in outcome.candidates if c.name == "terrain_offset"), None)
    return CauseGain(before, after_mse, judged_on, (before - after_mse) / before, outcome.best.z,
                     [GainStep(c.name, c.gain, c.z, c.held_out_mse_before, c.held_out_mse_after) for c in steps],
                     per_signal, pose_judged if "terrain_offset" in causes and pose_judged else None)


def no_cause_gain(base: FitResult, candidates: list[JudgedCandidate]) -> NoCauseGain:
    """With no cause named: no gain, and the best candidate (the ranking's first)."""
    return NoCauseGain(base.test_mse, base.test_mse, 0.0, candidates[0].name if candidates else None,
                       candidates[0].gain if candidates else 0.0)


def _cause_named(name: str, outcome: Outcome) -> str:
    """A named cause's physical explanation; for the registration of a campaign with several
    scans, with the scans it moves and the runs on each (the scans the pose shows misregistered)."""
    cause = CANDIDATES[name].cause
    pose = next((c.kinematic for c in outcome.candidates if c.name == name and c.kinematic), None)
    if pose is None or not pose.scans or len(pose.scans) < 2 or not pose.misregistered():
        return cause
    return cause + " (" + "; ".join(f"scan {s.scan}, " + ("run " if len(s.runs) == 1 else "runs ") + ", ".join(s.runs)
                                    for s in pose.misregistered()) + ")"


def diagnosis_result(problem: Problem, run_kind: np.ndarray, base: FitResult, duels: list[Duel], outcome: Outcome,
                     criteria: Criteria, t_start: float, judged: Verdict,
                     structures: tuple[ResidualStructure | None, ResidualStructure | None],
                     untested: str | None = None) -> DiagnosisResult:
    """The whole diagnosis from the search's ``outcome`` (the first round's comparisons ``duels``,
    judged on ``problem`` against the reference ``base``) and the ``judged`` verdict on what the
    models leave (``structures``: the base model's and the named causes' residual structure, None
    where it could not be tested, and why: ``untested``); wall time since ``t_start``
    (time.perf_counter, s).  The extended model and its gain are the
    search's catalog model even when the verdict does not name it (``unexplained.absorbed_by``)."""
    causes = [r.name for r in outcome.chosen]
    if outcome.chosen:
        extended = extended_model(problem, run_kind, causes, outcome.chosen[-1])
        gain: CauseGain | NoCauseGain = cause_gain(problem, run_kind, base, outcome)
    else:
        extended, gain = ExtendedModel(None, []), no_cause_gain(base, outcome.candidates)
    catalog = "; then ".join(_cause_named(c, outcome) for c in causes)
    plot_data = PlotData(problem.meta, problem.train, base.residuals,
                         outcome.chosen[-1].residuals if outcome.chosen else None)
    structure = {"base": structures[0].to_json() if structures[0] is not None else None,
                 "extended": structures[1].to_json() if structures[1] is not None else None,
                 "untested": untested}
    words = explanation(judged, catalog)
    if untested:
        words = f"{words}; whether structure beyond sensor noise remains could not be tested ({untested})"
    if judged.causes and outcome.equally_good and structures[0] is not None:
        note = ripple_between_tied(judged.causes[0], outcome.equally_good, structures[0].ripples())
        words = f"{words}; {note}" if note else words
    return DiagnosisResult(judged.cause, judged.causes, words, outcome.equally_good,
                           outcome.apart, duels + outcome.branch_duels, outcome.candidates, outcome.second_round,
                           baseline(problem, base), criteria, residual_analysis(problem, base.residuals), extended,
                           gain, time.perf_counter() - t_start, plot_data, judged.unexplained, structure)
