"""Record arithmetic the analyses share.

A recording read with :func:`fsmbench.io.lazy.open_recording` holds Dask
arrays; one read with :func:`~fsmbench.io.recording.read_recording` holds
numpy arrays. :func:`is_lazy` tells them apart and :func:`trim_record` finds
the ESRF study's trim in either (reading only the first samples of a lazy ``t``).
The filters and means here work on records in memory; a record out of core
is reduced by :mod:`fsmbench.budget.long_record` in two sequential reads.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from fsmbench.filters import first_order_lowpass
from fsmbench.progress import advance
from fsmbench.signal.streaming import BLOCK_SAMPLES, read_blocks

__all__ = [
    "LazyTrim",
    "block_means",
    "finite_blocks",
    "is_lazy",
    "lowpass",
    "lowpass_rms",
    "trim_record",
]

FloatArray = NDArray[np.float64]


def is_lazy(x: Any) -> bool:
    """True for a Dask array (a record read out of core)."""
    return type(x).__module__.startswith("dask")


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


def lowpass(x: Any, *, cutoff_hz: float, fs_hz: float) -> FloatArray:
    """The ESRF study's first-order low pass (from rest) of a record in memory.

    Records out of core go through :class:`fsmbench.signal.streaming.LowpassStream`
    (:mod:`fsmbench.budget.long_record`), the same recursion block by block.
    """
    return first_order_lowpass(np.asarray(x, dtype=float), cutoff_hz=cutoff_hz, fs_hz=fs_hz)


def lowpass_rms(x: Any, *, cutoff_hz: float, fs_hz: float) -> float:
    """Rms about the mean of ``x`` after the ESRF study's first-order low pass (from rest)."""
    y = lowpass(x, cutoff_hz=cutoff_hz, fs_hz=fs_hz)
    return float(np.sqrt(np.mean((y - y.mean()) ** 2)))


def block_means(x: Any, *, per: int) -> FloatArray:
    """Means of consecutive blocks of ``per`` samples (the incomplete tail dropped), shape (nb,)."""
    nb = int(x.shape[0]) // per
    if nb == 0:
        return np.zeros(0)
    return np.asarray(x[: nb * per], dtype=float).reshape(nb, per).mean(axis=1)


def finite_blocks(signals: Mapping[str, Any], *, name: str, start: int, stop: int,
                  fs_hz: float, what: str, block_samples: int = BLOCK_SAMPLES,
                  progress: Callable[[str], None] | None = None,
                  ) -> Iterator[tuple[int, dict[str, FloatArray]]]:
    """:func:`~fsmbench.signal.streaming.read_blocks`, each block checked finite, with progress.

    Parameters
    ----------
    signals : mapping of str to array_like or dask.array.Array, each shape (N,)
        The record's signals (one time axis).
    name : str
        Experiment name, for messages and progress.
    start, stop : int
        Sample range read.
    fs_hz : float
        Sampling rate [Hz]: progress is reported in seconds of record.
    what : str
        What the read is for, in the progress lines.
    block_samples : int
        Samples per block.
    progress : callable, optional
        Receives each read's progress (:func:`fsmbench.progress.advance`), once a
        block has been used.

    Raises
    ------
    ValueError
        Naming the signal and the record's first NaN or infinite sample.
    """
    for offset, block in read_blocks(signals, start=start, stop=stop,
                                     block_samples=block_samples):
        for k, x in block.items():
            if not np.all(np.isfinite(x)):
                first = start + offset + int(np.flatnonzero(~np.isfinite(x))[0])
                raise ValueError(f"{name}.{k} contains NaN or infinite samples (first at "
                                 f"sample {first}); remove or interpolate them")
        yield offset, block
        done = offset + next(iter(block.values())).size
        advance(progress, f"{name}: {what}", done / fs_hz, (stop - start) / fs_hz, "s")
