"""A measured column's sensor noise, estimated from the column itself.

No noise level is assumed: a user's instruments are not the paper's.  The estimate is the
median absolute second difference of the samples over 0.6745 sqrt(6): white noise's second
differences have variance 6 sigma^2, a signal that is smooth at the sample rate adds little to
them, and the median ignores the few steps and glitches.  A quantised column (an encoder's counts
over a read interval, at a steady spin) steps between two neighbouring levels, and more than
half of its second differences are exactly zero: the median then reads it as noiseless.  Its
rounding error is at least uniform over one level, so the estimate of a quantised column is
never below its step over sqrt(12). A column is quantised when every change from one sample to
the next is a whole multiple of the smallest such change (the step); a column read to many
digits has a step far below its noise, and a column that moves (a position along the track)
changes by no common step at all: the bound leaves both as they are.
Assumptions: the noise is white at the sample rate and its level does not change much within a
run (a noise that grows with the signal, as a motor current's does, is estimated at its typical
level).

A column read through a filter (a motor current low-passed in its electronics) breaks the first
assumption: its second differences see only what the filter lets through, and its noise is
estimated at a fraction of the noise its slow variations carry.  The campaign's manifest may
therefore state a column's noise (``sensor_noise``, juno.campaign): :func:`sensor_noise` is the
stated value where there is one, and the estimate elsewhere; :func:`noise_statements` says which
is which for every run, and :func:`far_from_estimate` when a stated value and the estimate
disagree by more than FAR_FACTOR, which the commands report.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Optional, Sequence

import numpy as np

#: A stated noise and the estimate disagree when one is more than this many times the other: a
#: first-order low-pass of 0.15 s on a motor current sampled at 20-50 Hz puts the estimate at a
#: fifth to a thirteenth of the unfiltered noise, while white noise's estimate is within a few per
#: cent of its truth.
FAR_FACTOR = 3.0


def column_noise(times: np.ndarray, values: np.ndarray) -> float:
    """Sensor noise (1 sigma, the column's units) of one measured column sampled at ``times``
    (s, any order); NaN with fewer than 5 finite samples."""
    order = np.argsort(times)
    v = np.asarray(values, float)[order]
    v = v[np.isfinite(v)]
    if len(v) < 5:
        return float("nan")
    d2 = np.diff(v, 2)
    robust = float(np.median(np.abs(d2 - np.median(d2))) / 0.6745 / np.sqrt(6.0))
    return max(robust, quantisation_step(v) / np.sqrt(12.0))


def quantisation_step(values: np.ndarray) -> float:
    """The step of a quantised column (module docstring): the smallest change from one sample to
    the next when every change is a whole multiple of it (to rounding), else 0."""
    changes = np.abs(np.diff(np.asarray(values, float)))
    changes = changes[changes > 0]
    if changes.size == 0:
        return 0.0
    step = float(changes.min())
    multiples = changes / step
    return step if bool(np.all(np.abs(multiples - np.round(multiples)) < 1e-6)) else 0.0


def sensor_noise(data: Any, column: str) -> float:
    """The sensor noise (1 sigma, the column's units) of ``column`` of the run ``data``
    (juno.campaign.RunData): the value the campaign's manifest states for it (its
    ``stated_noise``), else :func:`column_noise` of its samples."""
    stated = getattr(data, "stated_noise", {}).get(column)
    return float(stated) if stated is not None else column_noise(*data.samples(column))


def residual_scale(times: np.ndarray, values: np.ndarray, nominal: float, increment: bool,
                   stated: Optional[float] = None) -> float:
    """The scale (1 sigma, the column's units) a residual of this column is divided by: the noise
    of the compared quantity, ``stated`` in the manifest or else estimated from the column (an
    increment over a lag is the difference of two samples, sqrt(2) times a sample's noise), and
    never below ``nominal``.

    Why a floor: the nominal scales are what the replay can follow (a quieter sensor than the
    paper's does not make the model's path more exact), so a signal's weight in a fit never
    grows beyond the one it has at the paper's instruments; a noisier sensor weighs its signal
    down as its noise does, and the fit's uncertainty says so."""
    noise = float(stated) if stated is not None else column_noise(times, values)
    if increment:
        noise *= np.sqrt(2.0)
    return float(max(nominal, noise)) if np.isfinite(noise) else float(nominal)


#: What a stated noise far from the estimate suggests: below, the estimate is under 1/FAR_FACTOR of
#: the stated value; above, over FAR_FACTOR times it.
_FAR = {"below": "the column is filtered (its noise is not white at the sample rate) or the statement is wrong",
        "above": "the sensor is noisier than stated, the column varies fast (a ripple, a vibration) or the "
                 "statement is wrong"}


def _far(stated: float, estimated: float) -> Optional[str]:
    """"below" or "above" where the estimate is FAR_FACTOR from the stated value, else None (also
    when the column is too short to estimate)."""
    if not np.isfinite(estimated) or estimated <= 0:
        return None
    if estimated * FAR_FACTOR < stated:
        return "below"
    return "above" if estimated > FAR_FACTOR * stated else None


def _far_sentence(side: str, estimated: str, stated: str) -> str:
    where = f"under 1/{FAR_FACTOR:g} of" if side == "below" else f"over {FAR_FACTOR:g} times"
    return (f"the noise estimated from its samples ({estimated}) is {where} the stated {stated}: {_FAR[side]}; "
            "the stated value is used")


def far_from_estimate(stated: float, estimated: float, unit: str = "") -> Optional[str]:
    """What a stated noise that the estimate from the column's samples is far from (FAR_FACTOR)
    suggests, or None when they agree (or the column is too short to estimate); ``unit``: the
    column's, for the sentence."""
    side = _far(stated, estimated)
    unit = f" {unit}" if unit else ""
    return None if side is None else _far_sentence(side, f"{estimated:.3g}{unit}", f"{stated:.4g}{unit}")


@dataclass(frozen=True)
class NoiseStatement:
    """The sensor noise of one measured ``column`` of run ``run``: the value used (``noise``, 1
    sigma, the column's units), where it comes from (``source``: "stated" in the manifest or
    "estimated" from the samples), the estimate from the samples (NaN with too few), the stated
    value (None when none is stated) and, when the two are far apart, what that suggests."""

    run: str
    column: str
    noise: float
    source: str
    estimated: float
    stated: Optional[float]
    warning: Optional[str]

    def to_json(self) -> dict[str, Any]:
        return {"run": self.run, "column": self.column, "noise": _plain(self.noise), "source": self.source,
                "estimated": _plain(self.estimated), "stated": self.stated, "warning": self.warning}


def _plain(x: float) -> Optional[float]:
    return float(x) if np.isfinite(x) else None


def noise_statements(campaign: Any, kinds: Optional[Sequence[str]] = None) -> list[NoiseStatement]:
    """The sensor noise of every measured column of the campaign's runs of ``kinds`` (None:
    drawbar and terrain; (): none), in run and column order (juno.campaign.NOISE_COLUMNS).  Reads
    the runs (juno.campaign.read_run keeps them for the analysis that follows)."""
    from .campaign import NOISE_COLUMNS, read_run
    out = []
    for spec in campaign.runs:
        if spec.kind not in (("drawbar", "terrain") if kinds is None else kinds):
            continue
        data = read_run(campaign, spec)
        for column in NOISE_COLUMNS:
            if not data.has(column):
                continue
            estimated = column_noise(*data.samples(column))
            stated = data.stated_noise.get(column)
            if stated is None:
                out.append(NoiseStatement(spec.id, column, estimated, "estimated", estimated, None, None))
            else:
                out.append(NoiseStatement(spec.id, column, float(stated), "stated", estimated, float(stated),
                                          far_from_estimate(float(stated), estimated)))
    return out


def stated_noise_lines(statements: Sequence[NoiseStatement]) -> list[str]:
    """The text report of ``statements``: one line naming each column whose noise the manifest
    states, with its value and the estimate from the samples of each run, and a warning for each
    column whose stated values are far from their estimates (far_from_estimate; one line for the
    runs alike); [] when none is stated (every noise is then estimated from the samples)."""
    stated = [s for s in statements if s.source == "stated"]
    if not stated:
        return []
    by_column: dict[str, list[NoiseStatement]] = {}
    for s in stated:
        by_column.setdefault(s.column, []).append(s)
    parts, warnings = [], []
    for column, group in by_column.items():
        values = {s.noise for s in group}
        if len(values) == 1:
            estimates = ", ".join(f"{s.estimated:.3g}" for s in group)
            parts.append(f"{column} {group[0].noise:.4g} in {_runs(group)} (estimated {estimates})")
        else:
            parts.append(f"{column} " + ", ".join(f"{s.run} {s.noise:.4g} (estimated {s.estimated:.3g})" for s in group))
        for side in ("below", "above"):
            far = [s for s in group if _far(s.noise, s.estimated) == side]
            if far:
                sentence = _far_sentence(side, _span([s.estimated for s in far], ".3g"),
                                         _span([s.noise for s in far], ".4g"))
                warnings.append(f"warning: column '{column}' of {_runs(far)}: {sentence}")
    return (["sensor noise stated in the manifest: " + "; ".join(parts)
             + "; every other column's is estimated from its samples"] + warnings)


def _runs(statements: Sequence[NoiseStatement]) -> str:
    return f"run{'s' if len(statements) > 1 else ''} " + ", ".join(s.run for s in statements)


def _span(values: Sequence[float], spec: str) -> str:
    low, high = min(values), max(values)
    return f"{low:{spec}}" if f"{low:{spec}}" == f"{high:{spec}}" else f"{low:{spec}}-{high:{spec}}"
