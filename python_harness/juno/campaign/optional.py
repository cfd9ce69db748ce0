"""What the optional columns of a run buy, and what a campaign without them loses.

:data:`OPTIONAL_COLUMN_USES` says, for each optional column some kind of run uses, what its absence
costs there; it is the source of the table in docs/campaign-format.md ("What roll, pitch and yaw
buy", written by scripts/generate_docs.py).  :func:`missing_columns` lists the columns a
campaign's runs lack, with those costs: ``juno identify``, ``juno validate`` and ``juno diagnose``
print them and carry them in their JSON (``missing_columns``).  The IMU's accelerations and rates
(``acc_*``, ``gyro_*``) are read and kept, and no analysis uses them, so lacking them costs nothing.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Optional, Sequence

from .records import Campaign
from .tables import read_run

#: column -> {kind of run that uses it: what a run of that kind without it costs}.
OPTIONAL_COLUMN_USES: dict[str, dict[str, str]] = {
    "pitch": {
        "drawbar": "the joint fit and the diagnosis compare no pitch, so k_h is determined less well (on "
                   "full-length synthetic campaigns its stated uncertainty is 4-9 times larger, most of it the "
                   "replay's own bias, which the fit measures; a short campaign's fit may stop without "
                   "converging), and the residual structure test leaves the pitch out",
        "terrain": "the diagnosis registers the scan and tests the run's pose against it without the pitch "
                   "(on the height and any roll)",
    },
    "roll": {
        "terrain": "the diagnosis registers the scan and tests the run's pose against it without the roll "
                   "(on the height and any pitch)",
    },
    "yaw": {
        "drawbar": "each replay starts along the direction of the run's track (the rover driving straight, "
                   "forwards or backwards as its wheels turn), not at a measured heading",
        "terrain": "each replay starts along the direction of the run's track, not at a measured heading; "
                   "the run's pose is not tested against its scan (the track's direction is not the "
                   "rover's heading where it slides sideways), and --terrain-segments cannot replay it",
    },
}


@dataclass(frozen=True)
class MissingColumn:
    """An optional ``column`` that the ``runs`` (ids) of one ``kind`` lack (no column, or no
    sample in it), and what that costs them (``consequence``, from OPTIONAL_COLUMN_USES)."""

    column: str
    kind: str
    runs: tuple[str, ...]
    consequence: str

    def to_json(self) -> dict[str, Any]:
        return {"column": self.column, "kind": self.kind, "runs": list(self.runs),
                "consequence": self.consequence}

    def sentence(self) -> str:
        """The finding in one line: ``no pitch in drawbar runs dbp1, dbp2: the joint fit ...``."""
        return (f"no {self.column} in {self.kind} run{'s' if len(self.runs) != 1 else ''} "
                f"{', '.join(self.runs)}: {self.consequence}")


def missing_columns(campaign: Campaign, kinds: Optional[Sequence[str]] = None) -> list[MissingColumn]:
    """The optional columns the campaign's runs of ``kinds`` (None: every kind) lack where their
    kind uses them (OPTIONAL_COLUMN_USES), in the table's order; [] when nothing used is missing.
    Reads the runs (:func:`read_run` keeps them for the analysis that follows)."""
    out = []
    for column, uses in OPTIONAL_COLUMN_USES.items():
        for kind, consequence in uses.items():
            if kinds is not None and kind not in kinds:
                continue
            lacking = tuple(r.id for r in campaign.runs_of_kind(kind) if not read_run(campaign, r).has(column))
            if lacking:
                out.append(MissingColumn(column, kind, lacking, consequence))
    return out
