"""JunoFMU.simulate's stepping loop (direct ctypes calls, outputs read into the result in place,
held input rows not set again) gives what a plain fmpy loop gives, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

from juno.simulator import DEFAULT_OUTPUTS, InputSignals, JunoFMU, SimulationError


def plain_fmpy_run(fmu_path: str, parameters: dict, inputs: InputSignals, stop: float, dt: float,
                   outputs) -> dict[str, np.ndarray]:
    """The textbook fmpy co-simulation loop: set every input, doStep, getReal, every step."""
    md = read_model_description(fmu_path)
    vrs = {v.name: v.valueReference for v in md.modelVariables}
    slave = FMU2Slave(guid=md.guid, unzipDirectory=extract(fmu_path),
                      modelIdentifier=md.coSimulation.modelIdentifier, instanceName="plain")
    slave.instantiate()
    slave.setupExperiment(startTime=0.0)
    for name, value in parameters.items():
        if isinstance(value, int):
            slave.setInteger([vrs[name]], [value])
        else:
            slave.setReal([vrs[name]], [float(value)])
    n = int(round(stop / dt))
    times = dt * np.arange(n + 1)
    in_names = list(inputs.values)
    table = np.column_stack([np.interp(times, inputs.time, inputs.values[k]) for k in in_names])
    in_vrs = [vrs[k] for k in in_names]
    out_vrs = [vrs[k] for k in outputs]
    slave.setReal(in_vrs, list(table[0]))
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    rows = [slave.getReal(out_vrs)]
    for k in range(n):
        slave.setReal(in_vrs, list(table[k]))
        slave.doStep(times[k], dt)
        rows.append(slave.getReal(out_vrs))
    slave.terminate()
    slave.freeInstance()
    data = np.array(rows)
    return {"time": times, **{name: data[:, i] for i, name in enumerate(outputs)}}


@pytest.fixture(scope="module")
def juno(fmu_path):
    fmu = JunoFMU(fmu_path)
    yield fmu
    fmu.close()


# Inputs held for a while, then changed (steps and a ramp): rows equal to the previous one are
# where the loop skips fmi2SetReal.
T = np.array([0.0, 2.0, 2.0, 4.0, 6.0, 6.0, 10.0])
HELD_AND_CHANGING = InputSignals(T, {
    "drawbarForce": np.array([400.0, 400.0, 100.0, 100.0, 500.0, 250.0, 250.0]),
    "throttleLeft": np.array([0.45, 0.45, 0.45, 0.6, 0.6, 0.3, 0.3]),
    "throttleRight": np.full(T.size, 0.45),
})


@pytest.mark.parametrize("outputs", [DEFAULT_OUTPUTS, ("x", "wheelRR.sinkage", "torqueLeftApplied")])
def test_simulate_equals_a_plain_fmpy_loop(juno, fmu_path, outputs):
    params = {"drive.mode": 2, "solver.step": 0.005}
    got = juno.simulate(params, HELD_AND_CHANGING, 10.0, 0.01, outputs=outputs)
    want = plain_fmpy_run(fmu_path, params, HELD_AND_CHANGING, 10.0, 0.01, outputs)
    assert got.keys() == want.keys()
    for name in want:
        np.testing.assert_array_equal(got[name], want[name], err_msg=name)
    assert np.ptp(got["x"]) > 1.0          # the rover did drive


def test_an_input_refused_mid_run_stops_with_the_fmus_message(juno):
    t = np.array([0.0, 1.0, 1.0, 3.0])
    bad = InputSignals(t, {"throttleLeft": np.array([0.5, 0.5, 5.0, 5.0])})
    with pytest.raises(SimulationError, match=r"t = 1\.000 s.*throttleLeft.*outside its range"):
        juno.simulate({"drive.mode": 2}, bad, 3.0, 0.01)
    # the instance is reset and usable after the failure
    res = juno.simulate({"drive.mode": 2}, None, 1.0, 0.01, outputs=("x",))
    assert np.all(np.isfinite(res["x"]))
