"""Signal metrics on synthetic signals with known answers."""

from __future__ import annotations

import math

import numpy as np
import pytest
from metric_cases import DT, second_order_step, time_grid

from trackmj.results import signals as S


def test_rmse_ise_peak_of_constant_and_sine_error() -> None:
    t = time_grid(10.0)
    ref = np.full_like(t, 15e3)
    y = ref + 300.0 * np.sin(2 * np.pi * 2.0 * t)
    assert S.rmse(t, y, ref) == pytest.approx(300 / math.sqrt(2), rel=1e-3)
    assert S.ise(t, y, ref) == pytest.approx(300**2 / 2 * 10.0, rel=1e-3)
    assert S.peak_abs_error(t, y, ref) == pytest.approx(300.0, rel=1e-6)
    # window: a constant 100 N offset only after 5 s
    y2 = ref + np.where(t > 5.0, 100.0, 0.0)
    assert S.rmse(t, y2, ref, (6.0, 10.0)) == pytest.approx(100.0)
    assert S.rmse(t, y2, ref, (0.0, 4.0)) == 0.0
    assert math.isnan(S.rmse(t, y2, ref, (20.0, 30.0)))


def test_first_order_step_no_overshoot_and_settling_time() -> None:
    tau, t_step = 0.3, 3.0
    t = time_grid(10.0)
    y = 12e3 + 3e3 * np.where(t >= t_step, 1 - np.exp(-(t - t_step) / tau), 0.0)
    ov = S.overshoot(t, y, 12e3, 15e3, (t_step, 10.0))
    assert ov.value == 0.0 and ov.percent == 0.0
    # 2 % of the step size (60 N) -> the textbook -tau ln(0.02)
    ts = S.settling_time(t, y, 15e3, t_step, band_abs=0.02 * 3e3)
    assert ts == pytest.approx(-tau * math.log(0.02), abs=2e-4)
    # 2 % of the final value (300 N) -> -tau ln(300/3000)
    ts_final = S.settling_time(t, y, 15e3, t_step)
    assert ts_final == pytest.approx(-tau * math.log(0.1), abs=2e-4)


@pytest.mark.parametrize("zeta", [0.2, 0.5, 0.7])
def test_second_order_overshoot_is_textbook(zeta: float) -> None:
    t = time_grid(10.0)
    y = second_order_step(t, zeta, 2 * np.pi * 2.0)
    ov = S.overshoot(t, y, 0.0, 1.0)
    expected = math.exp(-zeta * math.pi / math.sqrt(1 - zeta**2))
    assert ov.value == pytest.approx(expected, rel=1e-3)
    assert ov.percent == pytest.approx(100 * expected, rel=1e-3)
    # settling in the 2 % band: the envelope bound exp(-zeta wn t)/sqrt(1-zeta^2) = 0.02
    wn = 2 * np.pi * 2.0
    bound = -math.log(0.02 * math.sqrt(1 - zeta**2)) / (zeta * wn)
    ts = S.settling_time(t, y, 1.0, 0.0)
    assert bound - 1.0 / (zeta * wn) < ts <= bound + 1e-3


def test_overshoot_of_downward_step_and_study_percent_convention() -> None:
    t = time_grid(5.0)
    y = 15e3 - 3e3 * second_order_step(t, 0.5, 10.0)  # 15 -> 12 kN, undershoots below 12
    ov = S.overshoot(t, y, 15e3, 12e3)
    assert ov.value == pytest.approx(3e3 * math.exp(-0.5 * math.pi / math.sqrt(0.75)), rel=1e-3)
    # the study quotes 15.7 kN after a 12 -> 15 kN step as 4.6 %: percent of the final value
    peak = S.overshoot(np.array([0.0, 1.0]), np.array([12e3, 15.7e3]), 12e3, 15e3)
    assert peak.percent == pytest.approx(4.67, abs=0.01)


def test_settling_nan_when_never_settled() -> None:
    t = time_grid(2.0)
    y = 1.0 + 0.5 * np.sin(2 * np.pi * t)
    # the sine passes through the ±0.02 band at its zero crossings; it last enters it when
    # 0.5 |sin(2 pi t)| = 0.02 just before t = 2 s
    entry = 2.0 - math.asin(0.04) / (2 * math.pi)
    assert S.settling_time(t, y, 1.0, 0.0) == pytest.approx(entry, abs=1e-5)
    assert math.isnan(S.settling_time(t, y, 1.0, 0.0, min_hold_s=0.1))


def test_recovery_time_after_a_dip() -> None:
    t = time_grid(20.0)
    ref = np.full_like(t, 15e3)
    on, tau = 12.0, 0.5
    dip = np.where(t >= on, 900.0 * np.exp(-(t - on) / tau), 0.0)
    y = ref - dip
    # |e| = 900 exp(-s/tau) <= 300 N from s = tau ln 3
    assert S.recovery_time(t, y, ref, on, 20.0, 300.0) == pytest.approx(tau * math.log(3),
                                                                         abs=2e-4)
    assert S.recovery_time(t, ref, ref, on, 20.0, 300.0) == 0.0


def test_fluctuation_band_of_sine_and_noise() -> None:
    t = time_grid(30.0)
    ref = np.full_like(t, 15e3)
    sine = ref + 1300.0 * np.sin(2 * np.pi * 8.3 * t)
    assert S.fluctuation_band(t, sine, ref) == pytest.approx(1300.0, rel=0.01)
    rng = np.random.default_rng(0)
    noisy = ref + rng.normal(0.0, 500.0, t.shape)
    assert S.fluctuation_band(t, noisy, ref) == pytest.approx(1.96 * 500.0, rel=0.03)


def test_constraint_violation_time() -> None:
    t = time_grid(10.0)
    y = np.where((t >= 2.0) & (t < 3.5), 25e3, 15e3)  # 1.5 s above 20 kN
    y[(t >= 6.0) & (t < 6.5)] = 8e3                  # 0.5 s below 10 kN
    assert S.constraint_violation_time(t, y, 10e3, 20e3) == pytest.approx(2.0, abs=2 * DT)


def test_switching_rate_of_known_mode_sequence() -> None:
    t = time_grid(10.0)
    # hold / pressurize / hold / release repeating with 0.5 s phases -> 2 changes per second
    phase = (t // 0.5).astype(int) % 4
    mode = np.array([0, 1, 0, -1], dtype=np.int8)[phase]
    assert S.switch_count(mode) == 20  # changes at 0.5, 1.0, ..., 10.0 s
    assert S.switching_rate(t, mode) == pytest.approx(2.0)
    assert S.switching_rate(t, mode, (0.0, 1.2)) == pytest.approx(2 / 1.2)
    assert S.switching_rate(t, np.zeros_like(mode)) == 0.0


def test_control_increment_rms_per_control_period() -> None:
    held = np.repeat(np.array([0.0, 0.1, -0.1, 0.1, -0.1]), 10)  # 10 ms zero-order hold
    assert S.control_increment_rms(held, stride=10) == pytest.approx(
        math.sqrt((0.1**2 + 3 * 0.2**2) / 4))
    assert S.control_increment_rms(held, stride=1) < S.control_increment_rms(held, stride=10)


@pytest.mark.parametrize("amp", [0.5, 3.0])
def test_band_rms_of_sines(amp: float) -> None:
    t = time_grid(30.0)

    def band(x: np.ndarray) -> float:
        return S.band_rms(t, x, 8.0, 12.0, resolution_Hz=0.5)

    assert band(amp * np.sin(2 * np.pi * 10.0 * t)) == pytest.approx(amp / math.sqrt(2),
                                                                       rel=0.01)
    assert band(amp * np.sin(2 * np.pi * 2.0 * t)) < 1e-3 * amp
    mixed = amp * np.sin(2 * np.pi * 2.0 * t) + 0.2 * np.sin(2 * np.pi * 9.1 * t + 1.0)
    assert band(mixed) == pytest.approx(0.2 / math.sqrt(2), rel=0.02)


def test_psd_integrates_to_the_variance_and_marks_missing_signals() -> None:
    t = time_grid(20.0)
    rng = np.random.default_rng(3)
    x = 5.0 + 2.0 * np.sin(2 * np.pi * 7.0 * t) + rng.normal(0.0, 0.5, t.shape)
    f, density = S.psd(t, x, resolution_Hz=0.5)
    assert f[1] - f[0] == pytest.approx(0.5)
    assert np.sum(density) * 0.5 == pytest.approx(np.var(x), rel=0.02)   # Parseval
    assert f[np.argmax(density)] == pytest.approx(7.0)
    _, none = S.psd(t, np.full_like(t, np.nan), resolution_Hz=0.5)
    assert np.isnan(none).all()


def test_lowpass_magnitude_is_the_squared_butterworth() -> None:
    """|H|^2 = 1/(1 + (f/fc)^4) for sosfiltfilt of a 2nd-order Butterworth: -6 dB at fc."""
    t = time_grid(20.0)
    inner = (t > 5.0) & (t < 15.0)            # away from the ends' odd extension
    for f in (0.5, 2.0, 8.0, 20.0):
        x = np.sin(2 * np.pi * f * t)
        gain = np.max(np.abs(S.lowpass(t, x, 2.0)[inner]))
        assert gain == pytest.approx(1.0 / (1.0 + (f / 2.0) ** 4), rel=0.01, abs=1e-5)
    assert np.isnan(S.lowpass(t, np.full_like(t, np.nan), 2.0)).all()
    with pytest.raises(ValueError, match="Nyquist"):
        S.lowpass(t, np.sin(t), 600.0)


def test_lowpass_of_a_perfect_step_is_what_its_docstring_says() -> None:
    """The filter's own share of a low-passed step response: 3.4 % overshoot, pre-ringing
    from 0.11 s before the step, inside ±10 % of the step from 0.11 s after it."""
    t = time_grid(20.0)
    y = S.lowpass(t, np.where(t >= 10.0, 3e3, 0.0), 2.0)
    assert (y.max() - 3e3) / 3e3 == pytest.approx(0.0335, abs=5e-4)
    assert S.settling_time(t, y, 3e3, 10.0, band_abs=300.0) == pytest.approx(0.111, abs=2e-3)
    assert 10.0 - t[np.flatnonzero(np.abs(y) > 300.0)[0]] == pytest.approx(0.111, abs=2e-3)


def test_energy_of_constant_and_linear_power() -> None:
    t = time_grid(4.0)
    assert S.energy(t, np.full_like(t, 250.0)) == pytest.approx(1000.0)
    e = S.cumulative_energy(t, 100.0 * t)  # ∫100 t dt = 50 t²
    np.testing.assert_allclose(e, 50.0 * t**2, atol=1e-9)
    assert e[0] == 0.0


def test_solve_time_stats() -> None:
    st = S.solve_time_stats(np.array([1e-3, 3e-3, 2e-3, 9e-3]),
                            np.array([True, True, False, True]))
    assert st == (pytest.approx(2.5e-3), 9e-3, 1)


def test_trailing_mean_is_causal_and_exact() -> None:
    t = time_grid(2.0)
    y = np.where(t >= 1.0, 1000.0, 0.0)
    m = S.trailing_mean(t, y, 0.5)
    assert m[t < 1.0].max() == 0.0                       # nothing from the future
    i = np.searchsorted(t, 1.25)                         # half the window past the step
    assert m[i] == pytest.approx(1000.0 * 251 / 500, rel=1e-9)
    assert m[t >= 1.5].min() == pytest.approx(1000.0)
