"""The spectra the engine's noise streams produce, in closed form.

Every prediction that needs a noise spectrum (the closed-loop tracking error,
the model validation) takes it from here, so it is the spectrum of exactly
the streams :class:`~fsmbench.sim.stream.BenchStream` runs
(:mod:`fsmbench.sim.noise`), sampled as they are:

- white noise of standard deviation σ: one-sided ``2σ²/fs``;
- a sampled Gauss–Markov process ``x[k+1] = a x[k] + √(1−a²) s w[k]``:
  ``2 s² (1−a²) / (fs |1 − a e^{−jωT}|²)`` (its variance is ``s²``, Parseval);
  the 1/f noise is a sum of them (:class:`~fsmbench.sim.noise.FlickerStream`,
  :func:`flicker_psd`); the noise model's fit uses the same closed forms;
- a random walk of step ``σ_w`` per sample: ``2 σ_w² / (fs |1 − e^{−jωT}|²)``
  (non-stationary: its spectrum over a record of length T is this one above
  ``1/T``);
- mains lines: power ``A²/2`` at each harmonic, returned apart.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fsmbench.bench.params import BenchParams
from fsmbench.sim.noise import FlickerStream

__all__ = ["NoiseSpectrum", "flicker_corners", "flicker_psd", "gauss_markov_psd",
           "qd_noise_spectrum", "walk_psd"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class NoiseSpectrum:
    """One-sided spectrum of a noise on each 4QD axis.

    Attributes
    ----------
    f_hz : array (F,)
        Frequencies [Hz], > 0.
    psd : array (F, 2)
        Broadband one-sided PSD per axis (h, v) [unit²/Hz].
    line_freqs_hz : array (L,)
        Frequencies of the lines [Hz].
    line_power : array (L, 2)
        Power of each line per axis [unit²] (a sine of peak A carries A²/2).
    """

    f_hz: FloatArray
    psd: FloatArray
    line_freqs_hz: FloatArray
    line_power: FloatArray

    def variance(self) -> FloatArray:
        """Broadband (trapezoid over ``f_hz``) plus line power, per axis, shape (2,)."""
        broad = np.trapezoid(self.psd, self.f_hz, axis=0) if self.f_hz.size > 1 \
            else np.zeros(2)
        return np.asarray(broad + self.line_power.sum(axis=0))


def gauss_markov_psd(f_hz: FloatArray, *, rms: float, tau_s: float, fs_hz: float) -> FloatArray:
    """One-sided PSD of the sampled Gauss–Markov process of :mod:`fsmbench.sim.noise` [unit²/Hz]."""
    a = math.exp(-1.0 / (fs_hz * tau_s))
    z = np.exp(-2j * np.pi * np.asarray(f_hz, dtype=float) / fs_hz)
    return np.asarray(2.0 * rms**2 * (1.0 - a * a) / (fs_hz * np.abs(1.0 - a * z) ** 2))


def flicker_corners(f_min_hz: float, fs_hz: float) -> tuple[FloatArray, float]:
    """:class:`~fsmbench.sim.noise.FlickerStream`'s corners [Hz] and ``ln`` of their ratio.

    Each of its Gauss–Markov parts has variance ``A² ln(ratio)`` for an ASD ``A`` at 1 Hz.
    """
    c = FlickerStream(lambda i: None, asd_at_1hz=1.0, f_min_hz=f_min_hz, fs_hz=fs_hz).corners_hz
    return np.asarray(c, dtype=float), math.log(c[1] / c[0])


def flicker_psd(f_hz: FloatArray, *, f_min_hz: float, fs_hz: float) -> FloatArray:
    """One-sided PSD of FlickerStream for ``A = 1`` [1/Hz]: its sampled AR(1) parts, exactly.

    Each part ``2 s² (1 − a²) / (fs |1 − a e^{−jωT}|²)`` is written as
    ``(1 − a²) / ((1 − a)² + 4 a sin²(ωT/2))`` with ``expm1``: no cancellation for
    the slowest corners, where ``a → 1``.
    """
    corners, s2 = flicker_corners(f_min_hz, fs_hz)
    la = -2.0 * np.pi * corners / fs_hz  # ln a: a = exp(-1/(fs tau)), tau = 1/(2 pi fc)
    sin2 = np.sin(np.pi * np.asarray(f_hz, dtype=float) / fs_hz)[..., None] ** 2
    part = -np.expm1(2 * la) / (np.expm1(la) ** 2 + 4 * np.exp(la) * sin2)
    return np.asarray(2.0 * s2 / fs_hz * part.sum(axis=-1), dtype=float)


def walk_psd(f_hz: FloatArray, *, fs_hz: float) -> FloatArray:
    """One-sided PSD of a random walk of 1 unit/√s sampled at ``fs_hz`` [1/Hz]."""
    return np.asarray(1.0 / (2 * fs_hz**2 * np.sin(np.pi * np.asarray(f_hz, dtype=float)
                                                     / fs_hz) ** 2))


def qd_noise_spectrum(params: BenchParams, f_hz: FloatArray) -> NoiseSpectrum:
    """The 4QD output noise the engine adds (white, 1/f, offset random walk, mains) [V].

    Parameters
    ----------
    params : BenchParams
        ``quad_diode`` noise keys and the converter rate (what the engine reads).
    f_hz : array (F,)
        Frequencies > 0 [Hz].

    Notes
    -----
    The Newport's angle noise seen by the 4QD and the converters' quantisation
    are not included: they enter the loop elsewhere. The linear offset drift
    is deterministic (a ramp, removed with the mean by every analysis that
    detrends) and is left out.
    """
    f = np.asarray(f_hz, dtype=float)
    if np.any(f <= 0):
        raise ValueError("f_hz must be > 0")
    qd = params.quad_diode
    fs = params.converter.fs_hz
    psd = np.zeros((f.size, 2))
    for i, axis in enumerate("hv"):
        psd[:, i] = 2.0 * qd.noise_rms_v[axis] ** 2 / fs
        asd = qd.flicker_asd_v_per_rthz[axis]
        if asd:
            psd[:, i] += asd**2 * flicker_psd(f, f_min_hz=qd.flicker_min_hz, fs_hz=fs)
        walk = qd.offset_random_walk_v_per_rts[axis]
        if walk:
            psd[:, i] += walk**2 * walk_psd(f, fs_hz=fs)
    amps = np.asarray(qd.mains_amplitude_v, dtype=float)
    keep = np.nonzero(amps != 0.0)[0]
    freqs = (keep + 1) * qd.mains_freq_hz
    inside = freqs < fs / 2
    power = np.repeat((amps[keep][inside] ** 2 / 2.0)[:, None], 2, axis=1)
    return NoiseSpectrum(f_hz=f, psd=psd, line_freqs_hz=np.asarray(freqs[inside], dtype=float),
                         line_power=power)
