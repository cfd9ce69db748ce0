"""``juno simulate``: a built-in scenario, or a measured run of a campaign, through the FMU."""

from __future__ import annotations

import argparse
import tempfile

from ..atomic import atomic_write_text
from ..core import progress_printer, write_json
from ..fmu_parameters import check_parameters, parse_assignments
from ..scenarios import SCENARIOS
from .options import positive_float, scenario_help

HELP = "run a scenario or a measured run through the FMU"
OUTPUTS = {"out": "file"}


def add_arguments(p: argparse.ArgumentParser) -> None:
    src = p.add_mutually_exclusive_group()
    src.add_argument("--scenario", choices=sorted(SCENARIOS), default="drawbar", help=scenario_help(SCENARIOS))
    src.add_argument("--campaign", metavar="DIR", help="simulate a measured run of this campaign")
    p.add_argument("--run", help="run id (with --campaign; default: the first run)")
    p.add_argument("--param", action="append", metavar="NAME=VALUE", help="set an FMU parameter (repeatable)")
    p.add_argument("--stop-time", type=positive_float, help="seconds (scenarios)")
    p.add_argument("--output-interval", type=positive_float, default=0.05, help="seconds (default 0.05)")
    p.add_argument("--out", metavar="CSV", help="write all outputs to CSV")


def run(args: argparse.Namespace) -> int:
    from ..campaign import format_run_csv, load_campaign
    from ..simulator import DEFAULT_OUTPUTS, InputSignals, JunoFMU
    say = progress_printer(args.quiet)
    params = check_parameters(parse_assignments(args.param), args.fmu)
    with JunoFMU(args.fmu) as fmu:
        if args.campaign:
            from ..identify import prepare_run
            from ..plausibility import enforce_plausibility
            from ..validate import grid_terrain
            campaign = load_campaign(args.campaign)
            enforce_plausibility(campaign, force=args.force, fmu=args.fmu)
            run_spec = campaign.run(args.run) if args.run else campaign.runs[0]
            with tempfile.TemporaryDirectory() as tmp:
                grid = str(grid_terrain(campaign, run_spec, tmp)[0]) if run_spec.kind == "terrain" else None
                prep = prepare_run(campaign, run_spec, terrain_file=grid)
                say(f"simulating measured run {run_spec.id} ({prep.duration:.1f} s, following the measured "
                    "wheel spins)")
                result = fmu.simulate({**prep.params, **params}, prep.inputs, prep.duration,
                                      args.output_interval, outputs=DEFAULT_OUTPUTS)
            label = f"run {run_spec.id} of {campaign.name}"
        else:
            scenario = SCENARIOS[args.scenario]
            stop = args.stop_time if args.stop_time is not None else scenario.stop_time
            say(f"simulating scenario '{args.scenario}': {scenario.description}")
            result = fmu.simulate({**scenario.params, **params}, InputSignals.constant(**scenario.inputs), stop,
                                  args.output_interval, outputs=DEFAULT_OUTPUTS)
            label = f"scenario {args.scenario}"
    if args.out:
        atomic_write_text(args.out, format_run_csv(result))
        say(f"wrote {args.out}")
    final = {k: float(v[-1]) for k, v in result.items()}
    print(f"{label}: t = {final['time']:.2f} s, x = {final['x']:.3f} m, y = {final['y']:.3f} m, "
          f"vx = {final['vx']:.4f} m/s, slip FL = {final['wheelFL.slip']:.4f}, "
          f"sinkage FL/RL = {final['wheelFL.sinkage'] * 1000:.1f}/{final['wheelRL.sinkage'] * 1000:.1f} mm")
    write_json(args.json, {"label": label, "final": final}, "simulate")
    return 0
