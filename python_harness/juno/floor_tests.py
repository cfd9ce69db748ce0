"""Tests that judge each terrain run's signals against floors calibrated by simulation.

What a right model leaves on a terrain run is model error, not noise (juno.scan_consistency,
juno.terrain_replay), so such a test compares a size with a floor rather than a p-value.  These
bases hold what those tests share: a run's signals, each of which disagrees when it exceeds its
floor, and a campaign's runs."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol


class FloorSignal(Protocol):
    """A signal judged against its floor: ``excess`` is its size over the floor."""

    @property
    def excess(self) -> float: ...

    @property
    def disagrees(self) -> bool: ...


@dataclass
class RunFloorTest:
    """The test of one terrain run (``run``): its signals."""

    run: str
    signals: list[Any] = field(default_factory=list)

    @property
    def significant(self) -> bool:
        return any(s.disagrees for s in self.signals)

    def disagreeing(self) -> list[Any]:
        """The signals beyond their floors, largest relative to the floor first."""
        return sorted((s for s in self.signals if s.disagrees), key=lambda s: -s.excess)


@dataclass
class CampaignFloorTests:
    """The test of every terrain run of a campaign, in the campaign's order."""

    runs: list[Any] = field(default_factory=list)

    @property
    def significant(self) -> bool:
        """Whether some terrain run disagrees."""
        return any(r.significant for r in self.runs)

    def disagreeing(self) -> list[Any]:
        """The terrain runs that disagree, in the campaign's order."""
        return [r for r in self.runs if r.significant]
