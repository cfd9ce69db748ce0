"""Whether each terrain run's replay follows its measured signals as closely as a right model's does.

The residual structure test (juno.residual_structure) looks at the drawbar runs only, and the
scan test (juno.scan_consistency) at each terrain run's pose against its scan without a replay.
A discrepancy in a terrain run's dynamics that no candidate explains (its torque columns swapped,
a brake dragging only on the terrain run) is seen by neither: without this test the diagnosis
would call it ``none``.

The test: the base model's replay of each terrain run (driven as the diagnosis chose, by the
measured spins or torques), and on each held-out 4 s block the mean residual of each compared
signal, in the column's units.  Sensor noise averages away over a block; what is left is what
the replay gets wrong.  Over the 3-D terrain that is never nothing, even at the true soil: the
replayed path drifts from the measured one, and the drift moves the wheels onto other ground.
So the size that counts is relative to what a right model leaves: the RMS of the held-out block
means over the column's sensor noise (estimated from the column itself:
juno.sensor_noise.column_noise), against a floor per signal calibrated by simulation
(scripts/structure_calibration.py --terrain-replay, docs/results/terrain-replay-calibration.md):
on campaigns with nothing hidden, of both synthetic designs, each floor lies about twice above
the largest ratio the fitted base model left.

As for the scan test (its module docstring has the argument), a floor so placed bounds the rate
of a false report per run and signal by 1 / (n + 1) for a calibration of n right runs, without
assuming a distribution; a campaign of k terrain runs is k chances, and no correction follows
from the calibration.  There is no p-value: what a right model leaves on the terrain is model
error, not noise.

Assumptions, named: the base model is the right one when nothing is hidden (so the test is
applied, by the verdict, only when no catalog cause is named: a named cause's model is judged on
its own held-out gain); sensor noise is white at the sample rate.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

from .campaign import Campaign, RunData, read_run
from .floor_tests import CampaignFloorTests, RunFloorTest
from .identify import PreparedRun
from .sensor_noise import column_noise

#: The floors: the largest RMS of a terrain run's held-out block means, over the column's sensor
#: noise, that is still what a right model leaves (module docstring), about twice the largest seen
#: on 20 campaigns with nothing hidden, of both designs (the 16 of
#: docs/results/terrain-replay-calibration.md, and 4 more): the drive torques up to 2.5, so 5; the
#: positions up to 7.0 (the replayed path drifts, and on the other design's ridge by up to 7 times
#: the total station's noise over a block), so 15.  What the positions' floor leaves unseen, the
#: torques' must see: a replay whose torques depart by 5 times their noise on a 4 s block is off
#: by 15-25 N m at the synthetic sensors' 3-5 N m.  Signals without a floor of their own use
#: DEFAULT_FLOOR, the larger.
FLOORS = {"torque_left": 5.0, "torque_right": 5.0, "pos_x": 15.0, "pos_y": 15.0, "pos_z": 15.0}
DEFAULT_FLOOR = 15.0
UNITS = {"pos_x": "m", "pos_y": "m", "pos_z": "m", "torque_left": "N m", "torque_right": "N m",
         "pitch": "rad", "roll": "rad", "yaw": "rad"}


@dataclass
class ReplaySignal:
    """One compared signal of a terrain run's replay: the RMS of its held-out block means
    (``rms``, the column's units, over ``blocks`` blocks), the column's sensor noise (same units)
    and the floor of their ratio; ``offset``: the mean of the block means."""

    signal: str
    unit: str
    blocks: int
    rms: float
    offset: float
    noise: float
    floor: float

    @property
    def ratio(self) -> float:
        """The RMS of the held-out block means over the sensor noise."""
        return self.rms / self.noise if self.noise > 0 else float("inf")

    @property
    def excess(self) -> float:
        """The ratio to the sensor noise over the floor."""
        return self.ratio / self.floor

    @property
    def disagrees(self) -> bool:
        return bool(self.ratio > self.floor)

    def to_json(self) -> dict[str, Any]:
        return {"signal": self.signal, "unit": self.unit, "blocks": self.blocks, "block_rms": self.rms,
                "mean": self.offset, "sensor_noise": self.noise, "ratio_to_noise": self.ratio,
                "floor": self.floor, "disagrees": self.disagrees}

    def sentence(self) -> str:
        return (f"{self.signal} {self.rms:.3g} {self.unit} RMS over held-out blocks ({self.ratio:.2g} x its sensor "
                f"noise, {self.ratio / self.floor:.2g} x its floor; mean {self.offset:+.3g} {self.unit})")


@dataclass
class TerrainReplay(RunFloorTest):
    """The replay test of one terrain run: every compared signal (ReplaySignal)."""

    def summary(self) -> str:
        found = self.disagreeing()
        if not found:
            return f"the replay of terrain run {self.run} follows it as closely as a right model's does"
        return (f"the replay of terrain run {self.run} departs from it beyond what a right model leaves: "
                + "; ".join(s.sentence() for s in found))

    def to_json(self) -> dict[str, Any]:
        return {"run": self.run, "significant": self.significant, "signals": [s.to_json() for s in self.signals],
                "summary": self.summary()}


@dataclass
class TerrainReplayTests(CampaignFloorTests):
    """The replay test of every terrain run of a campaign (TerrainReplay), in the campaign's order."""

    def summary(self) -> str:
        found = self.disagreeing()
        if found:
            return "; ".join(r.summary() for r in found)
        if len(self.runs) == 1:
            return self.runs[0].summary()
        return f"the replays of terrain runs {', '.join(r.run for r in self.runs)} follow them as closely as a " \
               "right model's do"

    def to_json(self) -> dict[str, Any]:
        return {"significant": self.significant, "disagreeing": [r.run for r in self.disagreeing()],
                "runs": [r.to_json() for r in self.runs], "summary": self.summary()}


def terrain_replay_tests(campaign: Campaign, prepared: Sequence[PreparedRun], meta: Mapping[str, np.ndarray],
                         train: np.ndarray, residuals: np.ndarray,
                         data: Mapping[str, RunData] | None = None) -> TerrainReplayTests | None:
    """The replay test (module docstring) of every terrain run among ``prepared``, whose scaled
    residuals (labelled by ``meta``: run, signal, block; training blocks ``train``) are
    ``residuals``; None without a terrain run.  ``data``: the measured runs by id, when read."""
    terrain = [p for p in prepared if p.kind == "terrain"]
    if not terrain:
        return None
    given = data or {}
    held_out = ~np.asarray(train, bool)
    runs = []
    for p in terrain:
        measured = given[p.run_id] if p.run_id in given else read_run(campaign, p.run_id)
        signals = []
        for column, (_t, _v, _out, sigma, lag) in p.targets.items():
            here = held_out & (meta["run"] == p.run_id) & (meta["signal"] == column)
            blocks = meta["block"][here]
            if len(np.unique(blocks)) < 2:
                continue
            values = residuals[here] * sigma
            means = np.array([np.mean(values[blocks == b]) for b in np.unique(blocks)])
            noise = column_noise(*measured.samples(column))
            if lag > 0:
                noise *= np.sqrt(2.0)      # an increment over a lag is the difference of two samples
            if not np.isfinite(noise):
                continue
            signals.append(ReplaySignal(column, UNITS.get(column, ""), len(means), float(np.sqrt(np.mean(means ** 2))),
                                        float(np.mean(means)), float(noise), FLOORS.get(column, DEFAULT_FLOOR)))
        runs.append(TerrainReplay(p.run_id, signals))
    return TerrainReplayTests(runs)
