"""The terrain run replayed in segments (identify.prepare_run's ``segment``, `juno diagnose
--terrain-segments`): each piece after the first restarts the rover at the measured pose and
speed, and the SEGMENT_SETTLE seconds after each restart are not compared.

Why it exists: over a mound the spin-following replay can drift in heading, and a few degrees
put the rover on another part of the mound; restarted at the measured pose, a heading error
cannot grow (docs/diagnosis.md, ``--terrain-segments``).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from juno.campaign import RunData, load_campaign
from juno.identify import SEGMENT_SETTLE, prepare_run, restart_segments, run_residuals
from juno.simulator import SOIL_PARAMETERS
from juno.validate import grid_terrain

pytest_plugins = ["harness_fixtures"]

LENGTH = 6.0   # s, the length measured in the README


def _run_data(duration: float, with_yaw: bool = True) -> RunData:
    t = np.arange(0.0, duration + 1e-9, 0.05)
    columns = {"time": t, "pos_x": 0.3 * t, "pos_y": 0.1 * t}
    if with_yaw:
        columns["yaw"] = np.full_like(t, np.arctan2(0.1, 0.3))
    return RunData(Path("t3d.csv"), "terrain", columns, run_id="t3d")


def test_segments_cover_the_run_and_later_ones_restart_at_the_measured_pose_and_speed():
    data = _run_data(30.0)
    segments = restart_segments(data, 30.0, LENGTH)
    assert [s.start for s in segments] == [0.0, 6.0, 12.0, 18.0, 24.0]
    assert [s.stop for s in segments] == [6.0, 12.0, 18.0, 24.0, 30.0]
    assert segments[0].init == {}                       # the run's own start, at rest
    for s in segments[1:]:
        assert s.init["init.x"] == pytest.approx(0.3 * s.start)
        assert s.init["init.y"] == pytest.approx(0.1 * s.start)
        assert s.init["init.yaw"] == pytest.approx(np.arctan2(0.1, 0.3))
        assert s.init["init.vx"] == pytest.approx(np.hypot(0.3, 0.1))   # along the heading


def test_a_last_piece_too_short_to_compare_joins_the_one_before():
    segments = restart_segments(_run_data(26.0), 26.0, LENGTH)
    assert [(s.start, s.stop) for s in segments][-1] == (18.0, 26.0)


def test_segments_need_the_measured_heading_and_a_length_beyond_the_settling():
    with pytest.raises(ValueError, match="t3d.*yaw"):
        restart_segments(_run_data(30.0, with_yaw=False), 30.0, LENGTH)
    with pytest.raises(ValueError, match="longer than"):
        restart_segments(_run_data(30.0), 30.0, SEGMENT_SETTLE)


@pytest.fixture(scope="module")
def misregistered(tmp_path_factory, harness_fmu):
    """terrain_offset seed 4005 at the study's strength (0.819), its terrain grid and its truth."""
    from juno.synthesize import synthesize
    out = tmp_path_factory.mktemp("offset4005")
    path = synthesize(out / "campaign", effect="terrain_offset", strength=0.819, seed=4005, noise=1.0,
                      fmu=harness_fmu)
    truth = json.loads((Path(path) / "truth.json").read_text())
    campaign = load_campaign(path)
    run = campaign.runs_of_kind("terrain")[0]
    grid, _ = grid_terrain(campaign, run, str(out))
    return campaign, run, str(grid), truth


def _prepared(misregistered, segment):
    campaign, run, grid, _ = misregistered
    prepared = prepare_run(campaign, run, terrain_file=grid, segment=segment)
    prepared.params["solver.step"] = 5e-3          # the diagnosis' step
    return prepared


def test_only_the_settling_after_each_restart_is_left_out(misregistered):
    whole, pieces = _prepared(misregistered, None), _prepared(misregistered, LENGTH)
    restarts = [s.start for s in pieces.segments[1:]]
    for column, (ts, vs, *_rest) in whole.targets.items():
        settling = np.zeros(len(ts), bool)
        for start in restarts:
            settling |= (ts >= start) & (ts < start + SEGMENT_SETTLE)
        np.testing.assert_array_equal(pieces.targets[column][0], ts[~settling])
        np.testing.assert_array_equal(pieces.targets[column][1], vs[~settling])


def _residuals(harness_fmu, prepared, params):
    soil = {k: params[k] for k in SOIL_PARAMETERS}
    return run_residuals(harness_fmu, prepared, soil, {k: v for k, v in params.items() if k not in SOIL_PARAMETERS})


def test_the_first_segment_replays_exactly_as_the_whole_run(misregistered, harness_fmu):
    truth = misregistered[3]
    params = {**truth["soil"], **truth["extension"]}
    whole, pieces = _prepared(misregistered, None), _prepared(misregistered, LENGTH)
    r_whole, r_pieces = _residuals(harness_fmu, whole, params), _residuals(harness_fmu, pieces, params)
    t_whole = np.concatenate([v[0] for v in whole.targets.values()])
    t_pieces = np.concatenate([v[0] for v in pieces.targets.values()])
    first = LENGTH
    np.testing.assert_array_equal(r_pieces[t_pieces < first], r_whole[t_whole < first])


def test_in_segments_the_true_registration_beats_the_scan_as_it_is(misregistered, harness_fmu):
    """Measured at the true soil, on the synthetic campaign this file builds (terrain_offset,
    seed 4005): in 6 s segments the truth fits to the noise (mean square 0.92) and the scan as it
    is does not (2.97); the whole 30 s replay tells them apart too (1.07 against 2.03), its
    stiff spin tracker never swinging between its torque limits at the start (where it did, the
    whole replay at the truth lost the rover)."""
    truth = misregistered[3]
    true_registration = {**truth["soil"], **truth["extension"]}
    as_scanned = dict(truth["soil"])
    mse = {}
    for label, segment in (("whole", None), ("segments", LENGTH)):
        prepared = _prepared(misregistered, segment)
        mse[label] = [float(np.mean(_residuals(harness_fmu, prepared, p) ** 2)) for p in (true_registration, as_scanned)]
    print(f"\nterrain mean squared residual, true registration / scan as it is: whole {mse['whole']}, "
          f"segments {mse['segments']}")
    assert mse["whole"][0] < mse["whole"][1]
    assert mse["segments"][0] < 1.5                    # noise is 1
    assert mse["segments"][1] > 2.0 * mse["segments"][0]


def test_the_cli_refuses_a_segment_shorter_than_the_settling(misregistered, tmp_path, capsys):
    from harness_fixtures import run_juno_here
    campaign = misregistered[0]
    out = tmp_path / "diagnosis.json"
    proc = run_juno_here(capsys, "diagnose", str(campaign.root), "--terrain-segments", "1", "--json", str(out),
                         "--quiet")
    assert proc.returncode == 2, proc.stderr
    assert "longer than" in proc.stderr and not out.exists()


def test_a_segment_starting_where_the_logged_heading_wraps_restarts_at_the_measured_heading():
    """An IMU logs the heading in (-pi, pi]: a rover turning through pi jumps from about pi to
    about -pi between two samples. A segment starting between them restarts at the heading the
    rover had (near pi, either sign), not at the mean of the two numbers (near 0, backwards)."""
    t = np.r_[0.0, np.arange(0.03, 30.0, 0.05)]       # samples at 5.98 and 6.03 s straddle its start
    heading = np.pi + 0.01 * (t - 6.0)                 # passes pi at 6 s, the second segment's start
    columns = {"time": t, "pos_x": np.cumsum(0.015 * np.cos(heading)), "pos_y": np.cumsum(0.015 * np.sin(heading)),
               "yaw": np.angle(np.exp(1j * heading))}
    data = RunData(Path("t3d.csv"), "terrain", columns, run_id="t3d")
    segment = restart_segments(data, 30.0, LENGTH)[1]
    assert segment.start == 6.0
    off = np.angle(np.exp(1j * (segment.init["init.yaw"] - np.pi)))
    assert abs(off) < 0.01, segment.init["init.yaw"]
