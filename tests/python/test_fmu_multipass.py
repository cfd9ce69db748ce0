"""Specification of the multi-pass extension: rear wheels roll in the front wheels' rut, on soil the
front wheels compacted.

Each side remembers the residual rut its front wheel leaves along its forward travel,
(1 - gamma) z_max; the rear wheel, one wheelbase behind, sinks that much less
(multipass.rutFraction of it) on soil stiffer by up to multipass.khFactor.  Off (0) by default.

A rover started moving (init.vx > 0) has been driving: its rear wheels stand in a rut from the
start.  Without that, a replay restarted mid-run on a slow climb dug the rear wheels in for
seconds (README, "terrain run replayed in segments").
"""

from __future__ import annotations

import numpy as np
import pytest

from fmu_helpers import run

SPIN = 2.0          # rad/s, both sides
MULTIPASS = {"multipass.rutFraction": 1.0, "multipass.khFactor": 2.0}
SINKAGE = ["wheelFL.sinkage", "wheelRL.sinkage", "wheelFR.sinkage", "wheelRR.sinkage"]


def _drive(fmu_unzipped, params, stop_time):
    return run(fmu_unzipped, {"drive.mode": 1, **params}, {"omegaRefLeft": SPIN, "omegaRefRight": SPIN},
               stop_time=stop_time, outputs=["x", "vx", *SINKAGE])


def _at(r, name, t):
    return float(np.interp(t, r["time"], r[name]))


def _front_rear(r, t):
    """Mean sinkage of the two front wheels and of the two rear wheels at time t, m."""
    front = 0.5 * (_at(r, "wheelFL.sinkage", t) + _at(r, "wheelFR.sinkage", t))
    rear = 0.5 * (_at(r, "wheelRL.sinkage", t) + _at(r, "wheelRR.sinkage", t))
    return front, rear


@pytest.fixture(scope="module")
def from_rest(fmu_unzipped):
    """12 s from rest, about 4 m: the front wheels cover the 0.82 m wheelbase in the first 3 s."""
    return {"off": _drive(fmu_unzipped, {}, 12.0), "on": _drive(fmu_unzipped, MULTIPASS, 12.0)}


def test_rear_wheels_roll_in_the_front_wheels_rut_once_the_rover_has_covered_a_wheelbase(from_rest):
    """The rear wheels sink far less with the extension (measured: 19.6 against 38.0 mm; under
    traction the rear wheels carry more load, so without a rut they sink deeper than the front
    ones, 22.0 mm); the front wheels, on fresh soil, sink alike."""
    on, off = from_rest["on"], from_rest["off"]
    assert _at(on, "x", 12.0) - on["x"][0] > 2.0, "the rover must cover more than a wheelbase"
    front_on, rear_on = _front_rear(on, 12.0)
    front_off, rear_off = _front_rear(off, 12.0)
    print(f"\nsinkage front/rear: multipass off {front_off * 1e3:.2f}/{rear_off * 1e3:.2f} mm, "
          f"on {front_on * 1e3:.2f}/{rear_on * 1e3:.2f} mm")
    assert front_on == pytest.approx(front_off, rel=0.1)
    assert rear_on < 0.7 * rear_off


def test_a_rover_started_moving_already_rolls_in_its_rut(fmu_unzipped, from_rest):
    """Half a second after a start at the speed the rover reached from rest, its rear wheels sink
    as they do after 12 s of driving, and far less than without the extension (with an empty rut
    memory at the start, as before, they sank as without it)."""
    steady_rear = _front_rear(from_rest["on"], 12.0)[1]
    speed = _at(from_rest["on"], "vx", 12.0)
    rear = {label: _front_rear(_drive(fmu_unzipped, {**params, "init.vx": speed}, 1.0), 0.5)[1]
            for label, params in (("on", MULTIPASS), ("off", {}))}
    print(f"\nstarted at {speed:.3f} m/s: rear sinkage at 0.5 s {rear['on'] * 1e3:.2f} mm "
          f"({rear['off'] * 1e3:.2f} without multi-pass); after 12 s from rest {steady_rear * 1e3:.2f} mm")
    assert rear["on"] == pytest.approx(steady_rear, rel=0.2)
    assert rear["on"] < 0.7 * rear["off"]


def test_a_rover_started_in_reverse_or_at_rest_gets_no_rut(fmu_unzipped):
    """The rut is recorded along forward travel only, and a rover at rest has just been put down:
    at the start its rear wheels sink as its front wheels do (at rest they carry alike)."""
    for params in ({**MULTIPASS, "init.vx": -0.2}, MULTIPASS, {"init.vx": 0.25}):
        r = run(fmu_unzipped, {"drive.mode": 1, **params}, {"omegaRefLeft": 0.0, "omegaRefRight": 0.0},
                stop_time=0.05, outputs=SINKAGE)
        front, rear = _front_rear(r, 0.0)
        assert rear == pytest.approx(front, rel=0.1), params
