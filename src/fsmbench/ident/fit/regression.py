"""Least squares on a record whose noise is not white: the covariance from the residual's spectrum.

The ordinary least-squares covariance ``s² (XᵀX)⁻¹`` assumes white residuals.
A 4QD calibration's residual holds 1/f noise, drift and mains: its power
near the sweep's 0.2 Hz, where the regressor lives, is many times its
average, and the ordinary standard error is 5× optimistic. The
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
The few lines averaged give the variance estimate few degrees of freedom,
fewest where a power law is read at the record's lowest lines (a 4QD
calibration's sweep lives there, under 1/f noise and drift): the estimate's
*effective degrees of freedom* ``ν = 2 / var(ln V̂)`` follow from each line's
log-density variance (``π²/6`` times the log-log regression's leverage at the
line it is read at; ``1/m`` for a mean of ``m`` lines), combined over the
lines that carry a coefficient as fully correlated (they share their
neighbours; conservative). :meth:`SandwichCovariance.std` gives the standard
deviation whose ±1.96 interval is the 95 % interval of Student's t on ``ν``
(``t₀.₉₇₅(ν)/1.96`` times the standard error, as the GUM's expanded
uncertainty with effective degrees of freedom).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import stats

__all__ = ["SandwichCovariance", "spectral_sandwich", "t_scaled_std"]

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


@dataclass(frozen=True)
class SandwichCovariance:
    """The spectral sandwich's covariance and how well it is known.

    Attributes
    ----------
    covariance : ndarray, shape (p, p)
        Covariance of the coefficients [units of β²].
    dof : ndarray, shape (p,)
        Effective degrees of freedom of each diagonal element (module notes).
    """

    covariance: FloatArray
    dof: FloatArray

    def std(self, column: int) -> float:
        """Standard deviation of one coefficient [its unit], t-scaled to its degrees of
        freedom (:func:`t_scaled_std`)."""
        return t_scaled_std(math.sqrt(max(float(self.covariance[column, column]), 0.0)),
                            float(self.dof[column]))


def t_scaled_std(std: float, dof: float) -> float:
    """``std × t₀.₉₇₅(ν) / z₀.₉₇₅``: the standard deviation whose ±1.96 interval is the 95 %
    interval of an estimate whose variance is read on ``dof`` degrees of freedom [unit of
    ``std``]; ``std`` itself for infinite ``dof``."""
    if not math.isfinite(dof):
        return std
    return float(std * stats.t.ppf(0.975, max(dof, 1.0)) / stats.norm.ppf(0.975))


def _local_power_law(lines: NDArray[np.intp], power: FloatArray, *, at: int
                     ) -> tuple[float, float]:
    """The noise density at line ``at`` from a straight line through ``(ln k, ln P_k)``
    of nearby lines (1/f noise and drift are power laws; white noise a flat one), and the
    variance of its log."""
    lk = np.log(lines.astype(float))
    lp = np.log(np.maximum(power, np.finfo(float).tiny)) + _EULER_GAMMA
    if lines.size < 3 or np.ptp(lk) < np.log(_MIN_SPAN):
        return float(np.mean(power)), 1.0 / max(lines.size, 1)
    centred = lk - lk.mean()
    sxx = float(np.sum(centred**2))
    slope = float(np.sum(centred * (lp - lp.mean())) / sxx)
    # A slope the lines do not resolve (|t| < 2 against the log-periodogram's π²/6 per
    # line) is white noise's: their mean is then read, not a power law whose random slope
    # moves the estimate by tens of % (the lines' log-spacing puts the nearest far out).
    if abs(slope) < _SLOPE_T * math.sqrt(_LOG_LINE_VARIANCE / sxx):
        return float(np.mean(power)), 1.0 / lines.size
    slope = float(np.clip(slope, *_SLOPE_RANGE))
    x0 = math.log(at)
    leverage = 1.0 / lines.size + (x0 - float(lk.mean())) ** 2 / sxx
    return (float(np.exp(np.mean(lp - slope * lk) + slope * x0)),
            _LOG_LINE_VARIANCE * leverage)


def spectral_sandwich(design: FloatArray, residual: FloatArray, *,
                      columns: Sequence[int], neighbours: int = 5) -> SandwichCovariance:
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
    SandwichCovariance
        ``(XᵀX)⁻¹ [(1/n) Σ_k X_kᴴ X_k σ²_k] (XᵀX)⁻¹`` [units of β²] and the
        effective degrees of freedom of its diagonal (module notes).
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
    log_var = 1.0 / np.maximum(count, 1).astype(float)
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
            density[i], log_var[i] = _local_power_law(near, restored[near],
                                                      at=max(int(i), 1))
    # One-sided lines count twice, except 0 and (even n) Nyquist.
    weight = np.full(k, 2.0)
    weight[0] = 1.0
    if n % 2 == 0:
        weight[-1] = 1.0
    meat = np.einsum("k,ki,kj->ij", weight * density, xk.conj(), xk).real / n
    covariance = np.asarray(bread @ meat @ bread, dtype=float)
    # Each coefficient's variance is Σ_k a_k σ²_k (a_k ≥ 0); the relative variance of its
    # estimate, the lines' log-density errors fully correlated, (Σ a_k σ²_k √v_k / Σ a_k σ²_k)².
    share = np.abs(xk @ bread) ** 2 * (weight * density)[:, None] / n  # (K, p)
    total = share.sum(axis=0)
    spread = (share * np.sqrt(log_var)[:, None]).sum(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        rel_var = np.where(total > 0, (spread / np.where(total > 0, total, 1.0)) ** 2, 0.0)
        dof = np.where(rel_var > 0, 2.0 / np.where(rel_var > 0, rel_var, 1.0), np.inf)
    return SandwichCovariance(covariance=covariance, dof=np.asarray(dof, dtype=float))
