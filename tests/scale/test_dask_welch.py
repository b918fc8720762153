"""Welch on Dask arrays equals the in-memory MATLAB-semantics engine, whatever the chunking."""

from __future__ import annotations

import itertools
import tracemalloc

import dask
import dask.array as da
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fsmbench.signal.welch import (
    WelchOptions,
    cpsd,
    cross_spectral_density,
    mscohere,
    pwelch,
    tfestimate,
)
from fsmbench.signal.welch_dask import (
    cross_spectral_density_dask,
)

# Same segments and FFTs, only the order of summing the segment products differs:
# reordering K <= a few hundred terms changes a sum by ~K*eps ~ 1e-14 relative.
RTOL = 1e-12


def _assert_csd_close(s_dask: np.ndarray, s_ref: np.ndarray) -> None:
    # Cross terms are compared relative to sqrt(Saa Sbb), their Cauchy-Schwarz bound:
    # a cross term near zero is a cancellation, not a value known to 1e-12 of itself.
    diag = np.abs(np.diagonal(s_ref, axis1=1, axis2=2))
    bound = np.sqrt(diag[:, :, None] * diag[:, None, :])
    assert s_dask.shape == s_ref.shape
    assert np.all(np.abs(s_dask - s_ref) <= RTOL * bound)


def _chunked(x: np.ndarray, cuts: list[int]) -> da.Array:
    n = x.shape[-1]
    edges = [0, *sorted({c for c in cuts if 0 < c < n}), n]
    sizes = tuple(b - a for a, b in itertools.pairwise(edges))
    return da.from_array(x, chunks=(*x.shape[:-1], sizes))


@st.composite
def _cases(draw: st.DrawFn) -> tuple[np.ndarray, WelchOptions, list[int], int | None]:
    length = draw(st.integers(1, 48))
    noverlap = draw(st.one_of(st.none(), st.integers(0, length - 1)))
    nfft = draw(st.one_of(st.none(), st.integers(1, 2 * length + 3)))  # below and above L
    options = WelchOptions.from_matlab(window=length, noverlap=noverlap, nfft=nfft, fs_hz=250.0)
    k = draw(st.integers(1, 300))
    n = options.window_length + (k - 1) * options.hop + draw(st.integers(0, options.hop - 1))
    c = draw(st.integers(1, 3))
    seed = draw(st.integers(0, 2**32 - 1))
    x = np.random.default_rng(seed).standard_normal((c, n))
    kind = draw(st.sampled_from(["single samples", "shorter than hop", "random cuts"]))
    if kind == "single samples" and n <= 2000:
        cuts = list(range(1, n))
    elif kind == "shorter than hop":
        step = draw(st.integers(1, max(1, options.hop - 1)))
        step = max(step, n // 500)  # keep the graph small for long records
        cuts = list(range(step, n, step))
    else:
        cuts = draw(st.lists(st.integers(1, max(1, n - 1)), max_size=12))
    spt = draw(st.one_of(st.none(), st.integers(1, 40)))
    return x, options, cuts, spt


@settings(max_examples=40, deadline=None)
@given(_cases())
def test_equals_in_memory_engine_for_any_chunking(
    case: tuple[np.ndarray, WelchOptions, list[int], int | None],
) -> None:
    x, options, cuts, spt = case
    s_ref, k_ref = cross_spectral_density(x, options)
    s_lazy, k = cross_spectral_density_dask(_chunked(x, cuts), options, segments_per_task=spt)
    assert k == k_ref
    _assert_csd_close(s_lazy.compute(scheduler="sync"), s_ref)


def test_siso_functions_equal_in_memory() -> None:
    rng = np.random.default_rng(7)
    x = rng.standard_normal(4000)
    y = np.convolve(x, [0.5, 0.3, -0.2], mode="same") + 0.1 * rng.standard_normal(4000)
    xd, yd = _chunked(x, [13, 500, 501, 2999]), _chunked(y, [1, 2, 1800])
    kw = {"window": np.hanning(300), "noverlap": 120, "nfft": 512, "fs_hz": 1000.0}
    pairs = [
        (pwelch(x, **kw), pwelch(xd, segments_per_task=4, **kw)),
        (cpsd(x, y, **kw), cpsd(xd, yd, segments_per_task=3, **kw)),
        (tfestimate(x, y, **kw), tfestimate(xd, yd, **kw)),
        (mscohere(x, y, **kw), mscohere(xd, y, **kw)),  # one Dask array is enough
    ]
    for ref, got in pairs:
        assert got.quantity == ref.quantity and got.n_segments == ref.n_segments
        assert got.effective_averages == ref.effective_averages
        np.testing.assert_array_equal(got.f_hz, ref.f_hz)
        # PSD/CPSD/H1/coherence of sums equal to 1e-12: ratios add at most a few eps.
        np.testing.assert_allclose(got.values, ref.values, rtol=RTOL, atol=0.0)


def test_too_short_record_gives_the_in_memory_error() -> None:
    options = WelchOptions.from_matlab(window=64, fs_hz=100.0)
    x = np.zeros((2, 63))
    with pytest.raises(ValueError) as ref:
        cross_spectral_density(x, options)
    with pytest.raises(ValueError) as got:
        cross_spectral_density_dask(da.from_array(x, chunks=(2, 10)), options)
    assert str(got.value) == str(ref.value)
    with pytest.raises(ValueError) as ref:
        pwelch(x[0], window=64, fs_hz=100.0, x_name="Va")
    with pytest.raises(ValueError) as got:
        pwelch(da.from_array(x[0], chunks=10), window=64, fs_hz=100.0, x_name="Va")
    assert str(got.value) == str(ref.value)


def test_bad_samples_and_constant_input_give_the_in_memory_errors() -> None:
    x = np.random.default_rng(1).standard_normal(1000)
    x[[400, 700]] = np.nan
    with pytest.raises(ValueError) as ref:
        pwelch(x, window=100, fs_hz=10.0, x_name="Uch")
    with pytest.raises(ValueError) as got:
        pwelch(_chunked(x, [333]), window=100, fs_hz=10.0, x_name="Uch")
    assert str(got.value) == str(ref.value)
    const, y = np.full(1000, 2.5), np.arange(1000.0)
    with pytest.raises(ValueError) as ref:
        tfestimate(const, y, window=100, fs_hz=10.0, x_name="Uch")
    with pytest.raises(ValueError) as got:
        tfestimate(_chunked(const, [5]), y, window=100, fs_hz=10.0, x_name="Uch")
    assert str(got.value) == str(ref.value)


def test_graph_on_a_billion_samples_is_built_lazily() -> None:
    x = da.zeros((2, 10**9), chunks=(2, 2**24))  # 16 GB if it were ever materialised
    options = WelchOptions.from_matlab(window=np.hanning(10000), fs_hz=10000.0)
    tracemalloc.start()
    s, k = cross_spectral_density_dask(x, options)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert isinstance(s, da.Array) and s.shape == (options.nfft // 2 + 1, 2, 2)
    assert k == options.n_segments(10**9)
    # One task per 2**24-sample chunk's segments plus the tree: a few hundred tasks.
    assert len(s.__dask_graph__()) < 400
    assert peak < 50e6  # bytes: graph bookkeeping only, far below one 268 MB chunk


def test_same_result_on_sync_scheduler_and_local_cluster() -> None:
    distributed = pytest.importorskip("distributed")
    rng = np.random.default_rng(3)
    x = da.from_array(rng.standard_normal((2, 20000)), chunks=(2, 1234))
    options = WelchOptions.from_matlab(window=500, noverlap=300, nfft=256, fs_hz=1000.0)
    s, _ = cross_spectral_density_dask(x, options, segments_per_task=7)
    sync = s.compute(scheduler="sync")
    with (
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0"
        ) as cluster,
        distributed.Client(cluster) as client,
    ):
        on_cluster = client.compute(s).result()
        with dask.config.set(scheduler=client.get):
            via_wrapper = pwelch(x[0], window=500, noverlap=300, nfft=256, fs_hz=1000.0)
    # Same graph, same tasks, same tree order: the same floating-point operations.
    np.testing.assert_array_equal(on_cluster, sync)
    np.testing.assert_array_equal(via_wrapper.values, pwelch(
        x[0], window=500, noverlap=300, nfft=256, fs_hz=1000.0).values)
