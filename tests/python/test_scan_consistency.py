"""Each terrain run's measured pose against its own scan (juno/scan_consistency.py): a scan that
is the ground agrees, a scan tilted about a horizontal axis disagrees, in the signals the tilt
moves; of several terrain runs, the ones whose scan disagrees are named.

The unit tests need no FMU: the "measured" pose is the rover posed kinematically on the true
ground, so they check the comparison itself, deterministically, in about a second.  The tests on
synthesized campaigns share one pair of twins (tilted_twins), synthesized once."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from juno.pointcloud import Grid
from juno.registration import Traverse, pose_on_ground
from juno.diagnose.problem import BLOCK
from juno.scan_consistency import FLOORS, ScanConsistency, ScanSignal, ScanTests, scan_consistency

#: The rover's geometry (m), fixed here so that the test needs no FMU.
GEOMETRY = {"wheelbase": 0.9, "track": 1.35, "pivot_height": 0.15, "wheel_radius": 0.28}
H0 = 0.43     # chassis height above flat ground, m


def _ground(tilt_deg: float = 0.0, axis_deg: float = 0.0, x0: float = 3.0) -> Grid:
    """A 0.3 m ridge across x = 4 m; with ``tilt_deg``, as a scan tilted by that angle about a
    horizontal axis at ``axis_deg`` from x through (x0, 0) reports it."""
    xs, ys = np.arange(-1.0, 10.0, 0.02), np.arange(-2.0, 2.0, 0.02)
    X, Y = np.meshgrid(xs, ys)
    z = 0.3 * np.exp(-(X - 4.0) ** 2 / (2 * 0.6 ** 2))
    a = np.radians(axis_deg)
    z = z + np.tan(np.radians(tilt_deg)) * (-(X - x0) * np.sin(a) + Y * np.cos(a))
    return Grid(x0=float(xs[0]), y0=float(ys[0]), cell=0.02, z=z)


def _measured_traverse() -> tuple[Traverse, np.ndarray]:
    """The rover driven along y = 0 from x = 0.5 to 7.5 m in 28 s, its pose as it rests on the
    true ground; and each sample's 4 s block."""
    t = np.arange(0.0, 28.0, 0.2)
    x = 0.5 + 0.25 * t
    zero = np.zeros_like(t)
    path = Traverse(x, zero, zero, zero, None, GEOMETRY["wheelbase"], GEOMETRY["track"], roll=None,
                    pivot_height=GEOMETRY["pivot_height"], wheel_radius=GEOMETRY["wheel_radius"], t=t)
    pose = pose_on_ground(_ground(), path, np.zeros(4), H0)
    measured = Traverse(x, zero, pose[:, 0], zero, pose[:, 2], GEOMETRY["wheelbase"], GEOMETRY["track"],
                        roll=pose[:, 1], pivot_height=GEOMETRY["pivot_height"],
                        wheel_radius=GEOMETRY["wheel_radius"], t=t)
    return measured, np.floor(t / BLOCK).astype(int)


def _test(grid: Grid) -> ScanConsistency:
    traverse, block = _measured_traverse()
    return scan_consistency(grid, traverse, H0, block % 2 == 0, block, "t3d")


def test_a_scan_that_is_the_ground_agrees_with_the_pose():
    result = _test(_ground())
    assert not result.significant, result.summary()
    assert {s.signal for s in result.signals} == {"height", "pitch", "roll"}
    assert all(s.rms < 0.05 * s.floor for s in result.signals), result.to_json()
    assert "agrees" in result.summary()


def test_a_scan_tilted_across_the_path_disagrees_in_height():
    """Tilted by 0.85 degrees about an axis at 60 degrees to the path through x = 3 m: the scan is
    up to 5 cm off along the 7 m traverse, many times the floor."""
    result = _test(_ground(0.85, 60.0))
    assert result.significant
    height = next(s for s in result.signals if s.signal == "height")
    assert height.disagrees and height.rms > 3 * FLOORS["height"], result.to_json()
    assert result.disagreeing()[0].signal == "height"
    assert "disagrees" in result.summary() and "height" in result.summary()


def test_a_scan_tilted_about_the_path_shows_in_roll_but_stays_within_the_roll_floor():
    """The known limit: tilted by 1 degree about the path itself, the height under the wheels is
    unchanged on average, and the scan leans by 17 mrad, of which the fitted roll gain (at least
    0.9) takes up a tenth.  The 16 mrad left lies within the roll floor (17 mrad, twice what a
    right scan leaves on the default design's mound flank), so it is not reported."""
    result = _test(_ground(1.0, 0.0))
    roll = next(s for s in result.signals if s.signal == "roll")
    assert 0.85 * np.radians(1.0) <= abs(roll.offset) <= np.radians(1.0), result.to_json()
    assert not roll.disagrees and not result.significant, result.summary()


def test_a_signal_disagrees_only_beyond_its_floor():
    at, above = ScanSignal("height", "m", 3, 0.005, 0.0, 0.005), ScanSignal("height", "m", 3, 0.0051, 0.0, 0.005)
    assert not at.disagrees and above.disagrees
    assert ScanConsistency("t3d", [at]).significant is False
    assert ScanConsistency("t3d", [at, above]).disagreeing() == [above]


def test_the_sensor_noise_left_in_the_block_means_is_taken_off_before_the_floor():
    """A block mean of n samples carries sigma / sqrt(n) of sensor noise: what is compared with
    the floor is the RMS beyond it; a signal whose block means' noise reaches its floor cannot
    show a disagreement of the floor's size and is not judged."""
    noisy = ScanSignal("height", "m", 3, 0.0075, 0.0, 0.006, noise=0.005)
    assert noisy.excess == pytest.approx(np.sqrt(0.0075 ** 2 - 0.005 ** 2))
    assert noisy.resolvable and not noisy.disagrees
    drowned = ScanSignal("height", "m", 3, 0.03, 0.0, 0.006, noise=0.014)
    assert not drowned.resolvable and not drowned.disagrees
    assert "14 mm of sensor noise" in drowned.unresolved_sentence()


def test_positions_from_a_noisy_receiver_leave_the_height_unjudged_not_disagreeing():
    """The scan that is the ground, the heights measured by a receiver with 4 cm of noise at
    5 Hz (about 13 mm in a 4 s block's mean): the height is not judged, and the pose does not
    disagree; with a millimetre of noise it is judged and agrees."""
    traverse, block = _measured_traverse()
    rng = np.random.default_rng(7)
    for sigma, judged in ((0.04, False), (0.001, True)):
        measured = Traverse(traverse.x, traverse.y, traverse.z + rng.normal(0.0, sigma, len(traverse.z)),
                            traverse.yaw, traverse.pitch, traverse.wheelbase, traverse.track, roll=traverse.roll,
                            pivot_height=traverse.pivot_height, wheel_radius=traverse.wheel_radius, t=traverse.t)
        result = scan_consistency(_ground(), measured, H0, block % 2 == 0, block, "t3d", {"height": sigma})
        height = next(s for s in result.signals if s.signal == "height")
        assert height.resolvable == judged and not result.significant, result.to_json()
        assert ("not judged" in result.summary()) != judged


def test_the_gains_fit_poses_the_rover_once_and_gives_what_a_pose_per_evaluation_gives(monkeypatch):
    """The attitude gains only scale the posed attitude, so the fit of the gains poses the rover on
    the scan once for its training samples (and once more for every sample), and its gains and
    block means are those of a fit that poses it anew at every evaluation, bit for bit."""
    from scipy.optimize import least_squares

    import juno.registration as registration
    grid = _ground(0.85, 60.0)
    traverse, block = _measured_traverse()
    train = block % 2 == 0
    fitted = traverse.subset(train)
    lower, upper = [g[0] for g in registration.GAIN_LIMITS], [g[1] for g in registration.GAIN_LIMITS]
    anew = least_squares(lambda g: registration.residuals(np.zeros(4), grid, fitted, H0, (g[0], g[1])),
                         np.clip(np.ones(2), lower, upper), bounds=(lower, upper))
    assert anew.nfev > 2        # the fit evaluates several gains: there is something to reuse
    solves = []
    solve = registration._Posing.solve
    monkeypatch.setattr(registration._Posing, "solve", lambda self, offsets: solves.append(len(self.tr.x))
                        or solve(self, offsets))
    result = scan_consistency(grid, traverse, H0, train, block, "t3d")
    assert solves == [len(fitted.x), len(traverse.x)]
    assert result.gains == (float(anew.x[0]), float(anew.x[1]))
    r = registration.residuals(np.zeros(4), grid, traverse, H0, result.gains)
    n = len(traverse.x)
    height = next(s for s in result.signals if s.signal == "height")
    means = np.array([np.mean(r[:n][~train & (block == b)] * registration.SIGMA_Z) for b in np.unique(block[~train])])
    assert height.rms == float(np.sqrt(np.mean(means ** 2)))


def test_a_pose_that_cannot_be_compared_is_an_error_not_an_agreement():
    traverse, block = _measured_traverse()
    traverse.z[7] = np.nan
    with pytest.raises(ValueError, match=r"terrain run t3d: the measured height is not finite at 1 of \d+ samples \(the first at t = 1.400 s\)"):
        scan_consistency(_ground(), traverse, H0, block % 2 == 0, block, "t3d")


def _seed_tilted_across_the_path(key: str, least_deg: float = 30.0) -> int:
    """The first seed of a generator keyed by ``key`` whose terrain_tilt axis lies at least
    ``least_deg`` off the terrain run's direction (x): drawn, not picked by hand (the truth is
    drawn before anything is simulated)."""
    import random

    from juno.synthesize import draw_truth
    rng = random.Random(f"juno scan test: {key}")
    while True:
        seed = rng.randrange(100_000)
        axis = draw_truth("terrain_tilt", 0.9, seed).distortion["scan.tiltAxis"]
        if np.radians(least_deg) <= axis <= np.pi - np.radians(least_deg):
            return seed


@pytest.fixture(scope="module")
def tilted_twins(tmp_path_factory) -> dict[str, Path]:
    """Two alternative-design campaigns of one seed (the same soil, path and sensor noise), one
    with the scan tilted by 0.9 degree about an axis crossing the terrain run's path: effect ->
    campaign folder."""
    from juno.synthesize import synthesize
    seed = _seed_tilted_across_the_path("alternative design")
    root = tmp_path_factory.mktemp("tilted-twins")
    return {effect: synthesize(root / effect, effect=effect, strength=0.9, seed=seed, design="alt")
            for effect in ("none", "terrain_tilt")}


def test_a_synthesized_campaign_whose_scan_is_tilted_across_the_path_disagrees_and_its_untilted_twin_agrees(
        tilted_twins, tmp_path):
    """The scan test of the diagnosis (the same blocks, the gridded scan) calls the tilted twin in
    height and passes the other."""
    from juno.campaign import load_campaign
    from juno.scan_consistency import terrain_run_scan_consistency
    from juno.validate import grid_terrain
    results = {}
    for effect, root in tilted_twins.items():
        campaign = load_campaign(root)
        run = campaign.runs_of_kind("terrain")[0]
        _path, grid = grid_terrain(campaign, run, tmp_path / f"{effect}-grid")
        results[effect] = terrain_run_scan_consistency(campaign, run, grid, BLOCK)
    assert not results["none"].significant, results["none"].summary()
    tilted = results["terrain_tilt"]
    assert tilted.significant and tilted.disagreeing()[0].signal == "height", tilted.to_json()


def _with_a_second_terrain_run(twins: dict[str, Path], out: Path) -> Path:
    """The untilted campaign with a second terrain run: the tilted twin's terrain run on its own
    (tilted) scan, as ``t3d_tilted``."""
    shutil.copytree(twins["none"], out)
    manifest = json.loads((out / "campaign.json").read_text())
    tilted = json.loads((twins["terrain_tilt"] / "campaign.json").read_text())
    run = next(r for r in tilted["runs"] if r["kind"] == "terrain")
    second = dict(run, id="t3d_tilted", file="runs/t3d_tilted.csv", terrain="terrain/scan_tilted.xyz")
    shutil.copyfile(twins["terrain_tilt"] / run["file"], out / second["file"])
    shutil.copyfile(twins["terrain_tilt"] / run["terrain"], out / second["terrain"])
    manifest["runs"].append(second)
    (out / "campaign.json").write_text(json.dumps(manifest, indent=2))
    return out


def test_of_two_terrain_runs_only_the_one_whose_scan_is_tilted_is_named(tilted_twins, tmp_path):
    """A campaign with two terrain runs, each on its own scan, only the second's tilted: the
    diagnosis's scan test (search.scan_against_pose) tests both, the first agrees, the second
    disagrees in height, and with nothing named and the drawbar runs clean the verdict is
    ``unexplained`` naming the second run alone, in its sentence, its JSON and its table."""
    from juno.campaign import load_campaign
    from juno.diagnose.render import _scan_table
    from juno.diagnose.search import scan_against_pose
    from juno.diagnose.verdict import verdict
    from juno.identify import gridded_scans
    from juno.residual_structure import ResidualStructure
    campaign = load_campaign(_with_a_second_terrain_run(tilted_twins, tmp_path / "campaign"))
    assert [r.id for r in campaign.runs_of_kind("terrain")] == ["t3d", "t3d_tilted"]
    grids = {run_id: grid for run_id, (_path, grid) in gridded_scans(campaign, tmp_path / "grids", "validate").items()}
    said: list[str] = []
    scan = scan_against_pose(campaign, grids, said.append)
    assert [r.run for r in scan.runs] == ["t3d", "t3d_tilted"] and scan.untested == {}
    assert [r.run for r in scan.disagreeing()] == ["t3d_tilted"], scan.to_json()
    assert scan.disagreeing()[0].disagreeing()[0].signal == "height"
    assert said == [scan.summary()] and "terrain run t3d_tilted disagrees" in said[0]
    assert "terrain run t3d " not in said[0], said[0]

    clean_drawbar_runs = ResidualStructure([], 0.01, 20, ["dbp1", "dbp2", "dbp3"])
    v = verdict([], clean_drawbar_runs, None, scan=scan)
    assert v.cause == "unexplained" and v.unexplained.scan is scan
    as_json = v.unexplained.to_json()["scan"]
    assert as_json["disagreeing"] == ["t3d_tilted"]
    assert [(r["run"], r["significant"]) for r in as_json["runs"]] == [("t3d", False), ("t3d_tilted", True)]
    rows = [line for line in _scan_table(v.unexplained) if line.startswith("| t3d")]
    assert rows and all(row.startswith("| t3d_tilted | ") for row in rows), rows
    assert "The measured pose agrees with the scan on terrain run t3d." in _scan_table(v.unexplained)


def test_the_scan_tests_of_several_runs_agree_only_when_every_run_agrees():
    """The campaign's scan test disagrees when any run's does, names only those runs, and says
    which runs it could not test."""
    at = ScanSignal("height", "m", 3, 0.5 * FLOORS["height"], 0.0, FLOORS["height"])
    above = ScanSignal("height", "m", 3, 2.0 * FLOORS["height"], 0.0, FLOORS["height"])
    agreeing = ScanTests([ScanConsistency("a", [at]), ScanConsistency("b", [at])], {"c": "too short"})
    assert not agreeing.significant and agreeing.disagreeing() == []
    assert agreeing.summary() == ("the measured pose on terrain runs a, b agrees with their scans; "
                                  "terrain run c not tested (too short)")
    one_off = ScanTests([ScanConsistency("a", [at]), ScanConsistency("b", [above])])
    assert one_off.significant and [r.run for r in one_off.disagreeing()] == ["b"]
    assert one_off.to_json()["disagreeing"] == ["b"] and "terrain run b disagrees" in one_off.summary()
    assert "terrain run a" not in one_off.summary()
