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
"""

from __future__ import annotations

import numpy as np


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


def residual_scale(times: np.ndarray, values: np.ndarray, nominal: float, increment: bool) -> float:
    """The scale (1 sigma, the column's units) a residual of this column is divided by: the noise
    of the compared quantity estimated from the column (an increment over a lag is the
    difference of two samples, sqrt(2) times a sample's noise), and never below ``nominal``.

    Why a floor: the nominal scales are what the replay can follow (a quieter sensor than the
    paper's does not make the model's path more exact), so a signal's weight in a fit never
    grows beyond the one it has at the paper's instruments; a noisier sensor weighs its signal
    down as its noise does, and the fit's uncertainty says so."""
    noise = column_noise(times, values)
    if increment:
        noise *= np.sqrt(2.0)
    return float(max(nominal, noise)) if np.isfinite(noise) else float(nominal)
