"""Windows, MATLAB default rules, datawrap, the one-pass engine and SISO input checks."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.signal as ss

from fsmbench.signal import welch_core as welch
from fsmbench.signal.welch import (
    WelchOptions,
    cpsd,
    cross_spectral_density,
    default_nfft,
    default_noverlap,
    effective_averages,
    hamming,
    hann,
    hanning,
    mscohere,
    pwelch,
    tfestimate,
)

FS_HZ = 1e4
LENGTHS = [1, 2, 3, 4, 5, 10, 11, 255, 256, 10_000]


# ------------------------------------------------------------------ windows
@pytest.mark.parametrize("n", LENGTHS)
def test_hanning_is_matlabs_formula(n: int) -> None:
    # independent evaluation of MATLAB's documented formula, scalar math.cos
    expected = [0.5 * (1.0 - math.cos(2.0 * math.pi * k / (n + 1))) for k in range(1, n + 1)]
    w = hanning(n)
    np.testing.assert_allclose(w, expected, rtol=1e-14, atol=1e-15)  # cos rounding, few ulp
    np.testing.assert_array_equal(w, w[::-1])  # built by mirroring: exactly symmetric
    assert w.min() > 0  # no zero end-points, unlike hann


def test_hanning_documented_values_and_difference_from_scipy_hann() -> None:
    np.testing.assert_allclose(hanning(5), [0.25, 0.75, 1.0, 0.75, 0.25], atol=1e-15)  # 1 ulp
    np.testing.assert_allclose(hann(5), [0.0, 0.5, 1.0, 0.5, 0.0], atol=1e-15)  # 1 ulp
    # the seed's window is not scipy's hann
    assert not np.allclose(hanning(10_000), ss.windows.hann(10_000))


@pytest.mark.parametrize("n", LENGTHS)
def test_hann_and_hamming_match_symmetric_scipy_windows(n: int) -> None:
    # scipy's sym=True windows evaluate the same formulas in another order: few-ulp differences
    np.testing.assert_allclose(hann(n), ss.windows.hann(n, sym=True), rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(hamming(n), ss.windows.hamming(n, sym=True), rtol=1e-13, atol=1e-15)


# ------------------------------------------------------------------ MATLAB defaults
@pytest.mark.parametrize(
    ("length", "noverlap", "nfft"),
    [(1, 0, 256), (100, 50, 256), (255, 127, 256), (256, 128, 256), (257, 128, 512),
     (1000, 500, 1024), (3244, 1622, 4096), (10_000, 5000, 16384)],
)
def test_default_noverlap_and_nfft(length: int, noverlap: int, nfft: int) -> None:
    assert default_noverlap(length) == noverlap
    assert default_nfft(length) == nfft
    opts = WelchOptions.from_matlab(window=hanning(length), fs_hz=FS_HZ)
    assert (opts.noverlap, opts.nfft) == (noverlap, nfft)
    assert opts.frequencies_hz.size == nfft // 2 + 1


def test_segment_count_matches_matlab_example() -> None:
    # MathWorks answer 434104: 14600 samples, 3244-sample segments, 50 % overlap -> 8 segments
    opts = WelchOptions.from_matlab(window=3244, fs_hz=1.0)
    assert opts.n_segments(14600) == 8
    assert pwelch(np.ones(14600), window=3244, fs_hz=1.0).n_segments == 8


def test_integer_window_means_symmetric_hamming(rng: np.random.Generator) -> None:
    x = rng.standard_normal(4000)
    np.testing.assert_array_equal(
        pwelch(x, window=64, fs_hz=FS_HZ).values, pwelch(x, window=hamming(64), fs_hz=FS_HZ).values
    )


def test_odd_nfft_grid_and_doubling(rng: np.random.Generator) -> None:
    x = rng.standard_normal(3000)
    r = pwelch(x, window=np.ones(255), noverlap=0, nfft=255, fs_hz=FS_HZ)
    assert r.f_hz.size == 128  # (nfft + 1)/2
    assert r.f_hz[-1] == pytest.approx(127 * FS_HZ / 255, rel=1e-15)  # exact grid
    seg = x[:255 * r.n_segments].reshape(r.n_segments, 255)
    raw = np.mean(np.abs(np.fft.fft(seg, axis=1)) ** 2, axis=0) / (FS_HZ * 255)
    # DC single, every other bin doubled (no Nyquist bin for odd nfft); 1e-12: reordering
    np.testing.assert_allclose(r.values, np.r_[raw[0], 2 * raw[1:128]], rtol=1e-12)


def test_effective_averages_without_overlap_is_k_and_hann_50_percent() -> None:
    assert effective_averages(hanning(100), 0, 7) == 7.0
    # Harris (1978): Hann overlap correlation at 50 % is 0.167 -> n_d = K/(1 + 2(1-1/K)0.0278)
    k = 61
    rho = 1.0 / 6.0
    assert effective_averages(hanning(10_000), 5000, k) == pytest.approx(
        k / (1 + 2 * (1 - 1 / k) * rho**2), rel=1e-3  # rho(hanning(10000)) differs from 1/6 by 4e-4
    )


# ------------------------------------------------------------------ datawrap (nfft < L)
def test_nfft_shorter_than_window_wraps_segments_like_matlab(rng: np.random.Generator) -> None:
    x, y = rng.standard_normal((2, 5000))
    w, noverlap, nfft = hanning(600), 300, 256
    r = cpsd(x, y, window=w, noverlap=noverlap, nfft=nfft, fs_hz=FS_HZ)
    # Independent implementation: wrap each windowed segment modulo nfft by hand, numpy FFT
    acc = np.zeros(nfft, complex)
    for k in range(r.n_segments):
        wrapped_x, wrapped_y = np.zeros(nfft), np.zeros(nfft)
        for i in range(w.size):
            wrapped_x[i % nfft] += w[i] * x[k * 300 + i]
            wrapped_y[i % nfft] += w[i] * y[k * 300 + i]
        acc += np.fft.fft(wrapped_x) * np.conj(np.fft.fft(wrapped_y))
    two_sided = acc / (r.n_segments * FS_HZ * np.dot(w, w))
    expected = np.r_[two_sided[0], 2 * two_sided[1:128], two_sided[128]]
    np.testing.assert_allclose(r.values, expected, rtol=1e-10, atol=1e-16)  # reordering only
    assert r.nfft == 256 and r.window_length == 600


# ------------------------------------------------------------------ engine
def test_blocked_engine_equals_single_block(
    rng: np.random.Generator, monkeypatch: pytest.MonkeyPatch
) -> None:
    channels = rng.standard_normal((3, 20_000))
    opts = WelchOptions.from_matlab(window=hanning(1000), fs_hz=FS_HZ)
    whole, k = cross_spectral_density(channels, opts)
    monkeypatch.setattr(welch, "_BLOCK_BYTES", 16 * 3 * 513 * 5)  # 5 segments per block
    blocked, k2 = cross_spectral_density(channels, opts)
    assert k == k2 == 39
    np.testing.assert_allclose(blocked, whole, rtol=1e-12, atol=1e-20)  # summation order only
    np.testing.assert_array_equal(whole, np.conj(np.swapaxes(whole, 1, 2)))  # Hermitian
    assert np.all(np.diagonal(whole, axis1=1, axis2=2).imag == 0)


def test_results_are_frozen_and_read_only(rng: np.random.Generator) -> None:
    r = pwelch(rng.standard_normal(2000), window=hanning(256), fs_hz=FS_HZ)
    with pytest.raises(AttributeError):
        r.nfft = 512  # type: ignore[misc]
    with pytest.raises(ValueError, match="read-only"):
        r.values[0] = 0.0


# ------------------------------------------------------------------ bad input
def test_short_record_says_how_many_samples_for_which_window() -> None:
    with pytest.raises(ValueError, match=r"'Uch'.*9999 samples.*10000-sample window "
                                         r"\(1 s at 10000 Hz\).*at least 10000 samples"):
        pwelch(np.ones(9999), window=hanning(10_000), fs_hz=FS_HZ, x_name="Uch")


def test_mscohere_needs_two_segments() -> None:
    x = np.arange(1500.0)
    with pytest.raises(ValueError, match=r"at least 1500 samples .* for 2 segments"):
        mscohere(x[:1499], x[:1499] ** 2, window=hanning(1000), fs_hz=FS_HZ)


def test_nan_is_reported_with_count_index_and_name() -> None:
    x = np.zeros(5000)
    x[[17, 40]] = np.nan
    with pytest.raises(ValueError, match=r"'Vph' \(y\) contains 2 NaN or infinite sample\(s\) "
                                         r"\(first at index 17\)"):
        cpsd(np.ones(5000), x, window=hanning(256), fs_hz=FS_HZ, y_name="Vph")


def test_unequal_lengths_name_both_signals() -> None:
    with pytest.raises(ValueError,
                       match=r"'Uch' \(input x\) has 5000, 'Vph' \(output y\) has 4999"):
        tfestimate(np.random.default_rng(0).standard_normal(5000), np.ones(4999),
                   window=hanning(256), fs_hz=FS_HZ, x_name="Uch", y_name="Vph")


@pytest.mark.parametrize("level", [0.0, 3.0])
def test_constant_excitation_has_undefined_response(level: float) -> None:
    y = np.random.default_rng(1).standard_normal(4000)
    with pytest.raises(ValueError, match=r"'Uch' \(input x\) is constant.*undefined"):
        tfestimate(np.full(4000, level), y, window=hanning(256), fs_hz=FS_HZ, x_name="Uch")
    with pytest.raises(ValueError, match=r"'Vpv' \(y\) is constant"):
        mscohere(y, np.full(4000, level), window=hanning(256), fs_hz=FS_HZ, y_name="Vpv")


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"window": hanning(256), "noverlap": 256}, r"must satisfy 0 <= noverlap < window"),
        ({"window": hanning(256), "noverlap": -1}, r"noverlap must satisfy"),
        ({"window": np.zeros(64)}, r"window is all zeros"),
        ({"window": np.ones((4, 4))}, r"1-D array"),
        ({"window": 0}, r"window length must be >= 1"),
        ({"window": True}, r"must be an integer"),
        ({"window": hanning(256), "nfft": 0}, r"nfft must be >= 1"),
        ({"window": hanning(256), "fs_hz": 0.0}, r"fs_hz must be a positive"),
    ],
)
def test_bad_options_are_rejected(kwargs: dict, message: str) -> None:
    kw = {"fs_hz": FS_HZ} | kwargs
    with pytest.raises((ValueError, TypeError), match=message):
        pwelch(np.ones(1000), **kw)


def test_complex_and_matrix_signals_are_rejected() -> None:
    with pytest.raises(TypeError, match="complex"):
        pwelch(np.ones(1000) * 1j, window=hanning(256), fs_hz=FS_HZ)
    with pytest.raises(ValueError, match=r"1-D array of samples, got shape \(500, 2\)"):
        pwelch(np.ones((500, 2)), window=hanning(256), fs_hz=FS_HZ)
