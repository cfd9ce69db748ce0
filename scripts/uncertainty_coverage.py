#!/usr/bin/env python3
"""Are the joint fit's stated uncertainties honest?  An opt-in study of their coverage.

For each campaign design and seed, a campaign with nothing hidden is synthesized (sensor noise
as the design has it), and the soil is fitted jointly (``juno identify --method joint``), once
on the campaign as it is and once with its IMU angles (roll, pitch, yaw) removed.  Each fitted
parameter's z-score against the truth, (estimate - truth) / stated 1 sigma, should scatter as a
standard normal if the stated uncertainty is honest: an RMS of z near 1, and |z| <= 2 for about
95 % of the estimates.  An RMS well above 1 means the fit states more certainty than it has.
The 1 sigma is the total: the sensors' noise and the replay's own bias (the fit's bootstrap,
asked for on every campaign) in quadrature.  Beside it the table gives the z-scores against the
noise's part alone (what a fit of a campaign with every column states by default, without the
bootstrap), and those of the estimate corrected by the bootstrap's bias (estimate - bias), which
the fit does not do.
Writes docs/results/uncertainty-coverage.md and .json (date, commit, machine).

Run it offline (a few minutes per design and seed on 2 cores):

    .venv/bin/python scripts/uncertainty_coverage.py --seeds 8 --first-seed 140001
"""

from __future__ import annotations

import argparse
import csv
import json
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "python_harness"))
sys.path.insert(0, str(ROOT / "scripts"))

from generate_docs import _now, _write, commit_description, machine_description  # noqa: E402

from juno.campaign import load_campaign  # noqa: E402
from juno.identify import identify_joint  # noqa: E402
from juno.rover_model import SOIL_PARAMETERS  # noqa: E402
from juno.simulator import JunoFMU  # noqa: E402
from juno.synthesize import synthesize  # noqa: E402

RESULTS = ROOT / "docs" / "results"
#: The IMU's attitude columns, which the "no IMU angles" variant removes.
IMU_ANGLES = ("roll", "pitch", "yaw")
#: |z| within this counts as covered; a standard normal lies within it 95.4 % of the time.
COVERED_Z = 2.0


def without_imu_angles(src: Path, dst: Path) -> Path:
    """A copy of campaign ``src`` at ``dst`` whose run CSVs have no roll, pitch or yaw column
    (rows left with nothing but their time dropped)."""
    shutil.copytree(src, dst)
    manifest = json.loads((dst / "campaign.json").read_text())
    for run in manifest["runs"]:
        path = dst / run["file"]
        with path.open(newline="") as f:
            rows = list(csv.reader(f))
        keep = [i for i, name in enumerate(rows[0]) if name not in IMU_ANGLES]
        header = [rows[0][i] for i in keep]
        body = [[row[i] for i in keep] for row in rows[1:]]
        body = [row for row in body if any(c for name, c in zip(header, row) if name != "time")]
        with path.open("w", newline="") as f:
            csv.writer(f).writerows([header] + body)
    return dst


def one_fit(fmu: JunoFMU, root: Path, truth: dict[str, float]) -> dict:
    """The joint fit of the campaign at ``root``: its status, its estimates' z-scores against
    ``truth`` (None where no uncertainty is stated), its evaluations and doubts."""
    t0 = time.perf_counter()
    fit = identify_joint(fmu, load_campaign(root), workers=1, estimate_bias=True)
    bias = {k: fit.replay_bias[k] for k in SOIL_PARAMETERS}

    def ratio(offset: dict[str, float], sigma: dict[str, float]) -> dict[str, float | None]:
        return {k: (float(offset[k] / sigma[k]) if np.isfinite(sigma[k]) and sigma[k] > 0 else None)
                for k in SOIL_PARAMETERS}
    error = {k: fit.params[k] - truth[k] for k in SOIL_PARAMETERS}
    return {"status": fit.status, "z": ratio(error, fit.std), "z_statistical": ratio(error, fit.std_statistical),
            "z_corrected": ratio({k: error[k] - bias[k] for k in SOIL_PARAMETERS}, fit.std),
            "bias_in_statistical_sigmas": ratio(bias, fit.std_statistical),
            "relative_std": {k: float(fit.relative_std[k]) for k in SOIL_PARAMETERS},
            "relative_bias": {k: float(bias[k] / fit.params[k]) for k in SOIL_PARAMETERS},
            "bias_refit": fit.bias_refit, "evaluations": fit.evaluations, "doubts": list(fit.doubts),
            "seconds": time.perf_counter() - t0}


def _values(cases: list[dict], key: str) -> np.ndarray:
    return np.array([v for c in cases for v in c[key].values() if v is not None], float)


def _rms(cases: list[dict], key: str) -> str:
    values = _values(cases, key)
    return f"{np.sqrt(np.mean(values ** 2)):.2f}" if values.size else "-"


def _median_abs(cases: list[dict], key: str) -> str:
    values = _values(cases, key)
    return f"{np.median(np.abs(values)):.2f}" if values.size else "-"


def page(cases: list[dict], started: str) -> str:
    lines = ["# How honest the joint fit's uncertainties are", "",
             "<!-- Generated by scripts/uncertainty_coverage.py: edit the script, not this file. -->", "",
             f"- run: {started} to {_now()}", f"- commit: {commit_description()}",
             f"- machine: {machine_description()}", "",
             "Campaigns with nothing hidden (the design's sensor noise), the soil fitted jointly "
             "([identification.md](../identification.md#the-joint-fit---method-joint)); each estimate's z-score is "
             "(estimate - truth) / its 1 sigma, the sensors' noise and the replay's own bias in quadrature (the "
             "bootstrap asked for on every campaign; by default a fit states it where its runs lack a column). "
             "Honest uncertainties give z-scores like a standard normal: "
             f"an RMS near 1 and |z| <= {COVERED_Z:g} for about 95 % of them. Fits stated without an uncertainty "
             "(status not converged or not identified) count apart. Then, over all four parameters: the RMS of "
             "the z-scores; the RMS of the z-scores against the noise's part of the 1 sigma alone (what a fit of a "
             "campaign with every column states by default); the RMS of the "
             "z-scores of the estimate "
             "corrected by the bootstrap's bias (estimate - bias, against the stated 1 sigma; the fit does not "
             "correct); the median size of the bias in the noise's sigmas.", "",
             "| design | IMU angles | fits | with an uncertainty | " + " | ".join(f"RMS z {k}" for k in SOIL_PARAMETERS)
             + f" | largest abs(z) | abs(z) <= {COVERED_Z:g} | RMS z, all four | RMS z, noise's sigma alone "
               "| RMS z, bias-corrected | median abs(bias) / noise's sigma | fits with a doubt |",
             "|---|---|---|---|" + "---|" * len(SOIL_PARAMETERS) + "---|---|---|---|---|---|---|"]
    for design, variant in sorted({(c["design"], c["variant"]) for c in cases}):
        mine = [c for c in cases if c["design"] == design and c["variant"] == variant]
        stated = [c for c in mine if all(v is not None for v in c["z"].values())]
        cells = []
        for k in SOIL_PARAMETERS:
            zs = np.array([c["z"][k] for c in stated], float)
            cells.append(f"{np.sqrt(np.mean(zs ** 2)):.2f}" if zs.size else "-")
        every = np.array([v for c in stated for v in c["z"].values()], float)
        largest = f"{np.max(np.abs(every)):.1f}" if every.size else "-"
        covered = f"{np.mean(np.abs(every) <= COVERED_Z):.0%}" if every.size else "-"
        doubted = sum(bool(c["doubts"]) for c in mine)
        lines.append(f"| {design} | {'yes' if variant == 'full' else 'none'} | {len(mine)} | {len(stated)} | "
                     + " | ".join(cells) + f" | {largest} | {covered} | {_rms(stated, 'z')} | "
                     f"{_rms(stated, 'z_statistical')} | "
                     f"{_rms(stated, 'z_corrected')} | {_median_abs(stated, 'bias_in_statistical_sigmas')} | "
                     f"{doubted} |")
    lines += ["", "Seeds: " + ", ".join(str(s) for s in sorted({c["seed"] for c in cases})) + ".", ""]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=8, help="campaigns per design")
    ap.add_argument("--first-seed", type=int, default=140001)
    ap.add_argument("--designs", nargs="+", default=["default", "alt"])
    ap.add_argument("--fmu", default=None)
    args = ap.parse_args(argv)
    started = _now()
    cases = []
    with JunoFMU(args.fmu) as fmu, tempfile.TemporaryDirectory(prefix="juno-coverage-") as tmp:
        for design in args.designs:
            for seed in range(args.first_seed, args.first_seed + args.seeds):
                root = synthesize(Path(tmp) / f"{design}-{seed}", effect="none", seed=seed, noise=1.0, fmu=fmu,
                                  design=design)
                truth = json.loads((Path(root) / "truth.json").read_text())["soil"]
                stripped = without_imu_angles(Path(root), Path(tmp) / f"{design}-{seed}-no-imu")
                for variant, path in (("full", Path(root)), ("no IMU angles", stripped)):
                    case = {"design": design, "seed": seed, "variant": variant, **one_fit(fmu, path, truth)}
                    cases.append(case)
                    print(f"{design:8s} seed {seed} {variant:13s}: {case['status']}; z "
                          + ", ".join(f"{k} {'-' if v is None else f'{v:+.2f}'}" for k, v in case["z"].items())
                          + f"; {case['evaluations']} evaluations, {len(case['doubts'])} doubts "
                          f"({case['seconds']:.0f} s)", flush=True)
    _write(RESULTS / "uncertainty-coverage.json",
           json.dumps({"provenance": {"run": started, "commit": commit_description(), "machine": machine_description()},
                       "covered_z": COVERED_Z, "cases": cases}, indent=1) + "\n")
    _write(RESULTS / "uncertainty-coverage.md", page(cases, started))
    return 0


if __name__ == "__main__":
    sys.exit(main())
