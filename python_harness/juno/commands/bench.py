"""``juno bench``: the benchmark of the performance targets; prints figures, asserts nothing."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..core import progress_printer, write_json
from .options import int_at_least, positive_int

HELP = "benchmark the contact laws, the FMU and the workflow; prints figures"
OUTPUTS: dict[str, str] = {}


def add_arguments(p: argparse.ArgumentParser) -> None:
    from ..bench import SECTIONS
    p.description = ("Benchmark the contact laws, the FMU (from C and through fmpy) and the identification "
                     "workflow. Prints medians of repeated runs next to the performance targets; asserts "
                     "nothing.")
    p.add_argument("--quick", action="store_true",
                   help="5 repeats of the micro-benchmarks and shorter contact batches, 1 joint fit")
    p.add_argument("--repeats", type=int_at_least(5), default=None, metavar="N",
                   help="repeats of the micro-benchmarks (contact, FMU runs, cost function); >= 5, "
                        "default 7 (5 with --quick)")
    p.add_argument("--long-repeats", type=positive_int, default=None, metavar="N",
                   help="repeats of the joint identification, default 3 (1 with --quick)")
    p.add_argument("--with-diagnose", action="store_true",
                   help="also time juno diagnose on the synthetic campaign (takes minutes; one run)")
    p.add_argument("--only", action="append", choices=SECTIONS, metavar="SECTION",
                   help="run only these sections (repeatable): " + ", ".join(SECTIONS))
    p.add_argument("--build-dir", metavar="DIR",
                   help="CMake build directory holding the FMU and the bench programs (default: build/ of "
                        "this checkout)")
    p.add_argument("--no-build", action="store_true",
                   help="do not run cmake --build for the bench programs (use them as they are)")


def run(args: argparse.Namespace) -> int:
    from ..bench import run_benchmarks
    record = run_benchmarks(quick=args.quick, repeats=args.repeats, long_repeats=args.long_repeats,
                            sections=args.only, with_diagnose=args.with_diagnose,
                            build_dir=Path(args.build_dir) if args.build_dir else None, build=not args.no_build,
                            fmu_path=Path(args.fmu) if args.fmu else None, say=progress_printer(args.quiet))
    write_json(args.json, record, "bench")
    return 0
