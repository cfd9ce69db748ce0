"""One registration per scan: a campaign whose terrain runs were scanned and registered
separately is registered scan by scan (juno.registration.scans_of, starts.registration_evidence),
each scan's offsets applied to its own runs only (candidates.for_runs, the replay's
run_parameters), and each scan moved charged its own six parameters.

The campaign here needs no FMU: its "measured" pose is the rover posed kinematically on the true
ground (juno.registration.pose_on_ground) with the synthetic campaigns' sensor noise, so the
tests check the registration itself, deterministically, in seconds."""

from __future__ import annotations

import numpy as np
import pytest

from juno.campaign import write_campaign
from juno.diagnose import CANDIDATES, FitResult, Problem, judge
from juno.diagnose import problem as problem_module
from juno.diagnose.candidates import for_runs, run_parameters, unqualified
from juno.diagnose.problem import BLOCK, residuals_or_failure
from juno.diagnose.starts import registration_candidate, registration_evidence, registration_start
from juno.identify import PAPER_INITIAL, PreparedRun
from juno.pointcloud import GRID_MARGIN, grid_from_points
from juno.registration import (HELD_OUT_RATIO, OFFSET_NAMES, HeldOutEvidence, ScanEvidence, ScanRegistrations, Traverse, joined,
                               pose_on_ground, scans_of)
from juno.rover_model import rover
from juno.synthesize import mound_surface
from juno.validate import GRID_CELL

OFFSETS = OFFSET_NAMES
#: The second scan's registration error: 15 cm and -12 cm, 2 cm high, 0.04 rad (2.3 deg).
TRUTH = np.array([0.15, -0.12, 0.02, 0.04])
H0 = 0.41          # chassis height above flat ground, m
SAMPLE = 0.2       # s between the total station's samples


def _scan_points() -> np.ndarray:
    """The scanned mound as the scan reports it: points every 5 cm over x -1..9 m, y -2.3..2.3 m."""
    xs, ys = np.arange(-1.0, 9.0 + 1e-9, 0.05), np.arange(-2.3, 2.3 + 1e-9, 0.05)
    X, Y = np.meshgrid(xs, ys)
    return np.column_stack([X.ravel(), Y.ravel(), mound_surface(X, Y, 3).ravel()])


def _measured(grid, offset: np.ndarray, seed: int) -> dict[str, np.ndarray]:
    """A terrain run 0.55 m beside the mound's crest, 28 s, its pose the rover's resting on
    ``grid`` registered by ``offset`` (where the scan really lies), tilting 1.15 times in pitch and
    1.05 in roll as the FMU's rover does, with 3 mm and 3 mrad of noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 28.0, SAMPLE)
    x = np.linspace(1.0, 6.5, len(t))
    y = -0.2 + 0.05 * np.sin(x)
    yaw = np.arctan(0.05 * np.cos(x))
    shape = rover()
    path = Traverse(x, y, np.zeros_like(t), yaw, None, shape.wheelbase, shape.track)
    z, roll, pitch, _beta = pose_on_ground(grid, path, offset, H0).T
    zero = np.zeros_like(t)
    noise = lambda: 0.003 * rng.standard_normal(len(t))   # noqa: E731
    return {"time": t, "torque_left": zero, "torque_right": zero, "omega_left": zero, "omega_right": zero,
            "pos_x": x, "pos_y": y, "pos_z": z + noise(), "yaw": yaw, "pitch": 1.15 * pitch + noise(),
            "roll": 1.05 * roll + noise()}


def _campaign(root, second_offset: np.ndarray, shared: bool = False):
    """A campaign with a drawbar run on flat ground and two terrain runs over the same mound:
    ``t3d_a`` on scan a.xyz, in its place; ``t3d_b`` on its own scan b.xyz (or on a.xyz too, if
    ``shared``), which really lies at ``second_offset`` from where the scan puts it."""
    points = _scan_points()
    grid = grid_from_points(points, cell=GRID_CELL, margin=GRID_MARGIN)
    t = np.arange(0.0, 12.0, SAMPLE)
    zero = np.zeros_like(t)
    drawbar = {"time": t, "torque_left": zero, "torque_right": zero, "omega_left": zero, "omega_right": zero,
               "pos_x": 0.1 * t, "pos_y": zero, "pos_z": H0 + zero, "drawbar_force": zero}
    manifest = {"name": "two scans", "runs": [
        {"id": "dbp", "kind": "drawbar"},
        {"id": "t3d_a", "kind": "terrain", "terrain": "a.xyz"},
        {"id": "t3d_b", "kind": "terrain", "terrain": "a.xyz" if shared else "b.xyz"}]}
    runs = {"dbp": drawbar, "t3d_a": _measured(grid, np.zeros(4), seed=11),
            "t3d_b": _measured(grid, second_offset, seed=7)}
    return write_campaign(root, manifest, runs, {"a.xyz": points, "b.xyz": points}), grid


def _where(offset: np.ndarray, qx: float, qy: float) -> np.ndarray:
    """World position (m) of scan point (qx, qy) under registration (ox, oy, oz, yaw)."""
    c, s = np.cos(offset[3]), np.sin(offset[3])
    return np.array([offset[0] + c * qx - s * qy, offset[1] + s * qx + c * qy])


@pytest.fixture(scope="module")
def second_scan_misregistered(tmp_path_factory):
    """(campaign, every scan's registration) with only the second scan misregistered (TRUTH)."""
    campaign, grid = _campaign(tmp_path_factory.mktemp("two_scans"), TRUTH)
    return campaign, registration_evidence(campaign, {"t3d_a": grid, "t3d_b": grid})


def test_each_terrain_run_on_its_own_scan_gets_its_own_registration(second_scan_misregistered):
    """Only the second scan is off: the second is found misregistered and its registration puts
    the mound (centre and 1 m either side along the track) within 5 cm and the height within 5 mm
    of where it is; the first stays exactly as it is."""
    campaign, found = second_scan_misregistered
    first, second = found.scans
    assert (first.scan, first.runs, second.scan, second.runs) == ("terrain/a.xyz", ("t3d_a",), "terrain/b.xyz", ("t3d_b",))
    assert second.significant and second.evidence.ratio > 3 * HELD_OUT_RATIO, second.evidence
    fitted = np.array([second.offsets[k] for k in OFFSETS])
    for qx in (3.0, 4.0, 5.0):
        miss = np.hypot(*(_where(fitted, qx, 0.35) - _where(TRUTH, qx, 0.35)))
        assert miss < 0.05, f"mound point {qx} m placed {miss:.3f} m off: fitted {fitted}"
    assert fitted[2] == pytest.approx(TRUTH[2], abs=0.005)
    assert not first.significant and first.evidence.ratio < HELD_OUT_RATIO / 2, first.evidence
    assert first.offsets == dict.fromkeys(OFFSETS, 0.0)
    assert found.significant and [s.scan for s in found.misregistered()] == ["terrain/b.xyz"]


def test_the_offsets_of_one_scan_never_move_another(second_scan_misregistered, tmp_path):
    """The first scan's registration is fitted on its own runs alone: with the second scan in its
    place too, the first scan's evidence is the same to the last digit.  And in the replay, the
    registration candidate moves the second scan's runs only: the first run gets no offset."""
    campaign, found = second_scan_misregistered
    both_right, grid = _campaign(tmp_path / "both_right", np.zeros(4))
    alone = registration_evidence(both_right, {"t3d_a": grid, "t3d_b": grid})
    assert alone.scans[0].evidence == found.scans[0].evidence
    assert not alone.significant

    candidate = registration_candidate(found)
    start = registration_start(found)
    assert [e.name for e in candidate.params] == [for_runs(k, ["t3d_b"]) for k in OFFSETS]
    assert set(start) == {e.name for e in candidate.params}
    params = {**PAPER_INITIAL, **start}
    assert not any(k.startswith("terrain.") for k in run_parameters(params, "t3d_a"))
    on_b = run_parameters(params, "t3d_b")
    assert [on_b[k] for k in OFFSETS] == [found.scans[1].offsets[k] for k in OFFSETS]


def test_runs_that_share_a_scan_share_one_registration_fitted_on_both(tmp_path):
    """Two terrain runs on one scan file, the scan in its place: one scan, both runs' samples in
    its registration, the catalogue's six parameters applied to every terrain run alike."""
    campaign, grid = _campaign(tmp_path / "shared", np.zeros(4), shared=True)
    assert [(scan, [r.id for r in runs]) for scan, runs in scans_of(campaign)] == [("terrain/a.xyz", ["t3d_a", "t3d_b"])]
    found = registration_evidence(campaign, grid)
    (only,) = found.scans
    assert only.runs == ("t3d_a", "t3d_b") and not found.significant
    assert only.evidence.held_out_samples == 2 * 60        # 3 held-out blocks of 20 samples per run
    assert registration_candidate(found) is CANDIDATES["terrain_offset"]
    assert registration_start(found) == dict.fromkeys(OFFSETS, 0.0)


# ------------------------------------------------------ the campaign's figures, without a fit

def _evidence(as_scanned: float, registered: float, samples: int) -> HeldOutEvidence:
    offsets = dict(zip(OFFSETS, (0.2, -0.1, 0.02, 0.03)))
    significant = as_scanned / registered >= HELD_OUT_RATIO
    return HeldOutEvidence(offsets, as_scanned, registered, offsets if significant else None, samples)


def test_one_scan_reports_exactly_its_own_evidence():
    one = _evidence(3.3, 1.1, 70)
    found = ScanRegistrations((ScanEvidence("a.xyz", ("t3d",), one),))
    assert (found.held_out_ms_as_scanned, found.held_out_ms_registered) == (3.3, 1.1)
    assert found.ratio == one.ratio and found.gain == one.gain and found.significant == one.significant


def test_several_scans_pool_their_held_out_samples_but_each_is_judged_on_its_own():
    """Pooled, a scan 10 times better registered and one not at all give a ratio under
    HELD_OUT_RATIO; the campaign still has a misregistered scan: the one whose own evidence passes."""
    bad, good = _evidence(20.0, 2.0, 50), _evidence(1.0, 1.0, 450)
    found = ScanRegistrations((ScanEvidence("a.xyz", ("t1",), good), ScanEvidence("b.xyz", ("t2",), bad),
                               ScanEvidence("c.xyz", ("t3",), None)))
    assert found.held_out_ms_as_scanned == pytest.approx((50 * 20.0 + 450 * 1.0) / 500)
    assert found.held_out_ms_registered == pytest.approx((50 * 2.0 + 450 * 1.0) / 500)
    assert found.ratio < HELD_OUT_RATIO and found.significant
    assert [s.scan for s in found.misregistered()] == ["b.xyz"]
    assert registration_start(found) == {for_runs(k, ["t2"]): v for k, v in bad.offsets_all.items()}


def test_a_joined_traverse_keeps_every_run_in_order():
    shape = rover()
    one = Traverse(np.arange(3.0), np.zeros(3), np.ones(3), np.zeros(3), np.zeros(3), shape.wheelbase, shape.track,
                   roll=np.zeros(3), t=np.arange(3.0))
    two = Traverse(np.arange(2.0) + 10, np.ones(2), np.ones(2), np.ones(2), None, shape.wheelbase, shape.track,
                   roll=np.ones(2), t=np.arange(2.0))
    both = joined([one, two])
    assert list(both.x) == [0.0, 1.0, 2.0, 10.0, 11.0] and list(both.roll) == [0, 0, 0, 1, 1]
    assert both.pitch is None          # measured on one run only: left out, not half a signal


# ------------------------------------------------------ the replay and the judge

def _prepared(run_id: str, terrain: bool) -> PreparedRun:
    params = {"terrain.file": f"{run_id}.asc"} if terrain else {}
    return PreparedRun(run_id, "terrain" if terrain else "drawbar", 1.0, None, params,
                       {"pos_z": (np.zeros(2), np.zeros(2), "z", 0.003, 0.0)})


def test_the_replay_gives_each_run_only_its_own_scans_registration(monkeypatch):
    """Each run is replayed with the offsets applied to its runs, the catalogue's unqualified
    offsets on every terrain run, and none on flat ground."""
    seen = {}

    def replay(_fmu, p, _soil, extra):
        seen[p.run_id] = extra
        return np.zeros(2), None
    monkeypatch.setattr(problem_module, "_replay", replay)
    problem = Problem("campaign", None, "unused.fmu",
                      [_prepared("dbp", False), _prepared("t3d_a", True), _prepared("t3d_b", True)])
    params = {**PAPER_INITIAL, "terrain.offsetZ": 0.01, for_runs("terrain.offsetX", ["t3d_b"]): 0.2,
              for_runs("terrain.offsetX", ["t3d_a", "t3d_c"]): -0.1}
    r, failure = residuals_or_failure(None, problem, params)
    assert failure is None and len(r) == 6
    assert seen == {"dbp": {}, "t3d_a": {"terrain.offsetZ": 0.01, "terrain.offsetX": -0.1},
                    "t3d_b": {"terrain.offsetZ": 0.01, "terrain.offsetX": 0.2}}


def test_each_scan_moved_is_charged_its_own_six_parameters():
    """Registered on two scans, the registration adds twelve parameters: on the replay (the second
    round) it must gain 3 % for each, twice what one scan's registration needs.  Switched off, no
    scan is moved."""
    catalogue = CANDIDATES["terrain_offset"]
    two = {**PAPER_INITIAL, **{for_runs(k, [run]): 0.05 for run in ("t1", "t2") for k in OFFSETS}}
    assert catalogue.parameters_in(two) == 12 and catalogue.acts(two)
    off = catalogue.switched_off(two)
    assert not catalogue.acts(off) and all(off[k] == 0.0 for k in two if unqualified(k).startswith("terrain."))
    assert catalogue.parameters_in({**PAPER_INITIAL, **dict.fromkeys(OFFSETS, 0.05)}) == 6

    t = np.arange(0.0, 120.0, 0.1)        # 15 held-out blocks a run
    runs = np.array(["dbp"] * len(t) + ["t1"] * len(t))
    times = np.concatenate([t, t])
    block = np.floor(times / BLOCK).astype(int)
    problem = Problem("campaign", None, "unused.fmu", [], (block % 2) == 0,
                      {"run": runs, "signal": np.array(["pos_z"] * len(runs)), "time": times, "block": block})
    run_kind = np.where(runs == "dbp", "drawbar", "terrain")
    reference = np.where(run_kind == "drawbar", 1.5, 6.0) * np.random.default_rng(3).standard_normal(len(runs))
    moved = np.where(run_kind == "drawbar", reference, 0.85 * reference)       # 28 % on the terrain runs
    base = FitResult("base", dict(PAPER_INITIAL), 1.0, 1.0, reference, 1, 0.0)
    one_scan = judge(problem, run_kind, base, FitResult("terrain_offset", {**PAPER_INITIAL, **dict.fromkeys(
        OFFSETS, 0.05)}, 1.0, 1.0, moved, 1, 0.0))
    two_scans = judge(problem, run_kind, base, FitResult("terrain_offset", two, 1.0, 1.0, moved, 1, 0.0))
    assert one_scan.gain == two_scans.gain and 0.12 < one_scan.gain < 0.24
    assert (one_scan.n_params, two_scans.n_params) == (6, 12)
    assert one_scan.significant and not two_scans.significant
    assert set(two_scans.extension) == {for_runs(k, [run]) for run in ("t1", "t2") for k in OFFSETS}


# ------------------------------------------------------ what the result says

def test_the_result_names_the_misregistered_scan_and_lists_every_scans_registration():
    """The registration's evidence as reported (JSON, the report's table, the explanation): each
    scan with its runs, offsets and ratio; only the misregistered one named as the cause's."""
    from types import SimpleNamespace

    from juno.diagnose.assemble import _cause_named
    from juno.diagnose.judging import kinematic_evidence
    from juno.diagnose.render import _candidates_table
    from juno.diagnose.results import JudgedCandidate
    bad = _evidence(20.0, 2.0, 60)
    found = ScanRegistrations((ScanEvidence("terrain/a.xyz", ("t3d_a",), _evidence(1.0, 1.0, 60)),
                               ScanEvidence("terrain/b.xyz", ("t3d_b", "t3d_c"), bad)))
    pose = kinematic_evidence(found)
    as_json = pose.to_json()["scans"]
    assert [(s["scan"], s["runs"], s["misregistered"]) for s in as_json] == [
        ("terrain/a.xyz", ["t3d_a"], False), ("terrain/b.xyz", ["t3d_b", "t3d_c"], True)]
    assert as_json[0]["offsets"] == dict.fromkeys(OFFSETS, 0.0) and as_json[1]["offsets"] == bad.offsets_all
    assert as_json[1]["ratio"] == pytest.approx(10.0)

    judged = JudgedCandidate("terrain_offset", CANDIDATES["terrain_offset"].cause, 0.5, 4.0, True, True, "ok", 0,
                             kinematic=pose)
    said = _cause_named("terrain_offset", SimpleNamespace(candidates=[judged]))
    assert said.endswith("(scan terrain/b.xyz, runs t3d_b, t3d_c)") and "a.xyz" not in said
    table = _candidates_table(SimpleNamespace(candidates=[judged], causes=["terrain_offset"], second_round=[],
                                              criteria=SimpleNamespace(registration_held_out_ratio=HELD_OUT_RATIO)))
    rows = [line for line in table if line.startswith("| terrain/")]
    assert rows[0].startswith("| terrain/a.xyz | t3d_a | 1 | no |")
    assert rows[1].startswith("| terrain/b.xyz | t3d_b, t3d_c | 10 | yes | +0.200, -0.100, +0.020, +0.030")
