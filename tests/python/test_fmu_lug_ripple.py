"""Specification of the lug ripple and of the wheels' spin angles.

Each side's wheel angle relative to its rocker (``spinAngleLeft``, ``spinAngleRight``, rad) is
integrated in the FMU state from 0 at initialisation, as an encoder would count it.  With
``grouser.lugCount`` N and ``grouser.rippleAmplitude`` a, the traction limit of a wheel pulses
with its lugs, F_taumax (1 + a cos(N theta + phi)), theta the side's spin angle and phi the
side's ``grouser.lugPhaseLeft`` or ``grouser.lugPhaseRight`` (0 by default: where the lugs are
when the run starts) on the front wheels, pi more on the rear ones (half a lug pitch behind);
a = 0 (the default) is no ripple.
"""

from __future__ import annotations

import numpy as np
import pytest

from fmu_helpers import Rover, output_names, run

N_LUGS = 18
DRAWBAR = {"drawbarForce": 400.0, "throttleLeft": 0.45, "throttleRight": 0.45}
OUTPUTS = ["omegaLeft", "spinAngleLeft", "torqueLeftApplied", "wheelFL.Ft", "wheelRL.Ft"]
STEP = 0.01          # s, communication step: 100 Hz, well above the lug-passing 2-3 Hz
STEADY_FROM = 6.0    # s, the drawbar run has settled by then


def _drawbar_run(fmu_unzipped, amplitude: float, phase_left: float = 0.0, phase_right: float = 0.0
                 ) -> dict[str, np.ndarray]:
    """A 12 s drawbar run at 400 N on DC motors (45 % throttle), lugs rippling at ``amplitude``,
    each side's lugs at its phase."""
    params = {"drive.mode": 2, "grouser.lugCount": N_LUGS, "grouser.rippleAmplitude": amplitude,
              "grouser.lugPhaseLeft": phase_left, "grouser.lugPhaseRight": phase_right}
    return run(fmu_unzipped, params, DRAWBAR, stop_time=12.0, step=STEP, outputs=OUTPUTS)


@pytest.fixture(scope="module")
def drawbar_runs(fmu_unzipped) -> dict[float, dict[str, np.ndarray]]:
    return {a: _drawbar_run(fmu_unzipped, a) for a in (0.0, 0.15, 0.3)}


def _steady(r: dict[str, np.ndarray], name: str) -> np.ndarray:
    return r[name][r["time"] >= STEADY_FROM]


def _ripple(r: dict[str, np.ndarray], wheel: str, phase: float) -> tuple[float, float]:
    """Least-squares fit of a wheel's traction over the steady part to m + c cos(N theta + phase)
    + s sin(N theta + phase): returns (m, c) in N, c the part in phase with the lugs."""
    theta = _steady(r, "spinAngleLeft")
    X = np.column_stack([np.ones_like(theta), np.cos(N_LUGS * theta + phase), np.sin(N_LUGS * theta + phase)])
    coef = np.linalg.lstsq(X, _steady(r, f"wheel{wheel}.Ft"), rcond=None)[0]
    return float(coef[0]), float(coef[1])


def test_the_traction_ripples_at_the_lug_passing_frequency(drawbar_runs):
    """The spectrum of a front wheel's traction peaks at N omega / (2 pi), within the spectrum's
    resolution, once the lugs ripple; without the ripple there is no such peak."""
    r = drawbar_runs[0.3]
    ft = _steady(r, "wheelFL.Ft")
    freq = np.fft.rfftfreq(len(ft), STEP)
    spectrum = np.abs(np.fft.rfft(ft - ft.mean()))
    peak = freq[1 + int(np.argmax(spectrum[1:]))]
    expected = N_LUGS * float(np.mean(_steady(r, "omegaLeft"))) / (2 * np.pi)
    resolution = freq[1]
    print(f"\npeak {peak:.3f} Hz, N omega / 2 pi = {expected:.3f} Hz, resolution {resolution:.3f} Hz")
    assert abs(peak - expected) <= 1.5 * resolution
    assert 1.0 < expected < 10.0                         # below the 20 Hz instruments' Nyquist frequency
    flat = _steady(drawbar_runs[0.0], "wheelFL.Ft")
    flat_spectrum = np.abs(np.fft.rfft(flat - flat.mean()))
    at = int(np.argmin(np.abs(freq - expected)))
    assert flat_spectrum[at - 1:at + 2].max() < 0.02 * spectrum[at - 1:at + 2].max()


def test_the_ripple_grows_with_its_amplitude_in_phase_with_the_lugs(drawbar_runs):
    """The traction's part at N per revolution, in phase with cos(N theta) on a front wheel and
    with cos(N theta + pi) on a rear one, is about a times the mean traction, so it doubles from
    a = 0.15 to 0.3 (within 10 %), and it is nil at a = 0."""
    parts = {}
    for a, r in drawbar_runs.items():
        for wheel, phase in (("FL", 0.0), ("RL", np.pi)):
            mean, in_phase = _ripple(r, wheel, phase)
            parts[a, wheel] = (mean, in_phase)
            print(f"\na = {a}: {wheel} traction {mean:.1f} N, ripple in phase {in_phase:.1f} N")
    for wheel in ("FL", "RL"):
        mean = parts[0.3, wheel][0]
        assert abs(parts[0.0, wheel][1]) < 0.002 * mean
        assert 0.5 * 0.3 * mean < parts[0.3, wheel][1] < 2.0 * 0.3 * mean
        assert parts[0.3, wheel][1] / parts[0.15, wheel][1] == pytest.approx(2.0, rel=0.1)


def test_a_sides_lug_phase_moves_its_ripple_by_that_phase(drawbar_runs, fmu_unzipped):
    """With the left side's lug phase at 1 rad, the traction's ripple is in phase with
    cos(N theta + 1) on the left front wheel and with cos(N theta + 1 + pi) on the left rear one,
    as large as at phase 0 (within 10 %); its part in phase with cos(N theta) is cos(1) of that
    (within 15 %): the whole ripple moved by the phase."""
    shifted = _drawbar_run(fmu_unzipped, 0.3, phase_left=1.0)
    for wheel, rear in (("FL", 0.0), ("RL", np.pi)):
        _mean, at_zero = _ripple(drawbar_runs[0.3], wheel, rear)
        _mean, moved = _ripple(shifted, wheel, rear + 1.0)
        _mean, unmoved = _ripple(shifted, wheel, rear)
        print(f"\n{wheel}: ripple {at_zero:.1f} N at phase 0, {moved:.1f} N at phase 1 in phase with it, "
              f"{unmoved:.1f} N in phase with phase 0's")
        assert moved == pytest.approx(at_zero, rel=0.1)
        assert unmoved == pytest.approx(np.cos(1.0) * at_zero, rel=0.15)


def test_the_drive_torque_ripples_with_the_traction(drawbar_runs):
    """The lugs' ripple reaches the measured drive torque: its spread over the steady part grows
    from the bare drive's to more than ten times that at a = 0.3."""
    still = float(np.std(_steady(drawbar_runs[0.0], "torqueLeftApplied")))
    rippled = float(np.std(_steady(drawbar_runs[0.3], "torqueLeftApplied")))
    print(f"\ntorque spread: {still:.3f} N m without, {rippled:.3f} N m with the ripple")
    assert rippled > 10 * still


def test_no_ripple_amplitude_is_the_base_model_exactly(fmu_unzipped):
    """grouser.rippleAmplitude = 0 with a lug count set gives the default model bit for bit, every
    output."""
    inputs = {"drawbarForce": 300.0, "throttleLeft": 0.6, "throttleRight": 0.5}
    base = run(fmu_unzipped, {"drive.mode": 2}, inputs, stop_time=3.0)
    zero = run(fmu_unzipped, {"drive.mode": 2, "grouser.lugCount": N_LUGS, "grouser.rippleAmplitude": 0.0},
               inputs, stop_time=3.0)
    for name in base:
        assert np.array_equal(base[name], zero[name]), name


def test_the_spin_angle_is_the_integral_of_the_spin(fmu_unzipped):
    """At fixed internal steps of one communication step each, the angle advances by h times the
    spin at the step's end (the positions' symplectic Euler), to round-off.  Under the automatic
    step, once the wheels have spun up (1 s: the first 10 ms sample misses the spin-up), the angle
    gained follows the trapezoidal integral of the 100 Hz spin output to 10 urad per rad."""
    names = ["omegaLeft", "omegaRight", "spinAngleLeft", "spinAngleRight"]
    inputs = {"drawbarForce": 200.0, "throttleLeft": 0.6, "throttleRight": 0.4}
    fixed = run(fmu_unzipped, {"drive.mode": 2, "solver.tolerance": 0.0, "solver.step": 1e-3}, inputs,
                stop_time=2.0, step=1e-3, outputs=names)
    auto = run(fmu_unzipped, {"drive.mode": 2}, inputs, stop_time=8.0, step=STEP, outputs=names)
    for side in ("Left", "Right"):
        angle, spin = fixed[f"spinAngle{side}"], fixed[f"omega{side}"]
        assert angle[0] == 0.0
        assert np.max(np.abs(np.diff(angle) - 1e-3 * spin[1:])) < 1e-14
        after = auto["time"] >= 1.0
        angle, spin = auto[f"spinAngle{side}"][after], auto[f"omega{side}"][after]
        gained = angle - angle[0]
        trapezoid = np.concatenate([[0.0], np.cumsum(0.5 * (spin[1:] + spin[:-1]) * STEP)])
        assert gained[-1] > 3.0
        assert np.max(np.abs(gained - trapezoid)) < 1e-5 * gained[-1]
    assert auto["spinAngleLeft"][-1] > 1.2 * auto["spinAngleRight"][-1]   # the faster side turns further


def test_a_restored_state_continues_the_ripple_exactly(fmu_unzipped):
    """An FMU state taken mid-run, serialized and restored into a second instance, holds the
    spin angles: the rippling run continues bit for bit."""
    params = {"drive.mode": 2, "grouser.lugCount": N_LUGS, "grouser.rippleAmplitude": 0.3}
    names = output_names(fmu_unzipped)
    with Rover(fmu_unzipped, "original") as original, Rover(fmu_unzipped, "copy") as copy:
        original.setup(params, initial_inputs=DRAWBAR)
        copy.setup(params, initial_inputs=DRAWBAR)
        original.advance(150, STEP, DRAWBAR, names)
        state = original.fmu.getFMUstate()
        blob = original.fmu.serializeFMUstate(state)
        original.fmu.freeFMUstate(state)
        expected = original.advance(100, STEP, DRAWBAR, names)
        restored = copy.fmu.deSerializeFMUstate(blob)
        copy.fmu.setFMUstate(restored)
        copy.fmu.freeFMUstate(restored)
        copy.time = 150 * STEP
        got = copy.advance(100, STEP, DRAWBAR, names)
    assert names.index("spinAngleLeft") >= 0 and expected[0, names.index("spinAngleLeft")] > 1.0
    assert np.array_equal(got, expected)
