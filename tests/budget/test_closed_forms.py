"""ESRF study 1.6, 4.1–4.5: quantisation, Newport noise, geometry, air, frame, filters."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.signal import cont2discrete, freqz

from fsmbench.bench.geometry import closed_form_path_error, small_angle_law, trace_bench
from fsmbench.bench.params import default_bench
from fsmbench.budget import (
    air_budget,
    cumulative_power,
    esrf_welch,
    first_order_lowpass,
    frame_budget,
    geometry_budget,
    noise_sources,
    ou_window_factor,
)
from fsmbench.budget.optics import law_checks
from fsmbench.budget.quantisation import SEED_4_5
from fsmbench.budget.spectra import gauss_markov_psd, window_variance, window_weight


@pytest.fixture(scope="module")
def nominal():
    return default_bench().nominal


@pytest.fixture(scope="module")
def noise(nominal):
    return noise_sources(nominal)


# ---------------------------------------------------------------- 1.6, 4.5a: quantisation
def test_quantisation_psd_closed_form(noise):
    q = 20.0 / 2**16
    assert noise.lsb_v == q
    assert noise.adc_psd_v2_per_hz == pytest.approx(q**2 / (12 * 1e4), rel=1e-15)  # same formula
    assert noise.dac_psd_v2_per_hz == noise.adc_psd_v2_per_hz
    # The seed prints 7.76e-13 V²/Hz (3 digits): agrees to its rounding.
    assert noise.adc_psd_v2_per_hz == pytest.approx(SEED_4_5["quantisation_psd_v2_per_hz"],
                                                    rel=5e-4)
    # Two-sided over ±fs/2 gives the variance q²/12 (1e-12: same arithmetic, other order).
    assert math.sqrt(noise.adc_psd_v2_per_hz * 1e4) == pytest.approx(q / math.sqrt(12),
                                                                      rel=1e-12)


def test_quantisation_noise_of_a_busy_signal_is_white_at_gamma():
    """Rounding a signal spanning many LSB: one-sided PSD = 2Γ = q²/(6 fs) at every frequency."""
    fs, q = 1e4, 20.0 / 2**16
    rng = np.random.default_rng(0)
    x = 0.3 * rng.standard_normal(200_000)  # ~1000 LSB rms
    e = np.round(x / q) * q - x
    s = esrf_welch(e, fs_hz=fs)
    band = (s.f_hz > 10) & (s.f_hz < 4900)
    # 39 Welch averages × ~3000 bins: the band mean is known to < 1 %; allow 3 %.
    assert np.mean(s.values[band]) == pytest.approx(q**2 / (6 * fs), rel=0.03)


def test_newport_dac_angle_noise(noise):
    gamma = (20.0 / 2**16) ** 2 / (12 * 1e4)
    expected = (2.62e-3) ** 2 * gamma
    # Closed forms: equal to rounding (1e-12); seed-printed values to their 3 digits (1e-3).
    assert noise.newport_dac_angle_psd_rad2_per_hz == pytest.approx(expected, rel=1e-12)
    # Errata E10: the product is 5.33e-18, not the seed's 3.96e-18.
    assert noise.newport_dac_angle_psd_rad2_per_hz == pytest.approx(5.33e-18, rel=1e-3)
    assert noise.newport_dac_angle_psd_rad2_per_hz / 3.96e-18 == pytest.approx(1.345, rel=1e-3)
    # rms over ±fs/2: gn0·q/√12 = 0.231 µrad (the seed: "0.2 µrad"); same tolerances.
    assert noise.newport_dac_angle_rms_rad == pytest.approx(2.62e-3 * 20 / 2**16 / math.sqrt(12),
                                                            rel=1e-12)
    assert noise.newport_dac_angle_rms_rad == pytest.approx(0.2308e-6, rel=1e-3)


def test_newport_datasheet_angle_noise(noise):
    # 3 µrad mechanical, one reflection: 6 µrad of beam; Γd = (6 µrad)²/fs = 3.6e-15 (seed).
    # Exact products of the parameters: 1e-12 is rounding.
    assert noise.newport_beam_angle_rms_rad == pytest.approx(6e-6, rel=1e-12)
    assert noise.newport_beam_angle_psd_rad2_per_hz == pytest.approx(3.6e-15, rel=1e-12)
    assert noise.newport_rotation_beam_factor == pytest.approx(1.6, rel=1e-12)  # 2R/(H+R)


def test_sercalo_and_qd_numbers(noise):
    # Seed 4.5c: 4·q·(5°/10 V) = 1.0653e-5 rad (printed to 5 digits: 1e-4).
    assert noise.seed_sercalo_dac_lsb_beam_angle_rad == pytest.approx(1.0653e-5, rel=1e-4)
    # Seed 4.5b: 0.03·1 mV/20 V = 1.5 µrad; through Table 2 the 1 mV is 32 µrad (exact: 1e-12).
    assert noise.seed_qd_angle_rad == pytest.approx(1.5e-6, rel=1e-12)
    assert noise.qd_noise_angle_rad[0] == pytest.approx(1e-3 / 31.0, rel=1e-12)
    assert noise.qd_lsb_angle_rad[1] == pytest.approx(20 / 2**16 / 36.3, rel=1e-12)
    # Static plant gain (nominal Gi = 1/(R + Rc), g0, factor 4); 1e-9: the 125 kHz coil pole.
    nom = default_bench().nominal
    g = nom.current_amp_gain_a_per_v().h * nom.sercalo.dc_gain_rad_per_a.h * 4
    assert noise.sercalo_dc_gain_rad_per_v[0] == pytest.approx(g, rel=1e-9)


# ---------------------------------------------------------------- 4.1, 4.2, 11.3: geometry
@pytest.mark.parametrize(("h", "length"), [(0.02, 0.1), (0.05, 0.05), (0.1, 0.02)])
@pytest.mark.parametrize("theta", [1e-7, 1e-6, 1e-5, 1e-4])
def test_path_error_law_against_trace(h, length, theta):
    law = small_angle_law(h_m=h, l_m=length)
    trace = float(trace_bench(theta, h_m=h, l_m=length).path_error_m)
    # Leading neglected term k4/k·θ² ≤ 7e-8 at 1e-4 rad: 1e-7; trace vs closed form: 1e-9.
    assert trace == pytest.approx(float(law.path_error_m(theta)), rel=1e-7)
    assert trace == pytest.approx(float(closed_form_path_error(theta, h_m=h, l_m=length)),
                                  rel=1e-9)


def test_geometry_budget(nominal):
    g = geometry_budget(nominal)
    assert g.path_error_m_per_rad2 == pytest.approx(12 * 0.05 + 8 * 0.05, rel=1e-15)  # exact
    assert g.fit.k_fit_m_per_rad2 == pytest.approx(1.0, rel=1e-7)  # fit over 1e-7..1e-4 rad
    assert g.fit.loglog_slope == pytest.approx(2.0, abs=1e-6)  # quartic term: < 1e-7
    # Table 4: 1, 5, 10 µrad → 1e-12, 2.5e-11, 1e-10 m of path; the seed's are 1000× larger.
    # 1e-9: the k4θ⁴ term (≤ 6.5e-10 at 10 µrad).
    np.testing.assert_allclose(g.table4.path_error_m, [1e-12, 25e-12, 1e-10], rtol=1e-9)
    np.testing.assert_allclose(np.asarray([1e-9, 25e-9, 100e-9]) / g.table4.path_error_m,
                               1000.0, rtol=1e-9)
    # 4.2: Sercalo 2√2 (two hits at 45°), Newport 2 (errata E18); exact at θ = 0 (1e-12).
    assert g.sercalo_motion.path_per_shift == pytest.approx(-2 * math.sqrt(2), rel=1e-12)
    assert g.newport_motion.path_per_shift == pytest.approx(-2.0, rel=1e-12)
    # 11.3: (6H + 4L)/16 = 0.03125 per squared beam angle, not the seed's L/2 = 0.05 (exact).
    assert g.measured_error_m_per_beam_rad2 == pytest.approx(0.03125, rel=1e-15)
    assert g.seed_11_3_m_per_beam_rad2 == pytest.approx(0.05, rel=1e-15)
    assert g.max_check_relative_difference < 1e-6  # quadratic law, θ ≤ 1e-4, all geometries


def test_law_checks_quartic_term():
    for c in law_checks():
        if c.theta_rad >= 1e-3:
            # At 1 mrad the quadratic law is off by k4/k·θ² (~7e-6); the quartic term fixes it.
            assert abs(c.relative_difference_quartic) < 1e-9
            assert abs(c.relative_difference) > 1e-6


# ---------------------------------------------------------------- 4.3, 4.4: air and frame
def test_air_seed_tables(nominal):
    a = air_budget(nominal)
    per_k = abs(a.without_compensation[0].error_m)
    assert per_k == pytest.approx(94.5e-9, rel=2e-3)  # Ciddor at 1530 nm: 0.945 ppm/K × 0.1 m
    assert a.without_compensation[1].error_m == pytest.approx(26.5e-9, rel=2e-3)  # 3 digits
    assert abs(a.without_compensation[2].error_m) == pytest.approx(8.7e-9, rel=5e-3)  # 2 digits
    # Eq. (11): the full ranges (±) of the compensated table, RSS.
    half = math.sqrt(sum(v.error_m**2 for v in a.with_compensation))
    assert a.eq11_full_range_rss_m == pytest.approx(2 * half, rel=1e-12)  # same sum
    assert a.eq11_full_range_rss_m == pytest.approx(56.4e-9, rel=2e-3)  # 3 digits
    # The seed's own arithmetic: √(20² + 50² + 4²) = 54.0 nm.
    assert math.sqrt(20**2 + 50**2 + 4**2) == pytest.approx(54.0, abs=0.01)  # it is 54.00


def test_frame_seed_numbers(nominal):
    f = frame_budget(nominal)
    assert f.aluminium_m_per_k == pytest.approx(0.05 * 23e-6, rel=1e-12)  # 1.15 µm/K ("≈1")
    assert f.invar_m_per_k == pytest.approx(60e-9, rel=1e-12)  # 0.05 × 1.2e-6, exact
    # Room drift through the frame lag: σ·√(τr/(τr + τf)).
    assert f.frame_temperature_stationary_rms_k == pytest.approx(0.05 * math.sqrt(600 / 1500))
    stat = frame_budget(nominal, window_s=None)
    # Numerical integral of the lagged Lorentzian against its closed form: 1e-4 (grid).
    assert stat.window_rms_m == pytest.approx(stat.stationary_rms_m, rel=1e-4)


@pytest.mark.parametrize(("window", "tau"), [(100.0, 1.0), (100.0, 30.0), (100.0, 600.0),
                                             (1.0, 900.0), (None, 5.0)])
def test_window_variance_of_gauss_markov(window, tau):
    var = window_variance(lambda f: gauss_markov_psd(f, rms=1.0, tau_s=tau), window_s=window,
                          f_max_hz=1e6, n=20000)
    # Log-grid trapezoid of a smooth integrand: 1e-4 relative.
    assert var == pytest.approx(ou_window_factor(window, tau), rel=1e-4)


def test_ou_window_factor_series_branch():
    x = 1e-4
    assert ou_window_factor(x * 1.0001, 1.0) == pytest.approx(ou_window_factor(x * 0.9999, 1.0),
                                                              rel=1e-3)  # continuous at switch
    assert ou_window_factor(1e6, 1.0) == pytest.approx(1.0, abs=3e-6)  # 1 − 2/x, x = 1e6


# ---------------------------------------------------------------- filters and spectra
def test_lowpass_is_the_exact_zoh_discretisation():
    fs, f0 = 1e4, 50.0
    w0 = 2 * math.pi * f0
    sys = tuple(np.array([[v]]) for v in (-w0, w0, 1.0, 0.0))
    ad, bd, cd, _, _ = cont2discrete(sys, 1 / fs, method="zoh")
    rng = np.random.default_rng(1)
    x = rng.standard_normal(5000)
    y = first_order_lowpass(x, cutoff_hz=f0, fs_hz=fs)
    ref = np.zeros_like(x)
    state = 0.0
    for k in range(x.size):  # the state-space recursion, as MATLAB's lsim runs it
        ref[k] = cd[0, 0] * state
        state = ad[0, 0] * state + bd[0, 0] * x[k]
    np.testing.assert_allclose(y, ref, rtol=1e-12, atol=1e-14)  # same recursion: rounding
    # Step from rest: 1 − exp(−w0 k T) exactly.
    step = first_order_lowpass(np.ones(100), cutoff_hz=f0, fs_hz=fs)
    np.testing.assert_allclose(step, 1 - np.exp(-w0 * np.arange(100) / fs), rtol=1e-12)  # exact
    steady = first_order_lowpass(np.full(10, 3.0), cutoff_hz=f0, fs_hz=fs, initial="steady")
    np.testing.assert_allclose(steady, 3.0, rtol=1e-14)  # equilibrium: rounding only
    # −3 dB at f0 to the discretisation's accuracy (plus the half-sample hold delay).
    _, h = freqz([0.0, 1 - math.exp(-w0 / fs)], [1.0, -math.exp(-w0 / fs)], worN=[f0], fs=fs)
    assert abs(h[0]) == pytest.approx(1 / math.sqrt(2), rel=1e-3)  # ZOH at f0/fs = 0.5 %: 1e-3


def test_cumulative_power_and_window_weight():
    f = np.linspace(0, 100, 1001)
    c = cumulative_power(f, np.full_like(f, 2.0))
    assert c[-1] == pytest.approx(200.0)  # trapezoid of a constant: exact
    assert window_weight(np.array([0.0]), window_s=10.0)[0] == 0.0
    # sinc(fT) vanishes at integer fT: weight 1 to rounding (pytest's default 1e-6).
    assert window_weight(np.array([0.1, 0.2]), window_s=10.0) == pytest.approx([1.0, 1.0])


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"cutoff_hz": 0.0, "fs_hz": 1e4}, "must be > 0"),
    ({"cutoff_hz": 10.0, "fs_hz": 1e4, "initial": "warm"}, "initial"),
])
def test_lowpass_bad_input(kwargs, match):
    with pytest.raises(ValueError, match=match):
        first_order_lowpass(np.ones(3), **kwargs)


def test_window_weight_bad_input():
    with pytest.raises(ValueError, match="window_s"):
        window_weight(np.ones(2), window_s=0.0)
