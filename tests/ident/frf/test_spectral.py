"""Public spectral API: agreement with scipy, closed-form checks, the seed's workflow.

Statistical checks use the number of independent averages n_d that the module
reports (Welch 1967); every tolerance is derived from it or from floating-point
reordering, and says so.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.signal as ss
import scipy.stats as st

import fsmbench.ident as ident_pkg
from fsmbench.ident.frf import response as frf_mod
from fsmbench.ident.frf import spectral
from fsmbench.ident.frf.spectral import (
    combine_columns,
    cpsd,
    hanning,
    mscohere,
    pwelch,
    spectral_matrix,
    tfestimate,
)
from fsmbench.signal import welch as welch_mod

FS_HZ = 1e4


def test_public_api_is_reexported_unchanged() -> None:
    for name in spectral.__all__:
        obj = getattr(spectral, name)
        assert getattr(ident_pkg, name) is obj
        assert obj is getattr(welch_mod, name, None) or obj is getattr(frf_mod, name, None)
    assert set(spectral.__all__) <= set(ident_pkg.__all__)


# ------------------------------------------------------------------ agreement with scipy
CASES = [
    # (window, noverlap, nfft): the seed's setting scaled down, no overlap, odd nfft, zero-padding
    (hanning(1000), 500, 1024),
    (hanning(1000), 0, 1000),
    (ss.windows.hamming(255, sym=True), 100, 255),
    (ss.windows.hann(300, sym=False), 250, 4096),
]


@pytest.mark.parametrize(("window", "noverlap", "nfft"), CASES)
def test_matches_scipy_with_explicit_arguments(
    rng: np.random.Generator, window: np.ndarray, noverlap: int, nfft: int
) -> None:
    x = 0.3 + rng.standard_normal(20_000)  # non-zero mean: detrending would show at DC
    y = ss.lfilter([1.0, 0.5], [1.0, -0.7], x) + 0.2 * rng.standard_normal(x.size)
    kw = {"fs": FS_HZ, "window": window, "noverlap": noverlap, "nfft": nfft, "detrend": False,
          "scaling": "density", "return_onesided": True}
    ours = {"window": window, "noverlap": noverlap, "nfft": nfft, "fs_hz": FS_HZ}
    f, pxx = ss.welch(x, **kw)
    _, pxy = ss.csd(x, y, **kw)
    _, cxy = ss.coherence(x, y, **{k: v for k, v in kw.items() if k in
                                   ("fs", "window", "noverlap", "nfft", "detrend")})
    # rtol 1e-10: same arithmetic, only the order of floating-point sums differs
    p = pwelch(x, **ours)
    np.testing.assert_allclose(p.f_hz, f, rtol=1e-12)
    np.testing.assert_allclose(p.values, pxx, rtol=1e-10)
    # MATLAB's cpsd(x, y) averages X conj(Y): the conjugate of scipy's conj(X) Y
    np.testing.assert_allclose(cpsd(x, y, **ours).values, np.conj(pxy), rtol=1e-10)
    np.testing.assert_allclose(tfestimate(x, y, **ours).values, pxy / pxx, rtol=1e-10)
    np.testing.assert_allclose(mscohere(x, y, **ours).values, cxy, rtol=1e-10)


def test_no_detrending_unlike_scipy_default(rng: np.random.Generator) -> None:
    x = 5.0 + rng.standard_normal(8192)
    ours = pwelch(x, window=hanning(512), fs_hz=FS_HZ).values
    _, detrended = ss.welch(x, fs=FS_HZ, window=hanning(512), noverlap=256, nfft=512)
    # the mean (5) puts ~25 V^2 worth of density at DC that scipy's default removes
    assert ours[0] > 100 * detrended[0]


def test_tfestimate_is_pyx_over_pxx(rng: np.random.Generator) -> None:
    x = rng.standard_normal(10_000)
    y = ss.lfilter([0.0, 1.0, 0.3], [1.0], x)
    kw = {"window": hanning(500), "fs_hz": FS_HZ}
    pyx = cpsd(y, x, **kw).values
    np.testing.assert_allclose(cpsd(x, y, **kw).values, np.conj(pyx), rtol=1e-12)  # reordering
    np.testing.assert_allclose(
        tfestimate(x, y, **kw).values, pyx / pwelch(x, **kw).values, rtol=1e-12  # reordering
    )


# ------------------------------------------------------------------ closed-form checks
def test_parseval_sum_of_psd_is_the_windowed_mean_square_and_the_variance(
    rng: np.random.Generator,
) -> None:
    sigma, length, noverlap = 0.8, 512, 256
    x = sigma * rng.standard_normal(100_000)
    r = pwelch(x, window=hanning(length), noverlap=noverlap, fs_hz=FS_HZ)
    total = r.values.sum() * FS_HZ / r.nfft  # sum(PSD) * df, V^2
    # Exact identity (DFT Parseval, nfft >= L): sum PSD df = sum_t c_t x_t^2 with
    # c_t = sum over segments covering t of w^2 / (K sum w^2).
    w2 = hanning(length) ** 2
    c = np.zeros(x.size)
    for k in range(r.n_segments):
        c[k * (length - noverlap) : k * (length - noverlap) + length] += w2
    c /= r.n_segments * w2.sum()
    np.testing.assert_allclose(total, np.dot(c, x**2), rtol=1e-12)  # reordering only
    # Statistical: E = sigma^2 and, for Gaussian x, Var = 2 sigma^4 sum c_t^2.
    sd = np.sqrt(2.0 * sigma**4 * np.dot(c, c))
    assert abs(total - sigma**2) < 4.5 * sd  # 4.5 sd: false alarm < 1e-5


def test_white_noise_level_and_chi_square_spread(rng: np.random.Generator) -> None:
    sigma = 0.7
    r = pwelch(sigma * rng.standard_normal(2**20), window=hanning(1024), fs_hz=FS_HZ)
    expected = 2.0 * sigma**2 / FS_HZ  # one-sided white PSD, V^2/Hz
    ratio = r.values[1:-1] / expected  # DC/Nyquist are not doubled: different law
    n_d = r.effective_averages
    independent = ratio[::4]  # Hann leakage correlates bins only within +-2
    # mean of n independent chi^2_{2 n_d}/(2 n_d): sd 1/sqrt(n n_d); 4.5 sd
    assert abs(independent.mean() - 1.0) < 4.5 / np.sqrt(independent.size * n_d)
    lo, hi = st.chi2.ppf([0.005, 0.995], 2 * n_d) / (2 * n_d)
    inside = np.mean((ratio > lo) & (ratio < hi))
    # 99 % interval over 511 bins; neighbours correlate, so allow 2 points of scatter (~4 sd)
    assert inside >= 0.97
    assert ratio.max() < 1.5  # 1.5 is ~15 sd of the chi^2 spread (n_d ~ 1940): scale errors show


def test_welch_effective_averages_predict_the_variance_at_75_percent_overlap(
    rng: np.random.Generator,
) -> None:
    # 75 % overlap: Welch's n_d ~ K/1.92; using K would halve the predicted variance.
    results = [
        pwelch(rng.standard_normal(8192), window=hanning(256), noverlap=192, fs_hz=1.0)
        for _ in range(300)
    ]
    runs = np.array([r.values for r in results]) / 2.0  # unit white noise at 1 Hz: PSD = 2
    variance = runs[:, 4:-4:4].var(axis=0, ddof=1).mean()  # every 4th bin: independent
    r = results[0]
    # 300 runs x 30 bins: relative sd of the pooled variance ~1.5 %; 0.1 is ~6 sd
    assert variance * r.effective_averages == pytest.approx(1.0, abs=0.1)
    assert variance * r.n_segments > 1.5  # naive K would be wrong by ~1.9x


def test_filtered_white_noise_follows_the_filter(
    rng: np.random.Generator, digital_filter: tuple[str, np.ndarray, np.ndarray]
) -> None:
    _, b, a = digital_filter
    sigma = 0.5
    y = ss.lfilter(b, a, sigma * rng.standard_normal(2**18 + 2000))[2000:]  # drop transient
    r = pwelch(y, window=hanning(1024), fs_hz=FS_HZ)
    _, h = ss.freqz(b, a, worN=r.f_hz, fs=FS_HZ)
    expected = sigma**2 * np.abs(h) ** 2 * 2.0 / FS_HZ
    ratio = r.values[1:-1] / expected[1:-1]
    n_d = r.effective_averages
    independent = ratio[::4]
    # window bias (B&P: (Be/Br)^2/3 < 1 % at the resonance) is far below the 4.5 sd random bound
    assert abs(independent.mean() - 1.0) < 4.5 / np.sqrt(independent.size * n_d)
    lo, hi = st.chi2.ppf([0.005, 0.995], 2 * n_d) / (2 * n_d)
    assert np.mean((ratio > lo) & (ratio < hi)) >= 0.97  # 99 % chi-square interval, as above


def test_tfestimate_recovers_a_filter_within_its_confidence_bounds(
    rng: np.random.Generator, digital_filter: tuple[str, np.ndarray, np.ndarray]
) -> None:
    _, b, a = digital_filter
    x = rng.standard_normal(2**17 + 2000)
    y = ss.lfilter(b, a, x)[2000:] + 0.05 * rng.standard_normal(2**17)
    x = x[2000:]
    coverage = {}
    for level in (0.95, 0.99):
        r = spectral_matrix(x, y, input_names=["u"], output_names=["y"], window=hanning(1024),
                            fs_hz=FS_HZ, confidence=level)
        np.testing.assert_allclose(  # the one-pass FRF is tfestimate, to reordering
            r.frf.values[:, 0, 0],
            tfestimate(x, y, window=hanning(1024), fs_hz=FS_HZ).values, rtol=1e-12,
        )
        _, h = ss.freqz(b, a, worN=r.frequency_hz, fs=FS_HZ)
        sl = slice(1, -1)  # DC and Nyquist estimates are real: phase law differs
        lo, hi = r.magnitude_lower.values[sl, 0, 0], r.magnitude_upper.values[sl, 0, 0]
        half = (r.phase_upper_rad.values[sl, 0, 0] - r.phase_lower_rad.values[sl, 0, 0]) / 2
        mag_ok = (np.abs(h[sl]) >= lo) & (np.abs(h[sl]) <= hi)
        phase_ok = np.abs(np.angle(h[sl] / r.frf.values[sl, 0, 0])) <= half
        coverage[level] = (mag_ok.mean(), phase_ok.mean())
    assert min(coverage[0.99]) >= 0.95  # the brief: >= 95 % of frequencies
    # calibration: 95 % bounds cover 95 % +- 3.5 binomial sd (~250 independent bins);
    # a sqrt(2) error in eps would give ~99.4 %, half of it ~68 %
    assert all(0.90 <= c <= 0.99 for c in coverage[0.95])


def test_pure_delay_gives_a_negative_linear_phase(rng: np.random.Generator) -> None:
    d = 5
    s = rng.standard_normal(2**17 + d)
    x, y = s[d:], s[:-d]  # y[n] = x[n - d]
    t = tfestimate(x, y, window=hanning(1024), fs_hz=FS_HZ)
    slope = np.polyfit(t.f_hz, np.unwrap(np.angle(t.values)), 1)[0]
    assert slope < 0
    # rtol 1e-4: only the d/L = 0.5 % of each segment not shared by x and y perturbs it
    assert slope == pytest.approx(-2 * np.pi * d / FS_HZ, rel=1e-4)
    residual = np.angle(t.values * np.exp(2j * np.pi * t.f_hz * d / FS_HZ))
    assert np.abs(residual).max() < 0.02  # B&P eps for that 0.5 % ~ 0.005 rad; 4 sd


def test_coherence_of_independent_noises_is_one_over_n_d(rng: np.random.Generator) -> None:
    a, b = rng.standard_normal((2, 2**19))
    c = mscohere(a, b, window=hanning(2048), fs_hz=FS_HZ)
    # E[coh] = 1/n_d (Carter et al. 1973); mean over ~1000 bins has ~4.5 % relative sd
    assert c.values[1:-1].mean() * c.effective_averages == pytest.approx(1.0, abs=0.2)


def test_coherence_of_noiseless_lti_output(rng: np.random.Generator) -> None:
    x = rng.standard_normal(2**16)
    kw = {"window": hanning(1024), "fs_hz": FS_HZ}
    # A static gain is the only LTI map whose segments are exactly proportional:
    # coherence 1 up to rounding (1e-12 ~ 1e4 ulp of accumulated sums).
    np.testing.assert_allclose(mscohere(x, -2.5 * x, **kw).values, 1.0, atol=1e-12)
    # A 3-tap FIR leaks 2 samples per 1024-sample segment: coherence >= 1 - 1e-4
    assert mscohere(x, ss.lfilter([1.0, 0.5, 0.25], [1.0], x), **kw).values.min() > 1 - 1e-4


# ------------------------------------------------------------------ the seed's workflow
def test_seed_workflow_builds_the_named_2x2_matrix(
    esrf_experiments: dict, resonance_ba: tuple[np.ndarray, np.ndarray]
) -> None:
    win = hanning(int(np.ceil(1 * FS_HZ)))  # win = hanning(ceil(1*fs))
    responses = [
        spectral_matrix(e.inputs, e.outputs, input_names=[e.input_name],
                        output_names=["Vph", "Vpv"], window=win, fs_hz=FS_HZ)
        for e in esrf_experiments.values()
    ]
    g = combine_columns(responses)
    assert g.frf.dims == ("frequency", "output", "input")
    assert g.output_names == ("Vph", "Vpv") and g.input_names == ("Uch", "Ucv")
    assert (g.nfft, g.noverlap, g.window_length) == (16384, 5000, 10000)
    assert g.frequency_hz[1] == pytest.approx(FS_HZ / 16384, rel=1e-15)  # exact grid
    e = esrf_experiments["Ucv"]
    np.testing.assert_allclose(  # column Ucv, row Vpv is MATLAB's tfestimate(uv.Ucv, uv.Vpv)
        g.frf.sel(output="Vpv", input="Ucv").values,
        tfestimate(e.inputs[:, 0], e.outputs[:, 1], window=win, fs_hz=FS_HZ).values,
        rtol=1e-12,  # reordering only
    )
    _, h = ss.freqz(*resonance_ba, worN=g.frequency_hz, fs=FS_HZ)
    gains = {("Vph", "Uch"): 1.0, ("Vpv", "Uch"): 0.2, ("Vph", "Ucv"): 0.1, ("Vpv", "Ucv"): 0.8}
    for (out, inp), gain in gains.items():
        true = np.abs(gain * h[1:-1])
        lo = g.magnitude_lower.sel(output=out, input=inp).values[1:-1]
        hi = g.magnitude_upper.sel(output=out, input=inp).values[1:-1]
        assert np.mean((true >= lo) & (true <= hi)) >= 0.9  # 95 % bounds; margin for ~8000 bins
    summary = json.loads(g.to_json())
    assert summary["n_segments"] == {"Uch": 11, "Ucv": 11}
