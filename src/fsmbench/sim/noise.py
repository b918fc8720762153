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

import numpy as np
from scipy.signal import lfilter, lfilter_zi

__all__ = [
    "GaussMarkovStream",
    "LagStream",
    "WhiteStream",
    "first_order_lag",
    "gauss_markov",
    "source_rng",
    "white_noise",
]


def source_rng(seed: int, experiment: str, source: str) -> np.random.Generator:
    """Independent generator for one noise source of one experiment.

    The (experiment, source) names are hashed into the seed sequence's spawn
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
        return self.rms * self._rng.standard_normal(n)


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
        w = self.rms * np.sqrt(1.0 - a * a) * self._rng.standard_normal(n)
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
