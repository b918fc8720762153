"""The budget's spectral helpers: the ESRF study's Welch estimate, low pass, cumulative power.

Conventions (used by every module of :mod:`fsmbench.budget`):

* A *one-sided* PSD ``S1(f)`` [U²/Hz] integrates over ``0 ≤ f ≤ fs/2`` to the
  variance; it is what MATLAB's ``pwelch`` returns. The ESRF study's quantisation
  density ``Γ = q²/(12 fs)`` (eqs. 12–15) is *two-sided*: it integrates over
  ``−fs/2 … fs/2`` (ESRF study 4.5a), so ``S1 = 2Γ``.
* The ESRF study's cumulative power ``cps = 1/π ∫ asd² dω = 2 ∫ asd² df`` (4.5c) is
  the cumulative power of the one-sided density ``2·asd²``.
* Drifts seen over a record of length T with its mean removed: the expected
  variance is ``∫ S1(f)·(1 − sinc²(f T)) df`` (the mean over T is a filter
  with response ``sinc(f T)``; removing it leaves ``1 − sinc²``).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.integrate import cumulative_trapezoid, trapezoid

from fsmbench.filters import first_order_lowpass
from fsmbench.signal.welch import SpectrumResult, hanning, is_dask_array, pwelch

__all__ = [
    "cumulative_power",
    "esrf_welch",
    "first_order_lowpass",
    "gauss_markov_psd",
    "window_variance",
    "window_weight",
]

FloatArray = NDArray[np.float64]


def esrf_welch(x: ArrayLike, *, fs_hz: float, name: str = "x") -> SpectrumResult:
    """The ESRF study's ``pwelch(x, hanning(ceil(1*fs)), [], [], fs)`` (3.5, 11.3).

    Parameters
    ----------
    x : array_like, shape (N,)
        Record (unit U), ``N ≥ ceil(fs)``.
    fs_hz : float
        Sampling frequency [Hz].
    name : str
        Signal name for error messages.

    Returns
    -------
    SpectrumResult
        One-sided PSD [U²/Hz] on ``(0:nfft/2)·fs/nfft`` (nfft = 16384 at 10 kHz).
    """
    n_win = math.ceil(1.0 * fs_hz)
    # A Dask array (a record out of core) is estimated over its chunks, equal to 1e-12.
    record = x if is_dask_array(x) else np.asarray(x, dtype=float)
    return pwelch(record, window=hanning(n_win), fs_hz=fs_hz, x_name=name)




def cumulative_power(f_hz: ArrayLike, psd: ArrayLike) -> FloatArray:
    """Cumulative power ``∫_{f0}^{f} S1 df`` (trapezoid, the ESRF study's ``cumtrapz``).

    ``f_hz`` shape (F,), ``psd`` shape (F,) one-sided [U²/Hz]; returns shape
    (F,) [U²], starting at 0. Its square root is the cumulative rms.
    """
    f = np.asarray(f_hz, dtype=float)
    s = np.asarray(psd, dtype=float)
    return np.asarray(cumulative_trapezoid(s, f, initial=0.0), dtype=float)


def window_weight(f_hz: ArrayLike, *, window_s: float | None) -> FloatArray:
    """``1 − sinc²(f T)``: share of a frequency left after removing the mean over T [1].

    ``window_s=None`` means an infinite record (weight 1). ``f_hz`` any shape.
    """
    f = np.asarray(f_hz, dtype=float)
    if window_s is None:
        return np.ones_like(f)
    if not window_s > 0:
        raise ValueError(f"window_s must be > 0 or None, got {window_s}")
    return np.asarray(1.0 - np.sinc(f * window_s) ** 2, dtype=float)


def gauss_markov_psd(f_hz: ArrayLike, *, rms: float, tau_s: float) -> FloatArray:
    """One-sided PSD of a first-order Gauss-Markov process, ``4σ²τ/(1 + (2πfτ)²)``.

    Integrates to ``σ²`` over ``0 … ∞`` (the twin's ``gauss_markov``, its
    sampling aside). ``f_hz`` any shape [Hz]; result [U²/Hz].
    """
    f = np.asarray(f_hz, dtype=float)
    return np.asarray(4.0 * rms**2 * tau_s / (1.0 + (2.0 * np.pi * f * tau_s) ** 2), dtype=float)


def window_variance(psd_fn: object, *, window_s: float | None, f_max_hz: float,
                    f_min_hz: float = 1e-9, n: int = 6000) -> float:
    """Expected variance ``∫ S1(f)(1 − sinc²(f T)) df`` of a mean-removed record of length T.

    Parameters
    ----------
    psd_fn : callable
        ``psd_fn(f_hz) -> S1`` one-sided PSD [U²/Hz], vectorised.
    window_s : float or None
        Record length T [s]; None for the stationary variance.
    f_max_hz : float
        Upper limit [Hz] (the Nyquist frequency of the record).
    f_min_hz : float
        Lower limit [Hz]; far below every corner of ``psd_fn``.
    n : int
        Points of the logarithmic grid (integrated as ``∫ S f d(ln f)``).

    Returns
    -------
    float
        Variance [U²].
    """
    if not callable(psd_fn):
        raise TypeError("psd_fn must be callable")
    f = np.logspace(math.log10(f_min_hz), math.log10(f_max_hz), n)
    integrand = np.asarray(psd_fn(f), dtype=float) * window_weight(f, window_s=window_s) * f
    return float(trapezoid(integrand, np.log(f)))
