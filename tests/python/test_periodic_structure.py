"""The periodic test: a ripple in the wheel angle at N per revolution in held-out residuals.

Synthetic residual arrays only (seconds): drawbar-like runs whose wheel spins vary slowly about
0.5-1.1 rad/s, the torque residuals sampled at 50 Hz, the held-out half of alternating 4 s
blocks, and the measured spin carrying encoder noise.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import binom

from juno.periodic_structure import (FALSE_ALARM, MATERIAL_FRACTION, PeriodicBases, PeriodicSeries, periodic_signal,
                                     periodic_structure, wheel_angle)

SIGMA = 3.0          # N m, torque sensor noise
SPIN_NOISE = 0.01    # rad/s, encoder spin noise


def _run(rng: np.random.Generator, name: str, spin: float, duration: float, noise: str = "white",
         ripple: float = 0.0, lugs: int = 18, dt: float = 0.02, wobble: float = 0.2) -> PeriodicSeries:
    """One run's held-out torque residuals: sensor noise (``noise``: white, plus a random walk or a
    slow drift as large as the noise or larger) and a ripple of amplitude ``ripple`` (N m) at
    ``lugs`` per revolution of the true wheel angle; the angle the test gets is the measured
    spin's integral; the spin varies by ``wobble`` of itself over the run."""
    t = np.arange(0.0, duration, dt)
    w = spin * (1.0 + wobble * np.sin(2.0 * np.pi * t / duration))
    true_angle = np.concatenate([[0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) * dt)])
    measured = w + SPIN_NOISE * rng.standard_normal(len(t))
    e = SIGMA * rng.standard_normal(len(t))
    if noise == "walk":
        e += 0.5 * SIGMA * np.cumsum(rng.standard_normal(len(t)))
    elif noise == "drift":
        e += 3.0 * SIGMA * np.sin(2.0 * np.pi * t / 20.0 + rng.uniform(0, 2 * np.pi))
    r = e + ripple * np.cos(lugs * true_angle + rng.uniform(0, 2 * np.pi))
    block = np.floor(t / 4.0).astype(int)
    held = block % 2 == 1
    return PeriodicSeries(name, "torque_left", t[held], r[held], block[held], wheel_angle(t, measured, t[held]),
                          SIGMA, dt, float(np.percentile(measured, 95)))


def _campaign(seed: int, **kw) -> list[PeriodicSeries]:
    rng = np.random.default_rng(seed)
    return [_run(rng, "dbp1", 0.6, 24.0, **kw), _run(rng, "dbp2", 1.0, 20.0, **kw)]


def test_the_wheel_angle_is_the_integral_of_the_spin():
    t = np.linspace(0.0, 10.0, 501)
    angle = wheel_angle(t, 0.5 + 0.1 * t, np.array([0.0, 4.0, 10.0]))
    assert angle == pytest.approx([0.0, 0.5 * 4 + 0.05 * 16, 0.5 * 10 + 0.05 * 100], rel=1e-9)


def test_the_angle_from_a_noisy_encoder_stays_coherent_over_a_run():
    """Spin noise of 0.01 rad/s white at 50 Hz makes the angle a random walk of
    sigma sqrt(T dt): 0.011 rad after 60 s, a phase error of 0.2 rad at 18 lugs."""
    rng = np.random.default_rng(5)
    dt, duration = 0.02, 60.0
    t = np.arange(0.0, duration + dt / 2, dt)
    errors = [wheel_angle(t, 1.0 + SPIN_NOISE * rng.standard_normal(len(t)), t[-1:])[0] - duration
              for _ in range(300)]
    expected = SPIN_NOISE * np.sqrt(duration * dt)
    assert np.std(errors) == pytest.approx(expected, rel=0.15)
    assert 18 * expected < 0.25


def test_a_ripple_at_18_per_revolution_is_found_with_its_count_and_amplitude():
    """The amplitude within three standard errors (each of a and b: sigma sqrt(2 / samples))."""
    runs = _campaign(1, ripple=1.5)
    found = periodic_signal(runs, "N m", n_signals=2)
    assert found is not None and found.significant
    assert found.lugs == 18
    standard_error = SIGMA * np.sqrt(2.0 / sum(len(r.residual) for r in runs))
    assert abs(found.amplitude - 1.5) < 3 * standard_error
    assert found.ratio == pytest.approx(found.amplitude / SIGMA)
    assert found.p_value < 1e-6


def test_a_significant_ripple_below_the_materiality_floor_is_not_reported():
    """At 0.2 sigma over 2000 samples the ripple is well resolved, but smaller than the floor."""
    rng = np.random.default_rng(2)
    runs = [_run(rng, f"r{i}", 0.8, 80.0, ripple=0.2 * SIGMA) for i in range(2)]
    found = periodic_signal(runs, "N m", n_signals=2)
    assert found.lugs == 18 and found.p_value < 1e-4
    assert found.ratio < MATERIAL_FRACTION and not found.significant


@pytest.mark.parametrize("noise", ["white", "walk", "drift"])
def test_noise_alone_gives_findings_no_more_often_than_the_stated_rate(noise):
    """Over 60 seeds, p-values of noise alone (white, or coloured by a random walk or a slow
    drift much larger than the noise) are not smaller than a uniform's: the count below 0.1 and
    the count reported (rate at most FALSE_ALARM / 2 per signal) stay within binomial bounds
    (a chance of 1e-3 of exceeding them if the rates hold)."""
    seeds = 60
    results = [periodic_signal(_campaign(100 + s, noise=noise), "N m", n_signals=2) for s in range(seeds)]
    p = np.array([r.p_value for r in results])
    assert np.sum(p < 0.1) <= binom.ppf(0.999, seeds, 0.1)
    assert sum(r.significant for r in results) <= binom.ppf(0.999, seeds, FALSE_ALARM / 2)


def test_the_tests_of_two_models_on_the_same_samples_share_their_bases_and_give_each_its_own_result(monkeypatch):
    """Two models' residuals on the same held-out samples and wheel angles (one with a ripple, one
    without): with their bases kept (PeriodicBases) each gets the result it gets alone, bit for
    bit, and each run's bases are computed once; a run whose angles differ gets its own."""
    import juno.periodic_structure as periodic
    rippled, plain = _campaign(7, ripple=1.5), _campaign(8)
    other = [PeriodicSeries(**{**vars(s), "residual": r.residual}) for s, r in zip(rippled, plain)]
    alone = [periodic_structure(runs, {"torque_left": "N m"}).to_json() for runs in (rippled, other)]
    assert alone[0]["significant"] and not alone[1]["significant"]
    made = []
    series_bases = periodic._series_bases
    monkeypatch.setattr(periodic, "_series_bases", lambda s, lugs: made.append(s.run) or series_bases(s, lugs))
    bases = PeriodicBases()
    shared = [periodic_structure(runs, {"torque_left": "N m"}, bases=bases).to_json() for runs in (rippled, other)]
    assert shared == alone
    assert made == ["dbp1", "dbp2"]
    periodic_structure(plain, {"torque_left": "N m"}, bases=bases)      # other wheel angles: bases of their own
    assert made == ["dbp1", "dbp2", "dbp1", "dbp2"]


def test_lug_counts_aliased_by_the_sampling_are_not_tested():
    """20 Hz torques at up to 2.2 rad/s: an N above 0.8 x Nyquist x 2 pi / spin (22.8) is not tested."""
    rng = np.random.default_rng(3)
    run = _run(rng, "fast", 1.8, 24.0, dt=0.05)
    found = periodic_signal([run], "N m", n_signals=1)
    limit = 0.8 * 10.0 * 2.0 * np.pi / run.fastest_spin
    assert found.tested[1] == int(np.floor(limit))


def test_the_campaign_result_names_the_signal_and_says_what_it_follows():
    rng = np.random.default_rng(4)
    left = [_run(rng, "dbp1", 0.7, 24.0, ripple=2.0), _run(rng, "dbp2", 1.0, 20.0, ripple=2.0)]
    right = [_run(rng, "dbp1", 0.7, 24.0), _run(rng, "dbp2", 1.0, 20.0)]
    for s in right:
        s.signal = "torque_right"
    result = periodic_structure(left + right, {"torque_left": "N m", "torque_right": "N m"})
    assert result.significant and result.level == pytest.approx(FALSE_ALARM / 2)
    assert [s.signal for s in result.found()] == ["torque_left"]
    assert "follows the wheel angle at 18 per revolution" in result.found()[0].sentence()
    assert result.to_json()["signals"][0]["per_revolution"] == 18


def _ringing(rng: np.random.Generator, name: str, spin: float, duration: float, hz: float, amplitude: float,
             dt: float = 0.02) -> PeriodicSeries:
    """One run's held-out torque residuals: sensor noise and an oscillation of ``amplitude`` (N m)
    at a fixed ``hz`` (a rover ringing near a stall), whatever the wheel's angle, at a steady spin."""
    series = _run(rng, name, spin, duration, dt=dt, wobble=0.01)
    series.residual = series.residual + amplitude * np.cos(2.0 * np.pi * hz * series.time)
    return series


def test_a_ripple_in_one_run_alone_is_no_lug_ripple():
    """As on a campaign whose rover rang at about 3 Hz near a stall in its slowest drawbar run:
    at that run's steady spin a fixed frequency scans as a lug count (3.07 Hz at 0.49 rad/s:
    N = 39).  Lugs give the same N in every run; with the run that carries the evidence left
    out, the others show nothing at that N, so no ripple is reported."""
    rng = np.random.default_rng(11)
    slow = _ringing(rng, "dbp2", 0.49, 24.0, hz=39 * 0.49 / (2 * np.pi), amplitude=3.0)
    others = [_run(rng, "dbp1", 1.0, 24.0), _run(rng, "dbp3", 0.95, 24.0)]
    found = periodic_signal([slow] + others, "N m", n_signals=1)
    assert found.p_value < FALSE_ALARM and found.ratio >= MATERIAL_FRACTION     # the scan alone would report it
    assert found.other_runs_p > FALSE_ALARM and not found.significant
    assert found.to_json()["other_runs_p"] == found.other_runs_p


def test_a_fixed_frequency_in_runs_at_different_spins_is_no_lug_ripple_but_lugs_at_any_spin_are():
    rng = np.random.default_rng(12)
    ringing = [_ringing(rng, "dbp1", 0.6, 24.0, hz=2.0, amplitude=2.5),
               _ringing(rng, "dbp2", 1.0, 20.0, hz=2.0, amplitude=2.5)]
    assert not periodic_signal(ringing, "N m", n_signals=1).significant
    lugs = periodic_signal(_campaign(12, ripple=2.5), "N m", n_signals=1)
    assert lugs.significant and lugs.lugs == 18 and lugs.other_runs_p < FALSE_ALARM


def test_one_run_cannot_tell_lugs_from_a_fixed_frequency():
    rng = np.random.default_rng(13)
    found = periodic_signal([_run(rng, "dbp1", 0.7, 24.0, ripple=3.0)], "N m", n_signals=1)
    assert found.p_value < 1e-6 and found.other_runs_p == 1.0 and not found.significant
