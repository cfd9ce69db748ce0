"""The ``juno`` command: simulate, identify, validate, synthesize, report, sweep, diagnose, bench.

A thin layer: the subcommands live in :mod:`juno.commands`, one module each, defined the same
way.  Before any computation every subcommand's arguments are checked (numbers by argparse,
``--param`` against the FMU's variable table, ``--params`` files) and so are its output paths
(:mod:`juno.outputs`).  Errors are one line ``juno CMD: error: ...`` and exit code 2; Ctrl-C
prints ``juno: interrupted`` (exit 130), SIGTERM ``juno: terminated`` (exit 143).  Every
temporary file of a command, its worker processes' included, lives in one folder of its own
(:func:`scratch_folder`), removed when the command ends in any of those ways.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import re
import shutil
import signal
import sys
import tempfile
import threading
from typing import Any, Iterator, Sequence

from . import __version__
from .commands import COMMANDS
from .commands.options import add_common_options
from .errors import InputError
from .outputs import PLOTS_MARKER, REPORT_MARKER, campaign_inputs, check_campaign_dir, check_output_dir, \
    check_output_file
from .parallel import SchedulerError, TaskError
from .simulator import SimulationError

EPILOG = "Every subcommand has --help. Results go to --json FILE as well as to the screen."


class OneLineParser(argparse.ArgumentParser):
    """A subcommand's parser whose errors are one line, ``juno CMD: error: ...`` (exit code 2),
    like every other refusal of the command; the usage is in ``--help``."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    """The ``juno`` parser: one subparser per module of :mod:`juno.commands`."""
    parser = argparse.ArgumentParser(prog="juno", description="JunoRover volumetric wheel/soil model: simulate, "
                                     "identify, validate, synthesize, diagnose, report.", epilog=EPILOG)
    parser.add_argument("--version", action="version", version=f"juno {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=OneLineParser)
    for name, module in COMMANDS.items():
        p = sub.add_parser(name, help=module.HELP)
        module.add_arguments(p)
        add_common_options(p)
        p.set_defaults(func=module.run)
    return parser


# ------------------------------------------------------------ output paths

def input_paths(args: argparse.Namespace) -> list[Any]:
    """The paths a command reads: the campaign folder, a --params file, files given as --param
    values, the FMU, a build folder."""
    from .simulator import default_fmu_path
    inputs: list[Any] = list(campaign_inputs(getattr(args, "campaign", None)))
    inputs.append(getattr(args, "params", None))
    inputs.append(getattr(args, "build_dir", None))
    for item in getattr(args, "param", None) or ():   # a file given as a parameter (terrain.file=...)
        value = item.split("=", 1)[-1].strip()
        if value and os.path.exists(value):
            inputs.append(value)
    try:
        inputs.append(getattr(args, "fmu", None) or default_fmu_path())
    except Exception:  # no default FMU: the command reports that itself
        pass
    return inputs


def check_output_paths(args: argparse.Namespace) -> None:
    """Refuse, before any computation, an output path that would destroy an input or a user's
    folder, or that cannot be written (:mod:`juno.outputs`)."""
    inputs = input_paths(args)
    outputs = COMMANDS[args.command].OUTPUTS
    for attr, kind in outputs.items():
        out = getattr(args, attr, None)
        flag = "OUT" if kind == "campaign" else f"--{attr}"
        if kind == "file":
            check_output_file(out, inputs, flag)
        elif kind == "report":
            check_output_dir(out, inputs, flag, REPORT_MARKER, "juno report")
        elif kind == "plots":
            check_output_dir(out, inputs, flag, PLOTS_MARKER, "juno diagnose --plots")
        elif kind == "campaign":
            check_campaign_dir(out, inputs, flag, overwrite=getattr(args, "overwrite", False))
        else:
            raise AssertionError(f"juno {args.command}: unknown kind of output {kind!r}")
    json_path = getattr(args, "json", None)
    check_output_file(json_path, inputs, "--json")
    for attr in outputs:
        out = getattr(args, attr, None)
        if json_path and out and os.path.realpath(json_path) == os.path.realpath(out):
            raise InputError(f"--json {json_path} and --{attr} {out} are the same path; give two")


# ------------------------------------------------------------------ main

class Terminated(KeyboardInterrupt):
    """SIGTERM, turned into an exception so that the ``finally`` blocks and context managers on
    the way out run (worker processes stopped, temporary folders removed, nothing half-written)."""


def _on_sigterm(signum, frame) -> None:
    raise Terminated()


def _message(exc: BaseException) -> str:
    """The text of an error for the one-line message (a bare KeyError's quotes removed)."""
    if isinstance(exc, KeyError) and len(exc.args) == 1 and isinstance(exc.args[0], str):
        return exc.args[0]
    if isinstance(exc, OSError) and exc.filename is not None and exc.strerror:
        return f"{exc.filename}: {exc.strerror}"
    # A NumPy scalar's repr (np.float64(0.5)) read as its number, wherever a message took it from.
    return re.sub(r"np\.(?:float|int|uint)\d*\(([^()]*)\)", r"\1", str(exc))


@contextlib.contextmanager
def scratch_folder() -> Iterator[str]:
    """A folder of the command's own in the system's temporary folder, made the temporary folder
    of this process and of every process it starts (tempfile.tempdir, and TMPDIR for processes
    started afresh) while the command runs, and removed with all it holds when the command ends,
    however it ends but by SIGKILL.  Why: a worker process stopped in the middle of a task (the
    pool terminates its workers on Ctrl-C, SIGTERM or a failed task) may be stopped before its
    own clean-up has removed what it made (the FMU it extracted); its files are in this folder,
    so they go with it."""
    root = tempfile.mkdtemp(prefix="juno-run-")
    saved_dir, saved_env = tempfile.tempdir, os.environ.get("TMPDIR")
    tempfile.tempdir = os.environ["TMPDIR"] = root
    try:
        yield root
    finally:
        tempfile.tempdir = saved_dir
        if saved_env is None:
            os.environ.pop("TMPDIR", None)
        else:
            os.environ["TMPDIR"] = saved_env
        shutil.rmtree(root, ignore_errors=True)


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    previous = previous_int = None
    if threading.current_thread() is threading.main_thread():
        previous = signal.signal(signal.SIGTERM, _on_sigterm)
        # Ctrl-C as the module docstring says even when juno was started with SIGINT ignored (a
        # background job of a non-interactive shell inherits that, and Python then keeps it).
        previous_int = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        check_output_paths(args)
        with scratch_folder():
            return int(args.func(args) or 0)
    except (InputError, SimulationError, FileNotFoundError, FileExistsError, KeyError, ValueError,
            TaskError, SchedulerError, OSError) as exc:
        print(f"juno {args.command}: error: {_message(exc)}", file=sys.stderr)
        return 2
    except Terminated:
        print("juno: terminated", file=sys.stderr)
        return 128 + signal.SIGTERM
    except KeyboardInterrupt:
        print("juno: interrupted", file=sys.stderr)
        return 130
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
        if previous_int is not None:
            signal.signal(signal.SIGINT, previous_int)


if __name__ == "__main__":
    sys.exit(main())
