"""Streaming Welch estimators of the live bench against the batch functions and closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import signal

from fsmbench.live.spectra import AccumulatingFrf, RollingAsd
from fsmbench.signal.welch import effective_averages, hanning, mscohere, pwelch, tfestimate

FS = 100.0  # small records keep the property tests fast; the code has no rate of its own


def _split(n: int, lengths: list[int]) -> list[slice]:
    """Cut ``range(n)`` into consecutive slices of the given lengths (cycled), the last shorter."""
    out, start, i = [], 0, 0
    while start < n:
        step = lengths[i % len(lengths)]
        out.append(slice(start, min(start + step, n)))
        start += step
        i += 1
    return out


BLOCKS = st.lists(st.integers(1, 400), min_size=1, max_size=8)


# --------------------------------------------------------------------------- RollingAsd
@settings(max_examples=40, deadline=None)
@given(n=st.integers(0, 900), lengths=BLOCKS, seed=st.integers(0, 2**32 - 1),
       window_s=st.sampled_from([0.5, 0.37, 1.0]), span_s=st.sampled_from([2.0, 3.33]))
def test_rolling_asd_equals_batch_pwelch_of_the_last_span(n: int, lengths: list[int], seed: int,
                                                          window_s: float, span_s: float) -> None:
    x = np.random.default_rng(seed).standard_normal((n, 2)) * [1.0, 1e-6]
    asd = RollingAsd(fs_hz=FS, channels=["a", "b"], window_s=window_s, span_s=span_s)
    for sl in _split(n, lengths):
        asd.push(x[sl])
    snap = asd.spectrum()
    length, keep = math.ceil(window_s * FS), round(span_s * FS)
    assert asd.n_samples_pushed == n
    if n < length:
        assert snap is None
        return
    assert snap is not None
    last = x[-min(n, keep):]
    assert snap.n_samples_used == last.shape[0]
    assert snap.span_s == pytest.approx(last.shape[0] / FS, rel=1e-15)  # one division
    for i in range(2):
        ref = pwelch(last[:, i], window=hanning(length), fs_hz=FS)
        np.testing.assert_array_equal(snap.frequency_hz, ref.f_hz)
        # The bound asked for is 1e-12 relative; the same pwelch runs on the same samples,
        # so the result is bit-identical, which is stronger.
        np.testing.assert_array_equal(snap.asd[i], np.sqrt(ref.values))
        assert snap.n_segments == ref.n_segments


def test_rolling_asd_one_sample_blocks_and_wraparound() -> None:
    """Blocks of one sample, more than one span: the oldest samples fall out in order."""
    x = np.random.default_rng(3).standard_normal((517, 1))
    asd = RollingAsd(fs_hz=FS, channels=["Va"], window_s=0.5, span_s=2.0)
    for row in x:
        asd.push(row[None, :])
    snap = asd.spectrum()
    assert snap is not None and snap.n_samples_used == 200
    np.testing.assert_array_equal(asd.samples(), x[-200:].T)
    ref = pwelch(x[-200:, 0], window=hanning(50), fs_hz=FS)
    np.testing.assert_array_equal(snap.asd[0], np.sqrt(ref.values))  # same pwelch, same samples
    asd.reset()
    assert asd.spectrum() is None and asd.n_samples_pushed == 0
    asd.push(x[:, 0])  # a 1-D block is accepted for a single channel
    np.testing.assert_array_equal(asd.samples(), x[-200:].T)


def test_rolling_asd_of_white_noise_is_rms_over_sqrt_half_fs() -> None:
    """One-sided PSD of white noise of rms s is s^2 / (fs/2): ASD s / sqrt(fs/2)."""
    fs, rms = 10_000.0, (0.3, 2e-3, 7.0)
    x = np.random.default_rng(11).standard_normal((150_000, 3)) * rms
    asd = RollingAsd(fs_hz=fs, channels=["Vph", "Vpv", "Va"])  # the device's configuration
    for sl in _split(x.shape[0], [100]):
        asd.push(x[sl])
    snap = asd.spectrum()
    assert snap is not None
    assert snap.n_samples_used == 100_000 and snap.span_s == 10.0  # 10 s of 10 kHz
    assert snap.frequency_hz[1] == pytest.approx(fs / 16384, rel=1e-15)  # MATLAB's default nfft
    # Mean of the PSD over the bins (DC and Nyquist excluded, they are not doubled). Each
    # bin is a chi^2 estimate with ~n_d = 19/1.056 averages, and Hann's 1.5-bin noise
    # bandwidth (bins of fs/L) leaves ~ L/3 independent bins below fs/2:
    # relative std of the mean ~ 1/sqrt(n_d L/3) = 0.4 %; 5 sigma allowed.
    n_d, length = 19 / 1.056, 10_000
    tol = 5.0 / math.sqrt(n_d * length / 3.0)
    mean_psd = np.mean(snap.asd[:, 1:-1] ** 2, axis=1)
    expected = (np.array(rms) / math.sqrt(fs / 2.0)) ** 2
    np.testing.assert_allclose(mean_psd, expected, rtol=tol)


def test_rolling_asd_refuses_bad_input() -> None:
    asd = RollingAsd(fs_hz=FS, channels=["Vph", "Vpv"], window_s=0.5, span_s=2.0)
    block = np.ones((10, 2))
    block[4, 1] = np.nan
    with pytest.raises(ValueError, match=r"'Vpv' has 1 NaN .* index 4"):
        asd.push(block)
    assert asd.n_samples_pushed == 0  # the bad block was not used
    with pytest.raises(ValueError, match=r"shape \(n, 2\).*got shape \(10, 3\)"):
        asd.push(np.ones((10, 3)))
    with pytest.raises(ValueError, match="shorter than one Welch segment"):
        RollingAsd(fs_hz=FS, channels=["a"], window_s=1.0, span_s=0.5)
    with pytest.raises(ValueError, match="repeated"):
        RollingAsd(fs_hz=FS, channels=["a", "a"])


# --------------------------------------------------------------------------- AccumulatingFrf
def _frf_data(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    y = np.column_stack([signal.lfilter([0.2, 0.5, 0.1], [1.0, -0.6], u),
                         rng.standard_normal(n) * 3.0 + np.roll(u, 2)])
    return u, y


@settings(max_examples=40, deadline=None)
@given(n=st.integers(0, 1200), lengths=BLOCKS, seed=st.integers(0, 2**32 - 1),
       window_s=st.sampled_from([0.32, 0.5, 1.01]), overlap=st.sampled_from([0.5, 0.0, 0.75]))
def test_accumulating_frf_equals_batch_tfestimate_and_mscohere(
        n: int, lengths: list[int], seed: int, window_s: float, overlap: float) -> None:
    u, y = _frf_data(n, seed)
    frf = AccumulatingFrf(fs_hz=FS, input_name="Uch", output_names=["Vph", "Vpv"],
                          window_s=window_s, overlap=overlap)
    for sl in _split(n, lengths):
        frf.push(u[sl], y[sl])
    length = math.ceil(window_s * FS)
    noverlap = math.floor(overlap * length)
    hop = length - noverlap
    k = max(0, (n - noverlap) // hop)  # MATLAB's segment count on the whole record
    assert frf.n_segments == k and frf.n_samples_pushed == n
    res = frf.result()
    if k < 2:
        assert res is None
        return
    assert res is not None
    assert res.n_samples == (k - 1) * hop + length
    m = res.n_samples
    for i in range(2):
        h = tfestimate(u[:m], y[:m, i], window=hanning(length), noverlap=noverlap, fs_hz=FS)
        c = mscohere(u[:m], y[:m, i], window=hanning(length), noverlap=noverlap, fs_hz=FS)
        assert h.n_segments == k
        np.testing.assert_array_equal(res.frequency_hz, h.f_hz)
        # Same segments and FFTs; only the order of the per-segment sums and the
        # cancelled density scale differ: rounding, amplified where |Pyx| is small by
        # cancellation among the segments' terms (~1e-15 seen, 1e-9 asked).
        np.testing.assert_allclose(res.h1[i], h.values, rtol=1e-9, atol=0)
        np.testing.assert_allclose(res.coherence[i], c.values, rtol=1e-9, atol=0)  # as above


def test_accumulating_frf_one_sample_blocks_and_reset() -> None:
    u, y = _frf_data(700, 5)
    frf = AccumulatingFrf(fs_hz=FS, input_name="Uch", output_names=["Vph", "Vpv"],
                          window_s=0.64)
    for i in range(u.size):
        frf.push(u[i:i + 1], y[i:i + 1])
    res = frf.result()
    assert res is not None and res.n_segments == (700 - 32) // 32
    h = tfestimate(u[:res.n_samples], y[:res.n_samples, 1], window=hanning(64), fs_hz=FS)
    np.testing.assert_allclose(res.h1[1], h.values, rtol=1e-9, atol=0)  # as in the test above
    frf.reset()
    assert frf.result() is None and frf.n_segments == 0 and frf.n_samples_pushed == 0
    frf.push(u, y)  # one block after the reset: the same numbers as the batch functions
    again = frf.result()
    assert again is not None and again.n_samples == res.n_samples
    np.testing.assert_allclose(again.h1, res.h1, rtol=1e-9, atol=0)  # as above


def test_accumulating_frf_converges_to_a_known_fir() -> None:
    """White noise through FIR filters (one with a 2-sample delay): H1 -> B(exp(j w / fs)).

    Noise-free outputs. Per segment ``Y = B X + R`` where ``R`` comes from the
    filter's memory at the window: ``R(w) = sum_m a(m) u(m) exp(-j w m)``,
    ``a(m) = sum_k b_k exp(-j w k) (w[m + k] - w[m])``, so for white ``u`` of variance
    ``s^2``: ``E|R|^2 = s^2 sum |a|^2`` and ``E|X|^2 = s^2 sum w^2``. Averaged over
    ``n_d`` (Welch's equivalent) segments, ``H1 - B`` is a zero-mean error of rms
    ``sigma = sqrt(sum|a|^2 / sum w^2 / n_d)`` plus the bias
    ``sum_k b_k exp(-j w k) (rho_k - 1)`` (``rho_k`` the window's autocorrelation),
    and ``1 - coherence`` has the mean ``sum|a|^2 / (|B|^2 sum w^2)``.
    """
    fs, n, length = 1000.0, 240_000, 1000
    firs = [np.array([0.5, 0.3, 0.2]), np.array([0.0, 0.0, 1.0, 0.4])]
    rng = np.random.default_rng(2)
    u = rng.standard_normal(n)
    y = np.column_stack([signal.lfilter(b, 1.0, u) for b in firs])
    frf = AccumulatingFrf(fs_hz=fs, input_name="Uch", output_names=["y1", "y2"])
    for sl in _split(n, [333, 1, 4096]):
        frf.push(u[sl], y[sl])
    res = frf.result()
    assert res is not None and res.n_segments == 479
    w = hanning(length)
    energy = float(np.dot(w, w))
    n_d = effective_averages(w, length // 2, res.n_segments)
    z = np.exp(-2j * np.pi * res.frequency_hz / fs)
    for i, b in enumerate(firs):
        k = np.arange(b.size)
        shifted = np.stack([np.concatenate([w[j:], np.zeros(j)]) - w for j in k])  # w[m+k] - w[m]
        taps = b[None, :] * z[:, None] ** k[None, :]  # (F, k): b_k exp(-j w k)
        h = taps.sum(axis=1)
        np.testing.assert_allclose(h, signal.freqz(b, 1.0, worN=res.frequency_hz, fs=fs)[1],
                                   rtol=1e-12)  # the same polynomial, two evaluations
        a2 = np.sum(np.abs(taps @ shifted) ** 2, axis=1)  # sum_m |a(m)|^2 per bin
        rho = np.array([np.dot(w[:length - j], w[j:]) / energy for j in k])
        bias = np.abs(taps @ (rho - 1.0))
        sigma = np.sqrt(a2 / energy / n_d)
        # A complex Gaussian error exceeds c sigma with probability exp(-c^2): 4.5 sigma
        # is 1.6e-9 per bin, 1e-6 over the 501 bins (2.7 sigma is the worst seen).
        err = np.abs(res.h1[i] - h)
        assert np.all(err <= bias + 4.5 * sigma), f"output {i}: {np.max(err / sigma):.3g} sigma"
        ratio = (1.0 - res.coherence[i]) / (a2 / energy / np.abs(h) ** 2)
        # Each bin averages the residual power over n_d ~ 450 segments: ~5 % rms (6.5 %
        # seen, bins are not independent); the mean over 501 bins is within 1.5 %, the
        # worst bin (1.29 seen) within 1.5, i.e. ~7 of those rms.
        assert abs(np.mean(ratio) - 1.0) < 0.015
        assert np.all(ratio < 1.5)


def test_accumulating_frf_refuses_bad_input() -> None:
    frf = AccumulatingFrf(fs_hz=FS, input_name="Uch", output_names=["Vph"], window_s=0.5)
    with pytest.raises(ValueError, match=r"'Vph' has 1 NaN .* index 3"):
        frf.push(np.zeros(5), np.array([0.0, 1.0, 2.0, np.inf, 4.0]))
    assert frf.n_samples_pushed == 0
    with pytest.raises(ValueError, match=r"y of shape \(n, 1\).*got \(5,\) and \(4, 1\)"):
        frf.push(np.zeros(5), np.zeros((4, 1)))
    frf.push(np.full(300, 2.0), np.random.default_rng(0).standard_normal(300))
    with pytest.raises(ValueError, match=r"'Uch' is constant \(2 for all 300 samples"):
        frf.result()
    with pytest.raises(ValueError, match=r"overlap must be a fraction in \[0, 1\)"):
        AccumulatingFrf(fs_hz=FS, input_name="Uch", output_names=["Vph"], overlap=1.0)
