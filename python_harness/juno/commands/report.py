"""``juno report``: identify, validate (and diagnose) a campaign and write a Markdown report
with its figures."""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

from ..core import progress_printer, write_json

HELP = "identify, validate (and diagnose) and write a Markdown report"
OUTPUTS = {"out": "report"}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("campaign", metavar="CAMPAIGN")
    p.add_argument("--out", metavar="DIR", required=True,
                   help="report folder: new, empty, or written by juno report before (then replaced whole)")
    p.add_argument("--diagnose", action="store_true", help="include the discrepancy diagnosis")
    p.add_argument("--rig-fmu", metavar="FMU",
                   help="the WheelRig FMU for the wheel_rig runs (default: build/WheelRig.fmu or $JUNO_RIG_FMU)")


def run(args: argparse.Namespace) -> int:
    from ..campaign import load_campaign
    from ..identify import identify_joint, identify_paper_runs, require_runs
    from ..plausibility import enforce_plausibility
    from ..report import write_report
    from ..simulator import JunoFMU
    from ..validate import validate_run
    say = progress_printer(args.quiet)
    campaign = load_campaign(args.campaign)
    enforce_plausibility(campaign, force=args.force, fmu=args.fmu)
    timings: dict[str, float] = {}
    rig = None
    if campaign.runs_of_kind("wheel_rig"):
        from ..wheel_rig import RigFMU
        from ..wheel_rig_report import rig_results
        t = time.perf_counter()
        say("fitting both contact laws to the wheel_rig runs")
        with RigFMU(args.rig_fmu) as rig_fmu:
            rig = rig_results(rig_fmu, campaign, progress=say)
        timings["single-wheel testbed fits"] = time.perf_counter() - t
        if not campaign.runs_of_kind("drawbar"):
            path = write_report(args.out, campaign, [], None, [], rig=rig, timings=timings)
            print(f"wrote report {path}")
            write_json(args.json, {"report": str(path), "rig": {law: f.params for law, f in rig.fits.items()},
                                   "timings": timings}, "report")
            return 0
    require_runs(campaign, "report")
    with JunoFMU(args.fmu) as fmu:
        t = time.perf_counter()
        say("paper-style identification of every drawbar run (one task per run, on the cores)")
        paper = identify_paper_runs(fmu, campaign, progress=say)
        timings["paper-style identification (all runs)"] = time.perf_counter() - t
        t = time.perf_counter()
        say("joint identification")
        joint = identify_joint(fmu, campaign, progress=say)
        timings["joint identification"] = time.perf_counter() - t
        t = time.perf_counter()
        validations = []
        best_paper = min(paper, key=lambda p: p.cost) if paper else None
        with tempfile.TemporaryDirectory() as tmp:
            for run_spec in campaign.runs_of_kind("terrain"):
                say(f"validating on {run_spec.id}")
                v = validate_run(fmu, campaign, run_spec, joint.params, tmp)
                validations.append(("joint fit", v))
                if best_paper:
                    validations.append((f"paper-style {best_paper.run_id}",
                                        validate_run(fmu, campaign, run_spec, best_paper.final, tmp,
                                                     grid_file=v.grid_file)))
        timings["validation"] = time.perf_counter() - t
        diagnosis = None
        if args.diagnose:
            from ..diagnose import diagnose
            t = time.perf_counter()
            say("diagnosing what the model gets wrong")
            diagnosis = diagnose(campaign, fmu=fmu, progress=say)
            timings["diagnosis"] = time.perf_counter() - t
    truth_path = Path(campaign.root) / "truth.json"
    truth = json.loads(truth_path.read_text()) if truth_path.is_file() else None
    path = write_report(args.out, campaign, paper, joint, validations, diagnosis, truth=truth, timings=timings,
                        rig=rig)
    print(f"wrote report {path}")
    write_json(args.json, {"report": str(path), "joint": joint.params, "timings": timings}, "report")
    return 0
