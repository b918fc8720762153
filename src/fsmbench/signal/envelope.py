"""Min/max/mean envelope of long records, for time plots that do not draw every sample.

A record of ``N`` samples is cut into ``n_bins`` consecutive bins; bin ``b`` holds
samples ``edges[b] .. edges[b+1]-1`` with ``edges[b] = floor(b*N/n_bins)``, so every
bin has ``floor(N/n_bins)`` or ``ceil(N/n_bins)`` samples and none is empty. Drawing
the band between ``minimum`` and ``maximum`` shows every excursion of the record
(min and max are exact), at a cost independent of ``N``.

On a Dask array the bins are grouped in tasks of about ``task_samples`` samples;
a task reads exactly its bins' samples from the one or several chunks holding them,
so a bin spanning a chunk boundary is reduced whole, and the result is the same
(bit for bit) as for the same samples in memory.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fsmbench.signal.segments import read_span

__all__ = ["Envelope", "minmax_envelope"]


@dataclass(frozen=True, eq=False)
class Envelope:
    """Per-bin minimum, maximum and mean of a record.

    Attributes
    ----------
    t_s : ndarray, shape (n_bins,)
        Bin centres, s: the mean of the sample times of the bin,
        ``t0 + (edges[b] + edges[b+1] - 1) / (2 fs)``.
    t_edges_s : ndarray, shape (n_bins + 1,)
        Bin edges, s: ``t0 + edges / fs`` (the last is one sample past the record).
    minimum, maximum, mean : ndarray, shape (n_bins,)
        Per-bin extreme values and mean, unit of the record.
    samples_per_bin : ndarray of int, shape (n_bins,)
        Samples in each bin.
    """

    t_s: NDArray[np.float64]
    t_edges_s: NDArray[np.float64]
    minimum: NDArray[np.float64]
    maximum: NDArray[np.float64]
    mean: NDArray[np.float64]
    samples_per_bin: NDArray[np.int64]


def _bins(
    pieces: list[NDArray[np.float64]], offset: int, length: int, local_edges: NDArray[np.int64]
) -> NDArray[np.float64]:
    """``(3, bins)``: min, max, mean of ``data[local_edges[i]:local_edges[i+1]]``."""

    return _reduce(read_span(pieces, offset, length), local_edges)


def _reduce(data: NDArray[np.float64], local_edges: NDArray[np.int64]) -> NDArray[np.float64]:
    """``(3, bins)``: min, max, mean of ``data`` between consecutive ``local_edges``."""
    starts = local_edges[:-1]
    counts = np.diff(local_edges)
    return np.stack([
        np.minimum.reduceat(data, starts),
        np.maximum.reduceat(data, starts),
        np.add.reduceat(data, starts) / counts,
    ])


def _concat(parts: list[NDArray[np.float64]]) -> NDArray[np.float64]:
    return np.concatenate(parts, axis=1)


def minmax_envelope(
    x: Any,
    *,
    fs_hz: float,
    n_bins: int,
    t0_s: float = 0.0,
    name: str = "record",
    task_samples: int | None = None,
) -> Envelope:
    """Min/max/mean envelope of a record in ``n_bins`` bins (NumPy or Dask, out of core).

    Parameters
    ----------
    x : array_like or dask.array.Array, shape (N,)
        Real samples (unit U); a Dask array may be chunked along time in any way.
        NaN samples propagate to their bin's values.
    fs_hz : float
        Sampling frequency, Hz.
    n_bins : int
        Number of bins, ``1 <= n_bins <= N``.
    t0_s : float, optional
        Time of the first sample, s.
    name : str, optional
        Signal name used in error messages.
    task_samples : int, optional
        Samples per Dask task (whole bins). Default ``max(largest chunk, 2**18)``.

    Returns
    -------
    Envelope
        Bin times (s) and per-bin minimum, maximum, mean (U), computed.
    """
    fs = float(fs_hz)
    if not (math.isfinite(fs) and fs > 0.0):
        raise ValueError(f"fs_hz must be a positive finite frequency in Hz, got {fs_hz!r}")
    lazy = type(x).__module__.startswith("dask")
    arr: Any = x if lazy else np.asarray(x, dtype=np.float64)
    if arr.ndim != 1:
        raise ValueError(f"{name} must be a 1-D array of samples, got shape {arr.shape}")
    n = int(arr.shape[0])
    bins = int(n_bins)
    if not 1 <= bins <= n:
        raise ValueError(
            f"{name}: n_bins must be between 1 and the number of samples ({n}), got {n_bins}"
        )
    edges = (np.arange(bins + 1, dtype=np.int64) * n) // bins
    if not lazy:  # in memory: the same reduction, no Dask needed
        return _envelope(_reduce(arr, edges), edges=edges, fs=fs, t0_s=t0_s)
    import dask
    from dask.base import tokenize

    from fsmbench.signal.welch_dask import _MIN_TASK_SAMPLES, _TimeChunks, as_time_chunked

    arr = as_time_chunked(x, what=name)
    longest = max(arr.chunks[0])
    per_task = int(task_samples) if task_samples is not None else max(longest, _MIN_TASK_SAMPLES)
    if per_task < 1:
        raise ValueError(f"task_samples must be >= 1, got {task_samples}")
    bins_per_task = max(1, per_task * bins // n)
    chunks = _TimeChunks(arr)
    gname = "envelope-" + tokenize(arr, bins, bins_per_task)
    dsk: dict[Any, Any] = {}
    parts = []
    for j, b0 in enumerate(range(0, bins, bins_per_task)):
        b1 = min(b0 + bins_per_task, bins)
        local = edges[b0 : b1 + 1] - edges[b0]
        dsk[(f"{gname}-part", j)] = (
            _bins, *chunks.covering(int(edges[b0]), int(edges[b1])), local
        )
        parts.append((f"{gname}-part", j))
    dsk[(gname, 0, 0)] = (_concat, parts)
    (stats,) = dask.compute(chunks.array_from(gname, dsk, ((3,), (bins,)), np.float64))
    return _envelope(stats, edges=edges, fs=fs, t0_s=t0_s)


def _envelope(stats: NDArray[np.float64], *, edges: NDArray[np.int64], fs: float,
              t0_s: float) -> Envelope:
    t_edges = t0_s + edges / fs
    t_mid = t0_s + (edges[:-1] + edges[1:] - 1) / (2.0 * fs)
    out = Envelope(
        t_s=t_mid, t_edges_s=t_edges, minimum=stats[0].copy(), maximum=stats[1].copy(),
        mean=stats[2].copy(), samples_per_bin=np.diff(edges),
    )
    for a in (out.t_s, out.t_edges_s, out.minimum, out.maximum, out.mean, out.samples_per_bin):
        a.setflags(write=False)
    return out
