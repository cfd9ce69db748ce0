#!/usr/bin/env python3
"""Both contact laws fitted to published single-wheel testbed measurements (the tables of
docs/results/wheel-rig-published.md).

data/published/single-wheel-published.csv holds measurements read off the figures of three
published testbed studies (its header names them).  This script converts them into one campaign
per study (each wheel a wheel_rig run: the smooth and the lugged wheel of a study ran on the same
soil), and for each campaign and each model (the volumetric law, the volumetric law with the
slip-sinkage extension, the Wong-Reece law; VARIANTS):

* fits every point and reports the parameters with their 1-sigma uncertainty and
  identifiability, and the fit's rms error per measured quantity;
* held-out prediction: fits the points at alternate slips of each wheel (the 1st, 3rd, ...
  in order of slip), predicts the others, and reports the rms error of the prediction of
  drawbar pull, torque and sinkage.

The figures' values carry no standard deviations, so the fit estimates a noise scale per
quantity from its residuals (juno.wheel_rig).  Writes docs/results/wheel-rig-published.json and
.md (whole, at the end) with the date, the commit and the machine.  About a minute per study on
one core.

    .venv/bin/python scripts/published_wheel_rig.py                     # every study
    .venv/bin/python scripts/published_wheel_rig.py --sets ding2011     # one study
    .venv/bin/python scripts/published_wheel_rig.py --campaigns out/rig # also keep the campaigns
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "scripts"))
sys.path.insert(0, str(ROOT / "python_harness"))

from generate_docs import _now, _write, commit_description, machine_description  # noqa: E402

from juno.campaign import Campaign, write_campaign  # noqa: E402
from juno.core import to_jsonable  # noqa: E402
from juno.identify import FitError  # noqa: E402
from juno.wheel_rig import RigFMU, RigRun, fit_rig, predict, rig_runs  # noqa: E402

DATA = ROOT / "data" / "published" / "single-wheel-published.csv"
RESULTS_JSON = ROOT / "docs" / "results" / "wheel-rig-published.json"
RESULTS_MD = ROOT / "docs" / "results" / "wheel-rig-published.md"

#: The studies, by the prefix of their rows' ``source`` (the part before the first '_'), as the
#: data file's header cites them.
SOURCES = {
    "ding2011": "Ding et al. 2011, J. Terramechanics 48(1):27-45 (HIT single-wheel testbed, Fig 9)",
    "kls1": "Wang & Han 2016, J. Korean Geotech. Soc. 32(11):97-108 (KICT testbed, KLS-1 simulant, Fig 14)",
    "rashid1": "Hurrell et al. 2025, Space Sci. Rev. 221 art. 37 (Rashid-1 wheel, FJS-1; drawbar = mu * load; "
               "no torque)",
}
#: The data file's columns and the wheel_rig columns they become.
COLUMN_OF = {"vertical_load_n": "vertical_load", "slip": "slip", "drawbar_pull_n": "drawbar_pull",
             "sinkage_m": "sinkage", "torque_nm": "torque"}
QUANTITIES = ("drawbar_pull", "torque", "sinkage")
#: The models compared: name -> (contact law, fit the slip-sinkage coefficient too).
VARIANTS = {"volumetric": ("volumetric", False), "volumetric + slip-sinkage": ("volumetric", True),
            "wong-reece": ("wong-reece", False)}


def read_published(path: Path = DATA) -> dict[str, dict[str, dict[str, Any]]]:
    """study -> wheel (the row's ``source``) -> {"wheel": manifest wheel, "table": columns}.

    Raises ValueError naming the line of a row that breaks the file's format."""
    lines = path.read_text(encoding="utf-8").splitlines()
    body = [(i + 1, line) for i, line in enumerate(lines) if line.strip() and not line.startswith("#")]
    reader = csv.reader(io.StringIO("\n".join(line for _, line in body)))
    header = next(reader)
    studies: dict[str, dict[str, dict[str, Any]]] = {}
    for (lineno, _), row in zip(body[1:], reader):
        if len(row) != len(header):
            raise ValueError(f"{path}, line {lineno}: {len(row)} cells, the header has {len(header)}")
        cell = dict(zip(header, row))
        source = cell["source"]
        study = source.split("_")[0]
        if study not in SOURCES:
            raise ValueError(f"{path}, line {lineno}: unknown study {study!r} (known: {', '.join(SOURCES)})")
        try:
            wheel = {"radius": float(cell["wheel_radius_m"]), "width": float(cell["wheel_width_m"]),
                     "lug_height": float(cell["lug_height_m"]), "lug_count": int(cell["lug_count"])}
            values = {c: float(cell[k]) if cell[k].strip() else float("nan") for k, c in COLUMN_OF.items()}
        except ValueError as e:
            raise ValueError(f"{path}, line {lineno}: {e}") from None
        entry = studies.setdefault(study, {}).setdefault(source, {"wheel": wheel, "table": {}})
        if entry["wheel"] != wheel:
            raise ValueError(f"{path}, line {lineno}: wheel of {source!r} differs from its first row's")
        for c, v in values.items():
            entry["table"].setdefault(c, []).append(v)
    return studies


def write_study_campaign(study: str, wheels: dict[str, dict[str, Any]], root: Path) -> Campaign:
    """The campaign of one study: one wheel_rig run per wheel, columns without any value left out."""
    runs, tables = [], {}
    for source, entry in wheels.items():
        table = {c: np.array(v) for c, v in entry["table"].items() if not np.all(np.isnan(v))}
        runs.append({"id": source, "kind": "wheel_rig", "wheel": entry["wheel"]})
        tables[source] = table
    manifest = {"name": f"published-{study}", "source": SOURCES[study], "runs": runs}
    return write_campaign(root, manifest, tables, overwrite=True)


def alternate_split(run: RigRun) -> tuple[np.ndarray, np.ndarray]:
    """Indices of the points at the 1st, 3rd, ... slip of a run (in order of slip) and of the others."""
    order = np.argsort(run.points.slip, kind="stable")
    return order[0::2], order[1::2]


def _rms(values: list[np.ndarray]) -> float | None:
    v = np.concatenate(values) if values else np.zeros(0)
    return float(np.sqrt(np.mean(v * v))) if v.size else None


def held_out(fmu: RigFMU, campaign: Campaign, runs: list[RigRun], law: str, slip_sinkage: bool) -> dict[str, Any]:
    """Fit on alternate slips, predict the others: rms prediction error per quantity (its unit)."""
    train, test = zip(*(alternate_split(r) for r in runs))
    fit = fit_rig(fmu, campaign, law, runs=[r.subset(i) for r, i in zip(runs, train)], slip_sinkage=slip_sinkage)
    errors: dict[str, list[np.ndarray]] = {q: [] for q in QUANTITIES}
    for run, idx in zip(runs, test):
        held = run.subset(idx)
        sim = predict(fmu, held, fit.model_parameters())
        for q in QUANTITIES:
            if q in held.measured:
                ok = ~np.isnan(held.measured[q])
                errors[q].append(sim[q][ok] - held.measured[q][ok])
    return {"rms": {q: _rms(errors[q]) for q in QUANTITIES}, "fit_rms": fit.rms, "params": fit.params,
            "points": {"fitted": int(sum(len(i) for i in train)), "predicted": int(sum(len(i) for i in test))}}


def study_result(fmu: RigFMU, study: str, campaign: Campaign, say) -> dict[str, Any]:
    runs = rig_runs(campaign)
    out: dict[str, Any] = {"source": SOURCES[study], "runs": {r.run_id: {"wheel": r.setup, "points": len(r.points)}
                                                              for r in runs}, "laws": {}}
    for name, (law, slip_sinkage) in VARIANTS.items():
        # A fit whose simulations failed is reported as failed, with its reason, never as numbers.
        t0 = time.perf_counter()
        entry: dict[str, Any] = {}
        try:
            entry["fit"] = fit_rig(fmu, campaign, law, runs=runs, slip_sinkage=slip_sinkage)
            say(f"{study}, {name}: fitted ({entry['fit'].evaluations} evaluations, {time.perf_counter() - t0:.0f} s)")
        except FitError as exc:
            entry["fit_error"] = str(exc)
            say(f"{study}, {name}: {exc}")
        try:
            entry["held_out"] = held_out(fmu, campaign, runs, law, slip_sinkage)
            say(f"{study}, {name}: held-out prediction done")
        except FitError as exc:
            entry["held_out_error"] = str(exc)
            say(f"{study}, {name}: held-out fit: {exc}")
        out["laws"][name] = entry
    return out


def _g(v: float | None, digits: int = 3) -> str:
    return "-" if v is None or not np.isfinite(v) else f"{v:.{digits}g}"


def summary(data: dict[str, Any]) -> list[str]:
    """One table of the held-out rms errors of every study and quantity, the lowest in bold."""
    variants = list(VARIANTS)
    lines = ["## Held-out prediction, every study", "",
             "RMS error of the slips left out of the fit; the lowest of each row in bold.", "",
             "| study | quantity | " + " | ".join(variants) + " |", "|---|---|" + "---|" * len(variants)]
    for study, res in data["studies"].items():
        for q, unit in (("drawbar_pull", "N"), ("torque", "N m"), ("sinkage", "m")):
            values = [res["laws"].get(v, {}).get("held_out", {}).get("rms", {}).get(q) for v in variants]
            if all(v is None for v in values):
                continue
            best = min((v for v in values if v is not None), default=None)
            cells = [("failed" if "held_out_error" in res["laws"].get(v, {}) else "-") if x is None else
                     (f"**{_g(x)}**" if x == best else _g(x)) for v, x in zip(variants, values)]
            lines.append(f"| {study} | {q} [{unit}] | " + " | ".join(cells) + " |")
    return lines + [""]


def page(data: dict[str, Any]) -> str:
    """docs/results/wheel-rig-published.md from the results."""
    prov = data["provenance"]
    lines = ["# Both contact laws on published single-wheel testbed data", "",
             "<!-- Generated by scripts/published_wheel_rig.py: edit the script, not this file. -->", "",
             f"- command: `{prov['command']}`", f"- run: {prov['started']} to {prov['finished']}",
             f"- commit: {prov['commit']}", f"- machine: {prov['machine']}", "",
             "Measurements read off the figures of published testbed studies "
             "([data/published/single-wheel-published.csv](../../data/published/single-wheel-published.csv)), "
             "fitted with each contact law of the WheelRig FMU (see [wheel-rig.md](../wheel-rig.md)). "
             "The figures give no standard deviations: each quantity's noise scale is estimated from the fit's "
             "residuals. Held-out: fitted on alternate slips of each wheel, the other slips predicted.", ""]
    lines += summary(data)
    for study, res in data["studies"].items():
        lines += [f"## {study}", "", f"Source: {res['source']}.", ""]
        wheels = ", ".join(f"{rid} (radius {w['wheel']['radius']:.4g} m, width {w['wheel']['width']:.3g} m, lugs "
                           f"{w['wheel']['lug_height'] * 1000:.0f} mm x {w['wheel']['lug_count']}; "
                           f"{w['points']} points)" for rid, w in res["runs"].items())
        lines += [f"Wheels: {wheels}.", "", "| | " + " | ".join(res["laws"]) + " |",
                  "|---|" + "---|" * len(res["laws"])]
        for q, unit in (("drawbar_pull", "N"), ("torque", "N m"), ("sinkage", "m")):
            cells = [_g(r["fit"]["rms"].get(q)) if "fit" in r else "failed" for r in res["laws"].values()]
            if any(c not in ("-", "failed") for c in cells):
                lines.append(f"| rms error of the fit, {q} [{unit}] | " + " | ".join(cells) + " |")
        for q, unit in (("drawbar_pull", "N"), ("torque", "N m"), ("sinkage", "m")):
            cells = [_g(r["held_out"]["rms"].get(q)) if "held_out" in r else "failed" for r in res["laws"].values()]
            if any(c not in ("-", "failed") for c in cells):
                lines.append(f"| held-out rms error, {q} [{unit}] | " + " | ".join(cells) + " |")
        lines.append("")
        for law, r in res["laws"].items():
            for what in ("fit_error", "held_out_error"):
                if what in r:
                    lines += [f"{law}: the {'held-out ' if what == 'held_out_error' else ''}fit failed: "
                              f"{r[what]}", ""]
            if "fit" not in r:
                continue
            fit = r["fit"]
            lines += [f"{law}: status {fit['status']}, chi-square {_g(fit['chi2'])} on {fit['dof']} degrees of "
                      f"freedom, noise " + ", ".join(f"{c} {n}" for c, n in fit["noise"].items()) + ".", "",
                      "| parameter | estimate | 1 sigma | identifiability |", "|---|---|---|---|"]
            for k, v in fit["params"].items():
                lines.append(f"| {k} | {_g(v, 4)} | {_g(fit['std'][k], 2)} | {fit['identifiability'][k]} |")
            lines.append("")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sets", nargs="+", choices=sorted(SOURCES), default=list(SOURCES), help="studies to fit")
    ap.add_argument("--rig-fmu", help="the WheelRig FMU (default build/WheelRig.fmu)")
    ap.add_argument("--campaigns", type=Path, help="also write each study's campaign into this folder")
    ap.add_argument("--no-write", action="store_true", help="print the page, write no results file")
    args = ap.parse_args(argv)
    say = lambda m: print(m, file=sys.stderr, flush=True)  # noqa: E731
    started = _now()
    studies = read_published()
    results: dict[str, Any] = {}
    with RigFMU(args.rig_fmu) as fmu, tempfile.TemporaryDirectory(prefix="juno-published-") as tmp:
        for study in args.sets:
            folder = (args.campaigns or Path(tmp)) / f"published-{study}"
            campaign = write_study_campaign(study, studies[study], folder)
            results[study] = study_result(fmu, study, campaign, say)
    command = "scripts/published_wheel_rig.py" + (f" --sets {' '.join(args.sets)}" if args.sets != list(SOURCES) else "")
    data = to_jsonable({"provenance": {"command": command, "started": started, "finished": _now(),
                                       "commit": commit_description(), "machine": machine_description()},
                        "studies": results})
    text = page(data)
    if args.no_write:
        print(text)
        return 0
    _write(RESULTS_JSON, json.dumps(data, indent=1) + "\n")
    _write(RESULTS_MD, text + "\n")
    say(f"wrote {RESULTS_MD.relative_to(ROOT)} and {RESULTS_JSON.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
