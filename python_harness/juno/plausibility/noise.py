"""A sensor noise the manifest states (``sensor_noise``) against the column it is stated for: a
noise larger than everything the column spans in a run is no sensor's noise but another unit's
(millimetres for metres, degrees for radians, a noise in mN m); a noise far from the one its
samples show is a hint that the column is filtered or the statement wrong (a warning)."""

from __future__ import annotations

from ..campaign import COLUMN_UNITS, RunData
from ..sensor_noise import column_noise, far_from_estimate
from .findings import Finding, _g, _own


def check_stated_noise(run: RunData, file: str) -> list[Finding]:
    """Each stated noise of ``run``'s columns (RunData.stated_noise) that the run has samples of:
    an error when it exceeds the column's range (its largest sample less its smallest), a warning
    when the estimate from the samples is far from it (juno.sensor_noise.far_from_estimate)."""
    found = []
    for column, stated in run.stated_noise.items():
        if not run.has(column):
            continue
        ts, vs, _lines = _own(run, column)
        span = float(vs.max() - vs.min())
        unit = COLUMN_UNITS[column]
        if stated > span:
            found.append(Finding("error", file, column,
                                 f"the manifest states a sensor noise of {_g(stated)} {unit} (1 sigma), more than the "
                                 f"column's whole range in this run ({_g(span)} {unit}, from {_g(vs.min())} to "
                                 f"{_g(vs.max())}): is the noise in another unit (mm, degrees, mN m)?"))
            continue
        far = far_from_estimate(stated, column_noise(ts, vs), unit)
        if far is not None:
            found.append(Finding("warning", file, column, f"sensor noise stated in the manifest: {far}"))
    return found
