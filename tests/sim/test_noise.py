"""Noise generators: statistics against their closed forms, and reproducibility."""

from __future__ import annotations

import numpy as np
import pytest

from fsmbench.sim.noise import first_order_lag, gauss_markov, source_rng, white_noise


def test_sources_are_reproducible_and_independent() -> None:
    a = white_noise(source_rng(7, "data_uch", "qd_h"), 1000, rms=1.0)
    b = white_noise(source_rng(7, "data_uch", "qd_h"), 1000, rms=1.0)
    c = white_noise(source_rng(7, "data_uch", "qd_v"), 1000, rms=1.0)
    d = white_noise(source_rng(8, "data_uch", "qd_h"), 1000, rms=1.0)
    np.testing.assert_array_equal(a, b)
    # Independent unit normals: |correlation| < 4/sqrt(n) with overwhelming probability.
    assert abs(np.corrcoef(a, c)[0, 1]) < 4 / np.sqrt(1000)
    assert abs(np.corrcoef(a, d)[0, 1]) < 4 / np.sqrt(1000)


def test_white_noise_rms() -> None:
    x = white_noise(source_rng(1, "e", "s"), 200_000, rms=3e-6)
    # Sample std of n normals: relative standard error 1/sqrt(2n) = 0.16 %; 5 sigma.
    assert np.std(x) == pytest.approx(3e-6, rel=5 / np.sqrt(2 * 200_000))
    assert not np.any(white_noise(source_rng(1, "e", "s"), 10, rms=0.0))


def test_gauss_markov_is_stationary_with_exponential_correlation() -> None:
    fs, tau, rms = 1000.0, 0.05, 2.0
    n = 400_000
    x = gauss_markov(source_rng(3, "e", "gm"), n, rms=rms, tau_s=tau, fs_hz=fs)
    # Effective number of independent samples ~ T / (2 tau) = 4000: std error ~1.1 %, allow 5 %.
    assert np.std(x) == pytest.approx(rms, rel=0.05)
    lag = int(tau * fs)
    rho = np.mean(x[:-lag] * x[lag:]) / np.var(x)
    # Exact autocorrelation e^{-1} at one correlation time; estimate std ~ 1/sqrt(4000).
    assert rho == pytest.approx(np.exp(-1.0), abs=0.05)
    # Stationary from the first sample: across many short runs x[0] has std rms.
    starts = [gauss_markov(source_rng(i, "e", "gm"), 2, rms=rms, tau_s=tau, fs_hz=fs)[0]
              for i in range(2000)]
    assert np.std(starts) == pytest.approx(rms, rel=0.1)  # 2000 samples: 1.6 % std error


def test_first_order_lag_step_response() -> None:
    fs, tau = 100.0, 0.5
    x = np.concatenate([np.zeros(5), np.ones(200)])
    y = first_order_lag(x, tau_s=tau, fs_hz=fs)
    k = np.arange(200)
    # Step-invariant discretisation: exact at the samples after the step.
    np.testing.assert_allclose(y[5:], 1 - np.exp(-k / (fs * tau)), atol=1e-12)
    steady = first_order_lag(np.full(10, 4.0), tau_s=tau, fs_hz=fs)
    np.testing.assert_allclose(steady, 4.0)


def test_gauss_markov_rejects_bad_tau() -> None:
    with pytest.raises(ValueError, match="tau_s"):
        gauss_markov(source_rng(1, "e", "s"), 10, rms=1.0, tau_s=0.0, fs_hz=1.0)
