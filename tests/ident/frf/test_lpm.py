"""Local polynomial method: unbiased, variance as estimated, the transient removed.

Known system: a second-order digital resonance (100 Hz, pole radius 0.95, 3 dB
bandwidth ~16 Hz at fs = 1 kHz) driven by white noise; scipy.signal gives the
exact response. 200 noise realisations are run at once as 200 output channels
of one record (same input, independent output noise).
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal as ss
import scipy.stats as st

from fsmbench.ident.frf.lpm import LpmOptions, default_half_width, local_polynomial_frf
from fsmbench.ident.frf.response import spectral_matrix
from fsmbench.signal.welch import hanning

FS = 1000.0
L = 4000  # 4 s: line spacing 0.25 Hz, the window (13 lines) 3.25 Hz << the mode's 16 Hz
B = np.array([0.05, 0.05])
A = np.array([1.0, -2 * 0.95 * np.cos(2 * np.pi * 100.0 / FS), 0.95**2])
DRAWS = 200
SIGMA = 0.1  # output noise rms


def truth(f_hz: np.ndarray) -> np.ndarray:
    return ss.freqz(B, A, worN=f_hz, fs=FS)[1]


def response_from_state(u: np.ndarray) -> np.ndarray:
    """The system's response to ``u`` from a non-zero initial state (as if running before)."""
    zi = ss.lfiltic(B, A, y=[3.0, -2.0], x=[1.0, 2.0])
    return ss.lfilter(B, A, u, zi=zi)[0]


def test_default_window_leaves_the_documented_dof() -> None:
    assert default_half_width(2) == 6
    est_dof = 2 * default_half_width(2) + 1 - 2 * 3
    assert est_dof == 2 * 3 + 1


def test_exact_on_a_polynomial_response(rng: np.random.Generator) -> None:
    """A pure gain with a record that starts from rest: G and T are polynomials, exact fit."""
    u = rng.standard_normal(2000)
    est = local_polynomial_frf(u, 2.5 * u, fs_hz=FS, input_name="u", output_names=["y"])
    np.testing.assert_allclose(est.frf[:, 0, 0], 2.5, atol=1e-9)  # round-off of 6x6 solves
    assert np.max(np.abs(est.transient)) < 1e-9


def test_unbiased_and_variance_matches_monte_carlo(rng: np.random.Generator) -> None:
    u = rng.standard_normal(L)
    y = response_from_state(u)[:, None] + SIGMA * rng.standard_normal((L, DRAWS))
    opts = LpmOptions(stride=13, f_min_hz=2.0, f_max_hz=490.0)  # non-overlapping windows
    est = local_polynomial_frf(u, y, fs_hz=FS, input_name="u",
                               output_names=[f"y{d}" for d in range(DRAWS)], options=opts)
    g, v = est.frf[:, :, 0], est.frf_variance[:, :, 0]
    g0 = truth(est.frequency_hz)
    emp = np.sum(np.abs(g - g.mean(axis=1, keepdims=True)) ** 2, axis=1) / (DRAWS - 1)
    # unbiased: sum over K lines of 2 |mean error|^2 / (emp / DRAWS) is chi2(2K); the 99.9 %
    # quantile rejects a correct estimator once in a thousand (fixed seed); the residual
    # polynomial bias at the mode (O((3.25/16)^3)) is well below the noise's std-of-mean
    z2 = 2.0 * np.abs(g.mean(axis=1) - g0) ** 2 / (emp / DRAWS)
    assert z2.sum() < st.chi2.ppf(0.999, 2 * z2.size)
    # variance within 10 %: the empirical variance over 200 draws has a 7 % relative
    # sampling std per line, 0.6 % averaged over ~150 lines; the estimate (7 dof, averaged
    # over 200 draws) adds < 0.3 %: 10 % is > 10 sigma. Without the dof correction
    # (|E|^2 / (2n+1)) the ratio would be 7/13.
    ratio = np.mean(v.mean(axis=1) / emp)
    assert abs(ratio - 1.0) < 0.10
    # noise PSD of white noise: 2 s^2 / fs; the mean over lines and draws has a relative
    # std well under 1 %: 3 % is > 5 sigma
    assert np.mean(est.output_noise_psd) == pytest.approx(2 * SIGMA**2 / FS, rel=0.03)


def test_transient_removed_far_below_welch_and_noise(rng: np.random.Generator) -> None:
    u = rng.standard_normal(L)
    y_clean = response_from_state(u)
    band = {"f_min_hz": 2.0, "f_max_hz": 490.0}
    lpm = local_polynomial_frf(u, y_clean, fs_hz=FS, input_name="u", output_names=["y"],
                               options=LpmOptions(**band))
    no_t = local_polynomial_frf(u, y_clean, fs_hz=FS, input_name="u", output_names=["y"],
                                options=LpmOptions(transient=False, **band))
    g0 = truth(lpm.frequency_hz)
    err_lpm = np.sqrt(np.mean(np.abs(lpm.frf[:, 0, 0] - g0) ** 2))
    err_no_t = np.sqrt(np.mean(np.abs(no_t.frf[:, 0, 0] - g0) ** 2))
    welch = spectral_matrix(u, y_clean, input_names=["u"], output_names=["y"],
                            window=hanning(400), fs_hz=FS)  # 0.4 s Hann, 19 segments
    fw = welch.frequency_hz
    sel = (fw >= 2.0) & (fw <= 490.0)
    err_welch = np.sqrt(np.mean(np.abs(welch.frf.values[sel, 0, 0] - truth(fw[sel])) ** 2))
    # noise-free record: the LPM is left with its degree-2 approximation error over
    # a window of 3.25 Hz on a 16 Hz-wide mode, (3.25 / (2 * 16))^3 ~ 1e-3 of the peak
    # gain; H1 with the transient's leakage and the 0.4 s window's smearing of the mode,
    # ~1e-2 of it; the same local fit without a transient term, the full leakage (~0.1):
    # more than one, resp. two, orders of magnitude (measured 70x and 900x)
    assert err_lpm < 0.05 * err_welch
    assert err_lpm < 0.01 * err_no_t
    # and far below the noise-limited std at the SNR of the Monte Carlo test
    noisy = local_polynomial_frf(u, y_clean + SIGMA * rng.standard_normal(L), fs_hz=FS,
                                 input_name="u", output_names=["y"], options=LpmOptions(**band))
    assert err_lpm < 0.1 * np.sqrt(np.mean(noisy.frf_variance))
    # the transient is exactly Y - G U on the record's DFT (the states at its start and
    # end); estimated to the polynomial's accuracy (as G: ~1e-3 relative)
    idx = np.round(lpm.frequency_hz * L / FS).astype(int)
    t_true = (np.fft.rfft(y_clean)[idx] - g0 * np.fft.rfft(u)[idx]) / np.sqrt(L)
    t_err = np.abs(lpm.transient[:, 0, 0] - t_true)
    assert np.sqrt(np.mean(t_err**2)) < 0.01 * np.sqrt(np.mean(np.abs(t_true) ** 2))


def test_stride_band_and_conversion(rng: np.random.Generator) -> None:
    u = rng.standard_normal(L)
    y = np.column_stack([response_from_state(u), 0.3 * u]) + 0.01 * rng.standard_normal((L, 2))
    every = local_polynomial_frf(u, y, fs_hz=FS, input_name="u", output_names=["a", "b"])
    some = local_polynomial_frf(u, y, fs_hz=FS, input_name="u", output_names=["a", "b"],
                                options=LpmOptions(stride=13, f_min_hz=10.0, f_max_hz=200.0))
    assert every.frequency_hz.size == L // 2 + 1
    assert some.frequency_hz[0] == 10.0 and some.frequency_hz[-1] <= 200.0
    np.testing.assert_allclose(np.diff(some.frequency_hz), 13 * FS / L)
    idx = np.round(some.frequency_hz * L / FS).astype(int)
    np.testing.assert_allclose(some.frf, every.frf[idx])  # same line, same window
    fr = some.to_frequency_response()
    assert fr.estimator == "lpm" and fr.nfft == L and fr.window_length == L
    np.testing.assert_allclose(fr.frf_variance.values, some.frf_variance)


def test_bad_input_is_named(rng: np.random.Generator) -> None:
    with pytest.raises(ValueError, match=r"data_uch\.mat: the input Uch is constant"):
        local_polynomial_frf(np.ones(100), rng.standard_normal(100), fs_hz=FS,
                             input_name="Uch", output_names=["Vph"], source="data_uch.mat")
    with pytest.raises(ValueError, match="fewer than the LPM window"):
        local_polynomial_frf(rng.standard_normal(20), rng.standard_normal(20), fs_hz=FS,
                             input_name="u", output_names=["y"])
    with pytest.raises(ValueError, match="no degree of freedom"):
        LpmOptions(half_width=2)
