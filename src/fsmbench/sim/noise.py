"""Noise and drift generators of the bench, seeded and streaming.

Every source draws from its own generator, derived from the run's seed, the
experiment and the source's name, so adding a source never changes the
others and the same seed always gives the same files.

Each generator is a small stateful stream (:class:`WhiteStream`,
:class:`GaussMarkovStream`, :class:`LagStream`): asked for ``n1`` then
``n2`` samples it returns, bit for bit, what one request of ``n1 + n2``
returns (numpy's generators consume their bit stream sample by sample, and
the filters hand their state over). The whole-record functions
(:func:`white_noise`, :func:`gauss_markov`, :func:`first_order_lag`) are
one request of these streams.
"""

from __future__ import annotations

import hashlib
import math
from typing import Any

import numpy as np
from scipy.signal import lfilter, lfilter_zi

__all__ = [
    "DriftStream",
    "FlickerStream",
    "GaussMarkovStream",
    "LagStream",
    "MainsStream",
    "WhiteStream",
    "first_order_lag",
    "gauss_markov",
    "source_rng",
    "white_noise",
]


def source_rng(seed: int, experiment: str, source: str) -> np.random.Generator:
    """Independent generator for one noise source of one experiment.

    The (experiment, source) names are hashed into the ESRF study sequence's spawn
    key; the hash (not Python's salted ``hash``) keeps runs reproducible
    across processes.
    """
    digest = hashlib.sha256(f"{experiment}/{source}".encode()).digest()
    key = tuple(int.from_bytes(digest[i:i + 4], "little") for i in range(0, 16, 4))
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=key))


class WhiteStream:
    """Gaussian white noise of standard deviation ``rms``, delivered in blocks.

    Parameters
    ----------
    rng : numpy Generator
        Owned by the stream from now on.
    rms : float
        Standard deviation (unit of the result); 0 gives zeros and draws nothing.
    """

    def __init__(self, rng: np.random.Generator, *, rms: float) -> None:
        self._rng = rng
        self.rms = float(rms)

    def next(self, n: int) -> np.ndarray:
        """The next ``n`` samples, shape (n,)."""
        if self.rms == 0.0:
            return np.zeros(n)
        x = self._rng.standard_normal(n)
        x *= self.rms  # in place: the same products, without a second array (20 % faster)
        return x


class GaussMarkovStream:
    """Stationary first-order Gauss-Markov process (sampled Ornstein-Uhlenbeck), in blocks.

    ``x[k+1] = a x[k] + sqrt(1 - a**2) rms w[k]`` with ``a = exp(-1/(fs tau))``
    is the exact sampling of ``dx = -x/tau dt + ...``; ``x[0]`` is drawn from
    the stationary law, so the process has standard deviation ``rms`` at every
    sample and a Lorentzian spectrum with corner ``1/(2 pi tau)``.

    Parameters
    ----------
    rng : numpy Generator
    rms : float
        Stationary standard deviation (unit of the result).
    tau_s : float
        Correlation time [s] (> 0).
    fs_hz : float
        Sampling frequency [Hz].
    """

    def __init__(self, rng: np.random.Generator, *, rms: float, tau_s: float,
                 fs_hz: float) -> None:
        if rms != 0.0 and tau_s <= 0:
            raise ValueError(f"tau_s must be > 0, got {tau_s}")
        self._rng = rng
        self.rms = float(rms)
        self._a = float(np.exp(-1.0 / (fs_hz * tau_s))) if rms != 0.0 else 0.0
        self._zi: np.ndarray | None = None  # filter state; None before the first sample

    def next(self, n: int) -> np.ndarray:
        """The next ``n`` samples, shape (n,)."""
        if self.rms == 0.0:
            return np.zeros(n)
        if n == 0:
            return np.zeros(0)
        a = self._a
        first = self._zi is None
        x0 = self.rms * self._rng.standard_normal() if first else 0.0
        w = self._rng.standard_normal(n)
        w *= self.rms * np.sqrt(1.0 - a * a)  # in place, as WhiteStream
        if first:
            w[0] = x0  # x[0] = x0 exactly; later samples follow the recursion
            self._zi = np.zeros(1)
        y, self._zi = lfilter([1.0], [1.0, -a], w, zi=self._zi)
        return np.asarray(y, dtype=float)


class LagStream:
    """``1/(1 + tau s)`` applied to a zero-order-held input delivered in blocks.

    Step-invariant discretisation ``y[k+1] = a y[k] + (1 - a) x[k]`` with
    ``a = exp(-Ts/tau)``, starting in equilibrium with the first sample
    (``y[0] = x[0]``).

    Parameters
    ----------
    tau_s : float
        Time constant [s].
    fs_hz : float
        Sampling frequency [Hz].
    """

    def __init__(self, *, tau_s: float, fs_hz: float) -> None:
        # The pole as fsmbench.filters.first_order_lowpass computes it (cutoff 1/(2 pi tau)).
        a = math.exp(-2.0 * math.pi * (1.0 / (2.0 * math.pi * tau_s)) / fs_hz)
        self._b = np.array([0.0, 1.0 - a])
        self._a = np.array([1.0, -a])
        self._zi: np.ndarray | None = None

    def next(self, x: np.ndarray) -> np.ndarray:
        """Filter the next block ``x`` (n,); returns (n,)."""
        x = np.asarray(x, dtype=float)
        if x.size == 0:
            return x.copy()
        if self._zi is None:
            self._zi = lfilter_zi(self._b, self._a) * x[0]
        y, self._zi = lfilter(self._b, self._a, x, zi=self._zi)
        return np.asarray(y, dtype=float)


class FlickerStream:
    """1/f noise as a sum of Gauss-Markov processes with log-spaced corners, in blocks.

    A Lorentzian of variance ``s**2`` and corner ``fc`` has the one-sided PSD
    ``(2 s**2 / (pi fc)) / (1 + (f/fc)**2)``; corners spaced by a factor ``r``
    with equal variances ``s**2 = A**2 ln r`` sum to ``A**2 / f`` between the
    lowest and highest corner (the integral over ``ln fc`` of the Lorentzians
    is ``pi/(2 f)``: van der Ziel's sum of relaxation processes). Three
    corners per decade keep the sum within 0.2 dB of ``A**2 / f`` a decade
    inside the corners (``tests/sim/test_real_bench.py``). Each process draws
    from its own generator, so blocks of any length give the bits of one request.

    Parameters
    ----------
    rngs : callable
        ``rngs(i)`` returns the generator of process ``i`` (called once each).
    asd_at_1hz : float
        Amplitude spectral density at 1 Hz, ``A`` [unit/sqrt(Hz)] (0: off).
    f_min_hz : float
        Lowest corner [Hz]: below it the spectrum flattens.
    fs_hz : float
        Sampling frequency [Hz]; the highest corner is ``fs/2``.
    per_decade : int
        Corners per decade.
    """

    def __init__(self, rngs: Any, *, asd_at_1hz: float, f_min_hz: float, fs_hz: float,
                 per_decade: int = 3) -> None:
        self.asd_at_1hz = float(asd_at_1hz)
        self._parts: list[GaussMarkovStream] = []
        if self.asd_at_1hz == 0.0:
            return
        if not 0 < f_min_hz < fs_hz / 2:
            raise ValueError(f"f_min_hz must be in (0, fs/2), got {f_min_hz}")
        n = int(np.ceil(per_decade * np.log10(fs_hz / 2 / f_min_hz))) + 1
        ratio = 10.0 ** (1.0 / per_decade)
        rms = self.asd_at_1hz * math.sqrt(math.log(ratio))
        self.corners_hz = f_min_hz * ratio ** np.arange(n)
        self._parts = [GaussMarkovStream(rngs(i), rms=rms, tau_s=1.0 / (2 * math.pi * fc),
                                         fs_hz=fs_hz) for i, fc in enumerate(self.corners_hz)]

    def next(self, n: int) -> np.ndarray:
        """The next ``n`` samples, shape (n,)."""
        out = np.zeros(n)
        for part in self._parts:
            out += part.next(n)
        return out


def _random_walk(rng: np.random.Generator, zi: np.ndarray, step_rms: float,
                 n: int) -> tuple[np.ndarray, np.ndarray]:
    """``x[k] = x[k-1] + step_rms w[k]`` from state ``zi`` (sequential: bit-identical in blocks)."""
    if n == 0:
        # scipy's lfilter returns an undefined final state for an empty input.
        return np.zeros(0), zi
    w = step_rms * rng.standard_normal(n)
    y, zf = lfilter([1.0], [1.0, -1.0], w, zi=zi)
    return np.asarray(y, dtype=float), np.asarray(zf, dtype=float)


class MainsStream:
    """Mains lines: ``sum_m A_m sin(2 pi m f0 t + p_m + m w(t))``, in blocks.

    The phases ``p_m`` are drawn once (uniform); ``w(t)`` is an optional random
    walk of the mains phase (``wander_rad_per_rts`` [rad/sqrt(s)]), the slow
    wandering of the grid's frequency, which every harmonic follows ``m`` times.
    Time is counted from the stream's first sample, so blocks give the bits
    of one request.

    Parameters
    ----------
    rng : numpy Generator
    fs_hz : float
        Sampling frequency [Hz].
    freq_hz : float
        Mains frequency f0 [Hz].
    amplitudes : sequence of float
        Peak amplitude of the fundamental, 2nd, 3rd, ... harmonic (unit of the result).
    wander_rad_per_rts : float
    """

    def __init__(self, rng: np.random.Generator, *, fs_hz: float, freq_hz: float,
                 amplitudes: Any, wander_rad_per_rts: float = 0.0) -> None:
        self._rng = rng
        self.amplitudes = np.asarray(amplitudes, dtype=float)
        self.fs_hz = float(fs_hz)
        self.freq_hz = float(freq_hz)
        self._step = float(wander_rad_per_rts) / math.sqrt(self.fs_hz)
        self._phases = (rng.uniform(0.0, 2 * math.pi, self.amplitudes.size)
                        if np.any(self.amplitudes != 0) else np.zeros(0))
        self._zi = np.zeros(1)
        self._k = 0

    def next(self, n: int) -> np.ndarray:
        """The next ``n`` samples, shape (n,)."""
        out = np.zeros(n)
        if self._phases.size == 0:
            return out
        k = np.arange(self._k, self._k + n, dtype=float)
        self._k += n
        wander = np.zeros(n)
        if self._step:
            wander, self._zi = _random_walk(self._rng, self._zi, self._step, n)
        for m, (amp, p0) in enumerate(zip(self.amplitudes, self._phases, strict=True), start=1):
            if amp == 0.0:
                continue
            # Cycles modulo 1 keep the phase exact over days of samples.
            cycles = np.mod(m * self.freq_hz * k / self.fs_hz, 1.0)
            out += amp * np.sin(2 * math.pi * cycles + p0 + m * wander)
        return out


class DriftStream:
    """Offset drift ``rate t + random walk`` (t from the first sample), in blocks.

    Parameters
    ----------
    rng : numpy Generator
    fs_hz : float
        Sampling frequency [Hz].
    rate_per_s : float
        Linear drift [unit/s].
    random_walk_per_rts : float
        Random walk: the offset's standard deviation grows as this times
        ``sqrt(t)`` [unit/sqrt(s)].
    """

    def __init__(self, rng: np.random.Generator, *, fs_hz: float, rate_per_s: float,
                 random_walk_per_rts: float) -> None:
        self._rng = rng
        self.fs_hz = float(fs_hz)
        self.rate_per_s = float(rate_per_s)
        self._step = float(random_walk_per_rts) / math.sqrt(self.fs_hz)
        self._zi = np.zeros(1)
        self._k = 0

    def next(self, n: int) -> np.ndarray:
        """The next ``n`` samples, shape (n,)."""
        out = self.rate_per_s * (np.arange(self._k, self._k + n, dtype=float) / self.fs_hz)
        self._k += n
        if self._step:
            walk, self._zi = _random_walk(self._rng, self._zi, self._step, n)
            out = out + walk
        return out


def white_noise(rng: np.random.Generator, n: int, *, rms: float) -> np.ndarray:
    """Gaussian white noise, shape (n,), standard deviation ``rms`` (flat to Nyquist)."""
    return WhiteStream(rng, rms=rms).next(n)


def gauss_markov(rng: np.random.Generator, n: int, *, rms: float, tau_s: float,
                 fs_hz: float) -> np.ndarray:
    """``n`` samples of :class:`GaussMarkovStream` (see there), shape (n,)."""
    return GaussMarkovStream(rng, rms=rms, tau_s=tau_s, fs_hz=fs_hz).next(n)


def first_order_lag(x: np.ndarray, *, tau_s: float, fs_hz: float) -> np.ndarray:
    """Response of ``1/(1 + tau s)`` to a zero-order-held ``x``, starting in equilibrium.

    Step-invariant discretisation: ``y[k+1] = a y[k] + (1 - a) x[k]``, ``y[0] = x[0]``.
    """
    return LagStream(tau_s=tau_s, fs_hz=fs_hz).next(x)
