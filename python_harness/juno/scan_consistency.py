"""Whether each terrain run's measured pose agrees with its scan, without simulating the rover.

The residual structure test (juno.residual_structure) looks at the drawbar runs only: over the
3-D terrain the replay drifts from the measured path even at the true soil.  A scan error that
is not a shift (a scan tilted about a horizontal axis) shows on the terrain runs alone, and no
catalog candidate describes it; without a test there, the diagnosis would call it ``none``.
Each terrain run is tested against its own scan (a campaign may hold several, each scanned
separately), by the same rule and floors.

This test needs no replay.  The rover is posed on the scan at every measured position and
heading (juno.registration.pose_on_ground: the four wheels resting on the scanned ground, the
chassis height above flat ground measured on the drawbar runs), and its height, pitch and roll
are compared with the measured ones, the attitude gains fitted on the training blocks as the
registration's held-out evidence fits them.  On each held-out 4 s block the mean residual of
each signal is taken: sensor noise mostly averages away (4 mm over 40 samples is 0.6 mm), what
is left is the kinematic model's own error (the rover does not rest exactly as posed: its
sinkage follows the load, and it pitches as it climbs) plus any disagreement between scan and
ground.  What the noise leaves (each block's sigma^2 / n, sigma stated in the manifest or estimated
from the measured column: juno.sensor_noise) is taken off the block means' mean square.

A signal disagrees when the RMS of its held-out block means beyond the sensor's noise exceeds
its floor.  A signal whose block means carry as much noise as its floor is not judged: a
receiver's 4 cm at 2 Hz leaves 14 mm in a 4 s block's mean, and a disagreement of the floor's
size could not be told from it (a run with no signal left to judge is untested, and says why).  The floors
(FLOORS) are calibrated by simulation (scripts/structure_calibration.py --scan,
docs/results/scan-calibration.md): on campaigns with nothing hidden, of both synthetic designs,
each floor lies about twice above the largest block-mean RMS the scan as it is left.  There is
no p-value: what a right scan leaves is model error, not noise, and only simulation gives its
size.

The floors apply per run, and are not corrected for the number of terrain runs k.  What the
calibration bounds is per run: each of its campaigns has one terrain run, and none of the n = 16
with nothing hidden came within half of a floor.  Without assuming a distribution, a right run
that is drawn like the calibration's exceeds the largest of those n in a given signal with
probability at most 1 / (n + 1), and one of k such runs with at most k / (n + k) (the largest of
n + k lies among the k new ones); a floor lies twice above that largest, so the rate of a false
report is below these bounds, by a margin the calibration cannot measure.  A campaign of k terrain
runs is therefore k chances: its bound grows from 1/17 to k/(16 + k) per signal (about k times,
the union bound over runs, whatever their ground shares).  No correction is applied because none
follows from the calibration: raising a floor for k runs needs the tail of what a right scan
leaves beyond the largest run simulated, which 16 runs do not give; a campaign of k runs would be
bounded as a single run is by a calibration of k x 16 right runs.

A terrain run without a measured heading (no yaw column) is not tested: the heading of its track
(juno.heading) is not the rover's where it slides sideways on a slope (by a tenth of a radian or
more on the synthetic mound, which turns the wheels' footprint by centimetres), and the floors
are calibrated with a measured heading.

Assumptions, named: the scan is used as it is (the test reports a scan the diagnosis did not
register; see verdict.py for when it counts), and the sinkage is about the same everywhere on the
terrain run (a soft soil patch the rover crosses sinks it deeper, which looks like a lower scan).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from .sensor_noise import sensor_noise

#: The floors of the RMS of the held-out block means, per signal (m for the height, rad for the
#: angles): about twice the largest a scan with nothing wrong left on synthetic campaigns with
#: nothing hidden, of both designs (the 16 of docs/results/scan-calibration.md: height 2.4 mm,
#: pitch 11.5 mrad, roll 8.3 mrad; up to 2.8 mm in height on 7 more seeds).  The roll's is set by
#: the default design's mound, on whose flank the downhill wheels sink deeper than the kinematic
#: pose has them.  So a scan tilted across the path (by up to 1 degree) shows by its height, and
#: one tilted about the path itself (the axis within about 20 degrees of it) leans the rover by
#: less than the roll floor and is not seen (the page lists those draws).
FLOORS = {"height": 0.006, "pitch": 0.024, "roll": 0.017}
UNITS = {"height": "m", "pitch": "rad", "roll": "rad"}
#: The measured column of each compared signal (its sensor noise: juno.sensor_noise).
SIGNAL_COLUMNS = {"height": "pos_z", "pitch": "pitch", "roll": "roll"}


@dataclass
class ScanSignal:
    """One compared signal: the RMS of its held-out block means (``rms``, signal units), its
    floor, the mean of the block means (``offset``: a constant disagreement), and the RMS the
    block means have from the sensor's noise alone (``noise``: each block's sigma^2 / n)."""

    signal: str
    unit: str
    blocks: int
    rms: float
    offset: float
    floor: float
    noise: float = 0.0

    @property
    def excess(self) -> float:
        """The block means' RMS beyond their sensor noise: sqrt(rms^2 - noise^2), at least 0."""
        return float(np.sqrt(max(self.rms ** 2 - self.noise ** 2, 0.0)))

    @property
    def resolvable(self) -> bool:
        """Whether the block means' own noise lies below the floor: else no disagreement of the
        floor's size can be told from the sensor's noise, and the signal is not judged."""
        return bool(self.noise < self.floor)

    @property
    def disagrees(self) -> bool:
        return bool(self.resolvable and self.excess > self.floor)

    def to_json(self) -> dict[str, Any]:
        return {"signal": self.signal, "unit": self.unit, "blocks": self.blocks, "block_rms": self.rms,
                "noise": self.noise, "beyond_noise": self.excess, "mean": self.offset, "floor": self.floor,
                "resolvable": self.resolvable, "disagrees": self.disagrees}

    def sentence(self) -> str:
        scale, shown = (1000.0, "mm") if self.unit == "m" else (1000.0, "mrad")
        return (f"{self.signal} {self.excess * scale:.3g} {shown} RMS over held-out blocks beyond the sensor's noise "
                f"({self.excess / self.floor:.2g} x its floor, mean {self.offset * scale:+.3g} {shown})")

    def unresolved_sentence(self) -> str:
        scale, shown = (1000.0, "mm") if self.unit == "m" else (1000.0, "mrad")
        return (f"{self.signal}'s block means carry {self.noise * scale:.3g} {shown} of sensor noise, at or above "
                f"the floor of {self.floor * scale:.3g} {shown}")


@dataclass
class ScanConsistency:
    """The scan test of one terrain run (``run``): every signal, and the attitude gains (pitch,
    roll) fitted on its training blocks."""

    run: str
    signals: list[ScanSignal] = field(default_factory=list)
    gains: tuple[float, float] = (1.0, 1.0)

    @property
    def significant(self) -> bool:
        return any(s.disagrees for s in self.signals)

    def disagreeing(self) -> list[ScanSignal]:
        """The signals that disagree, largest relative to their floor first."""
        return sorted((s for s in self.signals if s.disagrees), key=lambda s: -s.excess / s.floor)

    def resolvable(self) -> bool:
        """Whether some signal's block means are quiet enough to be judged (ScanSignal.resolvable)."""
        return any(s.resolvable for s in self.signals)

    def summary(self) -> str:
        found = self.disagreeing()
        unjudged = [s.unresolved_sentence() for s in self.signals if not s.resolvable]
        aside = f" (not judged: {'; '.join(unjudged)})" if unjudged else ""
        if not found:
            return f"the measured pose on terrain run {self.run} agrees with its scan{aside}"
        return (f"the measured pose on terrain run {self.run} disagrees with its scan (posed on it kinematically): "
                + "; ".join(s.sentence() for s in found) + aside)

    def to_json(self) -> dict[str, Any]:
        return {"run": self.run, "significant": self.significant, "gains": list(self.gains),
                "signals": [s.to_json() for s in self.signals], "summary": self.summary()}


@dataclass
class ScanTests:
    """The scan test of every terrain run of a campaign, each against its own scan: the runs
    tested (in the campaign's order) and the runs that could not be (run id -> why).  The floors
    apply per run (the module docstring says what that means for a campaign of several)."""

    runs: list[ScanConsistency] = field(default_factory=list)
    untested: dict[str, str] = field(default_factory=dict)

    @property
    def significant(self) -> bool:
        """Whether some terrain run's measured pose disagrees with its scan."""
        return any(r.significant for r in self.runs)

    def disagreeing(self) -> list[ScanConsistency]:
        """The terrain runs whose measured pose disagrees with their scan, in the campaign's order."""
        return [r for r in self.runs if r.significant]

    def summary(self) -> str:
        """One sentence: the runs that disagree and their signals, or that every run tested agrees."""
        found = self.disagreeing()
        if found:
            text = "; ".join(r.summary() for r in found)
        elif len(self.runs) == 1:
            text = self.runs[0].summary()
        elif self.runs:
            text = (f"the measured pose on terrain runs {', '.join(r.run for r in self.runs)} agrees with "
                    "their scans")
        else:
            text = "no terrain run could be tested against its scan"
        untested = [f"terrain run {run} not tested ({why})" for run, why in self.untested.items()]
        return "; ".join([text] + untested)

    def to_json(self) -> dict[str, Any]:
        return {"significant": self.significant, "disagreeing": [r.run for r in self.disagreeing()],
                "runs": [r.to_json() for r in self.runs],
                "untested": [{"run": run, "reason": why} for run, why in self.untested.items()],
                "summary": self.summary()}


def scan_consistency(grid, traverse, h0: float, train: np.ndarray, block: np.ndarray, run: str,
                     noise: Mapping[str, float] | None = None) -> ScanConsistency:
    """The test (module docstring) of ``traverse`` (juno.registration.Traverse) on ``grid`` (its
    gridded scan, as it is), with chassis height ``h0`` (m) above flat ground; ``train`` marks the
    training samples, ``block`` numbers every sample's block; ``noise``: each signal's sensor
    noise per sample (1 sigma; "height", "pitch", "roll"), none where not given.  ValueError if a
    residual is not finite (a measured sample missing, or the pose not solved): a test that
    cannot be computed is not a test passed."""
    from scipy.optimize import least_squares

    from .registration import GAIN_LIMITS, NOFFSETS, SIGMA_PITCH, SIGMA_ROLL, SIGMA_Z, _Posing, residuals
    measured = {"x": traverse.x, "y": traverse.y, "yaw": traverse.yaw, "height": traverse.z,
                "pitch": traverse.pitch, "roll": traverse.roll}
    for name, values in measured.items():
        _require_finite(run, f"measured {name}", values, traverse.t)
    train = np.asarray(train, bool)
    fitted = traverse.subset(train)
    lower, upper = [g[0] for g in GAIN_LIMITS], [g[1] for g in GAIN_LIMITS]
    # The scan as it is poses the rover once: the gains only scale the posed attitude, so every
    # evaluation of the fit reuses the training samples' pose (_Posing keeps it), the same numbers
    # as registration.residuals gives at each.
    posing = _Posing(grid, fitted, h0)
    fit = least_squares(lambda g: posing.residuals(np.zeros(NOFFSETS), (g[0], g[1])),
                        np.clip(np.ones(2), lower, upper), bounds=(lower, upper))
    gains = (float(fit.x[0]), float(fit.x[1]))
    r = residuals(np.zeros(NOFFSETS), grid, traverse, h0, gains)
    n = len(traverse.x)
    parts = {"height": r[:n] * SIGMA_Z}
    k = 1
    if traverse.pitch is not None:
        parts["pitch"] = r[k * n:(k + 1) * n] * SIGMA_PITCH
        k += 1
    if traverse.roll is not None:
        parts["roll"] = r[k * n:(k + 1) * n] * SIGMA_ROLL
    held = ~train
    blocks = np.unique(block[held])
    signals = []
    for name, values in parts.items():
        _require_finite(run, f"{name} of the rover posed on the scan", values, traverse.t)
        means = np.array([np.mean(values[held & (block == b)]) for b in blocks])
        if len(means) == 0:
            continue
        sigma = float((noise or {}).get(name, 0.0))
        sigma = sigma if np.isfinite(sigma) else 0.0
        counts = np.array([np.sum(held & (block == b)) for b in blocks])
        signals.append(ScanSignal(name, UNITS[name], len(means), float(np.sqrt(np.mean(means ** 2))),
                                  float(np.mean(means)), FLOORS[name], float(np.sqrt(np.mean(sigma ** 2 / counts)))))
    return ScanConsistency(run, signals, gains)


def _require_finite(run: str, what: str, values: np.ndarray | None, t: np.ndarray | None) -> None:
    """ValueError naming the run, the quantity and the first sample's time if ``values`` holds a
    value that is not finite."""
    if values is None:
        return
    bad = np.flatnonzero(~np.isfinite(values))
    if len(bad):
        when = f" (the first at t = {t[bad[0]]:.3f} s)" if t is not None else ""
        raise ValueError(f"terrain run {run}: the {what} is not finite at {len(bad)} of {len(values)} samples"
                         f"{when}; the scan test cannot be computed")


def terrain_run_scan_consistency(campaign, run, grid, block_s: float, h0: float | None = None
                                 ) -> ScanConsistency | None:
    """The test of terrain run ``run`` (juno.campaign.RunSpec) of ``campaign`` on ``grid``, its
    own gridded scan, in blocks of ``block_s`` seconds counted from the run's first sample (the
    diagnosis's: training blocks even, held-out blocks odd); ``h0`` (m): the chassis height above
    flat ground, measured on the drawbar runs when not given.  None when the campaign has no
    drawbar run to measure it on, or the run is too short to have both kinds of block."""
    from .campaign import read_run
    from .registration import flat_height, traverse_of
    h0 = flat_height(campaign) if h0 is None else h0
    if h0 is None:
        return None
    traverse = traverse_of(campaign, run)
    data = read_run(campaign, run)
    since_start = traverse.t - data.time[0]
    block = np.floor(since_start / block_s).astype(int)
    train = block % 2 == 0
    if train.all() or not train.any():
        return None
    noise = {signal: sensor_noise(data, column) for signal, column in SIGNAL_COLUMNS.items()
             if data.has(column)}
    return scan_consistency(grid, traverse, h0, train, block, run.id, noise)


def campaign_scan_consistency(campaign, grids: Mapping[str, Any], block_s: float) -> ScanTests | None:
    """The test of every terrain run of ``campaign``, each on its own gridded scan (``grids``: run
    id -> juno.pointcloud.Grid), in blocks of ``block_s`` seconds (terrain_run_scan_consistency);
    None when the campaign has no drawbar run to measure the chassis height on.  ValueError if a
    terrain run has no grid: a run left out would be a run reported as agreeing untested."""
    from .registration import flat_height
    h0 = flat_height(campaign)
    if h0 is None:
        return None
    from .campaign import read_run
    tests = ScanTests()
    for run in campaign.runs_of_kind("terrain"):
        if run.id not in grids:
            raise ValueError(f"terrain run {run.id}: no gridded scan to test its measured pose against")
        if not read_run(campaign, run).has("yaw"):
            tests.untested[run.id] = ("no measured heading (yaw column): the track's direction is not the rover's "
                                      "where it slides sideways on a slope, and the floors are calibrated with a "
                                      "measured heading")
            continue
        test = terrain_run_scan_consistency(campaign, run, grids[run.id], block_s, h0)
        if test is None:
            tests.untested[run.id] = f"shorter than two blocks of {block_s:g} s after settling"
        elif not test.resolvable():
            tests.untested[run.id] = ("the sensors' noise in the held-out block means reaches every floor: "
                                      + "; ".join(s.unresolved_sentence() for s in test.signals))
        else:
            tests.runs.append(test)
    return tests
