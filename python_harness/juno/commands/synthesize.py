"""``juno synthesize``: a synthetic measured campaign with a hidden effect (the truth only in
its ``truth.json``)."""

from __future__ import annotations

import argparse

from ..core import progress_printer, write_json
from .options import fraction, nonnegative_float, nonnegative_int, positive_float

HELP = "write a synthetic measured campaign with a hidden effect"
OUTPUTS = {"out": "campaign"}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("out", metavar="OUT")
    p.add_argument("--effect", action="append", metavar="EFFECT",
                   help="effect id to hide (default none = nothing); repeat to hide several at once; "
                        "the catalog, alternative forms and decoys are listed in juno.effects")
    p.add_argument("--strength", type=fraction, action="append", metavar="S",
                   help="effect strength, 0 to 1 (default 1); one for all effects, or one per --effect in order")
    p.add_argument("--seed", type=nonnegative_int, default=0, help="seed of the truth and the noise (default 0)")
    p.add_argument("--noise", type=nonnegative_float, default=1.0, help="sensor noise scale (0 = exact)")
    p.add_argument("--time-scale", type=positive_float, default=1.0, help="shorten runs (< 1) for quick tests")
    p.add_argument("--heavy-run", action="store_true",
                   help="one drawbar run held at about 70 %% slip at 80 %% throttle (instead of the "
                        "720 N one; the others 320 and 620 N): separates grouser thrust from K_vx")
    p.add_argument("--design", choices=("default", "alt"), default="default",
                   help="campaign layout: default = the paper's (three drawbar runs at 45 %% throttle, a "
                        "mound); alt = four drawbar runs at 50-60 %% throttle, a ridge, other instruments, "
                        "clocks not at zero, columns in another order")
    p.add_argument("--overwrite", action="store_true",
                   help="replace an existing OUT written by juno synthesize (never another folder)")


def run(args: argparse.Namespace) -> int:
    from ..synthesize import synthesize
    say = progress_printer(args.quiet)
    path = synthesize(args.out, effect=args.effect or ["none"], strength=args.strength or [1.0], seed=args.seed,
                      noise=args.noise, time_scale=args.time_scale, overwrite=args.overwrite, progress=say,
                      heavy_run=args.heavy_run, design=args.design)
    print(f"wrote campaign {path} (effect hidden: see {path}/truth.json only)")
    write_json(args.json, {"campaign": str(path)}, "synthesize")
    return 0
