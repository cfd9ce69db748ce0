"""How strong a ripple in the wheel angle a right model leaves, and how strong the lug ripple is:
the calibration of the periodic test's materiality floor (juno.periodic_structure.MATERIAL_FRACTION).

Opt-in study (a few seconds per campaign).  For each seed and campaign design, a campaign with
nothing hidden and one hiding the ``lug_ripple`` form are synthesized; the drawbar runs are
replayed with the true soil (and, for the ripple campaign, the catalog grouser's true thrust
gain and lug height: what the grouser candidate fits, without the ripple), and the periodic test
is run on the held-out torque residuals with the diagnosis's alternating 4 s blocks.  Prints,
per case and signal, the strongest N, its amplitude over the sensor noise and its p-value.

    .venv/bin/python scripts/periodic_calibration.py --seeds 4 --first-seed 500
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "python_harness"))

from juno.campaign import load_campaign, read_run  # noqa: E402
from juno.identify import prepare_run, run_residuals  # noqa: E402
from juno.residual_structure import residual_labels  # noqa: E402
from juno.periodic_structure import MATERIAL_FRACTION, PeriodicStructure, periodic_structure, \
    series_of_residuals  # noqa: E402
from juno.simulator import JunoFMU  # noqa: E402
from juno.synthesize import synthesize  # noqa: E402

BLOCK = 4.0            # s, the diagnosis's alternating training / held-out blocks
STEP = 5e-3            # s, the diagnosis's integration step
GROUSER = ("grouser.thrustGain", "grouser.lugHeight")


def periodic_at(fmu: JunoFMU, root: Path, params: dict[str, float]) -> PeriodicStructure:
    """The periodic test of the drawbar runs of the campaign at ``root`` replayed with the FMU
    parameters ``params`` (soil and extensions)."""
    campaign = load_campaign(root)
    prepared = [prepare_run(campaign, run) for run in campaign.runs_of_kind("drawbar")]
    for p in prepared:
        p.params["solver.step"] = STEP
    meta = residual_labels(prepared, BLOCK)
    block = meta["block"]
    soil = {k: v for k, v in params.items() if k.startswith("soil.")}
    extra = {k: v for k, v in params.items() if not k.startswith("soil.")}
    r = np.concatenate([run_residuals(fmu, p, soil, extra, 0.05) for p in prepared])
    data = {p.run_id: read_run(campaign, p.run_id) for p in prepared}
    return periodic_structure(series_of_residuals(prepared, meta, block % 2 == 0, r, data),
                              {"torque_left": "N m", "torque_right": "N m"})


def one_case(fmu: JunoFMU, effect: str, seed: int, design: str, strength: float) -> dict:
    with tempfile.TemporaryDirectory(prefix="juno-periodic-") as tmp:
        path = synthesize(Path(tmp) / "campaign", effect=effect, strength=strength, seed=seed, noise=1.0,
                          fmu=fmu, design=design)
        truth = json.loads((path / "truth.json").read_text())
        hidden = truth.get("hidden", {}).get("sim", {})
        params = {**truth["soil"], **{k: v for k, v in hidden.items() if k in GROUSER}}
        result = periodic_at(fmu, path, params)
    return {"effect": effect, "strength": strength, "seed": seed, "design": design,
            "signals": [s.to_json() for s in result.signals], "significant": result.significant}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--first-seed", type=int, default=500)
    ap.add_argument("--designs", nargs="+", default=["default", "alt"])
    ap.add_argument("--strengths", nargs="+", type=float, default=[1.0, 0.3], help="of the lug_ripple form")
    ap.add_argument("--fmu", default=None)
    ap.add_argument("--json", default=None, help="write every case to this file")
    args = ap.parse_args(argv)
    cases = []
    print(f"materiality floor {MATERIAL_FRACTION:g} x the sensor noise")
    with JunoFMU(args.fmu) as fmu:
        for design in args.designs:
            for seed in range(args.first_seed, args.first_seed + args.seeds):
                for effect, strength in [("none", 1.0)] + [("lug_ripple", s) for s in args.strengths]:
                    t0 = time.perf_counter()
                    case = one_case(fmu, effect, seed, design, strength)
                    cases.append(case)
                    print(f"{design:8s} seed {seed} {effect:10s} x{strength:g}: " + "; ".join(
                        f"{s['signal']} N={s['per_revolution']} {s['ratio_to_noise']:.3f} sigma p={s['p_value']:.2g}"
                        for s in case["signals"]) + f"; reported {case['significant']} "
                        f"({time.perf_counter() - t0:.0f} s)", flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(cases, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
