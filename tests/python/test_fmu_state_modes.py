"""FMU states carry their FMI mode: restoring one taken before initialisation, then one taken
while stepping, must work on an instance that has been initialised (found by fuzz_state: the
second restore was refused because the first had left the instance in Instantiated mode)."""

from fmpy import read_model_description
from fmpy.fmi2 import FMU2Slave


def test_restore_instantiated_then_stepping_state(fmu_path, fmu_unzipped):
    md = read_model_description(str(fmu_path))
    slave = FMU2Slave(guid=md.guid, unzipDirectory=fmu_unzipped,
                      modelIdentifier=md.coSimulation.modelIdentifier, instanceName="modes")
    slave.instantiate()
    try:
        before_init = slave.getFMUstate()
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        slave.exitInitializationMode()
        for k in range(10):
            slave.doStep(k * 0.01, 0.01)
        stepping = slave.getFMUstate()
        x_vr = [v.valueReference for v in md.modelVariables if v.name == "x"]
        x_at_state = slave.getReal(x_vr)[0]
        slave.setFMUstate(before_init)          # back to Instantiated mode
        slave.setFMUstate(stepping)             # and forward again: must be accepted
        assert slave.getReal(x_vr)[0] == x_at_state
        slave.doStep(0.1, 0.01)                 # and it steps on from 0.1 s
        slave.freeFMUstate(before_init)
        slave.freeFMUstate(stepping)
    finally:
        slave.freeInstance()


def test_a_stepping_state_needs_an_initialised_instance_and_then_continues_exactly(fmu_path, fmu_unzipped):
    """A state serialised after initialisation: a fresh instance refuses it (the terrain and what
    initialisation loads are not in the state), the same instance once initialised takes it and
    steps on exactly as the original did."""
    import pytest
    md = read_model_description(str(fmu_path))
    x_vr = [v.valueReference for v in md.modelVariables if v.name in ("x", "vx", "z")]

    def instance(name):
        s = FMU2Slave(guid=md.guid, unzipDirectory=fmu_unzipped,
                      modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
        s.instantiate()
        return s

    def initialise(s):
        s.setupExperiment(startTime=0.0)
        s.enterInitializationMode()
        s.exitInitializationMode()

    original, fresh = instance("original"), instance("fresh")
    try:
        initialise(original)
        for k in range(20):
            original.doStep(k * 0.01, 0.01)
        state = original.getFMUstate()
        blob = original.serializeFMUstate(state)
        original.doStep(0.2, 0.01)
        expected = original.getReal(x_vr)

        early = fresh.deSerializeFMUstate(blob)
        with pytest.raises(Exception, match=r"fmi2SetFMUstate.*status 3"):
            fresh.setFMUstate(early)                               # fresh: refused (fmi2Error)
        fresh.freeFMUstate(early)
        initialise(fresh)
        restored = fresh.deSerializeFMUstate(blob)
        fresh.setFMUstate(restored)                                # initialised: accepted
        fresh.doStep(0.2, 0.01)
        assert fresh.getReal(x_vr) == expected
        fresh.freeFMUstate(restored)
        original.freeFMUstate(state)
    finally:
        original.freeInstance()
        fresh.freeInstance()


def test_a_stepping_state_is_restored_only_on_the_ground_it_was_taken_on(fmu_unzipped, tmp_path):
    """The terrain grid is loaded at initialisation, not held in the state: a state taken on a
    grid is refused by an instance initialised on flat ground (it would drop the rover half a
    metre) or on another grid, naming terrain.file, and taken by one that loaded the same grid,
    from whatever path, which then steps on exactly as the original did."""
    import numpy as np
    import pytest

    from fmu_helpers import FMICallException, LogCapture, Rover, write_asc

    raised = write_asc(tmp_path / "raised.asc", np.full((4, 4), 0.5), -60.0, -60.0, 40.0)
    (tmp_path / "copy").mkdir()
    same = write_asc(tmp_path / "copy" / "raised again.asc", np.full((4, 4), 0.5), -60.0, -60.0, 40.0)
    higher = write_asc(tmp_path / "higher.asc", np.full((4, 4), 0.6), -60.0, -60.0, 40.0)
    names = ["x", "z", "vx", "wheelFL.Fn"]
    with Rover(fmu_unzipped, "original") as original:
        original.setup({"terrain.file": raised})
        original.advance(20, 0.01)
        blob = original.fmu.serializeFMUstate(original.fmu.getFMUstate())
        expected = original.advance(5, 0.01, names=names)
    for ground in ("", higher):
        log = LogCapture()
        with Rover(fmu_unzipped, "elsewhere", log=log) as other:
            other.setup({"terrain.file": ground})
            state = other.fmu.deSerializeFMUstate(blob)
            with pytest.raises(FMICallException):
                other.fmu.setFMUstate(state)
            assert any("fmi2SetFMUstate" in m and "terrain.file" in m for m in log.errors()), log.text()
            other.advance(1, 0.01)                  # refused: the instance steps on its own ground
    with Rover(fmu_unzipped, "same ground") as copy:
        copy.setup({"terrain.file": same})
        copy.fmu.setFMUstate(copy.fmu.deSerializeFMUstate(blob))
        copy.time = 0.2
        np.testing.assert_array_equal(copy.advance(5, 0.01, names=names), expected)
