"""Record arithmetic the analyses share, for records in memory and out of core alike.

A recording read with :func:`fsmbench.io.lazy.open_recording` holds Dask
arrays; one read with :func:`~fsmbench.io.recording.read_recording` holds
numpy arrays. The functions here take either and give the same numbers
(up to the order of summation): in memory they are the numpy expressions
the analyses always used; out of core they are Dask reductions, or a
sequential pass over the chunks where the computation is a recursion
(the low-pass filter). Memory stays bounded by a chunk.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import xarray as xr
from numpy.typing import NDArray
from scipy.signal import lfilter, lfilter_zi

from fsmbench.filters import first_order_lowpass

__all__ = [
    "LazyTrim",
    "block_means",
    "compute",
    "is_lazy",
    "lowpass",
    "lowpass_rms",
    "trim_record",
]

FloatArray = NDArray[np.float64]


def is_lazy(x: Any) -> bool:
    """True for a Dask array (a record read out of core)."""
    return type(x).__module__.startswith("dask")


def compute(*values: Any) -> tuple[Any, ...]:
    """Evaluate lazy values in one pass over the data (numbers pass through)."""
    if any(is_lazy(v) for v in values):
        import dask

        return tuple(dask.compute(*values))
    return values


@dataclass(frozen=True)
class LazyTrim:
    """Where a trimmed record starts and how long it is.

    Attributes
    ----------
    start : int
        First sample kept.
    n : int
        Samples kept.
    t0_s : float
        Time of the first sample kept [s].
    """

    start: int
    n: int
    t0_s: float


def trim_record(ds: xr.Dataset, *, t0_s: float, duration_s: float | None,
                fs_hz: float) -> LazyTrim:
    """The samples with ``t >= t0_s``, at most ``duration_s`` of them (None: all).

    Reads only the first samples of ``t`` when the record is out of core
    (a uniform time base is checked when the record is read).
    """
    t = ds["t"].data
    n_total = int(t.shape[0])
    if is_lazy(t):
        head = np.asarray(t[: min(n_total, math.ceil(max(t0_s, 0.0) * fs_hz) + 3)].compute())
        below = int(np.count_nonzero(head < t0_s))
        start = below if below < head.size else math.ceil((t0_s - float(head[0])) * fs_hz)
    else:
        start = int(np.count_nonzero(np.asarray(t) < t0_s))
    n = n_total - start
    if duration_s is not None:
        n = min(n, round(duration_s * fs_hz))
    t_start = float(np.asarray(t[start:start + 1]).ravel()[0]) if n > 0 and not is_lazy(t) \
        else (float(np.asarray(t[start:start + 1].compute())[0]) if n > 0 else float("nan"))
    return LazyTrim(start=start, n=max(n, 0), t0_s=t_start)


def lowpass(x: Any, *, cutoff_hz: float, fs_hz: float) -> Any:
    """The seed's first-order low pass (from rest) of a record, numpy or Dask.

    Out of core the recursion is a chain of tasks, one per chunk, each
    starting from the state the previous chunk ended in: the result is a
    lazy Dask array equal to the in-memory filter (same recursion, same
    order of operations), computed chunk by chunk.
    """
    if not is_lazy(x):
        return first_order_lowpass(np.asarray(x, dtype=float), cutoff_hz=cutoff_hz,
                                   fs_hz=fs_hz)
    import dask
    import dask.array as da

    a = math.exp(-2.0 * math.pi * cutoff_hz / fs_hz)
    b_coef, a_coef = np.array([0.0, 1.0 - a]), np.array([1.0, -a])

    def step(chunk: FloatArray, zi: FloatArray) -> tuple[FloatArray, FloatArray]:
        y, zf = lfilter(b_coef, a_coef, np.asarray(chunk, dtype=float), zi=zi)
        return np.asarray(y, dtype=float), np.asarray(zf, dtype=float)

    zi: Any = lfilter_zi(b_coef, a_coef) * 0.0  # from rest, as the in-memory default
    parts = []
    for block, size in zip(x.to_delayed().ravel(), x.chunks[0], strict=True):
        out = dask.delayed(step, nout=2)(block, zi)
        parts.append(da.from_delayed(out[0], shape=(size,), dtype=float))
        zi = out[1]
    return da.concatenate(parts) if parts else x


def lowpass_rms(x: Any, *, cutoff_hz: float, fs_hz: float) -> float:
    """Rms about the mean of ``x`` after the seed's first-order low pass (from rest)."""
    y = lowpass(x, cutoff_hz=cutoff_hz, fs_hz=fs_hz)
    if not is_lazy(y):
        return float(np.sqrt(np.mean((y - y.mean()) ** 2)))
    mean = float(y.mean().compute())
    return math.sqrt(float(((y - mean) ** 2).mean().compute()))


def block_means(x: Any, *, per: int) -> FloatArray:
    """Means of consecutive blocks of ``per`` samples (the incomplete tail dropped), shape (nb,)."""
    nb = int(x.shape[0]) // per
    if nb == 0:
        return np.zeros(0)
    if not is_lazy(x):
        return np.asarray(x[: nb * per], dtype=float).reshape(nb, per).mean(axis=1)
    # Chunks aligned to whole blocks so that the reshape is chunk-local.
    blocks_per_chunk = max(1, (1 << 20) // per)
    y = x[: nb * per].rechunk(per * blocks_per_chunk)
    return np.asarray(y.reshape(nb, per).mean(axis=1).compute(), dtype=float)
