"""Single absurd samples, column by column.

* **Single absurd samples** (any known column): each sample is compared with the median of the
  five samples around it (its column's own samples; a step or a monotone transient has no
  residual, a lone spike has). The noise's standard deviation is estimated robustly from the
  second differences, which cancel a linear trend: for white Gaussian noise of deviation s they
  have deviation s * sqrt(6), and 1.4826 * MAD is the standard deviation of Gaussian data, so
  ``s = 1.4826 * MAD(d2) / sqrt(6)`` (exact zeros left out: they are held samples, not noise).
  The residual from the median of five then has the tails of a Gaussian of deviation
  ``RESIDUAL_TAIL * s`` (1.14: the other four samples' median has a variance of 0.3 s^2;
  measured 1.09 over 2 million samples). A sample is an outlier when its residual exceeds both
  ``k * RESIDUAL_TAIL * s`` and a quarter of the column's robust span (the range of the
  running median of five, which no lone spike reaches). ``k`` is chosen so that Gaussian noise
  over the column's n samples raises a false alarm with probability ``FALSE_ALARM``:
  ``k = Phi^-1(1 - FALSE_ALARM / (2 n))``, with Student's t in place of Phi at the MAD's
  0.37 n degrees of freedom because s is itself estimated (5.5 for 2000 samples, 9.4 for the
  28 samples of a 5 Hz column over 5.5 s). The span term keeps noise-free data (MAD = 0) from
  flagging its own curvature.
* **Motion, not a glitch.** The median of five passes steps and monotone stretches, but clips the
  extremum of a swing a few samples wide (a 25 Hz pitch through a start's rocking), which is
  motion. A sample the median flags is an outlier only if it also lies beyond the same limit
  from the quadratic fitted by least squares to its neighbours within ``NEIGHBOURS`` samples on
  each side, leaving out itself and every other flagged sample, and then also each adjacent
  sample in turn (so a glitch two samples long, its partner flagged or not, does not pull the
  curve it is judged by): off any of these curves. The quadratic's prediction has its own
  variance, ``v s^2`` (v from the fit's design), so the limit there is ``k sqrt(1 + v) s``. A
  lone spike or pair lies off both; a swing that a quadratic through its neighbours follows is
  not an outlier. With fewer than ``NEIGHBOURS + 1`` clean neighbours (the ends of a column, a
  burst of glitches) the median's verdict stands.

* **Angles that wrap.** An instrument that reports an angle within one turn (a heading in
  (-pi, pi]) jumps by 2 pi where the angle passes the wrap; the samples on either side are the same
  direction, not outliers. An angle column (``roll``, ``pitch``, ``yaw``) whose samples all lie
  within one turn is tested as the continuous angle (``np.unwrap``), so a glitch is judged by how
  far it turns from its neighbours the short way round, at the wrap as anywhere else.

An outlier is an error when its residual exceeds ten times the column's span (nothing the run
measured), else a warning.
"""

from __future__ import annotations

import math
from statistics import NormalDist
from typing import Iterable, Optional

import numpy as np

from ..campaign import ANGLE_COLUMNS, RunData
from .findings import FloatArray, Finding, _at, _g, _own
from .limits import RoverLimits

#: Probability that Gaussian noise over one column raises an outlier finding.
FALSE_ALARM = 1e-4
#: Gaussian efficiency of the MAD as a scale estimate (degrees of freedom per sample).
MAD_EFFICIENCY = 0.37
#: Tail deviation of a white Gaussian sample's residual from its median of five, per unit noise.
RESIDUAL_TAIL = math.sqrt(1.3)
#: An outlier's residual must also exceed this fraction of the column's robust span.
SPAN_FRACTION = 0.25
#: ... and is an error beyond this multiple of the span.
ABSURD_SPAN = 10.0
#: Neighbours on each side of a flagged sample whose quadratic must also miss it.
NEIGHBOURS = 3


def outlier_threshold_k(n: int, false_alarm: float = FALSE_ALARM, scale_samples: Optional[int] = None) -> float:
    """k such that n Gaussian samples exceed k sigma (two-sided) with probability ~false_alarm.

    With ``scale_samples``, sigma is itself estimated from that many samples by a MAD: k is then
    Student's t quantile with ``MAD_EFFICIENCY * scale_samples`` degrees of freedom (the MAD's
    Gaussian efficiency is 37 %), so that a scale estimated from a few samples (a 5 Hz column of
    a short run) does not raise false alarms when it comes out low.
    """
    p = 1.0 - false_alarm / (2.0 * max(n, 1))
    if scale_samples is None:
        return float(NormalDist().inv_cdf(p))
    from scipy.stats import t as student

    return float(student.ppf(p, max(MAD_EFFICIENCY * scale_samples, 1.0)))


def _median_of_five(v: FloatArray) -> FloatArray:
    """Running median over 5 samples; the ends padded by odd reflection (a trend continues)."""
    if len(v) < 5:
        return np.full(len(v), np.median(v))
    with np.errstate(over="ignore", invalid="ignore"):
        pad = np.concatenate([2 * v[0] - v[2:0:-1], v, 2 * v[-1] - v[-2:-4:-1]])
    windows = np.lib.stride_tricks.sliding_window_view(pad, 5)
    return np.median(windows, axis=1)


def _off_the_motion(ts: FloatArray, vs: FloatArray, flagged: FloatArray, k: float, sigma: float,
                    floor: float) -> FloatArray:
    """Of the samples the median of five flags (indices ``flagged``), those that also lie beyond
    ``max(k sqrt(1 + v) sigma, floor)`` from the quadratic in time fitted to their clean
    neighbours (module docstring: "Motion, not a glitch"); ``sigma``: the noise's standard
    deviation."""
    out = []
    skip = set(int(i) for i in flagged)
    for i in flagged:
        i = int(i)
        window = [j for j in range(max(i - NEIGHBOURS, 0), min(i + NEIGHBOURS + 1, len(vs))) if j not in skip]
        if len(window) < NEIGHBOURS + 1:
            out.append(i)
            continue
        # The glitch's partner, when the median did not flag it, may be either adjacent sample:
        # the sample is judged against the neighbours with each left out in turn, and is off the
        # motion if it is off any of these curves.
        for partner in (None, i - 1, i + 1):
            near = [j for j in window if j != partner]
            if len(near) < NEIGHBOURS + 1:
                continue
            if _off_the_quadratic(ts, vs, i, near, k, sigma, floor):
                out.append(i)
                break
    return np.array(out, dtype=int)


def _off_the_quadratic(ts: FloatArray, vs: FloatArray, i: int, near: list[int], k: float, sigma: float,
                       floor: float) -> bool:
    """Whether sample ``i`` lies beyond ``max(k sqrt(1 + v) sigma, floor)`` from the least-squares
    quadratic in time through the samples ``near`` (v: the variance of its prediction at sample
    ``i``, per sigma^2); a fit that cannot be made leaves the sample flagged."""
    dt = ts[near] - ts[i]
    scale = float(np.max(np.abs(dt))) or 1.0
    x = np.column_stack([np.ones(len(near)), dt / scale, (dt / scale) ** 2])
    with np.errstate(all="ignore"):
        coef, *_ = np.linalg.lstsq(x, vs[near], rcond=None)
        variance = float(np.linalg.pinv(x.T @ x)[0, 0])
    if not (np.isfinite(coef[0]) and np.isfinite(variance)):
        return True
    return bool(abs(vs[i] - coef[0]) > max(k * math.sqrt(1.0 + variance) * sigma, floor))


def _continuous(name: str, vs: FloatArray) -> tuple[FloatArray, bool]:
    """The samples of column ``name`` as tested (module docstring, "Angles that wrap"): an angle
    column whose finite samples all lie within one turn made continuous, and True; any other
    column as it is, and False."""
    if name not in ANGLE_COLUMNS or vs.size < 2 or not np.all(np.isfinite(vs)):
        return vs, False
    if float(np.max(vs) - np.min(vs)) > 2.0 * math.pi * (1.0 + 1e-9):
        return vs, False
    unwrapped = np.unwrap(vs)
    return unwrapped, bool(np.any(unwrapped != vs))


def check_outliers(run: RunData, file: str, columns: Iterable[str], limits: RoverLimits) -> list[Finding]:
    """Single absurd samples, column by column (robust test of the module docstring).

    A position sample must also lie farther from the median of the five around it than the
    rover travels at its top speed over two sample periods: closer, it may be where the rover
    was (noise-free positions bounce by a centimetre at 5 Hz as the chassis settles).
    """
    out = []
    for name in columns:
        if not run.has(name):
            continue
        ts, measured, lines = _own(run, name)
        if len(measured) < 5:
            continue
        vs, unwrapped = _continuous(name, measured)
        with np.errstate(over="ignore", invalid="ignore"):
            smooth = _median_of_five(vs)
            r = vs - smooth
            r = np.where(np.isfinite(r), r, np.sign(vs) * np.inf)
            lo, hi = float(np.min(smooth)), float(np.max(smooth))
            span = hi - lo if np.isfinite(hi - lo) else np.inf
            d2 = vs[2:] - 2.0 * vs[1:-1] + vs[:-2]
            d2 = d2[d2 != 0]  # exact zeros are held samples (a frozen stretch), not noise
            if d2.size == 0:
                d2 = np.zeros(1)
            scale = RESIDUAL_TAIL * 1.4826 * float(np.median(np.abs(d2))) / math.sqrt(6.0)
        k = outlier_threshold_k(len(vs), scale_samples=len(d2))
        floor = SPAN_FRACTION * span
        if name.startswith("pos_"):
            floor = max(floor, 2.0 * limits.top_speed * float(np.median(np.diff(ts))))
        limit = max(k * scale, floor)
        bad = np.flatnonzero(np.abs(r) > limit)
        if bad.size == 0:
            continue
        bad = _off_the_motion(ts, vs, bad, k, scale / RESIDUAL_TAIL, floor)
        if bad.size == 0:
            continue
        worst = int(bad[np.argmax(np.abs(r[bad]))])
        absurd = bool(np.abs(r[worst]) > ABSURD_SPAN * max(span, scale))
        listed = ", ".join(_at(ts, measured, lines, int(i)) for i in bad[:3])
        if bad.size > 3:
            listed += f" and {bad.size - 3} more"
        what = f"{bad.size} samples far from their" if bad.size > 1 else "1 sample far from its"
        out.append(Finding("error" if absurd else "warning", file, name,
                           f"{what} neighbours: {listed} (the column's other samples span {_g(lo)} to {_g(hi)}"
                           f"{' as a continuous angle' if unwrapped else ''}; "
                           f"a sample more than {_g(limit)} from the median of the five around it is an outlier)"))
    return out
