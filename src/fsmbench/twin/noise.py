"""Noise and drift generators of the twin, vectorised and seeded.

Every source draws from its own generator, derived from the run's seed, the
experiment and the source's name, so adding a source never changes the
others and the same seed always gives the same files.
"""

from __future__ import annotations

import hashlib

import numpy as np
from scipy.signal import lfilter

from fsmbench.filters import first_order_lowpass

__all__ = ["first_order_lag", "gauss_markov", "source_rng", "white_noise"]


def source_rng(seed: int, experiment: str, source: str) -> np.random.Generator:
    """Independent generator for one noise source of one experiment.

    The (experiment, source) names are hashed into the seed sequence's spawn
    key; the hash (not Python's salted ``hash``) keeps runs reproducible
    across processes.
    """
    digest = hashlib.sha256(f"{experiment}/{source}".encode()).digest()
    key = tuple(int.from_bytes(digest[i:i + 4], "little") for i in range(0, 16, 4))
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=key))


def white_noise(rng: np.random.Generator, n: int, *, rms: float) -> np.ndarray:
    """Gaussian white noise, shape (n,), standard deviation ``rms`` (flat to Nyquist)."""
    if rms == 0.0:
        return np.zeros(n)
    return rms * rng.standard_normal(n)


def gauss_markov(rng: np.random.Generator, n: int, *, rms: float, tau_s: float,
                 fs_hz: float) -> np.ndarray:
    """Stationary first-order Gauss-Markov process (sampled Ornstein-Uhlenbeck).

    ``x[k+1] = a x[k] + sqrt(1 - a**2) rms w[k]`` with ``a = exp(-1/(fs tau))``
    is the exact sampling of ``dx = -x/tau dt + ...``; ``x[0]`` is drawn from
    the stationary law, so the process has standard deviation ``rms`` at every
    sample and a Lorentzian spectrum with corner ``1/(2 pi tau)``.

    Parameters
    ----------
    rng : numpy Generator
    n : int
        Number of samples.
    rms : float
        Stationary standard deviation (unit of the result).
    tau_s : float
        Correlation time [s] (> 0).
    fs_hz : float
        Sampling frequency [Hz].
    """
    if rms == 0.0:
        return np.zeros(n)
    if tau_s <= 0:
        raise ValueError(f"tau_s must be > 0, got {tau_s}")
    a = float(np.exp(-1.0 / (fs_hz * tau_s)))
    x0 = rms * rng.standard_normal()
    w = rms * np.sqrt(1.0 - a * a) * rng.standard_normal(n)
    w[0] = x0  # x[0] = x0 exactly; later samples follow the recursion
    return lfilter([1.0], [1.0, -a], w)


def first_order_lag(x: np.ndarray, *, tau_s: float, fs_hz: float) -> np.ndarray:
    """Response of ``1/(1 + tau s)`` to a zero-order-held ``x``, starting in equilibrium.

    Step-invariant discretisation: ``y[k+1] = a y[k] + (1 - a) x[k]``, ``y[0] = x[0]``.
    """
    return first_order_lowpass(x, cutoff_hz=1.0 / (2.0 * np.pi * tau_s), fs_hz=fs_hz,
                               initial="steady")
