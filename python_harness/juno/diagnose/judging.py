"""How a candidate is judged against its reference on the held-out blocks: the paired test over
held-out units (paired_z: a rank test and a sign-flip test of the sum), the gain thresholds, the
ranking by penalised gain, the head-to-head test of a runner-up with more parameters, the lead a
lug ripple gives the cause that makes it (ripple_maker_leads), and the judge itself (judge).

Everything here works on residuals already computed, with one exception: the terrain runs'
replicas (terrain_replicas.py) replay each model judged on them once, the first time it is."""

from __future__ import annotations

from dataclasses import replace
from typing import Sequence, TypeVar

import numpy as np

from ..identify import soil_at_search_bounds
from ..registration import HeldOutEvidence, ScanRegistrations
from ..simulator import SOIL_PARAMETERS
from .candidates import CANDIDATES, Candidate, makes_ripple
from .fitting import FitResult
from .problem import Problem
from .results import Ablation, Duel, JudgedCandidate, KinematicEvidence, Ranked, ScanRegistration
from .sensor_offset import offset_free

Z_MIN = 2.5          # paired-test threshold for a significant held-out gain
GAIN_MIN = 0.03      # and at least 3 % less held-out mean squared residual (per parameter added)
RESIDUAL_CAP = 10.0  # scaled residuals beyond this count as this when candidates are judged
TIE_RATIO = 0.75     # a candidate with >= 75 % of the best gain explains the data about as well
#: A runner-up whose penalised gain (penalised_gain) is within this of the leader's also gets its
#: own second round, and the final models decide (search.choose_branch): a one-cause ranking
#: settled by less than one parameter's charge is not evidence for either cause (a grouser with
#: long lugs and a drivetrain loss of the same traction ratio h / (R + h) explain drawbar data
#: almost equally), unless the paired test prefers the leader unit by unit (search.tie_settled).
NEAR_TIE = GAIN_MIN
#: A held-out unit (run, block, signal) whose mean squared scaled residual moved by less than this
#: is unchanged for the paired tests: 1 % of the sensor noise's variance, a 16th of the scatter of a
#: 4 s block's mean square (80 samples: sqrt(2/80) = 0.16).  Counted, such numerical dust (signals
#: a candidate does not touch, moved by 1e-4 by the solver) can outvote the units that carry real
#: evidence.  Dropping units symmetrically about zero keeps the test's null distribution.
NEGLIGIBLE_CHANGE = 0.01
#: Fewer held-out units than this left after the ties are dropped give z = 0 (no evidence): the
#: smallest one-sided p of the signed-rank test over n units is 2^-n, so with fewer than 6 no z
#: could pass Z_MIN or fall below -Z_MIN anyway.
MIN_UNITS = 6
#: Random sign flips that make the sum test's null distribution (paired_z), from a generator
#: seeded by the number of units, so a diagnosis is deterministic.  Its smallest p, 1 / 20,001,
#: lies far below the level either test is judged at (0.16 %).
SIGN_FLIPS = 20000
#: The two paired tests paired_z combines, each at its share of the level (Bonferroni).
PAIRED_TESTS = 2

R = TypeVar("R", bound=Ranked)


# ------------------------------------------------------------------ the held-out comparison

def capped_square(r: np.ndarray) -> np.ndarray:
    """Squared scaled residuals, capped at RESIDUAL_CAP^2 for judging candidates.  A replay that
    loses the rover (on the terrain run, a slightly different soil can leave the model stuck
    where the rover climbed, or the reverse) gives residuals of hundreds of sigma that say only
    "lost"; uncapped, one such run would outweigh every other run's evidence."""
    return np.minimum(r * r, RESIDUAL_CAP ** 2)


def z_threshold(n_tests: int) -> float:
    """Z_MIN corrected for ``n_tests`` one-sided tests (Bonferroni): the z of p(Z_MIN) / n."""
    from scipy.stats import norm
    return float(norm.isf(norm.sf(Z_MIN) / max(n_tests, 1)))


def _rank_test(means: np.ndarray) -> tuple[float, float]:
    """One-sided p-values (improvement, worsening) of the Wilcoxon signed-rank test of ``means``;
    the worsening side is asked only when the improvement side finds nothing (p above a half),
    else it is taken as 1."""
    from scipy.stats import wilcoxon
    up = float(wilcoxon(means, alternative="greater").pvalue)
    return up, (float(wilcoxon(means, alternative="less").pvalue) if up > 0.5 else 1.0)


def _sum_test(means: np.ndarray) -> tuple[float, float]:
    """One-sided p-values (improvement, worsening) of the sign-flip test of the sum of ``means``:
    the sum against the sums with each unit's sign flipped at random (SIGN_FLIPS draws), valid
    whenever the changes are symmetric about zero under the null, as the rank test assumes.
    Sums within a millionth of the units' total size of the observed one count as reaching it
    (single precision: the p-values err on the large side)."""
    rng = np.random.default_rng(len(means))
    columns = (len(means) + 7) // 8
    draws = np.frombuffer(rng.bytes(SIGN_FLIPS * columns), np.uint8).reshape(SIGN_FLIPS, columns)
    kept = np.unpackbits(draws, axis=1)[:, :len(means)].astype(np.float32)
    flipped = kept @ (2.0 * means).astype(np.float32) - np.float32(np.sum(means))
    total, tolerance = float(np.sum(means)), 1e-6 * float(np.sum(np.abs(means)))
    up = int(np.sum(flipped >= total - tolerance))
    down = int(np.sum(flipped <= total + tolerance))
    return (1 + up) / (SIGN_FLIPS + 1), (1 + down) / (SIGN_FLIPS + 1)


def paired_z(problem: Problem, base: np.ndarray, ext: np.ndarray, mask: np.ndarray | None = None) -> float:
    """Significance of the held-out improvement from residuals ``base`` to ``ext`` (over the
    residuals in ``mask``), as a signed z: positive for evidence of improvement, negative for
    evidence of worsening.  The units are the held-out (run, 4 s block, signal), each unit's
    change of mean squared residual is one observation, and two paired tests are made of them:

    - the Wilcoxon signed-rank test, which credits a change most units share: ranks make it
      robust to a few units with huge changes, which defeat a test of the sum;
    - the sign-flip test of the sum, which credits a large change in a few units: a soil patch
      or a strip of weaker soil that the rover crosses in a few blocks, or the rut a rear wheel
      drops into, changes a few units by tens of the noise variance and leaves the rest to the
      refitted soil's small changes of either sign, which outnumber it in a rank test.

    Each is judged at half the level (Bonferroni over PAIRED_TESTS), so the chance that noise
    alone passes either is what one test at the full level would give.  The z is the normal
    quantile of the smaller p-value times PAIRED_TESTS, in the direction (improvement or
    worsening) with the stronger evidence.  Units that moved by no more than NEGLIGIBLE_CHANGE
    are ties (dropped); with fewer than MIN_UNITS left, z is 0; -inf if ``ext`` failed on a run
    (NaN residuals)."""
    from scipy.stats import norm
    test = ~problem.train if mask is None else (~problem.train & mask)
    base, ext = offset_free(problem, base), offset_free(problem, ext)
    keys = np.char.add(np.char.add(problem.meta["run"][test], problem.meta["block"][test].astype(str)),
                       problem.meta["signal"][test])
    d = capped_square(base[test]) - capped_square(ext[test])
    if np.any(~np.isfinite(d)):
        return -np.inf
    _, inverse = np.unique(keys, return_inverse=True)
    means = np.bincount(inverse, weights=d) / np.maximum(np.bincount(inverse), 1)
    means = means[np.abs(means) > NEGLIGIBLE_CHANGE]
    if len(means) < MIN_UNITS:
        return 0.0
    (rank_up, rank_down), (sum_up, sum_down) = _rank_test(means), _sum_test(means)
    up = float(norm.isf(min(0.5, PAIRED_TESTS * min(rank_up, sum_up))))
    down = float(norm.isf(min(0.5, PAIRED_TESTS * max(min(rank_down, sum_down), 1e-300))))
    z = up if up >= down else -down
    return float(np.clip(z, -40.0, 40.0))


def held_out_mse(problem: Problem, r: np.ndarray, where: np.ndarray) -> float:
    """The capped mean squared scaled residual of ``r`` on the held-out blocks within ``where``
    (NaN residuals, of runs the model could not simulate, left out), the IMU's pitch offset taken
    off (sensor_offset.offset_free)."""
    return float(np.nanmean(capped_square(offset_free(problem, r)[~problem.train & where])))


def relative_gain(problem: Problem, before_r: np.ndarray, after_r: np.ndarray, where: np.ndarray) -> float:
    """Relative drop of the held-out capped mean squared residual over ``where``, from the
    residuals ``before_r`` to ``after_r``, the IMU's pitch offset taken off both
    (sensor_offset.offset_free); -inf if the model behind ``after_r`` failed on a run."""
    test = ~problem.train
    before_r, after_r = offset_free(problem, before_r), offset_free(problem, after_r)
    b = float(np.nanmean(capped_square(before_r[test & where])))
    a = float(np.mean(capped_square(after_r[test & where])))
    if not np.isfinite(a):
        return -np.inf
    return (b - a) / b if b > 0 else 0.0


def kinds_of(run_kind: np.ndarray) -> tuple[str, ...]:
    """The kinds of run present, sorted: every candidate is judged on each of them."""
    return tuple(sorted(set(run_kind.tolist())))


def gain_by_kind(problem: Problem, run_kind: np.ndarray, before_r: np.ndarray, after_r: np.ndarray
                 ) -> dict[str, float]:
    """relative_gain on each kind of run."""
    return {k: relative_gain(problem, before_r, after_r, run_kind == k) for k in kinds_of(run_kind)}


def z_by_kind(problem: Problem, run_kind: np.ndarray, before: FitResult, after: FitResult) -> dict[str, float]:
    """The evidence on each kind of run that ``after`` explains the held-out data better than
    ``before`` (signed z): paired_z on the drawbar runs; on the terrain runs, terrain_evidence of
    the paired test and the replicas' test (replica_z), when the problem carries the terrain runs'
    replicas (terrain_replicas.py), else the paired test alone."""
    zs = {k: paired_z(problem, before.residuals, after.residuals, run_kind == k) for k in kinds_of(run_kind)}
    if "terrain" in zs and problem.terrain_replicas is not None:
        zs["terrain"] = terrain_evidence(zs["terrain"], replica_z(problem, run_kind, before, after))
    return zs


def replica_z(problem: Problem, run_kind: np.ndarray, before: FitResult, after: FitResult) -> float | None:
    """The held-out improvement on the terrain runs from ``before`` to ``after`` (the drop of
    their capped mean squared residual) over its standard error, the spread of that drop over
    the problem's terrain replicas (terrain_replicas.py: every model replayed with the same fresh
    sensor noise); None where the replicas do not move it (both models alike there) or the drop
    is not finite."""
    replicas = problem.terrain_replicas
    test = ~problem.train & (run_kind == "terrain")
    observed = float(np.mean(capped_square(before.residuals[test])) - np.mean(capped_square(after.residuals[test])))
    if not np.isfinite(observed):
        return None
    spread = float(np.std(replicas.losses(before.params) - replicas.losses(after.params), ddof=1))
    return observed / spread if spread > 0 else None


def terrain_evidence(paired: float, replicas: float | None) -> float:
    """The terrain runs' z from the paired test's (``paired``) and the replicas' (``replicas``):
    evidence must exceed both the block-to-block scatter the paired test measures and the
    replay's sensitivity to its sensors' noise the replicas measure, so the smaller of the two in
    size when they agree in sign, and 0 when they disagree.  A model that fails on a terrain run
    (paired -inf) keeps that; without replicas' evidence, the paired test's."""
    if replicas is None or not np.isfinite(paired):
        return paired
    if paired * replicas <= 0:
        return 0.0
    return float(np.sign(paired) * min(abs(paired), abs(replicas)))


# ------------------------------------------------------------------ the judge

def passes(n_params: int, gain: float, zs: dict[str, float]) -> bool:
    """The significance rule for a gain: the pooled held-out relative ``gain`` exceeds GAIN_MIN
    per parameter added, the paired test's z (``zs``, per kind of run) exceeds the Bonferroni
    threshold on some kind of run, and no kind of run gets significantly worse (z > -Z_MIN).

    Why per kind: drawbar and terrain runs differ too much for one pooled rank test, where
    hundreds of unchanged drawbar units would drown a validation run's gain.  Why the pooled
    gain, not the best kind's: judged per kind, the open-loop terrain replay alone is noisy
    enough to name false causes (a many-parameter soil patch fitting the replay's drift), and
    it adds no hidden effect that the pooled gain misses.  Why GAIN_MIN per parameter: each
    parameter must buy its share of held-out error (a soil patch, 5 parameters, can take a few
    per cent on top of a right first cause by fitting local residual features)."""
    return bool(gain > GAIN_MIN * n_params and max(zs.values()) > z_threshold(len(zs)) and min(zs.values()) > -Z_MIN)


def ablation(problem: Problem, run_kind: np.ndarray, switched_off: FitResult, res: FitResult) -> Ablation:
    """The held-out gain and paired z of ``res`` over its own fit with the extension switched off."""
    z_off = z_by_kind(problem, run_kind, switched_off, res)
    everywhere = np.isin(run_kind, kinds_of(run_kind))
    return Ablation(relative_gain(problem, switched_off.residuals, res.residuals, everywhere),
                    float(max(z_off.values())), z_off,
                    gain_by_kind(problem, run_kind, switched_off.residuals, res.residuals))


def kinematic_evidence(registration: HeldOutEvidence | ScanRegistrations) -> KinematicEvidence:
    """The registration's held-out pose evidence as reported: the campaign's (pooled over its
    scans) and, given every scan's (ScanRegistrations), each scan's own."""
    scans = None
    if isinstance(registration, ScanRegistrations):
        scans = [ScanRegistration(s.scan, list(s.runs), s.offsets,
                                  None if s.evidence is None else s.evidence.held_out_ms_as_scanned,
                                  None if s.evidence is None else s.evidence.held_out_ms_registered,
                                  None if s.evidence is None else s.evidence.ratio, s.significant)
                 for s in registration.scans]
    return KinematicEvidence(registration.held_out_ms_as_scanned, registration.held_out_ms_registered,
                             registration.ratio, registration.gain, registration.significant, scans)


def soil_at_bounds(params: dict[str, float]) -> list[str]:
    """The soil parameters of a fit (``params``) that sit at a bound of the search
    (identify.soil_at_search_bounds), each as "name = value (lower|upper bound)"."""
    return [f"{b.name} = {b.value:.4g} ({b.side} bound)" for b in soil_at_search_bounds(params)]


def is_significant(candidate: Candidate, acts: bool, gain: float, zs: dict[str, float], off: Ablation | None,
                   registration: HeldOutEvidence | ScanRegistrations | None, at_bounds: Sequence[str] = (),
                   n_params: int | None = None) -> bool:
    """Whether a judged candidate names a cause.  The registration, with its kinematic evidence
    given: that evidence is significant, the extension acts and no kind of run's replay gets
    significantly worse (some scan's own evidence, for a campaign of several scans).  Every other
    candidate: its gain passes (passes, for the ``n_params`` its fit adds, Candidate.parameters_in;
    the catalogue's count when not given), the extension acts,
    switching it off loses the gain by the same rule (when the ablation is given), and the soil
    fitted with it sits at no bound of the search (``at_bounds``, soil_at_bounds).

    Why the bounds: they lie wide of any soil the paper or the terramechanics literature
    reports, so a fit that ends at one is a model the data push beyond any real soil, the optimum
    of the model lying outside it.  A model with the right cause does not need that: with the
    cause in it the soil comes back to a real soil.  A discrepancy no candidate describes (a
    pitch sensor's bias, with the pitch's offset held at none instead of free as sensor_offset.py
    leaves it) is absorbed instead by bending the soil as far as the search allows and
    letting the extension repair what the bent soil spoils elsewhere (the torque, for a
    drivetrain loss): the gain is then the soil's, carried by signals the extension does not act
    on, and the ablation, which switches the extension off on that same bent soil, cannot see it."""
    if registration is not None and candidate.is_registration:
        return bool(registration.significant and acts and min(zs.values()) > -Z_MIN)
    n = len(candidate.params) if n_params is None else n_params
    return passes(n, gain, zs) and acts and (off is None or passes(n, off.gain, off.z_by_kind)) and not at_bounds


def significant_but_for_its_soil(judged: JudgedCandidate) -> bool:
    """Whether a judged candidate fails is_significant by its soil alone: its fit sits at a bound
    of the search (``judged.soil_at_bounds``) and it passes every other test, its gain's and, where
    given, its ablation's.  Such a one-cause model may lack a second cause that its soil bends to
    absorb: search.first_cause_branches gives it a second round of its own."""
    if not judged.soil_at_bounds or judged.error:
        return False
    return is_significant(CANDIDATES[judged.name], judged.acts, judged.gain, judged.z_by_kind, judged.ablation, None,
                          (), judged.n_params)


def why_no_cause(judged: JudgedCandidate) -> list[str]:
    """The rules of is_significant that a judged physical candidate fails, in words (for a
    candidate that is no cause; [] when it fails none)."""
    n, zs, off = judged.n_params, judged.z_by_kind, judged.ablation
    why = []
    if judged.gain <= GAIN_MIN * n:
        why.append(f"its held-out gain over every run, {judged.gain:+.1%}, is under the {GAIN_MIN * n:.0%} its "
                   f"{n} parameter{'s' if n != 1 else ''} must buy")
    why += [f"it makes the {k} runs significantly worse (z {z:.1f})" for k, z in zs.items() if z <= -Z_MIN]
    if zs and max(zs.values()) <= z_threshold(len(zs)):
        why.append(f"no kind of run's gain is significant (z {max(zs.values()):.1f})")
    if off is not None and not passes(n, off.gain, off.z_by_kind):
        why.append("switched off on the same soil, it loses too little of its gain")
    if not judged.acts:
        why.append("its extension stays at its neutral setting")
    if judged.soil_at_bounds:
        why.append(f"its soil sits at a bound of the search ({', '.join(judged.soil_at_bounds)})")
    return why


def judge(problem: Problem, run_kind: np.ndarray, reference: FitResult, res: FitResult,
          switched_off: FitResult | None = None, registration: HeldOutEvidence | ScanRegistrations | None = None
          ) -> JudgedCandidate:
    """A candidate's held-out gain over ``reference`` (the base model, or the first cause), and
    whether it is significant (is_significant).

    Every candidate is judged on the held-out blocks of every run: the same data for every
    candidate, so their gains compare.  A physical extension is fitted on the drawbar runs only,
    so for it the terrain run is a validation run, as in the paper (grouser thrust, which
    drawbar tests at moderate slip cannot tell from K_vx, shows when the rover climbs); the
    registration is chosen on the terrain run's training blocks.  gain_by_kind is reported, not
    judged.

    With ``switched_off`` (the candidate's own fit with its extension at neutral), the gain must
    also survive that ablation: a gain that lives in the refitted soil, not in the extension,
    does not count.  It does not catch everything: a weak multi-pass on top of a right
    slip-sinkage fit can keep a gain of a few per cent against its own switched-off fit
    (docs/diagnosis.md, known limits).

    With ``registration`` (its kinematic held-out evidence, starts.registration_evidence; given
    in the first round only), the registration candidate (terrain_offset) is judged on it, and
    its replayed gain is reported, not judged.  Why: a misregistration is a fact of geometry,
    which the measured pose along the path shows directly, while the terrain replay's gain also
    carries how well the rover is replayed over the mound.  On synthetic campaigns the
    registration fitted on the training blocks explained the held-out pose several to a hundred
    times better than the scan as it is where the scan was misregistered, and about as well
    (0.5-1.5 times) where it was not, while its replayed gain was often only a few per cent.  On
    top of another cause the kinematic evidence is not given: a soft soil patch, which the
    kinematic model does not know, sinks the rover as a lowered scan would.  A campaign with
    several scans has a registration per scan (starts.registration_candidate), charged six
    parameters for each scan it moves on the replay, as any parameter is."""
    candidate = CANDIDATES[res.name]
    if res.error:
        return JudgedCandidate(res.name, candidate.cause, 0.0, 0.0, False, False, "failed", res.failed_evaluations,
                               error=res.error)
    kinds = kinds_of(run_kind)
    everywhere = np.isin(run_kind, kinds)
    gain = relative_gain(problem, reference.residuals, res.residuals, everywhere)
    zs = z_by_kind(problem, run_kind, reference, res)
    acts = candidate.acts(res.params)
    off = None if switched_off is None else ablation(problem, run_kind, switched_off, res)
    use_pose = registration is not None and candidate.is_registration
    n_params = candidate.parameters_in(res.params)
    # The registration's soil is its reference's (references.on_reference_soil), not fitted with it.
    at_bounds = [] if candidate.is_registration else soil_at_bounds(res.params)
    return JudgedCandidate(
        res.name, candidate.cause, float(gain), float(max(zs.values())),
        is_significant(candidate, acts, gain, zs, off, registration, at_bounds, n_params), acts, res.status,
        res.failed_evaluations,
        gain_by_kind=gain_by_kind(problem, run_kind, reference.residuals, res.residuals), z_by_kind=zs,
        ablation=off, kinematic=kinematic_evidence(registration) if use_pose else None, judged_on=list(kinds),
        held_out_mse_before=held_out_mse(problem, reference.residuals, everywhere),
        held_out_mse_after=float(np.mean(capped_square(offset_free(problem, res.residuals)
                                                        [~problem.train & everywhere]))),
        test_mse=res.test_mse, train_mse=res.train_mse, n_params=n_params,
        soil={k: res.params[k] for k in SOIL_PARAMETERS},
        extension={k: v for k, v in res.params.items() if candidate.owns(k)}, soil_at_bounds=at_bounds,
        evaluations=res.evaluations, wall_time=res.wall_time)


# ------------------------------------------------------------------ ranking and head to head

def penalised_gain(judged: Ranked) -> float:
    """A candidate's held-out relative gain less GAIN_MIN per parameter it adds: the ranking of
    candidates, so that of two that explain the data about as well the one with fewer parameters
    is named.  Why: a soil patch (5 parameters) grown over the whole test area is a uniform
    F_taumax scale, which is what a grouser's thrust gain (one parameter) is; unpenalised, the
    larger model wins such a tie by a fraction of a point."""
    return float(judged.gain) - GAIN_MIN * int(judged.n_params)


def ranked(judged: Sequence[R]) -> list[R]:
    """Judged candidates (judge) best first, by penalised_gain."""
    return sorted(judged, key=lambda c: -penalised_gain(c))


def head_to_head(problem: Problem, run_kind: np.ndarray, leader: FitResult, challenger: FitResult) -> Duel:
    """Whether ``challenger`` explains the held-out data significantly better than ``leader``: the
    paired test of judge with the leader's model as the reference (z over the Bonferroni
    threshold on some kind of run, above -Z_MIN on every kind).  The challenger is a significant
    candidate with more parameters and a larger raw gain than the leader of the penalised
    ranking (leader_after_head_to_head), or, to settle a near tie, that leader itself against
    the runner-up within NEAR_TIE of it (search.tie_settled).

    The fixed charge of GAIN_MIN per parameter keeps a model with more parameters out when the
    two explain the data alike; it should not keep it out when the held-out data prefer it
    unit by unit: a model whose raw held-out gain beats the leader's by a point or two, with a
    parameter more, loses the penalised ranking even where every held-out block prefers it."""
    zs = z_by_kind(problem, run_kind, leader, challenger)
    gain = relative_gain(problem, leader.residuals, challenger.residuals, np.ones(len(run_kind), bool))
    better = bool(max(zs.values()) > z_threshold(len(zs)) and min(zs.values()) > -Z_MIN and gain > 0)
    return Duel(leader.name, challenger.name, zs, gain, better)


def leader_after_head_to_head(problem: Problem, run_kind: np.ndarray, significant: Sequence[R],
                              results: Sequence[FitResult]) -> tuple[list[R], list[Duel]]:
    """The significant candidates (ranked) with the leader replaced by any runner-up that has more
    parameters, a larger raw gain and wins head_to_head against it; returns (the reordered
    list, the comparisons made).  ``results``: the fits, found by name."""
    order = list(significant)
    fits = {r.name: r for r in results}
    duels = []
    for c in list(order[1:]):
        lead = order[0]
        if c.n_params > lead.n_params and c.gain > lead.gain:
            duel = head_to_head(problem, run_kind, fits[lead.name], fits[c.name])
            duels.append(duel)
            if duel.challenger_better:
                order.remove(c)
                order.insert(0, c)
    return order, duels


def ripple_maker_leads(problem: Problem, run_kind: np.ndarray, order: Sequence[R], results: Sequence[FitResult]
                       ) -> tuple[list[R], list[Duel]]:
    """The significant candidates (ranked, ``order``) when the measured drive torques ripple with
    the wheel angle at a lug count (juno.periodic_structure, on the base model's residuals): a
    leader whose cause makes no such ripple gives the lead to the best-ranked runner-up whose
    cause makes one (candidates.makes_ripple, by name), unless the
    leader explains the held-out data significantly better than it (head_to_head, with the
    runner-up's model as the reference; stage "ripple").  Returns (the reordered list, the
    comparison made, if any).  ``results``: the fits, found by name.

    Why: the ripple is evidence the held-out gains cannot weigh.  The candidates are judged on
    4 s block means, which average a ripple of a few Hz away, and no catalog model makes one, so
    the ripple is in every model's residuals alike.  A drivetrain loss cannot make it (a gear's
    mesh ripples at hundreds per wheel revolution, beyond the N's the test scans); lugs entering
    the soil one by one make it, and the periodic test reports one falsely in at most 1 % of
    campaigns.  So between two causes that both explain the held-out data significantly, the one
    whose mechanism also accounts for the ripple is named, and the held-out data can still
    overturn that, by the paired test that overturns any leader: a lead in the penalised
    ranking alone is not enough."""
    order = list(order)
    if not order or makes_ripple(order[0].name):
        return order, []
    maker = next((c for c in order[1:] if makes_ripple(c.name)), None)
    if maker is None:
        return order, []
    fits = {r.name: r for r in results}
    lead = order[0]
    duel = replace(head_to_head(problem, run_kind, fits[maker.name], fits[lead.name]), stage="ripple")
    if not duel.challenger_better:
        order.remove(maker)
        order.insert(0, maker)
    return order, [duel]
