"""The single-wheel testbed section of ``juno report``: drawbar pull, torque and sinkage against
slip, measured (with error bars) against each fitted contact law, side by side.

:func:`rig_results` fits the laws and simulates their curves (the FMU work);
:func:`rig_section` draws the figure and writes the Markdown (no FMU).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .campaign import Campaign  # noqa: E402
from .wheel_rig import LAWS, RigFitResult, RigPoints, RigRun, fit_rig, predict, rig_runs  # noqa: E402

#: Points of each fitted curve, evenly spread over the run's measured slips.
CURVE_POINTS = 21
#: The columns drawn, with their axis labels.
PLOTTED = {"drawbar_pull": "drawbar pull [N]", "torque": "torque [N m]", "sinkage": "sinkage [m]"}
LAW_STYLE = {"volumetric": ("C0", "-"), "wong-reece": ("C3", "--")}


@dataclass
class RigCurve:
    """One run's fitted curves: ``slip`` (the grid) and law -> column -> values."""

    run_id: str
    slip: np.ndarray
    values: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)


@dataclass
class RigResults:
    """The rig fits of a campaign (law -> fit), its runs and every run's fitted curves."""

    fits: dict[str, RigFitResult]
    runs: list[RigRun]
    curves: list[RigCurve]


def rig_results(fmu, campaign: Campaign, laws: Sequence[str] = tuple(LAWS),
                progress: Callable[[str], None] | None = None) -> RigResults:
    """Fits each law to the campaign's wheel_rig runs and simulates its curves against slip (at
    each run's load and slip angle, the first point's when they vary)."""
    runs = rig_runs(campaign)
    fits = {law: fit_rig(fmu, campaign, law, runs=runs, progress=progress) for law in laws}
    curves = []
    for run in runs:
        lo, hi = float(run.points.slip.min()), float(run.points.slip.max())
        slip = np.linspace(lo, hi, CURVE_POINTS) if hi > lo else np.array([lo])
        grid = RigRun(run.run_id, run.file, run.setup,
                      RigPoints.of(run.points.load[0], slip, run.points.slip_angle[0]), {}, {})
        curve = RigCurve(run.run_id, slip)
        for law, fit in fits.items():
            sim = predict(fmu, grid, fit.model_parameters())
            curve.values[law] = {c: sim[c] for c in PLOTTED}
        curves.append(curve)
    return RigResults(fits, runs, curves)


def figure_rig(results: RigResults, out: Path) -> str:
    """One row per run, one column per measured quantity: the measurements with their error bars
    (the table's std, else the noise scale the fits estimated: the larger of the laws') and each
    law's fitted curve."""
    runs = results.runs
    fig, axes = plt.subplots(len(runs), len(PLOTTED), figsize=(4 * len(PLOTTED), 3.2 * len(runs)), squeeze=False)
    for i, (run, curve) in enumerate(zip(runs, results.curves)):
        for j, (column, label) in enumerate(PLOTTED.items()):
            ax = axes[i, j]
            if column in run.measured:
                m = run.measured[column]
                if column in run.std:
                    err = run.std[column]
                else:
                    scales = [s for s in (f.noise_scale.get(column) for f in results.fits.values()) if s is not None]
                    err = np.full(len(m), max(scales)) if scales else None
                ax.errorbar(run.points.slip, m, yerr=err, fmt="ko", ms=4, capsize=2, label="measured")
            for law, values in curve.values.items():
                color, style = LAW_STYLE.get(law, ("C2", ":"))
                ax.plot(curve.slip, values[column], color=color, ls=style, label=f"{law} fit")
            ax.set_xlabel("slip [-]")
            ax.set_ylabel(label)
            ax.grid(alpha=0.3)
            if i == 0 and j == 0:
                ax.legend(fontsize=8)
        wheel = f"lugs {run.setup.lug_height * 1000:.0f} mm" if run.setup.lugged else "smooth rim"
        axes[i, 0].set_title(f"{run.run_id}: {run.points.load[0]:.4g} N, {wheel}", loc="left", fontsize=9)
    fig.tight_layout()
    name = "rig_fit.png"
    fig.savefig(out / name, dpi=110)
    plt.close(fig)
    return name


def rig_section(results: RigResults, out: Path) -> list[str]:
    """The report's section: the figure, each law's parameters with uncertainty and
    identifiability, the fit's rms errors and its doubts."""
    laws = list(results.fits)
    lines = ["## Single-wheel testbed fit", "",
             f"The wheel_rig runs {', '.join(r.run_id for r in results.runs)} fitted by weighted least squares "
             f"with each contact law ({', '.join(laws)}), every point simulated to its steady state in the "
             "WheelRig FMU. Error bars: the table's standard deviations, else the noise scale the fit estimated "
             "from the data.", "", f"![rig fit]({figure_rig(results, out)})", ""]
    for law, fit in results.fits.items():
        lines += [f"### {law} contact law", "", "| Parameter | Estimate | 1 sigma | relative | identifiability |",
                  "|---|---|---|---|---|"]
        for k, v in fit.params.items():
            lines.append(f"| {k} | {v:.4g} | {fit.std[k]:.3g} | {fit.relative_std[k]:.1%} | "
                         f"{fit.identifiability[k]} |")
        lines += ["", "RMS error of the fit: " + ", ".join(f"{c} {v:.3g}" for c, v in fit.rms.items()) +
                  "; noise: " + ", ".join(f"{c} {n}" for c, n in fit.noise.items()) +
                  f"; chi-square {fit.chi2:.3g} on {fit.dof} degrees of freedom; status {fit.status}.", ""]
        lines += [f"Doubtful: {doubt}.\n" for doubt in fit.doubts]
    return lines
