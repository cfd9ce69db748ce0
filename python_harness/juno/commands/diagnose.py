"""``juno diagnose``: what the simulation gets wrong in a campaign, the physical cause named
from a catalogue of model extensions, and the gain measured on held-out data."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..core import progress_printer, write_json
from .options import add_batch_options, positive_float

HELP = "find what the simulation gets wrong, name the cause, measure the gain"
OUTPUTS = {"plots": "plots"}

#: The names of the diagnosis's candidates (juno.diagnose.CANDIDATES), sorted: the choices of
#: --candidates.  Written out so that building the parser, on every ``juno`` start, does not
#: import the diagnosis (SciPy's optimizers, half a second); a test keeps it equal to the catalogue.
CANDIDATE_NAMES = ("drivetrain_loss", "grouser", "multipass", "payload", "slip_sinkage", "soil_patch", "terrain_offset")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("campaign", metavar="CAMPAIGN")
    add_batch_options(p, "the candidate fits")
    p.add_argument("--candidates", nargs="+", choices=CANDIDATE_NAMES, help="only these candidates")
    p.add_argument("--plots", metavar="DIR",
                   help="write residual plots to DIR (new, empty, or written by diagnose --plots before)")
    p.add_argument("--terrain-segments", type=positive_float, metavar="SECONDS",
                   help="experimental: replay the terrain run in pieces of SECONDS, each restarted at the "
                        "measured pose and speed (needs a 'yaw' column), so that a heading drift cannot grow")


def run(args: argparse.Namespace) -> int:
    from ..campaign import load_campaign
    from ..diagnose import diagnose, public_json, residual_figures, summary_lines
    from ..outputs import PLOTS_MARKER, campaign_inputs, marked_directory
    from ..plausibility import enforce_plausibility
    from ..simulator import JunoFMU
    say = progress_printer(args.quiet)
    campaign = load_campaign(args.campaign)
    enforce_plausibility(campaign, force=args.force, fmu=args.fmu)
    result = diagnose(campaign, fmu=JunoFMU(args.fmu) if args.fmu else None, workers=args.workers,
                      candidates=args.candidates, progress=say, scheduler=args.scheduler,
                      terrain_segment=args.terrain_segments)
    if args.plots:
        with marked_directory(args.plots, PLOTS_MARKER, "juno diagnose --plots",
                              inputs=campaign_inputs(args.campaign), what="--plots") as tmp:
            residual_figures(result, Path(tmp))
    write_json(args.json, public_json(result), "diagnose")
    for line in summary_lines(result):
        print(line)
    print(f"diagnosis took {result.wall_time:.0f} s", file=sys.stderr)
    return 0
