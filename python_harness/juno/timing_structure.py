"""Residual structure that follows a signal's rate of change: a clock offset between instruments.

A drawbar replay is driven by measured inputs (the wheel spins and the drawbar force, on the
motor and load-cell clocks) and compared with measured outputs (positions, pitch, torques) that
other instruments may time-stamp on clocks of their own.  When an output's clock is offset from
the inputs' by tau, its sample at time t holds the value the rover had at t + tau, and its
residual against a right model is, to first order, tau times the signal's rate of change:

    r(t) = y_measured(t) - y_model(t) = y(t + tau) - y(t) ~ tau dy/dt.

The block means of residual_structure do not see it: a rate of change that comes and goes within
a block (the rover slowing as the drawbar load rises, speeding up as it falls) averages away.
This test fits the one parameter tau per compared signal, and one common tau for the positions,
which one instrument time-stamps, and reports that one.

Method (docs/diagnosis.md, "What no candidate explains"):

1. **The regressor.** For every held-out sample of a compared signal (the same samples the
   structure test uses), the replay's rate of change of the compared quantity (for the
   positions, compared as increments over a lag, the increments'), by a central difference over
   +-RATE_HALF_WIDTH s of the replay at the signal's sample times.  The replay carries no sensor
   noise, so the regressor is not attenuated by noise of its own.
2. **The estimate.** tau = sum(g r) / sum(g^2) over the signal's held-out samples in every drawbar
   run (r the residual, g the regressor, both in the signal's units): least squares for a
   common offset.
3. **The null by simulation.** The same contrast of each bootstrap replica of the structure test
   (the replay with fresh input noise, and fresh output noise; residual_structure step 3) gives
   tau's distribution when the model is right; the observed tau minus the replicas' mean, over
   their standard deviation, is taken as Student's t with replicas - 1 degrees of freedom (scaled
   by sqrt(1 + 1 / replicas) for the estimated mean); the offset reported is tau less that mean.
4. **One clock, one test.** The positions (TIMED_SIGNALS) come from one instrument (a total
   station's prism, a GNSS antenna), so they share one clock and one offset: tau is estimated
   over the held-out samples of all of them together (steps 2 and 3 over their union; in scaled
   units, the least squares common offset, each sample weighed by its signal's noise), and
   tested once (POSITIONS).  Tested one by one, a position that the model gets wrong in a way
   that correlates with its rate of change (pos_y off by 0.4-0.8 s where pos_x, from the same
   prism, is off by 0.03) would be reported as a clock that the other position, on the same
   clock, contradicts; and three tests would each need a third of the level.  Each position's
   own estimate is still given (not tested), so that the user can see whether they agree.
5. **The test.** The positions are offset when their common offset's two-sided p is below
   FALSE_ALARM, the offset lies between MATERIAL_OFFSET and LINEAR_LIMIT, and the positions'
   own offsets agree with it: one clock gives every position the same offset, so Cochran's Q
   of their own estimates about the common one (each over its null spread; the common estimate
   is their inverse-variance weighted mean under white noise) is chi-squared with one degree of
   freedom fewer than the positions, and a Q beyond its 1 - FALSE_ALARM quantile says the
   residual follows the rate of change in a way no clock does (a real offset is refused so in at
   most FALSE_ALARM of campaigns).  Below MATERIAL_OFFSET an offset is the replay's own: it
   applies its inputs held over each communication step (juno.simulator), a delay of half a
   step that a right model's positions show as offsets of a few hundredths of a second.  Beyond
   LINEAR_LIMIT the first-order expansion does not hold (the rover's speed changes within about
   a second), so a fitted tau that large says only that the residual correlates with the rate of
   change, not that the signal is shifted; a shift that large leaves block-mean structure of its
   own, which residual_structure reports.

Why the positions alone: their timing follows the spins' through kinematics (the rover moves at
the wheels' spin times their radius, less the slip), which a right model reproduces to within
the replay's half-step delay.  The pitch follows the chassis' settling under a changing load and
the drive torques the replay's speed controller following the measured spins: on right models
these leave offsets of their own, resolved at up to 0.17 s in the pitch (MATERIAL_OFFSET's
calibration), larger than the smallest offset reported.  Their offsets are estimated and reported in the JSON
(``timed`` false), not tested; a clock offset of the IMU alone is not found (a known limit).

Assumptions: one constant offset per signal over the campaign's drawbar runs, and one for all
the positions (one instrument); the rover's speed
changes within the held-out blocks (a rising or falling drawbar load), which is where an offset
shows; a signal whose rate of change is nearly constant has no information about an offset
(tau's null spread is then large and nothing is reported).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

#: At most this many false offset reports per campaign (one test: the positions' common offset).
FALSE_ALARM = 0.01
#: The signals whose common offset is tested (see the module docstring: the positions, which one
#: instrument time-stamps).
TIMED_SIGNALS = ("pos_x", "pos_y", "pos_z")
#: The name the positions' common offset is reported under.
POSITIONS = "positions"
#: Half-width (s) of the central difference that gives a compared signal's rate of change: wide
#: enough to span two samples of the slowest instruments (5 Hz positions), narrow enough to follow
#: the rover's speed changes, which take about a second.
RATE_HALF_WIDTH = 0.25
#: The smallest offset (s) reported: twice the replay's communication step
#: (residual_structure.OUTPUT_INTERVAL, 0.05 s), whose sample-and-hold of the inputs delays the
#: replay by half a step.  Calibrated by simulation (scripts/structure_calibration.py,
#: docs/results/structure-calibration.md): on campaigns with nothing hidden, of both designs, the
#: fitted right model leaves offsets in the positions of up to about 0.04 s that the test resolves;
#: the floor lies twice above them, and below the clock offset the decoy of juno.effects hides
#: (0.25 s at strength 1).  The positions' common offset (and its null's mean) is a weighted mean
#: of theirs one by one (weights sum(g^2) per signal), so it stays within the same bound.
MATERIAL_OFFSET = 0.1
#: The largest offset (s) reported as one: where the first-order expansion stops holding.
LINEAR_LIMIT = 1.0


@dataclass
class SignalOffset:
    """The offset test of one compared signal: ``offset`` (s; the measured value stamped t is the
    replay's at t + offset, so a positive offset is a clock running behind the inputs'), the
    null's spread of it (``spread``, s), the p-value, whether it is reported (``significant``),
    the held-out samples it was fitted on, and the RMS of offset x rate of change over them
    (``explained``, in units of the signal's sigma)."""

    signal: str
    offset: float
    spread: float
    p_value: float
    significant: bool
    samples: int
    explained: float = 0.0
    timed: bool = True
    #: for the positions' common offset: the p-value of its signals' own offsets agreeing with it
    #: (Cochran's Q; module docstring, step 5), None with fewer than two of them
    agreement_p: float | None = None

    def to_json(self) -> dict[str, Any]:
        return {"signal": self.signal, "offset": self.offset, "null_spread": self.spread,
                "p_value": self.p_value, "significant": self.significant, "samples": self.samples,
                "explained_rms": self.explained, "timed": self.timed, "agreement_p": self.agreement_p}

    def sentence(self) -> str:
        """The offset in words: what the residual follows, and the clock offset that would leave it
        (a model error can correlate with the rate of change too, so the clock is not asserted)."""
        if self.signal == POSITIONS:
            lag = "lag" if self.offset > 0 else "lead"
            subject, their = f"the positions ({', '.join(TIMED_SIGNALS)})", "their residuals follow their"
        else:
            lag = "lags" if self.offset > 0 else "leads"
            subject, their = self.signal, "its residual follows its"
        return (f"{subject} {lag} the replay by {abs(self.offset):.2g} s: {their} rate of "
                f"change as a clock {abs(self.offset):.2g} s {self.direction()} the inputs' clock leaves it "
                f"(p {self.p_value:.1g})")

    def brief(self) -> str:
        """The finding in a few words (a progress line)."""
        return f"{self.signal} offset {self.offset:+.2g} s from the inputs"

    def direction(self) -> str:
        """'behind' when the signal's sample stamped t was taken later than t on the inputs' clock
        (a positive offset), 'ahead of' otherwise."""
        return "behind" if self.offset > 0 else "ahead of"


@dataclass
class TimingStructure:
    """Every compared signal's offset test; ``significant`` if any signal is offset."""

    signals: list[SignalOffset]
    level: float

    @property
    def significant(self) -> bool:
        return any(s.significant for s in self.signals)

    def found(self) -> list[SignalOffset]:
        """The offset signals, largest offset relative to its null spread first."""
        return sorted((s for s in self.signals if s.significant), key=lambda s: -abs(s.offset) / s.spread)

    def to_json(self) -> dict[str, Any]:
        return {"significant": self.significant, "false_alarm": FALSE_ALARM, "level": self.level,
                "material_offset": MATERIAL_OFFSET, "linear_limit": LINEAR_LIMIT, "rate_half_width": RATE_HALF_WIDTH,
                "signals": [s.to_json() for s in self.signals]}


def rate_of_change(times: np.ndarray, values: np.ndarray, half_width: float = RATE_HALF_WIDTH) -> np.ndarray:
    """The rate of change (units per s) of the series ``values`` at its own ``times`` (s), by a
    central difference over +-``half_width`` s interpolated between the series' samples; NaN
    where the difference would reach past either end."""
    t = np.asarray(times, float)
    v = np.asarray(values, float)
    g = (np.interp(t + half_width, t, v) - np.interp(t - half_width, t, v)) / (2.0 * half_width)
    g[(t - half_width < t[0]) | (t + half_width > t[-1])] = np.nan
    return g


def regressors(prepared: Sequence[Any], residuals: np.ndarray, kinds: Sequence[str] = ("drawbar",)) -> np.ndarray:
    """For every residual of ``prepared`` (identify.PreparedRun, in run_residuals' order; the
    scaled ``residuals`` of the replay), the rate of change of the replay's compared quantity
    (measured minus residual) in scaled units (over the signal's sigma) per s; NaN for the runs
    not of ``kinds`` and where no central difference fits."""
    parts = []
    start = 0
    for p in prepared:
        for _column, (ts, vs, _out, sigma, _lag) in p.targets.items():
            n = len(ts)
            if p.kind not in kinds or n < 3:
                parts.append(np.full(n, np.nan))
            else:
                model = vs - residuals[start:start + n] * sigma
                parts.append(rate_of_change(ts, model) / sigma)
            start += n
    return np.concatenate(parts) if parts else np.zeros(0)


def timing_structure(signal_of: np.ndarray, tested: np.ndarray, g: np.ndarray, residuals: np.ndarray,
                     null_residuals: np.ndarray) -> TimingStructure:
    """The offset test (module docstring) over the residuals where ``tested`` (held-out samples of
    the drawbar runs), labelled by their signal (``signal_of``), with regressor ``g`` (regressors)
    and ``null_residuals`` (replicas x residuals, the structure test's bootstrap): all in scaled
    units.  Every signal's offset is estimated (not tested), then the positions' common one
    (POSITIONS), which alone can be significant."""
    use = tested & np.isfinite(g)
    names = [str(s) for s in np.unique(signal_of[use])]
    out = [_offset(name, use & (signal_of == name), g, residuals, null_residuals, timed=False) for name in names]
    positions = use & np.isin(signal_of, TIMED_SIGNALS)
    common = _offset(POSITIONS, positions, g, residuals, null_residuals, timed=True) if np.any(positions) else None
    if common is not None:
        own = [o for o in out if o is not None and o.signal in TIMED_SIGNALS]
        if len(own) >= 2:
            from scipy.stats import chi2
            q = sum(((o.offset - common.offset) / o.spread) ** 2 for o in own)
            common.agreement_p = float(chi2.sf(q, len(own) - 1))
            common.significant = common.significant and common.agreement_p >= FALSE_ALARM
        out.append(common)
    return TimingStructure([o for o in out if o is not None], FALSE_ALARM)


def _offset(name: str, mine: np.ndarray, g: np.ndarray, residuals: np.ndarray, null_residuals: np.ndarray,
            timed: bool) -> SignalOffset | None:
    """The offset of the samples ``mine`` (one signal's, or the positions' together) against the
    null of the replicas (module docstring, steps 2-3); significant only when ``timed`` (step 5).
    None when the samples carry no rate of change or there are too few replicas for a spread."""
    from scipy.stats import t as student_t
    replicas = null_residuals.shape[0]
    gm = g[mine]
    gg = float(np.sum(gm * gm))
    if gg <= 0 or replicas < 3:
        return None
    observed = float(np.sum(gm * residuals[mine])) / gg
    null = null_residuals[:, mine] @ gm / gg
    spread = float(np.std(null, ddof=1)) * np.sqrt(1.0 + 1.0 / replicas)
    if not spread > 0:
        return None
    t_stat = (observed - float(np.mean(null))) / spread
    p = float(2.0 * student_t.sf(abs(t_stat), replicas - 1))
    offset = observed - float(np.mean(null))
    explained = abs(offset) * float(np.sqrt(np.mean(gm * gm)))
    material = MATERIAL_OFFSET <= abs(offset) <= LINEAR_LIMIT
    return SignalOffset(name, offset, spread, p, bool(timed and p < FALSE_ALARM and material),
                        int(np.sum(mine)), explained, timed)
