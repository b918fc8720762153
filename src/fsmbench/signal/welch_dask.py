"""Welch estimates on Dask arrays with MATLAB's semantics, equal to the in-memory engine.

:func:`cross_spectral_density_dask` is :func:`fsmbench.signal.welch.cross_spectral_density`
for a record chunked along time: the same MATLAB segments (segment ``k`` is samples
``k*hop .. k*hop + L - 1``, ``K = floor((N - noverlap)/hop)`` of them), the same
window, datawrap (``nfft < L``), density scaling and one-sided doubling. Only the
order in which the segments' products are summed differs, so both agree to
floating-point reordering (~1e-15 relative).

How a record in chunks is cut: the segments are grouped in *tasks* of consecutive
segments (``segments_per_task``). A task reads exactly the samples its segments
cover, ``k0*hop .. (k1-1)*hop + L``, from the one or several chunks holding them
(a segment spanning two or more chunks is read whole, once), and returns the
unscaled sum over its segments of ``X_a conj(X_b)``, shape (c, c, F). The partial
sums are added in a tree and scaled once. Every segment belongs to exactly one
task, whatever the chunk boundaries; a task holds O(its samples) in memory, never
the whole record.

MATLAB's four functions (:mod:`fsmbench.signal.welch`) come here when given a Dask
array: :func:`pairwise_dask` checks the records as the in-memory path does (in the
same pass over the data as the spectra) and returns the same spectral matrix. They run
on Dask's current scheduler (a ``dask.distributed`` client if one is active).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, cast

import dask
import dask.array as da
import numpy as np
from dask.base import tokenize
from dask.core import flatten
from dask.highlevelgraph import HighLevelGraph
from numpy.typing import ArrayLike, NDArray

from fsmbench.signal.segments import segment_sums
from fsmbench.signal.welch_core import WelchOptions, _check_record, _label

__all__ = [
    "DEFAULT_CHUNK_SAMPLES",
    "as_time_chunked",
    "cross_spectral_density_dask",
    "pairwise_dask",
]

#: Chunk length (samples) given to NumPy inputs: 1 Mi samples = 8 MiB per channel.
DEFAULT_CHUNK_SAMPLES = 1 << 20
# Default task size: at least this many samples per task, so that short chunks do not
# make one task (and one graph node) per segment; larger chunks give larger tasks.
_MIN_TASK_SAMPLES = 1 << 18
# Memory cap for one block of segment FFTs inside a task (complex128), as in the engine.
# Fan-in of the tree that adds the per-task partial sums.
_FAN_IN = 8


# --------------------------------------------------------------------------- chunk plumbing
def as_time_chunked(x: Any, *, what: str = "record") -> da.Array:
    """A real record as a float64 Dask array chunked along time only.

    Parameters
    ----------
    x : dask.array.Array or array_like, shape (N,) or (c, N)
        Samples along the last axis. NumPy inputs get chunks of
        :data:`DEFAULT_CHUNK_SAMPLES` samples.
    what : str, optional
        Name used in error messages.

    Returns
    -------
    dask.array.Array, float64, same shape
        One chunk along every axis but the last (time), the time chunks unchanged.
    """
    if isinstance(x, da.Array):
        arr = x
    else:
        values = np.asarray(x)
        arr = da.from_array(values, chunks=(*values.shape[:-1], DEFAULT_CHUNK_SAMPLES))
    if arr.ndim not in (1, 2):
        raise ValueError(f"{what} must have shape (N,) or (channels, N), got {arr.shape}")
    if np.issubdtype(arr.dtype, np.complexfloating):
        raise TypeError(f"{what} is complex; only real signals (one-sided spectra) are supported")
    if not (np.issubdtype(arr.dtype, np.number) or arr.dtype == np.bool_):
        raise TypeError(f"{what} must hold numbers, got dtype {arr.dtype}")
    if any(len(c) > 1 for c in arr.chunks[:-1]):
        arr = arr.rechunk({i: -1 for i in range(arr.ndim - 1)})
    return arr.astype(np.float64)


class _TimeChunks:
    """The chunk keys of a time-chunked Dask array and where each chunk starts (samples).

    Tasks are written as plain graph tuples referring to these keys: a ``dask.delayed``
    call per task costs milliseconds of graph bookkeeping, a tuple microseconds.
    """

    def __init__(self, x: da.Array) -> None:
        self.array = x
        self.keys: list[Any] = list(flatten(x.__dask_keys__()))
        self.bounds = np.concatenate([[0], np.cumsum(x.chunks[-1])]).astype(np.int64)

    def covering(self, start: int, stop: int) -> list[Any]:
        """``[chunk keys, offset of start in the first, stop - start]`` for samples start..stop-1.

        A list, not a tuple: in a task, lists are walked for keys, tuples could read as tasks.
        """
        if stop <= start:
            return [[], 0, 0]
        i0 = int(np.searchsorted(self.bounds, start, side="right")) - 1
        i1 = int(np.searchsorted(self.bounds, stop, side="left"))
        return [self.keys[i0:i1], start - int(self.bounds[i0]), stop - start]

    def array_from(
        self, name: str, dsk: dict[Any, Any], chunks: tuple[tuple[int, ...], ...], dtype: Any
    ) -> da.Array:
        """A Dask array whose single block is ``dsk[(name, 0, ...)]``, computed from the chunks."""
        graph = HighLevelGraph.from_collections(name, dsk, dependencies=[cast(Any, self.array)])
        return da.Array(graph, name, chunks=chunks, dtype=dtype)


def _tree_sum(dsk: dict[Any, Any], name: str, keys: list[Any]) -> Any:
    """Add the arrays at ``keys`` in a tree of fan-in :data:`_FAN_IN`; return the root key."""
    level = 0
    while len(keys) > 1:
        nxt = []
        for i in range(0, len(keys), _FAN_IN):
            key = (f"{name}-sum{level}", i // _FAN_IN)
            dsk[key] = (_add_all, keys[i : i + _FAN_IN])
            nxt.append(key)
        keys, level = nxt, level + 1
    return keys[0]


def _add_all(arrays: Sequence[NDArray[Any]]) -> NDArray[Any]:
    total = arrays[0].copy()
    for a in arrays[1:]:
        total += a
    return total


# --------------------------------------------------------------------------- engine
def _scaled(acc: NDArray[np.complex128], scale: NDArray[np.float64]) -> NDArray[np.complex128]:
    return np.moveaxis(acc * scale, -1, 0)


def cross_spectral_density_dask(
    channels: Any, options: WelchOptions, *, segments_per_task: int | None = None
) -> tuple[da.Array, int]:
    """One-sided cross-spectral density matrix of a record chunked along time (lazy).

    Parameters
    ----------
    channels : dask.array.Array or array_like, shape (c, N)
        Real records, one row per channel (unit U_a of channel ``a``), chunked
        along time in any way (chunks may be shorter than a segment).
    options : WelchOptions
        Resolved window, overlap, nfft and fs.
    segments_per_task : int, optional
        Consecutive segments summed by one task. Default: the segments starting
        in ``max(largest chunk, 2**18)`` samples. Memory per task is
        ``~ c * (segments_per_task * hop + L) * 8`` bytes plus one FFT block.

    Returns
    -------
    S : dask.array.Array, complex128, shape (nfft//2 + 1, c, c)
        Lazy; ``S.compute()`` equals :func:`fsmbench.signal.welch.cross_spectral_density`
        on the same samples (U_a U_b / Hz) to floating-point reordering.
    n_segments : int
        Number of segments ``K`` averaged (known without reading the data).

    Raises
    ------
    ValueError
        A record shorter than one segment (same message as the in-memory engine).
    """
    x = as_time_chunked(channels, what="channels")
    if x.ndim != 2:
        raise ValueError(f"channels must have shape (channels, N), got {x.shape}")
    c, n = (int(v) for v in x.shape)
    length, hop, nfft = options.window_length, options.hop, options.nfft
    k_total = options.n_segments(n)
    if k_total < 1:
        raise ValueError(f"record of {n} samples is too short for {options.describe_window()}")
    if segments_per_task is None:
        longest = max(x.chunks[1])
        segments_per_task = max(1, max(longest, _MIN_TASK_SAMPLES) // hop)
    elif int(segments_per_task) < 1:
        raise ValueError(f"segments_per_task must be >= 1, got {segments_per_task}")
    chunks = _TimeChunks(x)
    window = np.asarray(options.window)
    name = "welch-csd-" + tokenize(x, window.tobytes(), options.noverlap, nfft, options.fs_hz,
                                   int(segments_per_task))
    window_key = f"{name}-window"
    dsk: dict[Any, Any] = {window_key: window}
    parts = []
    for j, k0 in enumerate(range(0, k_total, int(segments_per_task))):
        k1 = min(k0 + int(segments_per_task), k_total)
        pieces, offset, span = chunks.covering(k0 * hop, (k1 - 1) * hop + length)
        key = (f"{name}-part", j)
        dsk[key] = (segment_sums, pieces, offset, span, k1 - k0, window_key, hop, nfft)
        parts.append(key)
    # Same scaling as the engine: density |X|^2 / (fs sum(w^2)) over K segments, one-sided.
    n_freq = nfft // 2 + 1
    energy = float(np.dot(window, window))
    scale = np.full(n_freq, 2.0 / (options.fs_hz * energy * k_total))
    scale[0] /= 2.0
    if nfft % 2 == 0:
        scale[-1] /= 2.0
    dsk[(name, 0, 0, 0)] = (_scaled, _tree_sum(dsk, name, parts), scale)
    return chunks.array_from(name, dsk, ((n_freq,), (c,), (c,)), np.complex128), k_total


# --------------------------------------------------------------------------- SISO API
def _checks(x: da.Array) -> tuple[da.Array, da.Array, da.Array, da.Array]:
    """Lazy: number of non-finite samples, index of the first, minimum and maximum."""
    bad = ~da.isfinite(x)
    return bad.sum(), da.argmax(bad), da.nanmin(x), da.nanmax(x)


def pairwise_dask(
    arrays: Sequence[tuple[Any, str | None, str]],
    *,
    window: int | ArrayLike,
    noverlap: int | None,
    nfft: int | None,
    fs_hz: float,
    min_segments: int = 1,
    need_power: Sequence[bool] = (),
    segments_per_task: int | None = None,
) -> tuple[WelchOptions, NDArray[np.complex128], int]:
    """The spectral matrix of 1-D records, any of them a Dask array (computed).

    Parameters
    ----------
    arrays : sequence of (array, name, role)
        Each record (Dask or NumPy, shape (N,)), its signal name (or None) and its role in
        messages (``"x"``, ``"input x"`` …).
    window, noverlap, nfft, fs_hz
        MATLAB's arguments (:meth:`fsmbench.signal.welch_core.WelchOptions.from_matlab`).
    min_segments : int
        Fewest segments the estimate needs (2 for a coherence).
    need_power : sequence of bool
        Per record: refused when constant (an input of a ratio).
    segments_per_task : int, optional
        See :func:`cross_spectral_density_dask`.

    Returns
    -------
    options : WelchOptions
    s : ndarray, complex, shape (nfft//2 + 1, c, c)
        ``S[f, a, b]``, U_a U_b / Hz.
    n_segments : int

    Raises
    ------
    ValueError
        A record too short, not 1-D, with NaN or infinite samples, or constant where
        ``need_power``: the in-memory path's messages.
    """
    options = WelchOptions.from_matlab(window=window, noverlap=noverlap, nfft=nfft, fs_hz=fs_hz)
    checked: list[tuple[str, da.Array]] = []
    for x, name, role in arrays:
        who = _label(name, role)
        arr = as_time_chunked(x, what=who)
        if arr.ndim != 1:
            raise ValueError(f"{who} must be a 1-D array of samples, got shape {arr.shape}")
        checked.append((who, arr))
    # _check_record reads only .size: lengths and record length, without touching the data.
    _check_record(cast(Any, checked), options, min_segments=min_segments)
    stacked = da.stack([arr for _, arr in checked]).rechunk({0: -1})
    s_lazy, k = cross_spectral_density_dask(stacked, options, segments_per_task=segments_per_task)
    # One pass over the data: the spectra and the input checks together.
    s, *stats = dask.compute(s_lazy, *[_checks(arr) for _, arr in checked])
    for (who, _), (n_bad, first, _, _) in zip(checked, stats, strict=True):
        if int(n_bad):
            raise ValueError(
                f"{who} contains {int(n_bad)} NaN or infinite sample(s) (first at index "
                f"{int(first)}); remove or interpolate them before spectral estimation"
            )
    for (who, arr), (_, _, lo, hi), need in zip(checked, stats, need_power, strict=False):
        if need and lo == hi:
            raise ValueError(
                f"{who} is constant ({float(lo):g} for all {arr.size} samples): it has no power "
                "at any non-zero frequency, so the coherence and the frequency response are "
                "undefined"
            )
    return options, np.asarray(s), k
