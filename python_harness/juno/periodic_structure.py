"""Residual structure periodic in the wheel angle: a ripple at N per wheel revolution.

A lugged wheel makes the traction, and the drive torque it takes, ripple at the lug-passing
frequency N omega / (2 pi), a few Hz at drawbar spins.  The block means residual_structure tests
average such a ripple away.  This test looks for it in the held-out residual *samples* of the
drive torques: a component a cos(N theta) + b sin(N theta) in the wheel angle theta, for every
whole N in N_RANGE.

Method (docs/diagnosis.md, "What no candidate explains"):

1. **The wheel angle.** Each side's measured spin (``omega_left``, ``omega_right``) integrated
   over the run from its first sample (trapezoids).  Encoder spin noise of sigma_w rad/s, white
   at the sample interval dt, makes the angle a random walk of sigma_w sqrt(T dt) after T s: at
   0.01 rad/s, 50 Hz and 60 s, 0.011 rad, which at N = 18 is a phase error of 0.2 rad (the
   ripple keeps 98 % of its amplitude); at 20 Hz, 0.3 rad.  The angle stays coherent over a
   run, so each run is fitted coherently; runs are combined incoherently (their lug phases
   relative to the measured angle need not agree).
2. **Slow structure removed.** Within every held-out block, the residual and the two angle
   regressors lose their mean and their slope in time: slow model error (drift, a random walk,
   the block means the other test sees) does not leak into the ripple's fit.
3. **The ordinate.** For angle frequency nu (per radian; whole nu = N per revolution), SS(nu) is
   the sum of squares least squares on the two regressors explains.  Residuals white at sigma^2
   give SS / sigma^2 ~ chi-square(2).
4. **The noise level from the neighbourhood** (constant false-alarm rate, as a radar's CFAR):
   sigma^2 at nu = N is the mean of SS / 2 over REFERENCE_CELLS angle frequencies on each side,
   spaced by the run's resolution 2 pi / (angle turned in the run) beyond GUARD_CELLS of it.  A
   residual whose spectrum is not flat (coloured, falling with frequency as drift and random
   walks do) is judged against its own level there; a convex spectrum makes the symmetric
   neighbours' mean larger than the level at nu, so the test errs on the safe side.  The
   reference is a quadratic form in the residuals whose effective degrees of freedom
   tr(Q)^2 / tr(Q^2) are computed exactly for the run's samples, so the ratio
   q = (SS(N) / 2) / reference is taken as F(2, dof).
5. **The test.** Per signal and N, Z = sum over runs of 2 q, against a scaled chi-square with
   the mean and variance of the sum of the runs' 2 F(2, dof) (Satterthwaite).  The strongest N
   is reported; its p-value over the scan is Sidak's 1 - (1 - p_min)^(number of N tested), and
   the signal has a ripple when that p is below FALSE_ALARM / (number of signals tested): at
   most FALSE_ALARM false reports per campaign over the N's and signals.  A ripple must also
   be material: its amplitude (the runs' sample-weighted RMS of sqrt(a^2 + b^2)) at least
   MATERIAL_FRACTION of the signal's sensor noise sigma.
6. **Locked to the wheel angle, not to the clock.**  Within one run at a steady spin omega, a
   ripple at N per revolution is also an oscillation at the fixed frequency N omega / (2 pi):
   a rover ringing at 3 Hz near a stall, at 0.49 rad/s, scans as N = 39.  Lugs make the same N
   in every run, whatever its spin.  So the evidence at the strongest N must not rest on one
   run: with that run left out, the other runs at the same N (no scan: one test) must give a p
   below the same level.  The rule only removes findings, so the false-alarm rate above still
   bounds it; with a single run a ripple is never reported (nothing tells it from an
   oscillation), and with every run at one spin the rule cannot tell the two apart either.

N_RANGE is 4..48 lugs per revolution: fewer than four is not a lugged tyre, and at the
slowest drawbar spins (0.5 rad/s) N = 4 ripples at 0.3 Hz, one cycle per 4 s block, which the
per-block detrending would take; 48 lugs on the Juno's 0.28 m wheel is a 3.7 cm pitch, a tread
rather than lugs.  An N whose frequency at the run's fastest spin (95th percentile) exceeds
NYQUIST_FRACTION of the Nyquist frequency of the signal's samples is not tested in that run
(aliased: 20 Hz torques resolve N = 18 up to 2.8 rad/s).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

from .sensor_noise import sensor_noise

#: At most this many false ripple reports per campaign (Sidak over the N's, Bonferroni over signals).
FALSE_ALARM = 0.01
#: Whole lug counts tested (see the module docstring).
N_RANGE = (4, 48)
#: A ripple smaller than this fraction of the signal's sensor noise (amplitude over the per-sample
#: sigma) is not reported.  Calibrated by simulation (scripts/periodic_calibration.py, true soil,
#: four campaigns of each design): on campaigns with nothing hidden the strongest N's amplitude
#: is what noise alone fits, 0.10-0.14 sigma with the default design's 50 Hz torques and up to
#: 0.28 sigma with the alt design's 20 Hz ones (fewer samples), never significant; the lug_ripple
#: form left by the catalog grouser is 1.3-2.5 sigma at strength 1 and 0.45-0.86 sigma at 0.3.
#: The floor lies above the first and below the last.
MATERIAL_FRACTION = 0.35
#: Reference angle frequencies on each side of the tested one, and the resolution cells left out
#: between them (the tested ripple's main lobe).
REFERENCE_CELLS = 6
GUARD_CELLS = 2
#: A run's reference needs at least this many effective degrees of freedom to be used.
MIN_DOF = 8.0
#: Highest tested frequency, as a fraction of the samples' Nyquist frequency.
NYQUIST_FRACTION = 0.8


def wheel_angle(spin_times: np.ndarray, spin: np.ndarray, at: np.ndarray) -> np.ndarray:
    """The wheel angle (rad) at the times ``at`` (s): the measured spin (rad/s, sampled at
    ``spin_times``, s) integrated by trapezoids from its first sample, non-finite samples left out."""
    t = np.asarray(spin_times, float)
    w = np.asarray(spin, float)
    ok = np.isfinite(t) & np.isfinite(w)
    t, w = t[ok], w[ok]
    order = np.argsort(t)
    t, w = t[order], w[order]
    if len(t) < 2:
        raise ValueError("a wheel angle needs at least two finite spin samples")
    angle = np.concatenate([[0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) * np.diff(t))])
    return np.interp(np.asarray(at, float), t, angle)


@dataclass
class PeriodicSeries:
    """One compared signal of one run: its held-out residual samples (signal units, at ``time``,
    s, grouped in ``block``s), the side's wheel angle there (rad), the signal's sensor noise
    (1 sigma, signal units) and the sample interval (s)."""

    run: str
    signal: str
    time: np.ndarray
    residual: np.ndarray
    block: np.ndarray
    angle: np.ndarray
    noise: float
    sample_interval: float
    fastest_spin: float       # rad/s, the run's 95th percentile of the side's spin


@dataclass
class PeriodicSignal:
    """The scan of one signal over its runs: the strongest N, its ripple's amplitude (signal
    units, the runs' sample-weighted RMS), its ratio to the sensor noise, its p-value over the
    scan, and whether it is reported (``significant``)."""

    signal: str
    unit: str
    lugs: int
    amplitude: float
    noise: float
    ratio: float
    p_value: float
    significant: bool
    tested: tuple[int, int]   # the lowest and highest N tested in some run
    runs: list[str]
    #: the p-value at the same N of the runs other than the strongest (module docstring, step 6);
    #: 1 when no other run tests that N
    other_runs_p: float = 1.0

    def to_json(self) -> dict[str, Any]:
        return {"signal": self.signal, "unit": self.unit, "per_revolution": self.lugs,
                "amplitude": self.amplitude, "noise": self.noise, "ratio_to_noise": self.ratio,
                "p_value": self.p_value, "significant": self.significant,
                "tested_per_revolution": list(self.tested), "runs": self.runs, "other_runs_p": self.other_runs_p}

    def sentence(self) -> str:
        """The finding in words."""
        return (f"{self.signal} follows the wheel angle at {self.lugs} per revolution (lug passing?), "
                f"amplitude {self.amplitude:.3g} {self.unit} ({self.ratio:.2g} x its sensor noise)")

    def brief(self) -> str:
        """The finding in a few words (a progress line)."""
        return f"{self.signal} ripple at {self.lugs} per wheel revolution ({self.ratio:.2g} x noise)"


@dataclass
class PeriodicStructure:
    """The periodic test of every tested signal; ``significant`` if any has a ripple."""

    signals: list[PeriodicSignal]
    level: float                  # the per-signal p threshold (FALSE_ALARM / signals)

    @property
    def significant(self) -> bool:
        return any(s.significant for s in self.signals)

    def found(self) -> list[PeriodicSignal]:
        """The signals with a ripple, largest (relative to their noise) first."""
        return sorted((s for s in self.signals if s.significant), key=lambda s: -s.ratio)

    @property
    def excess(self) -> float:
        """Sum over the signals with a ripple of (ripple RMS / noise)^2 (RMS = amplitude / sqrt 2)."""
        return float(sum(0.5 * s.ratio ** 2 for s in self.signals if s.significant))

    def to_json(self) -> dict[str, Any]:
        return {"significant": self.significant, "false_alarm": FALSE_ALARM, "level": self.level,
                "material_fraction": MATERIAL_FRACTION, "per_revolution_range": list(N_RANGE),
                "signals": [s.to_json() for s in self.signals]}


def _detrend_matrix(x: np.ndarray, time: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """``x`` (samples x columns) less, within each block (contiguous rows from ``starts``), its
    least squares mean and slope in ``time``."""
    counts = np.diff(np.append(starts, len(time)))
    t_mean = np.add.reduceat(time, starts) / counts
    tc = time - np.repeat(t_mean, counts)
    tt = np.add.reduceat(tc * tc, starts)
    x_mean = np.add.reduceat(x, starts, axis=0) / counts[:, None]
    slope = np.add.reduceat(tc[:, None] * x, starts, axis=0) / np.maximum(tt, 1e-300)[:, None]
    return x - np.repeat(x_mean, counts, axis=0) - tc[:, None] * np.repeat(slope, counts, axis=0)


def _bases(angle: np.ndarray, time: np.ndarray, starts: np.ndarray, nus: np.ndarray) -> np.ndarray:
    """Per angle frequency, an orthonormal basis (samples x 2) of its detrended cos and sin
    regressors: shape (frequencies, samples, 2)."""
    phase = angle[:, None] * nus[None, :]
    x = np.concatenate([np.cos(phase), np.sin(phase)], axis=1)
    x = _detrend_matrix(x, time, starts)
    f = len(nus)
    stacked = np.stack([x[:, :f].T, x[:, f:].T], axis=2)      # (f, n, 2)
    q, _r = np.linalg.qr(stacked)
    return q


@dataclass
class _SeriesBases:
    """What the scan of one series computes from its samples' times, blocks and wheel angles
    alone, whatever the residual: the sample order by time, the blocks' first rows (``starts``),
    the tested N's with their count of frequencies (the tested one, then its references) and
    their references' degrees of freedom, the orthonormal bases of every frequency (_bases), and
    each N's detrended regressors (made when first asked for)."""

    order: np.ndarray
    time: np.ndarray
    angle: np.ndarray
    starts: np.ndarray
    plan: list[tuple[int, int, float]]        # (N, frequencies, reference dof)
    q: np.ndarray
    _regressors: dict[int, np.ndarray]

    def regressors(self, n: int) -> np.ndarray:
        """cos(N theta) and sin(N theta), detrended within each block (samples x 2)."""
        if n not in self._regressors:
            self._regressors[n] = _detrend_matrix(np.column_stack([np.cos(n * self.angle), np.sin(n * self.angle)]),
                                                  self.time, self.starts)
        return self._regressors[n]


def _series_bases(s: PeriodicSeries, lugs: np.ndarray) -> _SeriesBases | None:
    """The residual-independent part of the scan of ``s`` over the N's ``lugs``; None when the
    run cannot test any N (too few samples, no angle turned, every N aliased or short of
    references)."""
    order = np.argsort(s.time)
    time, block, angle = s.time[order], s.block[order], s.angle[order]
    starts = np.flatnonzero(np.r_[True, block[1:] != block[:-1]])
    if len(time) < 20:
        return None
    turned = float(np.ptp(angle))
    if turned <= 0:
        return None
    cell = 2.0 * np.pi / turned
    nyquist = 0.5 / s.sample_interval
    offsets = cell * np.arange(GUARD_CELLS + 1, GUARD_CELLS + REFERENCE_CELLS + 1)
    # Per N, the tested frequency and its references, in pairs symmetric about it (a spectrum
    # that falls with frequency then raises the reference, never lowers it); a pair whose lower
    # member falls below half of N or 1.5 per revolution, where the detrending takes the power,
    # is left out.
    plan = []
    for n in lugs:
        if n * s.fastest_spin / (2.0 * np.pi) > NYQUIST_FRACTION * nyquist:
            continue
        kept = offsets[n - offsets >= max(1.5, 0.5 * n)]
        if len(kept) >= 2:
            plan.append((int(n), np.concatenate([[float(n)], n - kept, n + kept])))
    if not plan:
        return None
    q = _bases(angle, time, starts, np.concatenate([nus for _n, nus in plan]))
    counted = []
    first = 0
    for n, nus in plan:
        qn = q[first:first + len(nus)]
        first += len(nus)
        # The reference is r' Q r with Q = mean over the m references of P_j / 2 (P_j the
        # projection on reference j): E = tr(Q) sigma^2 = sigma^2, Var = 2 tr(Q^2) sigma^4, and
        # tr(P_j P_k) = ||U_j' U_k||_F^2 for orthonormal bases U.
        m = len(nus) - 1
        u = qn[1:].transpose(1, 0, 2).reshape(len(time), 2 * m)
        counted.append((n, len(nus), 4.0 * m * m / float(np.sum((u.T @ u) ** 2))))
    return _SeriesBases(order, time, angle, starts, counted, q, {})


class PeriodicBases:
    """The residual-independent part of the scans of series (_SeriesBases), kept for the scans of
    other residuals on the same samples: the periodic test of several models of one campaign
    (the base model's and the one with its named causes) scans the same held-out samples at the
    same wheel angles, and only the residuals differ.  A series is recognised by its contents
    (times, blocks, angles, sample interval, fastest spin) and the N's scanned, so a kept part is
    used only where it would be computed again, the same numbers."""

    def __init__(self) -> None:
        self._kept: dict[tuple, _SeriesBases | None] = {}

    def of(self, s: PeriodicSeries, lugs: np.ndarray) -> _SeriesBases | None:
        """_series_bases of ``s`` over ``lugs``, computed once."""
        key = tuple((a.dtype.str, a.shape, a.tobytes()) for a in (s.time, s.block, s.angle, np.asarray(lugs))) \
            + (float(s.sample_interval), float(s.fastest_spin))
        if key not in self._kept:
            self._kept[key] = _series_bases(s, lugs)
        return self._kept[key]


def _scan_series(s: PeriodicSeries, lugs: np.ndarray, bases: PeriodicBases | None = None
                 ) -> dict[int, tuple[float, float, float]]:
    """Per tested N of one series: (2 q, the reference's degrees of freedom, amplitude in signal
    units).  N's the run cannot test (aliased, or too few reference degrees of freedom) are left
    out.  ``bases``: the residual-independent parts already computed (PeriodicBases)."""
    b = bases.of(s, lugs) if bases is not None else _series_bases(s, lugs)
    if b is None:
        return {}
    r = _detrend_matrix(s.residual[b.order][:, None], b.time, b.starts)[:, 0]
    proj = (b.q[:, :, 0] @ r) ** 2 + (b.q[:, :, 1] @ r) ** 2
    out: dict[int, tuple[float, float, float]] = {}
    first = 0
    for n, count, dof in b.plan:
        pn = proj[first:first + count]
        first += count
        reference = float(np.mean(pn[1:])) / 2.0
        if dof < MIN_DOF or reference <= 0:
            continue
        # The ripple's amplitude: the least squares coefficients of cos(N theta) and sin(N theta).
        coef, *_ = np.linalg.lstsq(b.regressors(n), r, rcond=None)
        out[n] = (float(pn[0]) / reference, dof, float(np.hypot(*coef)))
    return out


def _sum_of_f_sf(z: float, dofs: Sequence[float]) -> float:
    """P(sum of 2 F(2, d) over ``dofs`` > z), by a scaled chi-square with the sum's mean and
    variance (Satterthwaite)."""
    from scipy.stats import chi2
    d = np.asarray(dofs, float)
    mean = float(np.sum(2.0 * d / (d - 2.0)))
    var = float(np.sum(4.0 * d ** 3 / ((d - 2.0) ** 2 * (d - 4.0))))
    c = var / (2.0 * mean)
    k = 2.0 * mean * mean / var
    return float(chi2.sf(z / c, k))


def periodic_signal(series: Sequence[PeriodicSeries], unit: str, n_signals: int,
                    lugs: tuple[int, int] = N_RANGE, bases: PeriodicBases | None = None) -> PeriodicSignal | None:
    """The scan (module docstring) of one signal over its runs' ``series``; None when no run can
    test any N.  ``n_signals``: how many signals the campaign tests (the Bonferroni factor).
    ``bases``: the residual-independent parts of scans made before (PeriodicBases), kept."""
    grid = np.arange(lugs[0], lugs[1] + 1)
    scans = [_scan_series(s, grid, bases) for s in series]
    tested = sorted({n for scan in scans for n in scan})
    if not tested:
        return None
    p_of: dict[int, float] = {}
    for n in tested:
        parts = [scan[n] for scan in scans if n in scan]
        p_of[n] = _sum_of_f_sf(sum(z for z, _d, _a in parts), [d for _z, d, _a in parts])
    best = min(tested, key=lambda n: (p_of[n], n))
    p = float(-np.expm1(len(tested) * np.log1p(-min(p_of[best], 1.0 - 1e-16))))
    weights = [len(s.residual) for s, scan in zip(series, scans) if best in scan]
    amps = [scan[best][2] for scan in scans if best in scan]
    amplitude = float(np.sqrt(np.average(np.square(amps), weights=weights)))
    noise = float(np.median([s.noise for s in series]))
    ratio = amplitude / noise if noise > 0 else float("inf")
    level = FALSE_ALARM / max(n_signals, 1)
    at_best = [scan[best] for scan in scans if best in scan]
    strongest = max(range(len(at_best)), key=lambda i: at_best[i][0])
    others = [part for i, part in enumerate(at_best) if i != strongest]
    other_runs_p = _sum_of_f_sf(sum(z for z, _d, _a in others), [d for _z, d, _a in others]) if others else 1.0
    return PeriodicSignal(series[0].signal, unit, int(best), amplitude, noise, ratio, p,
                          bool(p < level and ratio >= MATERIAL_FRACTION and other_runs_p < level),
                          (tested[0], tested[-1]), sorted({s.run for s, scan in zip(series, scans) if scan}),
                          other_runs_p)


def periodic_structure(series: Sequence[PeriodicSeries], units: dict[str, str] | None = None,
                       lugs: tuple[int, int] = N_RANGE, bases: PeriodicBases | None = None) -> PeriodicStructure:
    """The periodic test of every signal in ``series`` (grouped by signal; ``units``: signal ->
    unit), at most FALSE_ALARM false reports over all of them.  ``bases``: where the scans'
    residual-independent parts are kept for the tests of other models on the same samples
    (PeriodicBases); each test computes its own without."""
    names = sorted({s.signal for s in series})
    found = [periodic_signal([s for s in series if s.signal == name], (units or {}).get(name, ""), len(names), lugs,
                             bases)
             for name in names]
    return PeriodicStructure([f for f in found if f is not None], FALSE_ALARM / max(len(names), 1))


#: The compared signals tested, and the measured spin whose angle each follows.
SPIN_OF = {"torque_left": "omega_left", "torque_right": "omega_right"}


def series_of_residuals(prepared: Sequence[Any], meta: Mapping[str, np.ndarray], train: np.ndarray,
                        residuals: np.ndarray, data: Mapping[str, Any],
                        noise: Mapping[tuple[str, str], float] | None = None) -> list[PeriodicSeries]:
    """The held-out samples of the drive torques of the drawbar runs among ``prepared``
    (identify.PreparedRun; ``residuals`` scaled as identify.run_residuals gives them, labelled by
    ``meta``, training samples ``train``), in N m, with each side's wheel angle from the measured
    run (``data``: run id -> campaign.RunData).  ``noise``: the sensor noise of (run, column)
    when known (juno.sensor_noise.sensor_noise, stated or estimated, otherwise)."""
    out = []
    start = 0
    for p in prepared:
        n_run = sum(len(v[0]) for v in p.targets.values())
        here = slice(start, start + n_run)
        start += n_run
        if p.kind != "drawbar":
            continue
        d = data[p.run_id]
        t0 = d.time[0]
        for column, (ts, _vs, _out, sigma, _lag) in p.targets.items():
            spin = SPIN_OF.get(column)
            if spin is None or not d.has(spin):
                continue
            mine = (meta["run"][here] == p.run_id) & (meta["signal"][here] == column) & ~train[here]
            if np.sum(mine) < 20:
                continue
            tw, w = d.samples(spin)
            t = meta["time"][here][mine]
            known = (noise or {}).get((p.run_id, column))
            sensor = known if known is not None else sensor_noise(d, column)
            out.append(PeriodicSeries(p.run_id, column, t, residuals[here][mine] * sigma, meta["block"][here][mine],
                                      wheel_angle(tw - t0, w, t), float(sensor), float(np.median(np.diff(ts))),
                                      float(np.percentile(w[np.isfinite(w)], 95))))
    return out
