"""Welch's segment sums on chunks of a record, without Dask.

Shared by the Dask graphs of :mod:`fsmbench.signal.welch_dask` (each task sums the
segments it owns) and the block-fed estimators of :mod:`fsmbench.signal.streaming`
(which records in memory use too, so this module must import without the
``dask`` extra).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from fsmbench.signal.welch_core import segment_sums as welch_segment_sums

__all__ = ["read_span", "segment_sums"]


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

    The accumulation of :func:`fsmbench.signal.welch_core.segment_sums` on the samples
    ``offset .. offset+length-1`` of the concatenated chunks.
    """
    data = read_span(pieces, offset, length)
    return welch_segment_sums(data, n_segments=n_seg, window=window, hop=hop, nfft=nfft)
