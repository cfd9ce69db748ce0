"""The verdict: a catalog cause, ``none``, or ``unexplained``.

The search (search.py) names catalog causes by their held-out gain.  The verdict then asks the
residual structure test (juno/residual_structure.py) what the models leave:

- no cause named, and the base model leaves no structure: ``none``; the residuals are
  consistent with sensor noise, or hold structure the test resolves below its floors (the most a
  right model's replay leaves), which the verdict lists (``below_floors``): a right model's
  replay leaves such structure on many campaigns with nothing hidden
  (docs/results/structure-calibration.md counts them), so it names no cause, but the words
  "consistent with sensor noise" would be false;
- no cause named, but the base model leaves structure: ``unexplained``, with the signals and
  what they follow (a ripple in the drive torques at N per wheel revolution counts as
  structure: no catalog cause models one);
- no cause named, but some candidate explains the drawbar runs' held-out data significantly
  better than the base model, by its extension (partial_explanations), without passing as a
  cause (its pooled gain too small, or the terrain runs worse): ``unexplained``, with those
  candidates.  Why: ``none`` says that no extension explains the held-out data significantly
  better; such a candidate does, on part of the data, and the base model is then wrong there
  whatever the structure test sees;
- no cause named, and some terrain run's measured pose disagrees with its own scan
  (juno.scan_consistency, the rover posed on the scan without a replay): ``unexplained``, with
  the runs and the signals that disagree.  Why only then: the structure test sees the drawbar runs alone, so a
  scan error that is not a shift (a tilt) would otherwise be called ``none``; once a cause is
  named, the scan test says nothing about it (the catalog's soil causes change how deep the
  wheels sink, which the kinematic pose takes as uniform, and the registration moves the scan
  the test takes as it is);
- causes named, and their model leaves no structure: the causes;
- causes named, and their model leaves structure: if it removes at least EXPLAINED_SHARE of
  the base model's structure, the causes, with the remainder reported as ``unexplained``
  beside them; otherwise ``unexplained``, with the catalog causes reported as only absorbing
  part of it.  Why: a cause is named for explaining a discrepancy; one that removes less than
  half of it is fitting its free parameters to part of a discrepancy it does not describe (a
  soil patch bent around a dragging brake), and naming it would send the engineer after the
  wrong physics.  The share is measured on the structure of the held-out block means, the
  structure the candidates are fitted and judged on; a ripple in the wheel angle, which no
  candidate models, counts neither for nor against a cause: it is reported beside whatever is
  named (lugs that add thrust and ripple are named ``grouser``, with the ripple as the
  remainder).  When the named causes make no such ripple and their model's torques still ripple,
  a candidate whose cause makes one and that explains the drawbar runs' held-out data by the
  partial-explanation test is reported beside them (ripple_makers_not_named): the same data read
  another way, which the ripple favours.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from ..periodic_structure import PeriodicSignal
from ..residual_structure import ResidualStructure, SignalStructure
from ..scan_consistency import ScanTests
from ..timing_structure import SignalOffset
from .candidates import CANDIDATES, makes_ripple

if TYPE_CHECKING:   # results.py holds the verdict's types, and judging.py imports results.py
    from .results import JudgedCandidate

#: The least share of the base model's residual structure a catalog model must remove to be
#: named for it (see the module docstring).
EXPLAINED_SHARE = 0.5


#: The kinds of run on which a candidate's paired z is evidence by itself (partial_explanations).
PAIRED_EVIDENCE_KINDS = ("drawbar",)


@dataclass
class PartialExplanation:
    """A candidate that explains the held-out data of one kind of run (``kind``) significantly
    better than the base model, with paired z ``z`` and ``ablation_z`` against its own fit with
    the extension switched off, though it is no cause (partial_explanations): its held-out gain
    over every run (``gain``; ``gain_by_kind``) and the rules it fails (``why_no_cause``,
    judging.why_no_cause)."""

    name: str
    kind: str
    z: float
    ablation_z: float
    gain: float
    gain_by_kind: dict[str, float]
    why_no_cause: list[str] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        return {"name": self.name, "kind": self.kind, "z": self.z, "ablation_z": self.ablation_z,
                "gain": self.gain, "gain_by_kind": self.gain_by_kind, "why_no_cause": self.why_no_cause}

    def sentence(self) -> str:
        """The finding in words."""
        gains = ", ".join(f"{k} runs {g:+.0%}" for k, g in self.gain_by_kind.items())
        why = f": {'; '.join(self.why_no_cause)}" if self.why_no_cause else ""
        return (f"{self.name} explains the {self.kind} runs' held-out data better than the base model (z {self.z:.1f}; "
                f"its extension's own share z {self.ablation_z:.1f}; held-out gain {gains}) but is no cause{why}")


def partial_explanations(candidates: list[JudgedCandidate]) -> list[PartialExplanation]:
    """The first round's candidates (``candidates``, judged against the base model) that explain
    the held-out data of a kind of run in PAIRED_EVIDENCE_KINDS (the drawbar runs) significantly
    better than the base model by their extension: there both the paired z against the base
    model and the ablation's z (against the same fit with the extension switched off) exceed
    z_threshold for every test made, one per physical candidate and such kind of run
    (Bonferroni).  The registration is judged on the pose (the scan test covers it), and a failed
    fit or one whose extension does not act is no evidence.

    Why the threshold: if the base model is right, the chance that any of those tests reaches it
    is at most that of one test reaching Z_MIN (0.6 %), whatever the tests share.  Why the
    ablation too: a gain that lives in the soil refitted beside the extension says the base fit
    was not at its optimum, not that the model is wrong.  Why the drawbar runs only: they are
    replayed following the measured spins, block by block alike, while a terrain run is one
    open-loop replay whose blocks share its drift, so its paired z overstates the evidence
    (judging.passes asks the pooled gain for the same reason).  On a default-design campaign
    with nothing hidden, a multi-pass fit took 11 % off the terrain replay's held-out error at
    z 3.8, its ablation 4.0."""
    from .judging import why_no_cause, z_threshold     # judging imports results, which imports this module
    physical = [c for c in candidates if c.name in CANDIDATES and not CANDIDATES[c.name].is_registration
                and not c.error]
    kinds = max((sum(k in PAIRED_EVIDENCE_KINDS for k in c.z_by_kind) for c in physical), default=0)
    threshold = z_threshold(len(physical) * kinds)
    found = []
    for c in physical:
        if not c.acts or c.ablation is None:
            continue
        for kind, z in c.z_by_kind.items():
            if kind not in PAIRED_EVIDENCE_KINDS:
                continue
            off = c.ablation.z_by_kind.get(kind, 0.0)
            if z > threshold and off > threshold:
                found.append(PartialExplanation(c.name, kind, z, off, c.gain, dict(c.gain_by_kind), why_no_cause(c)))
    return sorted(found, key=lambda f: -f.z)


def ripple_makers_not_named(causes: list[str], ripples: list[PeriodicSignal],
                            candidates: list[JudgedCandidate]) -> list[PartialExplanation]:
    """When the named ``causes`` make no ripple in the wheel angle and their model's drive torques
    still ripple (``ripples``): the first round's candidates whose cause makes one and that explain
    the drawbar runs' held-out data better than the base model by the test of
    partial_explanations, though they are no cause.

    Why: the ripple is evidence the held-out gains cannot weigh (the candidates are judged on block
    means, which average it away), and it says something about the named cause: a drivetrain loss
    cannot make a ripple at a lug count, lugs entering the soil do.  A lug model that the held-out
    data support but whose fit ends with its soil at a bound of the search (the ripple's
    traction, which the catalog grouser lacks, bent it there) is then the other reading of the
    same data, and the engineer is told so beside the cause named."""
    if not ripples or any(c in CANDIDATES and makes_ripple(c) for c in causes):
        return []
    return [p for p in partial_explanations(candidates) if makes_ripple(p.name) and p.name not in causes]


@dataclass
class Unexplained:
    """Structure beyond sensor noise that the catalog does not explain: in the model ``model``
    ("base", or the named causes joined by "+"), the signals that hold it (largest relative to
    their noise first), and the signals that ripple with the wheel angle (``ripples``,
    juno.periodic_structure); ``absorbed_by``: catalog causes whose model removes only
    ``share_removed`` of the base model's structure (so they are not named)."""

    model: str
    signals: list[SignalStructure]
    absorbed_by: list[str] = field(default_factory=list)
    share_removed: float | None = None
    ripples: list[PeriodicSignal] = field(default_factory=list)
    #: every terrain run's pose against its scan (juno.scan_consistency), when one disagrees
    scan: ScanTests | None = None
    #: the signals time-stamped off the replay's inputs (juno.timing_structure)
    offsets: list[SignalOffset] = field(default_factory=list)
    #: candidates that explain the drawbar runs' held-out data without being a cause
    #: (partial_explanations; with no cause named)
    partial: list[PartialExplanation] = field(default_factory=list)
    #: candidates whose cause makes the ripple the named causes leave, and that explain the drawbar
    #: runs' held-out data without being a cause (ripple_makers_not_named; with causes named)
    ripple_makers: list[PartialExplanation] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        return {"model": self.model, "signals": [s.to_json() for s in self.signals],
                "ripples": [r.to_json() for r in self.ripples],
                "offsets": [o.to_json() for o in self.offsets],
                "partial": [p.to_json() for p in self.partial],
                "ripple_makers": [p.to_json() for p in self.ripple_makers],
                "absorbed_by": self.absorbed_by, "share_removed": self.share_removed,
                "scan": self.scan.to_json() if self.scan is not None else None,
                "summary": self.summary()}

    def ripple_maker_sentences(self) -> list[str]:
        """Each candidate whose cause makes the ripple the named causes leave, in words."""
        return [f"{p.name} makes such a ripple, and {self.model} does not: {p.sentence()}" for p in self.ripple_makers]

    def summary(self, most: int = 3) -> str:
        """One sentence: the ``most`` largest signals' structure and the covariate each follows
        best, then the ripples in the wheel angle (the JSON has every signal and covariate)."""
        more = len(self.signals) - most
        parts = [s.sentence() for s in self.signals[:most]]
        if more > 0:
            parts.append(f"and {more} more signal{'s' if more > 1 else ''}")
        scan = [self.scan.summary()] if self.scan is not None and self.scan.significant else []
        return "; ".join(parts + [r.sentence() for r in self.ripples] + self.ripple_maker_sentences()
                         + [o.sentence() for o in self.offsets]
                         + scan + [p.sentence() for p in self.partial])


@dataclass
class Verdict:
    """What the diagnosis reports: ``cause`` (a catalog cause, "none" or "unexplained"), the
    catalog ``causes`` named (strongest first), and what is left unexplained (or None)."""

    cause: str
    causes: list[str]
    unexplained: Unexplained | None
    #: with ``none``: the base model's signals the structure test resolves below their floors
    below_floors: list[SignalStructure] = field(default_factory=list)
    #: with ``none``: what of the terrain runs' pose could not be tested against their scan, and why
    scan_not_judged: list[str] = field(default_factory=list)


def verdict(causes: list[str], base: ResidualStructure | None, extended: ResidualStructure | None,
            scan: ScanTests | None = None, candidates: list[JudgedCandidate] | None = None) -> Verdict:
    """The verdict (module docstring) from the catalog ``causes`` the search named, the structure
    tests of the base model and of the model with those causes (None when none was named), the
    terrain runs' scan tests (None: no terrain run tested) and the first round's judged
    ``candidates`` (partial_explanations, used when no cause is named; ripple_makers_not_named,
    when the named causes leave a ripple they cannot make); the scan is used only when no cause
    is named.
    A test that could not be made is None (search.what_the_models_leave): the named causes then
    stand on their held-out evidence, with no share of the base model's structure to weigh them
    by; the base model's test must exist when nothing is named."""
    if not causes:
        assert base is not None
        disagrees = scan if scan is not None and scan.significant else None
        partial = partial_explanations(candidates or [])
        if base.significant or disagrees is not None or partial:
            return Verdict("unexplained", [], Unexplained("base", base.structured(), ripples=base.ripples(),
                                                          scan=disagrees, offsets=base.offsets(), partial=partial))
        return Verdict("none", [], None, base.below_floors(), not_judged(scan))
    if extended is None or not extended.significant:
        return Verdict(causes[0], causes, None)
    makers = ripple_makers_not_named(causes, extended.ripples(), candidates or [])
    if not extended.structured() or base is None:
        # only a ripple or an offset is left (the causes explain what they act on), or the base
        # model's structure is unknown: what is left is reported beside the causes
        return Verdict(causes[0], causes, Unexplained("+".join(causes), extended.structured(),
                                                      ripples=extended.ripples(), offsets=extended.offsets(),
                                                      ripple_makers=makers))
    removed = 1.0 - extended.block_excess / base.block_excess if base.block_excess > 0 else 0.0
    left = Unexplained("+".join(causes), extended.structured(), share_removed=removed, ripples=extended.ripples(),
                       offsets=extended.offsets(), ripple_makers=makers)
    if removed >= EXPLAINED_SHARE:
        return Verdict(causes[0], causes, left)
    left.absorbed_by = list(causes)
    return Verdict("unexplained", [], left)


def ripple_between_tied(named: str, tied: list[str], ripples: list[PeriodicSignal]) -> str | None:
    """A sentence on what a ripple in the wheel angle says between the named cause and the causes
    reported equally good (``tied``), or None: when the data ripple (``ripples``, the base model's
    periodic test) and the tied causes part into some that make such a ripple and some that make
    none (Candidate.ripples_with_wheel_angle), the ripple is evidence the held-out gains could not
    weigh (the candidates are judged on block means, which average it away)."""
    both = [named] + [t for t in tied if t != named]
    makes = [c for c in both if c in CANDIDATES and makes_ripple(c)]
    without = [c for c in both if c in CANDIDATES and not makes_ripple(c)]
    if not ripples or not makes or not without:
        return None
    r = ripples[0]
    return (f"{r.signal} ripples with the wheel angle at {r.lugs} per revolution, which {' and '.join(makes)} "
            f"makes and {' and '.join(without)} does not: the ripple favours {' and '.join(makes)}")


def explanation(verdict_: Verdict, catalog_explanation: str) -> str:
    """The verdict in words, from the named causes' physical explanation."""
    u = verdict_.unexplained
    if verdict_.cause == "none":
        return ("no extension explains the held-out data significantly better, and " + residuals_of_none(verdict_)
                + "".join(f"; {note}" for note in verdict_.scan_not_judged))
    if verdict_.cause == "unexplained":
        absorbed = (f"; {', '.join(u.absorbed_by)} would remove only {u.share_removed:.0%} of it, so it is not named"
                    if u.absorbed_by else "")
        if not u.signals and not u.ripples and not u.offsets:
            if u.partial and (u.scan is None or not u.scan.significant):
                # The only evidence is a candidate's own: the base model is wrong where that
                # candidate acts, by less than a cause must explain.  Both readings fit it.
                names = " or ".join(dict.fromkeys(p.name for p in u.partial))
                return (f"a discrepancy no extension in the catalog explains well enough to be named: {u.summary()}; "
                        f"read it as a weak form of {names}'s cause, or another cause it describes in part")
            return f"no extension in the catalog explains the data: {u.summary() or 'structure remains'}"
        return ("the drawbar runs' held-out residuals hold structure beyond sensor noise that no extension in the "
                f"catalog explains: {u.summary()}{absorbed}")
    if u is not None:
        return f"{catalog_explanation}; structure beyond sensor noise remains: {u.summary()}"
    return catalog_explanation


def residuals_of_none(verdict_: Verdict) -> str:
    """What the base model's residuals hold under the verdict ``none``, in words: sensor noise, or
    structure the test resolves below the floors, each signal with its size and floor."""
    if not verdict_.below_floors:
        return "the residuals are consistent with sensor noise"
    return ("the residuals hold no structure above the floors a right model's replay stays under; below them "
            "the test resolves " + "; ".join(s.below_floor_sentence() for s in verdict_.below_floors))


def not_judged(scan: ScanTests | None) -> list[str]:
    """What of the terrain runs' measured pose the scan test could not judge, in words: the runs
    not tested, and the signals whose block means carry as much sensor noise as their floor."""
    if scan is None:
        return []
    notes = [f"terrain run {run}'s pose was not tested against its scan ({why})" for run, why in scan.untested.items()]
    for run in scan.runs:
        notes += [f"terrain run {run.run}'s {s.signal} was not judged against its scan ({s.unresolved_sentence()})"
                  for s in run.signals if not s.resolvable]
    return notes
