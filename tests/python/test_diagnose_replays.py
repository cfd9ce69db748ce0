"""How a diagnosis's fits spend their simulations: what they compute must not depend on it.

* A replay asked for again with the same parameters (a fit returning to a point it evaluated)
  comes from the fit's ReplayCache, not from a new simulation; other parameters are simulated.
* A lone fit whose finite-difference Jacobians are evaluated over two worker processes is the
  same fit, bit for bit, as the one made in this process alone (evaluations counted alike).
* A soil patch's coarse search split into tasks (one per start, then the refinement from the
  best) is the fit made in one session, bit for bit: the same optimum, residuals, evaluations
  and failures, and a batch of fits reports them in the order of its jobs.
* A fit simulates each run only as far as its last training sample, and its residuals there are
  the whole replay's, bit for bit (drawbar runs, and a terrain run replayed in segments); a run
  it replays to its end anyway is the whole replay, which the result at the optimum reuses.
* Fits made one after another in this process share one FMU instance, each the same fit.
* The Jacobian SciPy asks for at the point it accepts with the budget spent is not simulated,
  and the fit is the same as the one that simulates it.
"""

from __future__ import annotations

import numpy as np

from dataclasses import replace

from juno.diagnose import fitting
from juno.diagnose.candidates import CANDIDATES
from juno.diagnose.fitting import (_coarse_points, _coarse_start_job, _refined_job, _split, fit_candidate,
                                   run_jobs)
from juno.diagnose.starts import patch_on_the_ground
from juno.diagnose.problem import (OUTPUT_INTERVAL, ReplayCache, build_problem, residuals_or_failure, run_kinds,
                                   training_part)
from juno.identify import PAPER_INITIAL, gridded_scans

pytest_plugins = ["harness_fixtures"]

SEED = 21


class CountingFMU:
    """An FMU that counts its simulations (run_residuals only calls ``simulate``)."""

    def __init__(self, fmu):
        self.fmu, self.simulations = fmu, 0

    def simulate(self, *args, **kwargs):
        self.simulations += 1
        return self.fmu.simulate(*args, **kwargs)


def test_a_replay_asked_for_again_is_remembered_not_simulated(small_campaign, harness_fmu, fmu_path):
    problem = build_problem(small_campaign(SEED).campaign, fmu_path, None)
    n_runs = len(problem.prepared)
    fmu, cache = CountingFMU(harness_fmu), ReplayCache()
    params = dict(PAPER_INITIAL)
    first, failure = residuals_or_failure(fmu, problem, params, ("drawbar",), cache)
    assert failure is None and fmu.simulations == n_runs
    again, _ = residuals_or_failure(fmu, problem, dict(params), ("drawbar",), cache)
    assert fmu.simulations == n_runs and cache.hits == n_runs, "the same parameters must not be simulated again"
    np.testing.assert_array_equal(again, first)
    uncached, _ = residuals_or_failure(harness_fmu, problem, params, ("drawbar",))
    np.testing.assert_array_equal(uncached, first)
    residuals_or_failure(fmu, problem, {**params, "soil.eta": params["soil.eta"] * 1.01}, ("drawbar",), cache)
    assert fmu.simulations == 2 * n_runs, "other parameters are another replay"


def test_a_lone_fit_is_the_same_with_its_jacobian_over_two_processes(small_campaign, fmu_path):
    synthetic = small_campaign(SEED, "drivetrain_loss")
    problem = build_problem(synthetic.campaign, fmu_path, None)
    candidate = CANDIDATES["drivetrain_loss"]
    start = dict(start_ext=start_extension(synthetic, candidate))
    here = fit_candidate(problem, candidate, start_soil(synthetic), max_nfev=3, workers=1, **start)
    spread = fit_candidate(problem, candidate, start_soil(synthetic), max_nfev=3, workers=2, **start)
    assert not here.error and not spread.error
    assert here.params == spread.params
    np.testing.assert_array_equal(here.residuals, spread.residuals)
    assert here.evaluations == spread.evaluations > 3, "every Jacobian point counts as an evaluation"


def start_soil(synthetic) -> dict[str, float]:
    """Where these tests' short fits start: the campaign's true soil (with start_extension, its
    true extension).  They specify how a fit's evaluations are made, not where it goes; from the
    paper's soil and no loss, the first trust-region step of a drivetrain loss's fit on a 4 s
    campaign goes to a soil the rover sinks into at initialisation, one failed simulation of a
    budget of a few, which makes the fit an error."""
    return {k: float(synthetic.truth["soil"][k]) for k in PAPER_INITIAL}


def start_extension(synthetic, candidate) -> dict[str, float]:
    """The campaign's true values of ``candidate``'s parameters (start_soil)."""
    return {k: float(v) for k, v in synthetic.truth["extension"].items() if candidate.owns(k)}


def same_fits(a, b) -> list[str]:
    """Differences between two FitResults apart from their wall times (empty if identical)."""
    diffs = [f"{k}: {getattr(a, k)!r} != {getattr(b, k)!r}" for k in
             ("name", "params", "train_mse", "test_mse", "evaluations", "failed_evaluations", "error")
             if getattr(a, k) != getattr(b, k)]
    if not np.array_equal(a.residuals, b.residuals, equal_nan=True):
        diffs.append("residuals differ")
    return diffs


def patch_job(campaign, fmu_path, budget: int = 3):
    """A soil-patch fit with three starts along the short campaign's 1 m of drawbar track (as
    patch_grid's, which keeps 0.5 m from either end and so has none on so short a track), each
    refined by a short fit, from the paper's soil, ``budget`` evaluations for the refinement."""
    problem = build_problem(campaign, fmu_path, None)
    grid = tuple((("soilPatch.x", x), ("soilPatch.y", 0.0), ("soilPatch.radius", 0.7), ("soilPatch.khFactor", 0.8),
                  ("soilPatch.strengthFactor", 0.8)) for x in (0.2, 0.5, 0.8))
    patch = replace(patch_on_the_ground(campaign, fmu_path), grid=grid)
    return (problem, patch, dict(PAPER_INITIAL), None, budget)


def test_a_patch_search_made_of_tasks_is_the_fit_made_in_one_session(small_campaign, fmu_path):
    """Every start of the coarse search tried on its own (as a pool's task would, here in this
    process), then the refinement from the best of them: fit_candidate's fit, bit for bit."""
    campaign = small_campaign(SEED, "soil_patch").campaign
    job = patch_job(campaign, fmu_path)
    problem, patch, start_soil, _, budget = job
    assert _split(job) and len(_coarse_points(patch)) >= 3, "the search must have several starts to split"
    whole = fit_candidate(problem, patch, start_soil, max_nfev=budget)
    tried = [_coarse_start_job((job, k)) for k in range(len(_coarse_points(patch)))]
    assert all(t.error is None for t in tried)
    assert len({t.cost for t in tried}) == len(tried), "the starts must differ (else any start would do)"
    split = _refined_job((job, tried))
    assert whole.error is None
    assert same_fits(split, whole) == []
    assert split.evaluations > sum(t.evaluations for t in tried) > len(tried) * patch.short_fits


def test_a_batch_with_a_split_patch_search_gives_the_serial_batch_in_order(small_campaign, fmu_path):
    """run_jobs over two processes (the patch search as tasks beside another candidate's fit)
    gives the serial run's fits, and says them in the order of the jobs."""
    campaign = small_campaign(SEED, "soil_patch").campaign
    patch = patch_job(campaign, fmu_path)
    jobs = [patch, (patch[0], CANDIDATES["drivetrain_loss"], dict(PAPER_INITIAL), None, 3)]
    said_serial, said_split = [], []
    serial = run_jobs(jobs, 1, None, said_serial.append)
    split = run_jobs(jobs, 2, None, said_split.append)
    for a, b in zip(split, serial):
        assert same_fits(a, b) == []
    assert [m.split(":")[0] for m in said_split] == [m.split(":")[0] for m in said_serial] == \
        ["  soil_patch", "  drivetrain_loss"]


def test_a_fit_simulates_each_run_only_as_far_as_its_training_samples(small_campaign, harness_fmu, fmu_path,
                                                                      tmp_path):
    """The runs as a fit replays them (training_part) compare the training samples only, and
    give the numbers the whole replay gives there; a run whose last block is held out is
    simulated only to its last training sample (the short campaign's first drawbar run, 5.5 s,
    ends in its held-out block 4-8 s).  A terrain run replayed in segments keeps its segments up
    to its last training sample."""
    campaign = small_campaign(SEED).campaign
    grids = {run_id: path for run_id, (path, _grid) in gridded_scans(campaign, tmp_path, "validate").items()}
    params = dict(PAPER_INITIAL)
    for problem, kinds in ((build_problem(campaign, fmu_path, None), ("drawbar",)),
                           (build_problem(campaign, fmu_path, grids, terrain_segment=3.0), ("terrain",))):
        part = training_part(problem, kinds)
        whole, failure = residuals_or_failure(harness_fmu, problem, params, kinds)
        assert failure is None
        trained, failure = residuals_or_failure(harness_fmu, part, params, kinds)
        assert failure is None and part.train.all()
        np.testing.assert_array_equal(trained, whole[problem.train[np.isin(run_kinds(problem), kinds)]])
        for full, short in zip([p for p in problem.prepared if p.kind in kinds], part.prepared):
            last = max(ts[-1] for ts, *_ in short.targets.values() if len(ts))
            stop = (short.segments[-1].stop if short.segments else short.duration)
            assert last <= stop < last + 2 * OUTPUT_INTERVAL or stop == full.duration, (full.run_id, last, stop)
    first = build_problem(campaign, fmu_path, None).prepared[0]
    short = training_part(build_problem(campaign, fmu_path, None), ("drawbar",)).prepared[0]
    assert first.duration > 4.5 and short.duration < 4.2, (first.duration, short.duration)


def test_a_run_the_fit_replays_to_its_end_is_not_simulated_again_at_the_optimum(small_campaign, fmu_path,
                                                                                 monkeypatch):
    """A drawbar run whose last training sample needs its replay to the end is replayed by the fit
    as itself (fitting.fit_part: compared on every sample, its training residuals picked), so the
    result at the optimum finds that replay in the fit's ReplayCache; a run the fit replays only
    to its last training sample (the first, whose last block is held out) is simulated there.
    The result is the replay of every run at the optimum, bit for bit."""
    from juno.diagnose.problem import residuals_by_run, training_run
    from juno.simulator import JunoFMU
    problem = build_problem(small_campaign(SEED).campaign, fmu_path, None)
    whole, start = [], 0
    for p in problem.prepared:
        n = sum(len(v[0]) for v in p.targets.values())
        if p.kind == "drawbar" and training_run(p, problem.train[start:start + n]).duration == p.duration:
            whole.append(p.run_id)
        start += n
    drawbar = [p.run_id for p in problem.prepared if p.kind == "drawbar"]
    assert whole and len(whole) < len(drawbar), (whole, drawbar)
    part = fitting.fit_part(problem, ("drawbar",))
    assert [p.run_id for p in part.prepared] == drawbar
    assert all((q is p) == (p.run_id in whole) for p, q in zip(problem.prepared, part.prepared))
    at_optimum: list[str] = []
    result_at_optimum = fitting._result_at_optimum

    def counted(session, *args):
        simulate = session.fmu.simulate
        session.fmu.simulate = lambda *a, **k: at_optimum.append("run") or simulate(*a, **k)
        try:
            return result_at_optimum(session, *args)
        finally:
            session.fmu.simulate = simulate
    monkeypatch.setattr(fitting, "_result_at_optimum", counted)
    res = fit_candidate(problem, None, dict(PAPER_INITIAL), max_nfev=3)
    assert not res.error
    assert len(at_optimum) == len(problem.prepared) - len(whole)
    with JunoFMU(fmu_path) as fmu:
        replayed, failures = residuals_by_run(fmu, problem, res.params)
    assert not failures
    np.testing.assert_array_equal(res.residuals, replayed)


def test_serial_fits_share_one_fmu_instance_and_are_the_fits_made_each_with_its_own(small_campaign, fmu_path,
                                                                                    monkeypatch):
    """A batch fitted in this process opens the FMU once for all its fits (every replay resets the
    instance), and each fit is the one fit_candidate makes with an FMU of its own, bit for bit."""
    problem = build_problem(small_campaign(SEED, "drivetrain_loss").campaign, fmu_path, None)
    jobs = [(problem, None, dict(PAPER_INITIAL), None, 2),
            (problem, CANDIDATES["drivetrain_loss"], dict(PAPER_INITIAL), None, 2)]
    alone = [fit_candidate(problem, c, soil, max_nfev=budget) for problem, c, soil, _ext, budget in jobs]
    opened = []

    class CountedFMU(fitting.JunoFMU):
        def __init__(self, *args, **kwargs):
            opened.append(args)
            super().__init__(*args, **kwargs)
    monkeypatch.setattr(fitting, "JunoFMU", CountedFMU)
    batch = run_jobs(jobs, workers=1, scheduler=None, say=lambda m: None)
    assert len(opened) == 1
    assert [same_fits(a, b) for a, b in zip(alone, batch)] == [[], []]


def test_the_jacobian_asked_for_with_the_budget_spent_is_not_simulated(small_campaign, fmu_path, monkeypatch):
    """SciPy's trust-region loop computes the Jacobian at each point it accepts, then stops when
    ``max_nfev`` evaluations are spent: that last Jacobian (one evaluation per free parameter:
    four soil parameters and a drivetrain loss's fraction alone here) is never used, and the fit
    with it skipped is the fit that simulates it, bit for bit.  Here both steps of a two-evaluation budget are
    accepted: the start, its Jacobian, the step, and no second Jacobian (7 evaluations, not 12)."""
    synthetic = small_campaign(SEED, "drivetrain_loss")
    problem = build_problem(synthetic.campaign, fmu_path, None)
    loss = CANDIDATES["drivetrain_loss"]
    candidate = replace(loss, params=loss.params[:1], active=loss.active[:1])
    start = dict(start_ext=start_extension(synthetic, candidate))
    lean = fit_candidate(problem, candidate, start_soil(synthetic), max_nfev=2, **start)
    init = fitting._TrainingResiduals.__init__

    def every_jacobian(self, *args, **kwargs):
        init(self, *args, **kwargs)
        self.max_nfev = None
    monkeypatch.setattr(fitting._TrainingResiduals, "__init__", every_jacobian)
    full = fit_candidate(problem, candidate, start_soil(synthetic), max_nfev=2, **start)
    assert lean.error is None and full.error is None
    assert same_fits(lean, full) == [f"evaluations: {lean.evaluations!r} != {full.evaluations!r}"]
    assert (lean.evaluations, full.evaluations) == (1 + 5 + 1, 1 + 5 + 1 + 5)


def test_a_manifest_that_says_the_imu_mounting_is_calibrated_holds_the_pitch_offset_at_none(small_campaign, fmu_path,
                                                                                             tmp_path):
    """The diagnosis's problem takes the IMU's pitch offset as a free nuisance unless the
    campaign's manifest says ``"imu_mounting": "calibrated"`` (sensor_offset.py)."""
    import json
    import shutil
    from juno.campaign import load_campaign
    source = small_campaign(SEED).path
    assert build_problem(load_campaign(source), fmu_path, None).pitch_offset_free
    copy = shutil.copytree(source, tmp_path / "campaign")
    manifest = json.loads((copy / "campaign.json").read_text())
    (copy / "campaign.json").write_text(json.dumps({**manifest, "imu_mounting": "calibrated"}))
    assert not build_problem(load_campaign(copy), fmu_path, None).pitch_offset_free
