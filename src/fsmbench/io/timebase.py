"""A recording's time base: the uniform grid fitted to ``t``, and how far ``t`` strays from it.

The bench's converters sample on their own clock; ``t`` is what the real-time
target stamped each sample with, read from its own clock, which jitters (a
target's clock stamps 10 kHz samples within ±50 ns of ``k/fs``). The analyses
take the samples as uniform at the rate :func:`fit_time_base` fits to the whole
of ``t`` by least squares (the first step alone would be off by up to twice the
jitter), and keep ``t`` as it was read.

How far ``t`` may stray from the fitted grid, :data:`JITTER_TOLERANCE` (0.1 % of a
period, 100 ns at 10 kHz), is physics, not taste:

* it accepts the ±50 ns stamps with a factor 2 to spare, and separates them from a
  dropped or repeated sample, which moves the rest of ``t`` by a whole period
  (1000 times the tolerance);
* were the stamps the sampling instants themselves (a converter triggered by
  software), a deviation ``d`` would change a sine of frequency ``f`` by at most
  ``2 pi f d`` of its amplitude: at the tolerance, 6e-4 (-64 dB) at 1 kHz and 3e-3
  (-50 dB) at the Nyquist frequency, ten times below the few-percent scatter of the
  identification's frequency responses. (The ±50 ns stamps alone would give 3e-4,
  -70 dB, at 1 kHz.) A 1 % tolerance would allow -44 dB at 1 kHz, comparable to
  that scatter;
* a stored ``t`` whose float resolution alone exceeds it cannot be uniform and is
  named as such: double-precision Unix time (2.4e-7 s between doubles near 1.7e9 s,
  0.12 % of a 10 kHz period at half that spacing) and single precision beyond 2 s.

Only the irregularities a clock cannot produce are refused, each in one line that
names the file, ``t`` and the problem: ``t`` not increasing, a step that is not one
period (a dropped sample, a jump), or ``t`` straying from every uniform grid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Final

import numpy as np

from fsmbench.io.errors import RecordingError
from fsmbench.io.signals import TIME

__all__ = ["EXACT_TOLERANCE", "JITTER_TOLERANCE", "TimeBase", "coarse_double", "fit_time_base",
           "irregular", "nominal_rate", "not_increasing", "rate_text", "single_precision",
           "sum_k_squared", "time_base"]

#: Largest deviation of ``t`` from the fitted uniform grid [periods] taken as clock jitter.
JITTER_TOLERANCE: Final = 1e-3
#: Below this deviation [periods] ``t`` is a uniform grid as computed in float64 (``k/fs``
#: rounds by ~1e-16 of ``t``: 1e-11 s a day into a record, 1e-7 of a 10 kHz period).
EXACT_TOLERANCE: Final = 1e-6


@dataclass(frozen=True)
class TimeBase:
    """The uniform grid fitted to a record's ``t``.

    Attributes
    ----------
    fs_hz : float
        Sampling rate [Hz]: from the first and last sample when ``t`` is a uniform grid
        (``max_deviation_s`` below :data:`EXACT_TOLERANCE` of a period), to 12 significant
        digits; else the least-squares fit over every sample, to the digits its error
        allows (:func:`nominal_rate`).
    max_deviation_s : float
        Largest ``|t[k] - (t0 + k/fs)|`` from the least-squares grid [s].
    at_index : int
        The sample where it is largest.
    """

    fs_hz: float
    max_deviation_s: float
    at_index: int

    @property
    def period_s(self) -> float:
        """The fitted sampling period [s]."""
        return 1.0 / self.fs_hz

    @property
    def jittered(self) -> bool:
        """True when ``t`` strays from a uniform grid by more than float64 rounding."""
        return self.max_deviation_s > EXACT_TOLERANCE * self.period_s

    def jitter_sentence(self) -> str:
        """One line: how far ``t`` strays and how the samples are taken (for a notice)."""
        d, period = self.max_deviation_s, self.period_s
        return (f"t strays up to {_seconds(d)} ({100 * d / period:.2g} % of the "
                f"{_seconds(period)} period, at t[{self.at_index}]) from a uniform grid: clock "
                f"jitter (up to {100 * JITTER_TOLERANCE:g} % accepted); the samples are taken "
                f"as uniform at {rate_text(self.fs_hz)}, fitted to the whole of t (least "
                "squares, to the digits it fixes)")


def rate_text(fs_hz: float) -> str:
    """A rate [Hz] in words with the digits it was given (``"10000.00003 Hz"``)."""
    return f"{fs_hz:.12g} Hz"


def _seconds(x: float) -> str:
    for scale, unit in ((1.0, "s"), (1e-3, "ms"), (1e-6, "µs"), (1e-9, "ns")):
        if abs(x) >= scale:
            return f"{x / scale:.3g} {unit}"
    return f"{x / 1e-12:.3g} ps"


def _two_times(a: float, b: float) -> tuple[str, str]:
    """Two times [s] with 10 significant digits, or as many more as tell them apart."""
    for digits in range(10, 18):
        sa, sb = f"{a:.{digits}g}", f"{b:.{digits}g}"
        if sa != sb or a == b:
            return sa, sb
    return sa, sb


def sum_k_squared(n: int) -> float:
    """``sum(k**2)`` of the centred sample numbers ``k - (n - 1)/2``, in closed form."""
    return n * (n * n - 1.0) / 12.0


def _least_squares(t: np.ndarray) -> tuple[float, np.ndarray]:
    """(period [s], |residuals| [s]) of the line ``t0 + k T`` fitted to ``t``.

    Three arrays of ``t``'s size, the rest in place. The sum of products is numpy's pairwise
    sum, not BLAS's dot (12 ms for 1e5 samples on a 2-core machine, measured, against 0.1 ms).
    """
    n = t.size
    k = np.arange(n, dtype=np.float64)
    k -= 0.5 * (n - 1)  # centred: slope and mean uncorrelated
    u = t - t[0]  # t far from 0 (Unix time) keeps its resolution in the differences
    scratch = k * u
    period = float(scratch.sum()) / sum_k_squared(n)
    u -= float(np.mean(u))
    u -= np.multiply(k, period, out=scratch)
    return period, np.abs(u, out=u)


def fit_time_base(t: np.ndarray, origin: str) -> TimeBase:
    """Fit a uniform grid to ``t`` [s]; refuse what clock jitter cannot explain.

    Parameters
    ----------
    t : numpy.ndarray
        Sample times [s], shape (N,), N >= 2, finite.
    origin : str
        The file (or label) the messages name.

    Returns
    -------
    TimeBase
        The rate and how far ``t`` strays from the grid.

    Raises
    ------
    RecordingError
        On ``t``: not increasing (the first place named), or straying from the fitted grid
        by more than :data:`JITTER_TOLERANCE` of a period (the step farthest from the
        median step named, in periods, with the samples it says are missing).
    """
    not_up = ~(t[1:] > t[:-1])
    if not_up.any():
        i = int(np.argmax(not_up))
        raise not_increasing(origin, i + 1, float(t[i]), float(t[i + 1]))
    period, residual = _least_squares(t)
    at = int(np.argmax(residual))
    base = time_base(n=t.size, span_s=float(t[-1] - t[0]), period_s=period,
                     deviation_s=float(residual[at]), at_index=at)
    if base is None:
        dt = np.diff(t)
        step = float(np.median(dt))
        i = int(np.argmax(np.abs(dt - step)))
        raise irregular(origin, index=i + 1, t_before=float(t[i]), t_after=float(t[i + 1]),
                        step_s=step, step_words="the median step",
                        deviation_s=float(residual[at]), period_s=period)
    return base


def time_base(*, n: int, span_s: float, period_s: float, deviation_s: float,
              at_index: int) -> TimeBase | None:
    """The time base of a least-squares fit, or None when ``t`` strays too far from it.

    Parameters
    ----------
    n : int
        Samples.
    span_s : float
        ``t[-1] - t[0]`` [s].
    period_s : float
        The fitted period [s].
    deviation_s : float
        Largest distance of ``t`` from the fitted grid [s].
    at_index : int
        Where it is largest.
    """
    if deviation_s > JITTER_TOLERANCE * period_s:
        return None
    if deviation_s <= EXACT_TOLERANCE * period_s:
        # The rate read before jitter was accepted: the mean step over the whole record,
        # exact to ~1e-15, whose 12 digits recover the nominal value (10000.0, not
        # 9999.999999999998).
        fs = float(f"{(n - 1) / span_s:.12g}")
    else:
        fs = nominal_rate(period_s=period_s, deviation_s=deviation_s, n=n)
    return TimeBase(fs_hz=fs, max_deviation_s=deviation_s, at_index=at_index)


def nominal_rate(*, period_s: float, deviation_s: float, n: int) -> float:
    """The rate [Hz] of a least-squares period, as the shortest decimal its error allows.

    Stamps within ``d`` of the true grid move the fitted period by at most
    ``d sum|k| / sum k^2 = 3 d / n`` (``k`` the centred sample numbers), so the rate is
    known to ``3 d / (n T)`` of itself: ±3e-4 Hz for 50 ns stamps over 5 s at 10 kHz. Within
    that, the fewest significant digits: the bench's 10000 Hz for every record of one
    clock (the stages require one rate), a crystal's 10000.3 Hz where the record shows it.

    Parameters
    ----------
    period_s : float
        The least-squares period [s].
    deviation_s : float
        Largest distance of ``t`` from the fitted grid [s].
    n : int
        Samples.
    """
    fs = 1.0 / period_s
    bound = fs * 3.0 * deviation_s / (n * period_s)
    for digits in range(1, 13):
        rounded = float(f"{fs:.{digits}g}")
        if abs(rounded - fs) <= bound:
            return rounded
    return float(f"{fs:.12g}")


def not_increasing(origin: str, index: int, t_before: float, t_after: float) -> RecordingError:
    """The refusal of a ``t`` that stops increasing at ``index``."""
    a, b = _two_times(t_before, t_after)
    return RecordingError(origin, f"is not increasing at index {index}: t[{index - 1}] = {a} s, "
                          f"t[{index}] = {b} s", variable=TIME, kind="is not increasing")


def irregular(origin: str, *, index: int, t_before: float, t_after: float, step_s: float,
              step_words: str, deviation_s: float, period_s: float) -> RecordingError:
    """The refusal of a ``t`` that strays from every uniform grid: the step farthest from
    ``step_s`` (between ``index - 1`` and ``index``), in periods, and the deviation."""
    a, b = _two_times(t_before, t_after)
    gap = t_after - t_before
    periods = gap / step_s
    missing = round(periods) - 1
    why = (f"; {missing} sample{'s' if missing > 1 else ''} missing?"
           if missing >= 1 and abs(periods - round(periods)) < 0.1 else "")
    return RecordingError(
        origin, f"is not uniformly sampled at index {index}: t[{index - 1}] = {a} s, "
        f"t[{index}] = {b} s, a step of {gap:.6g} s where {step_words} is {step_s:.6g} s "
        f"({periods:.3g} periods{why}); t strays {_seconds(deviation_s)} "
        f"({_percent(deviation_s / period_s)} of a period) from a uniform grid, more than "
        f"clock jitter ({100 * JITTER_TOLERANCE:g} %)", variable=TIME,
        kind="is not uniformly sampled")


def _percent(fraction: float) -> str:
    return f"{100 * fraction:.3g} %" if math.isfinite(fraction) else "an unknown fraction"


def coarse_double(t: np.ndarray) -> str | None:
    """Why a double ``t`` far from 0 cannot lie on a uniform grid, or None.

    Unix time: doubles near 1.7e9 s are 2.4e-7 s apart, so rounding alone moves a
    stamp by up to 1.2e-7 s, 0.12 % of a 10 kHz period. Named when rounding alone
    reaches half of :data:`JITTER_TOLERANCE`.
    """
    if t.size < 2 or not np.isfinite(t).all():
        return None
    top, step = float(np.max(np.abs(t))), float(np.median(np.diff(t)))
    spacing = float(np.spacing(top))
    if not (step > 0 and 0.5 * spacing > 0.5 * JITTER_TOLERANCE * step):
        return None
    unix = 1e8 < float(t[0]) < 1e10  # 1973 to 2286 in seconds since 1970
    return (f"t is stored in double precision (float64), whose values near {top:.4g} s are "
            f"{spacing:.3g} s apart ({100 * spacing / step:.2g} % of the {step:.3g} s step), so "
            "the steps cannot be uniform"
            + ("; t looks like an absolute time (seconds since 1970, Unix time)"
               if unix else "; t starts far from 0")
            + ": save the time from the record's start, rebuilt from the sample numbers "
            "(MATLAB: t = (0:N-1)'/fs), and the start time, if needed, in another variable")


def single_precision(t: np.ndarray, stored: np.dtype[Any]) -> str:
    """Why a single-precision ``t`` is not uniform, and the fix."""
    top = float(np.max(np.abs(t)))
    spacing = float(np.spacing(np.asarray(top, dtype=stored)))
    return (f"t is stored in single precision ({stored}), whose values near {top:.4g} s are "
            f"{spacing:.3g} s apart, so the steps cannot be uniform; save t in double "
            "precision, rebuilt from the sample numbers (MATLAB: t = (0:N-1)'/fs)")
