"""The search for the cause: fit the base model and every candidate, judge them (the first
round), look for a further cause on top of the first (the second round), and when two first
causes are close, give each its own second round and compare the final models (choose_branch).
diagnose() runs it all and returns a DiagnosisResult."""

from __future__ import annotations

import contextlib
import shutil
import tempfile
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from ..campaign import Campaign, load_campaign, missing_columns, read_run
from ..errors import InputError
from ..identify import PAPER_INITIAL, gridded_scans, require_runs
from ..registration import HELD_OUT_RATIO, ScanRegistrations
from ..simulator import SOIL_PARAMETERS, JunoFMU, SimulationError
from ..telling_apart import heaviest_drawbar_load, telling_apart
from .assemble import diagnosis_result
from .candidates import (CANDIDATES, Candidate, combined, fmu_parameters, parameters_of_a_new_run,
                         run_parameters)
from .fitting import (BASE_ITERATIONS, CANDIDATE_ITERATIONS, FitJob, FitResult, better_of_two_fits, fit_candidate,
                      fit_objective, run_jobs, training_objective)
from .judging import (GAIN_MIN, NEAR_TIE, NEGLIGIBLE_CHANGE, TIE_RATIO, Z_MIN, head_to_head, judge,
                      leader_after_head_to_head, penalised_gain, ranked, relative_gain, ripple_maker_leads,
                      significant_but_for_its_soil, soil_at_bounds)
from .problem import BLOCK, Problem, build_problem, run_kinds
from .references import best_reference, on_reference_soil
from .results import Contender, Criteria, DiagnosisResult, Duel, JudgedCandidate, Ranked, TiedPair
from .ripple_nuisance import with_lug_ripple
from .starts import (patch_grid, patch_on_the_ground, patch_start, payload_for_the_rover, registration_candidate,
                     registration_evidence, registration_start)
from ..parallel import BackgroundTask, TaskPool
from ..periodic_structure import PeriodicBases, PeriodicStructure, periodic_structure, series_of_residuals
from ..residual_structure import UNITS, ResidualStructure, residual_structure
from ..sensor_noise import noise_statements
from ..scan_consistency import ScanTests, campaign_scan_consistency
from .terrain_drive import choose_terrain_drive, drive_problems, settle_terrain_drive
from .terrain_replicas import terrain_replicas
from .verdict import verdict

#: The fits of a first cause on a longer budget than a candidate's (search.second_round): a
#: soil patch's search alone makes several short fits and a long one, about three candidate
#: budgets, and a further extension must beat the first cause fitted on as long.
LONG_FIT = 3 * CANDIDATE_ITERATIONS


@dataclass
class Search:
    """What every step of the search shares: the campaign, the problem as the candidates are
    judged on it (and each residual's kind of run), the candidates searched with a campaign-made
    grid (and the registration, once known, with the offsets of each scan it moves), the
    registration's kinematic evidence (every scan's), where the fits run, and the progress
    reporter."""

    campaign: Campaign
    problem: Problem
    searched: dict[str, Candidate]
    registration: ScanRegistrations | None
    workers: int | None
    scheduler: str | None
    say: Callable[[str], None]
    #: the registration still being fitted (in a worker process of its own while the first fits
    #: run: it simulates nothing, and only the registration candidate's start needs it)
    registering: BackgroundTask | None = None
    #: what the periodic tests of the models of this campaign share (the same held-out samples)
    periodic_bases: PeriodicBases = field(default_factory=PeriodicBases)
    run_kind: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        self.run_kind = run_kinds(self.problem)

    def registration_known(self) -> None:
        """Waits for the registration being fitted (if any), makes the registration candidate
        the campaign's (starts.registration_candidate: one registration per scan), and says what
        it found."""
        if self.registering is None:
            return
        self.registration, self.registering = self.registering.result(), None
        self.searched["terrain_offset"] = registration_candidate(self.registration)
        for scan in self.registration.scans if self.registration is not None else ():
            runs = ("terrain run " if len(scan.runs) == 1 else "terrain runs ") + ", ".join(scan.runs)
            if scan.evidence is None:
                self.say(f"scan {scan.scan}: not registered ({runs} too short for training and held-out blocks)")
                continue
            self.say(f"registration of scan {scan.scan} fitted on the training blocks of {runs}: held-out pose "
                     f"{scan.evidence.ratio:.3g} times better than the scan as it is"
                     + (" (misregistered)" if scan.significant else ""))

    def candidate(self, name: str) -> Candidate:
        """The candidate ``name`` as this campaign searches it (``searched``, else the catalog's)."""
        return self.searched.get(name, CANDIDATES[name])

    def fits(self, jobs: list[FitJob]) -> list[FitResult]:
        """The fits of ``jobs``, in order (fitting.run_jobs, where this search's fits run)."""
        return run_jobs(jobs, self.workers, self.scheduler, self.say)


@dataclass
class Setting:
    """The campaign prepared: the problem (terrain runs replayed by ``terrain_drive``), the
    problem under every drive, the base model's fit, the training loss of each drive at the base
    model, the candidates that can be fitted, and every terrain run's gridded scan by run id
    (each scan's registration and each run's scan test are on its own)."""

    problem: Problem
    problems: dict[str, Problem]
    base: FitResult
    terrain_drive: str
    drive_losses: dict[str, float]
    names: list[str]
    grids: dict[str, Any] = field(default_factory=dict)


@dataclass
class FirstRound:
    """Every candidate fitted and judged against the base model (or the better reference): the
    fits, the reference, the judged candidates (significant first, the head-to-head winner
    leading), the penalised ranking's leader, the comparisons made and how the terrain runs were
    finally replayed (with each drive's lowest training loss)."""

    results: list[FitResult]
    base: FitResult
    candidates: list[JudgedCandidate]
    significant: list[JudgedCandidate]
    ranked_first: JudgedCandidate | None
    duels: list[Duel]
    terrain_drive: str
    settled_losses: dict[str, dict[str, Any]]
    #: the base model's drive torques tested for a ripple in the wheel angle (wheel_angle_ripple)
    ripple: PeriodicStructure | None = None


@dataclass
class Outcome:
    """What the search names: the first cause's judged record (None: no cause), the candidates
    (the named first cause leading), the ones equally good and the runs that would tell them
    apart, the second round, the chosen fits (the first cause's, then the model with both) and
    the comparisons between branches' final models."""

    best: JudgedCandidate | None
    candidates: list[JudgedCandidate]
    equally_good: list[str]
    second_round: list[JudgedCandidate] = field(default_factory=list)
    chosen: list[FitResult] = field(default_factory=list)
    branch_duels: list[Duel] = field(default_factory=list)
    apart: list[TiedPair] = field(default_factory=list)


# ------------------------------------------------------------------ the whole diagnosis

def diagnose(campaign: Campaign | str | Path, fmu: JunoFMU | None = None, workers: int | None = None,
             candidates: Sequence[str] | None = None,
             progress: Callable[[str], None] | None = None, scheduler: str | None = None,
             terrain_segment: float | None = None) -> DiagnosisResult:
    """Runs the whole analysis (the package's docstring) and returns the diagnosis.
    ``terrain_segment`` (s, experimental): replay the terrain run in segments of that length,
    each restarted at the measured pose and speed (build_problem); None: one whole replay."""
    say = progress or (lambda m: None)
    t_start = time.perf_counter()
    campaign = load_campaign(campaign) if not isinstance(campaign, Campaign) else campaign
    from ..simulator import default_fmu_path
    fmu_path = str(fmu.fmu_path) if fmu is not None else str(default_fmu_path())
    names = list(candidates or CANDIDATES)
    require_runs(campaign, "diagnose")
    missing = missing_columns(campaign)
    noise = noise_statements(campaign)
    with tempfile.TemporaryDirectory(prefix="juno-diagnose-") as tmp, contextlib.ExitStack() as stack:
        fmu_path = fmu_snapshot(fmu_path, tmp, scheduler)
        registering: list[BackgroundTask] = []

        def start_registration(grids: dict[str, Any]) -> None:
            """The kinematic registration of every scan, fitted in a process of its own from the
            moment the scans are gridded (in this process when the diagnosis is to run in one)."""
            registering.append(stack.enter_context(
                BackgroundTask(_registration_task, (campaign, grids), background=workers != 1)))
        bases = PeriodicBases()
        setting = prepare(campaign, fmu_path, names, tmp, terrain_segment, say, workers, on_grid=start_registration,
                          periodic_bases=bases)
        searched = {"soil_patch": replace(patch_on_the_ground(campaign, fmu_path), grid=patch_grid(campaign)),
                    "payload": payload_for_the_rover(campaign, fmu_path),
                    **({"grouser": with_lug_ripple(CANDIDATES["grouser"], setting.problem, setting.base.params,
                                                   setting.base.residuals)} if "grouser" in setting.names else {})}
        search = Search(campaign, setting.problem, searched, None, workers, scheduler, say,
                        registering[0] if registering else None, periodic_bases=bases)
        stack.callback(lambda: search.problem.terrain_replicas and search.problem.terrain_replicas.close())
        first = first_round(search, setting)
        outcome = further_causes(search, first)
        *structures, untested = what_the_models_leave(campaign, fmu_path, search.problem, first.base, outcome, say,
                                                      workers if scheduler is None else None, search.periodic_bases)
        scan = scan_against_pose(campaign, setting.grids, say)
    criteria = Criteria(BLOCK, Z_MIN, GAIN_MIN, TIE_RATIO, terrain_segment, first.terrain_drive, setting.drive_losses,
                        first.settled_losses, NEGLIGIBLE_CHANGE, HELD_OUT_RATIO,
                        len(search.problem.terrain_replicas.problems) if search.problem.terrain_replicas else 0,
                        search.problem.pitch_offset_free)
    judged = verdict([r.name for r in outcome.chosen], *structures, scan=scan, candidates=first.candidates)
    result = diagnosis_result(search.problem, search.run_kind, first.base, first.duels, outcome, criteria, t_start,
                              judged, (structures[0], structures[1]), untested)
    if result.structure is not None:
        result.structure["scan"] = scan.to_json() if scan is not None else None
    return replace(result, missing_columns=missing, sensor_noise=noise)


def scan_against_pose(campaign: Campaign, grids: dict[str, Any], say: Callable[[str], None]) -> ScanTests | None:
    """Every terrain run's measured pose against its own gridded scan (``grids``, by run id;
    juno.scan_consistency, no simulation), or None without a terrain run."""
    if not grids:
        return None
    scan = campaign_scan_consistency(campaign, grids, BLOCK)
    if scan is not None:
        say(scan.summary())
    return scan


def _registration_task(args: tuple[Campaign, dict[str, Any]]) -> ScanRegistrations | None:
    """starts.registration_evidence of (campaign, each terrain run's gridded scan): a picklable
    task."""
    campaign, grids = args
    return registration_evidence(campaign, grids)


def terrain_runs_named(campaign: Campaign) -> str:
    """"terrain run ID" or "terrain runs ID, ID, ..." (a campaign may have several)."""
    ids = [r.id for r in campaign.runs_of_kind("terrain")]
    return ("terrain run " if len(ids) == 1 else "terrain runs ") + ", ".join(ids)


def fmu_snapshot(fmu_path: str, tmp: str, scheduler: str | None) -> str:
    """The FMU every fit of one diagnosis opens: a copy in ``tmp`` taken once, at the start.
    Each fit opens the FMU file anew (a worker process cannot share an open instance), so an FMU
    rebuilt or replaced while a diagnosis runs would otherwise have some fits made with one model
    and some with another, compared as if they were one.  On a Dask cluster (``scheduler``) the
    workers need the FMU at the path given, so that path is used as it is."""
    if scheduler is not None:
        return fmu_path
    copy = Path(tmp) / "fmu" / Path(fmu_path).name
    copy.parent.mkdir()
    shutil.copyfile(fmu_path, copy)
    return str(copy)


def what_the_models_leave(campaign: Campaign, fmu_path: str, problem: Problem, base: FitResult, outcome: Outcome,
                          say: Callable[[str], None], workers: int | None = None,
                          periodic_bases: PeriodicBases | None = None
                          ) -> tuple[ResidualStructure | None, ResidualStructure | None, str | None]:
    """The residual structure test (juno.residual_structure) of the base model and of the model
    with every named cause (None when none was named), on the held-out blocks of the drawbar
    runs, and why a test could not be made (None when both were); the bootstrap's replays run in
    ``workers`` local processes (None: one per core); ``periodic_bases``: what the search's
    periodic test of the base model kept (Search.periodic_bases).

    A test whose replicas cannot be replayed (a replica, the model replayed with fresh sensor noise
    on its inputs, diverged) is None: with a cause named, the cause stands on its held-out evidence
    and the result says that what it leaves could not be tested; with none named, neither "none"
    nor "unexplained" can be said, and the simulation's error is raised."""
    models = [base] + ([outcome.chosen[-1]] if outcome.chosen else [])
    data = {p.run_id: read_run(campaign, p.run_id) for p in problem.prepared if p.kind == "drawbar"}
    # the models' periodic tests scan the same samples at the same angles
    bases = periodic_bases if periodic_bases is not None else PeriodicBases()
    tests: list[ResidualStructure | None] = []
    untested = None
    with JunoFMU(fmu_path) as fmu, TaskPool(workers) as pool:
        for m in models:
            try:
                tests.append(residual_structure(campaign, fmu, problem.prepared, problem.meta, problem.train,
                                                m.residuals, fmu_parameters(m.params), data=data, pool=pool,
                                                periodic_bases=bases, for_run=run_parameters))
            except SimulationError as exc:
                if not outcome.chosen:
                    raise
                tests.append(None)
                untested = untested or f"a replica of the {m.name} model could not be replayed: {exc}"
    for m, t in zip(models, tests):
        found = (", ".join(t.findings(brief=True)) or "none") if t is not None else "not tested"
        small = ", ".join(s.brief() for s in t.below_floors()) if t is not None else ""
        found += f" (below the floors: {small})" if small else ""
        say(f"structure beyond sensor noise left by the {m.name} model on the drawbar runs: {found}")
    return tests[0], (tests[1] if len(tests) > 1 else None), untested


def prepare(campaign: Campaign, fmu_path: str, names: list[str], tmp: str, terrain_segment: float | None,
            say: Callable[[str], None], workers: int | None = 1,
            on_grid: Callable[[Any], None] | None = None, periodic_bases: PeriodicBases | None = None) -> Setting:
    """Grids every terrain run's scan into ``tmp`` (each terrain run is replayed on its own), builds
    the problem, fits the base model (an error if it fails; its Jacobians over ``workers`` local
    processes) and chooses the terrain drive the candidates are fitted with.  Without a terrain
    run the candidates that need one are left out.  ``on_grid`` is called with every terrain
    run's gridded scan (by run id) as soon as they are made.  When the base model's drive torques
    ripple with the wheel angle, the fits take that ripple as a nuisance from then on
    (_with_ripple_as_nuisance); ``periodic_bases``: what that test keeps (Search.periodic_bases)."""
    grid_file: dict[str, str] | None = None
    grids: dict[str, Any] = {}
    if campaign.runs_of_kind("terrain"):
        scans = gridded_scans(campaign, tmp, "validate")
        grid_file = {run_id: path for run_id, (path, _grid) in scans.items()}
        grids = {run_id: g for run_id, (_path, g) in scans.items()}
        if on_grid is not None:
            on_grid(grids)
    else:
        # A candidate is never missing from the results unexplained, and a diagnosis left with no
        # candidate would report "none" without having tried one: an error, before the base fit.
        left_out = [n for n in names if CANDIDATES[n].needs_terrain]
        names = [n for n in names if not CANDIDATES[n].needs_terrain]
        why = "needs a terrain run (a run with its LIDAR scan), and the campaign has none"
        if not names:
            raise InputError(f"'diagnose': every candidate asked for ({', '.join(left_out)}) {why}",
                             campaign.manifest_path)
        if left_out:
            say(f"left out {', '.join(left_out)}: {why}")
    problem = build_problem(campaign, fmu_path, grid_file, terrain_segment)
    say(f"fitting the base model on the training blocks ({int(np.sum(problem.train))} residuals)")
    base = fit_candidate(problem, None, dict(PAPER_INITIAL), max_nfev=BASE_ITERATIONS, workers=workers)
    if base.error:
        raise SimulationError("the base model could not be fitted", [base.error])
    base = _with_ripple_as_nuisance(campaign, problem, base, periodic_bases or PeriodicBases(), say, workers)
    terrain_drive, drive_losses, problems = "spin", {}, {"spin": problem}
    if grid_file is not None:
        problems = drive_problems(campaign, problem, terrain_segment)
        problem, base, terrain_drive, drive_losses = choose_terrain_drive(campaign, problem, base,
                                                                          terrain_segment, problems)
        say(f"{terrain_runs_named(campaign)} replayed by {terrain_drive} (training fit loss at the base model: "
            + ", ".join(f"{d} {v:.3g}" for d, v in drive_losses.items()) + ")")
    say(f"base model: held-out mean squared residual {base.test_mse:.4g}; fitting {len(names)} candidates")
    return Setting(problem, problems, base, terrain_drive, drive_losses, names, grids)


def _with_ripple_as_nuisance(campaign: Campaign, problem: Problem, base: FitResult, bases: PeriodicBases,
                             say: Callable[[str], None], workers: int | None) -> FitResult:
    """When ``base``'s drive torques ripple with the wheel angle (ripple_of), every fit from here
    on takes that ripple as a nuisance (ripple_nuisance.py: ``problem.ripple_lugs``), and the
    base model is fitted again so, as it was at first, from the paper's soil (its loss is another
    one now, and every fit of the base model starts where the first did); otherwise ``base`` as
    it is."""
    found = ripple_of(campaign, problem, base, bases)
    if found is None or not found.significant:
        return base
    problem.ripple_lugs = found.found()[0].lugs
    say(f"the drive torques ripple with the wheel angle at {problem.ripple_lugs} per revolution, which no "
        "candidate makes: the fits leave it out (refitting the base model)")
    refit = fit_candidate(problem, None, dict(PAPER_INITIAL), max_nfev=BASE_ITERATIONS, workers=workers)
    if refit.error:
        raise SimulationError("the base model could not be fitted with the ripple left out", [refit.error])
    return refit


# ------------------------------------------------------------------ the first round

def first_round(search: Search, setting: Setting) -> FirstRound:
    """Fits every candidate, settles the terrain drive over every fitted model, and judges each
    candidate against the better reference (best_reference); ``search`` is updated to the
    problem the candidates are judged on."""
    names, base = setting.names, setting.base
    fitted, restarts = _first_fits(search, setting)
    terrain_drive, settled_losses = setting.terrain_drive, {}
    if len(setting.problems) > 1:
        fitted_drive = terrain_drive
        terrain_drive, settled_losses, settled = settle_terrain_drive(setting.problems, terrain_drive,
                                                                      [base] + fitted)
        base, fitted = settled[0], settled[1:]
        search.problem = setting.problems[terrain_drive]
        search.run_kind = run_kinds(search.problem)
        search.say(f"{terrain_runs_named(search.campaign)} judged as replayed by {terrain_drive} (fitted with "
                   f"{fitted_drive}; lowest "
                   "training fit loss: " + ", ".join(f"{d} {v['loss']:.3g} ({v['model']})"
                                                     for d, v in settled_losses.items()) + ")")
    problem, run_kind = search.problem, search.run_kind
    terrain_replicas(problem, search.campaign)
    results = fitted[:len(names)]
    for n, again in zip(restarts, fitted[len(names):]):
        i = names.index(n)
        results[i] = better_of_two_fits(problem, run_kind, results[i], again)
    base, switched_off = best_reference(problem, run_kind, base, results, "base")
    moved = [on_reference_soil(problem, run_kind, base, res) for res in results]
    for old_fit, res in zip(results, moved):
        if res is not old_fit:          # its extension switched off is now the reference itself
            switched_off[res.name] = base
    results = moved
    judged = ranked([judge(problem, run_kind, base, res, switched_off.get(res.name), search.registration)
                     for res in results])
    significant = [c for c in judged if c.significant]
    ranked_first = significant[0] if significant else None
    significant, duels = leader_after_head_to_head(problem, run_kind, significant, results)
    ripple = wheel_angle_ripple(search, base)
    if ripple is not None and ripple.significant:
        significant, by_ripple = ripple_maker_leads(problem, run_kind, significant, results)
        duels += by_ripple
    candidates = significant + [c for c in judged if not c.significant]
    return FirstRound(results, base, candidates, significant, ranked_first, duels, terrain_drive, settled_losses,
                      ripple)


def wheel_angle_ripple(search: Search, model: FitResult) -> PeriodicStructure | None:
    """The periodic test (juno.periodic_structure) of ``model``'s held-out drive torques on the
    drawbar runs: whether they ripple with the wheel angle at a lug count.  No simulation: the
    residuals are the model's, the sensor noise is stated or estimated from the data, and the ripple is in
    every catalog model's residuals alike (none makes one).  None without a drawbar run that
    measures a drive torque and its side's spin."""
    found = ripple_of(search.campaign, search.problem, model, search.periodic_bases)
    if found is not None and found.significant:
        search.say("the drive torques ripple with the wheel angle: " + ", ".join(s.brief() for s in found.found()))
    return found


def ripple_of(campaign: Campaign, problem: Problem, model: FitResult, bases: PeriodicBases
              ) -> PeriodicStructure | None:
    """wheel_angle_ripple of ``model`` on ``problem`` (``bases``: Search.periodic_bases)."""
    data = {p.run_id: read_run(campaign, p.run_id) for p in problem.prepared if p.kind == "drawbar"}
    series = series_of_residuals(problem.prepared, problem.meta, problem.train, model.residuals, data)
    return periodic_structure(series, UNITS, bases=bases) if series else None


def _first_fits(search: Search, setting: Setting) -> tuple[list[FitResult], list[str]]:
    """Every candidate's fit from the base optimum (with its extension at its start: a soil patch
    where the base model is worst, the registration where the pose puts it), then, for those that
    restart from the paper's soil (Candidate.soil_restart), their fits from there; and the names
    of those.

    Starting at the base optimum with the extension at (or next to) its neutral setting is
    starting at the base model: least squares accepts only improving steps, so a nested
    extension can never end worse than the base on the training data (the grouser carrying a lug
    ripple is the exception: it starts with the ripple on and is fitted on a loss that keeps the
    ripple, ripple_nuisance.with_lug_ripple)."""
    names, base, problem = setting.names, setting.base, setting.problem
    start_soil = {k: base.params[k] for k in SOIL_PARAMETERS}
    first_starts = {"soil_patch": patch_start(search.campaign, problem, base.residuals)}

    def job(n: str) -> FitJob:
        return problem, search.searched.get(n, CANDIDATES[n]), start_soil, first_starts.get(n)
    # The registration candidate starts where the registration puts the scan: while that is
    # being fitted, the other fits run, and it is fitted after them.
    later = [n for n in names if n == "terrain_offset"] if search.registering is not None else []
    if not later:
        first_starts["terrain_offset"] = registration_start(search.registration)
    now = [n for n in names if n not in later]
    restarts = [n for n in names if CANDIDATES[n].soil_restart]
    fitted = search.fits([job(n) for n in now] + [(problem, search.candidate(n), dict(PAPER_INITIAL), None)
                                                  for n in restarts])
    search.registration_known()
    first_starts["terrain_offset"] = registration_start(search.registration)
    fit_of = dict(zip(now, fitted)) | dict(zip(later, search.fits([job(n) for n in later]) if later else []))
    return [fit_of[n] for n in names] + fitted[len(now):], restarts


def equally_good_as(best: JudgedCandidate | None, significant: Sequence[JudgedCandidate]) -> list[str]:
    """The significant runners-up whose gain is at least TIE_RATIO of the cause's."""
    return [c.name for c in significant[1:] if best and c.gain >= TIE_RATIO * best.gain]


# ------------------------------------------------------------------ further causes and branches

def further_causes(search: Search, first: FirstRound) -> Outcome:
    """The second round on top of the first cause.  When the head-to-head test put a candidate
    with more parameters ahead of the penalised ranking's leader, or a runner-up is within
    NEAR_TIE of the leader after the charge and the held-out data do not prefer the leader
    (tie_settled), the two are alternatives whose duel was decided on one-cause models only, so
    each gets its own second round and the final models are compared (choose_branch).  A
    runner-up held back by its soil alone (judging.significant_but_for_its_soil) can be such an
    alternative; its branch counts only if its final model brings the soil back from the bound
    (branches_with_real_soil)."""
    significant = first.significant
    best = significant[0] if significant else None
    equally_good = equally_good_as(best, significant)
    if not best:
        return Outcome(None, first.candidates, equally_good)
    fit_of = {r.name: r for r in first.results}
    tie_duels: list[Duel] = []

    def settled(runner_up: Ranked, leader: Ranked = best) -> bool:
        duel = tie_settled(search.problem, search.run_kind, fit_of[leader.name], fit_of[runner_up.name])
        tie_duels.append(duel)
        if duel.challenger_better:
            search.say(f"{leader.name} explains the held-out data significantly better than {runner_up.name} "
                       f"(z {max(duel.z_by_kind.values()):.1f}): the near tie is settled, {runner_up.name} "
                       "gets no second round of its own")
        return duel.challenger_better
    held_back = [c for c in first.candidates if not c.significant and significant_but_for_its_soil(c)]
    branches = first_cause_branches(best, first.ranked_first, significant, settled, held_back)
    excluded = set(equally_good) | {b.name for b in branches}
    more = [c.name for c in first.candidates if c.name not in excluded and not c.error]
    rounds = [second_round(search, fit_of[b.name], more) for b in branches]
    kept = branches_with_real_soil([r[1] for r in rounds], [b in held_back for b in branches])
    for i in sorted(set(range(len(branches))) - set(kept)):
        search.say(f"{branches[i].name}: no second cause brings its soil back from the bound of the search; "
                   "its branch names no cause")
    branches, rounds = [branches[i] for i in kept], [rounds[i] for i in kept]
    pick, branch_duels = 0, []
    if len(branches) > 1:
        pick, branch_duels = choose_branch(search.problem, search.run_kind, first.base, [r[1] for r in rounds],
                                           ripple=first.ripple is not None and first.ripple.significant)
    best, (judged_second, chosen) = branches[pick], rounds[pick]
    significant = [best] + [c for c in significant if c.name != best.name]
    candidates = significant + [c for c in first.candidates if not c.significant and c.name != best.name]
    equally_good = equally_good_as(best, significant)
    apart = tied_models_apart(search.campaign, search.problem, fit_of[best.name], [fit_of[n] for n in equally_good])
    return Outcome(best, candidates, equally_good, judged_second, chosen, tie_duels + branch_duels, apart)


def first_cause_branches(best: Ranked, ranked_first: Ranked, significant: Sequence[Ranked],
                         settled: Callable[[Ranked], bool] = lambda runner_up: False,
                         held_back: Sequence[Ranked] = ()) -> list[Ranked]:
    """The first causes that each get a second round: the leader (``best``, after any
    head-to-head test), the penalised ranking's leader if the head-to-head test overturned it,
    and the closest other candidate whose penalised gain is within NEAR_TIE of theirs: a
    significant one (``significant`` is ranked) unless ``settled(runner_up)``, the held-out data
    already preferring the leader to it (tie_settled); else one of ``held_back``, those that fail
    significance by their soil alone (judging.significant_but_for_its_soil), unsettled.
    ``settled`` is asked of that closest significant candidate only.

    Why the held-back: the soil-bound rule (judging.is_significant) judges a model as the cause
    it would name, and with two causes hidden a one-cause model is incomplete.  Fitted alone, a
    drivetrain loss bends the soil to a bound to make up for a hidden slip-sinkage, which a
    grouser's lugs and thrust take up within a real soil; the loss is the truer first cause, and
    with slip-sinkage on top its soil comes back.  So a held-back runner-up is an alternative
    first cause whose final model decides (choose_branch), and only if that model's soil is real
    (branches_with_real_soil).  Why no settling for it: its one-cause residuals carry the bent
    soil's error, which the leader's lack by construction, so the paired test between the two
    one-cause models says nothing about the branch (on a loss + slip-sinkage campaign the grouser
    was better unit by unit at z 3.7, while the final models' held-out mean squared residuals were
    1.29 for loss + slip-sinkage and 1.51 for grouser + slip-sinkage)."""
    branches = [best] + ([ranked_first] if ranked_first.name != best.name else [])
    top = max(penalised_gain(b) for b in branches)

    def close(group: Sequence[Ranked]) -> list[Ranked]:
        return [c for c in group if c.name not in {b.name for b in branches} and top - penalised_gain(c) < NEAR_TIE]
    runner_up = close(significant)[:1]
    if runner_up:
        return branches + [c for c in runner_up if not settled(c)]
    return branches + close(held_back)[:1]


def branches_with_real_soil(finals: Sequence[Sequence[FitResult]], held_back: Sequence[bool]) -> list[int]:
    """The indices of the branches (each the chosen fits of one first cause and its second round,
    ``finals``) that can be reported: every one whose first cause was significant, and a
    held-back one (``held_back``) only where its final model's soil sits at no bound of the
    search (judging.soil_at_bounds): the rule that held it back, applied to the model it would
    name."""
    return [i for i, (fits, back) in enumerate(zip(finals, held_back)) if not back or not soil_at_bounds(fits[-1].params)]


def tie_settled(problem: Problem, run_kind: np.ndarray, leader: FitResult, runner_up: FitResult) -> Duel:
    """Whether the leader's one-cause model explains the held-out data significantly better than
    a runner-up's within NEAR_TIE of it: judging.head_to_head with the runner-up's model as the
    reference and the leader's as the challenger (stage "near tie").

    Why: a cause is named by two rules, the gain less the charge per parameter (judging.ranked)
    and, where those disagree with the data, the paired test over held-out units
    (judging.leader_after_head_to_head).  A margin under one parameter's charge decides nothing
    by the first rule, and that is why the runner-up gets a second round of its own; but when
    the paired test prefers the leader unit by unit, the held-out data have decided by the
    second rule, the one that overturns a leader, and both rules agree.  Only when neither decides is the tie left to the final models."""
    return replace(head_to_head(problem, run_kind, runner_up, leader), stage="near tie")


def choose_branch(problem: Problem, run_kind: np.ndarray, base: FitResult,
                  branches: Sequence[Sequence[FitResult]], ripple: bool = False) -> tuple[int, list[Duel]]:
    """Which of several alternative explanations (each the chosen fits of one first cause and
    its second round) to report: their final models are ranked by held-out gain over ``base``
    less GAIN_MIN per parameter, and a runner-up with more parameters and a larger raw gain
    leads if it wins head_to_head, as in the first round; with the drive torques rippling with
    the wheel angle (``ripple``), a final model with a cause that makes the ripple leads one
    without unless that one wins head to head (judging.ripple_maker_leads), as in the first
    round.  Returns the index of the chosen branch and the comparisons made (stage "final
    models", or "final models, ripple").

    Why: the first round compares one-cause models.  With two effects hidden, a grouser (lugs
    that mimic a drivetrain loss, a thrust gain that takes up part of a slip-sinkage) can beat
    the loss as a one-cause model, and grouser (+ slip-sinkage) be named where the truth is
    loss + slip-sinkage."""
    summaries, fits = [], []
    everywhere = np.ones(len(run_kind), bool)
    for chosen in branches:
        label = "+".join(r.name for r in chosen)
        final = replace(chosen[-1], name=label)
        # a two-cause fit is named after its second; a registration counts six per scan it moves
        n_params = sum(CANDIDATES[r.name].parameters_in(r.params) for r in chosen)
        gain = relative_gain(problem, base.residuals, final.residuals, everywhere)
        summaries.append(Contender(label, gain, n_params))
        fits.append(final)
    order, duels = leader_after_head_to_head(problem, run_kind, ranked(summaries), fits)
    duels = [replace(d, stage="final models") for d in duels]
    if ripple:
        order, by_ripple = ripple_maker_leads(problem, run_kind, order, fits)
        duels += [replace(d, stage="final models, ripple") for d in by_ripple]
    return next(i for i, s in enumerate(summaries) if s.name == order[0].name), duels


def tied_models_apart(campaign: Campaign, problem: Problem, named: FitResult, tied: list[FitResult]
                      ) -> list[TiedPair]:
    """The steady drawbar run that would tell the cause's fit from each fit reported equally
    good (juno.telling_apart), with the campaign's rover; [] when nothing is tied.  Two models
    that fit the campaign equally well usually part at loads beyond the campaign's heaviest
    run, where their predicted steady slips differ by far more than the sensor noise."""
    if not tied:
        return []
    fixed = dict(campaign.rover)
    with JunoFMU(problem.fmu_path) as fmu:
        found = telling_apart(fmu, (named.name, parameters_of_a_new_run({**fixed, **named.params})),
                              {r.name: parameters_of_a_new_run({**fixed, **r.params}) for r in tied},
                              heaviest_drawbar_load(campaign))
    return [TiedPair.from_telling_apart(f) for f in found]


# ------------------------------------------------------------------ the second round

def second_round(search: Search, first_res: FitResult, more: list[str]
                 ) -> tuple[list[JudgedCandidate], list[FitResult]]:
    """Is there a further cause on top of ``first_res``?  Each candidate named in ``more`` (even
    one that did not help on its own: an unmodelled first cause can hide it) is refitted
    together with the first cause (starting at its optimum, and from the paper's soil too where
    both restart) and judged against it with the same criteria.  Returns the judged second round
    (ranked) and the chosen fits: ``[first_res]``, or
    ``[first_res, model with both causes]`` when the best of the round is significant."""
    first = search.searched.get(first_res.name, CANDIDATES[first_res.name])
    if not more:
        return [], [first_res]
    search.say(f"first cause: {first.name}; looking for a second cause among {', '.join(more)}")
    problem, run_kind = search.problem, search.run_kind
    results, continued = _second_fits(search, first_res, more)
    reference = continued if fit_objective(problem, run_kind, continued) <= \
        fit_objective(problem, run_kind, first_res) else first_res
    reference, switched_off = best_reference(problem, run_kind, reference, results, first_res.name)
    judged = ranked([judge(problem, run_kind, reference, res, switched_off.get(res.name)) for res in results])
    judged, adopted = _survives_first_cause_refit(search, first_res, reference, results, switched_off, judged)
    named_second = bool(judged and judged[0].significant)
    # With no second cause, a first-cause fit that the refit improved is the model reported.
    chosen = [adopted if adopted is not None and not named_second else first_res]
    if named_second:
        both = next(r for r in results if r.name == judged[0].name)
        chosen.append(refit_from_paper_soil(search, first, both))
    return judged, chosen


def _second_fits(search: Search, first_res: FitResult, more: list[str]) -> tuple[list[FitResult], FitResult]:
    """Every candidate of ``more`` fitted together with the first cause (the better of two starts
    where both restart from the paper's soil), and the first cause alone fitted on for LONG_FIT.

    The reference is the first cause's model fitted on for at least as long as the others (its
    fit may not have converged): a second extension must beat that, not merely the first fit's
    stopping point; otherwise an extension "on top" can merely finish an unconverged first fit
    and be named a second cause.

    Two causes that both restart from the paper's soil (Candidate.soil_restart) are also fitted
    together from there: the first cause's optimum has its soil bent to absorb the second cause
    as well, and a joint fit started in that basin can stay in it and judge the right second
    cause too weak.  The better fit of each pair is chosen by training_objective, not the
    drawbar-only fit_objective (why: its docstring)."""
    first = search.searched.get(first_res.name, CANDIDATES[first_res.name])
    problem = search.problem
    start_soil = {k: first_res.params[k] for k in SOIL_PARAMETERS}
    start_ext = {k: v for k, v in first_res.params.items() if k not in SOIL_PARAMETERS}
    second_starts = {"soil_patch": patch_start(search.campaign, problem, first_res.residuals),
                     "terrain_offset": registration_start(search.registration)}
    jobs = [(problem, combined(first, search.searched.get(n, CANDIDATES[n])), start_soil,
             {**start_ext, **second_starts.get(n, {})}) for n in more]
    jobs.append((problem, replace(first, grid=()), start_soil, start_ext, LONG_FIT))
    restarts = [n for n in more if first.soil_restart and CANDIDATES[n].soil_restart]
    jobs += [(problem, combined(first, search.candidate(n)), dict(PAPER_INITIAL), None) for n in restarts]
    fitted = search.fits(jobs)
    results, continued, from_paper = fitted[:len(more)], fitted[len(more)], fitted[len(more) + 1:]
    for n, again in zip(restarts, from_paper):
        i = more.index(n)
        if training_objective(problem, again) < training_objective(problem, results[i]):
            search.say(f"  {first.name} + {n}: the fit from the paper's soil is kept (lower training loss on "
                       "every run)")
            results[i] = again
    return results, continued


def _survives_first_cause_refit(search: Search, first_res: FitResult, reference: FitResult,
                                results: list[FitResult], switched_off: dict[str, FitResult],
                                judged: list[JudgedCandidate]) -> tuple[list[JudgedCandidate], FitResult | None]:
    """A second cause must survive its own removal with the first cause refitted: the winner's
    fit with its extension switched off is the start of one more fit of the first cause alone,
    and that fit becomes the reference (the round is judged again) if it fits the training data
    better.  Why: the extra parameter can merely carry the fit out of a local optimum of the
    first cause, and its gain is then the first cause's own, not a second cause's.  Returns the
    judged round and the adopted first-cause refit (None if none was better)."""
    first = search.searched.get(first_res.name, CANDIDATES[first_res.name])
    problem, run_kind = search.problem, search.run_kind
    own = {e.name for e in first.params}
    refitted: set[str] = set()
    adopted: FitResult | None = None
    while judged and judged[0].significant and judged[0].name not in refitted:
        top = judged[0].name
        refitted.add(top)
        top_fit = next(r for r in results if r.name == top)
        start = CANDIDATES[top].switched_off(top_fit.params)
        search.say(f"  {first.name} alone, refitted from the {first.name} + {top} optimum with {top} switched off")
        alone = search.fits([(problem, replace(first, grid=()), {k: start[k] for k in SOIL_PARAMETERS},
                              {k: v for k, v in start.items() if k in own}, LONG_FIT)])[0]
        cost_alone = fit_objective(problem, run_kind, alone)
        cost_reference = fit_objective(problem, run_kind, reference)
        if cost_alone >= cost_reference:
            break
        search.say(f"  it fits the drawbar runs' training blocks better ({cost_alone:.4g} against "
                   f"{cost_reference:.4g}): it is the reference now")
        reference = adopted = replace(alone, name=first_res.name)
        judged = ranked([judge(problem, run_kind, reference, res, switched_off.get(res.name)) for res in results])
    return judged, adopted


def refit_from_paper_soil(search: Search, first: Candidate, both_fit: FitResult) -> FitResult:
    """The model with both named causes, refitted once more from the paper's initial soil with
    both extensions at their starts; the better of the two fits by fit_objective is reported.
    Only the reported model changes: the causes are already named.

    Why: the second round starts from the first cause's optimum, where the soil has been bent to
    absorb the second cause too, and the joint fit can stay in that basin, as a single
    candidate's can (Candidate.soil_restart).  Only for two causes that both restart from the
    paper's soil (a soil patch needs its own search to be found at all)."""
    second = search.candidate(both_fit.name)
    if not (first.soil_restart and second.soil_restart):
        return both_fit
    search.say(f"refitting {first.name} + {second.name} from the paper's initial soil")
    job = (search.problem, combined(first, replace(second, grid=())), dict(PAPER_INITIAL), None, LONG_FIT)
    again = search.fits([job])[0]
    kept, other = (fit_objective(search.problem, search.run_kind, both_fit),
                   fit_objective(search.problem, search.run_kind, again))
    search.say(f"  training objective {kept:.4g} from the first cause's optimum, {other:.4g} from the paper's soil")
    if other < kept and not names_its_causes(first, second, again):
        why = [f"{c.name} is switched off in it" for c in (first, second) if not c.acts(again.params)]
        bounded = soil_at_bounds(again.params)
        why += [f"its soil sits at a bound of the search ({', '.join(bounded)})"] if bounded else []
        search.say(f"  the fit from the paper's soil is not kept: {'; '.join(why)}")
        return both_fit
    return again if other < kept else both_fit


def names_its_causes(first: Candidate, second: Candidate, fit: FitResult) -> bool:
    """Whether ``fit``, a model with both extensions, is one that could have named both causes:
    each extension acts (Candidate.acts) and the soil sits at no bound of the search
    (judging.soil_at_bounds).  The reported model must be such a one: a refit that switched the
    second extension off, or pushed the soil to a bound, is not the model the causes were named
    for, however well it fits."""
    return first.acts(fit.params) and second.acts(fit.params) and not soil_at_bounds(fit.params)
