"""The verdict: a catalog cause, ``none``, or ``unexplained``.

The search (search.py) names catalog causes by their held-out gain.  The verdict then asks the
residual structure test (juno/residual_structure.py) what the models leave:

- no cause named, and the base model leaves no structure: ``none``; the residuals are
  consistent with sensor noise;
- no cause named, but the base model leaves structure: ``unexplained``, with the signals and
  what they follow (a ripple in the drive torques at N per wheel revolution counts as
  structure: no catalog cause models one);
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
  remainder).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from ..periodic_structure import PeriodicSignal
from ..residual_structure import ResidualStructure, SignalStructure
from ..scan_consistency import ScanTests
from ..timing_structure import SignalOffset
from .candidates import CANDIDATES, makes_ripple

#: The least share of the base model's residual structure a catalog model must remove to be
#: named for it (see the module docstring).
EXPLAINED_SHARE = 0.5


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

    def to_json(self) -> dict[str, Any]:
        return {"model": self.model, "signals": [s.to_json() for s in self.signals],
                "ripples": [r.to_json() for r in self.ripples],
                "offsets": [o.to_json() for o in self.offsets],
                "absorbed_by": self.absorbed_by, "share_removed": self.share_removed,
                "scan": self.scan.to_json() if self.scan is not None else None,
                "summary": self.summary()}

    def summary(self, most: int = 3) -> str:
        """One sentence: the ``most`` largest signals' structure and the covariate each follows
        best, then the ripples in the wheel angle (the JSON has every signal and covariate)."""
        more = len(self.signals) - most
        parts = [s.sentence() for s in self.signals[:most]]
        if more > 0:
            parts.append(f"and {more} more signal{'s' if more > 1 else ''}")
        scan = [self.scan.summary()] if self.scan is not None and self.scan.significant else []
        return "; ".join(parts + [r.sentence() for r in self.ripples] + [o.sentence() for o in self.offsets] + scan)


@dataclass
class Verdict:
    """What the diagnosis reports: ``cause`` (a catalog cause, "none" or "unexplained"), the
    catalog ``causes`` named (strongest first), and what is left unexplained (or None)."""

    cause: str
    causes: list[str]
    unexplained: Unexplained | None


def verdict(causes: list[str], base: ResidualStructure | None, extended: ResidualStructure | None,
            scan: ScanTests | None = None) -> Verdict:
    """The verdict (module docstring) from the catalog ``causes`` the search named, the structure
    tests of the base model and of the model with those causes (None when none was named), and
    the terrain runs' scan tests (None: no terrain run tested; used only when no cause is named).
    A test that could not be made is None (search.what_the_models_leave): the named causes then
    stand on their held-out evidence, with no share of the base model's structure to weigh them
    by; the base model's test must exist when nothing is named."""
    if not causes:
        assert base is not None
        disagrees = scan if scan is not None and scan.significant else None
        if base.significant or disagrees is not None:
            return Verdict("unexplained", [], Unexplained("base", base.structured(), ripples=base.ripples(),
                                                          scan=disagrees, offsets=base.offsets()))
        return Verdict("none", [], None)
    if extended is None or not extended.significant:
        return Verdict(causes[0], causes, None)
    if not extended.structured() or base is None:
        # only a ripple or an offset is left (the causes explain what they act on), or the base
        # model's structure is unknown: what is left is reported beside the causes
        return Verdict(causes[0], causes, Unexplained("+".join(causes), extended.structured(),
                                                      ripples=extended.ripples(), offsets=extended.offsets()))
    removed = 1.0 - extended.block_excess / base.block_excess if base.block_excess > 0 else 0.0
    left = Unexplained("+".join(causes), extended.structured(), share_removed=removed, ripples=extended.ripples(),
                       offsets=extended.offsets())
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
        return "no extension explains the held-out data significantly better, and the residuals are consistent " \
               "with sensor noise"
    if verdict_.cause == "unexplained":
        absorbed = (f"; {', '.join(u.absorbed_by)} would remove only {u.share_removed:.0%} of it, so it is not named"
                    if u.absorbed_by else "")
        if not u.signals and not u.ripples and not u.offsets:
            return f"no extension in the catalog explains the data, and {u.summary()}"
        return ("the drawbar runs' held-out residuals hold structure beyond sensor noise that no extension in the "
                f"catalog explains: {u.summary()}{absorbed}")
    if u is not None:
        return f"{catalog_explanation}; structure beyond sensor noise remains: {u.summary()}"
    return catalog_explanation
