"""Write modelDescription/JunoRover_ref.csv: the reference result of the FMU's default experiment
(0 to 30 s, communication step 0.01 s, the start values), sampled every 0.5 s.

The build packs it into the FMU as ``extra/JunoRover_ref.csv``, as the FMI Reference FMUs ship
theirs; tests/python/test_fmu_documentation.py simulates the default experiment afresh and
compares.  Run it again after a change that changes the default experiment's result:

    .venv/bin/python scripts/make_reference_result.py [--fmu build/JunoRover.fmu]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
REFERENCE = ROOT / "modelDescription" / "JunoRover_ref.csv"
#: The outputs the reference result holds: the pose, the speeds, the drive and the front left wheel.
OUTPUTS = ("x", "y", "z", "yaw", "pitch", "vx", "omegaLeft", "omegaRight", "torqueLeftApplied",
           "torqueRightApplied", "wheelFL.sinkage", "wheelFL.slip", "wheelFL.Fn", "wheelFL.Ft")
OUTPUT_INTERVAL = 0.5   # s


def default_experiment(fmu: str | Path) -> np.ndarray:
    """The FMU's default experiment as fmpy runs it: a structured array of time and OUTPUTS."""
    from fmpy import read_model_description, simulate_fmu
    md = read_model_description(str(fmu))
    exp = md.defaultExperiment
    return simulate_fmu(str(fmu), start_time=float(exp.startTime), stop_time=float(exp.stopTime),
                        step_size=float(exp.stepSize), output_interval=OUTPUT_INTERVAL, output=list(OUTPUTS))


def format_csv(result: np.ndarray) -> str:
    names = result.dtype.names
    lines = [",".join(f'"{n}"' for n in names)]
    lines += [",".join(f"{float(row[n]):.17g}" for n in names) for row in result]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fmu", default=str(ROOT / "build" / "JunoRover.fmu"), help="the built FMU")
    args = ap.parse_args(argv)
    if not Path(args.fmu).is_file():
        print(f"{args.fmu}: FMU not found (cmake --build build first)", file=sys.stderr)
        return 2
    sys.path.insert(0, str(ROOT / "python_harness"))
    from juno.atomic import atomic_write_text
    atomic_write_text(REFERENCE, format_csv(default_experiment(args.fmu)))
    print(f"wrote {REFERENCE.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
