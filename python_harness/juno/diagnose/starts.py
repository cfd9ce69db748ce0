"""Where a candidate's search starts: the soil patch at the base model's worst place
(patch_start) and along the ground the drawbar runs covered (patch_grid), its centre kept on
the ground the wheels touched (patch_on_the_ground), and the registration of each scan fitted
kinematically on the measured pose (registration_evidence, registration_candidate,
registration_start)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..campaign import Campaign, read_run
from ..registration import ScanEvidence, ScanRegistrations
from .candidates import CANDIDATES, Candidate, for_runs
from .problem import BLOCK, Problem

#: Bins along x (m) over which patch_start averages the squared residuals: the distance from which
#: the patch's least-squares fit converges (patch_grid), so a start in the worst bin is in its basin.
PATCH_BIN = 0.5
#: Distance (m) from which the least-squares fit of a patch converges to it (measured: from 0.5 m
#: off, to the truth within 2 cm): patch_grid's starts are twice this apart.
PATCH_CONVERGES = 0.5
#: A bin with no more torque samples than this (a quarter of a second of both drive torques at
#: 20 Hz) is too thin an average to be the worst.
PATCH_MIN_SAMPLES = 10


def patch_start(campaign: Campaign, problem: Problem, r: np.ndarray) -> dict[str, float]:
    """Where to start the soil-patch search: the place where the residuals ``r`` (of the base
    model or the first cause) of the drive torques are largest: the centroid of the samples in
    the PATCH_BIN-wide bin along x with the largest mean squared residual, at the measured
    positions; {} when there are no torque residuals."""
    x, y, w = _torque_residuals_along_path(campaign, problem, r)
    if x is None:
        return {}
    bins = np.floor(x / PATCH_BIN)
    best, best_val = None, -1.0
    for b in np.unique(bins):
        sel = bins == b
        if np.sum(sel) > PATCH_MIN_SAMPLES and np.mean(w[sel]) > best_val:
            best, best_val = b, float(np.mean(w[sel]))
    if best is None:
        return {}
    sel = bins == best
    return {"soilPatch.x": float(np.mean(x[sel])), "soilPatch.y": float(np.mean(y[sel]))}


def _torque_residuals_along_path(campaign: Campaign, problem: Problem, r: np.ndarray
                                 ) -> tuple[np.ndarray | None, np.ndarray | None, np.ndarray | None]:
    """(x, y, squared residual) of every drive-torque residual in ``r``, at the measured position
    (m) of its time; (None, None, None) when there are none."""
    meta = problem.meta
    xs, ys, ws = [], [], []
    for run_id in np.unique(meta["run"]):
        data = read_run(campaign, campaign.run(str(run_id)))
        tx, px = data.samples("pos_x")
        ty, py = data.samples("pos_y")
        t0 = data.time[0]
        for sig in ("torque_left", "torque_right"):
            m = (meta["run"] == run_id) & (meta["signal"] == sig)
            if not np.any(m):
                continue
            t = meta["time"][m] + t0
            xs.append(np.interp(t, tx, px))
            ys.append(np.interp(t, ty, py))
            ws.append(r[m] ** 2)
    if not ws:
        return None, None, None
    return np.concatenate(xs), np.concatenate(ys), np.concatenate(ws)


def patch_grid(campaign: Campaign, spacing: float = PATCH_CONVERGES * 2) -> tuple[tuple[tuple[str, float], ...], ...]:
    """Starts for the soil-patch search: a somewhat weaker patch of 0.7 m radius centred at
    evenly spaced places at most ``spacing`` m apart along the ground the drawbar runs covered
    (from the measured positions), from 0.5 m after its start to 0.5 m before its end.
    The least-squares fit of a patch converges from PATCH_CONVERGES, but from the wrong side of
    the track it settles on a patch that explains little, and the cost at a start with the
    base soil does not tell which start is in the right basin: so each start gets a short fit
    (Candidate.short_fits).  Starts twice PATCH_CONVERGES apart put every place along the track
    within that distance of one: closer starts are short fits that find the same basin.
    Measured on three fresh soil-patch draws (strength 0.74-0.94, the soil patch the only
    candidate): from starts about 1 m apart the fitted patch was the one found from starts
    0.5 m apart (its centre within 0.3 mm, the held-out gain within 0.1 %), and the diagnosis
    took 22-25 CPU seconds instead of 28-36."""
    xs, ys = [], []
    for run in campaign.runs_of_kind("drawbar"):
        data = read_run(campaign, run)
        xs.append(data.samples("pos_x")[1])
        ys.append(data.samples("pos_y")[1])
    if not xs:
        return ()
    x, y = np.concatenate(xs), np.concatenate(ys)
    y_mid = float(np.median(y))
    first, last = float(np.min(x)) + 0.5, float(np.max(x)) - 0.5
    if last < first:
        return ()
    places = np.linspace(first, last, int(np.ceil((last - first) / spacing - 1e-9)) + 1)
    return tuple((("soilPatch.x", float(cx)), ("soilPatch.y", y_mid), ("soilPatch.radius", 0.7),
                  ("soilPatch.khFactor", 0.8), ("soilPatch.strengthFactor", 0.8)) for cx in places)


def patch_on_the_ground(campaign: Campaign, fmu_path: str) -> Candidate:
    """The soil-patch candidate with its centre bounded to the ground the wheels touched: the
    measured path of every run, widened by half the rover's track and half a wheel's width.
    Why: a patch is a property of ground the rover drove over; centred off that ground, the data
    sees only the tail of its Gaussian, a smooth one-sided gradient across the track, and such a
    fit stands for no patch (it can mimic, for instance, a drag on one side of the rover)."""
    from ..rover_model import rover
    xs, ys = [], []
    for run in campaign.runs:
        if run.kind not in ("drawbar", "terrain"):
            continue
        data = read_run(campaign, run)
        if data.has("pos_x") and data.has("pos_y"):
            xs.append(data.samples("pos_x")[1])
            ys.append(data.samples("pos_y")[1])
    patch = CANDIDATES["soil_patch"]
    if not xs:
        return patch
    shape = rover(campaign.rover, fmu_path)
    margin = 0.5 * shape.track + 0.5 * shape.wheel_width
    x, y = np.concatenate(xs), np.concatenate(ys)
    bounds = {"soilPatch.x": (float(np.min(x)) - margin, float(np.max(x)) + margin),
              "soilPatch.y": (float(np.min(y)) - margin, float(np.max(y)) + margin)}
    params = tuple(replace(e, start=float(np.clip(e.start, *bounds[e.name])), lower=bounds[e.name][0],
                           upper=bounds[e.name][1]) if e.name in bounds else e for e in patch.params)
    return replace(patch, params=params)


def payload_for_the_rover(campaign: Campaign, fmu_path: str) -> Candidate:
    """The payload candidate with bounds from the rover's stated mass m (rover.mass as the
    manifest's rover entry or the FMU's default gives it): from -m/2 (a rover half as heavy as
    stated) to +m (twice as heavy), within the FMU's range of rover.payload (-200 to 1000 kg).
    Beyond those a weighing was not wrong, the rover is another one."""
    from ..rover_model import rover
    mass = rover(campaign.rover, fmu_path).mass
    payload = CANDIDATES["payload"]
    (param,) = payload.params
    return replace(payload, params=(replace(param, lower=max(-0.5 * mass, -200.0), upper=min(mass, 1000.0)),))


def registration_evidence(campaign: Campaign, grids) -> ScanRegistrations | None:
    """Each scan's registration fitted kinematically on the training blocks of the terrain runs on
    it (the measured height, pitch and roll against the rover posed on the scan, no simulation:
    juno.registration), and how much better than the scan as it is it explains their held-out
    blocks.  ``grids``: each terrain run's gridded scan by run id (runs on one scan have the same
    grid; the scan's first run's is used), or one grid for every terrain run.  None when no scan's
    runs are long enough to have both kinds of block.

    Why per scan: each scan was taken and registered on its own, so each has its own error; the
    runs on one scan share its registration and all of them measure it, and no other scan's
    data enters it (juno.registration.scans_of)."""
    from ..registration import flat_height, held_out_evidence, joined, scans_of, traverse_of
    h0 = flat_height(campaign)
    found = []
    for scan, runs in scans_of(campaign):
        grid = grids[runs[0].id] if isinstance(grids, dict) else grids
        traverses, masks = [], []
        for run in runs:
            traverse = traverse_of(campaign, run)
            # The blocks of build_problem, which count from the run's first sample: the traverse's
            # times are the run's own clock, which may start anywhere (a data logger's), and
            # blocks counted on it would fit the registration on the blocks the replay is judged on.
            since_start = traverse.t - read_run(campaign, run).time[0]
            traverses.append(traverse)
            masks.append((np.floor(since_start / BLOCK).astype(int) % 2) == 0)
        train = np.concatenate(masks)
        evidence = None
        if train.any() and not train.all():
            evidence = held_out_evidence(grid, joined(traverses), h0, train)
        found.append(ScanEvidence(scan, tuple(r.id for r in runs), evidence))
    if all(s.evidence is None for s in found):
        return None
    return ScanRegistrations(tuple(found))


def _registered_scans(evidence: ScanRegistrations) -> list[ScanEvidence]:
    """The scans the registration candidate moves: those whose evidence is significant; when none
    is, every scan (each at its neutral setting)."""
    return evidence.misregistered() or list(evidence.scans)


def registration_candidate(evidence: ScanRegistrations | None) -> Candidate:
    """The registration candidate of a campaign: the catalogue's six parameters, which move every
    terrain run's scan alike, when the campaign has one scan; with several, the six parameters of
    each scan it moves (_registered_scans), each applied to that scan's runs only
    (candidates.for_runs), so the offsets of one scan never move another and every scan moved
    is charged its own six parameters (Candidate.parameters_in)."""
    catalogue = CANDIDATES["terrain_offset"]
    if evidence is None or len(evidence.scans) == 1:
        return catalogue
    return replace(catalogue, params=tuple(replace(e, name=for_runs(e.name, s.runs))
                                           for s in _registered_scans(evidence) for e in catalogue.params))


def registration_start(evidence: ScanRegistrations | None) -> dict[str, float]:
    """Where the registration candidate (registration_candidate) is: each scan it moves at the
    kinematic registration fitted on every sample of its runs once that scan's held-out evidence
    is significant (so its replayed gain, which is reported but not judged, is not fully held out
    for the height), else at the scan as it is (the neutral setting, which does not act)."""
    if evidence is None:
        return {e.name: 0.0 for e in CANDIDATES["terrain_offset"].params}
    if len(evidence.scans) == 1:
        return evidence.scans[0].offsets
    return {for_runs(k, s.runs): v for s in _registered_scans(evidence) for k, v in s.offsets.items()}
