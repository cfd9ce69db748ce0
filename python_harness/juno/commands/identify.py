"""``juno identify``: the soil parameters from a campaign's drawbar runs, per run as the paper
does and jointly over every run's whole time series; from its wheel_rig runs (single-wheel
testbed tables) by a least-squares fit of each contact law (juno.wheel_rig)."""

from __future__ import annotations

import argparse
import tempfile
from typing import Any

from ..core import progress_printer, write_json
from .options import add_batch_options, nonnegative_int, positive_int

HELP = "identification of the soil parameters (drawbar runs; single-wheel testbed tables)"
OUTPUTS: dict[str, str] = {}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("campaign", metavar="CAMPAIGN")
    p.add_argument("--method", choices=("paper", "joint", "both", "rig"), default="both",
                   help="paper: per drawbar run from steady-window averages; joint: all runs, whole time series; "
                        "both: paper and joint on the drawbar runs (and the rig fit when the campaign has "
                        "wheel_rig runs; a campaign of wheel_rig runs only gets the rig fit alone); rig: only the "
                        "fit of the wheel_rig runs")
    p.add_argument("--law", choices=("volumetric", "wong-reece", "both"), default="both",
                   help="rig fit: the contact law(s) fitted to the wheel_rig runs (default both, side by side)")
    p.add_argument("--slip-sinkage", action="store_true",
                   help="rig fit: fit the slip-sinkage coefficient with the volumetric law too (sinkage rising "
                        "with slip, which testbeds measure)")
    p.add_argument("--rig-fmu", metavar="FMU",
                   help="rig fit: the WheelRig FMU (default: build/WheelRig.fmu or $JUNO_RIG_FMU)")
    p.add_argument("--with-terrain", action="store_true", help="include the terrain runs in the joint fit")
    p.add_argument("--optimizer", choices=("least-squares", "nelder-mead"), default="least-squares",
                   help="joint fit: trust-region Gauss-Newton (default) or Nelder-Mead then a polish")
    p.add_argument("--max-evaluations", type=positive_int, default=400,
                   help="the joint fit's budget of model evaluations, each Jacobian's four points included; "
                        "a fit that uses it without converging says so (default 400)")
    p.add_argument("--starts", type=positive_int, default=1,
                   help="joint fit from N starting points (the paper's guess and N-1 scattered around it), "
                        "one parallel task each; reports the best and how far the others ended (default 1)")
    p.add_argument("--replay-bias", choices=("auto", "on", "off"), default="auto",
                   help="joint fit: estimate the replay's own bias (a refit of the runs simulated with the fitted "
                        "soil, about 0.8 of a fit's time more) and add it to the uncertainty: auto (default) where "
                        "the fitted runs lack a column they use (no pitch, no yaw), on, or off (the uncertainty is "
                        "then the sensors' noise alone, which understates the error where a signal is missing)")
    p.add_argument("--seed", type=nonnegative_int, default=0,
                   help="seed of the scattered starting points (default 0)")
    add_batch_options(p)


def run(args: argparse.Namespace) -> int:
    from ..campaign import load_campaign, missing_columns
    from ..identify import identify_joint, identify_multistart, identify_paper_runs, terrain_grids
    from ..plausibility import enforce_plausibility
    from ..sensor_noise import noise_statements, stated_noise_lines
    from ..simulator import JunoFMU
    say = progress_printer(args.quiet)
    campaign = load_campaign(args.campaign)
    enforce_plausibility(campaign, force=args.force, fmu=args.fmu)
    batch = {"workers": args.workers, "scheduler": args.scheduler}
    missing = missing_columns(campaign, joint_fit_kinds(args))
    noise = noise_statements(campaign, joint_fit_kinds(args))
    out: dict[str, Any] = {"campaign": campaign.name, "missing_columns": missing, "sensor_noise": noise}
    has_rig = bool(campaign.runs_of_kind("wheel_rig"))
    if args.method == "rig" or (has_rig and args.method == "both"):
        out["rig"] = _rig_fits(campaign, args, say)
        if args.method == "rig" or not campaign.runs_of_kind("drawbar"):
            write_json(args.json, out, "identify")
            return 0
    with JunoFMU(args.fmu) as fmu:
        if args.method in ("paper", "both"):
            runs = campaign.runs_of_kind("drawbar")
            say("paper-style Nelder-Mead on " + ", ".join(r.id for r in runs))
            out["paper"] = identify_paper_runs(fmu, campaign, runs, progress=say, **batch)
            for p in out["paper"]:
                print(f"{p.run_id}: " + ", ".join(f"{k} = {v:.4g}" for k, v in p.final.items()) +
                      f" (cost {p.cost:.3g}, {p.evaluations} evaluations, rank {p.jacobian_rank}/4)")
                for caveat in paper_fit_caveats(p):
                    print(f"{p.run_id}: {caveat}")
            if any(p.jacobian_rank < len(p.final) for p in out["paper"]):
                print("paper: each run's steady averages are three numbers; the joint fit (--method joint) "
                      "gives every parameter with its uncertainty and says which are identifiable")
        if args.method in ("joint", "both"):
            with tempfile.TemporaryDirectory() as tmp:
                grid = terrain_grids(campaign, tmp, "identify --with-terrain") if args.with_terrain else None
                joint_args = dict(include_terrain=args.with_terrain, terrain_file=grid,
                                  max_evaluations=args.max_evaluations, optimizer=args.optimizer,
                                  estimate_bias={"auto": None, "on": True, "off": False}[args.replay_bias])
                if args.starts > 1:
                    say(f"joint identification from {args.starts} starting points (seed {args.seed})")
                    multi = identify_multistart(fmu, campaign, args.starts, seed=args.seed, progress=say,
                                                **batch, **joint_args)
                    joint = multi.best
                    out["multistart"] = {"starts": multi.starts, "costs": [f.cost for f in multi.fits],
                                         "params": [f.params for f in multi.fits], "spread": multi.spread,
                                         "wall_time": multi.wall_time}
                    print(f"multi-start: {args.starts} fits in {multi.wall_time:.1f} s; costs "
                          + ", ".join(f"{f.cost:.4g}" for f in multi.fits) + "; largest relative distance from "
                          "the best: " + ", ".join(f"{k} {v:.2%}" for k, v in multi.spread.items()))
                else:
                    say("joint identification over the whole time series")
                    joint = identify_joint(fmu, campaign, progress=say, **batch, **joint_args)
            out["joint"] = joint
            for k, v in joint.params.items():
                print(f"joint: {k} = {v:.5g} +- {joint.std[k]:.2g}{uncertainty_parts(joint, k)} "
                      f"({joint.identifiability[k]})")
            print(f"joint: {joint.evaluations} evaluations in {joint.wall_time:.1f} s; status {joint.status}")
            for line in pitch_offset_lines(joint):
                print(line)
            for doubt in joint.doubts:
                print(f"joint: doubtful: {doubt}")
    for m in missing:
        print(m.sentence())
    for line in stated_noise_lines(noise):
        print(line)
    write_json(args.json, out, "identify")
    return 0


def pitch_offset_lines(joint) -> list[str]:
    """What the joint fit made of the pitch's constant offset on each IMU mounting: a free
    parameter of the fit (the mounting's), or, where the manifest says the mounting is
    calibrated, what the fitted model's pitch residuals hold."""
    from ..imu_mounting import offsets_text
    if not joint.pitch_offset:
        return []
    if joint.pitch_offset_free:
        return [f"joint: the pitch reads {offsets_text(joint.pitch_offset)} from the fitted model's: the IMU's "
                "mounting, a free parameter of the fit (imu_mounting \"free\"; \"calibrated\" holds it at none)"]
    return [f"joint: the pitch reads {offsets_text(joint.pitch_offset)} from the fitted model's; the manifest says "
            "the IMU's mounting is calibrated, so the fit took no offset"]


def uncertainty_parts(joint, name: str) -> str:
    """The parts of a joint fit's 1 sigma of parameter ``name``, as printed after it: the
    sensors' noise and the replay's own bias (signed), or nothing when the bias was not estimated."""
    if name not in joint.replay_bias:
        return ""
    return f" (noise {joint.std_statistical[name]:.2g}, replay bias {joint.replay_bias[name]:+.2g})"


def joint_fit_kinds(args: argparse.Namespace) -> tuple[str, ...]:
    """The kinds of run whose optional columns the requested fits use: the joint fit's drawbar
    runs (and terrain runs, --with-terrain); the paper's steady averages and the rig fit use none."""
    if args.method not in ("joint", "both"):
        return ()
    return ("drawbar", "terrain") if args.with_terrain else ("drawbar",)


def paper_fit_caveats(fit) -> list[str]:
    """What a reader of one paper-style fit (identify.PaperResult) must know before using its
    values: a fit that did not converge, or whose run determines fewer parameter combinations
    than there are parameters (the rest of the values are wherever the simplex stopped)."""
    caveats = []
    if fit.status != "ok":
        caveats.append(f"{fit.status}: the fit did not move from its start or the averages see no "
                       "parameter; these values are not an estimate")
    elif not fit.converged:
        caveats.append(f"not converged within {fit.evaluations} evaluations; the values are where the "
                       "search stopped")
    n = len(fit.final)
    if fit.status == "ok" and fit.jacobian_rank < n:
        caveats.append(f"rank {fit.jacobian_rank}/{n}: the run's averages determine only {fit.jacobian_rank} "
                       f"combination{'s' if fit.jacobian_rank != 1 else ''} of the {n} parameters; "
                       "along the others the values are not determined by the data")
    return caveats


def _rig_fits(campaign, args: argparse.Namespace, say) -> dict[str, Any]:
    """The rig fit of each requested contact law on the campaign's wheel_rig runs, printed."""
    from ..wheel_rig import RigFMU, check_determined, fit_rig, law_parameters, rig_runs
    runs = rig_runs(campaign)
    laws = ("volumetric", "wong-reece") if args.law == "both" else (args.law,)
    both = {r.setup.lugged for r in runs} == {True, False}
    for law in laws:  # before the FMU is opened: the tables alone decide it
        check_determined(runs, law_parameters(law, both, args.slip_sinkage and law == "volumetric"), law,
                         campaign.manifest_path)
    fits: dict[str, Any] = {}
    with RigFMU(args.rig_fmu) as fmu:
        for law in laws:
            say(f"rig fit ({law} contact law) of " + ", ".join(r.run_id for r in runs))
            fit = fit_rig(fmu, campaign, law, runs=runs, slip_sinkage=args.slip_sinkage and law == "volumetric",
                          progress=say)
            fits[law] = fit
            for k, v in fit.params.items():
                print(f"rig {law}: {k} = {v:.5g} +- {fit.std[k]:.2g} ({fit.identifiability[k]})")
            print(f"rig {law}: rms error " + ", ".join(f"{c} {v:.3g}" for c, v in fit.rms.items()) +
                  f"; noise {', '.join(f'{c}: {n}' for c, n in fit.noise.items())}; {fit.evaluations} "
                  f"evaluations in {fit.wall_time:.1f} s; status {fit.status}")
            for doubt in fit.doubts:
                print(f"rig {law}: doubtful: {doubt}")
    return fits
