"""The FMU's default step, the automatic one, is accurate: on the benchmark runs, slip, drive
torque and sinkage at the FMU's default solver settings (AUTOMATIC) stay within ACCURACY of a
converged reference, and the automatic step runs wherever the fixed 1 ms step runs.

solver.tolerance > 0 takes each internal step as a two-stage linearly implicit step with an
embedded first-order solution, the step chosen by their difference, up to solver.step.  The runs are those the benchmarks time and
a PID run that the importer drives with stepped references:

* drawbar - 30 s on flat ground at the start values (motor drive at 45 % throttle, 400 N);
* terrain - 60 s over a 0.5 m mound with 4 mm undulations (bench/bench_fmu.c's grid), 45 %
  throttle, no drawbar;
* pid     - 20 s of PID speed control, the references stepped 1 -> 2 -> 3 -> 1.5 -> 2.5 rad/s
  every 4 s (the right side 10 % slower, so the rover turns), against 300 N.

The metric, per signal (the four wheels' slip and sinkage, the two drive torques): the RMS
of the difference from the reference over the run after its first SETTLE seconds (the start
from the static equilibrium), relative to the reference signal's own RMS over the same span;
every signal of every run must be within ACCURACY.  The reference is the same run at a fixed
step of REFERENCE_STEP; fixed steps of 0.25 ms and 0.125 ms are within 0.073 % and 0.025 % of
it on these runs (measured when the bound was set): the difference shrinks in proportion to
the step, as a first-order method's error does, so the reference stands for the converged
solution to about 0.03 %.
"""

from __future__ import annotations

import math

import numpy as np

from fmu_helpers import WHEELS, FMICallException, LogCapture, Rover, model_description, run, slope_grid, write_asc
from test_fmu_ranges import _values, _walked_variables

ACCURACY = 2e-3            # relative RMS difference from the converged reference
AUTOMATIC = {"solver.step": 0.02, "solver.tolerance": 4e-4}   # the FMU's default
FIXED_1MS = {"solver.step": 1e-3, "solver.tolerance": 0.0}    # the fixed step the harness pins
REFERENCE_STEP = 6.25e-5   # s, fixed
COMM_STEP = 0.02           # s
SETTLE = 5.0               # s

SIGNALS = ([f"wheel{w}.slip" for w in WHEELS] + [f"wheel{w}.sinkage" for w in WHEELS]
           + ["torqueLeftApplied", "torqueRightApplied"])


def mound_grid(path) -> str:
    """bench_fmu's terrain: a 0.5 m Gaussian mound at (4, 0.35) m with 4 mm undulations, 2 cm
    cells over x -1..9 m, y -2.3..2.3 m."""
    x = -1.0 + 0.02 * np.arange(501)
    y = -2.3 + 0.02 * np.arange(231)
    X, Y = np.meshgrid(x, y)
    z = 0.5 * np.exp(-((X - 4.0) ** 2 / (2 * 0.81) + (Y - 0.35) ** 2 / (2 * 0.49)))
    for a, b, c in ((1.3, 2.1, 0.4), (2.7, 1.2, 2.2), (1.9, 2.8, 4.1), (1.1, 1.6, 5.3)):
        z += 0.004 * np.sin(a * X + b * Y + c)
    return write_asc(path, np.round(z, 6), -1.0, -2.3, 0.02)


def pid_reference(t: float) -> float:
    """The stepped speed reference of the pid run, rad/s."""
    return (1.0, 2.0, 3.0, 1.5, 2.5)[min(int(t // 4.0), 4)]


def _runs(tmp_path) -> dict[str, tuple[dict, object, float]]:
    return {
        "drawbar": ({}, None, 30.0),
        "terrain": ({"terrain.file": mound_grid(tmp_path / "mound.asc"), "init.x": 0.8},
                    {"drawbarForce": 0.0, "throttleLeft": 0.45, "throttleRight": 0.45}, 60.0),
        "pid": ({"drive.mode": 1},
                {"drawbarForce": 300.0, "omegaRefLeft": pid_reference,
                 "omegaRefRight": lambda t: 0.9 * pid_reference(t)}, 20.0),
    }


def relative_rms_error(value: np.ndarray, reference: np.ndarray, time: np.ndarray) -> float:
    """RMS of value - reference after SETTLE s, relative to the reference's RMS there."""
    part = time >= SETTLE
    return float(np.sqrt(np.mean((value[part] - reference[part]) ** 2) / np.mean(reference[part] ** 2)))


def _worst_errors(fmu_unzipped, tmp_path, setting: dict) -> dict[str, tuple[str, float]]:
    """Run name -> (signal, relative RMS difference) of the signal farthest from the reference,
    at the solver ``setting`` (FMU parameters; {} for the FMU's default)."""
    worst = {}
    for name, (params, inputs, duration) in _runs(tmp_path).items():
        result = run(fmu_unzipped, {**params, **setting}, inputs, stop_time=duration, step=COMM_STEP,
                     outputs=SIGNALS)
        ref = run(fmu_unzipped, {**params, "solver.step": REFERENCE_STEP, "solver.tolerance": 0.0}, inputs,
                  stop_time=duration, step=COMM_STEP, outputs=SIGNALS)
        errors = {s: relative_rms_error(result[s], ref[s], ref["time"]) for s in SIGNALS}
        assert all(math.isfinite(e) for e in errors.values()), (name, errors)
        worst[name] = max(errors.items(), key=lambda kv: kv[1])
    return worst


def test_the_default_solver_setting_is_the_automatic_step(fmu_unzipped):
    """The FMU declares AUTOMATIC as its solver parameters' start values: a tool that sets
    nothing gets the setting the next test bounds."""
    declared = {v.name: float(v.start) for v in model_description(fmu_unzipped).modelVariables
                if v.name in AUTOMATIC}
    assert declared == AUTOMATIC


def test_the_default_step_is_within_the_accuracy_bound_of_a_converged_reference(fmu_unzipped, tmp_path):
    """Nothing set: every run's every signal within ACCURACY of the reference."""
    worst = _worst_errors(fmu_unzipped, tmp_path, {})
    print("\nthe default: worst relative RMS difference from the reference: "
          + ", ".join(f"{n}: {s} {e:.3%}" for n, (s, e) in worst.items()))
    for name, (signal, error) in worst.items():
        assert error <= ACCURACY, f"{name} run: {signal} differs from the converged reference by {error:.3%} RMS"


def test_the_metric_sees_a_step_that_is_too_large(fmu_unzipped, tmp_path):
    """The bound is not vacuous: a fixed 10 ms step exceeds it on the terrain run."""
    params, inputs, duration = _runs(tmp_path)["terrain"]
    coarse = run(fmu_unzipped, {**params, "solver.step": 0.01, "solver.tolerance": 0.0}, inputs,
                 stop_time=duration, step=COMM_STEP, outputs=SIGNALS)
    ref = run(fmu_unzipped, {**params, "solver.step": 2.5e-4, "solver.tolerance": 0.0}, inputs,
              stop_time=duration, step=COMM_STEP, outputs=SIGNALS)
    worst = max(relative_rms_error(coarse[s], ref[s], ref["time"]) for s in SIGNALS)
    print(f"\nterrain run at a fixed 10 ms: worst relative RMS difference {worst:.3%}")
    assert worst > ACCURACY


# ---------------------------------------------------------------------------------------------
# Stability: the automatic step runs wherever the fixed 1 ms step runs
# ---------------------------------------------------------------------------------------------

STABILITY_TIME = 3.0     # s of driving after initialisation
LOOSE = {"solver.step": 0.02, "solver.tolerance": 1e-2}   # mostly 20 ms steps


def _outcome(fmu_unzipped, params) -> str:
    """'ran', 'refused' (initialisation failed) or the error of the step that failed."""
    log = LogCapture()
    try:
        run(fmu_unzipped, params, None, stop_time=STABILITY_TIME, step=0.1, outputs=["x"], log=log)
        return "ran"
    except FMICallException as exc:
        if "fmi2DoStep" not in str(exc):
            return "refused"
        return log.text().strip().splitlines()[-1] if log.text().strip() else str(exc)


def test_the_automatic_step_runs_wherever_the_fixed_1ms_step_runs(fmu_unzipped, tmp_path):
    """Every value of every declared range that tests/python/test_fmu_ranges.py walks (the
    heaviest rover, the softest soil, the stiffest PID, ...; not the solver's own, which the
    automatic setting replaces) and a 15 degree slope: driven for
    STABILITY_TIME s at the start values otherwise, a case the fixed 1 ms step runs must run
    with the automatic step too, at a tolerance so loose that it takes steps of up to 20 ms
    wherever it can: a step whose state diverges is taken again, shorter."""
    cases = [(f"{v.name} = {value!r} ({where})", {v.name: value})
             for v in _walked_variables(fmu_unzipped) if not v.name.startswith("solver.")
             for value, where in _values(v)]
    cases.append(("a 15 degree slope", {"terrain.file": slope_grid(15.0).write(tmp_path / "slope.asc")}))
    problems, ran = [], 0
    for what, params in cases:
        fixed = _outcome(fmu_unzipped, {**params, **FIXED_1MS})
        if fixed != "ran":
            continue
        ran += 1
        automatic = _outcome(fmu_unzipped, {**params, **LOOSE})
        if automatic != "ran":
            problems.append(f"{what}: runs at the fixed step, not with the automatic one: {automatic}")
    print(f"\n{ran} of {len(cases)} cases run at the fixed step")
    assert ran > len(cases) // 2
    assert not problems, "\n".join(problems)


def test_on_the_stiffest_soils_the_automatic_step_keeps_the_rover_on_its_wheels(fmu_unzipped):
    """On soil.kh = 1e8 and 5e7 (the stiffest values the range walk takes) at the loose
    tolerance, where what the step's linearisation leaves out varies as fast as the step (the
    chassis pitching on its wheels in a few steps a period), the correction carried from the
    last step must not feed that pitching:
    driven at the start values for STABILITY_TIME s, height and pitch follow the fixed 1 ms
    step's at every sample within 0.1 mm and 0.2 mrad (about five times the differences
    measured when the bounds were set; a rover thrown by the correction flies metres high)."""
    names = ["z", "pitch"]
    for kh in (1e8, 5e7):
        fixed = run(fmu_unzipped, {"soil.kh": kh, **FIXED_1MS}, None, stop_time=STABILITY_TIME, step=0.1,
                    outputs=names)
        loose = run(fmu_unzipped, {"soil.kh": kh, **LOOSE}, None, stop_time=STABILITY_TIME, step=0.1,
                    outputs=names)
        assert np.max(np.abs(loose["z"] - fixed["z"])) <= 1e-4, f"soil.kh = {kh:g}: height"
        assert np.max(np.abs(loose["pitch"] - fixed["pitch"])) <= 2e-4, f"soil.kh = {kh:g}: pitch"


def test_a_restored_state_continues_the_automatic_step_exactly(fmu_unzipped):
    """The automatic step's next step size is part of the FMU state: a state taken mid-run and
    restored (also after the run went on with other steps) continues bit for bit."""
    names = SIGNALS + ["x", "vx"]
    with Rover(fmu_unzipped) as r:
        r.setup(AUTOMATIC)
        r.advance(150, 0.01, names=names)                 # through the start, steps growing
        state = r.fmu.getFMUstate()
        t = r.time
        first = r.advance(50, 0.01, names=names)
        r.fmu.setFMUstate(state)
        r.time = t
        again = r.advance(50, 0.01, names=names)
        r.fmu.freeFMUstate(state)
    assert np.array_equal(first, again)
