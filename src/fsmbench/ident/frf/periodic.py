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

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.stats import f as f_dist

from fsmbench.ident.frf.estimate import FrfEstimate, simo_signals

__all__ = ["Distortion", "PeriodicOptions", "detect_period", "detect_transient", "distortion",
           "excited_lines", "periodic_frf"]

# An input line is excited when its averaged power exceeds this fraction of the
# strongest line's: a multisine's lines are within a few dB of each other,
# round-off and DAC quantisation lie 50 dB or more below them.
_EXCITED_RELATIVE = 1e-4
# ... and this many times the variance of its own average (not noise alone).
_EXCITED_SNR = 10.0
# ... and this fraction of the median excited line's (see :func:`excited_lines`).
_EXCITED_OF_TYPICAL = 1e-2
# A steady period is called a transient with this chance (:func:`detect_transient`).
_TRANSIENT_FALSE_ALARM = 1e-3
# Odd non-excited lines each side whose level an excited line's distortion takes (8 lines:
# the mean of 8 exponential powers has a relative std of 35 %).
_DISTORTION_NEIGHBOURS = 4
# A non-excited line this many times its neighbourhood's median is a spike (mains), not
# distortion (an exponential power exceeds 20x its mean once in 5e8).
_SPIKE = 20.0
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
    transient_periods : int or None
        Leading whole periods dropped (the transient), >= 0; None: detected
        from the data (:func:`detect_transient`), at least ``min_transient_periods``.
    min_transient_periods : int
        The fewest periods dropped when detecting (the excitation's own
        ``transient_periods`` from ``excitation.json``, or 1).
    lines : sequence of int or None
        Excited DFT lines ``k`` of one period (frequency ``k fs / N``); None:
        :func:`excited_lines` on the input.
    confidence : float
        Level of the circular confidence bound, in (0, 1).
    """

    period_samples: int | None = None
    transient_periods: int | None = None
    lines: Sequence[int] | None = None
    confidence: float = 0.95
    min_transient_periods: int = 1

    def __post_init__(self) -> None:
        if self.period_samples is not None and self.period_samples < 2:
            raise ValueError(f"period_samples must be >= 2, got {self.period_samples}")
        if self.transient_periods is not None and self.transient_periods < 0:
            raise ValueError(f"transient_periods must be >= 0, got {self.transient_periods}")
        if self.min_transient_periods < 0:
            raise ValueError(f"min_transient_periods must be >= 0, got "
                             f"{self.min_transient_periods}")
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
    periods fit, and ``rho`` stays at or above the threshold at every multiple of ``N``
    (a narrowband signal nearly repeats at its carrier's period and drifts away at the
    multiples). Of the first such lag and its near neighbours (within twice the lag where
    ``rho`` first fell below one half: a signal nearly repeats just before its period)
    the best is returned.

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
    # Candidates: the local maxima of the correlation at or above the threshold, shortest
    # first. A narrowband excitation (a multisine in a few ±5 % bands) nearly repeats at
    # its carrier's period (a tuned loop's stage-1 record on Ucv: 50 samples for 40000),
    # and a little before its own period while the lag is within its envelope's
    # correlation width (rho 0.91 at 39860 on Uch). A true period repeats at every
    # multiple, where a carrier's phase drifts away; and the period is then the best lag
    # within twice that width.
    inner = rho[1:-1]
    peaks = np.flatnonzero((inner >= threshold) & (inner >= rho[:-2]) & (inner >= rho[2:])) + 1
    width = 2 * max(int(below[0]), 1)
    for peak in peaks:
        if float(np.min(rho[peak::peak])) < threshold:
            continue
        k = int(peak) + int(np.argmax(rho[peak:min(peak + width + 1, rho.size)]))
        while k + 1 < rho.size and rho[k + 1] > rho[k]:  # climb to the local maximum
            k += 1
        return k
    return None


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


def detect_transient(output_blocks: NDArray[np.complex128], *, minimum: int = 1,
                     false_alarm: float = _TRANSIENT_FALSE_ALARM) -> int:
    """Leading periods that still carry the transient (the first ``q`` to drop).

    Each period's spectrum (all lines ``1 .. N/2``, every output) is compared
    with the mean of the record's last half, whose spread between periods gives
    each line's noise variance ``s²(k)`` (``M − 1`` degrees of freedom, ``M``
    periods). For a steady period, ``|Y_p(k) − Ȳ(k)|² / (s²(k) (1 + 1/M))`` is
    ``F(2, 2(M − 1))`` at every line. Period ``p`` carries a transient when
    either the sum over the ``K`` lines exceeds its mean by 5 of its standard
    deviations (a transient spread over many lines) or one line exceeds the
    ``F`` quantile at ``1 − false_alarm / K`` (a mode ringing on a few lines).
    The first period that passes both ends the transient: a transient decays.

    Parameters
    ----------
    output_blocks : ndarray, complex, shape (P, K, p)
        Normalised DFT of each whole period of the outputs (lines ``0 .. N/2``).
    minimum : int
        Fewest periods returned.
    false_alarm : float
        Chance that a steady period is called a transient, per period (the
        line test's; the sum's 5 sigma adds < 1e-6).

    Returns
    -------
    int
        Periods to drop: ``minimum`` when fewer than 6 periods leave nothing to
        test, else between ``minimum`` and ``P − P // 2``.
    """
    y = np.asarray(output_blocks)
    total = y.shape[0]
    ref = total // 2
    if total - ref < 3 or total - 2 <= minimum:
        return max(minimum, 0)  # too few periods to test: the minimum
    tail = y[total - ref:, 1:]  # last half, lines 1 .. N/2
    mean = tail.mean(axis=0)
    s2 = np.sum(np.abs(tail - mean) ** 2, axis=0) / (ref - 1)
    ok = s2 > 0
    nu = 2.0 * (ref - 1)
    k = int(ok.sum())
    if k == 0:
        return minimum
    f_mean = nu / (nu - 2.0) if nu > 2 else math.inf
    f_var = nu**3 / ((nu - 2.0) ** 2 * (nu - 4.0)) if nu > 4 else math.inf
    line_limit = float(f_dist.isf(false_alarm / k, 2, nu))
    for p in range(minimum, total - ref):
        ratio = np.abs(y[p, 1:] - mean) ** 2 / np.where(ok, s2, 1.0) / (1.0 + 1.0 / ref)
        ratio = ratio[ok]
        excess = float(ratio.sum()) - k * f_mean
        if excess <= 5.0 * math.sqrt(k * f_var) and float(ratio.max()) <= line_limit:
            return p
    return total - ref


@dataclass(frozen=True)
class Distortion:
    """Nonlinear distortion seen on the non-excited lines of an odd grid (best linear
    approximation, Pintelon & Schoukens ch. 3, the "fast method").

    Attributes
    ----------
    variance : ndarray, shape (F, p)
        Variance the stochastic distortion adds to each excited line's output
        mean, from the nearest odd non-excited lines (their power less their
        noise's), U_out² (normalised DFT); 0 when not detectable.
    detectable : bool
        The grid leaves odd lines free (odd, odd-odd, random-odd designs); a
        full grid's distortion lands on its own lines, out of sight.
    odd_db, even_db : tuple of float
        Per output: distortion power on the odd (even) non-excited lines less
        their noise, over the output power on the excited lines [dB] (NaN: no
        such line or nothing above the noise).
    noise_db : tuple of float
        Per output: the noise variance of the mean on the excited lines over
        their output power [dB].
    """

    variance: NDArray[np.float64]
    detectable: bool
    odd_db: tuple[float, ...]
    even_db: tuple[float, ...]
    noise_db: tuple[float, ...]

    def summary(self) -> dict[str, object]:
        """Plain values."""
        return {"detectable": self.detectable, "odd_db": list(self.odd_db),
                "even_db": list(self.even_db), "noise_db": list(self.noise_db)}


def _db(num: float, den: float) -> float:
    return 10.0 * math.log10(num / den) if num > 0 and den > 0 else math.nan


def distortion(output_mean: NDArray[np.complex128], mean_noise_variance: NDArray[np.float64],
               lines: NDArray[np.intp], *, output_power: NDArray[np.float64] | None = None,
               neighbours: int = _DISTORTION_NEIGHBOURS) -> Distortion:
    """Distortion on the excited ``lines`` from the non-excited ones (see :class:`Distortion`).

    Parameters
    ----------
    output_mean : ndarray, complex, shape (K, p)
        Period-averaged output spectrum at every line ``0 .. N/2`` (less the
        response to what the input holds at the non-excited lines).
    mean_noise_variance : ndarray, shape (K, p)
        Variance of that average (noise), same shape.
    lines : ndarray of int
        Excited lines.
    output_power : ndarray, shape (len(lines), p), optional
        The output's power on the excited lines, the levels' reference
        (default: ``|output_mean|²`` there).
    neighbours : int
        Odd non-excited lines each side averaged for an excited line's level.
    """
    ym = np.asarray(output_mean)
    nv = np.asarray(mean_noise_variance, dtype=float)
    n_out = ym.shape[1]
    excited = np.zeros(ym.shape[0], dtype=bool)
    excited[lines] = True
    lo, hi = int(lines.min()), int(lines.max())
    k = np.arange(ym.shape[0])
    inside = (k >= lo) & (k <= hi) & ~excited & (k >= 1)
    odd_free = np.flatnonzero(inside & (k % 2 == 1))
    even_free = np.flatnonzero(inside & (k % 2 == 0))
    detectable = bool(np.all(lines % 2 == 1) and odd_free.size >= 2)
    var = np.zeros((lines.size, n_out))
    power = np.abs(ym) ** 2
    excess = power - nv  # distortion power, noise taken out (unbiased, may be < 0)
    signal = (power[lines] if output_power is None else np.asarray(output_power)).mean(axis=0)

    def level(free: NDArray[np.intp], j: int) -> float:
        if free.size == 0:
            return math.nan
        e = excess[free, j]
        keep = power[free, j] <= _SPIKE * max(float(np.median(power[free, j])), 1e-300)
        return float(np.mean(e[keep])) if keep.any() else math.nan

    if detectable:
        for j in range(n_out):
            # A spike (a mains harmonic, any periodic disturbance) is not distortion.
            clean = odd_free[power[odd_free, j] <= _SPIKE * _running_median(
                power[odd_free, j])]
            if clean.size == 0:
                continue
            pos = np.searchsorted(clean, lines)
            for i, line in enumerate(lines):
                window = clean[max(0, pos[i] - 2 * neighbours):pos[i] + 2 * neighbours]
                near = window[np.argsort(np.abs(window - line), kind="stable")[:2 * neighbours]]
                local = float(np.mean(excess[near, j]))
                # Counted when above twice its own noise (the mean of the lines' noise
                # powers, exponential: std = mean / sqrt(n)); noise alone would
                # otherwise add ~15 % of the noise variance, clipped at zero.
                if local > 2.0 * float(np.mean(nv[near, j])) / math.sqrt(near.size):
                    var[i, j] = local
    return Distortion(
        variance=var, detectable=detectable,
        odd_db=tuple(_db(level(odd_free, j), float(signal[j])) for j in range(n_out)),
        even_db=tuple(_db(level(even_free, j), float(signal[j])) for j in range(n_out)),
        noise_db=tuple(_db(float(nv[lines, j].mean()), float(signal[j]))
                       for j in range(n_out)))


def _running_median(x: NDArray[np.float64], width: int = 21) -> NDArray[np.float64]:
    """Median of each value's neighbourhood (``width`` values, clipped at the ends)."""
    half = width // 2
    return np.array([np.median(x[max(0, i - half):i + half + 1]) for i in range(x.size)])


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
    steady = _steady_periods(u, y, n, options=opts, input_name=input_name, source=source)
    stats = _period_statistics(u, y, n, first=steady.first, periods=steady.periods)
    lines = _analysed_lines(stats, n, options=opts, periods=steady.periods,
                            input_name=input_name, source=source)
    dist = _output_distortion(stats, lines, periods=steady.periods)
    return _line_estimate(stats, lines, dist, n=n, steady=steady, fs_hz=fs_hz,
                          input_name=input_name, output_names=names,
                          confidence=opts.confidence)


class _SteadyPeriods(NamedTuple):
    """A record's whole periods kept for the average: ``periods`` of them from sample
    ``first``, after ``dropped`` transient ones (``detected`` in the data, or given)."""

    first: int
    periods: int
    dropped: int
    detected: bool


class _PeriodStatistics(NamedTuple):
    """Each line's means over the periods, ``um`` (K,) [U_in] and ``ym`` (K, p) [U_out], and
    sample (co)variances ``s2u`` [U_in²], ``s2y`` [U_out²] and ``syu`` [U_out U_in] (module
    notes; normalised DFT, lines ``0 .. N/2``)."""

    um: NDArray[np.complex128]
    ym: NDArray[np.complex128]
    s2u: NDArray[np.float64]
    s2y: NDArray[np.float64]
    syu: NDArray[np.complex128]


def _steady_periods(u: NDArray[np.float64], y: NDArray[np.float64], n: int, *,
                    options: PeriodicOptions, input_name: str, source: str) -> _SteadyPeriods:
    """The record's last whole periods of ``n`` samples, its transient dropped.

    Raises
    ------
    ValueError
        Fewer than two periods, before or after the transient.
    """
    total = u.size // n
    if total < 2:
        raise ValueError(f"{source}: {input_name} holds {total} whole period(s) of {n} samples; "
                         "at least 2 are needed for a noise estimate")
    head = u.size - total * n  # keep the record's end
    if options.transient_periods is None:
        dropped = detect_transient(_blocks(y, n, head, total),
                                   minimum=options.min_transient_periods)
        detected = True
    else:
        dropped, detected = options.transient_periods, False
    periods = total - dropped
    if periods < 2:
        raise ValueError(f"{source}: {input_name} holds {total} whole period(s) of {n} samples; "
                         f"after dropping {dropped} transient period(s) at least "
                         "2 are needed for a noise estimate")
    return _SteadyPeriods(first=head + dropped * n, periods=periods, dropped=dropped,
                          detected=detected)


def _period_statistics(u: NDArray[np.float64], y: NDArray[np.float64], n: int, *,
                       first: int, periods: int) -> _PeriodStatistics:
    """Means and sample (co)variances over ``periods`` periods of ``n`` samples from
    ``first`` (module notes)."""
    ub = _blocks(u, n, first, periods)  # (P, K)
    yb = _blocks(y, n, first, periods)  # (P, K, p)
    um, ym = ub.mean(axis=0), yb.mean(axis=0)
    du, dy = ub - um, yb - ym
    s2u = np.sum(np.abs(du) ** 2, axis=0) / (periods - 1)  # (K,)
    s2y = np.sum(np.abs(dy) ** 2, axis=0) / (periods - 1)  # (K, p)
    syu = np.einsum("pkc,pk->kc", dy, du.conj()) / (periods - 1)  # (K, p)
    return _PeriodStatistics(um=um, ym=ym, s2u=s2u, s2y=s2y, syu=syu)


def _analysed_lines(stats: _PeriodStatistics, n: int, *, options: PeriodicOptions,
                    periods: int, input_name: str, source: str) -> NDArray[np.intp]:
    """The lines estimated: ``options.lines``, else those the input excites.

    Raises
    ------
    ValueError
        A given line outside ``0 .. n/2``, or no line.
    """
    um = stats.um
    if options.lines is None:
        lines = excited_lines(np.abs(um) ** 2, stats.s2u / periods)
    else:
        lines = np.asarray(sorted({int(k) for k in options.lines}), dtype=np.intp)
        if lines.size and (lines.min() < 0 or lines.max() >= um.size):
            raise ValueError(f"{source}: lines must be in [0, {um.size - 1}] for a period of "
                             f"{n} samples")
    if lines.size == 0:
        raise ValueError(f"{source}: no excited line in the input {input_name}")
    return lines


def _output_distortion(stats: _PeriodStatistics, lines: NDArray[np.intp], *,
                       periods: int) -> Distortion:
    """:func:`distortion` of the output beyond the response to the input's own content."""
    um, ym = stats.um, stats.ym
    s2u, s2y, syu = stats.s2u, stats.s2y, stats.syu
    # The distortion is what the output holds at the non-excited lines beyond the input's
    # own content there (the DAC's quantisation of a periodic command is periodic too) times
    # the response, interpolated between the excited lines.
    g_all = np.empty_like(ym)
    k_all = np.arange(um.size)
    gk = ym[lines] / um[lines][:, None]
    for j in range(ym.shape[1]):
        g_all[:, j] = (np.interp(k_all, lines, gk[:, j].real)
                       + 1j * np.interp(k_all, lines, gk[:, j].imag))
    resid = ym - g_all * um[:, None]
    resid_var = np.maximum(s2y + np.abs(g_all) ** 2 * s2u[:, None]
                           - 2.0 * np.real(g_all.conj() * syu), 0.0) / periods
    return distortion(resid, resid_var, lines, output_power=np.abs(ym[lines]) ** 2)


def _line_estimate(stats: _PeriodStatistics, lines: NDArray[np.intp], dist: Distortion, *,
                   n: int, steady: _SteadyPeriods, fs_hz: float, input_name: str,
                   output_names: Sequence[str], confidence: float) -> FrfEstimate:
    """``G = Y / U`` on ``lines`` with its first-order variance (module notes), as the
    :class:`FrfEstimate` of :func:`periodic_frf` (period ``n`` samples, ``fs_hz`` [Hz])."""
    periods = steady.periods
    s2u, s2y, syu = stats.s2u, stats.s2y, stats.syu
    uk, yk = stats.um[lines], stats.ym[lines]
    g = yk / uk[:, None]
    var = (s2y[lines] + np.abs(g) ** 2 * s2u[lines, None]
           - 2.0 * np.real(g.conj() * syu[lines])) / (periods * np.abs(uk[:, None]) ** 2)
    var = np.maximum(var, 0.0)  # round-off can make a noise-free line's estimate negative
    with np.errstate(divide="ignore"):
        snr = np.abs(g * uk[:, None]) ** 2 / s2y[lines]
    one_sided = np.where((lines == 0) | (2 * lines == n), 1.0, 2.0)
    dist_var = dist.variance / np.abs(uk[:, None]) ** 2
    return FrfEstimate(
        frequency_hz=lines * fs_hz / n, frf=g[:, :, None], frf_variance=var[:, :, None],
        output_noise_psd=(one_sided[:, None] * s2y[lines] / fs_hz)[:, :, None],
        input_psd=(one_sided * np.abs(uk) ** 2 / fs_hz)[:, None], snr=snr[:, :, None],
        input_names=(str(input_name),), output_names=tuple(output_names), fs_hz=float(fs_hz),
        resolution_hz=float(fs_hz) / n, estimator="periodic",
        options={"period_samples": int(n), "periods_used": int(periods),
                 "transient_periods": int(steady.dropped),
                 "transient_detected": steady.detected,
                 "n_lines": int(lines.size), "distortion": dist.summary()},
        dof=(float(periods - 1),), confidence=confidence,
        distortion_variance=dist_var[:, :, None])
