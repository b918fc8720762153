"""Overlapping Allan deviation: definition, closed forms, allantools, Dask chunkings, regions."""

from __future__ import annotations

import itertools
import math

import dask.array as da
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from fsmbench.signal.allan import SLOPE_TOLERANCE, allan_deviation, allan_regions

# Sums of the same terms in another grouping: ~n*eps relative with n <= 1e4 terms.
RTOL = 1e-12


def _naive(y: np.ndarray, m: int) -> float:
    """The definition literally: all overlapping pairs of adjacent m-averages."""
    ybar = np.convolve(y, np.ones(m) / m, mode="valid")
    d = ybar[m:] - ybar[:-m]
    return math.sqrt(np.mean(d * d) / 2.0)


def test_equals_the_definition_with_default_octave_taus() -> None:
    y = np.random.default_rng(0).standard_normal(3000) + 5.0
    r = allan_deviation(y, fs_hz=50.0)
    np.testing.assert_array_equal(r.m, [1, 2, 4, 8, 16, 32, 64, 128, 256, 512])  # up to N/4
    np.testing.assert_array_equal(r.n_terms, 3000 - 2 * r.m + 1)
    np.testing.assert_allclose(r.tau_s, r.m / 50.0, rtol=0, atol=0)
    ref = [_naive(y, int(m)) for m in r.m]
    # convolve's sums and ours differ in order; the mean of 5 is removed by neither exactly.
    np.testing.assert_allclose(r.adev, ref, rtol=1e-11)


def test_equals_allantools_oadev() -> None:
    # allantools is used here ONLY as an independent reference (test extra).
    allantools = pytest.importorskip("allantools")
    rng = np.random.default_rng(1)
    y = np.cumsum(rng.standard_normal(4000)) * 1e-3 + rng.standard_normal(4000)
    taus = np.array([0.01, 0.02, 0.05, 0.13, 0.4, 1.0, 5.0, 19.0])
    r = allan_deviation(y, fs_hz=100.0, taus_s=taus)
    t_ref, adev_ref, _, n_ref = allantools.oadev(y, rate=100.0, data_type="freq", taus=taus)
    np.testing.assert_allclose(r.tau_s, t_ref, rtol=1e-15)
    np.testing.assert_array_equal(r.n_terms, n_ref)  # same N - 2m + 1 terms
    # allantools integrates to phase with one global cumsum: its rounding, ~1e-13 here.
    np.testing.assert_allclose(r.adev, adev_ref, rtol=1e-10)


@st.composite
def _chunkings(draw: st.DrawFn) -> tuple[np.ndarray, tuple[int, ...], int, np.ndarray]:
    n = draw(st.integers(2, 600))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    y = 1e-9 * rng.standard_normal(n) + 1e-12 * np.arange(n) + 0.7  # nm noise on 0.7 m
    cuts = sorted(set(draw(st.lists(st.integers(1, max(1, n - 1)), max_size=15))) - {n})
    edges = [0, *cuts, n]
    chunks = tuple(b - a for a, b in itertools.pairwise(edges))
    cell = draw(st.integers(1, 64))
    m = np.unique(draw(st.lists(st.integers(1, n // 2), min_size=1, max_size=6)))
    return y, chunks, cell, m


@settings(max_examples=40, deadline=None)
@given(_chunkings())
def test_dask_equals_numpy_for_any_chunking(
    case: tuple[np.ndarray, tuple[int, ...], int, np.ndarray],
) -> None:
    y, chunks, cell, m = case
    taus = m / 10.0
    ref = allan_deviation(y, fs_hz=10.0, taus_s=taus)
    got = allan_deviation(da.from_array(y, chunks=chunks), fs_hz=10.0, taus_s=taus,
                          task_samples=cell)
    np.testing.assert_array_equal(got.m, ref.m)
    np.testing.assert_allclose(got.adev, ref.adev, rtol=RTOL, atol=0)
    # and both are the definition. The ADEV ignores a constant offset; convolving on the
    # 0.7 m offset itself would lose eps*0.7 m against deviations down to picometres
    # (averaged nanometre noise: 2e-5 relative was seen), so the offset goes first.
    naive = [_naive(y - y[0], int(mi)) for mi in m]
    # Sums of <= 600 terms in another order, on nanometre values: ~1e-13 relative.
    np.testing.assert_allclose(ref.adev, naive, rtol=1e-9)


def test_white_noise_closed_form_within_chi_square_bounds() -> None:
    s, n = 2.0e-9, 2**16
    y = s * np.random.default_rng(2).standard_normal(n)
    r = allan_deviation(y, fs_hz=1000.0)
    for m, adev in zip(r.m[r.m <= n // 16], r.adev, strict=False):
        expected_var = s * s / m  # E[(ybar_{k+m} - ybar_k)^2] / 2 = (2 s^2/m)/2
        # Equivalent degrees of freedom of overlapping ADEV, white FM (Howe; SP 1065 Table 5),
        # N phase points = n + 1: var_hat * edf / var ~ chi2(edf). Two-sided 1e-6 bounds.
        big_n = n + 1
        edf = (3 * (big_n - 1) / (2 * m) - 2 * (big_n - 2) / big_n) * 4 * m**2 / (4 * m**2 + 5)
        lo, hi = stats.chi2.ppf([0.5e-6, 1 - 0.5e-6], edf) / edf
        assert lo < adev**2 / expected_var < hi, (m, adev**2 / expected_var, lo, hi)


def test_random_walk_closed_form_on_an_ensemble() -> None:
    # y_i = s * sum_{j<=i} w_j. B_{k+m} - B_k = sum_t c_t s w_{k+t}, c_t = min(t, 2m - t),
    # t = 1..2m-1, so E[(B_{k+m}-B_k)^2] = s^2 (2 sum_{t<m} t^2 + m^2) = s^2 m (2m^2+1)/3
    # and sigma^2 = that / (2 m^2) = s^2 (2m^2+1)/(6m)  (~ s^2 m/3; cf. SP 1065, RW FM).
    s, n, runs = 0.5, 1024, 200
    rng = np.random.default_rng(3)
    taus = np.array([1, 2, 4, 8, 16]) / 100.0
    avar = np.array([
        allan_deviation(s * np.cumsum(rng.standard_normal(n)), fs_hz=100.0, taus_s=taus).adev**2
        for _ in range(runs)
    ])
    m = np.array([1, 2, 4, 8, 16])
    expected = s * s * (2 * m**2 + 1) / (6 * m)
    # Ensemble mean vs expectation: 5 standard errors of the mean (CLT over 200 runs).
    stderr = avar.std(axis=0, ddof=1) / math.sqrt(runs)
    assert np.all(np.abs(avar.mean(axis=0) - expected) < 5 * stderr), (avar.mean(0), expected)


def test_linear_drift_is_exact() -> None:
    a, fs = 3e-9, 200.0  # 3 nm/s on top of 1.2 m
    y = 1.2 + a * np.arange(50000) / fs
    r = allan_deviation(da.from_array(y, chunks=7777), fs_hz=fs, task_samples=5000)
    # ybar_{k+m} - ybar_k = a*tau exactly in exact arithmetic; the float samples carry
    # eps*1.2 m ~ 3e-16 m rounding each, i.e. <~1e-9 relative of a*tau at tau = 5 ms.
    np.testing.assert_allclose(r.adev, a * r.tau_s / math.sqrt(2.0), rtol=1e-8)


def test_regions_of_white_noise_plus_drift() -> None:
    fs, n = 1000.0, 2**18
    rng = np.random.default_rng(4)
    y = 1e-9 * rng.standard_normal(n) + 2e-9 * np.arange(n) / fs  # 1 nm white, 2 nm/s drift
    regions = allan_regions(allan_deviation(y, fs_hz=fs, unit="m"))
    kinds = [g.noise for g in regions]
    assert kinds[0] == "white" and kinds[-1] == "drift", [g.describe() for g in regions]
    white, drift = regions[0], regions[-1]
    assert abs(white.slope + 0.5) <= SLOPE_TOLERANCE and abs(drift.slope - 1.0) <= SLOPE_TOLERANCE
    # White: sigma(1 s) = 1 nm / sqrt(1000) = 31.6 pm; drift: a/sqrt(2) = 1.41 nm at 1 s.
    # Fitted levels from a few points: 10 % covers the white estimate's scatter over ~5 taus.
    assert white.level_at_1s == pytest.approx(1e-9 / math.sqrt(fs), rel=0.1)
    assert drift.level_at_1s == pytest.approx(2e-9 / math.sqrt(2.0), rel=0.1)
    assert white.tau_start_s == pytest.approx(1e-3) and drift.tau_stop_s > 10.0
    text = white.describe()
    assert text.startswith("white noise: ") and "pm at 1 s, slope −0.5" in text
    assert "drift rate about 2" in drift.describe() and "nm per second" in drift.describe()


def test_bad_input_verdicts() -> None:
    y = np.ones(100)
    with pytest.raises(ValueError, match="needs two averages of 60 samples"):
        allan_deviation(y, fs_hz=10.0, taus_s=[6.0])
    with pytest.raises(ValueError, match="shorter than one sample"):
        allan_deviation(y, fs_hz=10.0, taus_s=[0.01])
    y[37] = np.inf
    verdict = r"'Va' contains NaN or infinite samples \(first at index 37\)"
    with pytest.raises(ValueError, match=verdict):
        allan_deviation(da.from_array(y, chunks=10), fs_hz=10.0, name="'Va'", task_samples=8)


def test_a_held_quantity_has_slope_minus_one() -> None:
    """Differences of white noise (what a loop leaves of a held quantity): sqrt(3) sigma / m."""
    from fsmbench.signal.allan import allan_regions

    rng = np.random.default_rng(11)
    w = rng.standard_normal(400_001)
    y = np.diff(w)
    res = allan_deviation(y, fs_hz=1.0, taus_s=2.0 ** np.arange(0, 10), unit="rad")
    # Each m-average is (w[k+m] - w[k]) / m, so sigma^2 = (1/2) E[(w2 - 2 w1 + w0)^2] / m^2.
    expected = np.sqrt(3.0) / res.m
    # Hundreds of thousands of overlapping terms, correlated over 2m: 5 % at m = 512.
    np.testing.assert_allclose(res.adev, expected, rtol=0.05)
    assert [r.noise for r in allan_regions(res)] == ["bounded"]
