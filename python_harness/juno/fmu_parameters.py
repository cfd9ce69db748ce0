"""FMU parameters given as text (``--param NAME=VALUE``), typed and range-checked against the
FMU's own variable table before any simulation.

The FMU's modelDescription.xml is the one source of each parameter's type and [min, max], so a
value the FMU would refuse at initialisation is refused here first, with a message that names
the option, the parameter and the rule.
"""

from __future__ import annotations

import difflib
import math
import re
from pathlib import Path
from typing import Any, Iterable, Mapping

from .errors import InputError, parse_finite

__all__ = ["fmu_variables", "parse_assignments", "parameter_value", "check_parameters", "check_rover_overrides"]


def fmu_variables(fmu_path: str | Path | None) -> dict[str, Any]:
    """The FMU's variables by name, read from its modelDescription.xml (no instance is made).
    ``None`` means the default FMU (:func:`juno.simulator.default_fmu_path`)."""
    from fmpy import read_model_description

    from .simulator import FMU_HINT, default_fmu_path
    path = Path(fmu_path) if fmu_path else default_fmu_path()
    if not path.is_file():
        raise InputError(f"FMU not found: {FMU_HINT}", path)
    try:
        md = read_model_description(str(path))
    except Exception as exc:  # a zip or XML error of a broken FMU
        raise InputError(f"not a readable FMU: {type(exc).__name__}: {exc}", path) from None
    return {v.name: v for v in md.modelVariables}


def parse_assignments(items: Iterable[str] | None, option: str = "--param") -> dict[str, str]:
    """``NAME=VALUE`` pairs as text by name; :func:`check_parameters` types and range-checks them."""
    params: dict[str, str] = {}
    for item in items or ():
        if "=" not in item:
            raise InputError(f"{option} expects NAME=VALUE, got '{item}'")
        name, value = item.split("=", 1)
        if not name.strip():
            raise InputError(f"{option} expects NAME=VALUE, got '{item}' (no name)")
        params[name.strip()] = value.strip()
    return params


def _as_text(value: object) -> str:
    """A value as the user wrote it: text as is, a number in its shortest exact decimal."""
    if isinstance(value, str):
        return value
    return repr(float(value)) if isinstance(value, float) else f"{value!r}"


#: Units a value is often written in by mistake, by the FMU unit it belongs in: (name, size of
#: one of them in the FMU's unit).
MISTAKEN_UNITS = {
    "m": (("millimetres", 1e-3), ("centimetres", 1e-2), ("inches", 0.0254)),
    "kg": (("grams", 1e-3), ("pounds", 0.45359237)),
    "rad": (("degrees", math.pi / 180.0),),
    "m/s": (("km/h", 1.0 / 3.6),),
}


def _unit_hint(var: Any, number: float, low: float, high: float) -> str:
    """Which mistaken units bring an out-of-range value within [low, high], those whose value
    lies nearest the FMU's default first (ratio of the two), as a clause; empty when none."""
    unit = var.unit or ""
    try:
        start = abs(float(var.start))
    except (TypeError, ValueError):
        start = 0.0
    fits = [(name, number * size) for name, size in MISTAKEN_UNITS.get(unit, ()) if low <= number * size <= high]
    if not fits:
        return ""
    if start > 0:
        fits.sort(key=lambda f: abs(math.log(abs(f[1]) / start)) if f[1] != 0 else math.inf)
    options = " or ".join(f"{name} ({value:.4g} {unit})" for name, value in fits)
    return f": is it in {options}? Give it in {unit}"


def parameter_value(variables: Mapping[str, Any], name: str, value: object, option: str = "--param") -> object:
    """``value`` (text or number) as the FMU parameter ``name`` needs it: a finite float within
    [min, max] for Real, a whole number within [min, max] for Integer/Enumeration, a bool for
    Boolean, text for String.  Raises InputError naming the option, the parameter and the rule."""
    var = variables.get(name)
    if var is None:
        close = difflib.get_close_matches(name, [n for n, v in variables.items() if v.causality == "parameter"],
                                          n=3, cutoff=0.6)
        hint = f"; did you mean {', '.join(close)}?" if close else ""
        raise InputError(f"{option} {name}: the FMU has no parameter '{name}'{hint}")
    if var.causality != "parameter":
        raise InputError(f"{option} {name}: '{name}' is an FMU {var.causality}, not a parameter that can be set")
    text = _as_text(value)
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
        unit = f" {var.unit}" if var.unit and var.unit != "1" else ""
        raise InputError(f"{option} {name}={text}: out of the FMU's range [{low:g}, {high:g}]{unit} of '{name}'"
                         + _unit_hint(var, number, low, high))
    return number


def check_parameters(params: Mapping[str, object], fmu_path: str | Path | None,
                     option: str = "--param") -> dict[str, object]:
    """Every value of ``params`` typed and range-checked against the FMU (:func:`parameter_value`)."""
    if not params:
        return {}
    variables = fmu_variables(fmu_path)
    return {name: parameter_value(variables, name, value, option) for name, value in params.items()}


def check_rover_overrides(rover: Mapping[str, object], manifest: str | Path,
                          fmu_path: str | Path | None) -> dict[str, object]:
    """A campaign's ``rover`` parameter overrides typed and range-checked against the FMU
    (:func:`parameter_value`), so that a misspelt name or a value in the wrong unit is refused
    with the manifest's file and line before any simulation, not by a worker half-way through."""
    if not rover:
        return {}
    variables = fmu_variables(fmu_path)
    path = Path(manifest)
    try:
        lines = path.read_text(encoding="utf-8", errors="replace").splitlines()
    except OSError:
        lines = []
    checked = {}
    for name, value in rover.items():
        try:
            checked[name] = parameter_value(variables, name, value, option="'rover':")
        except InputError as exc:
            line = next((i for i, text in enumerate(lines, start=1) if f'"{name}"' in text), None)
            raise InputError(exc.message, path, line, name) from None
    return checked
