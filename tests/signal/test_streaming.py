"""Estimators fed block by block equal the in-memory ones, whatever the blocks."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fsmbench.budget.signals import block_means
from fsmbench.filters import first_order_lowpass
from fsmbench.signal.envelope import minmax_envelope
from fsmbench.signal.streaming import (
    BlockMeanStream,
    EnvelopeStream,
    LowpassStream,
    SumStream,
    WelchStream,
    read_blocks,
)
from fsmbench.signal.welch import WelchOptions, hanning, pwelch

FS = 1000.0
# Same samples and arithmetic, sums grouped differently: rounding only (1e-12 relative).
RTOL = 1e-12


def _record(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    # An offset, a drift and noise: the shapes of a huddle test's Va.
    return 3.0 + 1e-3 * np.linspace(0, 1, n) + 1e-4 * rng.standard_normal(n)


def _blocks(x: np.ndarray, block: int) -> list[np.ndarray]:
    return [b["x"] for _, b in read_blocks({"x": x}, start=0, stop=x.size, block_samples=block)]


@settings(max_examples=25, deadline=None)
@given(n=st.integers(300, 5000), block=st.integers(1, 3000), win=st.integers(16, 300),
       seed=st.integers(0, 100))
def test_welch_stream_equals_pwelch(n: int, block: int, win: int, seed: int) -> None:
    x = _record(n, seed)
    if n < win:
        return
    window = hanning(win)
    ref = pwelch(x, window=window, fs_hz=FS)
    stream = WelchStream(options=WelchOptions.from_matlab(window=window, noverlap=None, nfft=None,
                                                          fs_hz=FS), n_samples=n, name="x")
    for part in _blocks(x, block):
        stream.update(part)
    got = stream.result()
    assert got.n_segments == ref.n_segments
    assert got.effective_averages == ref.effective_averages
    np.testing.assert_allclose(got.values, ref.values, rtol=RTOL, atol=0)


def test_welch_stream_refuses_a_short_read() -> None:
    x = _record(2000, 1)
    stream = WelchStream(options=WelchOptions.from_matlab(window=hanning(100), noverlap=None,
                                                          nfft=None, fs_hz=FS),
                         n_samples=x.size, name="Va")
    stream.update(x[:1000])
    with pytest.raises(ValueError, match=r"Va: .* of .* Welch segments were read"):
        stream.result()


@settings(max_examples=25, deadline=None)
@given(n=st.integers(1, 4000), bins_frac=st.floats(0.0, 1.0), block=st.integers(1, 2000),
       seed=st.integers(0, 100))
def test_envelope_stream_equals_minmax_envelope(n: int, bins_frac: float, block: int,
                                                seed: int) -> None:
    x = _record(n, seed)
    bins = max(1, min(n, round(bins_frac * n)))
    ref = minmax_envelope(x, fs_hz=FS, n_bins=bins)
    stream = EnvelopeStream(n_samples=n, n_bins=bins, fs_hz=FS)
    for part in _blocks(x, block):
        stream.update(part)
    got = stream.result()
    # Extremes are exact; means differ by the grouping of sums.
    np.testing.assert_array_equal(got.minimum, ref.minimum)
    np.testing.assert_array_equal(got.maximum, ref.maximum)
    np.testing.assert_allclose(got.mean, ref.mean, rtol=RTOL)
    np.testing.assert_array_equal(got.t_s, ref.t_s)
    np.testing.assert_array_equal(got.samples_per_bin, ref.samples_per_bin)


@settings(max_examples=25, deadline=None)
@given(n=st.integers(1, 5000), per=st.integers(1, 700), block=st.integers(1, 2000),
       seed=st.integers(0, 100))
def test_block_mean_and_lowpass_streams(n: int, per: int, block: int, seed: int) -> None:
    x = _record(n, seed)
    means = BlockMeanStream(per=per)
    low = LowpassStream(cutoff_hz=50.0, fs_hz=FS)
    sums = SumStream(shift=3.0)
    y = []
    for part in _blocks(x, block):
        means.update(part)
        y.append(low.filter(part))
        sums.update(part)
    # Each mean is taken over the same contiguous samples as in memory: bit for bit.
    np.testing.assert_array_equal(means.result(), block_means(x, per=per))
    # The filter state handed over between blocks: the recursion of one whole run.
    np.testing.assert_allclose(np.concatenate(y), first_order_lowpass(x, cutoff_hz=50.0,
                                                                       fs_hz=FS), rtol=RTOL)
    assert sums.mean == pytest.approx(float(np.mean(x)), rel=RTOL)
    assert sums.rms_about_mean == pytest.approx(float(np.std(x)), rel=1e-9)  # 1e-4 noise on a
    # 3.0 offset: the shift keeps the squares well conditioned, 1e-9 covers their rounding


def test_read_blocks_reads_dask_and_numpy_alike() -> None:
    da = pytest.importorskip("dask.array")
    x = _record(10_000, 3)
    lazy = da.from_array(x, chunks=777)
    got = list(read_blocks({"a": lazy, "b": x}, start=123, stop=9_000, block_samples=1000))
    assert [o for o, _ in got] == list(range(0, 8877, 1000))
    np.testing.assert_array_equal(np.concatenate([b["a"] for _, b in got]), x[123:9000])
    np.testing.assert_array_equal(np.concatenate([b["b"] for _, b in got]), x[123:9000])
