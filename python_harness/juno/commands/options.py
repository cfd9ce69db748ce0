"""Argument types and the options several subcommands share.

Every numeric option is checked by argparse with one of the ``type=`` functions here, so a
negative count or a NaN is refused with a one-line message before anything runs.
"""

from __future__ import annotations

import argparse
import re
from typing import Callable, TypeVar

from ..errors import InputError, parse_finite

T = TypeVar("T", int, float)


def _typed(kind: type, test: Callable[[T], bool], wanted: str) -> Callable[[str], T]:
    """An argparse ``type=`` function: parse ``kind`` (int, or a finite float), then ``test``."""
    def parse(text: str):
        try:
            if kind is int:
                if not re.fullmatch(r"\s*[+-]?[0-9]+\s*", text):
                    raise ValueError
                value = int(text)
            else:
                value = parse_finite(text)
        except (ValueError, InputError):
            raise argparse.ArgumentTypeError(f"must be {wanted}, got '{text}'") from None
        if not test(value):
            raise argparse.ArgumentTypeError(f"must be {wanted}, got '{text}'")
        return value
    parse.__name__ = wanted   # argparse names the type in some messages
    return parse


positive_int = _typed(int, lambda v: v >= 1, "a positive integer")
nonnegative_int = _typed(int, lambda v: v >= 0, "an integer >= 0")
positive_float = _typed(float, lambda v: v > 0, "a positive finite number")
nonnegative_float = _typed(float, lambda v: v >= 0, "a finite number >= 0")
fraction = _typed(float, lambda v: 0 <= v <= 1, "a number from 0 to 1")


def int_at_least(low: int) -> Callable[[str], int]:
    """``type=`` for an integer >= ``low``."""
    return _typed(int, lambda v: v >= low, f"an integer >= {low}")


def add_common_options(p: argparse.ArgumentParser) -> None:
    """--json, --fmu, --quiet and --force, which every subcommand has."""
    p.add_argument("--json", metavar="FILE", help="write the machine-readable result to FILE")
    p.add_argument("--fmu", metavar="FMU", help="the FMU (default: build/JunoRover.fmu or $JUNO_FMU)")
    p.add_argument("--quiet", action="store_true", help="no progress messages")
    p.add_argument("--force", action="store_true",
                   help="go on despite implausible measured data (its errors are printed as warnings)")


def add_batch_options(p: argparse.ArgumentParser, what: str = "the batch") -> None:
    """--workers and --scheduler of the subcommands that run batches (:mod:`juno.parallel`)."""
    p.add_argument("--workers", type=positive_int, default=None, metavar="N",
                   help=f"local worker processes for {what} (default: one per core; 1 = no pool)")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help=f"run {what} on the Dask distributed cluster at ADDRESS (tcp://host:port); its "
                        "workers need the FMU (and the campaign folder) at the same paths as here")


def scenario_help(scenarios) -> str:
    """The --scenario help text: every scenario and what it does (``%`` escaped for argparse)."""
    return "; ".join(f"{k}: {s.description}" for k, s in scenarios.items()).replace("%", "%%")
