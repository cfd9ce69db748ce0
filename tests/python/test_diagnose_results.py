"""The diagnosis's typed results (juno.diagnose.results) write the JSON object `juno diagnose --json`
has always written: the same keys in the same order, a failed candidate in its short form, and
optional parts (a duel's stage, the registration's pose evidence) only when there is one.

No simulation: the records are built from made-up residuals and values.
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from juno.core import to_jsonable
from juno.diagnose import (Baseline, CauseGain, Contender, Criteria, DiagnosisResult, Duel, ExtendedModel, FitResult,
                           GainStep, JudgedCandidate, KinematicEvidence, NoCauseGain, Problem, ResidualAnalysis,
                           SignalGain, TiedPair, judge, public_json, summary_lines)
from juno.identify import PAPER_INITIAL

JUDGED_KEYS = ["name", "cause", "gain", "z", "gain_by_kind", "z_by_kind", "acts", "ablation", "kinematic", "judged_on",
               "held_out_mse_before", "held_out_mse_after", "significant", "test_mse", "train_mse", "n_params", "soil",
               "extension", "soil_at_bounds", "evaluations", "failed_evaluations", "status", "wall_time"]
RESULT_KEYS = ["cause", "causes", "explanation", "equally_good", "telling_apart", "head_to_head", "candidates",
               "second_round", "baseline", "criteria", "residual_analysis", "extended", "gain", "wall_time",
               "unexplained", "structure", "missing_columns", "sensor_noise"]


def _problem() -> tuple[Problem, np.ndarray]:
    """A drawbar and a terrain run of 40 s at 20 Hz, one signal each, in alternate 4 s blocks."""
    t = np.arange(0.0, 40.0, 0.05)
    runs = np.array(["dbp1"] * len(t) + ["t3d"] * len(t))
    times = np.concatenate([t, t])
    block = np.floor(times / 4.0).astype(int)
    problem = Problem("campaign", None, "unused.fmu", [], (block % 2) == 0,
                      {"run": runs, "signal": np.array(["speed"] * len(runs)), "time": times, "block": block})
    return problem, np.where(runs == "dbp1", "drawbar", "terrain")


def _fit(name: str, residuals: np.ndarray, **extension: float) -> FitResult:
    return FitResult(name, {**PAPER_INITIAL, **extension}, 1.0, 1.0, residuals, 3, 0.5)


def test_a_judged_candidate_writes_every_key_in_order_and_nested_records_as_objects():
    problem, run_kind = _problem()
    reference = np.random.default_rng(1).standard_normal(len(run_kind))
    verdict = judge(problem, run_kind, _fit("base", reference),
                    _fit("drivetrain_loss", 0.5 * reference, **{"drive.lossFraction": 0.2, "drive.friction": 5.0}),
                    _fit("drivetrain_loss", reference, **{"drive.lossFraction": 0.0, "drive.friction": 0.0}))
    out = verdict.to_json()
    assert list(out) == JUDGED_KEYS
    assert list(out["ablation"]) == ["gain", "z", "z_by_kind", "gain_by_kind"]
    assert out["kinematic"] is None and out["judged_on"] == ["drawbar", "terrain"]
    assert out["extension"] == {"drive.lossFraction": 0.2, "drive.friction": 5.0} and out["n_params"] == 2
    assert out["status"] == "ok" and out["gain"] == pytest.approx(0.75)    # residuals halved: squares quartered
    json.dumps(to_jsonable(out))      # plain JSON, nothing left as a record


def test_a_failed_candidate_writes_its_short_form():
    problem, run_kind = _problem()
    failed = FitResult("grouser", {}, np.inf, np.inf, np.zeros(0), 0, 0.1, error="diverged", failed_evaluations=7)
    verdict = judge(problem, run_kind, _fit("base", np.ones(len(run_kind))), failed)
    assert verdict.to_json() == {"name": "grouser", "cause": verdict.cause, "error": "diverged", "status": "failed",
                                 "failed_evaluations": 7, "significant": False, "acts": False, "gain": 0.0, "z": 0.0}
    assert verdict.n_params == 0     # a failed fit is charged for no parameters in the ranking


def test_a_duels_stage_and_the_registrations_evidence_appear_only_when_given():
    duel = Duel("drivetrain_loss", "grouser", {"drawbar": 3.1}, 0.02, True)
    assert list(duel.to_json()) == ["leader", "challenger", "z_by_kind", "gain", "challenger_better"]
    assert replace(duel, stage="final models").to_json()["stage"] == "final models"
    gain = CauseGain(2.0, 1.0, ["drawbar"], 0.5, 4.0, [GainStep("terrain_offset", 0.5, 4.0, 2.0, 1.0)],
                     {"speed": SignalGain(0.2, 0.1, 0.5)})
    assert "registration" not in gain.to_json()
    pose = KinematicEvidence(3.0, 0.3, 10.0, 0.9, True)
    with_pose = replace(gain, registration=pose).to_json()
    assert with_pose["registration"] == {"held_out_ms_as_scanned": 3.0, "held_out_ms_registered": 0.3, "ratio": 10.0,
                                         "gain": 0.9, "significant": True}


def _no_cause_result() -> DiagnosisResult:
    candidate = JudgedCandidate("slip_sinkage", "sinkage grows with slip", 0.01, 0.4, False, True, "ok", 0,
                                gain_by_kind={"drawbar": 0.01}, z_by_kind={"drawbar": 0.4}, n_params=1)
    tied = TiedPair(["a", "b"], 0.8, 1400.0, {"a": 1.0, "b": 0.9}, 0.1, 0.02, {"load_N": [1400.0], "a": [1.0],
                                                                               "b": [0.9]})
    return DiagnosisResult(
        "none", [], "no extension explains the held-out data significantly better", [], [tied], [], [candidate], [],
        Baseline({"soil.kh": 1e5}, 1.2, 1.1, {"speed": 0.01}, "ok", 0),
        Criteria(4.0, 2.5, 0.03, 0.75, None, "spin", {}, {}, 0.01, 4.0),
        ResidualAnalysis({"dbp1/speed": {"mean": 0.1, "rms": 1.1}}, 1.2),
        ExtendedModel(None, []), NoCauseGain(1.2, 1.2, 0.0, "slip_sinkage", 0.01), 12.0)


def test_the_diagnosis_writes_its_keys_in_order_without_the_figures_data():
    out = public_json(_no_cause_result())
    assert list(out) == RESULT_KEYS
    assert out["extended"] == {"name": None, "causes": []}
    assert list(out["gain"]) == ["held_out_mse_before", "held_out_mse_after", "relative", "best_candidate",
                                 "best_candidate_gain"]
    assert list(out["telling_apart"][0]) == ["models", "throttle", "load_N", "slip", "difference",
                                             "difference_within_campaign", "ladder"]
    assert list(out["criteria"]) == ["block_s", "z_min", "gain_min", "tie_ratio", "terrain_segment_s",
                                     "terrain_drive", "terrain_drive_training_loss", "terrain_drive_settled",
                                     "negligible_change", "registration_held_out_ratio", "terrain_replicas",
                                     "pitch_offset_free"]
    json.dumps(to_jsonable(out))


def test_the_printout_reads_the_typed_result():
    lines = summary_lines(_no_cause_result())
    assert lines[0] == "cause: none (no extension explains the held-out data significantly better)"
    assert lines[1].startswith("   slip_sinkage ") and "drawbar +1.0% (z 0.4)" in lines[1]
    assert lines[2].startswith("What would tell a from b: a steady drawbar run on flat ground at 1400 N")


def test_the_columns_a_campaign_lacks_close_the_printout_and_are_typed_in_the_json():
    """A campaign without pitch: the printout ends with the column, its runs and the cost, and
    the JSON's ``missing_columns`` has them as fields; a full campaign's is empty."""
    from juno.campaign import OPTIONAL_COLUMN_USES, MissingColumn
    assert public_json(_no_cause_result())["missing_columns"] == []
    lacking = MissingColumn("pitch", "drawbar", ("dbp1", "dbp2"), OPTIONAL_COLUMN_USES["pitch"]["drawbar"])
    result = replace(_no_cause_result(), missing_columns=[lacking])
    assert summary_lines(result)[-1] == ("no pitch in drawbar runs dbp1, dbp2: "
                                         + OPTIONAL_COLUMN_USES["pitch"]["drawbar"])
    assert to_jsonable(public_json(result))["missing_columns"] == [
        {"column": "pitch", "kind": "drawbar", "runs": ["dbp1", "dbp2"],
         "consequence": OPTIONAL_COLUMN_USES["pitch"]["drawbar"]}]


def test_a_stated_sensor_noise_closes_the_printout_and_every_column_s_noise_is_in_the_json():
    """The JSON's ``sensor_noise`` gives each run's columns their noise and whether it was stated
    or estimated; the printout names the stated columns, and warns of one far from its estimate."""
    from juno.sensor_noise import NoiseStatement, far_from_estimate
    assert public_json(_no_cause_result())["sensor_noise"] == []
    statements = [NoiseStatement("dbp1", "torque_left", 3.2, "stated", 0.25, 3.2, far_from_estimate(3.2, 0.25)),
                  NoiseStatement("dbp1", "omega_left", 0.005, "estimated", 0.005, None, None)]
    result = replace(_no_cause_result(), sensor_noise=statements)
    assert summary_lines(result)[-2:] == [
        "sensor noise stated in the manifest: torque_left 3.2 in run dbp1 (estimated 0.25); every other column's is "
        "estimated from its samples",
        "warning: column 'torque_left' of run dbp1: " + far_from_estimate(3.2, 0.25)]
    assert to_jsonable(public_json(result))["sensor_noise"] == [
        {"run": "dbp1", "column": "torque_left", "noise": 3.2, "source": "stated", "estimated": 0.25, "stated": 3.2,
         "warning": far_from_estimate(3.2, 0.25)},
        {"run": "dbp1", "column": "omega_left", "noise": 0.005, "source": "estimated", "estimated": 0.005,
         "stated": None, "warning": None}]


def test_a_branch_contender_ranks_like_a_judged_candidate():
    """choose_branch ranks final models (Contender) by the rule judged candidates are ranked by."""
    from juno.diagnose import ranked
    assert [c.name for c in ranked([Contender("a", 0.50, 3), Contender("b", 0.45, 1)])] == ["b", "a"]
    assert ranked([Contender("a", 0.50, 3)])[0].gain == pytest.approx(0.50)


def test_the_report_of_an_unexplained_discrepancy_tables_what_is_left(tmp_path):
    from dataclasses import replace

    from juno.diagnose import report_section
    from juno.residual_structure import Covariate, SignalStructure
    from juno.diagnose.verdict import Unexplained
    left = SignalStructure("torque_right", "N m", 10, 2.8, 5.1, 1.8, 1e-20, True,
                           [Covariate("side", 0.99, 10.2, "N m, left minus right")])
    result = replace(_no_cause_result(), cause="unexplained", plot_data=None,
                     unexplained=Unexplained("soil_patch", [left], ["soil_patch"], 0.2))
    text = "\n".join(report_section(result, tmp_path))
    assert "**Cause: unexplained.**" in text
    assert "soil_patch would remove only 20% of it, so it is not named" in text
    assert "| torque_right | 5.1 N m | 1.8 | side (99%, +10.2 N m, left minus right) |" in text
    json.dumps(to_jsonable(public_json(result)))


def test_the_report_gives_the_pitch_offset_in_degrees_and_what_was_made_of_it(tmp_path):
    """The base model's pitch offset by IMU mounting (rad in the JSON) is said in degrees, with
    whether every fit took it off as the IMU's mounting or kept it as evidence (a calibrated
    mounting); a campaign whose runs name their mountings has one for each; without a measured
    pitch nothing is said."""
    from dataclasses import replace

    from juno.diagnose import report_section
    base = _no_cause_result()
    offset = np.radians(1.5)
    result = replace(base, plot_data=None, baseline=replace(base.baseline, pitch_offset={"campaign": offset}))
    assert public_json(result)["baseline"]["pitch_offset"] == {"campaign": offset}
    free = "\n".join(report_section(result, tmp_path))
    assert "The measured pitch reads +1.50 deg (+26.18 mrad) from the base model's" in free
    assert "takes it off as the IMU's mounting, credited to no cause" in free
    calibrated = replace(result, criteria=replace(result.criteria, pitch_offset_free=False))
    assert "calibrated, so it is evidence like the rest" in "\n".join(report_section(calibrated, tmp_path))
    two = replace(base, plot_data=None,
                  baseline=replace(base.baseline, pitch_offset={"day1": offset, "day2": -offset / 3}))
    assert ("reads +1.50 deg (+26.18 mrad) on the mounting day1, -0.50 deg (-8.73 mrad) on the mounting day2"
            in "\n".join(report_section(two, tmp_path)))
    assert "measured pitch reads" not in "\n".join(report_section(replace(base, plot_data=None), tmp_path))


def test_a_registration_significant_on_the_pose_alone_says_so_and_why_it_is_not_named(tmp_path):
    """A soft patch sinks the wheels as a lowered scan would: the registration can pass the pose's
    bar while the patch is the cause.  The printout and the report say what its significance
    rests on, that the named cause explains the data better, and what it adds on top of it; a
    registration that is named, or not significant, gets no such sentence."""
    from juno.diagnose import report_section
    base = _no_cause_result()
    pose = KinematicEvidence(0.59, 0.18, 3.32, 0.70, True)
    registration = JudgedCandidate("terrain_offset", "the scan is misregistered", -0.007, 0.0, True, True, "ok", 0,
                                   gain_by_kind={"terrain": -0.05}, z_by_kind={"terrain": 0.0}, n_params=6,
                                   kinematic=pose)
    patch = JudgedCandidate("soil_patch", "soil varies", 0.79, 7.0, True, True, "ok", 0,
                            gain_by_kind={"drawbar": 0.8}, z_by_kind={"drawbar": 7.0}, n_params=5)
    on_top = replace(registration, gain=0.062, significant=False)
    result = replace(base, cause="soil_patch", causes=["soil_patch"], equally_good=[], telling_apart=[],
                     candidates=[patch, registration], second_round=[on_top], plot_data=None,
                     extended=ExtendedModel("soil_patch", ["soil_patch"]),
                     gain=CauseGain(4.9, 1.0, ["drawbar"], 0.79, 7.0, [GainStep("soil_patch", 0.79, 7.0, 4.9, 1.0)],
                                    {"speed": SignalGain(0.2, 0.1, 0.5)}))
    lines = summary_lines(result)
    said = lines[lines.index(next(x for x in lines if x.startswith(" * terrain_offset"))) + 1].strip()
    assert said.startswith("significant on the measured pose alone (held-out pose 3.32 times better registered, "
                           "evidence from 4 times); not named: soil_patch explains the held-out data better, "
                           "and on top of it the registration is not significant (further gain +6.2%)")
    assert "The registration is significant on the measured pose alone" in "\n".join(report_section(result, tmp_path))
    named = replace(result, cause="terrain_offset", causes=["terrain_offset"], second_round=[])
    assert not any("on the measured pose alone" in x for x in summary_lines(named))
    unexplained = replace(result, cause="unexplained", causes=[], second_round=[])
    assert any("not named: the diagnosis is unexplained; a soil effect" in x for x in summary_lines(unexplained))
    weak = replace(result, candidates=[patch, replace(registration, significant=False,
                                                      kinematic=replace(pose, ratio=1.2, significant=False))])
    assert not any("on the measured pose alone" in x for x in summary_lines(weak))
