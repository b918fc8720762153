"""Least squares on a record whose noise is not white: the covariance from the residual's spectrum.

The ordinary least-squares covariance ``s² (XᵀX)⁻¹`` assumes white residuals.
A 4QD calibration's residual holds 1/f noise, drift and mains: its power
near the sweep's 0.2 Hz, where the regressor lives, is many times its
average, and the ordinary standard error is 5× optimistic (issue 20). The
estimate's error is ``(XᵀX)⁻¹ Xᵀ e``; for a stationary ``e`` whose DFT lines
are uncorrelated with variances ``n σ²_k`` (``σ²_k`` the two-sided spectral
density in variance per sample),

    cov(Xᵀ e) = (1/n) Σ_k X_kᴴ X_k σ²_k,

with ``X_k`` the DFT (unnormalised) of the columns at line ``k`` — the
*spectral sandwich* (a heteroskedasticity-and-autocorrelation-consistent
covariance in the frequency domain; for white noise it is ``σ² XᵀX``).
``σ²_k`` is estimated from the residual's periodogram: at the lines where a
column of interest lives the residual is suppressed by the fit itself, so
each such line takes the mean of the nearest ``neighbours`` lines on each
side that the fit leaves (their periodogram divided by ``1 − ℓ_k``, the
share the fit removes), through a local power law; elsewhere the
periodogram averaged over ±``neighbours`` lines.
The few lines averaged give the variance estimate ~``4 neighbours`` degrees
of freedom.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

__all__ = ["spectral_sandwich"]

FloatArray = NDArray[np.float64]

#: A line is set apart when the fit removes more than this share of its noise (a sine over
#: whole periods: 0.5 of its line's; a constant: all of line 0).
_DEPLETED = 0.4
#: The power law through the neighbours is used when they span at least this ratio of
#: frequencies; closer together, their mean (a slope read over a narrow span extrapolates
#: its noise).
_MIN_SPAN = 1.5
#: ... with its exponent within these (white noise 0, 1/f -1, a random walk -2).
_SLOPE_RANGE = (-2.5, 0.5)
#: Lines carrying more than this fraction of the columns' strongest power get the local
#: power law; the rest (their share of the variance below ~1e-6) the running mean.
_IMPORTANT = 1e-6
#: E[ln P] = ln σ² − γ for a periodogram line (exponential, 2 degrees of freedom).
_EULER_GAMMA = 0.5772156649015329
#: ... and var[ln P] = π²/6 (trigamma(1)).
_LOG_LINE_VARIANCE = math.pi**2 / 6.0
#: A local slope is used when it is this many of its standard deviations from zero.
_SLOPE_T = 2.0


def _local_power_law(lines: NDArray[np.intp], power: FloatArray, *, at: int) -> float:
    """The noise density at line ``at`` from a straight line through ``(ln k, ln P_k)``
    of nearby lines (1/f noise and drift are power laws; white noise a flat one)."""
    lk = np.log(lines.astype(float))
    lp = np.log(np.maximum(power, np.finfo(float).tiny)) + _EULER_GAMMA
    if lines.size < 3 or np.ptp(lk) < np.log(_MIN_SPAN):
        return float(np.mean(power))
    centred = lk - lk.mean()
    sxx = float(np.sum(centred**2))
    slope = float(np.sum(centred * (lp - lp.mean())) / sxx)
    # A slope the lines do not resolve (|t| < 2 against the log-periodogram's π²/6 per
    # line) is white noise's: their mean is then read, not a power law whose random slope
    # moves the estimate by tens of % (the lines' log-spacing puts the nearest far out).
    if abs(slope) < _SLOPE_T * math.sqrt(_LOG_LINE_VARIANCE / sxx):
        return float(np.mean(power))
    slope = float(np.clip(slope, *_SLOPE_RANGE))
    return float(np.exp(np.mean(lp - slope * lk) + slope * np.log(at)))


def spectral_sandwich(design: FloatArray, residual: FloatArray, *,
                      columns: Sequence[int], neighbours: int = 5) -> FloatArray:
    """Covariance of the least-squares coefficients for a coloured residual (see the module).

    Parameters
    ----------
    design : ndarray, shape (n, p)
        The regressors ``X`` [their units].
    residual : ndarray, shape (n,)
        The fit's residual ``y − X β`` [unit of y].
    columns : sequence of int
        Columns whose lines are set apart (the slopes of interest; not a
        constant or a trend, whose lines are the noise's lowest).
    neighbours : int
        Lines each side averaged for the noise density (≥ 1).

    Returns
    -------
    ndarray, shape (p, p)
        ``(XᵀX)⁻¹ [(1/n) Σ_k X_kᴴ X_k σ²_k] (XᵀX)⁻¹`` [units of β²].
    """
    x = np.asarray(design, dtype=float)
    r = np.asarray(residual, dtype=float)
    n = r.size
    if x.shape[0] != n:
        raise ValueError(f"design has {x.shape[0]} rows, the residual {n} samples")
    if neighbours < 1:
        raise ValueError(f"neighbours must be >= 1, got {neighbours}")
    xk = np.fft.rfft(x, axis=0)  # (K, p)
    bread = np.linalg.inv(x.T @ x)
    # The fit removes from each line its leverage ℓ_k = X_kᴴ (XᵀX)⁻¹ X_k / n of the noise
    # (E|R_k|² = n σ²_k (1 − ℓ_k) for a smooth σ²): undone before the density is read.
    leverage = np.einsum("ki,ij,kj->k", xk.conj(), bread, xk).real / n
    pk = np.abs(np.fft.rfft(r)) ** 2 / n  # (K,) periodogram, variance per sample
    k = pk.size
    occupied = leverage > _DEPLETED
    occupied[0] = True  # the mean's line
    restored = pk / np.clip(1.0 - leverage, 1.0 - _DEPLETED, None)
    # Everywhere: the mean of the free lines within ±neighbours (cumulative sums) ...
    csum = np.concatenate([[0.0], np.cumsum(np.where(occupied, 0.0, restored))])
    ccount = np.concatenate([[0], np.cumsum(~occupied)])
    lo = np.clip(np.arange(k) - neighbours, 0, k)
    hi = np.clip(np.arange(k) + neighbours + 1, 0, k)
    count = ccount[hi] - ccount[lo]
    density = np.where(count > 0, (csum[hi] - csum[lo]) / np.maximum(count, 1),
                       float(np.mean(restored[~occupied])) if (~occupied).any() else 0.0)
    # ... and where the columns of interest live, a local power law through the nearest
    # free lines (the lines that carry the estimate; a handful).
    interest = np.zeros(k)
    for c in columns:
        interest += np.abs(xk[:, c]) ** 2
    important = np.flatnonzero(occupied | (interest > _IMPORTANT * interest.max()))
    free = np.flatnonzero(~occupied)
    if free.size:
        for i in important:
            j = int(np.searchsorted(free, i))
            window = free[max(0, j - 2 * neighbours):j + 2 * neighbours]
            near = window[np.argsort(np.abs(window - i), kind="stable")[:2 * neighbours]]
            density[i] = _local_power_law(near, restored[near], at=max(int(i), 1))
    # One-sided lines count twice, except 0 and (even n) Nyquist.
    weight = np.full(k, 2.0)
    weight[0] = 1.0
    if n % 2 == 0:
        weight[-1] = 1.0
    meat = np.einsum("k,ki,kj->ij", weight * density, xk.conj(), xk).real / n
    return np.asarray(bread @ meat @ bread, dtype=float)
