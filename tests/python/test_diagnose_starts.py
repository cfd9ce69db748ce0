"""Where the diagnosis's soil-patch search may look: along the ground the runs covered, with the
patch's centre kept on the ground the wheels touched (juno/diagnose/starts.py)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from juno.campaign import read_run
from juno.diagnose.candidates import CANDIDATES
from juno.diagnose.starts import PATCH_CONVERGES, patch_grid, patch_on_the_ground, payload_for_the_rover
from juno.rover_model import rover

pytest_plugins = ["harness_fixtures"]


def _path(campaign):
    xs, ys = [], []
    for run in campaign.runs:
        data = read_run(campaign, run)
        xs.append(data.samples("pos_x")[1])
        ys.append(data.samples("pos_y")[1])
    return np.concatenate(xs), np.concatenate(ys)


def test_the_patch_centre_is_bounded_to_the_wheels_footprint(noisy_campaign, fmu_path):
    campaign = noisy_campaign.campaign
    patch = patch_on_the_ground(campaign, fmu_path)
    bounds = {e.name: (e.lower, e.upper) for e in patch.params}
    x, y = _path(campaign)
    shape = rover(campaign.rover, fmu_path)
    margin = 0.5 * shape.track + 0.5 * shape.wheel_width
    assert bounds["soilPatch.x"] == (np.min(x) - margin, np.max(x) + margin)
    assert bounds["soilPatch.y"] == (np.min(y) - margin, np.max(y) + margin)
    for e in patch.params:                      # every start inside its bounds
        assert e.lower <= e.start <= e.upper, e
    unchanged = {e.name: e for e in CANDIDATES["soil_patch"].params}
    for name in ("soilPatch.radius", "soilPatch.khFactor", "soilPatch.strengthFactor"):
        assert bounds[name] == (unchanged[name].lower, unchanged[name].upper)


def test_the_patch_grid_starts_lie_inside_the_bounds(noisy_campaign, fmu_path):
    campaign = noisy_campaign.campaign
    bounds = {e.name: (e.lower, e.upper) for e in patch_on_the_ground(campaign, fmu_path).params}
    grid = patch_grid(campaign)
    assert grid
    for point in grid:
        values = dict(point)
        for name in ("soilPatch.x", "soilPatch.y"):
            assert bounds[name][0] <= values[name] <= bounds[name][1]


def test_every_place_along_the_drawbar_track_is_within_reach_of_a_patch_start(noisy_campaign):
    """The patch's fit converges from PATCH_CONVERGES (0.5 m): every place along the drawbar runs'
    track, but the half metre at either end, is at most that far from a start, and the starts are
    no closer together than they need to be for that (closer ones would find the same basins)."""
    campaign = noisy_campaign.campaign
    x = np.concatenate([read_run(campaign, r).samples("pos_x")[1] for r in campaign.runs_of_kind("drawbar")])
    starts = np.array([dict(point)["soilPatch.x"] for point in patch_grid(campaign)])
    places = np.linspace(np.min(x) + 0.5, np.max(x) - 0.5, 200)
    assert len(starts) >= 2
    assert np.max(np.min(np.abs(places[:, None] - starts[None, :]), axis=1)) <= PATCH_CONVERGES + 1e-9
    gaps = np.diff(starts)
    assert np.all(gaps > 0) and np.allclose(gaps, gaps[0]) and gaps[0] <= 2 * PATCH_CONVERGES + 1e-9
    assert len(starts) == 1 + int(np.ceil((starts[-1] - starts[0]) / (2 * PATCH_CONVERGES) - 1e-9))


def test_the_grouser_fit_also_starts_from_thrust_gains_away_from_none():
    """The thrust gain acts where the shear nears its limit, and at a drawbar campaign's slips the
    shear modulus takes up most of it: the grouser's coarse search tries gains of a half and one
    besides its start at none, each inside the gain's bounds, so that the fit can reach the
    basin where the gain, not K_vx and the lugs' height, carries the extra thrust."""
    grouser = CANDIDATES["grouser"]
    gain = next(p for p in grouser.params if p.name == "grouser.thrustGain")
    tried = sorted(dict(point)["grouser.thrustGain"] for point in grouser.grid)
    assert gain.start == 0.0 and tried == [0.5, 1.0]
    assert all(gain.lower < g <= gain.upper for g in tried)


def test_the_payload_ranges_from_half_the_stated_rover_to_twice_it(noisy_campaign, fmu_path):
    """The payload's bounds follow the mass the campaign states (rover.mass in the manifest's rover
    entry, else the FMU's default), within the FMU's range of rover.payload (-200 to 1000 kg);
    its neutral start and the catalog's other settings stay."""
    catalog = CANDIDATES["payload"]
    for rover_entry, lower, upper in (({}, -0.5 * 317.7, 317.7), ({"rover.mass": 120.0}, -60.0, 120.0),
                                      ({"rover.mass": 1500.0}, -200.0, 1000.0)):
        campaign = replace(noisy_campaign.campaign, rover=rover_entry)
        (param,) = payload_for_the_rover(campaign, fmu_path).params
        assert (param.lower, param.upper) == (lower, upper), rover_entry
        assert param.start == catalog.params[0].start == 0.0
    assert payload_for_the_rover(noisy_campaign.campaign, fmu_path).active == catalog.active


def test_a_payload_the_manifest_states_is_part_of_the_stated_mass(noisy_campaign, fmu_path):
    """A manifest's rover.payload is given to every replay as part of rover.mass (the same rover to
    the FMU), so that the payload candidate's neutral 0 is the campaign's statement."""
    from juno.identify import base_parameters
    campaign = replace(noisy_campaign.campaign, rover={"rover.payload": 25.0, "wheel.width": 0.25})
    assert base_parameters(campaign) == {"rover.mass": 317.7 + 25.0, "wheel.width": 0.25}
    (param,) = payload_for_the_rover(campaign, fmu_path).params
    assert param.upper == 317.7 + 25.0
