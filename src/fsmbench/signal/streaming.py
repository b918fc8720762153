"""Estimators fed block after block: many analyses in one sequential read of a record.

The Dask graphs of :mod:`fsmbench.signal.welch_dask`, :mod:`~fsmbench.signal.allan`
and :mod:`~fsmbench.signal.envelope` spread one estimate over workers. On one
machine a day-long record is limited by the disk, not the processor (a day of
huddle test 5 is 41 GB; reading it once takes 6–10 min here), and every
estimate that reads the record again costs another full read, while a Dask
graph of tens of thousands of chunks costs memory of its own. The classes here
take consecutive blocks of a record instead, keep only what the next block
needs (a Welch segment's tail, the Allan deviation's ``2 m_max`` samples, a
partial envelope bin, a filter state), and give at the end the numbers of the
in-memory estimators: the same arithmetic on the same samples, summed in
another order (equal to 1e-12, ``tests/scale/test_streaming.py``).

:func:`read_blocks` reads aligned blocks of several signals (NumPy or Dask).
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.signal import lfilter

from fsmbench.signal.allan import AllanResult
from fsmbench.signal.envelope import Envelope, _envelope
from fsmbench.signal.segments import segment_sums
from fsmbench.signal.welch import SpectrumResult, WelchOptions, _result

__all__ = [
    "AllanStream",
    "BlockMeanStream",
    "EnvelopeStream",
    "LowpassStream",
    "SumStream",
    "WelchStream",
    "read_blocks",
]

FloatArray = NDArray[np.float64]

#: Samples per block read (8 MiB per signal in float64).
BLOCK_SAMPLES = 1 << 20


def read_blocks(signals: Mapping[str, Any], *, start: int, stop: int,
                block_samples: int = BLOCK_SAMPLES) -> Iterator[tuple[int, dict[str, FloatArray]]]:
    """Consecutive aligned blocks ``[a, b)`` of every signal, as ``(a - start, {name: block})``.

    Parameters
    ----------
    signals : mapping of str to array_like or dask.array.Array, each shape (N,)
        The record's signals (one time axis).
    start, stop : int
        Sample range read.
    block_samples : int
        Samples per block (the last may be shorter).
    """
    if block_samples < 1:
        raise ValueError(f"block_samples must be >= 1, got {block_samples}")
    lazy = [k for k, x in signals.items() if type(x).__module__.startswith("dask")]
    for a in range(start, stop, block_samples):
        b = min(a + block_samples, stop)
        blocks = {k: x[a:b] for k, x in signals.items()}
        if lazy:
            import dask

            # One compute for all signals: their chunks are read side by side.
            values = dask.compute(*(blocks[k] for k in lazy))
            blocks.update(zip(lazy, values, strict=True))
        yield a - start, {k: np.asarray(v, dtype=np.float64) for k, v in blocks.items()}


class SumStream:
    """Exact sums of ``x - shift`` and of its square over all blocks (``math.fsum`` of block sums).

    Parameters
    ----------
    shift : float
        Subtracted from every sample first (the mean, for moments about it).
    """

    def __init__(self, *, shift: float = 0.0) -> None:
        self.shift = float(shift)
        self._sums: list[float] = []
        self._squares: list[float] = []
        self.count = 0

    def update(self, block: FloatArray) -> None:
        """Add one block (unit U)."""
        d = block - self.shift if self.shift else block
        self._sums.append(float(np.sum(d)))
        self._squares.append(float(np.sum(d * d)))
        self.count += int(block.size)

    @property
    def mean(self) -> float:
        """Mean of all samples [U] (the shift added back)."""
        return self.shift + math.fsum(self._sums) / self.count

    @property
    def rms(self) -> float:
        """Root mean square of ``x - shift`` [U]."""
        return math.sqrt(math.fsum(self._squares) / self.count)

    @property
    def rms_about_mean(self) -> float:
        """Root mean square of ``x`` about its mean [U]."""
        m = math.fsum(self._sums) / self.count
        return math.sqrt(max(0.0, math.fsum(self._squares) / self.count - m * m))


class WelchStream:
    """Welch's averaged periodogram (MATLAB ``pwelch`` semantics) of a record read in blocks.

    Segments that span two blocks are completed from the next block (the tail
    of each block is kept until then), so every segment of the in-memory
    estimate is counted, once.

    Parameters
    ----------
    options : WelchOptions
        Window, overlap, nfft, fs (``WelchOptions.from_matlab``).
    n_samples : int
        Length of the whole record (samples): fixes the number of segments.
    name : str
        Signal name for messages.
    """

    def __init__(self, *, options: WelchOptions, n_samples: int, name: str) -> None:
        self.options = options
        self.name = name
        self.k_total = options.n_segments(int(n_samples))
        if self.k_total < 1:
            raise ValueError(f"{name}: record of {n_samples} samples is too short for "
                             f"{options.describe_window()}")
        self._window = np.asarray(options.window, dtype=float)
        self._acc = np.zeros(options.nfft // 2 + 1)
        self._tail = np.zeros(0)
        self._done = 0

    def update(self, block: FloatArray) -> None:
        """Add the next samples of the record (unit U)."""
        if self._done >= self.k_total:
            return
        data = np.concatenate([self._tail, block]) if self._tail.size else block
        length, hop = self.options.window_length, self.options.hop
        fit = (data.size - length) // hop + 1 if data.size >= length else 0
        n_seg = min(fit, self.k_total - self._done)
        if n_seg > 0:
            span = (n_seg - 1) * hop + length
            acc = segment_sums([data[None, :]], 0, span, n_seg, self._window, hop,
                                self.options.nfft)
            self._acc += acc[0, 0].real
            self._done += n_seg
        # Keep the samples from the next segment's start on.
        self._tail = data[n_seg * hop:].copy() if self._done < self.k_total else np.zeros(0)

    def result(self) -> SpectrumResult:
        """One-sided PSD [U²/Hz] on ``options.frequencies_hz``, as ``pwelch``."""
        if self._done != self.k_total:
            raise ValueError(f"{self.name}: {self._done} of {self.k_total} Welch segments were "
                             "read; the record ended early")
        opts = self.options
        n_freq = opts.nfft // 2 + 1
        # The engine's scaling: |X|^2 / (fs sum(w^2)) over K segments, one-sided.
        scale = np.full(n_freq, 2.0 / (opts.fs_hz * float(np.dot(self._window, self._window))
                                       * self.k_total))
        scale[0] /= 2.0
        if opts.nfft % 2 == 0:
            scale[-1] /= 2.0
        return _result(opts, np.ascontiguousarray(self._acc * scale), "psd", self.k_total)


class EnvelopeStream:
    """Per-bin minimum, maximum and mean of a record read in blocks (bins as ``minmax_envelope``).

    Parameters
    ----------
    n_samples : int
        Length of the whole record.
    n_bins : int
        ``1 <= n_bins <= n_samples``; bin ``b`` holds samples ``edges[b]:edges[b+1]``,
        ``edges = arange(n_bins + 1) * n_samples // n_bins``.
    fs_hz, t0_s : float
        Sampling frequency [Hz] and time of the first sample [s].
    """

    def __init__(self, *, n_samples: int, n_bins: int, fs_hz: float, t0_s: float = 0.0) -> None:
        if not 1 <= n_bins <= n_samples:
            raise ValueError(f"n_bins must be between 1 and {n_samples}, got {n_bins}")
        self.edges = (np.arange(n_bins + 1, dtype=np.int64) * n_samples) // n_bins
        self.fs_hz, self.t0_s = float(fs_hz), float(t0_s)
        self._stats = np.zeros((3, n_bins))
        self._stats[0], self._stats[1] = np.inf, -np.inf
        self._pos = 0

    def update(self, block: FloatArray) -> None:
        """Add the next samples of the record."""
        if block.size == 0:
            return
        a, b = self._pos, self._pos + block.size
        first = int(np.searchsorted(self.edges, a, side="right")) - 1
        last = int(np.searchsorted(self.edges, b - 1, side="right")) - 1
        starts = np.maximum(self.edges[first:last + 1], a) - a
        lo = np.minimum.reduceat(block, starts)
        hi = np.maximum.reduceat(block, starts)
        total = np.add.reduceat(block, starts)
        sl = slice(first, last + 1)
        np.minimum(self._stats[0, sl], lo, out=self._stats[0, sl])
        np.maximum(self._stats[1, sl], hi, out=self._stats[1, sl])
        self._stats[2, sl] += total  # sums until result()
        self._pos = b

    def result(self) -> Envelope:
        """The envelope (unit of the record)."""
        counts = np.diff(self.edges)
        stats = self._stats.copy()
        stats[2] /= counts
        return _envelope(stats, edges=self.edges, fs=self.fs_hz, t0_s=self.t0_s)


class BlockMeanStream:
    """Means of consecutive blocks of ``per`` samples (the incomplete tail dropped).

    Each mean is taken over one contiguous ``per``-sample array, as
    ``x[:nb*per].reshape(nb, per).mean(axis=1)`` does in memory.
    """

    def __init__(self, *, per: int) -> None:
        if per < 1:
            raise ValueError(f"per must be >= 1, got {per}")
        self.per = int(per)
        self._tail = np.zeros(0)
        self._means: list[FloatArray] = []

    def update(self, block: FloatArray) -> None:
        """Add the next samples of the record."""
        data = np.concatenate([self._tail, block]) if self._tail.size else block
        nb = data.size // self.per
        if nb:
            self._means.append(data[: nb * self.per].reshape(nb, self.per).mean(axis=1))
        self._tail = data[nb * self.per:].copy()

    def result(self) -> FloatArray:
        """The block means, shape (N // per,)."""
        return np.concatenate(self._means) if self._means else np.zeros(0)


class LowpassStream:
    """The study's first-order low pass from rest (:func:`fsmbench.filters.first_order_lowpass`)
    applied block after block, its state handed from each block to the next."""

    def __init__(self, *, cutoff_hz: float, fs_hz: float) -> None:
        a = math.exp(-2.0 * math.pi * cutoff_hz / fs_hz)
        self._b, self._a = np.array([0.0, 1.0 - a]), np.array([1.0, -a])
        self._z = np.zeros(1)

    def filter(self, block: FloatArray) -> FloatArray:
        """The filtered block (unit of the input)."""
        y, self._z = lfilter(self._b, self._a, block, zi=self._z)
        return np.asarray(y, dtype=np.float64)


class AllanStream:
    """Overlapping Allan deviation (:mod:`fsmbench.signal.allan`'s formula) of a record read in
    blocks, at the averaging factors ``factors``.

    Each block is appended to the samples still needed (about the last
    ``2 m_max``); the m-sums come from a cumulative sum of that segment
    (``x - x[0]``, the offset removed so nanometres are not lost under metres),
    and every position is counted once, when all its samples are in. Memory:
    one block plus ``2 m_max`` samples, whatever the record's length.

    Parameters
    ----------
    n_samples : int
        Length of the whole record.
    fs_hz : float
        Sampling frequency [Hz].
    factors : ndarray of int, shape (T,)
        Averaging factors m (``tau = m / fs``), ``2 m <= n_samples``.
    unit, name : str
        Unit of the samples and name for messages.
    """

    def __init__(self, *, n_samples: int, fs_hz: float, factors: NDArray[np.int64],
                 unit: str, name: str) -> None:
        self.n, self.fs_hz, self.unit, self.name = int(n_samples), float(fs_hz), unit, name
        self.m = np.asarray(factors, dtype=np.int64)
        if np.any(2 * self.m > self.n) or np.any(self.m < 1):
            raise ValueError(f"{name}: averaging factors must be 1 <= m <= N/2 = {self.n // 2}")
        self._sums: list[list[float]] = [[] for _ in self.m]
        self._next = np.zeros(self.m.size, dtype=np.int64)  # next position to count, per m
        self._last = self.n - 2 * self.m  # last position, per m
        self._buf = np.zeros(0)
        self._pos = 0  # record index of _buf[0]
        self._x0: float | None = None

    def update(self, block: FloatArray) -> None:
        """Add the next samples of the record (finite, unit U)."""
        if block.size == 0:
            return
        bad = np.flatnonzero(~np.isfinite(block))
        if bad.size:
            raise ValueError(f"{self.name} contains NaN or infinite samples (first at index "
                             f"{self._pos + self._buf.size + int(bad[0])}); remove or "
                             "interpolate them before the Allan deviation")
        if self._x0 is None:
            self._x0 = float(block[0])
        self._buf = np.concatenate([self._buf, block - self._x0])
        c = np.concatenate([[0.0], np.cumsum(self._buf)])
        for i, m in enumerate(int(v) for v in self.m):
            stop = min(int(self._last[i]), self._pos + self._buf.size - 2 * m)
            if stop < self._next[i]:
                continue
            lo, hi = int(self._next[i]) - self._pos, stop - self._pos + 1
            mid = c[lo + m:hi + m]
            d = (c[lo + 2 * m:hi + 2 * m] - mid) - (mid - c[lo:hi])
            # numpy's pairwise sum (error ~ log2(n) eps) per block, exact fsum across blocks:
            # math.fsum over every term costs ~50 ns a sample, 35 min on a day's three signals.
            self._sums[i].append(float(np.sum(d * d)))
            self._next[i] = stop + 1
        keep = int(min(int(self._next.min()), self.n)) - self._pos
        self._buf = self._buf[keep:]
        self._pos += keep

    def result(self) -> AllanResult:
        """The Allan deviation [U] at ``tau = m / fs``."""
        if np.any(self._next <= self._last):
            raise ValueError(f"{self.name}: the record ended before all Allan terms were read")
        n_terms = self.n - 2 * self.m + 1
        total = np.array([math.fsum(s) for s in self._sums])
        avar = total / (2.0 * self.m.astype(np.float64) ** 2 * n_terms)
        return AllanResult(tau_s=self.m / self.fs_hz, adev=np.sqrt(avar), n_terms=n_terms,
                           m=self.m.copy(), fs_hz=self.fs_hz, n_samples=self.n, unit=self.unit)
