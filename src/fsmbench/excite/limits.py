"""Converter limits of an excitation, checked through the bench model before it is written.

An excitation on one DAC channel must fit the DAC itself and every ADC
channel the bench carries it to. For ``Uch`` the coil-voltage channel
``Vch = Ga Zc Gi Uch`` (about 185 V/V at DC in the nominal model, a 1 kHz
low pass) is the tight one: it is why the seed injects only tens of mV.
The 4QD outputs ``Vph, Vpv`` see the Sercalo's lightly damped modes.

The peak is taken on the samples the ADCs would read: the designed samples
go through the bench's sampled model (:func:`fsmbench.sim.plant.twin_discrete`:
DAC delay, zero-order hold, the circuit and mechanics, the Newport's lag),
from rest, as one linear convolution evaluated with FFTs and enough zeros
behind the record for the slowest mode to die out (no wrap-around). An
excitation a player repeats (``after_end = "repeat"``) is also checked in its
periodic steady state. Noise of the bench is not included: it adds
millivolts to peaks of volts.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.fft
from scipy.linalg import schur

from fsmbench.bench.params import BenchParams
from fsmbench.excite.design import ExcitationDesign
from fsmbench.sim.discretize import DiscretePlant
from fsmbench.sim.plant import ADC_CHANNELS, DAC_CHANNELS, twin_discrete

__all__ = ["ConverterPeak", "ExcitationLimitError", "LimitReport", "check_limits",
           "converter_peaks", "input_response", "response_from_rest"]

# Residual of the slowest mode left when the zero padding ends (wrap-around error).
_TAIL_DECAY = 1e-9
# A channel whose peak stays below this fraction of its range is not reached
# (exact zeros of the model give ~1e-17 V through the solver).
_REACHED_FRACTION = 1e-9


class ExcitationLimitError(ValueError):
    """An excitation leaves a converter's range; the message is one line."""


@dataclass(frozen=True)
class ConverterPeak:
    """Largest value an excitation gives on one converter channel.

    Attributes
    ----------
    converter : str
        ``"DAC"`` or ``"ADC"``.
    signal : str
        The channel, the seed's name (``Uch``, ``Vch`` ...).
    peak_v : float
        Largest absolute value [V].
    limit_v : float
        Half the converter's span [V] (10 V for the bench's ±10 V converters).
    """

    converter: str
    signal: str
    peak_v: float
    limit_v: float

    @property
    def fraction(self) -> float:
        """``peak_v / limit_v`` [1]."""
        return self.peak_v / self.limit_v

    def line(self) -> str:
        """``ADC Vch: 7.12 V peak of ±10 V (71 %)``."""
        return (f"{self.converter} {self.signal}: {self.peak_v:.3g} V peak of "
                f"±{self.limit_v:g} V ({100 * self.fraction:.0f} %)")


@dataclass(frozen=True)
class LimitReport:
    """Peaks of one excitation at the DAC and every ADC channel it reaches.

    Attributes
    ----------
    input : str
        DAC channel excited.
    model : str
        Which parameters the check used (``"nominal"`` or ``"true"``).
    amplitude_rms_v : float
        Rms of the excitation checked [V].
    peaks : tuple of ConverterPeak
        The DAC first, then the ADC channels reached.
    slowest_time_constant_s : float
        Envelope time constant of the model's slowest mode [s] (the Sercalo's
        lightly damped modes, ``1 / (xi w0)``): how long a start-up transient
        lasts, what transient periods should cover.
    """

    input: str
    model: str
    amplitude_rms_v: float
    peaks: tuple[ConverterPeak, ...]
    slowest_time_constant_s: float = 0.0

    def worst(self) -> ConverterPeak:
        """The channel nearest (or furthest beyond) its limit."""
        return max(self.peaks, key=lambda c: c.fraction)

    @property
    def fits(self) -> bool:
        """Every peak inside its limit."""
        return self.worst().fraction <= 1.0

    def fitting_amplitude_rms_v(self) -> float:
        """Largest rms amplitude that fits every converter [V], 3 significant digits, down."""
        x = self.amplitude_rms_v / self.worst().fraction
        step = 10.0 ** (math.floor(math.log10(x)) - 2)
        return math.floor(x / step * (1 + 1e-12)) * step

    def verdict(self) -> str:
        """One line: the first violation with the amplitude that would fit, or all fine."""
        w = self.worst()
        if self.fits:
            return (f"{self.input}: every converter within range (closest {w.line()}, "
                    f"{self.model} model)")
        return (f"{self.input}: an excitation of {self.amplitude_rms_v:.4g} V rms drives "
                f"{w.converter} {w.signal} to {w.peak_v:.3g} V peak, beyond its "
                f"±{w.limit_v:g} V range ({self.model} bench model); at most "
                f"{self.fitting_amplitude_rms_v():.3g} V rms fits")


def _slowest_decay_samples(plant: DiscretePlant) -> float:
    """Time constant of the slowest plant mode [samples]."""
    a = plant.a[:plant.n_plant_states, :plant.n_plant_states]
    rho = float(np.max(np.abs(np.linalg.eigvals(a))))
    if not rho < 1.0:
        raise ValueError(f"the bench model is not stable (spectral radius {rho:.9f})")
    return -1.0 / math.log(rho)


def response_from_rest(samples_v: np.ndarray, *, input: str, plant: DiscretePlant,
                       outputs: tuple[str, ...] = ADC_CHANNELS,
                       periodic: bool = False) -> np.ndarray:
    """Outputs of the sampled plant for one input's samples, shape (n, len(outputs)).

    Parameters
    ----------
    samples_v : ndarray, shape (n,)
        Commands on ``input`` [V], the other inputs zero.
    input : str
        DAC channel.
    plant : DiscretePlant
        Sampled bench (:func:`fsmbench.sim.plant.twin_discrete`).
    outputs : tuple of str
        Output channels to return.
    periodic : bool
        The periodic steady state of ``samples_v`` repeated forever (one
        period returned) instead of the response from rest.
    """
    x = np.asarray(samples_v, dtype=float)
    n = x.size
    size = n if periodic else scipy.fft.next_fast_len(
        n + math.ceil(_slowest_decay_samples(plant) * math.log(1 / _TAIL_DECAY)), real=True)
    spec = scipy.fft.rfft(x, n=size)
    h = input_response(plant, np.fft.rfftfreq(size, d=plant.ts_s), input=input,
                       outputs=outputs)
    return scipy.fft.irfft(h * spec[:, None], n=size, axis=0)[:n]


def input_response(plant: DiscretePlant, f_hz: np.ndarray, *, input: str,
                   outputs: tuple[str, ...] = ADC_CHANNELS) -> np.ndarray:
    """``c (zI - a)^-1 b_j`` at ``z = exp(j 2 pi f T)`` for one input, shape (F, len(outputs)).

    The same as :meth:`DiscretePlant.frequency_response` but through the
    complex Schur form ``a = U T U^H``: one back substitution per state,
    each vectorised over the frequencies (O(n^2 F) instead of one n x n solve
    per frequency), so a response at every FFT bin of a long record is cheap.
    The delay registers make ``a`` defective; the Schur form does not mind.
    """
    j = plant.input_names.index(input)
    rows = [plant.output_names.index(o) for o in outputs]
    t, u = schur(plant.a.astype(complex), output="complex")
    rhs = u.conj().T @ plant.b[:, j]
    z = np.exp(2j * np.pi * np.asarray(f_hz, dtype=float).ravel() * plant.ts_s)
    n = t.shape[0]
    y = np.zeros((z.size, n), dtype=complex)
    for i in range(n - 1, -1, -1):  # (zI - T) y = rhs, T upper triangular
        y[:, i] = (rhs[i] + y[:, i + 1:] @ t[i, i + 1:]) / (z - t[i, i])
    return y @ (plant.c[rows] @ u).T


def converter_peaks(design: ExcitationDesign, *, params: BenchParams,
                    model: str = "nominal") -> LimitReport:
    """Peak of ``design`` at the DAC and at each ADC channel it reaches (see the module notes).

    Parameters
    ----------
    design : ExcitationDesign
    params : BenchParams
        The bench model (``bench.nominal`` for a real bench: its gains are the
        larger ones; ``bench.true`` for the twin).
    model : str
        Name of ``params`` in the report.

    Raises
    ------
    ValueError
        The design's sampling rate is not the bench's.
    """
    fs = params.converter.fs_hz
    if abs(design.fs_hz - fs) > 1e-9 * fs:
        raise ValueError(f"{design.input}: the excitation is sampled at {design.fs_hz:g} Hz, "
                         f"the bench at {fs:g} Hz")
    if design.input not in DAC_CHANNELS:
        raise ValueError(f"unknown input {design.input!r}; DAC channels are "
                         f"{', '.join(DAC_CHANNELS)}")
    limit = params.converter.range_v / 2
    plant = twin_discrete(params)
    y = np.abs(response_from_rest(design.samples_v, input=design.input, plant=plant))
    peak = y.max(axis=0)
    if design.after_end == "repeat":
        steady = response_from_rest(design.one_period(), input=design.input, plant=plant,
                                    periodic=True)
        peak = np.maximum(peak, np.abs(steady).max(axis=0))
    peaks = [ConverterPeak("DAC", design.input, float(np.max(np.abs(design.samples_v))), limit)]
    peaks += [ConverterPeak("ADC", name, float(p), limit)
              for name, p in zip(ADC_CHANNELS, peak, strict=True)
              if p > _REACHED_FRACTION * limit]
    return LimitReport(input=design.input, model=model, amplitude_rms_v=design.amplitude_rms_v,
                       peaks=tuple(peaks),
                       slowest_time_constant_s=_slowest_decay_samples(plant) * plant.ts_s)


def check_limits(design: ExcitationDesign, *, params: BenchParams,
                 model: str = "nominal") -> LimitReport:
    """:func:`converter_peaks`, raising when a converter's range is left.

    Raises
    ------
    ExcitationLimitError
        One line naming the input, the converter, the peak, the limit and the
        rms amplitude that would fit.
    """
    report = converter_peaks(design, params=params, model=model)
    if not report.fits:
        raise ExcitationLimitError(report.verdict())
    return report
