"""The ``juno`` command: simulate, identify, validate, synthesize, report, sweep, diagnose, bench.

Before any computation every subcommand checks its arguments (numbers by argparse, ``--param``
against the FMU's variable table, ``--params`` files) and its output paths
(:mod:`juno.outputs`).  Errors are one line ``juno CMD: error: ...`` and exit code 2; Ctrl-C
prints ``juno: interrupted`` (exit 130), SIGTERM ``juno: terminated`` (exit 143).
"""

from __future__ import annotations

import argparse
import difflib
import json
import math
import os
import re
import signal
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from . import __version__
from .atomic import atomic_write_text
from .errors import InputError, parse_finite
from .outputs import (PLOTS_MARKER, REPORT_MARKER, campaign_inputs, check_campaign_dir, check_output_dir,
                      check_output_file)
from .parallel import SchedulerError, TaskError
from .simulator import SimulationError

EPILOG = "Every subcommand has --help. Results go to --json FILE as well as to the screen."


def _progress(quiet: bool):
    start = time.perf_counter()

    def say(message: str) -> None:
        if not quiet:
            print(f"[{time.perf_counter() - start:7.1f} s] {message}", file=sys.stderr, flush=True)
    return say


def _to_jsonable(obj: Any) -> Any:
    """JSON-safe copy: tuples and arrays as lists, numpy scalars as numbers, NaN/inf as null,
    dataclasses as dicts (every --json output goes through it)."""
    if isinstance(obj, dict):
        return {str(k): _to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _to_jsonable(obj.tolist())
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (np.floating, float)):
        return float(obj) if np.isfinite(obj) else None
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if hasattr(obj, "__dataclass_fields__"):
        return _to_jsonable({k: getattr(obj, k) for k in obj.__dataclass_fields__})
    return obj


def _write_json(path: str | None, payload: Any) -> None:
    if path:
        atomic_write_text(path, json.dumps(_to_jsonable(payload), indent=2) + "\n")


def _parse_params(items: Sequence[str]) -> dict[str, str]:
    """--param NAME=VALUE pairs as text; :func:`check_parameters` types and range-checks them."""
    params: dict[str, str] = {}
    for item in items or ():
        if "=" not in item:
            raise InputError(f"--param expects NAME=VALUE, got '{item}'")
        name, value = item.split("=", 1)
        if not name.strip():
            raise InputError(f"--param expects NAME=VALUE, got '{item}' (no name)")
        params[name.strip()] = value.strip()
    return params


def _require_positive(name: str, value: float | None) -> None:
    if value is not None and not (math.isfinite(value) and value > 0):
        raise InputError(f"{name} = {value:g} must be a positive number of seconds")


def _check_plausibility(campaign, args) -> None:
    """The measured data's plausibility checks, right after loading, before any computation."""
    from .plausibility import enforce_plausibility
    enforce_plausibility(campaign, force=getattr(args, "force", False))


# ------------------------------------------------------------ argument types

def _typed(kind: type, test, wanted: str):
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


def int_at_least(low: int):
    """``type=`` for an integer >= ``low``."""
    return _typed(int, lambda v: v >= low, f"an integer >= {low}")


# ------------------------------------------------------------ FMU parameters

def _fmu_variables(fmu_path: str | None) -> dict[str, Any]:
    """The FMU's variables by name, read from its modelDescription.xml (no instance made)."""
    from fmpy import read_model_description

    from .simulator import default_fmu_path
    path = Path(fmu_path) if fmu_path else default_fmu_path()
    if not path.is_file():
        raise InputError("FMU not found (build it with cmake first, or give --fmu)", path)
    try:
        md = read_model_description(str(path))
    except Exception as exc:  # a zip or XML error of a broken FMU
        raise InputError(f"not a readable FMU: {type(exc).__name__}: {exc}", path) from None
    return {v.name: v for v in md.modelVariables}


def parameter_value(variables: dict[str, Any], name: str, value: object, option: str = "--param") -> object:
    """``value`` (text or number) as the FMU parameter ``name`` needs it: a finite float within
    [min, max] for Real, a whole number within [min, max] for Integer/Enumeration, text for
    String.  Raises InputError naming the option, the parameter and the rule."""
    var = variables.get(name)
    if var is None:
        close = difflib.get_close_matches(name, [n for n, v in variables.items() if v.causality == "parameter"],
                                          n=3, cutoff=0.6)
        hint = f"; did you mean {', '.join(close)}?" if close else ""
        raise InputError(f"{option} {name}: the FMU has no parameter '{name}'{hint}")
    if var.causality != "parameter":
        raise InputError(f"{option} {name}: '{name}' is an FMU {var.causality}, not a parameter that can be set")
    text = value if isinstance(value, str) else f"{value!r}" if not isinstance(value, float) else f"{value:.17g}"
    if var.type == "String":
        return str(value)
    if var.type == "Boolean":
        low = text.strip().lower()
        if low not in ("0", "1", "true", "false"):
            raise InputError(f"{option} {name}={text}: '{name}' is a Boolean: give true or false")
        return low in ("1", "true")
    if var.type in ("Integer", "Enumeration"):
        if isinstance(value, (int, float)) and not isinstance(value, bool) and float(value).is_integer():
            number: float = int(value)
        elif isinstance(value, str) and re.fullmatch(r"[+-]?[0-9]+", text.strip()):
            number = int(text)
        else:
            raise InputError(f"{option} {name}={text}: '{name}' is an {var.type}: give a whole number")
    else:
        try:
            number = parse_finite(text) if isinstance(value, str) else float(value)
        except InputError:
            raise InputError(f"{option} {name}={text}: '{name}' needs a finite number") from None
        if not math.isfinite(number):
            raise InputError(f"{option} {name}={text}: '{name}' needs a finite number")
    low = float(var.min) if var.min not in (None, "") else -math.inf
    high = float(var.max) if var.max not in (None, "") else math.inf
    if not low <= number <= high:
        raise InputError(f"{option} {name}={text}: out of the FMU's range [{low:g}, {high:g}] of '{name}'")
    return number


def check_parameters(params: dict[str, object], fmu_path: str | None, option: str = "--param") -> dict[str, object]:
    """Every ``params`` value typed and range-checked against the FMU (:func:`parameter_value`)."""
    if not params:
        return {}
    variables = _fmu_variables(fmu_path)
    return {name: parameter_value(variables, name, value, option) for name, value in params.items()}


# ------------------------------------------------------------ output paths

#: The path options each subcommand writes besides --json: attribute -> kind of output.
OUTPUT_OPTIONS = {"simulate": {"out": "file"}, "sweep": {"out": "file"}, "report": {"out": "report"},
                  "synthesize": {"out": "campaign"}, "diagnose": {"plots": "plots"}}


def input_paths(args) -> list[Any]:
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


def check_output_paths(args) -> None:
    """Refuse, before any computation, an output path that would destroy an input or a user's
    folder, or that cannot be written (:mod:`juno.outputs`)."""
    inputs = input_paths(args)
    options = OUTPUT_OPTIONS.get(args.command, {})
    for attr, kind in options.items():
        out = getattr(args, attr, None)
        flag = "OUT" if attr == "out" and args.command == "synthesize" else f"--{attr}"
        if kind == "file":
            check_output_file(out, inputs, flag)
        elif kind == "report":
            check_output_dir(out, inputs, flag, REPORT_MARKER, "juno report")
        elif kind == "plots":
            check_output_dir(out, inputs, flag, PLOTS_MARKER, "juno diagnose --plots")
        elif kind == "campaign":
            check_campaign_dir(out, inputs, flag, overwrite=getattr(args, "overwrite", False))
    json_path = getattr(args, "json", None)
    check_output_file(json_path, inputs, "--json")
    for attr, kind in options.items():
        out = getattr(args, attr, None)
        if json_path and out and os.path.realpath(json_path) == os.path.realpath(out):
            raise InputError(f"--json {json_path} and --{attr} {out} are the same path; give two")


# ------------------------------------------------------------ subcommands

SCENARIOS = {
    "drawbar": ("a 30 s drawbar pull test at 45 %% throttle against 400 N", 30.0,
                {"drive.mode": 2}, {"drawbarForce": 400.0, "throttleLeft": 0.45, "throttleRight": 0.45}),
    "straight": ("20 s straight run at 45 %% throttle, no drawbar", 20.0,
                 {"drive.mode": 2}, {"drawbarForce": 0.0, "throttleLeft": 0.45, "throttleRight": 0.45}),
    "turn": ("20 s skid-steer turn: 20 %% left, 60 %% right throttle", 20.0,
             {"drive.mode": 2}, {"drawbarForce": 0.0, "throttleLeft": 0.2, "throttleRight": 0.6}),
    "rest": ("10 s at rest on flat ground", 10.0,
             {"drive.mode": 0}, {"drawbarForce": 0.0, "torqueLeft": 0.0, "torqueRight": 0.0}),
}


def cmd_simulate(args) -> int:
    from .campaign import format_run_csv, load_campaign
    from .simulator import DEFAULT_OUTPUTS, InputSignals, JunoFMU
    say = _progress(args.quiet)
    _require_positive("--stop-time", args.stop_time)
    _require_positive("--output-interval", args.output_interval)
    params = check_parameters(_parse_params(args.param), args.fmu)
    with JunoFMU(args.fmu) as fmu:
        if args.campaign:
            from .identify import prepare_run
            from .validate import grid_terrain
            campaign = load_campaign(args.campaign)
            _check_plausibility(campaign, args)
            run = campaign.run(args.run) if args.run else campaign.runs[0]
            with tempfile.TemporaryDirectory() as tmp:
                grid = str(grid_terrain(campaign, run, tmp)[0]) if run.kind == "terrain" else None
                prep = prepare_run(campaign, run, terrain_file=grid)
                say(f"simulating measured run {run.id} ({prep.duration:.1f} s, following the measured wheel spins)")
                result = fmu.simulate({**prep.params, **params}, prep.inputs, prep.duration,
                                      args.output_interval, outputs=DEFAULT_OUTPUTS)
            label = f"run {run.id} of {campaign.name}"
        else:
            text, stop, scen_params, inputs = SCENARIOS[args.scenario]
            stop = args.stop_time if args.stop_time is not None else stop
            say(f"simulating scenario '{args.scenario}': {text.replace('%%', '%')}")
            result = fmu.simulate({**scen_params, **params}, InputSignals.constant(**inputs), stop,
                                  args.output_interval, outputs=DEFAULT_OUTPUTS)
            label = f"scenario {args.scenario}"
    if args.out:
        atomic_write_text(args.out, format_run_csv(result))
        say(f"wrote {args.out}")
    final = {k: float(v[-1]) for k, v in result.items()}
    print(f"{label}: t = {final['time']:.2f} s, x = {final['x']:.3f} m, y = {final['y']:.3f} m, "
          f"vx = {final['vx']:.4f} m/s, slip FL = {final['wheelFL.slip']:.4f}, "
          f"sinkage FL/RL = {final['wheelFL.sinkage'] * 1000:.1f}/{final['wheelRL.sinkage'] * 1000:.1f} mm")
    _write_json(args.json, {"label": label, "final": final})
    return 0


def cmd_identify(args) -> int:
    from .campaign import load_campaign
    from .identify import identify_joint, identify_multistart, identify_paper_runs
    from .simulator import JunoFMU
    say = _progress(args.quiet)
    campaign = load_campaign(args.campaign)
    _check_plausibility(campaign, args)
    batch = {"workers": args.workers, "scheduler": args.scheduler}
    out: dict[str, Any] = {"campaign": campaign.name}
    with JunoFMU(args.fmu) as fmu:
        if args.method in ("paper", "both"):
            runs = campaign.runs_of_kind("drawbar")
            say("paper-style Nelder-Mead on " + ", ".join(r.id for r in runs))
            out["paper"] = identify_paper_runs(fmu, campaign, runs, progress=say, **batch)
            for p in out["paper"]:
                print(f"{p.run_id}: " + ", ".join(f"{k} = {v:.4g}" for k, v in p.final.items()) +
                      f" (cost {p.cost:.3g}, {p.evaluations} evaluations, rank {p.jacobian_rank}/4)")
        if args.method in ("joint", "both"):
            grid = None
            tmp = tempfile.TemporaryDirectory()
            if args.with_terrain:
                from .identify import terrain_grids
                grid = terrain_grids(campaign, tmp.name, "identify --with-terrain")
            joint_args = dict(include_terrain=args.with_terrain, terrain_file=grid,
                              max_evaluations=args.max_evaluations, optimizer=args.optimizer)
            if args.starts > 1:
                say(f"joint identification from {args.starts} starting points (seed {args.seed})")
                multi = identify_multistart(fmu, campaign, args.starts, seed=args.seed, progress=say,
                                            **batch, **joint_args)
                j = multi.best
                out["multistart"] = {"starts": multi.starts, "costs": [f.cost for f in multi.fits],
                                     "params": [f.params for f in multi.fits], "spread": multi.spread,
                                     "wall_time": multi.wall_time}
                print(f"multi-start: {args.starts} fits in {multi.wall_time:.1f} s; costs "
                      + ", ".join(f"{f.cost:.4g}" for f in multi.fits) + "; largest relative distance from "
                      "the best: " + ", ".join(f"{k} {v:.2%}" for k, v in multi.spread.items()))
            else:
                say("joint identification over the whole time series")
                j = identify_joint(fmu, campaign, progress=say, **batch, **joint_args)
            tmp.cleanup()
            out["joint"] = j
            for k, v in j.params.items():
                print(f"joint: {k} = {v:.5g} +- {j.std[k]:.2g} ({j.identifiability[k]})")
            print(f"joint: {j.evaluations} evaluations in {j.wall_time:.1f} s")
    _write_json(args.json, out)
    return 0


def _load_soil(path: str) -> dict[str, float]:
    """The soil parameters of an identify result (``juno identify --json``): its joint fit's
    ``params``, or a ``params`` object, or the four parameters at the top level."""
    from .errors import decode_input_text, read_input_bytes
    from .simulator import SOIL_PARAMETERS
    p = Path(path)
    text = decode_input_text(p, read_input_bytes(p))
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(f"not valid JSON: {exc.msg} (column {exc.colno})", p, exc.lineno) from None
    if not isinstance(data, dict):
        raise InputError("not an identify result (juno identify --json): a JSON object is needed", p)
    if isinstance(data.get("joint"), dict) and "params" in data["joint"]:
        data, where = data["joint"]["params"], "joint.params"
    elif "params" in data:
        data, where = data["params"], "params"
    else:
        where = "the top level"
    if not isinstance(data, dict):
        raise InputError(f"not an identify result (juno identify --json): {where} is not an object", p)
    missing = [k for k in SOIL_PARAMETERS if k not in data]
    if missing:
        raise InputError(f"not an identify result (juno identify --json): {where} lacks "
                         + ", ".join(missing), p)
    soil = {}
    for k in SOIL_PARAMETERS:
        v = data[k]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise InputError(f"{where}: '{k}' must be a finite number, got {json.dumps(v)}", p)
        soil[k] = float(v)
    return soil


def cmd_validate(args) -> int:
    from .campaign import load_campaign
    from .identify import identify_joint, require_runs
    from .simulator import JunoFMU
    from .validate import validate_run
    say = _progress(args.quiet)
    soil = _load_soil(args.params) if args.params else None
    campaign = load_campaign(args.campaign)
    _check_plausibility(campaign, args)
    require_runs(campaign, "validate")
    with JunoFMU(args.fmu) as fmu:
        if soil is None:
            say("no --params given: identifying first (joint fit)")
            soil = identify_joint(fmu, campaign, progress=say).params
        results = {}
        with tempfile.TemporaryDirectory() as tmp:
            for run in campaign.runs_of_kind("terrain"):
                say(f"validating on terrain run {run.id}")
                v = validate_run(fmu, campaign, run, soil, tmp, cell=args.cell)
                results[run.id] = v.rms
                print(f"{run.id}: RMS " + ", ".join(f"{k} {x:.4g}" for k, x in v.rms.items()))
    _write_json(args.json, {"soil": soil, "rms": results})
    return 0


def cmd_synthesize(args) -> int:
    from .synthesize import synthesize
    say = _progress(args.quiet)
    path = synthesize(args.out, effect=args.effect or ["none"], strength=args.strength or [1.0], seed=args.seed,
                      noise=args.noise,
                      time_scale=args.time_scale, overwrite=args.overwrite, progress=say,
                      heavy_run=args.heavy_run)
    print(f"wrote campaign {path} (effect hidden: see {path}/truth.json only)")
    _write_json(args.json, {"campaign": str(path)})
    return 0


def cmd_report(args) -> int:
    from .campaign import load_campaign
    from .identify import identify_joint, identify_paper_runs
    from .report import write_report
    from .simulator import JunoFMU
    from .validate import validate_run
    say = _progress(args.quiet)
    campaign = load_campaign(args.campaign)
    _check_plausibility(campaign, args)
    timings: dict[str, float] = {}
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
        with tempfile.TemporaryDirectory() as tmp:
            for run in campaign.runs_of_kind("terrain"):
                say(f"validating on {run.id}")
                v = validate_run(fmu, campaign, run, joint.params, tmp)
                validations.append(("joint fit", v))
                best_paper = min(paper, key=lambda p: p.cost) if paper else None
                if best_paper:
                    validations.append((f"paper-style {best_paper.run_id}",
                                        validate_run(fmu, campaign, run, best_paper.final, tmp, grid_file=v.grid_file)))
        timings["validation"] = time.perf_counter() - t
        diagnosis = None
        if args.diagnose:
            from .diagnose import diagnose
            t = time.perf_counter()
            say("diagnosing what the model gets wrong")
            diagnosis = diagnose(campaign, fmu=fmu, progress=say)
            timings["diagnosis"] = time.perf_counter() - t
    truth_path = Path(campaign.root) / "truth.json"
    truth = json.loads(truth_path.read_text()) if truth_path.is_file() else None
    path = write_report(args.out, campaign, paper, joint, validations, diagnosis, truth=truth, timings=timings)
    print(f"wrote report {path}")
    _write_json(args.json, {"report": str(path), "joint": joint.params, "timings": timings})
    return 0


# ------------------------------------------------------------------ main

class OneLineParser(argparse.ArgumentParser):
    """A subcommand's parser whose errors are one line, ``juno CMD: error: ...`` (exit code 2),
    like every other refusal of the command; the usage is in ``--help``."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="juno", description="JunoRover volumetric wheel/soil model: simulate, "
                                     "identify, validate, synthesize, diagnose, report.", epilog=EPILOG)
    parser.add_argument("--version", action="version", version=f"juno {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=OneLineParser)

    def common(p):
        p.add_argument("--json", metavar="FILE", help="write the machine-readable result to FILE")
        p.add_argument("--fmu", metavar="FMU", help="the FMU (default: build/JunoRover.fmu or $JUNO_FMU)")
        p.add_argument("--quiet", action="store_true", help="no progress messages")
        p.add_argument("--force", action="store_true",
                       help="go on despite implausible measured data (its errors are printed as warnings)")

    p = sub.add_parser("simulate", help="run a scenario or a measured run through the FMU")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--scenario", choices=sorted(SCENARIOS), default="drawbar",
                     help="; ".join(f"{k}: {v[0]}" for k, v in SCENARIOS.items()))
    src.add_argument("--campaign", metavar="DIR", help="simulate a measured run of this campaign")
    p.add_argument("--run", help="run id (with --campaign; default: the first run)")
    p.add_argument("--param", action="append", metavar="NAME=VALUE", help="set an FMU parameter (repeatable)")
    p.add_argument("--stop-time", type=positive_float, help="seconds (scenarios)")
    p.add_argument("--output-interval", type=positive_float, default=0.05, help="seconds (default 0.05)")
    p.add_argument("--out", metavar="CSV", help="write all outputs to CSV")
    common(p)
    p.set_defaults(func=cmd_simulate)

    p = sub.add_parser("identify", help="Nelder-Mead identification of the soil parameters")
    p.add_argument("campaign", metavar="CAMPAIGN")
    p.add_argument("--method", choices=("paper", "joint", "both"), default="both",
                   help="paper: per drawbar run from steady-window averages; joint: all runs, whole time series")
    p.add_argument("--with-terrain", action="store_true", help="include the terrain run in the joint fit")
    p.add_argument("--optimizer", choices=("least-squares", "nelder-mead"), default="least-squares",
                   help="joint fit: trust-region Gauss-Newton (default) or Nelder-Mead then a polish")
    p.add_argument("--max-evaluations", type=positive_int, default=400, help="Nelder-Mead budget of the joint fit")
    p.add_argument("--starts", type=positive_int, default=1,
                   help="joint fit from N starting points (the paper's guess and N-1 scattered around it), "
                        "one parallel task each; reports the best and how far the others ended (default 1)")
    p.add_argument("--seed", type=nonnegative_int, default=0,
                   help="seed of the scattered starting points (default 0)")
    add_batch_options(p)
    common(p)
    p.set_defaults(func=cmd_identify)

    p = sub.add_parser("validate", help="simulate the terrain runs with identified parameters and compare")
    p.add_argument("campaign", metavar="CAMPAIGN")
    p.add_argument("--params", metavar="JSON", help="identified parameters (the --json of identify)")
    p.add_argument("--cell", type=positive_float, default=0.05, help="terrain grid resolution in m (default 0.05)")
    common(p)
    p.set_defaults(func=cmd_validate)

    p = sub.add_parser("synthesize", help="write a synthetic measured campaign with a hidden effect")
    p.add_argument("out", metavar="OUT")
    p.add_argument("--effect", action="append", metavar="EFFECT",
                   help="effect id to hide (default none = nothing); repeat to hide several at once")
    p.add_argument("--strength", type=fraction, action="append", metavar="S",
                   help="effect strength, 0 to 1 (default 1); one for all effects, or one per --effect in order")
    p.add_argument("--seed", type=nonnegative_int, default=0, help="seed of the truth and the noise (default 0)")
    p.add_argument("--noise", type=nonnegative_float, default=1.0, help="sensor noise scale (0 = exact)")
    p.add_argument("--time-scale", type=positive_float, default=1.0, help="shorten runs (< 1) for quick tests")
    p.add_argument("--heavy-run", action="store_true",
                   help="one drawbar run held at about 70 %% slip at 80 %% throttle (instead of the "
                        "720 N one; the others 320 and 620 N): separates grouser thrust from K_vx")
    p.add_argument("--overwrite", action="store_true",
                   help="replace an existing OUT written by juno synthesize (never another folder)")
    common(p)
    p.set_defaults(func=cmd_synthesize)

    p = sub.add_parser("report", help="identify, validate (and diagnose) and write a Markdown report")
    p.add_argument("campaign", metavar="CAMPAIGN")
    p.add_argument("--out", metavar="DIR", required=True,
                   help="report folder: new, empty, or written by juno report before (then replaced whole)")
    p.add_argument("--diagnose", action="store_true", help="include the discrepancy diagnosis")
    common(p)
    p.set_defaults(func=cmd_report)
    _add_module_command(sub, common, "sweep",
                        "simulate a scenario over a grid of FMU parameter values; CSV/JSON of summary outputs")
    _add_module_command(sub, common, "diagnose",
                        "find what the simulation gets wrong, name the cause, measure the gain")
    _add_module_command(sub, common, "bench",
                        "benchmark the contact laws, the FMU and the workflow; prints figures")
    return parser


def add_batch_options(p) -> None:
    """--workers and --scheduler of the subcommands that run batches (juno.parallel)."""
    p.add_argument("--workers", type=positive_int, default=None, metavar="N",
                   help="local worker processes for the batch (default: one per core; 1 = no pool)")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="run the batch on the Dask distributed cluster at ADDRESS (tcp://host:port); its "
                        "workers need the FMU (and the campaign folder) at the same paths as here")


def _add_module_command(sub, common, name: str, help_text: str) -> None:
    """A subcommand whose options and function live in its own module (juno.<name>)."""
    import importlib
    p = sub.add_parser(name, help=help_text)
    importlib.import_module(f".{name}", __package__).add_arguments(p)
    common(p)


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


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    previous = None
    if threading.current_thread() is threading.main_thread():
        previous = signal.signal(signal.SIGTERM, _on_sigterm)
    try:
        check_output_paths(args)
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


if __name__ == "__main__":
    sys.exit(main())
