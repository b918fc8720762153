"""MATLAB's ``pwelch``, ``cpsd``, ``tfestimate`` and ``mscohere``, for NumPy and Dask arrays.

Each returns the numbers MATLAB's function of the same name returns for the same
arguments (real input, one-sided spectra, ``[]`` meaning "MATLAB default"). One
function per estimator whatever the array: a Dask array (a record out of core,
chunked along time in any way) is estimated over its chunks by
:mod:`fsmbench.signal.welch_dask` (the ``dask`` extra, imported only then), equal to
the in-memory estimate to floating-point reordering (~1e-15 relative), with the same
checks and the same messages. The windows, options and the engine are
:mod:`fsmbench.signal.welch_core`'s, re-exported here.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fsmbench.signal.welch_core import (
    SpectrumResult,
    WelchOptions,
    _as_signal,
    _check_has_power,
    _check_record,
    _label,
    _result,
    cross_spectral_density,
    default_nfft,
    default_noverlap,
    effective_averages,
    hamming,
    hann,
    hanning,
    segment_sums,
)

__all__ = [
    "SpectrumResult",
    "WelchOptions",
    "cpsd",
    "cross_spectral_density",
    "default_nfft",
    "default_noverlap",
    "effective_averages",
    "hamming",
    "hann",
    "hanning",
    "is_dask_array",
    "mscohere",
    "pwelch",
    "segment_sums",
    "tfestimate",
]


def is_dask_array(x: object) -> bool:
    """Whether ``x`` is a Dask array (told by its type's module: Dask is an optional extra)."""
    return type(x).__module__.split(".", 1)[0] == "dask"


def _pairwise(
    arrays: Sequence[tuple[ArrayLike, str | None, str]],
    *,
    window: int | ArrayLike,
    noverlap: int | None,
    nfft: int | None,
    fs_hz: float,
    min_segments: int = 1,
    need_power: Sequence[bool] = (),
    segments_per_task: int | None = None,
) -> tuple[WelchOptions, NDArray[np.complex128], int]:
    if any(is_dask_array(x) for x, _name, _role in arrays):
        # A record out of core: the same estimate over its chunks (the dask extra's seam).
        from fsmbench.signal.welch_dask import pairwise_dask

        return pairwise_dask(arrays, window=window, noverlap=noverlap, nfft=nfft, fs_hz=fs_hz,
                             min_segments=min_segments, need_power=need_power,
                             segments_per_task=segments_per_task)
    options = WelchOptions.from_matlab(window=window, noverlap=noverlap, nfft=nfft, fs_hz=fs_hz)
    checked = [(_label(nm, role), _as_signal(x, name=nm, role=role)) for x, nm, role in arrays]
    _check_record(checked, options, min_segments=min_segments)
    for (who, arr), need in zip(checked, need_power, strict=False):
        if need:
            _check_has_power(arr, who)
    s, k = cross_spectral_density(np.stack([arr for _, arr in checked]), options)
    return options, s, k


def pwelch(
    x: ArrayLike,
    *,
    window: int | ArrayLike,
    noverlap: int | None = None,
    nfft: int | None = None,
    fs_hz: float,
    x_name: str | None = None,
    segments_per_task: int | None = None,
) -> SpectrumResult:
    """MATLAB ``[pxx, f] = pwelch(x, window, noverlap, nfft, fs)`` for real ``x``.

    Parameters
    ----------
    x : array_like or dask.array.Array, shape (N,)
        Real record, unit U_x. Not detrended (MATLAB does not remove the mean).
    window : int or array_like, shape (L,)
        Integer ``L`` means ``hamming(L)``; an array is used as is.
    noverlap : int, optional
        Overlap, samples; ``None`` is MATLAB's ``[]`` (``floor(L/2)``).
    nfft : int, optional
        FFT length, samples; ``None`` is ``max(256, 2^nextpow2(L))``.
    fs_hz : float
        Sampling frequency, Hz.
    x_name : str, optional
        Signal name used in error messages.
    segments_per_task : int, optional
        Dask arrays only: consecutive segments summed by one task
        (:func:`fsmbench.signal.welch_dask.cross_spectral_density_dask`).

    Returns
    -------
    SpectrumResult
        ``values``: one-sided PSD, U_x^2/Hz, shape (nfft//2 + 1,).
    """
    options, s, k = _pairwise(
        [(x, x_name, "x")], window=window, noverlap=noverlap, nfft=nfft, fs_hz=fs_hz,
        segments_per_task=segments_per_task,
    )
    return _result(options, np.ascontiguousarray(s[:, 0, 0].real), "psd", k)


def cpsd(
    x: ArrayLike,
    y: ArrayLike,
    *,
    window: int | ArrayLike,
    noverlap: int | None = None,
    nfft: int | None = None,
    fs_hz: float,
    x_name: str | None = None,
    y_name: str | None = None,
    segments_per_task: int | None = None,
) -> SpectrumResult:
    """MATLAB ``[pxy, f] = cpsd(x, y, window, noverlap, nfft, fs)`` for real signals.

    MATLAB's convention: ``pxy`` averages ``X conj(Y)``, the complex conjugate
    of ``scipy.signal.csd(x, y)`` (which averages ``conj(X) Y``).

    Parameters
    ----------
    x, y : array_like, shape (N,)
        Real records of equal length, units U_x and U_y.
    window, noverlap, nfft, fs_hz
        As in :func:`pwelch`.
    x_name, y_name : str, optional
        Signal names used in error messages.
    segments_per_task : int, optional
        Dask arrays only, as in :func:`pwelch`.

    Returns
    -------
    SpectrumResult
        ``values``: complex one-sided CPSD, U_x U_y/Hz, shape (nfft//2 + 1,).
    """
    options, s, k = _pairwise(
        [(x, x_name, "x"), (y, y_name, "y")],
        window=window, noverlap=noverlap, nfft=nfft, fs_hz=fs_hz,
        segments_per_task=segments_per_task,
    )
    return _result(options, np.ascontiguousarray(s[:, 0, 1]), "cpsd", k)


def tfestimate(
    x: ArrayLike,
    y: ArrayLike,
    *,
    window: int | ArrayLike,
    noverlap: int | None = None,
    nfft: int | None = None,
    fs_hz: float,
    x_name: str | None = None,
    y_name: str | None = None,
    segments_per_task: int | None = None,
) -> SpectrumResult:
    """MATLAB ``[txy, f] = tfestimate(x, y, window, noverlap, nfft, fs)`` (H1 estimator).

    ``txy = Pyx / Pxx`` with ``Pyx = cpsd(y, x)`` (average of ``Y conj(X)``), so a
    pure delay of ``d`` samples gives the phase ``-2 pi f d / fs``.

    Parameters
    ----------
    x : array_like, shape (N,)
        Real input (excitation) record, unit U_x; must not be constant.
    y : array_like, shape (N,)
        Real output record, unit U_y.
    window, noverlap, nfft, fs_hz
        As in :func:`pwelch`.
    x_name, y_name : str, optional
        Signal names used in error messages.
    segments_per_task : int, optional
        Dask arrays only, as in :func:`pwelch`.

    Returns
    -------
    SpectrumResult
        ``values``: complex frequency response, U_y/U_x, shape (nfft//2 + 1,).
    """
    options, s, k = _pairwise(
        [(x, x_name, "input x"), (y, y_name, "output y")], window=window, noverlap=noverlap,
        nfft=nfft, fs_hz=fs_hz, need_power=(True, False), segments_per_task=segments_per_task,
    )
    return _result(options, s[:, 1, 0] / s[:, 0, 0].real, "tf", k)


def mscohere(
    x: ArrayLike,
    y: ArrayLike,
    *,
    window: int | ArrayLike,
    noverlap: int | None = None,
    nfft: int | None = None,
    fs_hz: float,
    x_name: str | None = None,
    y_name: str | None = None,
    segments_per_task: int | None = None,
) -> SpectrumResult:
    """MATLAB ``[cxy, f] = mscohere(x, y, window, noverlap, nfft, fs)``.

    ``cxy = |Pxy|^2 / (Pxx Pyy)``. MATLAB's documentation requires at least two
    segments (with one the estimate is identically 1); fewer raise here.

    Parameters
    ----------
    x, y : array_like, shape (N,)
        Real records of equal length; neither may be constant.
    window, noverlap, nfft, fs_hz
        As in :func:`pwelch`.
    x_name, y_name : str, optional
        Signal names used in error messages.
    segments_per_task : int, optional
        Dask arrays only, as in :func:`pwelch`.

    Returns
    -------
    SpectrumResult
        ``values``: magnitude-squared coherence in [0, 1], shape (nfft//2 + 1,).
    """
    options, s, k = _pairwise(
        [(x, x_name, "x"), (y, y_name, "y")], window=window, noverlap=noverlap, nfft=nfft,
        fs_hz=fs_hz, min_segments=2, need_power=(True, True),
        segments_per_task=segments_per_task,
    )
    coh = np.abs(s[:, 0, 1]) ** 2 / (s[:, 0, 0].real * s[:, 1, 1].real)
    return _result(options, coh, "coherence", k)
