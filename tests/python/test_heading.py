"""The rover's heading where a run has no yaw column (juno/heading.py): at the start, the track's
direction with its standard error; along the run, the direction of travel."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from juno.campaign import RunData
from juno.heading import LEAST_TRAVEL, start_heading, track_headings


def straight_run(heading: float, speed: float, noise: float, seed: int, spin: float = 1.0,
                 duration: float = 10.0, rate: float = 5.0) -> RunData:
    """A run without yaw: 1 s at rest, then straight at ``speed`` (m/s, negative: reversing) along
    ``heading`` (rad), positions at ``rate`` Hz with ``noise`` (m) on each, spins ``spin`` rad/s."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration, 1.0 / rate)
    s = speed * np.clip(t - 1.0, 0.0, None)
    x = 3.0 + s * np.cos(heading) + rng.normal(0, noise, len(t))
    y = -2.0 + s * np.sin(heading) + rng.normal(0, noise, len(t))
    return RunData(Path("run.csv"), "drawbar", {"time": t, "pos_x": x, "pos_y": y, "omega_left": np.full(len(t), spin),
                                                "omega_right": np.full(len(t), spin)}, run_id="db1")


def test_the_start_heading_is_the_tracks_direction_within_its_standard_error():
    """Over many noise draws the errors scatter as the stated standard error says."""
    errors, sigmas = [], []
    for seed in range(200):
        h = start_heading(straight_run(0.7, 0.15, 0.005, seed))
        assert h.source == "track"
        errors.append(np.angle(np.exp(1j * (h.value - 0.7))))
        sigmas.append(h.sigma)
    assert abs(np.mean(errors)) < 3 * np.std(errors) / np.sqrt(len(errors))
    assert 0.7 < np.std(errors) / np.sqrt(np.mean(np.square(sigmas))) < 1.3
    assert np.mean(sigmas) < 0.02


def test_a_rover_reversing_faces_against_its_track():
    h = start_heading(straight_run(0.7, -0.15, 0.005, 1, spin=-1.0))
    assert h.value == pytest.approx(0.7, abs=0.05)


def test_a_measured_yaw_is_taken_as_it_is():
    run = straight_run(0.7, 0.15, 0.005, 1)
    run.columns["yaw"] = np.full(len(run.time), -1.25)
    assert start_heading(run).value == -1.25 and start_heading(run).source == "yaw"


def test_a_rover_that_hardly_moves_has_no_start_heading_and_the_message_says_what_to_give():
    with pytest.raises(ValueError, match=r"run 'db1' has no yaw column.*give the heading as a yaw column"):
        start_heading(straight_run(0.7, 0.5 * LEAST_TRAVEL / 9.0, 0.0, 1))


def test_the_direction_of_travel_follows_a_turn_and_holds_where_the_rover_stands():
    t = np.arange(0.0, 20.0, 0.2)
    turn = 0.05 * t                                   # rad: a steady turn at 0.05 rad/s
    speed = np.where(t < 15.0, 0.2, 0.0)              # stands still for the last 5 s
    x = np.cumsum(speed * np.cos(turn)) * 0.2
    y = np.cumsum(speed * np.sin(turn)) * 0.2
    heading = track_headings(t, x, y)
    moving = (t > 1.0) & (t < 14.0)
    assert np.max(np.abs(heading[moving] - turn[moving])) < 0.02
    assert np.all(np.abs(np.diff(heading[t > 15.5])) == 0)
