"""Filters shared by the twin and the analyses: exact discretisations, vectorised."""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.signal import lfilter, lfilter_zi

__all__ = ["first_order_lowpass"]

FloatArray = NDArray[np.float64]

def first_order_lowpass(x: ArrayLike, *, cutoff_hz: float, fs_hz: float,
                        initial: Literal["zero", "steady"] = "zero") -> FloatArray:
    """``1/(1 + s/(2π f0))`` applied to a sampled record, exactly discretised (seed 3.3, 11.6).

    The seed calls ``lsim(G_lpf, x, t)``; for a non-smooth input MATLAB holds
    each sample (zero-order hold) and starts from a zero state. The exact
    step-invariant discretisation is ``y[k+1] = a·y[k] + (1 − a)·x[k]`` with
    ``a = exp(−2π f0 T)``, run here by :func:`scipy.signal.lfilter`.

    Parameters
    ----------
    x : array_like, shape (N,)
        Input record (unit U).
    cutoff_hz : float
        Corner frequency f0 [Hz] (> 0).
    fs_hz : float
        Sampling frequency [Hz] (> 0).
    initial : {"zero", "steady"}
        ``"zero"``: ``y[0] = 0`` (``lsim``); ``"steady"``: ``y[0] = x[0]``, the
        filter starts in equilibrium (no start-up transient).

    Returns
    -------
    ndarray, shape (N,)
        Filtered record (unit U).
    """
    if not (cutoff_hz > 0 and fs_hz > 0):
        raise ValueError(f"cutoff_hz and fs_hz must be > 0, got {cutoff_hz}, {fs_hz}")
    if initial not in ("zero", "steady"):
        raise ValueError(f"initial must be 'zero' or 'steady', not {initial!r}")
    u = np.asarray(x, dtype=float)
    a = math.exp(-2.0 * math.pi * cutoff_hz / fs_hz)
    b_coef, a_coef = [0.0, 1.0 - a], [1.0, -a]
    if initial == "zero" or u.size == 0:
        return np.asarray(lfilter(b_coef, a_coef, u), dtype=float)
    y, _ = lfilter(b_coef, a_coef, u, zi=lfilter_zi(b_coef, a_coef) * u[0])
    return np.asarray(y, dtype=float)
