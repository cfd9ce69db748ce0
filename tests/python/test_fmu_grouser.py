"""Specification of the grouser extension: the lugged tires shear soil at a larger radius and gain
thrust beyond the Mohr-Coulomb limit of a smooth rim.

grouser.thrustGain g scales the traction limit F_taumax by (1 + g); grouser.lugHeight h moves the
shear surface to the lug tips, at R + h, while the soil's pressure stays on the rim of radius R.
So the shear's moment about the axle is (R + h) F_t, and its slip is that of the lug tips,
1 - v / (omega (R + h)).  Both are off (0) by default.
"""

from __future__ import annotations

import numpy as np
import pytest

from fmu_helpers import run, wheel_names

R = 0.2794
LUG = 0.02
DRAWBAR = 450.0
STOP = 22.0


def _steady(r, name):
    """Mean of an output over the last 5 s of a 22 s run (the drawbar runs settle by then)."""
    last = r["time"] >= r["time"][-1] - 5.0 - 1e-9
    return float(np.mean(r[name][last]))


@pytest.fixture(scope="module")
def steady_drawbar(fmu_unzipped):
    """Drawbar pull at 450 N on DC motors (throttle 0.8), with and without lugs."""
    outputs = ["vx", "omegaLeft", "torqueLeftApplied"] + wheel_names("Ft") + wheel_names("Fn") + wheel_names("sinkage")
    runs = {}
    for label, params in (("smooth", {}), ("lugs", {"grouser.lugHeight": LUG})):
        runs[label] = run(fmu_unzipped, {"drive.mode": 2, **params},
                          {"drawbarForce": DRAWBAR, "throttleLeft": 0.8, "throttleRight": 0.8},
                          stop_time=STOP, outputs=outputs)
    return runs


def _lever(r):
    """Drive torque of the left side over the traction of its two wheels: the shear's lever, m."""
    return _steady(r, "torqueLeftApplied") / (_steady(r, "wheelFL.Ft") + _steady(r, "wheelRL.Ft"))


def test_the_shear_acts_at_the_rim_without_lugs_and_at_the_lug_tips_with_them(steady_drawbar):
    """At a steady spin the drive torque balances the shear's moment alone (the normal force
    passes through the hub): torque = lever x traction, with the lever R, or R + h with lugs."""
    smooth, lugs = _lever(steady_drawbar["smooth"]), _lever(steady_drawbar["lugs"])
    print(f"\nlever: smooth {smooth:.5f} m (R = {R}), lugs {lugs:.5f} m (R + h = {R + LUG})")
    assert smooth == pytest.approx(R, rel=2e-3)
    assert lugs == pytest.approx(R + LUG, rel=2e-3)


def test_the_lug_tips_slip_as_the_smooth_rim_does_under_the_same_load(steady_drawbar):
    """The soil's pressure is unchanged, so under the same drawbar load the traction needs the
    same shear slip: 1 - v / (omega (R + h)) with lugs equals 1 - v / (omega R) without.  The
    rim itself then slips less (at the same omega the rover goes faster)."""
    def slip(r, radius):
        return 1.0 - _steady(r, "vx") / (_steady(r, "omegaLeft") * radius)

    smooth, lugs = steady_drawbar["smooth"], steady_drawbar["lugs"]
    at_rim, at_tips = slip(smooth, R), slip(lugs, R + LUG)
    print(f"\nshear slip: smooth rim {at_rim:.4f}, lug tips {at_tips:.4f}; "
          f"the lugged wheel's rim {slip(lugs, R):.4f}")
    assert at_tips == pytest.approx(at_rim, abs=0.01)
    assert slip(lugs, R) < at_rim - 0.03
    for w in ("FL", "RL"):   # the same pressure: the same sinkage and normal force
        assert _steady(lugs, f"wheel{w}.sinkage") == pytest.approx(_steady(smooth, f"wheel{w}.sinkage"), rel=0.03)
        assert _steady(lugs, f"wheel{w}.Fn") == pytest.approx(_steady(smooth, f"wheel{w}.Fn"), rel=0.03)


def test_no_lugs_is_the_base_model_exactly(fmu_unzipped):
    """grouser.lugHeight = 0 set explicitly gives the default model bit for bit."""
    inputs = {"drawbarForce": 300.0, "throttleLeft": 0.6, "throttleRight": 0.5}
    base = run(fmu_unzipped, {"drive.mode": 2}, inputs, stop_time=3.0)
    zero = run(fmu_unzipped, {"drive.mode": 2, "grouser.lugHeight": 0.0}, inputs, stop_time=3.0)
    for name in base:
        assert np.array_equal(base[name], zero[name]), name

