"""The segment arithmetic of Welch's method on chunks of a record, without Dask.

Shared by the Dask graphs of :mod:`fsmbench.scale.welch` (each task sums the
segments it owns) and the block-fed estimators of :mod:`fsmbench.scale.streaming`
(which records in memory use too, so this module must import without the
``dask`` extra).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.fft
from numpy.typing import NDArray

__all__ = ["read_span", "segment_sums"]

# Windowed segments transformed at once: about 64 MiB of complex spectra.
_BLOCK_BYTES = 1 << 26


def read_span(pieces: Sequence[NDArray[np.float64]], offset: int,
              length: int) -> NDArray[np.float64]:
    """Samples ``offset .. offset+length-1`` of the concatenated chunks (time on the last axis)."""
    if length == 0:
        return np.zeros((0,), dtype=np.float64)
    if len(pieces) == 1:
        return pieces[0][..., offset : offset + length]
    first = pieces[0][..., offset:]
    return np.concatenate([first, *pieces[1:]], axis=-1)[..., :length]


def segment_sums(
    pieces: Sequence[NDArray[np.float64]], offset: int, length: int, n_seg: int,
    window: NDArray[np.float64], hop: int, nfft: int,
) -> NDArray[np.complex128]:
    """Unscaled ``sum_k X_a conj(X_b)`` over ``n_seg`` segments, shape (c, c, nfft//2 + 1).

    Mirrors the accumulation of :func:`fsmbench.ident.welch.cross_spectral_density`
    (same windowing, datawrap, rfft and ``re^2 + im^2`` diagonal); keep them in step.
    """
    data = read_span(pieces, offset, length)
    c = data.shape[0]
    win_len = window.size
    n_freq = nfft // 2 + 1
    acc = np.zeros((c, c, n_freq), dtype=np.complex128)
    segments = np.lib.stride_tricks.sliding_window_view(data, win_len, axis=1)[:, ::hop][:, :n_seg]
    block = max(1, _BLOCK_BYTES // (16 * c * n_freq))
    for k0 in range(0, n_seg, block):
        windowed = segments[:, k0 : k0 + block] * window
        if nfft < win_len:
            pad = -win_len % nfft
            windowed = np.pad(windowed, ((0, 0), (0, 0), (0, pad)))
            windowed = windowed.reshape(c, windowed.shape[1], -1, nfft).sum(axis=2)
        spectra = scipy.fft.rfft(windowed, n=nfft, axis=-1)
        for a in range(c):
            acc[a, a] += (spectra[a].real ** 2 + spectra[a].imag ** 2).sum(axis=0)
            for b in range(a + 1, c):
                acc[a, b] += (spectra[a] * spectra[b].conj()).sum(axis=0)
    for a in range(c):
        for b in range(a):
            acc[a, b] = acc[b, a].conj()
    return acc
