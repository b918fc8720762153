"""Frequency response of a periodic excitation: averaging over periods, noise from their spread.

For an input repeating every ``N`` samples (a multisine), every period of a
steady-state record carries the same signal and an independent noise
realisation. Following Pintelon & Schoukens, *System Identification: A
Frequency Domain Approach* (2nd ed., 2012), ch. 2 ("nonparametric noise
models", sample means and sample (co)variances over periods):

* the record's last ``P`` whole periods are cut into ``(P, N)`` blocks and the
  first ``transient_periods`` are dropped (the system's transient from the
  start of the excitation leaks into every line of the early periods);
* per period ``p`` the DFTs ``U_p(k)``, ``Y_p(k)`` (normalised by ``N^-1/2``);
  the means ``U(k)``, ``Y(k)`` over periods; the sample (co)variances
  ``s2_U = sum |U_p - U|^2 / (P - 1)``, ``s2_Y``, ``s_YU = sum (Y_p - Y)(U_p - U)^* / (P - 1)``
  and those of the means, divided by ``P``;
* ``G = Y / U`` at the excited lines only, and to first order in the noise
  (``dG = (dY - G dU) / U``)::

      var G = (s2_Y + |G|^2 s2_U - 2 Re(G^* s_YU)) / (P |U|^2),

  which includes the input noise and the input/output noise covariance (a
  noise source inside a feedback loop, or one common to both channels).

The excited lines are those whose averaged input power exceeds 1e-4 of the
strongest line (a designed multisine puts equal power on its lines and only
round-off or quantisation elsewhere), 10 times its own noise variance and
1e-2 of the median excited line's; or they are given. :func:`detect_period`
tells whether a record is periodic (the "auto" rule of the identification).

The first-order variance neglects terms in ``(noise/|U|)^2``; with noise on
the input ``Y/U`` is also biased by a relative ``O(s2_U / (P |U|^2))``
(errors-in-variables), negligible at the SNR of a designed excitation.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fsmbench.ident.frf_estimate import FrfEstimate, simo_signals

__all__ = ["PeriodicOptions", "detect_period", "excited_lines", "periodic_frf"]

# An input line is excited when its averaged power exceeds this fraction of the
# strongest line's: a multisine's lines are within a few dB of each other,
# round-off and DAC quantisation lie 50 dB or more below them.
_EXCITED_RELATIVE = 1e-4
# ... and this many times the variance of its own average (not noise alone).
_EXCITED_SNR = 10.0
# ... and this fraction of the median excited line's (see :func:`excited_lines`).
_EXCITED_OF_TYPICAL = 1e-2
# A record is periodic with period N when consecutive periods correlate above
# this (normalised): noise excitation gives ~1/sqrt(L); a periodic input with a
# 20 dB SNR still gives 0.99.
_PERIODIC_CORRELATION = 0.9
# ... after having fallen below this at a shorter lag (it decorrelates within a period).
_DECORRELATED = 0.5


@dataclass(frozen=True)
class PeriodicOptions:
    """Options of :func:`periodic_frf`.

    Attributes
    ----------
    period_samples : int or None
        Period ``N`` of the excitation, samples; None: :func:`detect_period`.
    transient_periods : int
        Leading whole periods dropped (the transient), >= 0.
    lines : sequence of int or None
        Excited DFT lines ``k`` of one period (frequency ``k fs / N``); None:
        :func:`excited_lines` on the input.
    confidence : float
        Level of the circular confidence bound, in (0, 1).
    """

    period_samples: int | None = None
    transient_periods: int = 1
    lines: Sequence[int] | None = None
    confidence: float = 0.95

    def __post_init__(self) -> None:
        if self.period_samples is not None and self.period_samples < 2:
            raise ValueError(f"period_samples must be >= 2, got {self.period_samples}")
        if self.transient_periods < 0:
            raise ValueError(f"transient_periods must be >= 0, got {self.transient_periods}")
        if not 0.0 < self.confidence < 1.0:
            raise ValueError(f"confidence must be in (0, 1), got {self.confidence!r}")


def detect_period(signal: ArrayLike, *, min_period: int = 16,
                  threshold: float = _PERIODIC_CORRELATION) -> int | None:
    """Smallest period (samples) at which the record repeats, or None.

    The normalised correlation ``rho(N) = sum x(t) x(t+N) / sqrt(sum x(t)^2 sum x(t+N)^2)``
    (mean removed, over the overlap) is computed for every lag by one FFT; the
    record is periodic with period ``N`` when ``rho(N) >= threshold`` after
    ``rho`` has fallen below 0.5 at a shorter lag (a slowly varying signal
    correlates at short lags without repeating) and at least two whole
    periods fit. Of the qualifying lags (``N``, ``2N``, ...
    and their near neighbours) the smallest local maximum is returned.

    Parameters
    ----------
    signal : array_like, shape (L,)
        The excitation record (any unit).
    min_period : int
        Shortest period considered, samples (shorter lags correlate through
        the signal's own bandwidth).
    threshold : float
        Correlation needed, in (0, 1].

    Returns
    -------
    int or None
        ``N``, or None for a non-periodic record.
    """
    x = np.asarray(signal, dtype=float)
    x = x - x.mean()
    n = x.size
    if n < 2 * min_period:
        return None
    nfft = 1 << int(2 * n - 1).bit_length()
    spec = np.fft.rfft(x, nfft)
    acf = np.fft.irfft(np.abs(spec) ** 2, nfft)[: n // 2 + 1]
    # energies of the two overlapping parts x[:L-N] and x[N:] for every lag N
    c2 = np.concatenate([[0.0], np.cumsum(x**2)])
    lags = np.arange(acf.size)
    e_head = c2[n - lags]
    e_tail = c2[n] - c2[lags]
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = acf / np.sqrt(e_head * e_tail)
    rho = np.nan_to_num(rho, nan=-np.inf)
    # a smooth (low-pass) signal correlates with itself at short lags without repeating:
    # a period counts only after the correlation has first fallen below one half
    below = np.flatnonzero(rho < _DECORRELATED)
    if below.size == 0:
        return None
    rho[: max(min_period, int(below[0]))] = -np.inf
    good = np.flatnonzero(rho >= threshold)
    if good.size == 0:
        return None
    k = int(good[0])
    while k + 1 < rho.size and rho[k + 1] > rho[k]:  # climb to the local maximum
        k += 1
    return k


def excited_lines(input_mean_power: ArrayLike, mean_noise_variance: ArrayLike) -> NDArray[np.intp]:
    """Indices ``k >= 1`` of the excited lines of a periodic input.

    Parameters
    ----------
    input_mean_power : array_like, shape (K,)
        ``|U(k)|^2`` of the period-averaged input, U_in^2 (normalised DFT).
    mean_noise_variance : array_like, shape (K,)
        Variance of that average, ``s2_U / P``, U_in^2.

    Returns
    -------
    ndarray of int
        Lines above 1e-4 of the strongest, above 10 times their noise variance and
        above 1e-2 of the median of those (the quantisation error of a periodic
        command is periodic and passes the first two tests on a few lines).
    """
    pw = np.asarray(input_mean_power, dtype=float)
    nv = np.asarray(mean_noise_variance, dtype=float)
    k = np.arange(pw.size)
    ref = pw[1:].max() if pw.size > 1 else 0.0
    found = np.flatnonzero((k >= 1) & (pw > _EXCITED_RELATIVE * ref) & (pw > _EXCITED_SNR * nv)
                           & (pw > 0.0))
    if found.size == 0:
        return found
    # The DAC's quantisation error of a periodic command is periodic too: a few of its lines
    # pass the tests above (1e-4 of a 6e-4 V line is 6 uV, a 16-bit LSB's error spread over
    # 5000 lines is ~1 uV rms per line). A designed line is within 20 dB of the typical one.
    return found[pw[found] > _EXCITED_OF_TYPICAL * float(np.median(pw[found]))]


def _blocks(x: NDArray[np.float64], n: int, first: int, periods: int) -> NDArray[np.complex128]:
    """Normalised DFT of each period: (periods, n//2 + 1) (or (periods, lines, channels))."""
    seg = x[first: first + periods * n].reshape(periods, n, *x.shape[1:])
    return np.fft.rfft(seg, axis=1) / np.sqrt(n)


def periodic_frf(
    inputs: ArrayLike,
    outputs: ArrayLike,
    *,
    fs_hz: float,
    input_name: str,
    output_names: Sequence[str],
    options: PeriodicOptions | None = None,
    source: str = "the record",
) -> FrfEstimate:
    """SIMO FRF of one periodic experiment, with the variance of every excited line.

    Parameters
    ----------
    inputs : array_like, float, shape (L,)
        Measured excitation, U_in.
    outputs : array_like, float, shape (L, p) or (L,)
        Measured responses, U_out, same ``L``.
    fs_hz : float
        Sampling frequency, Hz.
    input_name : str
        Name of the input (the column).
    output_names : sequence of str
        ``p`` output names.
    options : PeriodicOptions, optional
        Period, transient periods, lines, confidence level.
    source : str
        Named in error messages (e.g. the file).

    Returns
    -------
    FrfEstimate
        ``estimator="periodic"``, lines ``k fs / N`` of the excited ``k``,
        ``dof = (P - 1,)``, no transient; ``snr`` per period.

    Raises
    ------
    ValueError
        Non-finite samples, unequal lengths, no period found, fewer than two
        periods left after the transient, or no excited line.
    """
    opts = options or PeriodicOptions()
    u, y, names = simo_signals(inputs, outputs, input_name=input_name,
                               output_names=output_names, source=source)
    n = opts.period_samples or detect_period(u)
    if n is None:
        raise ValueError(f"{source}: the input {input_name} is not periodic (no lag with "
                         f"correlation >= {_PERIODIC_CORRELATION}); use the LPM or Welch")
    total = u.size // n
    periods = total - opts.transient_periods
    if periods < 2:
        raise ValueError(f"{source}: {input_name} holds {total} whole period(s) of {n} samples; "
                         f"after dropping {opts.transient_periods} transient period(s) at least "
                         "2 are needed for a noise estimate")
    first = u.size - total * n + opts.transient_periods * n  # keep the record's end
    ub = _blocks(u, n, first, periods)  # (P, K)
    yb = _blocks(y, n, first, periods)  # (P, K, p)
    um, ym = ub.mean(axis=0), yb.mean(axis=0)
    du, dy = ub - um, yb - ym
    s2u = np.sum(np.abs(du) ** 2, axis=0) / (periods - 1)  # (K,)
    s2y = np.sum(np.abs(dy) ** 2, axis=0) / (periods - 1)  # (K, p)
    syu = np.einsum("pkc,pk->kc", dy, du.conj()) / (periods - 1)  # (K, p)
    if opts.lines is None:
        lines = excited_lines(np.abs(um) ** 2, s2u / periods)
    else:
        lines = np.asarray(sorted({int(k) for k in opts.lines}), dtype=np.intp)
        if lines.size and (lines.min() < 0 or lines.max() >= um.size):
            raise ValueError(f"{source}: lines must be in [0, {um.size - 1}] for a period of "
                             f"{n} samples")
    if lines.size == 0:
        raise ValueError(f"{source}: no excited line in the input {input_name}")
    uk, yk = um[lines], ym[lines]
    g = yk / uk[:, None]
    var = (s2y[lines] + np.abs(g) ** 2 * s2u[lines, None]
           - 2.0 * np.real(g.conj() * syu[lines])) / (periods * np.abs(uk[:, None]) ** 2)
    var = np.maximum(var, 0.0)  # round-off can make a noise-free line's estimate negative
    with np.errstate(divide="ignore"):
        snr = np.abs(g * uk[:, None]) ** 2 / s2y[lines]
    one_sided = np.where((lines == 0) | (2 * lines == n), 1.0, 2.0)
    return FrfEstimate(
        frequency_hz=lines * fs_hz / n, frf=g[:, :, None], frf_variance=var[:, :, None],
        output_noise_psd=(one_sided[:, None] * s2y[lines] / fs_hz)[:, :, None],
        input_psd=(one_sided * np.abs(uk) ** 2 / fs_hz)[:, None], snr=snr[:, :, None],
        input_names=(str(input_name),), output_names=tuple(names), fs_hz=float(fs_hz),
        resolution_hz=float(fs_hz) / n, estimator="periodic",
        options={"period_samples": int(n), "periods_used": int(periods),
                 "transient_periods": opts.transient_periods, "n_lines": int(lines.size)},
        dof=(float(periods - 1),), confidence=opts.confidence)
