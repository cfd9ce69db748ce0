"""The torque-driven replay (identify.prepare_run's ``drive="torque"``): the measured drive torque
drives each side, damped towards the measured spin as a DC motor's back-EMF does at a constant
throttle.  The diagnosis replays the terrain run this way where it fits the training blocks
better than the spin replay (diagnose.choose_terrain_drive).

Why it exists: where the rover climbs a mound at high slip, imposing the measured spins is
ill-conditioned.  On a noise-free synthetic terrain run with a drivetrain loss and slip-sinkage
(seed 3199, the campaign this file builds), the spin replay at the truth, even at the truth's
own 1 ms step, lifts a front wheel off for seconds and misses the torque by about 9 sigma; the
torque replay reproduces it.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from juno.campaign import RunData, load_campaign, read_run
from juno.identify import (REPLAY_DRIVES, REPLAY_MOTOR, REPLAY_SPIN_DAMPING, prepare_run, run_residuals,
                           torque_replay_throttle)
from juno.simulator import SOIL_PARAMETERS, InputSignals, JunoFMU
from juno.synthesize import synthesize
from juno.validate import grid_terrain

pytest_plugins = ["harness_fixtures"]


@pytest.fixture(scope="module")
def climbing_at_high_slip(tmp_path_factory, harness_fmu):
    """A noise-free campaign whose terrain run climbs the mound at slips of 0.6-0.7."""
    root = tmp_path_factory.mktemp("torque_replay")
    out = synthesize(root / "campaign", ["drivetrain_loss", "slip_sinkage"], [0.996, 0.955], 3199, noise=0.0,
                     fmu=harness_fmu)
    truth = json.loads((out / "truth.json").read_text())
    campaign = load_campaign(out)
    run = campaign.runs_of_kind("terrain")[0]
    grid, _ = grid_terrain(campaign, run, root)
    return campaign, run, str(grid), truth


def _torque_rms(fmu: JunoFMU, campaign, run, grid: str, truth: dict, drive: str, step: float) -> float:
    """RMS of the scaled torque residuals of the terrain run replayed at the truth."""
    prepared = prepare_run(campaign, run, terrain_file=grid, drive=drive)
    prepared.params["solver.step"] = step
    r = run_residuals(fmu, prepared, {k: truth["soil"][k] for k in SOIL_PARAMETERS}, truth["extension"])
    n = 0
    for column, (ts, *_rest) in prepared.targets.items():
        if column.startswith("torque"):
            break
        n += len(ts)
    count = sum(len(v[0]) for c, v in prepared.targets.items() if c.startswith("torque"))
    return float(np.sqrt(np.mean(r[n:n + count] ** 2)))


def test_the_throttle_makes_the_motor_give_the_measured_torque_plus_a_spin_damping(harness_fmu):
    """Held at a spin w, REPLAY_MOTOR at torque_replay_throttle(T, omega) delivers
    T + K (omega - w): the measured torque exactly where the spins agree."""
    torque, omega = 180.0, 1.2
    throttle = float(torque_replay_throttle(np.array([torque]), np.array([omega]))[0])
    m = REPLAY_MOTOR
    for w in (omega, omega - 0.1, omega + 0.05):
        delivered = (m["motor.efficiency"] * m["motor.gearRatio"] * m["motor.kt"]
                     * (throttle * m["motor.voltage"] - m["motor.kt"] * m["motor.gearRatio"] * w)
                     / m["motor.resistance"])
        assert delivered == pytest.approx(torque + REPLAY_SPIN_DAMPING * (omega - w), rel=1e-12)
    assert REPLAY_SPIN_DAMPING == pytest.approx(153.0, rel=0.01)
    # And the FMU's motor is that motor: at rest (spin 0) the first step's torque is T + K omega.
    sim = harness_fmu.simulate({"drive.mode": 2, **REPLAY_MOTOR, "drive.torqueMax": 2000.0, "solver.step": 1e-3,
                                "solver.tolerance": 0.0},
                               InputSignals.constant(throttleLeft=throttle, throttleRight=throttle, drawbarForce=0.0),
                               0.001, 0.001, outputs=["torqueLeftApplied", "omegaLeft"])
    w_end = sim["omegaLeft"][-1]
    assert sim["torqueLeftApplied"][-1] == pytest.approx(torque + REPLAY_SPIN_DAMPING * (omega - w_end), rel=1e-9)


def test_climbing_at_high_slip_the_torque_replay_reproduces_the_truth_where_imposed_spins_do_not(
        climbing_at_high_slip, harness_fmu):
    campaign, run, grid, truth = climbing_at_high_slip
    by_torque = _torque_rms(harness_fmu, campaign, run, grid, truth, "torque", 1e-3)
    by_spin = _torque_rms(harness_fmu, campaign, run, grid, truth, "spin", 1e-3)
    # Measured: 0.14 and 9.3 sigma (the measurements are noise-free; sigma is the sensor's).
    assert by_torque < 0.5, f"torque replay at the truth's own step: torque residual {by_torque:.2f} sigma rms"
    assert by_spin > 10 * by_torque, f"spin replay {by_spin:.2f} against torque replay {by_torque:.2f} sigma rms"
    # At the diagnosis' 5 ms the torque replay stays within the noise (measured 0.67 sigma).
    assert _torque_rms(harness_fmu, campaign, run, grid, truth, "torque", 5e-3) < 1.0


def test_a_torque_replay_names_what_it_cannot_use(climbing_at_high_slip):
    campaign, run, grid, _ = climbing_at_high_slip
    with pytest.raises(ValueError, match="t3d.*unknown replay drive 'current'"):
        prepare_run(campaign, run, terrain_file=grid, drive="current")
    data = read_run(campaign, run)
    no_torque = RunData(data.path, data.kind, {k: v for k, v in data.columns.items() if k != "torque_right"},
                        run_id=data.run_id)
    with pytest.raises(ValueError, match="t3d.*torque_right"):
        prepare_run(campaign, run, data=no_torque, terrain_file=grid, drive="torque")
    huge = RunData(data.path, data.kind, {**data.columns, "torque_left": data.columns["torque_left"] * 100.0},
                   run_id=data.run_id)
    with pytest.raises(ValueError, match=r"t3d.*t = .* s.*torque_left.*throttle"):
        prepare_run(campaign, run, data=huge, terrain_file=grid, drive="torque")
    # The spin replay needs no torque column at all.
    assert prepare_run(campaign, run, data=no_torque, terrain_file=grid).params["drive.mode"] == 1


def test_the_diagnosis_replays_the_terrain_run_by_the_drive_that_fits_its_training_blocks_better(
        climbing_at_high_slip, harness_fmu):
    """diagnose.choose_terrain_drive, blind: at the base model, each drive's replay of the terrain
    run is scored on the training blocks only, and the better one is used for every candidate.
    Here (climbing at high slip, the model at the truth) that is the torque replay."""
    from juno import diagnose
    campaign, _run, grid, truth = climbing_at_high_slip
    problem = diagnose.build_problem(campaign, str(harness_fmu.fmu_path), grid)
    params = {**truth["soil"], **truth["extension"]}
    at_truth = diagnose.replayed(problem, "base", params, diagnose.all_residuals(harness_fmu, problem, params))
    chosen, base, drive, losses = diagnose.choose_terrain_drive(campaign, problem, at_truth)
    assert set(losses) == set(REPLAY_DRIVES)
    assert drive == min(losses, key=losses.get) == "torque", losses
    assert losses["spin"] > 1.5 * losses["torque"], losses
    terrain = next(p for p in chosen.prepared if p.kind == "terrain")
    assert terrain.params["drive.mode"] == 2
    assert all(p.params["drive.mode"] == 1 for p in chosen.prepared if p.kind == "drawbar")
    # The base model's residuals are those of the chosen replay; the drawbar runs' are unchanged.
    np.testing.assert_array_equal(base.residuals, diagnose.all_residuals(harness_fmu, chosen, params))
    drawbar = np.isin(problem.meta["run"], [p.run_id for p in problem.prepared if p.kind == "drawbar"])
    np.testing.assert_array_equal(base.residuals[drawbar], at_truth.residuals[drawbar])


def test_once_the_candidates_are_fitted_the_terrain_run_is_judged_by_the_drive_the_best_model_fits_best(
        climbing_at_high_slip, harness_fmu):
    """diagnose.settle_terrain_drive, blind: over every fitted model, the drive under which some
    model fits the terrain run's training blocks best.  A wrong model (the paper's initial soil,
    neither the loss nor slip-sinkage) is replayed better with its spins imposed, as any model
    that the measured torque would carry off the measured path; the right one (the truth), far
    better driven by the torque.  Alone, the wrong model keeps the spin replay; beside the
    right one, every model is judged on the torque replay; a failed fit is passed on."""
    from juno import diagnose
    from juno.identify import PAPER_INITIAL
    campaign, _run, grid, truth = climbing_at_high_slip
    problem = diagnose.build_problem(campaign, str(harness_fmu.fmu_path), grid)
    problems = diagnose.drive_problems(campaign, problem)

    def replayed(name, params):
        return diagnose.replayed(problem, name, params, diagnose.all_residuals(harness_fmu, problem, params))
    wrong = replayed("base", dict(PAPER_INITIAL))
    right = replayed("truth", {**truth["soil"], **truth["extension"]})
    failed = diagnose.FitResult("broken", {}, np.inf, np.inf, np.zeros(0), 0, 0.0, error="did not converge")

    drive, best, _ = diagnose.settle_terrain_drive(problems, "spin", [wrong])
    assert drive == "spin" and best["torque"]["loss"] > best["spin"]["loss"], best

    drive, best, settled = diagnose.settle_terrain_drive(problems, "spin", [wrong, failed, right])
    assert drive == "torque", best
    assert best["torque"]["model"] == "truth" and best["spin"]["loss"] > 2 * best["torque"]["loss"], best
    assert settled[1] is failed
    drawbar = np.isin(problem.meta["run"], [p.run_id for p in problem.prepared if p.kind == "drawbar"])
    for before, after in ((wrong, settled[0]), (right, settled[2])):
        assert after.name == before.name and after.params == before.params
        np.testing.assert_array_equal(after.residuals,
                                      diagnose.all_residuals(harness_fmu, problems["torque"], before.params))
        np.testing.assert_array_equal(after.residuals[drawbar], before.residuals[drawbar])
