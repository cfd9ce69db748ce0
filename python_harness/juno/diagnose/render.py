"""The diagnosis for people: a few lines of text (summary_lines), residual figures
(residual_figures) and the report's section (report_section)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..campaign import DEFAULT_IMU_MOUNT
from ..imu_mounting import offsets_text
from ..registration import OFFSET_NAMES
from ..sensor_noise import stated_noise_lines
from .candidates import CANDIDATES
from .results import DiagnosisResult, Duel, JudgedCandidate, TiedPair
from .verdict import Unexplained


def summary_lines(result: DiagnosisResult) -> list[str]:
    """The diagnosis in a few lines of text: the cause, every candidate's held-out gain and
    significance, the head-to-head judgements, ties and the run that would settle them, the
    second round, the causes named, strongest first, and the optional columns the campaign lacks
    with what that costs."""
    lines = [f"cause: {result.cause} ({result.explanation})"]
    for c in result.candidates:
        mark = "*" if c.significant else " "
        lines.append(f" {mark} {c.name:16s} held-out gain {c.gain:+7.1%}  z {c.z:6.1f}   {by_kind(c)}")
        lines += at_bounds_lines(c, named_with(result, c))
        said = pose_only_sentence(result, c)
        lines += [f"      {said}"] if said else []
    lines += [duel_sentence(duel) for duel in result.head_to_head]
    if result.equally_good:
        lines.append("equally good: " + ", ".join(result.equally_good))
    lines += [apart_sentence(a) for a in result.telling_apart]
    if result.second_round:
        lines.append(f"on top of {result.cause}:")
        for c in result.second_round:
            mark = "*" if c.significant else " "
            lines.append(f" {mark} {c.name:16s} further held-out gain {c.gain:+7.1%}  z {c.z:6.1f}   {by_kind(c)}")
            lines += at_bounds_lines(c)
    if len(result.causes) > 1:
        lines.append("causes, strongest first: " + ", ".join(result.causes))
    lines += [m.sentence() for m in result.missing_columns]
    lines += stated_noise_lines(result.sensor_noise)
    return lines


def named_with(result: DiagnosisResult, c: JudgedCandidate) -> str | None:
    """The second cause with which a first-round candidate held back by its soil was named the
    first cause (search.first_cause_branches: its final model's soil is real), or None."""
    if c.soil_at_bounds and len(result.causes) > 1 and result.causes[0] == c.name:
        return result.causes[1]
    return None


def at_bounds_lines(c: JudgedCandidate, second: str | None = None) -> list[str]:
    """A line under a candidate whose fitted soil sits at a bound of the search (no evidence for
    its cause alone: judging.is_significant), or none; ``second``: the cause with which it was
    named all the same (named_with)."""
    if not c.soil_at_bounds:
        return []
    if second is not None:
        return [f"      alone, its soil sits at a bound of the search ({', '.join(c.soil_at_bounds)}); with "
                f"{second} on top the soil is a real one, and that model explains the held-out data best"]
    return [f"      its soil sits at a bound of the search ({', '.join(c.soil_at_bounds)}): the data push the "
            "soil beyond any real one, so its gain is no evidence for the cause"]


def pose_only_sentence(result: DiagnosisResult, c: JudgedCandidate) -> str | None:
    """What a registration significant on the measured pose but not named rests on, and why it is
    not named; None for any other candidate.  The pose is kinematic evidence: a soil effect that
    sinks the wheels deeper in places (a soft patch or strip) lowers the rover as a lowered scan
    would, so the registration's significance alone says the pose does not fit the scan as it
    is, not that the scan is misregistered."""
    if not (c.significant and c.kinematic and c.kinematic.significant) or c.name in result.causes:
        return None
    scans = c.kinematic.misregistered()
    ratios = (", ".join(f"{s.scan} {s.ratio:.3g}" for s in scans) if len(c.kinematic.scans or []) > 1
              else f"{c.kinematic.ratio:.3g}")
    said = (f"significant on the measured pose alone (held-out pose {ratios} times better "
            f"registered, evidence from {result.criteria.registration_held_out_ratio:g} times); not named: ")
    said += (f"{result.causes[0]} explains the held-out data better" if result.causes
             else f"the diagnosis is {result.cause}")
    on_top = next((s for s in result.second_round if s.name == c.name), None)
    if on_top is not None and not on_top.significant:
        said += f", and on top of it the registration is not significant (further gain {on_top.gain:+.1%})"
    return said + ("; a soil effect that sinks the wheels deeper in places moves the pose as a "
                   "misregistered scan would")


def significance(c: JudgedCandidate, second: str | None = None) -> str:
    """A report table's cell: "yes", "no", "no: soil at a bound of the search (...)", or, for a
    first cause named with ``second`` (named_with), "alone no: ...; named with ..."."""
    if c.significant:
        return "yes"
    if c.soil_at_bounds and second is not None:
        return f"alone no: soil at a bound of the search ({', '.join(c.soil_at_bounds)}); named with {second}"
    return f"no: soil at a bound of the search ({', '.join(c.soil_at_bounds)})" if c.soil_at_bounds else "no"


def by_kind(c: JudgedCandidate) -> str:
    """A candidate's held-out gain and z on each kind of run, e.g. 'drawbar +12.0 % (z 3.1)'."""
    gains, zs = c.gain_by_kind, c.z_by_kind
    return ", ".join(f"{k} {gains[k]:+.1%} (z {zs[k]:.1f})" for k in gains if k in zs) or "-"


def duel_sentence(duel: Duel) -> str:
    """One line on a head_to_head comparison: who won, by how much, how significantly."""
    zs = ", ".join(f"{k} z {z:.1f}" for k, z in duel.z_by_kind.items())
    verdict = "explains the held-out data better than" if duel.challenger_better else \
        "is not significantly better than"
    if duel.stage == "near tie":
        then = "no second round of its own" if duel.challenger_better else "a second round of its own"
        return (f"near tie: {duel.challenger} {verdict} {duel.leader}, which gets {then}: "
                f"held-out mean squared residual {-duel.gain:+.1%} against it, {zs}")
    if duel.stage in ("ripple", "final models, ripple"):
        then = f"{duel.challenger} stays first" if duel.challenger_better else f"{duel.leader} is put first"
        stage = "ripple, between the final models" if duel.stage.startswith("final") else "ripple"
        return (f"{stage}: the drive torques ripple with the wheel angle, which {duel.leader} makes and "
                f"{duel.challenger} does not; {duel.challenger} {verdict} {duel.leader}, so {then}: "
                f"held-out mean squared residual {-duel.gain:+.1%} against it, {zs}")
    stage = "head to head of the final models" if duel.stage == "final models" else "head to head"
    return (f"{stage}: {duel.challenger} (more parameters) {verdict} {duel.leader}: "
            f"held-out mean squared residual {-duel.gain:+.1%} against it, {zs}")


def apart_sentence(a: TiedPair) -> str:
    """One sentence on the run that would tell a tied candidate from the cause (tied_models_apart)."""
    named, other = a.models
    return (f"What would tell {named} from {other}: a steady drawbar run on flat ground at {a.load_N:.0f} N "
            f"and throttle {a.throttle:g} (the load ramped in over 4 s), where the fitted models settle at "
            f"slips {a.slip[named]:.3f} ({named}) and {a.slip[other]:.3f} ({other}); up to this "
            f"campaign's heaviest drawbar load they differ by at most {a.difference_within_campaign:.3f}.")


# ------------------------------------------------------------------ figures

def residual_figures(result: DiagnosisResult, out: Path) -> list[str]:
    """Residuals of the base model (and the extended one) against time, by run and signal, and
    the base model's bias by run and signal; written into ``out``, their file names returned."""
    import matplotlib
    matplotlib.use("Agg")
    return [_residuals_in_time(result, out), _bias_by_run_and_signal(result, out)]


def _residuals_in_time(result: DiagnosisResult, out: Path) -> str:
    """Scaled residuals against time within each run, runs side by side, one panel per signal."""
    import matplotlib.pyplot as plt
    data = result.plot_data
    meta, base, best = data.problem_meta, data.base_residuals, data.best_residuals
    runs, signals = list(np.unique(meta["run"])), list(np.unique(meta["signal"]))
    fig, axes = plt.subplots(len(signals), 1, figsize=(10, 2.0 * len(signals)), sharex=False)
    axes = np.atleast_1d(axes)
    for ax, sig in zip(axes, signals):
        offset = 0.0
        for run in runs:
            m = (meta["run"] == run) & (meta["signal"] == sig)
            if not np.any(m):
                continue
            ax.plot(meta["time"][m] + offset, base[m], lw=0.5, color="C0", label="base" if offset == 0 else None)
            if best is not None:
                ax.plot(meta["time"][m] + offset, best[m], lw=0.5, color="C1",
                        label=f"extended ({result.cause})" if offset == 0 else None)
            ax.axvline(offset, color="0.7", lw=0.5)
            ax.text(offset, 0, f" {run}", fontsize=7, va="bottom")
            offset += float(meta["time"][m].max()) + 2.0
        ax.set_ylabel(f"{sig}\n[sigma]", fontsize=8)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    axes[-1].set_xlabel("time within each run, runs side by side [s]")
    fig.suptitle("Scaled residuals (measured - simulated) / sigma")
    fig.tight_layout()
    fig.savefig(out / "residuals_time.png", dpi=100)
    plt.close(fig)
    return "residuals_time.png"


def _bias_by_run_and_signal(result: DiagnosisResult, out: Path) -> str:
    """Mean residual per run and signal, left against right: where and on which side."""
    import matplotlib.pyplot as plt
    meta, base = result.plot_data.problem_meta, result.plot_data.base_residuals
    fig, ax = plt.subplots(figsize=(10, 3.5))
    labels, vals = [], []
    for run in np.unique(meta["run"]):
        for sig in np.unique(meta["signal"]):
            m = (meta["run"] == run) & (meta["signal"] == sig)
            if np.any(m):
                labels.append(f"{run}\n{sig}")
                vals.append(float(np.mean(base[m])))
    colours = ["C2" if "left" in lab else "C3" if "right" in lab else "C0" for lab in labels]
    ax.bar(range(len(vals)), vals, color=colours)
    ax.set_xticks(range(len(vals)))
    ax.set_xticklabels(labels, fontsize=6, rotation=90)
    ax.set_ylabel("mean residual [sigma]")
    ax.set_title("Base model bias by run and signal (green left, red right side)")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / "residuals_bias.png", dpi=100)
    plt.close(fig)
    return "residuals_bias.png"


# ------------------------------------------------------------------ the report's section

def report_section(result: DiagnosisResult, out: Path) -> list[str]:
    """Markdown lines of the diagnosis for the report (figures written into ``out``)."""
    lines = ["## 5. What the model gets wrong: diagnosis", ""]
    figs = residual_figures(result, out) if result.plot_data is not None else []
    lines += _base_model_lines(result)
    for f in figs:
        lines += [f"![{f}]({f})", ""]
    lines += _candidates_table(result)
    if result.cause == "none":
        words = result.explanation
        lines += [f"**Cause: none.** {words[:1].upper()}{words[1:]}.", ""]
    elif result.cause == "unexplained":
        lines += _unexplained_lines(result)
    else:
        lines += _cause_lines(result)
        if result.unexplained is not None:
            lines += ["Structure beyond sensor noise remains in the model with the named causes:", ""]
            lines += _structure_table(result.unexplained)
            lines += _paragraph(result.unexplained.ripple_maker_sentences())
    return lines


def _unexplained_lines(result: DiagnosisResult) -> list[str]:
    """The verdict 'unexplained': what the residuals hold, and the catalog causes that absorb only
    part of it."""
    u = result.unexplained
    if u is not None and not u.signals and not u.ripples and not u.offsets:
        lines = ["**Cause: unexplained.** No extension in the catalog explains the data: "
                 + (u.summary() or "structure remains") + ".", ""]
        return lines + _scan_table(u)
    lines = ["**Cause: unexplained.** The drawbar runs' held-out residuals hold structure beyond sensor noise "
             "that no extension in the catalog explains (a sensor error, or physics the model does not have)."]
    if u is not None and u.absorbed_by:
        lines[0] += (f" {', '.join(u.absorbed_by)} would remove only {u.share_removed:.0%} of it, so it is "
                     "not named.")
    lines.append("")
    if u is not None:
        lines += _structure_table(u) + _scan_table(u)
        lines += _paragraph([p.sentence() for p in u.partial])
    return lines


def _paragraph(clauses: list[str]) -> list[str]:
    """Markdown lines of ``clauses`` as sentences (capitalised, each with its full stop), then a
    blank line; nothing for no clauses."""
    return [c[0].upper() + c[1:] + "." for c in clauses] + ([""] if clauses else [])


def _scan_table(u: Unexplained) -> list[str]:
    """One row per signal of a terrain run whose measured pose disagrees with its own scan
    (juno.scan_consistency): the run, the RMS of the signal's held-out block means, against its
    floor.  The runs that agree are named beneath (the floors apply per run)."""
    if u.scan is None or not u.scan.significant:
        return []
    lines = ["The rover posed on each terrain run's own scan (no replay), against its measured pose:", "",
             "| terrain run | signal | held-out block means (RMS) | floor | mean |", "|---|---|---|---|---|"]
    for run in u.scan.disagreeing():
        for s in run.disagreeing():
            scale, unit = (1000.0, "mm") if s.unit == "m" else (1000.0, "mrad")
            lines.append(f"| {run.run} | {s.signal} | {s.rms * scale:.3g} {unit} | {s.floor * scale:.3g} {unit} | "
                         f"{s.offset * scale:+.3g} {unit} |")
    lines.append("")
    agree = [r.run for r in u.scan.runs if not r.significant]
    if agree:
        lines += [f"The measured pose agrees with the scan on terrain run{'s' if len(agree) > 1 else ''} "
                  f"{', '.join(agree)}.", ""]
    if u.scan.untested:
        lines += ["Not tested: " + "; ".join(f"terrain run {run} ({why})" for run, why in u.scan.untested.items())
                  + ".", ""]
    return lines


def _structure_table(u: Unexplained) -> list[str]:
    """One row per signal with structure: its size, against its sensor noise, and what it follows;
    then one per signal that ripples with the wheel angle."""
    lines = ["| signal | structure (RMS) | x sensor noise | follows |", "|---|---|---|---|"]
    for s in u.signals:
        follows = "; ".join(f"{c.name} ({c.share:.0%}" + (f", {c.slope:+.3g} {c.unit}" if c.name != "run" else "")
                            + ")" for c in s.follows) or "-"
        lines.append(f"| {s.signal} | {s.structure_rms:.3g} {s.unit} | {s.ratio:.2g} | {follows} |")
    for r in u.ripples:      # amplitude a of a cos(N theta + phi): RMS a / sqrt 2
        lines.append(f"| {r.signal} | {r.amplitude / np.sqrt(2.0):.3g} {r.unit} (amplitude {r.amplitude:.3g}) | "
                     f"{r.ratio / np.sqrt(2.0):.2g} | the wheel angle at {r.lugs} per revolution "
                     f"(lug passing?; p {r.p_value:.2g}) |")
    for o in u.offsets:      # the offset times the signal's rate of change, over the held-out samples
        lines.append(f"| {o.signal} | offset {o.offset:+.3g} s (null spread {o.spread:.2g} s) | "
                     f"{o.explained:.2g} | its own rate of change, as a clock {o.direction()} the replay "
                     f"inputs' leaves it (clock offset?; p {o.p_value:.2g}) |")
    lines.append("")
    return lines


def _base_model_lines(result: DiagnosisResult) -> list[str]:
    """The base model's held-out error and how the terrain run was replayed."""
    criteria = result.criteria
    lines = [f"Base model fitted on alternate {criteria.block_s:g} s training blocks of every run; "
             f"held-out mean squared scaled residual {result.baseline.test_mse:.3g} (1 = sensor noise).", ""]
    lines += _mounting_lines(result)
    settled = criteria.terrain_drive_settled or {}
    if settled:
        drive = criteria.terrain_drive
        how = "following the measured spins" if drive == "spin" else "driven by the measured torque"
        lines += [f"The terrain run is replayed {how} for every model: the replay under which a fitted model "
                  f"({settled[drive]['model']}) fits its training blocks best (lowest training loss: "
                  + ", ".join(f"{d} {v['loss']:.3g}" for d, v in settled.items()) + ").", ""]
    return lines


def _mounting_lines(result: DiagnosisResult) -> list[str]:
    """The constant the base model's pitch residuals hold on each IMU mounting, and what the
    diagnosis made of it."""
    offsets = result.baseline.pitch_offset
    if not offsets:
        return []
    one = list(offsets) == [DEFAULT_IMU_MOUNT]
    said = (f"The measured pitch reads {offsets_text(offsets)} from the base model's on the drawbar runs' "
            "training blocks (measured - simulated). ")
    if result.criteria.pitch_offset_free:
        said += (f"Every fit and comparison takes {'it' if one else 'each'} off as the IMU's mounting, credited to "
                 "no cause (`imu_mounting` \"free\"; a manifest that says \"calibrated\" keeps it as evidence).")
    else:
        said += "The manifest says the IMU's mounting is calibrated, so it is evidence like the rest."
    return [said, ""]


def _candidates_table(result: DiagnosisResult) -> list[str]:
    """Every candidate's held-out gain and significance, and the registration's pose evidence."""
    lines = ["| candidate extension | physical cause | held-out gain | per kind of run | significant |",
             "|---|---|---|---|---|"]
    for c in result.candidates:
        cell = significance(c, named_with(result, c))
        lines.append(f"| {c.name} | {c.cause} | {c.gain:+.1%} | {by_kind(c)} | {cell} |")
    lines.append("")
    for c in result.candidates:
        if c.kinematic and c.kinematic.scans and len(c.kinematic.scans) > 1:
            lines += [f"The registration ({c.name}) is judged on the measured pose, not on the replay, one per scan: "
                      f"fitted on the training blocks of the terrain runs on a scan, it is evidence that the scan "
                      f"is misregistered when it explains their held-out blocks' height, pitch and roll at least "
                      f"{result.criteria.registration_held_out_ratio:g} times better than the scan as it is.", "",
                      "| scan | terrain runs | held-out ratio | misregistered | offsets x, y, z (m), yaw (rad), slopes x, y |",
                      "|---|---|---|---|---|"]
            for s in c.kinematic.scans:
                ratio = "too short to test" if s.ratio is None else f"{s.ratio:.3g}"
                offsets = ", ".join(f"{s.offsets.get(k, 0.0):+.3f}" for k in OFFSET_NAMES)
                lines.append(f"| {s.scan} | {', '.join(s.runs)} | {ratio} | {'yes' if s.misregistered else 'no'} "
                             f"| {offsets} |")
            lines.append("")
        elif c.kinematic:
            k = c.kinematic
            lines += [f"The registration ({c.name}) is judged on the measured pose, not on the replay: fitted on "
                      f"the terrain run's training blocks, it explains the held-out blocks' height, pitch and roll "
                      f"{k.ratio:.3g} times better than the scan as it is (mean squared scaled residual "
                      f"{k.held_out_ms_as_scanned:.3g} against {k.held_out_ms_registered:.3g}; evidence from "
                      f"{result.criteria.registration_held_out_ratio:g} times).", ""]
        said = pose_only_sentence(result, c)
        if said:
            lines += [f"The registration is {said}.", ""]
    return lines


def _cause_lines(result: DiagnosisResult) -> list[str]:
    """The cause, the comparisons, ties, the second round, and the extended model's gain per signal."""
    lines = [f"**Cause: {result.cause}** - {CANDIDATES[result.cause].cause}.", ""]
    for duel in result.head_to_head:
        lines += [duel_sentence(duel), ""]
    if result.equally_good:
        lines += ["Explaining the data about as well: " + ", ".join(result.equally_good) + ".", ""]
    for a in result.telling_apart:
        lines += [apart_sentence(a), ""]
    if result.second_round:
        lines += [f"Further causes on top of {result.cause} (each refitted together with it):", "",
                  "| candidate extension | further held-out gain | per kind of run | significant |",
                  "|---|---|---|---|"]
        for c in result.second_round:
            lines.append(f"| {c.name} | {c.gain:+.1%} | {by_kind(c)} | {significance(c)} |")
        lines.append("")
        if len(result.causes) > 1:
            lines += [f"**Second cause: {result.causes[1]}** - {CANDIDATES[result.causes[1]].cause}. "
                      "The extended model below has both.", ""]
    extension = result.extended.extension or {}
    lines += ["Fitted extension parameters: " + ", ".join(f"{k} = {v:.4g}" for k, v in extension.items())
              + ".", "", f"Held-out RMS per signal on the {' and '.join(result.gain.judged_on)} runs, "
              "where the extension was fitted:", "",
              "| signal | held-out RMS before | after | gain |", "|---|---|---|---|"]
    for k, g in result.gain.per_signal.items():
        lines.append(f"| {k} | {g.before:.4g} | {g.after:.4g} | {g.relative:+.1%} |")
    lines.append("")
    return lines
