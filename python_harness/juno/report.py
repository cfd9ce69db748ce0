"""A self-contained Markdown report with PNG figures.

Sections: the campaign, the paper's per-run identification (Tables 1-3 and
Figures 4-9), the joint identification with uncertainty, the traction
ratio against slip (Figure 10), the 3-D terrain validation (Figures 12-14)
and, when given, the discrepancy diagnosis.  The report folder is written
whole or not at all.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .outputs import REPORT_MARKER, OutputError, marked_directory  # noqa: E402
from .campaign import Campaign, forward_speed, missing_columns, read_run  # noqa: E402
from .sensor_noise import noise_statements, stated_noise_lines  # noqa: E402
from .identify import JointResult, PaperResult  # noqa: E402
from .imu_mounting import offsets_text  # noqa: E402
from . import rover_model  # noqa: E402
from .rover_model import SOIL_PARAMETERS, Rover  # noqa: E402
from .validate import SETTLING, ValidationResult  # noqa: E402

LABELS = {"soil.kh": "Foundation stiffness k_h [N/m^(2+eta)]", "soil.eta": "Nonlinearity exponent eta",
          "soil.gamma": "Foundation rebound gamma [-]", "soil.Kvx": "Traction modulus K_vx"}


def _fmt(v: float) -> str:
    return f"{v:.4g}"


def _save(fig, path: Path) -> str:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path.name


def figure_run(campaign: Campaign, run_id: str, window, out: Path) -> str:
    """Inputs (drawbar force, torques) and objectives (speed, spins) of a drawbar run (Figs 4-9)."""
    data = read_run(campaign, campaign.run(run_id))
    fig, axes = plt.subplots(2, 2, figsize=(10, 6), sharex=True)
    t, f = data.samples("drawbar_force")
    axes[0, 0].plot(t, f, lw=0.6)
    axes[0, 0].set_ylabel("drawbar force [N]")
    for side in ("left", "right"):
        axes[0, 1].plot(*data.samples(f"torque_{side}"), lw=0.6, label=side)
        axes[1, 1].plot(*data.samples(f"omega_{side}"), lw=0.6, label=side)
    axes[0, 1].set_ylabel("drive torque [N m]")
    axes[1, 1].set_ylabel("wheel spin [rad/s]")
    ts = np.linspace(data.time[0], data.time[-1], 400)
    axes[1, 0].plot(ts, forward_speed(data, ts), lw=0.8)
    axes[1, 0].set_ylabel("forward speed [m/s]")
    for ax in axes.flat:
        if window:
            ax.axvspan(window[0], window[1], color="0.9")
        ax.grid(alpha=0.3)
    axes[0, 1].legend()
    axes[1, 0].set_xlabel("time [s]")
    axes[1, 1].set_xlabel("time [s]")
    fig.suptitle(f"Drawbar run {run_id}: inputs (top) and objectives (bottom); steady window shaded")
    return _save(fig, out / f"run_{run_id}.png")


#: Contact patch area (m^2) at which Figure 10 draws Eqn 5: a harness choice for the figure (a
#: patch 0.19 m long under the 0.254 m wide wheel, as at a sinkage of about 1.7 cm).  It scales
#: only the cohesion term, A C / F_n = 0.06 beside tan(phi) = 0.58 at the FMU's defaults.
FIGURE10_PATCH_AREA = 0.049


def traction_ratio(soil: dict[str, float], slip: np.ndarray, rover: Rover,
                   area: float = FIGURE10_PATCH_AREA) -> np.ndarray:
    """F_t / F_n of Eqn 5 against slip for the soil ``soil`` (its K_vx), at a quarter of the
    rover's weight on each wheel and a contact patch of ``area`` (m^2), with the rover's soil
    strength (cohesion, friction angle)."""
    return rover_model.traction_ratio(slip, soil["soil.Kvx"], rover.weight / 4, area, rover.cohesion,
                                      rover.friction_angle)


def figure_traction(paper: Sequence[PaperResult], joint: JointResult | None, points, rover: Rover,
                    out: Path) -> str:
    """Figure 10: traction ratio against slip for every identified parameter set, with measured points."""
    s = np.linspace(0, 1, 200)
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    for p in paper:
        ax.plot(s, traction_ratio(p.final, s, rover), lw=1, label=f"paper-style, {p.run_id}")
    if joint is not None:
        ax.plot(s, traction_ratio(joint.params, s, rover), "k", lw=2, label="joint fit")
    if points:
        ax.plot([q[0] for q in points], [q[1] for q in points], "ro", label="measured steady states")
    ax.set_xlabel("longitudinal slip [-]")
    ax.set_ylabel("traction ratio F_t / F_n [-]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return _save(fig, out / "fig10_traction_ratio.png")


def measured_traction_points(paper: Sequence[PaperResult], rover: Rover) -> list[tuple[float, float]]:
    """(slip, traction ratio) of each run's steady state: total wheel force / the rover's weight."""
    pts = []
    for p in paper:
        a = p.averages
        w = 0.5 * (a.omega_left + a.omega_right)
        if w * a.wheel_radius <= 0:
            continue
        slip = 1 - a.speed / (w * a.wheel_radius)
        ratio = (a.torque_left + a.torque_right) / a.wheel_radius / rover.weight
        pts.append((slip, ratio))
    return pts


def figure_validation(v: ValidationResult, out: Path) -> str:
    """Figures 12-14: position and speed, wheel spins, drive torques, measured against simulated."""
    fig, axes = plt.subplots(3, 2, figsize=(10, 9))
    pairs = [("pos_x", "x position [m]"), ("speed", "forward speed [m/s]"),
             ("omega_left", "left wheel spin [rad/s]"), ("omega_right", "right wheel spin [rad/s]"),
             ("torque_left", "left drive torque [N m]"), ("torque_right", "right drive torque [N m]")]
    for ax, (name, label) in zip(axes.flat, pairs):
        ax.plot(v.time, v.measured[name], lw=0.8, label="measured")
        ax.plot(v.time, v.simulated[name], lw=0.8, label="simulated")
        ax.set_ylabel(label)
        ax.set_title(f"RMS error {v.rms[name]:.3g}", fontsize=9)
        ax.grid(alpha=0.3)
    axes[0, 0].legend()
    for ax in axes[-1]:
        ax.set_xlabel("time since the run's start [s]")   # the run's own clock may start anywhere
    fig.suptitle(f"3-D terrain run {v.run_id}: measured against simulated")
    return _save(fig, out / f"validation_{v.run_id}.png")


def figure_path(v: ValidationResult, out: Path) -> str:
    fig, ax = plt.subplots(figsize=(7, 3.5))
    ax.plot(v.measured["pos_x"], v.measured["pos_y"], label="measured")
    ax.plot(v.simulated["pos_x"], v.simulated["pos_y"], label="simulated")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(alpha=0.3)
    ax.legend()
    return _save(fig, out / f"path_{v.run_id}.png")


def _paper_outcome(p: PaperResult) -> str:
    """How a paper-style fit ended, in words (never "converged" for a fit that did not move)."""
    if p.status != "ok":
        return "not identified: the fit did not move, or the averaged objectives see no parameter"
    return "converged" if p.converged else "stopped at the evaluation limit"


def _paper_section(campaign: Campaign, paper: Sequence[PaperResult], out: Path) -> list[str]:
    """Section 1: each drawbar run's paper-style fit (Tables 1-3, Figures 4-9) and their spread."""
    lines = ["## 1. Identification the paper's way (Tables 1-3)", "",
             "Per drawbar run: steady-window averages of drawbar force and drive torques are the "
             "inputs, averages of forward speed and wheel spins the objectives; cost of Eqns 10-13 with "
             "the paper's weights; unconstrained Nelder-Mead from the paper's initial guess.", ""]
    for p in paper:
        a = p.averages
        lines += [f"### Run {p.run_id} (steady window {a.window[0]:g}-{a.window[1]:g} s)", "",
                  f"Averages: drawbar {a.drawbar:.1f} N, torque L/R {a.torque_left:.1f}/{a.torque_right:.1f} "
                  f"N m, speed {a.speed:.4f} m/s, spin L/R {a.omega_left:.4f}/{a.omega_right:.4f} rad/s.", "",
                  "| Model parameter | Initial value | Final value |", "|---|---|---|"]
        for k in SOIL_PARAMETERS:
            lines.append(f"| {LABELS[k]} | {_fmt(p.initial[k])} | {_fmt(p.final[k])} |")
        lines += ["", f"Cost {p.cost:.3g} after {p.evaluations} evaluations "
                  f"({_paper_outcome(p)}); "
                  f"the three averaged objectives see {p.jacobian_rank} of the 4 parameter directions, "
                  "so this fit cannot pin all four parameters.", "",
                  f"![run {p.run_id}]({figure_run(campaign, p.run_id, a.window, out)})", ""]
    lines += ["### Spread between runs", "", "| Parameter | " + " | ".join(p.run_id for p in paper) +
              " | spread (max/min - 1) |", "|---|" + "---|" * (len(paper) + 1)]
    for k in SOIL_PARAMETERS:
        vals = [p.final[k] for p in paper]
        spread = max(vals) / min(vals) - 1 if min(vals) > 0 else float("nan")
        lines.append(f"| {k} | " + " | ".join(_fmt(v) for v in vals) + f" | {spread:.1%} |")
    lines.append("")
    return lines


def _joint_section(joint: JointResult) -> list[str]:
    """Section 2: the joint fit's estimates, uncertainties, identifiability and correlations."""
    lines = ["## 2. Joint identification (beyond the paper)", ""]
    if joint.doubts:
        lines += ["**The fit is doubtful**; read its estimates and uncertainties with that in mind:", ""]
        lines += [f"- {d}" for d in joint.doubts] + [""]
    lines += [f"One fit over runs {', '.join(joint.runs)} using the whole time series: the model follows the "
             "measured wheel spins and is compared on drive torque, 1 s position increments, height and "
             "pitch; parameters searched as log/logit; trust-region Gauss-Newton on the scaled residuals; "
             "1-sigma uncertainty from the Jacobian, scaled by the residual variance and inflated for "
             "time-correlated residuals" + (", and the replay's own bias (a refit of the runs simulated with the "
                                            "fitted soil, noise-free) added in quadrature" if joint.replay_bias else
                                            "; the replay's own bias is not included (it is estimated where the "
                                            "runs lack a column the fit uses)") + ".", "",
             "| Parameter | Estimate | 1 sigma | relative | of it: noise | of it: replay bias | identifiability |",
             "|---|---|---|---|---|---|---|"]
    for k in SOIL_PARAMETERS:
        stat = joint.std_statistical.get(k, joint.std[k])
        bias = f"{joint.replay_bias[k]:+.3g}" if k in joint.replay_bias else "-"
        lines.append(f"| {k} | {_fmt(joint.params[k])} | {_fmt(joint.std[k])} | "
                     f"{joint.relative_std[k]:.2%} | {_fmt(stat)} | {bias} | {joint.identifiability[k]} |")
    corr = np.asarray(joint.correlation)
    if joint.pitch_offset:
        lines += ["", f"The measured pitch reads {offsets_text(joint.pitch_offset)} from the fitted model's: "
                  + ("the IMU's mounting, a free parameter of the fit (the manifest's `imu_mounting` is free)."
                     if joint.pitch_offset_free else
                     "the manifest says the IMU's mounting is calibrated, so the fit took no offset.")]
    lines += ["", f"Mean squared scaled residual {joint.cost:.4g}; {joint.evaluations} model evaluations; "
              f"{joint.wall_time:.1f} s.", "", "Correlation of the estimates:", "",
              "| | " + " | ".join(SOIL_PARAMETERS) + " |", "|---|" + "---|" * 4]
    for i, k in enumerate(SOIL_PARAMETERS):
        lines.append(f"| {k} | " + " | ".join(f"{corr[i, j]:+.2f}" for j in range(4)) + " |")
    lines.append("")
    return lines


def _validation_section(campaign: Campaign, validations: Sequence[tuple[str, ValidationResult]],
                        out: Path) -> list[str]:
    """Section 4: the terrain runs' RMS errors (Figures 12-14 for the first validation), or why
    there is no validation."""
    lines: list[str] = []
    if not campaign.runs_of_kind("terrain"):
        lines += ["## 4. Validation on the 3-D terrain (Figures 12-14)", "",
                  "Not done: validation needs a terrain run (a run with its LIDAR scan), and the campaign has "
                  "none.", ""]
    if validations:
        lines += ["## 4. Validation on the 3-D terrain (Figures 12-14)", "",
                  "Each terrain run's LIDAR scan is gridded and the rover simulated on it, a PID on torque "
                  "following the measured wheel spins.", "",
                  "| Run | Parameters | grid | x [m] | y [m] | z [m] | speed [m/s] | spin L/R [rad/s] | "
                  "torque L/R [N m] |", "|---|---|---|---|---|---|---|---|---|"]
        for label, v in validations:
            r = v.rms
            lines.append(f"| {v.run_id} | {label} | {v.grid_cell * 100:.0f} cm | {r['pos_x']:.3f} | {r['pos_y']:.3f} | "
                         f"{r['pos_z']:.3f} | {r['speed']:.3f} | {r['omega_left']:.3f}/{r['omega_right']:.3f} | "
                         f"{r['torque_left']:.1f}/{r['torque_right']:.1f} |")
        lines.append("")
        # A campaign may have several terrain runs, each on its own scan: every run gets its
        # figures, drawn for the first parameter set it was validated with.
        first_of_run: dict[str, tuple[str, ValidationResult]] = {}
        for label, v in validations:
            first_of_run.setdefault(v.run_id, (label, v))
        lines += [f"RMS errors over each run after its first {SETTLING:g} s (the PID catching the measured "
                  "spins). In units of each column's sensor noise, stated in the manifest or else estimated from "
                  "the measured column itself (1 is agreement to within the noise; many times it is model error):", ""]
        for label, v in validations:
            known = [name for name in v.rms if np.isfinite(v.noise_ratio(name))]
            lines.append(f"- {v.run_id}, {label}: " + ", ".join(f"{name} {v.noise_ratio(name):.2g}" for name in known))
        lines.append("")
        for run_id, (label, v) in first_of_run.items():
            lines += [f"Run {run_id}, {label}:", "",
                      f"![validation {run_id}]({figure_validation(v, out)})", "",
                      f"![path {run_id}]({figure_path(v, out)})", ""]
    return lines


def _validation_summary(validations: Sequence[tuple[str, ValidationResult]]) -> dict[str, dict[str, dict]]:
    """The RMS errors of every validation, by terrain run, then by parameter set (its label)."""
    out: dict[str, dict[str, dict]] = {}
    for label, v in validations:
        out.setdefault(v.run_id, {})[label] = v.rms
    return out


def _truth_section(truth: dict[str, Any], joint: JointResult | None) -> list[str]:
    """A synthetic campaign's truth against the joint fit, clearly marked as for checking only."""
    lines = ["## Synthetic truth (for checking only)", "",
             "This campaign is synthetic; its `truth.json` is read here, by the report, and never by "
             "identification or diagnosis.", "", "| Parameter | truth | joint fit | error |", "|---|---|---|---|"]
    for k in SOIL_PARAMETERS:
        tv = truth["soil"][k]
        jv = joint.params[k] if joint else float("nan")
        lines.append(f"| {k} | {_fmt(tv)} | {_fmt(jv)} | {jv / tv - 1:+.1%} |")
    lines += ["", f"Hidden effect: `{truth.get('effect')}` (strength {truth.get('strength')}).", ""]
    return lines


def write_report(out_dir: str | Path, campaign: Campaign, paper: Sequence[PaperResult],
                 joint: JointResult | None, validations: Sequence[tuple[str, ValidationResult]],
                 diagnosis: dict[str, Any] | None = None, overwrite: bool = True,
                 truth: dict[str, Any] | None = None, timings: dict[str, float] | None = None,
                 rig: Any = None) -> Path:
    """Writes ``out_dir/report.md`` and its figures; returns the report path.

    ``rig``: the fits of the campaign's wheel_rig runs (juno.wheel_rig_report.RigResults), drawn
    in their own section.
    ``validations``: (label, result) pairs, e.g. joint-fit and paper-style parameters.
    ``truth``: a synthetic campaign's truth, shown in its own clearly marked section.
    ``overwrite``: replace an existing ``out_dir`` written by this function before (it holds
    the marker file :data:`juno.outputs.REPORT_MARKER`); a folder holding anything else, or the
    campaign folder, is never replaced (:class:`juno.outputs.OutputError`).
    """
    out_dir = Path(out_dir)
    if not overwrite and out_dir.is_dir() and any(out_dir.iterdir()):
        raise OutputError(f"report folder {out_dir} exists and is not empty (overwrite=False)")
    with marked_directory(out_dir, REPORT_MARKER, "juno report", inputs=[campaign.root],
                          what="report folder") as tmp:
        tmp = Path(tmp)
        lines = [f"# Juno rover soil identification and validation: {campaign.name}", ""]
        lines += ["Volumetric wheel/soil model of Petersen and McPhee (2013) in the JunoRover FMU.",
                  f"Campaign folder: `{campaign.root}`; runs: " +
                  ", ".join(f"{r.id} ({r.kind})" for r in campaign.runs) + ".", ""]
        missing = missing_columns(campaign, ("drawbar", "terrain"))
        if missing:
            lines += ["What the campaign's runs lack, and what that costs:", ""]
            lines += [f"- {m.sentence()}" for m in missing] + [""]
        noise = noise_statements(campaign)
        stated = stated_noise_lines(noise)
        if stated:
            lines += ["The campaign's sensor noise:", ""] + [f"- {line}" for line in stated] + [""]
        if paper:
            lines += _paper_section(campaign, paper, tmp)
        if joint is not None:
            lines += _joint_section(joint)
        if rig is not None:
            from .wheel_rig_report import rig_section
            lines += rig_section(rig, tmp)
        if paper or joint is not None:
            geometry = rover_model.rover(campaign.rover)
            name = figure_traction(paper, joint, measured_traction_points(paper, geometry), geometry, tmp)
            lines += ["## 3. Traction ratio against slip (Figure 10)", "", f"![traction]({name})", ""]
        lines += _validation_section(campaign, validations, tmp)
        if diagnosis is not None:
            from .diagnose import report_section
            lines += report_section(diagnosis, tmp)
        if truth is not None:
            lines += _truth_section(truth, joint)
        if timings:
            lines += ["## Timings", "", "| step | wall time [s] |", "|---|---|"]
            lines += [f"| {k} | {v:.1f} |" for k, v in timings.items()]
            lines.append("")
        (tmp / "report.md").write_text("\n".join(lines), encoding="utf-8")
        summary = {"campaign": campaign.name,
                   "paper": [{"run": p.run_id, "final": p.final, "cost": p.cost} for p in paper],
                   "joint": None if joint is None else {"params": joint.params, "std": joint.std,
                                                        "std_statistical": joint.std_statistical,
                                                        "std_systematic": joint.std_systematic,
                                                        "replay_bias": joint.replay_bias,
                                                        "pitch_offset": joint.pitch_offset,
                                                        "pitch_offset_free": joint.pitch_offset_free,
                                                        "doubts": list(joint.doubts)},
                   "missing_columns": [m.to_json() for m in missing],
                   "sensor_noise": [n.to_json() for n in noise],
                   # run id -> parameter set -> RMS errors: one entry per terrain run
                   "validation": _validation_summary(validations)}
        if rig is not None:
            summary["rig"] = {law: {"params": f.params, "std": f.std, "rms": f.rms} for law, f in rig.fits.items()}
        (tmp / "summary.json").write_text(json.dumps(summary, indent=2), encoding="utf-8")
    return out_dir / "report.md"
