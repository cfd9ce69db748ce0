"""``juno sweep``: a scenario simulated over a grid of FMU parameter values, one summary row per
point."""

from __future__ import annotations

import argparse

from ..atomic import atomic_write_text
from ..core import progress_printer, write_json
from ..errors import InputError
from ..fmu_parameters import fmu_variables, parameter_value, parse_assignments
from ..scenarios import SCENARIOS
from .options import add_batch_options, positive_float, scenario_help

HELP = "simulate a scenario over a grid of FMU parameter values; CSV/JSON of summary outputs"
OUTPUTS = {"out": "file"}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--scenario", choices=sorted(SCENARIOS), default="drawbar", help=scenario_help(SCENARIOS))
    p.add_argument("--vary", action="append", metavar="NAME=VALUES", required=True,
                   help="an FMU parameter and its values: v1,v2,... or start:stop:n (repeatable; all "
                        "combinations are simulated, the last --vary changing fastest)")
    p.add_argument("--param", action="append", metavar="NAME=VALUE", help="a fixed FMU parameter (repeatable)")
    p.add_argument("--stop-time", type=positive_float, help="seconds (default: the scenario's)")
    p.add_argument("--output-interval", type=positive_float, default=0.05, help="seconds (default 0.05)")
    p.add_argument("--window", type=positive_float,
                   help="summarize the last WINDOW seconds (default: the last quarter)")
    p.add_argument("--out", metavar="CSV", help="write one row per point to CSV")
    add_batch_options(p)


def _varied_values(items: list[str], variables) -> dict[str, list[object]]:
    """--vary NAME=VALUES as typed, range-checked values by parameter name."""
    from ..sweep import parse_values
    vary: dict[str, list[object]] = {}
    for item in items:
        if "=" not in item:
            raise InputError(f"--vary expects NAME=VALUES, got '{item}'")
        name, values = (s.strip() for s in item.split("=", 1))
        if name in vary:
            raise InputError(f"--vary {name} given twice")
        vary[name] = [parameter_value(variables, name, v, "--vary") for v in parse_values(values)]
    return vary


def run(args: argparse.Namespace) -> int:
    from ..simulator import InputSignals, JunoFMU
    from ..sweep import format_csv, grid, sweep
    say = progress_printer(args.quiet)
    variables = fmu_variables(args.fmu)
    vary = _varied_values(args.vary, variables)
    scenario = SCENARIOS[args.scenario]
    stop = args.stop_time if args.stop_time is not None else scenario.stop_time
    fixed = {**scenario.params, **{name: parameter_value(variables, name, value)
                                   for name, value in parse_assignments(args.param).items()}}
    points = grid(vary)
    say(f"sweeping scenario '{args.scenario}' ({scenario.description}) over {len(points)} points")
    with JunoFMU(args.fmu) as fmu:
        result = sweep(fmu, points, fixed, InputSignals.constant(**scenario.inputs), stop, args.output_interval,
                       args.window, workers=args.workers, scheduler=args.scheduler, progress=say)
    if args.out:
        atomic_write_text(args.out, format_csv(result))
        say(f"wrote {args.out}")
    failed = [p for p in result if p.error]
    shown = ("mean.vx", "mean.wheelFL.slip", "mean.wheelFL.sinkage")
    for p in result:
        label = ", ".join(f"{k} = {v:.4g}" for k, v in p.params.items())
        if p.error:
            print(f"{label}: failed: {p.error}")
        else:
            print(f"{label}: " + ", ".join(f"{c} {p.summary[c]:.4g}" for c in shown))
    print(f"{len(result)} points, {len(failed)} failed")
    write_json(args.json, {"scenario": args.scenario, "stop_time": stop, "fixed": fixed, "vary": vary,
                           "points": [{"params": p.params, "summary": p.summary, "error": p.error}
                                      for p in result]}, "sweep")
    return 0
