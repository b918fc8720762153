"""The noise's leakage across neighbouring lines, removed from closed-loop periodic data.

With the loop closed around a lightly damped, notched resonance, the noise near
it is narrowband (the closed loop's slowest mode: ~0.75 s on the twin, 0.2 Hz
wide). Over a record of ``P`` whole periods, the DFT of such a process is its
spectrum sampled on the record's bins *plus* the leakage of the record's two
edges, a term ``T(k)`` that is a smooth (rational) function of the bin, the
same one on every neighbouring line: the "transient" of the local polynomial
method (Pintelon, Schoukens, Vandersteen, Barbé, *IEEE Trans. Instrum. Meas.*
59(11), 2010; for periodic excitations Pintelon, Vandersteen, Schoukens,
Rolain, *MSSP* 25(7), 2011). The periods' mean is that record's DFT on the
excited bins, so averaging the periods keeps ``T``: the neighbouring lines'
errors are the same leakage (|correlation| 0.7-0.8 on the twin), and the
periods' scatter, which sees each period's own edges, overstates the mean's
variance (5-15 times near the resonances).

:func:`leakage_corrected_lines` estimates ``T`` where the excitation is not:
on the ``2 m`` bins of the whole record nearest each excited bin that are not a
harmonic of the period (only noise and leakage there: the nonlinear distortion
of a periodic excitation lands on harmonics), a polynomial of degree ``R`` in
the bin offset per signal. Its value at the excited bin is subtracted; the
residuals' covariance (``2 m - R - 1`` degrees of freedom) is the noise's, and
the corrected line's covariance is that times ``1 + h`` (``h`` the
interpolation's leverage).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["LeakageCorrected", "LeakageOptions", "leakage_corrected_lines", "mean_variance"]


@dataclass(frozen=True)
class LeakageOptions:
    """The local model of the leakage around each excited line.

    Attributes
    ----------
    neighbours : int
        Non-harmonic bins of the whole record used on each side of an excited bin
        (``m``): ``P - 1`` on each side are the bins between two harmonics.
    degree : int
        Degree of the local polynomial in the bin offset (``R``): 2 follows a
        ``1/(f - f_r)`` leakage to a few per cent half a hertz from the resonance.
    smoothing_lines : int
        The noise's covariance averaged over this many neighbouring excited lines
        (odd; 1: each line's own neighbours only).
    """

    neighbours: int = 5
    degree: int = 2
    smoothing_lines: int = 1

    @property
    def dof(self) -> float:
        """Degrees of freedom of one line's noise covariance, ``2 m - R - 1``."""
        return float(2 * self.neighbours - self.degree - 1)

    def to_json(self) -> dict[str, Any]:
        """Plain values."""
        return {"neighbours": self.neighbours, "degree": self.degree,
                "smoothing_lines": self.smoothing_lines, "dof": self.dof}

    def __post_init__(self) -> None:
        if self.degree < 0 or self.neighbours < 1:
            raise ValueError(f"the leakage model needs a degree >= 0 and >= 1 neighbour per "
                             f"side, got degree {self.degree}, {self.neighbours} neighbours")
        if self.smoothing_lines < 1 or self.smoothing_lines % 2 == 0:
            raise ValueError(f"smoothing_lines must be odd and positive, got "
                             f"{self.smoothing_lines}")
        if 2 * self.neighbours - (self.degree + 1) < 2:
            raise ValueError(f"{2 * self.neighbours} neighbouring bins leave fewer than 2 "
                             f"degrees of freedom to a degree-{self.degree} polynomial")


@dataclass(frozen=True, eq=False)
class LeakageCorrected:
    """One record's excited lines with the leakage removed.

    Attributes
    ----------
    z : ndarray, complex, shape (F, q)
        The signals' normalised DFT over the whole record on each excited bin, the
        local leakage removed (the periods' mean times ``sqrt(P)``) [V].
    r : ndarray, complex, shape (F,)
        The excitation's, same scale [V].
    noise_cov : ndarray, complex, shape (F, q, q)
        The noise's covariance on one bin of the whole record, from the residuals
        of the local fits [V²].
    leverage : ndarray, shape (F,)
        ``h``: the corrected line's covariance is ``noise_cov (1 + h)`` [1].
    dof : float
        Degrees of freedom of ``noise_cov`` per line, ``2 m - R - 1``.
    """

    z: NDArray[np.complex128]
    r: NDArray[np.complex128]
    noise_cov: NDArray[np.complex128]
    leverage: NDArray[np.float64]
    dof: float


def _offsets(periods: int, neighbours: int) -> NDArray[np.intp]:
    """The ``2 m`` non-harmonic bin offsets nearest 0, ``m`` each side, sorted."""
    side = [d for d in range(1, neighbours * periods + 1) if d % periods][:neighbours]
    return np.array(sorted([-d for d in side] + side), dtype=np.intp)


def leakage_corrected_lines(excitation: NDArray[np.float64], signals: NDArray[np.float64], *,
                            periods: int, lines: NDArray[np.intp],
                            options: LeakageOptions | None = None) -> LeakageCorrected:
    """The excited lines of ``P`` whole periods with the noise's leakage removed (module notes).

    Parameters
    ----------
    excitation : ndarray, shape (P n,)
        The excitation over the periods kept [V].
    signals : ndarray, shape (P n, q)
        The recorded signals over the same samples (e.g. ``[y, u]``) [V].
    periods : int
        ``P``, whole periods in the samples given (at least 2).
    lines : ndarray of int, shape (F,)
        The excited lines on the period's grid (line ``l`` is bin ``P l`` of the record).
    options : LeakageOptions, optional

    Raises
    ------
    ValueError
        Fewer than 2 periods, samples not a whole number of periods, signals of another
        length, or a line whose neighbours fall outside the record's band.
    """
    opts = options or LeakageOptions()
    x = np.asarray(excitation, dtype=float)
    z = np.asarray(signals, dtype=float)
    if periods < 2 or x.size % periods:
        raise ValueError(f"{x.size} samples are not {periods} (>= 2) whole periods")
    if z.ndim != 2 or z.shape[0] != x.size:
        raise ValueError(f"the signals {z.shape} must be ({x.size}, q)")
    length = x.size
    r_all = np.fft.rfft(x) / math.sqrt(length)
    z_all = np.fft.rfft(z, axis=0) / math.sqrt(length)
    bins = periods * np.asarray(lines, dtype=np.intp)
    off = _offsets(periods, opts.neighbours)
    idx = bins[:, None] + off[None, :]
    # Near DC or Nyquist the window slides by whole periods: it stays between harmonics.
    below = np.maximum(1 - idx.min(axis=1), 0)
    above = np.maximum(idx.max(axis=1) - (r_all.size - 1), 0)
    idx = idx + (-(-below // periods) * periods - (-(-above // periods)) * periods)[:, None]
    if idx.min() < 1 or idx.max() > r_all.size - 1:
        raise ValueError(f"the record ({periods} periods) is too short for "
                         f"{opts.neighbours} neighbouring bins per side of each line")
    d = (idx - bins[:, None]) / float(off.max())
    powers = d[:, :, None] ** np.arange(opts.degree + 1)[None, None, :]  # (F, W, R+1)
    pinv = np.linalg.pinv(powers)  # (F, R+1, W)
    zw = z_all[idx]  # (F, W, q)
    coef = pinv @ zw  # (F, R+1, q)
    resid = zw - powers @ coef
    dof = float(off.size - (opts.degree + 1))
    cov = _smooth(np.einsum("fwa,fwb->fab", resid, np.conj(resid)) / dof, opts.smoothing_lines)
    # The polynomial at the excited bin (offset 0): its constant term; its variance over
    # the noise's is the leverage (pinv's first row squared).
    leverage = np.sum(np.abs(pinv[:, 0, :]) ** 2, axis=1)
    corrected = z_all[bins] - coef[:, 0, :]
    return LeakageCorrected(z=corrected, r=r_all[bins], noise_cov=cov, leverage=leverage,
                            dof=dof * opts.smoothing_lines)


def _smooth(x: NDArray[Any], width: int) -> NDArray[Any]:
    """Running mean over ``width`` neighbouring lines along axis 0 (shorter at the ends)."""
    if width <= 1:
        return x
    half = width // 2
    c = np.cumsum(np.concatenate([np.zeros((1, *x.shape[1:]), dtype=x.dtype), x]), axis=0)
    i = np.arange(x.shape[0])
    lo, hi = np.maximum(i - half, 0), np.minimum(i + half + 1, x.shape[0])
    return (c[hi] - c[lo]) / (hi - lo).reshape(-1, *([1] * (x.ndim - 1)))


def mean_variance(s0: NDArray[np.float64], c1: NDArray[np.float64],
                   periods: int) -> NDArray[np.float64]:
    """The variance of the mean of ``P`` periods' noise, consecutive periods correlated.

    Near a lightly damped resonance the noise on an excited line a few lines away is
    mostly the rectangular window's leakage of the resonance's narrowband noise: each
    period's DFT there is the difference of that process at the period's two edges,
    so consecutive periods share an edge with opposite signs (lag-1 correlation -1/2)
    and their sum telescopes. On the twin (12 seeds, the ESRF study's controller) the
    periods' scatter over ``P`` overstated the mean's variance 6.6-7.1 times at
    252.25 and 252.75 Hz (``P = 6``), and the fit underweighted the resonance lines.

    A stationary sequence with lag-1 autocovariance ``g1`` only (an MA(1), which the
    telescoping is) has ``var(mean) = (P g0 + 2 (P - 1) g1) / P^2``. From the deviations
    about the mean, ``s0 = sum |d_p|^2 / (P - 1)`` and ``c1 = Re sum d_p d_(p-1)^*``
    have expectations ``g0 - 2 g1 / P`` and ``-(P-1)/P g0 + k g1`` with
    ``k = (P-1) - 2 (2P-3)/P + 2 (P-1)^2/P^2`` (checked by simulation to 1 %), solved
    for ``g0``, ``g1``. Floored at ``s0 / P^2`` (a mean whose sum telescopes entirely);
    ``P < 3`` cannot separate the two: ``s0 / P``.

    ``s0``, ``c1`` (F, 2), already smoothed over neighbouring lines.
    """
    p = float(periods)
    if periods < 3:
        return s0 / p
    k = (p - 1.0) - 2.0 * (2.0 * p - 3.0) / p + 2.0 * (p - 1.0) ** 2 / p**2
    det = k - 2.0 * (p - 1.0) / p**2
    g0 = (k * s0 + 2.0 / p * c1) / det
    g1 = (c1 + (p - 1.0) / p * s0) / det
    out = (p * g0 + 2.0 * (p - 1.0) * g1) / p**2
    return np.maximum(out, s0 / p**2)
