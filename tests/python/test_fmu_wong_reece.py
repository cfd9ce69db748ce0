"""Specification of the Wong-Reece/Ishigami contact law in the FMU (contact.model = 1;
Wong and Reece 1967, Ishigami et al. 2007; README "Contact laws").

The law integrates normal and shear stress around the rim (fmu_src/wong_reece.c); the FMU applies
its drawbar pull Fx, vertical load Fz and resisting torque T at each wheel.  Defaults: the dry sand
set (n 1.1, kc 0.99e3, kphi 1.528e6, K 10 mm, a0 0.40, a1 0.15), cohesion and friction angle from
soil.cohesion and soil.phi, rear rebound lambda = soil.gamma.  Run with -s to see the figures.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import integrate, optimize

from fmu_helpers import (
    G,
    WHEELS,
    FMICallException,
    LogCapture,
    Rover,
    bumpy_grid,
    run,
    slope_grid,
    wheel_names,
)

MASS = 317.7
R = 0.2794
B = 0.254
QUARTER_WEIGHT = MASS * G / 4
WR = {"contact.model": 1}
FIXED_1MS = {"solver.step": 1e-3, "solver.tolerance": 0.0}   # the fixed step the tests below examine
FREE = {"drawbarForce": 0.0, "torqueLeft": 0.0, "torqueRight": 0.0}
# the defaults of the table (modelDescription/variables.h)
DRY_SAND = {"n": 1.1, "kc": 990.0, "kphi": 1.528e6, "K": 0.010, "a0": 0.40, "a1": 0.15}
COHESION, PHI, GAMMA = 1000.0, 0.5236, 0.0813


def _mean(r, quantity):
    return np.mean([r[n] for n in wheel_names(quantity)], axis=0)


def _sum(r, quantity):
    return np.sum([r[n] for n in wheel_names(quantity)], axis=0)


# ---------------------------------------------------------------------------------------------
# An independent reference: Wong-Reece at zero slip, by adaptive quadrature (scipy)
# ---------------------------------------------------------------------------------------------

def _wong_reece_fz(h: float, soil=DRY_SAND, c=COHESION, phi=PHI, lam=GAMMA) -> float:
    """Vertical load (N) a rigid wheel (R, B) carries at sinkage h (m) and slip 0 by the equations of
    Wong and Reece with Ishigami's peak angle: sigma = r^n (kc/b + kphi) (cos t - cos t_f)^n in front of the peak
    t_m = a0 t_f, the front profile mapped linearly onto [t_r, t_m] behind it, t_r from the rebound
    lambda h; j = r [(t_f - t) - (sin t_f - sin t)], tau = (c + sigma tan phi)(1 - exp(-j/K))."""
    n, K = soil["n"], soil["K"]
    k = R ** n * (soil["kc"] / B + soil["kphi"])
    tf = math.acos(1 - h / R)
    tr = -math.acos(1 - lam * h / R)
    tm = soil["a0"] * tf

    def sigma(t):
        if t >= tm:
            base = math.cos(t) - math.cos(tf)
        else:
            ts = tf - (t - tr) / (tm - tr) * (tf - tm)
            base = math.cos(ts) - math.cos(tf)
        return k * max(base, 0.0) ** n

    def tau(t):
        j = R * ((tf - t) - (math.sin(tf) - math.sin(t)))
        return (c + sigma(t) * math.tan(phi)) * (1 - math.exp(-j / K))

    f = lambda t: tau(t) * math.sin(t) + sigma(t) * math.cos(t)  # noqa: E731
    return R * B * (integrate.quad(f, tr, tm, limit=200)[0] + integrate.quad(f, tm, tf, limit=200)[0])


def _wong_reece_sinkage(load: float) -> float:
    return optimize.brentq(lambda h: _wong_reece_fz(h) - load, 1e-4, 0.2, xtol=1e-10)


# ---------------------------------------------------------------------------------------------
# Static equilibrium
# ---------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def static_wr(fmu_unzipped):
    return run(fmu_unzipped, {"drive.mode": 0, **WR}, FREE, stop_time=0.0)


def test_rover_starts_in_static_equilibrium_each_wheel_carrying_a_quarter(static_wr):
    for w in WHEELS:
        fz = static_wr[f"wheel{w}.Fz"][0]
        assert fz == pytest.approx(QUARTER_WEIGHT, rel=0.01), f"wheel {w}: Fz = {fz:.1f} N, m g / 4 = {QUARTER_WEIGHT:.1f} N"
        # at rest the support is vertical: no drawbar pull, no traction
        assert abs(static_wr[f"wheel{w}.Fx"][0]) < 1e-6 * QUARTER_WEIGHT
        assert abs(static_wr[f"wheel{w}.Ft"][0]) < 1e-6 * QUARTER_WEIGHT


def test_static_sinkage_matches_an_independent_wong_reece_integration(static_wr):
    ref = _wong_reece_sinkage(QUARTER_WEIGHT)
    sink = [static_wr[f"wheel{w}.sinkage"][0] for w in WHEELS]
    print(f"\nWong-Reece static sinkage: FMU {np.mean(sink) * 1000:.3f} mm, scipy reference "
          f"{ref * 1000:.3f} mm at m g / 4 = {QUARTER_WEIGHT:.1f} N")
    for w, s in zip(WHEELS, sink):
        assert s == pytest.approx(ref, rel=0.02), f"wheel {w}: sinkage {s * 1000:.3f} mm, reference {ref * 1000:.3f} mm"


def test_the_contact_law_changes_the_sinkage(fmu_unzipped, static_wr):
    """The two laws really are different: the volumetric model at its Table 2 soil sinks ~17 mm."""
    vol = run(fmu_unzipped, {"drive.mode": 0}, FREE, stop_time=0.0)
    s_vol, s_wr = vol["wheelFL.sinkage"][0], static_wr["wheelFL.sinkage"][0]
    assert abs(s_wr / s_vol - 1) > 0.2, (s_vol, s_wr)


def test_rover_left_alone_stays_put(fmu_unzipped):
    """At standstill WR's rolling resistance and zero-slip torque fade out (README): no creep."""
    r = run(fmu_unzipped, {"drive.mode": 0, **WR}, FREE, stop_time=10.0, step=0.05)
    d = np.hypot(r["x"] - r["x"][0], r["y"] - r["y"][0])
    assert d.max() < 1e-3, f"the rover crept {d.max() * 1000:.2f} mm in 10 s"
    assert np.ptp(r["z"]) < 1e-4


def test_initial_equilibrium_on_a_slope(fmu_unzipped, tmp_path):
    path = slope_grid(8.0, x_range=(-10, 10), y_range=(-3, 3), cell=0.25).write(tmp_path / "s.asc")
    r = run(fmu_unzipped, {"drive.mode": 0, **WR}, FREE, stop_time=0.0, terrain=path)
    fz = {w: r[f"wheel{w}.Fz"][0] for w in WHEELS}
    assert min(fz.values()) > 0.25 * QUARTER_WEIGHT, fz
    assert abs(math.degrees(r["pitch"][0]) + 8.0) < 1.0


# ---------------------------------------------------------------------------------------------
# Drawbar pull at 45 % throttle (as the volumetric model's test in test_fmu_physics.py)
# ---------------------------------------------------------------------------------------------

DRAWBAR_FORCES = (200.0, 400.0, 600.0, 800.0)


@pytest.fixture(scope="module")
def drawbar_runs(fmu_unzipped):
    """The drawbar runs at a fixed 1 ms step."""
    return {f: run(fmu_unzipped, {"drive.mode": 2, **FIXED_1MS, **WR},
                   {"drawbarForce": f, "throttleLeft": 0.45, "throttleRight": 0.45}, stop_time=22.0)
            for f in DRAWBAR_FORCES}


def test_drawbar_slip_settles_and_rises_with_drawbar_force(drawbar_runs):
    slips = []
    print("\nWong-Reece drawbar pull, throttle 0.45 (last 5 s of 22 s):")
    for f, r in drawbar_runs.items():
        assert all(np.all(np.isfinite(v)) for v in r.values())
        last = r["time"] >= r["time"][-1] - 5.0 - 1e-9
        slip = _mean(r, "slip")[last]
        fx = _sum(r, "Fx")[last].mean()
        print(f"  F = {f:5.0f} N: slip {slip.mean():.4f} (range {np.ptp(slip):.2g}), vx {r['vx'][last].mean():.3f} "
              f"m/s, sinkage {_mean(r, 'sinkage')[last].mean() * 1000:.2f} mm, sum Fx {fx:.1f} N")
        assert np.ptp(slip) < 0.01, f"F = {f} N: slip still changes by {np.ptp(slip):.4f} in the last 5 s"
        assert r["vx"][last].mean() > 0.0
        # steady state on flat ground: the wheels' net pull carries the drawbar load
        assert fx == pytest.approx(f, rel=0.02, abs=5.0)
        slips.append(float(slip.mean()))
    assert all(np.diff(slips) > 0.01), f"steady slip must rise with drawbar force: {slips}"
    assert all(-0.1 < s < 1.0 for s in slips)


def test_the_fixed_1_ms_step_is_converged(fmu_unzipped, drawbar_runs):
    """The linearisation (slip damping, normal stiffness) keeps a fixed 1 ms step stable and
    accurate: a run at a quarter of the step settles to the same slip."""
    fine = run(fmu_unzipped, {"drive.mode": 2, "solver.step": 2.5e-4, "solver.tolerance": 0.0, **WR},
               {"drawbarForce": 600.0, "throttleLeft": 0.45, "throttleRight": 0.45}, stop_time=12.0)
    coarse = drawbar_runs[600.0]
    s_fine = _mean(fine, "slip")[-50:].mean()
    s_coarse = _mean(coarse, "slip")[(coarse["time"] > 7.0) & (coarse["time"] <= 12.0 + 1e-9)].mean()
    print(f"\nslip at 600 N: solver.step 1 ms {s_coarse:.5f}, 0.25 ms {s_fine:.5f}")
    assert s_coarse == pytest.approx(s_fine, rel=0.02, abs=1e-3)


def test_slip_damping_keeps_a_5_ms_step_stable(fmu_unzipped, drawbar_runs):
    """The slip damping d(Fx, Fz, T)/d(v, omega R) in the implicit step: at a fixed 5 ms step the
    run settles to the 1 ms slip (without the damping term it oscillates at 5 ms and settles at
    a wrong slip already at 2 ms: measured while writing this test)."""
    big = run(fmu_unzipped, {"drive.mode": 2, "solver.step": 5e-3, "solver.tolerance": 0.0, **WR},
              {"drawbarForce": 600.0, "throttleLeft": 0.45, "throttleRight": 0.45}, stop_time=12.0)
    ref = drawbar_runs[600.0]
    s_big = _mean(big, "slip")[-100:]
    s_ref = _mean(ref, "slip")[(ref["time"] > 11.0) & (ref["time"] <= 12.0 + 1e-9)].mean()
    assert np.ptp(s_big) < 1e-3
    assert s_big.mean() == pytest.approx(s_ref, rel=0.01)


# ---------------------------------------------------------------------------------------------
# Terrain
# ---------------------------------------------------------------------------------------------

def test_drives_over_bumpy_terrain(fmu_unzipped, tmp_path):
    grid = bumpy_grid(seed=2, amplitude=0.05, cell=0.05, x_range=(-2.0, 6.0), y_range=(-3.0, 3.0), flat_start=0.8)
    path = grid.write(tmp_path / "bumpy.asc")
    r = run(fmu_unzipped, {"drive.mode": 2, **WR}, {"drawbarForce": 0.0, "throttleLeft": 0.45, "throttleRight": 0.45},
            stop_time=10.0, terrain=path)
    assert all(np.all(np.isfinite(v)) for v in r.values())
    frac = {w: float(np.mean(r[f"wheel{w}.Fz"] > 0)) for w in WHEELS}
    print(f"\nWong-Reece on bumps: travelled {r['x'][-1]:.2f} m, contact fractions {frac}, rocker range "
          f"{math.degrees(np.ptp(r['rocker'])):.2f} deg")
    assert r["x"][-1] > 1.8
    assert min(frac.values()) >= 0.95
    assert math.degrees(np.ptp(r["rocker"])) > 0.5
    assert abs(r["y"][-1]) < 0.5


# ---------------------------------------------------------------------------------------------
# Parameters
# ---------------------------------------------------------------------------------------------

# Each value inside its declared range, but the combination breaks a rule checked together at
# initialisation (the single values out of range are refused when set, below).
BAD = [
    ({"wongReece.a0": 0.3, "wongReece.a1": 0.35}, "wongReece.a1"),   # |a1| > a0: theta_m < 0 at s = -1
    ({"wongReece.a0": 0.8, "wongReece.a1": 0.3}, "wongReece.a1"),    # |a1| >= 1 - a0: theta_m >= theta_f at s = 1
    ({"wongReece.kc": -3e5, "wongReece.kphi": 1e6}, "wongReece.kc"),  # kc / b + kphi < 0
    ({"wongReece.kphi": 1e3, "wongReece.kc": -1e3}, "wongReece.kphi"),
]


@pytest.mark.parametrize("law", [0, 1])
@pytest.mark.parametrize("params,name", BAD, ids=[n + "=" + str(list(p.values())[0]) for p, n in BAD])
def test_bad_wong_reece_parameters_fail_initialisation_naming_them(fmu_unzipped, params, name, law):
    """Checked whichever law is selected: a bad combination is reported when it is set, not when
    the law is switched on later."""
    log = LogCapture()
    with Rover(fmu_unzipped, log=log) as r:
        with pytest.raises(FMICallException) as exc:
            r.setup({"contact.model": law, **params})
    assert exc.value.function == "fmi2ExitInitializationMode"
    assert name in log.errors()[-1], log.errors()


@pytest.mark.parametrize("name,value", [("wongReece.points", 5), ("contact.model", 2), ("wongReece.K", -0.01),
                                        ("wongReece.K", 0.0), ("wongReece.n", 0.0), ("wongReece.a0", 1.0),
                                        ("wongReece.kc", -1e6), ("wongReece.kphi", -2e6)])
def test_out_of_range_values_are_refused_when_set(fmu_unzipped, name, value):
    log = LogCapture()
    with Rover(fmu_unzipped, log=log) as r:
        with pytest.raises(FMICallException):
            r.set({name: value})
    assert any(name in m for m in log.errors()), log.errors()


def test_points_change_the_result_only_a_little(fmu_unzipped):
    """wongReece.points is the quadrature resolution: 20 vs 1000 points move the static sinkage
    by well under 1 %, and the values are used (they do differ)."""
    s = {}
    for pts in (20, 1000):
        r = run(fmu_unzipped, {"drive.mode": 0, "wongReece.points": pts, **WR}, FREE, stop_time=0.0)
        s[pts] = r["wheelFL.sinkage"][0]
    assert s[20] != s[1000]
    assert s[20] == pytest.approx(s[1000], rel=0.01)


def test_soil_parameters_reach_the_law(fmu_unzipped, static_wr):
    """A stiffer soil (kphi x 2) sinks less; a larger K does not change the static load balance."""
    stiff = run(fmu_unzipped, {"drive.mode": 0, "wongReece.kphi": 2 * DRY_SAND["kphi"], **WR}, FREE, stop_time=0.0)
    assert stiff["wheelFL.sinkage"][0] < 0.8 * static_wr["wheelFL.sinkage"][0]


def test_contact_model_0_is_bit_identical_to_the_default(fmu_unzipped, tmp_path):
    grid = bumpy_grid(seed=3, amplitude=0.04, cell=0.05, x_range=(-2.0, 6.0), y_range=(-3.0, 3.0), flat_start=0.8)
    path = grid.write(tmp_path / "b.asc")
    inputs = {"drawbarForce": 300.0, "throttleLeft": 0.5, "throttleRight": 0.4}
    a = run(fmu_unzipped, {"drive.mode": 2}, inputs, stop_time=4.0, terrain=path)
    b = run(fmu_unzipped, {"drive.mode": 2, "contact.model": 0, "wongReece.kphi": 3e6, "wongReece.points": 50},
            inputs, stop_time=4.0, terrain=path)
    assert a.keys() == b.keys()
    for k in a:
        assert np.array_equal(a[k], b[k]), f"{k} differs"
