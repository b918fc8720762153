"""Noise processes: white, 1/f (flicker), Ornstein-Uhlenbeck, and the converters' grid."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy.signal import lfilter

__all__ = ["flicker", "ou", "quantise", "slow_ou", "uniform_lsb"]

Array = NDArray[np.float64]


def flicker(rng: np.random.Generator, n: int, fs_hz: float, asd_at_1hz: float,
            f_min_hz: float) -> Array:
    """1/f noise of one-sided ASD ``asd_at_1hz / sqrt(f)`` [unit/√Hz], flat below ``f_min_hz``.

    Shapes the spectrum of white Gaussian noise: a white sequence of unit
    variance has a one-sided PSD of ``2 / fs``, so each FFT line is scaled by
    ``sqrt(S(f) fs / 2)``. The mean (the DC line) is zero.
    """
    if asd_at_1hz == 0.0 or n < 2:
        return np.zeros(n)
    spec = np.fft.rfft(rng.standard_normal(n))
    f = np.fft.rfftfreq(n, 1.0 / fs_hz)
    psd = asd_at_1hz**2 / np.maximum(f, f_min_hz)
    scale = np.sqrt(psd * fs_hz / 2.0)
    scale[0] = 0.0
    return np.fft.irfft(spec * scale, n)


def ou(rng: np.random.Generator, n: int, dt_s: float, rms: float, tau_s: float) -> Array:
    """Stationary Ornstein-Uhlenbeck process sampled every ``dt_s`` (exact AR(1)).

    ``x[k] = a x[k-1] + rms sqrt(1 - a²) e[k]``, ``a = exp(-dt/tau)``, started
    from its stationary distribution.
    """
    if rms == 0.0:
        return np.zeros(n)
    a = math.exp(-dt_s / tau_s)
    e = rng.standard_normal(n) * rms * math.sqrt(1.0 - a * a)
    x0 = rng.standard_normal() * rms
    out, _ = lfilter([1.0], [1.0, -a], e, zi=[a * x0])
    return out


def slow_ou(rng: np.random.Generator, t_s: Array, rms: float, tau_s: float,
            rate_hz: float = 10.0) -> Array:
    """An OU process for ``tau_s`` ≫ the record, drawn at ``rate_hz`` and interpolated."""
    t_end = float(t_s[-1]) if len(t_s) else 0.0
    tc = np.arange(0.0, t_end + 2.0 / rate_hz, 1.0 / rate_hz)
    return np.interp(t_s, tc, ou(rng, len(tc), 1.0 / rate_hz, rms, tau_s))


def first_order(x: Array, dt_s: float, tau_s: float, x0: float) -> Array:
    """``x`` through ``1 / (1 + tau s)`` sampled exactly for a held input, from ``x0``."""
    a = math.exp(-dt_s / tau_s)
    out, _ = lfilter([0.0, 1.0 - a], [1.0, -a], x, zi=[a * x0])
    return out


def uniform_lsb(rng: np.random.Generator, shape: tuple[int, ...], lsb: float) -> Array:
    """Additive model of a converter's rounding: uniform on ``±lsb/2``."""
    return rng.uniform(-lsb / 2.0, lsb / 2.0, size=shape)


def quantise(x: Array, lsb: float, span: float | None = None) -> Array:
    """Round to the converter's grid and clip to its rails ``[-span/2, span/2 - lsb]``."""
    q = np.round(np.asarray(x) / lsb) * lsb
    if span is not None:
        q = np.clip(q, -span / 2.0, span / 2.0 - lsb)
    return q
