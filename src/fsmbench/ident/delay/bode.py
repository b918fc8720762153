"""Pure delay of a frequency-response path from its phase, via the Bode gain-phase relation.

The seed removes a hard-coded delay before fitting models: ``Ts = 1e-4 s`` for the
Sercalo paths (2.3 d) and 0.5 ms for the Newport (2.4 d). This module measures it.

Principle
---------
A path ``H(s) = G(s) e^{-s tau}`` with ``G`` rational, stable and minimum phase has
``arg G`` fixed by ``ln|G| = ln|H|`` (Bode's gain-phase relation, a Hilbert transform
in log frequency ``u = ln(w/w0)``)::

    arg G(j w0) = (1/pi) * integral d ln|H|/du * ln coth(|u|/2) du

so ``arg H - arg G = phi0 - 2 pi f tau`` is a straight line in ``f`` whose slope is the
delay and whose offset ``phi0`` is a multiple of ``pi`` (``pi`` for a negative gain).
:func:`bode_minimum_phase` evaluates the integral exactly for ``ln|H|``
interpolated linearly in ``u`` between the measured bins (the kernel's primitive
is a dilogarithm, ``int_0^v ln coth(t/2) dt = pi^2/4 - 2 Li2(e^-v) + Li2(e^-2v)/2``);
:func:`estimate_delay_from_response` fits the line by weighted least squares.

Tails
-----
The integral runs over all frequencies, the data do not: outside the band the
log-magnitude is continued by the asymptotic expansion every rational function
has, ``ln|G| = a + n u + c e^{-2 (u - u_edge)} + O(e^{-4u})`` above the band (``|G|^2``
is rational in ``w^2``, so the corrections go in powers of ``1/w^2``) and the
mirror image below it, with ``n`` an integer (minus the relative degree above,
the low-frequency order below). ``a`` and ``c`` are fitted to the top and bottom
``tail_ratio`` (default a factor 1.6) of the band, and ``n``, unless given, is the
integer near the local slope that fits best. That region must be clear of
resonances; give ``high_frequency_slope`` when the relative degree is known
(-2 for both mirrors' paths): the choice of ``n`` is the fragile step.
A constant-slope continuation instead (the textbook truncation) confuses the
slow approach of a mode's roll-off to -40 dB/decade with extra phase lag: on
the twin's noise-free Sercalo FRF over 10-1000 Hz it gives 73 µs instead of 150 µs.

Assumptions (violations bias ``tau``, not its standard error)
------------------------------------------------------------
* ``G`` is minimum phase (zeros in the left half plane) up to its sign; a right
  half-plane zero at ``z`` Hz looks like an extra delay of about ``1/(pi z)`` s.
* Dynamics above the band follow the expansion above; a pole at ``p >> f_hi`` is
  indistinguishable from a delay of ``1/(2 pi p)`` and is counted as one
  (the twin's 125 kHz coil pole adds 1.3 µs).
* The band is below ~fs/4: a zero-order-held, sampled path equals ``G(jw) e^{-jwT/2}``
  times a real factor ``1 - O((wT)^2)`` that the Bode relation would read as extra
  roll-off. The half-sample hold delay is part of the delay found, so the
  twin's Sercalo paths give the DAC's 1e-4 s plus 0.5e-4 s.
* Bins where the estimate is unreliable are excluded from the line fit by
  coherence; lightly damped resonances smeared by the Welch window also get a
  low coherence there, and a robust (median-absolute-deviation) outlier cut
  removes the few bins left where the smeared magnitude and phase disagree.

``std_s`` is the random error of the line fit, scaled by the residual scatter
and by the correlation of neighbouring bins (``bins_per_independent``). On
noisy synthetic paths the actual scatter is ~1.3x ``std_s`` (the Bode phase
inherits magnitude noise correlated over many bins, which the line fit does
not model). It does not include the systematic error of the tails and of
sampling: on the twin (seed's 1 s Welch estimates, automatic bands) the
estimates are 3.6 and 6.2 µs short of the Sercalo's 150 µs and 7.2 and 8.7 µs
short of the Newport's 500 µs, while ``std_s`` is 0.2-0.6 µs. The band should
reach ~2.5x the highest mode or pole frequency (the tail expansion converges
above it): for the Newport (poles at 0.68 and 1.7 kHz) a band ending at 1 kHz
gives ~560 µs.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike, NDArray
from scipy.special import spence

from fsmbench.ident.frf.response import FrequencyResponse

__all__ = [
    "DelayEstimate",
    "bode_minimum_phase",
    "coherent_band",
    "estimate_delay",
    "estimate_delay_from_response",
    "kernel_primitive",
    "remove_delay",
]

_HALF_PI2 = np.pi**2 / 4.0  # integral of ln coth(t/2) over t in (0, inf)
_EXTENSION = 8.0  # tails are continued over e^8 ~ 3000x in frequency, then with slope n
_EXTENSION_POINTS = 400
_CHUNK = 256  # evaluation points per block of the kernel matrix (memory bound)
_OUTLIER_MADS = 5.0  # residuals beyond 5 robust standard deviations are excluded
_HANN_ENBW_BINS = 1.5  # equivalent noise bandwidth of a Hann window, in 1/L bins

_Frf = TypeVar("_Frf", xr.DataArray, FrequencyResponse)


@dataclass(frozen=True)
class DelayEstimate:
    """Delay of one path, from the slope of its non-minimum-phase phase.

    Attributes
    ----------
    delay_s : float
        Estimated pure delay ``tau``, s (positive: the output lags).
    std_s : float
        Standard error of ``delay_s`` from the line fit, s.
    band_hz : tuple of float
        Band ``(f_lo, f_hi)`` over which the magnitude was integrated and the
        phase fitted, Hz.
    method : str
        ``"bode-gain-phase"``.
    phase_offset_rad : float
        Intercept ``phi0`` of the fitted line, rad; ``~k pi`` when the assumptions hold.
    gain_sign : int
        ``(-1)^k`` for the multiple of ``pi`` nearest ``phi0``: the sign of ``G(0)``.
    n_frequencies : int
        Bins used in the line fit (after the coherence and outlier cuts).
    n_outliers : int
        Bins removed by the outlier cut.
    low_frequency_slope, high_frequency_slope : float
        Asymptotic slopes ``d ln|H| / d ln f`` used below and above the band.
    residual_rms_rad : float
        RMS of the line-fit residuals (unweighted), rad.
    output, input : str or None
        Names of the path, when known.
    """

    delay_s: float
    std_s: float
    band_hz: tuple[float, float]
    method: str
    phase_offset_rad: float
    gain_sign: int
    n_frequencies: int
    n_outliers: int
    low_frequency_slope: float
    high_frequency_slope: float
    residual_rms_rad: float
    output: str | None = None
    input: str | None = None

    def summary(self) -> dict[str, Any]:
        """JSON-serialisable dict of every field (SI units, Hz)."""
        out = dataclasses.asdict(self)
        out["band_hz"] = list(self.band_hz)
        return out

    def to_json(self, **kwargs: Any) -> str:
        """:meth:`summary` as a JSON string (``kwargs`` go to :func:`json.dumps`)."""
        return json.dumps(self.summary(), **kwargs)


# --------------------------------------------------------------------------- Bode integral
def kernel_primitive(v: NDArray[np.float64]) -> NDArray[np.float64]:
    """``int_0^v ln coth(|t|/2) dt`` (odd in v), via ``sum_{k odd} 2 e^{-k|v|}/k^2``."""
    a = np.abs(v)
    x = np.exp(-a)
    # Li2(x) = spence(1 - x); sum_{k odd} x^k/k^2 = Li2(x) - Li2(x^2)/4.
    tail = 2.0 * (spence(1.0 - x) - 0.25 * spence(1.0 - x * x))
    return np.sign(v) * (_HALF_PI2 - tail)


def _tail_fit(
    u: NDArray[np.float64], a: NDArray[np.float64], *, edge: float, side: int,
    slope: float | None,
) -> tuple[float, float, float]:
    """Fit ``a0 + n u + c e^{-2 side (u - edge)}``; returns (a0, n, c). ``side`` +1 high, -1 low.

    With ``slope`` None, ``n`` is the integer (within 1 of the free fit's and of
    the plain local slope) whose fit leaves the smallest residual.
    """
    if u.size < 3 or np.ptp(u) <= 0:
        n = 0.0 if slope is None else float(slope)
        return (float(np.mean(a - n * u)) if u.size else 0.0), n, 0.0
    x = np.exp(-2.0 * side * (u - edge))
    basis = np.column_stack([np.ones_like(u), x])
    if slope is None:
        local = float(np.polyfit(u, a, 1)[0])
        free = local
        if u.size >= 4:
            coef, *_ = np.linalg.lstsq(np.column_stack([basis, u]), a, rcond=None)
            free = float(coef[2])
        lowest, highest = int(np.floor(min(free, local))) - 1, int(np.ceil(max(free, local))) + 1
        candidates = [float(k) for k in range(lowest, highest + 1)]
    else:
        candidates = [float(slope)]
    fits = []
    for n in candidates:
        coef, *_ = np.linalg.lstsq(basis, a - n * u, rcond=None)
        fits.append((float(np.sum((basis @ coef - (a - n * u)) ** 2)), n, coef))
    _, n_best, coef_best = min(fits, key=lambda item: item[0])
    return float(coef_best[0]), n_best, float(coef_best[1])


def bode_minimum_phase(
    frequency_hz: ArrayLike,
    magnitude: ArrayLike,
    *,
    at_hz: ArrayLike | None = None,
    fit_mask: ArrayLike | None = None,
    low_frequency_slope: float | None = None,
    high_frequency_slope: float | None = None,
    tail_ratio: float = 1.6,
) -> tuple[NDArray[np.float64], float, float]:
    """Phase of the minimum-phase function with a measured magnitude (Bode gain-phase relation).

    Parameters
    ----------
    frequency_hz : array_like, shape (F,)
        Strictly increasing positive frequencies, Hz: the band.
    magnitude : array_like, shape (F,)
        ``|H|`` at those frequencies (any unit; positive).
    at_hz : array_like, shape (E,), optional
        Where to evaluate the phase, Hz (default: ``frequency_hz``).
    fit_mask : array_like of bool, shape (F,), optional
        Bins trusted for the tail fits (default: all).
    low_frequency_slope, high_frequency_slope : float, optional
        Asymptotic ``d ln|H| / d ln f`` below and above the band (e.g. 0 and -2
        for a mass-spring mode). Default: fitted, rounded to an integer.
    tail_ratio : float
        The tails are fitted over ``[f_lo, f_lo * tail_ratio]`` and
        ``[f_hi / tail_ratio, f_hi]``; > 1.

    Returns
    -------
    phase_rad : ndarray, shape (E,)
        Minimum phase, rad (continuous, ``n pi / 2`` at frequencies where the
        slope is ``n`` over many decades).
    low_slope, high_slope : float
        The asymptotic slopes used.
    """
    f = np.asarray(frequency_hz, dtype=float).ravel()
    mag = np.asarray(magnitude, dtype=float).ravel()
    if f.shape != mag.shape or f.size < 4:
        raise ValueError("frequency_hz and magnitude must have the same length >= 4")
    if np.any(f <= 0) or np.any(np.diff(f) <= 0):
        raise ValueError("frequency_hz must be positive and strictly increasing")
    if not np.all(np.isfinite(mag)) or np.any(mag <= 0):
        raise ValueError("magnitude must be finite and positive")
    if not tail_ratio > 1.0:
        raise ValueError(f"tail_ratio must be > 1, got {tail_ratio!r}")
    mask = np.ones(f.size, bool) if fit_mask is None else np.asarray(fit_mask, bool).ravel()
    at = f if at_hz is None else np.asarray(at_hz, dtype=float).ravel()
    u, a = np.log(f), np.log(mag)
    lo_sel = mask & (u <= u[0] + np.log(tail_ratio))
    hi_sel = mask & (u >= u[-1] - np.log(tail_ratio))
    a_lo, n_lo, c_lo = _tail_fit(u[lo_sel], a[lo_sel], edge=u[0], side=-1,
                                 slope=low_frequency_slope)
    a_hi, n_hi, c_hi = _tail_fit(u[hi_sel], a[hi_sel], edge=u[-1], side=+1,
                                 slope=high_frequency_slope)
    step = np.linspace(0.0, _EXTENSION, _EXTENSION_POINTS)[1:]
    u_low = (u[0] - step)[::-1]
    u_high = u[-1] + step
    a_low = a_lo + n_lo * u_low + c_lo * np.exp(2.0 * (u_low - u[0]))
    a_high = a_hi + n_hi * u_high + c_hi * np.exp(-2.0 * (u_high - u[-1]))
    ug = np.concatenate([u_low, u, u_high])
    ag = np.concatenate([a_low, a, a_high])
    slopes = np.diff(ag) / np.diff(ug)
    u_eval = np.log(at)
    phase = np.empty(u_eval.size)
    for start in range(0, u_eval.size, _CHUNK):
        ue = u_eval[start:start + _CHUNK]
        prim = kernel_primitive(ug[None, :] - ue[:, None])
        inner = (prim[:, 1:] - prim[:, :-1]) @ slopes
        outer = n_lo * (prim[:, 0] + _HALF_PI2) + n_hi * (_HALF_PI2 - prim[:, -1])
        phase[start:start + _CHUNK] = (inner + outer) / np.pi
    return phase, n_lo, n_hi


# --------------------------------------------------------------------------- delay fit
def estimate_delay_from_response(
    frequency_hz: ArrayLike,
    response: ArrayLike,
    *,
    band_hz: tuple[float, float],
    coherence: ArrayLike | None = None,
    phase_std_rad: ArrayLike | None = None,
    min_coherence: float = 0.9,
    bins_per_independent: float = 1.0,
    low_frequency_slope: float | None = None,
    high_frequency_slope: float | None = None,
    tail_ratio: float = 1.6,
    max_points: int = 1000,
    output: str | None = None,
    input: str | None = None,
) -> DelayEstimate:
    """Delay of one FRF path as the slope of ``arg H - arg G_min`` over a band.

    Parameters
    ----------
    frequency_hz : array_like, shape (F,)
        Increasing frequencies, Hz.
    response : array_like, complex, shape (F,)
        ``H(j 2 pi f)``.
    band_hz : (float, float)
        ``(f_lo, f_hi)``, Hz, ``0 < f_lo < f_hi``: integration and fit band.
    coherence : array_like, shape (F,), optional
        Bins with coherence below ``min_coherence`` are left out of the tail
        and line fits (their magnitude still enters the integral).
    phase_std_rad : array_like, shape (F,), optional
        Standard deviation of the measured phase, rad (e.g.
        ``FrequencyResponse.random_error``): weights ``1/std^2``. Default: equal weights.
    min_coherence : float
        Coherence threshold, in [0, 1).
    bins_per_independent : float
        Number of adjacent bins per statistically independent estimate (>= 1):
        zero padding and window overlap correlate neighbours; ``std_s`` is
        scaled by its square root.
    low_frequency_slope, high_frequency_slope : float, optional
        See :func:`bode_minimum_phase`.
    tail_ratio : float
        See :func:`bode_minimum_phase`.
    max_points : int
        At most this many bins (every k-th usable bin) enter the line fit; the
        Bode integral still uses every bin. Neighbouring bins carry nearly the
        same information, and the integral costs (bins used) x (bins in band).
    output, input : str, optional
        Path names, stored in the result.

    Returns
    -------
    DelayEstimate
    """
    f = np.asarray(frequency_hz, dtype=float).ravel()
    h = np.asarray(response, dtype=complex).ravel()
    bins = _fit_bins(f, h, band_hz=band_hz, coherence=coherence, phase_std_rad=phase_std_rad,
                     min_coherence=min_coherence, bins_per_independent=bins_per_independent,
                     max_points=max_points)
    band, good = bins.band, bins.good
    phase_min, n_lo, n_hi = bode_minimum_phase(
        f[band], np.abs(h[band]), at_hz=f[good], fit_mask=bins.fit_mask[band],
        tail_ratio=tail_ratio, low_frequency_slope=low_frequency_slope,
        high_frequency_slope=high_frequency_slope)
    line = _phase_line(f[good], h[good], phase_min=phase_min, w=1.0 / bins.sigma[good] ** 2)
    k = int(np.round(line.coef[0] / np.pi))
    return DelayEstimate(
        delay_s=float(line.coef[1]),
        std_s=float(np.sqrt(line.cov[1, 1] * bins.bins_per_independent)),
        band_hz=bins.band_hz, method="bode-gain-phase", phase_offset_rad=float(line.coef[0]),
        gain_sign=-1 if k % 2 else 1, n_frequencies=int(line.keep.sum()),
        n_outliers=int((~line.keep).sum()), low_frequency_slope=float(n_lo),
        high_frequency_slope=float(n_hi),
        residual_rms_rad=float(np.sqrt(np.mean(line.err**2))), output=output, input=input,
    )


@dataclass(frozen=True)
class _FitBins:
    """Which bins of one path enter the Bode integral and the line fit (masks over all bins)."""

    band_hz: tuple[float, float]  # the band [Hz]
    band: NDArray[np.bool_]  # in the band, finite and non-zero: the Bode integral's bins
    fit_mask: NDArray[np.bool_]  # usable (coherent, with a phase std): the tail fits' bins
    good: NDArray[np.bool_]  # usable and thinned to max_points: the line fit's bins
    sigma: NDArray[np.float64]  # phase std of every bin [rad] (1: equal weights)
    bins_per_independent: float  # adjacent fitted bins per independent estimate, thinned


def _fit_bins(f: NDArray[np.float64], h: NDArray[np.complex128], *,
              band_hz: tuple[float, float], coherence: ArrayLike | None,
              phase_std_rad: ArrayLike | None, min_coherence: float,
              bins_per_independent: float, max_points: int) -> _FitBins:
    """The checked band and the bins :func:`estimate_delay_from_response` uses (its parameters).

    ``f`` [Hz] and ``h`` are the path's bins, flattened. Raises ``ValueError`` on bad
    shapes, a bad band or ``bins_per_independent``, or fewer than 8 usable bins.
    """
    if f.shape != h.shape:
        raise ValueError(f"frequency_hz {f.shape} and response {h.shape} differ in shape")
    lo, hi = (float(b) for b in band_hz)
    if not 0.0 < lo < hi:
        raise ValueError(f"band_hz must satisfy 0 < f_lo < f_hi, got {band_hz!r}")
    if not bins_per_independent >= 1.0:
        raise ValueError(f"bins_per_independent must be >= 1, got {bins_per_independent!r}")
    band = (f >= lo) & (f <= hi) & np.isfinite(h) & (np.abs(h) > 0)
    good = band.copy()
    if coherence is not None:
        coh = _same_shape(coherence, f, "coherence")
        good &= np.nan_to_num(coh, nan=0.0) >= min_coherence
    sigma = np.ones(f.size)
    if phase_std_rad is not None:
        sigma = _same_shape(phase_std_rad, f, "phase_std_rad")
        good &= np.isfinite(sigma) & (sigma > 0)
    fit_mask = good.copy()
    if good.sum() < 8:
        raise ValueError(f"only {int(good.sum())} usable bins in {band_hz} Hz (need >= 8): "
                         "widen the band or lower min_coherence")
    stride = int(np.ceil(good.sum() / max(int(max_points), 8)))
    if stride > 1:
        thinned = np.zeros_like(good)
        thinned[np.flatnonzero(good)[::stride]] = True
        good, bins_per_independent = thinned, max(1.0, bins_per_independent / stride)
    return _FitBins((lo, hi), band, fit_mask, good, sigma, bins_per_independent)


@dataclass(frozen=True)
class _PhaseLine:
    """The line ``phi0 - 2 pi f tau`` fitted to the non-minimum phase."""

    coef: NDArray[np.float64]  # (phi0 [rad], tau [s])
    cov: NDArray[np.float64]  # their covariance, scaled by the reduced chi-square
    keep: NDArray[np.bool_]  # the fitted bins the outlier cut left
    err: NDArray[np.float64]  # the kept bins' residuals [rad]


def _phase_line(fg: NDArray[np.float64], hg: NDArray[np.complex128], *,
                phase_min: NDArray[np.float64], w: NDArray[np.float64]) -> _PhaseLine:
    """Weighted line fit, outliers cut, of ``arg hg - phase_min`` over ``fg`` [Hz].

    ``phase_min`` is the Bode minimum phase [rad] and ``w`` the weights [rad⁻²] at ``fg``.
    """
    resid = np.unwrap(np.angle(hg * np.exp(-1j * phase_min)))
    design = np.column_stack([np.ones_like(fg), -2.0 * np.pi * fg])
    keep = np.ones(fg.size, bool)
    for _ in range(3):  # fit, cut outliers, refit (stops when the cut is stable)
        coef = _wls(design[keep], resid[keep], w[keep])
        line = design @ coef
        # Re-wrap about the line: repairs a 2 pi slip of np.unwrap at a noisy bin.
        resid = line + np.angle(np.exp(1j * (resid - line)))
        err = resid - line
        scale = 1.4826 * np.median(np.abs(err[keep] - np.median(err[keep])) * np.sqrt(w[keep]))
        new_keep = np.abs(err) * np.sqrt(w) <= _OUTLIER_MADS * max(scale, 1e-300)
        if np.array_equal(new_keep, keep) or new_keep.sum() < 8:
            break
        keep = new_keep
    coef = _wls(design[keep], resid[keep], w[keep])
    err = resid[keep] - design[keep] @ coef
    dof = max(int(keep.sum()) - 2, 1)
    chi2 = float(np.sum(w[keep] * err**2) / dof)
    cov = np.linalg.inv(design[keep].T @ (w[keep, None] * design[keep])) * chi2
    return _PhaseLine(coef, np.asarray(cov, dtype=float), keep, err)


def _same_shape(values: ArrayLike, f: NDArray[np.float64], what: str) -> NDArray[np.float64]:
    arr = np.asarray(values, dtype=float).ravel()
    if arr.shape != f.shape:
        raise ValueError(f"{what} has shape {arr.shape}, frequency_hz {f.shape}")
    return arr


def _wls(a: NDArray[np.float64], y: NDArray[np.float64],
         w: NDArray[np.float64]) -> NDArray[np.float64]:
    sw = np.sqrt(w)
    coef, *_ = np.linalg.lstsq(a * sw[:, None], y * sw, rcond=None)
    return np.asarray(coef)


def coherent_band(f: NDArray[np.float64], coh: NDArray[np.float64], *, f_lo: float,
                   f_max: float, threshold: float, width: int) -> float:
    """Top of the band: first frequency above ``f_lo`` where the running-median coherence fails.

    The median runs over the lines above ``f_lo`` only: the lowest lines (drift, 1/f noise,
    the window's DC leakage) must not drag down the start of the band.
    """
    keep = f > f_lo
    f, coh = f[keep], coh[keep]
    if f.size == 0:
        return f_lo
    half = min(width // 2, f.size - 1)
    # Mirrored at the ends, not the end value repeated: two low lines at the band's start
    # (drift, 1/f noise) repeated half a window would end the band where it begins.
    padded = np.pad(np.nan_to_num(coh, nan=0.0), half, mode="reflect")
    windows = np.lib.stride_tricks.sliding_window_view(padded, 2 * half + 1)
    smooth = np.median(windows, axis=1)
    above = f <= f_max
    bad = np.flatnonzero(above & (smooth < threshold))
    if bad.size == 0:
        return float(f[above][-1]) if above.any() else f_lo
    return float(f[bad[0] - 1]) if bad[0] > 0 else f_lo


def estimate_delay(
    frf: FrequencyResponse,
    *,
    output_name: str,
    input_name: str,
    band_hz: tuple[float, float] | None = None,
    min_coherence: float = 0.9,
    max_frequency_hz: float | None = None,
    weighted: bool = False,
    low_frequency_slope: float | None = None,
    high_frequency_slope: float | None = None,
    tail_ratio: float = 1.6,
) -> DelayEstimate:
    """Delay of the path ``input_name -> output_name`` of a Welch FRF matrix.

    Parameters
    ----------
    frf : FrequencyResponse
        From :func:`fsmbench.ident.spectral_matrix` (H1, coherence, random error).
    output_name, input_name : str
        The path.
    band_hz : (float, float), optional
        Default: from ``10 fs / window_length``, at least 10 Hz (10 Hz for the seed's
        1 s window, clear of the window's DC leakage) up to where the coherence,
        smoothed by a running median over ``15 fs / window_length`` Hz, at least
        15 Hz, of the response's own lines (so that the narrow dip
        at a smeared resonance does not end the band), first drops below
        ``min_coherence``; at most ``max_frequency_hz``.
    min_coherence : float
        Coherence threshold for the band and for the bins fitted.
    max_frequency_hz : float, optional
        Upper limit of the automatic band, Hz; default ``fs/4`` (see the
        module notes on sampled paths).
    weighted : bool
        Weight bins by ``1/random_error^2`` (Bendat & Piersol phase variance);
        default equal weights, which is more robust when the Bode-phase model
        error, not noise, dominates (high coherence).
    low_frequency_slope, high_frequency_slope, tail_ratio
        See :func:`bode_minimum_phase`.

    Returns
    -------
    DelayEstimate
        ``std_s`` accounts for the correlation of zero-padded, overlapped bins:
        ``bins_per_independent = 1.5 nfft / window_length`` (Hann window's noise
        bandwidth).
    """
    f = frf.frequency_hz
    h = frf.frf.sel(output=output_name, input=input_name).values
    coh = frf.coherence.sel(output=output_name, input=input_name).values
    resolution = frf.fs_hz / frf.window_length
    if band_hz is None:
        # At least 10 Hz: an estimate over the whole record (LPM) resolves fractions of a
        # hertz, where drift and 1/f noise leave no coherence; 1 s Welch starts there anyway.
        f_lo = max(10.0 * resolution, 10.0)
        f_max = frf.fs_hz / 4.0 if max_frequency_hz is None else float(max_frequency_hz)
        spacing = float(np.median(np.diff(f))) if f.size > 1 else frf.fs_hz / frf.nfft
        width = max(3, round(max(15.0 * resolution, 15.0) / spacing))
        f_hi = coherent_band(f, coh, f_lo=f_lo, f_max=f_max, threshold=min_coherence,
                              width=width)
        if f_hi <= 2.0 * f_lo:
            raise ValueError(f"path {input_name}->{output_name}: coherence >= {min_coherence} "
                             f"only up to {f_hi:.3g} Hz; give band_hz explicitly")
        band_hz = (f_lo, f_hi)
    eps = frf.random_error.sel(output=output_name, input=input_name).values if weighted else None
    return estimate_delay_from_response(
        f, h, band_hz=band_hz, coherence=coh, phase_std_rad=eps, min_coherence=min_coherence,
        bins_per_independent=max(1.0, _HANN_ENBW_BINS * frf.nfft / frf.window_length),
        low_frequency_slope=low_frequency_slope, high_frequency_slope=high_frequency_slope,
        tail_ratio=tail_ratio, output=output_name, input=input_name)


# --------------------------------------------------------------------------- removal
def remove_delay(frf: _Frf, delay_s: float | Mapping[str, float]) -> _Frf:
    """Multiply a frequency response by ``exp(+j 2 pi f tau)``, undoing a delay ``tau``.

    The seed's ``tf_Uch_Vph./G_delay_resp`` with ``G_delay = exp(-s Ts)``.

    Parameters
    ----------
    frf : xarray.DataArray or FrequencyResponse
        A DataArray with a ``frequency`` coordinate (Hz) and, when ``delay_s``
        is a mapping, an ``input`` dimension; or a :class:`FrequencyResponse`,
        whose ``frf`` and ``cross_psd`` are rotated and phase bounds shifted
        (magnitudes, coherence and PSDs are unchanged).
    delay_s : float or mapping of str to float
        Delay to remove, s; a mapping gives one delay per input name (inputs
        not named are left as they are).

    Returns
    -------
    Same type as ``frf``
        A new object; the input is not modified.
    """
    if isinstance(frf, FrequencyResponse):
        f = frf.frequency_hz
        shift = _phase_shift(frf.frf, f, delay_s)
        rot = shift.copy(data=np.exp(1j * shift.values))
        return dataclasses.replace(
            frf,
            frf=frf.frf * rot,
            cross_psd=frf.cross_psd * rot,
            phase_lower_rad=frf.phase_lower_rad + shift,
            phase_upper_rad=frf.phase_upper_rad + shift,
        )
    if isinstance(frf, xr.DataArray):
        if "frequency" not in frf.coords:
            raise ValueError("the DataArray needs a 'frequency' coordinate (Hz)")
        return frf * _rotation(frf, np.asarray(frf["frequency"].values, float), delay_s)
    raise TypeError(f"remove_delay takes an xarray.DataArray or FrequencyResponse, "
                    f"got {type(frf).__name__}")


def _delay_by_input(da: xr.DataArray, delay_s: float | Mapping[str, float]) -> xr.DataArray:
    if not isinstance(delay_s, Mapping):
        return xr.DataArray(float(delay_s))
    if "input" not in da.dims:
        raise ValueError("per-input delays need an 'input' dimension")
    names = [str(n) for n in da["input"].values]
    unknown = sorted(set(delay_s) - set(names))
    if unknown:
        raise ValueError(f"delays given for unknown input(s) {unknown}; inputs are {names}")
    values = [float(delay_s.get(n, 0.0)) for n in names]
    return xr.DataArray(values, dims=("input",), coords={"input": da["input"].values})


def _phase_shift(da: xr.DataArray, f: NDArray[np.float64],
                 delay_s: float | Mapping[str, float]) -> xr.DataArray:
    freq = xr.DataArray(f, dims=("frequency",), coords={"frequency": da["frequency"].values})
    shift = 2.0 * np.pi * freq * _delay_by_input(da, delay_s)
    return shift.broadcast_like(da).transpose(*da.dims)


def _rotation(da: xr.DataArray, f: NDArray[np.float64],
              delay_s: float | Mapping[str, float]) -> xr.DataArray:
    shift = _phase_shift(da, f, delay_s)
    return shift.copy(data=np.exp(1j * shift.values))
