"""Min/max/mean envelope: exact against a naive loop, identical on NumPy and Dask."""

from __future__ import annotations

import itertools

import dask.array as da
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fsmbench.signal.envelope import minmax_envelope


def _naive(x: np.ndarray, n_bins: int) -> tuple[np.ndarray, ...]:
    n = x.size
    edges = [b * n // n_bins for b in range(n_bins + 1)]
    parts = [x[a:b] for a, b in itertools.pairwise(edges)]
    return (
        np.array(edges),
        np.array([p.min() for p in parts]),
        np.array([p.max() for p in parts]),
        np.array([p.mean() for p in parts]),
    )


def test_equals_a_naive_loop() -> None:
    x = np.random.default_rng(0).standard_normal(10007)
    env = minmax_envelope(x, fs_hz=100.0, n_bins=37, t0_s=2.0)
    edges, lo, hi, mean = _naive(x, 37)
    np.testing.assert_array_equal(env.minimum, lo)  # min and max are exact
    np.testing.assert_array_equal(env.maximum, hi)
    # reduceat sums in another order than mean()'s pairwise sum: ~n*eps with n <= 271.
    np.testing.assert_allclose(env.mean, mean, rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(env.samples_per_bin, np.diff(edges))
    assert set(env.samples_per_bin) == {270, 271} and env.samples_per_bin.sum() == 10007
    np.testing.assert_allclose(env.t_edges_s, 2.0 + edges / 100.0, rtol=1e-15)
    # centre of bin b = mean of its sample times
    centres = [np.mean(2.0 + np.arange(a, b) / 100.0) for a, b in itertools.pairwise(edges)]
    np.testing.assert_allclose(env.t_s, centres, rtol=1e-14)


@st.composite
def _cases(draw: st.DrawFn) -> tuple[np.ndarray, tuple[int, ...], int, int]:
    n = draw(st.integers(1, 3000))
    x = np.random.default_rng(draw(st.integers(0, 2**32 - 1))).standard_normal(n)
    if draw(st.booleans()) and n <= 500:
        chunks = (1,) * n
    else:
        cuts = sorted(set(draw(st.lists(st.integers(1, max(1, n - 1)), max_size=20))) - {n})
        edges = [0, *cuts, n]
        chunks = tuple(b - a for a, b in itertools.pairwise(edges))
    n_bins = draw(st.integers(1, n))
    per_task = draw(st.integers(1, n + 5))
    return x, chunks, n_bins, per_task


@settings(max_examples=40, deadline=None)
@given(_cases())
def test_dask_equals_numpy_for_any_chunking(
    case: tuple[np.ndarray, tuple[int, ...], int, int],
) -> None:
    x, chunks, n_bins, per_task = case
    ref = minmax_envelope(x, fs_hz=10.0, n_bins=n_bins)
    got = minmax_envelope(da.from_array(x, chunks=chunks), fs_hz=10.0, n_bins=n_bins,
                          task_samples=per_task)
    # Each bin is reduced whole in both, so all three statistics are bit for bit equal.
    for field in ("minimum", "maximum", "mean", "t_s", "samples_per_bin"):
        np.testing.assert_array_equal(getattr(got, field), getattr(ref, field))
    _, lo, hi, _ = _naive(x, n_bins)
    np.testing.assert_array_equal(got.minimum, lo)
    np.testing.assert_array_equal(got.maximum, hi)


def test_bad_bin_count_is_a_one_line_verdict() -> None:
    with pytest.raises(ValueError, match="'Va': n_bins must be between 1 and the number"):
        minmax_envelope(np.zeros(10), fs_hz=1.0, n_bins=11, name="'Va'")
