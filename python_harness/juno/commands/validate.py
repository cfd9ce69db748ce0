"""``juno validate``: the terrain runs simulated with identified soil parameters, compared with
the measurements."""

from __future__ import annotations

import argparse
import json
import math
import tempfile
from pathlib import Path

from ..core import progress_printer, write_json
from ..errors import InputError, decode_input_text, read_input_bytes
from .options import positive_float

HELP = "simulate the terrain runs with identified parameters and compare"
OUTPUTS: dict[str, str] = {}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("campaign", metavar="CAMPAIGN")
    p.add_argument("--params", metavar="JSON", help="identified parameters (the --json of identify)")
    # No default here: the library's (validate.GRID_CELL, 10 cm), so that juno validate, juno
    # report and juno diagnose grid a scan alike (the library is imported only when a command runs).
    p.add_argument("--cell", type=positive_float, default=None,
                   help="terrain grid resolution in m (default 0.1, the grid juno report and juno diagnose use)")


def load_identified_soil(path: str | Path) -> dict[str, float]:
    """The soil parameters of an identify result (``juno identify --json``): its joint fit's
    ``params``, or a ``params`` object, or the four parameters at the top level.  Raises
    InputError naming the file and what is missing or wrong."""
    from ..rover_model import SOIL_PARAMETERS
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


def run(args: argparse.Namespace) -> int:
    from ..campaign import load_campaign, missing_columns
    from ..identify import identify_joint, require_runs
    from ..plausibility import enforce_plausibility
    from ..sensor_noise import noise_statements, stated_noise_lines
    from ..simulator import JunoFMU
    from ..validate import GRID_CELL, validate_run
    say = progress_printer(args.quiet)
    cell = GRID_CELL if args.cell is None else args.cell
    soil = load_identified_soil(args.params) if args.params else None
    campaign = load_campaign(args.campaign)
    enforce_plausibility(campaign, force=args.force, fmu=args.fmu)
    require_runs(campaign, "validate")
    # the terrain runs are replayed; the drawbar runs too when the soil is identified here first
    missing = missing_columns(campaign, ("terrain",) if soil is not None else ("drawbar", "terrain"))
    statements = noise_statements(campaign, ("terrain",) if soil is not None else ("drawbar", "terrain"))
    soil_doubts: list[str] = []   # why the soil identified here should not be trusted (fit_doubts)
    with JunoFMU(args.fmu) as fmu:
        if soil is None:
            say("no --params given: identifying first (joint fit)")
            fit = identify_joint(fmu, campaign, progress=say)
            soil, soil_doubts = fit.params, list(fit.doubts)
        results, noise = {}, {}
        with tempfile.TemporaryDirectory() as tmp:
            for run_spec in campaign.runs_of_kind("terrain"):
                say(f"validating on terrain run {run_spec.id}")
                v = validate_run(fmu, campaign, run_spec, soil, tmp, cell=cell)
                results[run_spec.id], noise[run_spec.id] = v.rms, v.noise
                print(f"{run_spec.id}: RMS " + ", ".join(_rms_text(v, k) for k in v.rms))
    for doubt in soil_doubts:
        print(f"the soil validated comes from a doubtful joint fit: {doubt}")
    for m in missing:
        print(m.sentence())
    for line in stated_noise_lines(statements):
        print(line)
    write_json(args.json, {"soil": soil, "soil_doubts": soil_doubts, "rms": results, "noise": noise,
                           "missing_columns": missing, "sensor_noise": statements}, "validate")
    return 0


def _rms_text(v, name: str) -> str:
    """``pos_x 0.009021 (4.5 x noise)``: an RMS error, in units of its sensor noise where known."""
    if v.rms[name] != v.rms[name]:
        from ..validate import SETTLING
        return f"{name} not compared (no sample after the first {SETTLING:g} s)"
    ratio = v.noise_ratio(name)
    return f"{name} {v.rms[name]:.4g}" + (f" ({ratio:.2g} x noise)" if ratio == ratio else "")
