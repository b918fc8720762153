"""Converter limits of an excitation, checked through the bench model before it is written.

An excitation on one DAC channel must fit the DAC itself and every ADC
channel the bench carries it to. For ``Uch`` the coil-voltage channel
``Vch = Ga Zc Gi Uch`` (about 185 V/V at DC in the nominal model, a 1 kHz
low pass) is the tight one: it is why the ESRF study injects only tens of mV.
The 4QD outputs ``Vph, Vpv`` see the Sercalo's lightly damped modes.

The peak is taken on the samples the ADCs would read: the designed samples
go through the bench's sampled model (:func:`fsmbench.sim.plant.twin_discrete`:
DAC delay, zero-order hold, the circuit and mechanics, the Newport's lag),
from rest, as one linear convolution evaluated with FFTs and enough zeros
behind the record for the slowest mode to die out (no wrap-around). An
excitation a player repeats (``after_end = "repeat"``) is also checked in its
periodic steady state. Noise of the bench is not included: it adds
millivolts to peaks of volts.

The 4QD's linear range is checked from the same peaks (:class:`QuadDiodePeak`):
the bench's 4QD compresses ``Vph, Vpv`` as ``y (1 - k (y / V_fs)**2)``
(``k = nonlinearity_pct / 100`` at ``V_fs = |gain| * nonlinearity_full_swing_rad``,
:meth:`fsmbench.sim.stream.BenchStream._qd_cubic`), so the compression at a
channel's peak is ``k (peak / V_fs)**2``; it scales with the amplitude squared.
The coherent part of the cubic at each excited line lowers the best linear
gain by ``3 k sigma**2 / V_fs**2 = 3 c_peak / CF**2`` (``sigma`` the rms,
``CF`` the crest factor of the 4QD signal; minus ``(3/4) k |Y_l|**2 / V_fs**2``
on line ``l``): ``3/4`` of the peak compression for a sine, less for signals
more peaked than ``sqrt(3)``, more for flatter ones.
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

__all__ = ["DEFAULT_MAX_QD_COMPRESSION", "QD_CHANNELS", "ConverterPeak",
           "ExcitationLimitError", "LimitReport", "QuadDiodePeak", "check_limits",
           "converter_peaks", "input_response", "response_from_rest"]

#: The 4QD's output channels and the mirror axis each reads.
QD_CHANNELS = (("Vph", "h"), ("Vpv", "v"))

#: Default limit of the 4QD's compression at the peak [1]: 1 %, for the
#: identification's 1 % gain target. The cubic lowers each line's best linear gain
#: by at most ``3 / CF**2`` times the peak compression (module notes; a sine's one
#: line exactly 3/4): 0.75 % for a sine, at most 0.39 % for the 1-2000 Hz Uch
#: multisine as the 4QD sees it (CF 2.8), under 1 % for any 4QD signal with
#: CF >= sqrt(3), and under the gains' outer 3 % tolerance for any signal (CF >= 1).
DEFAULT_MAX_QD_COMPRESSION = 0.01

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
        The channel, the ESRF study's name (``Uch``, ``Vch`` ...).
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
class QuadDiodePeak:
    """Beam angle and compression of the 4QD on one of its channels.

    Attributes
    ----------
    signal : str
        ``"Vph"`` or ``"Vpv"``.
    peak_v : float
        Largest absolute value of the linear response [V].
    rms_v : float
        Rms of the linear response over the record (a period when repeated) [V].
    gain_v_per_rad : float
        ``|4QD gain|`` of the channel [V/rad].
    full_swing_v : float
        ``V_fs = |gain| * nonlinearity_full_swing_rad`` [V].
    nonlinearity : float
        ``k``: compression at ``V_fs`` [1] (0: a linear 4QD).
    limit : float
        Largest compression allowed at the peak [1].
    """

    signal: str
    peak_v: float
    rms_v: float
    gain_v_per_rad: float
    full_swing_v: float
    nonlinearity: float
    limit: float = DEFAULT_MAX_QD_COMPRESSION

    @property
    def angle_rad(self) -> float:
        """Beam angle on the 4QD at the peak, ``peak_v / gain`` [rad]."""
        return self.peak_v / self.gain_v_per_rad

    @property
    def compression(self) -> float:
        """``k (peak / V_fs)**2``: how far short of linear the peak reads [1]."""
        if self.nonlinearity == 0.0:
            return 0.0
        return self.nonlinearity * (self.peak_v / self.full_swing_v) ** 2

    @property
    def gain_bias(self) -> float:
        """Bound on the fall of each line's best linear gain, ``3 k (rms / V_fs)**2`` [1].

        The coherent part of the cubic on line ``l`` is ``3 k (rms**2 - |Y_l|**2 / 4) / V_fs**2``:
        this bound for many lines, twice the truth for a single sine.
        """
        if self.nonlinearity == 0.0:
            return 0.0
        return 3.0 * self.nonlinearity * (self.rms_v / self.full_swing_v) ** 2

    @property
    def fits(self) -> bool:
        """The compression at the peak is within :attr:`limit`."""
        return self.compression <= self.limit

    def amplitude_factor(self) -> float:
        """Scale of the excitation that brings the compression to the limit [1] (inf if linear)."""
        c = self.compression
        return math.inf if c == 0.0 else math.sqrt(self.limit / c)

    def line(self) -> str:
        """``4QD Vph: beam 15.1 mrad peak, compressed 4.05 % at the peak (limit 1 %), ...``."""
        return (f"4QD {self.signal}: beam {1e3 * self.angle_rad:.3g} mrad peak, compressed "
                f"{100 * self.compression:.3g} % at the peak (limit {100 * self.limit:.3g} %), "
                f"linear gain at most {100 * self.gain_bias:.2g} % low")


@dataclass(frozen=True)
class LimitReport:
    """Peaks of one excitation at the DAC and every ADC channel it reaches.

    Attributes
    ----------
    input : str
        DAC channel excited.
    model : str
        Which parameters the check used (``"nominal"`` or ``"true"``, or words
        such as ``"nominal bench model, 4QD identified in DIR"``).
    amplitude_rms_v : float
        Rms of the excitation checked [V].
    peaks : tuple of ConverterPeak
        The DAC first, then the ADC channels reached.
    slowest_time_constant_s : float
        Envelope time constant of the model's slowest mode [s] (the Sercalo's
        lightly damped modes, ``1 / (xi w0)``): how long a start-up transient
        lasts, what transient periods should cover.
    quad_diode : tuple of QuadDiodePeak
        Beam angle and compression on each 4QD channel reached (``Vph``, ``Vpv``).
    qd_nonlinearity_pct : float
        The model's 4QD compression at its full swing [%] (0: linear, not limited).
    max_qd_compression : float
        Largest compression allowed at a 4QD peak [1].
    """

    input: str
    model: str
    amplitude_rms_v: float
    peaks: tuple[ConverterPeak, ...]
    slowest_time_constant_s: float = 0.0
    quad_diode: tuple[QuadDiodePeak, ...] = ()
    qd_nonlinearity_pct: float = 0.0
    max_qd_compression: float = DEFAULT_MAX_QD_COMPRESSION

    def worst(self) -> ConverterPeak:
        """The channel nearest (or furthest beyond) its limit."""
        return max(self.peaks, key=lambda c: c.fraction)

    @property
    def converters_fit(self) -> bool:
        """Every converter peak inside its range."""
        return self.worst().fraction <= 1.0

    @property
    def qd_linear(self) -> bool:
        """The model's 4QD is linear: its compression is not limited."""
        return self.qd_nonlinearity_pct == 0.0

    def worst_qd(self) -> QuadDiodePeak | None:
        """The 4QD channel with the largest compression (None if none is reached)."""
        return max(self.quad_diode, key=lambda q: q.compression, default=None)

    @property
    def fits(self) -> bool:
        """Every converter in range and the 4QD's compression within its limit."""
        return self.converters_fit and all(q.fits for q in self.quad_diode)

    def fitting_amplitude_rms_v(self) -> float:
        """Largest rms amplitude that fits converters and 4QD [V], 3 significant digits, down."""
        factor = min([1.0 / self.worst().fraction]
                     + [q.amplitude_factor() for q in self.quad_diode])
        x = self.amplitude_rms_v * factor
        step = 10.0 ** (math.floor(math.log10(x)) - 2)
        # Printed through 3 digits, so that 0.00745 is not 0.007450000000000001.
        return float(f"{math.floor(x / step * (1 + 1e-12)) * step:.3g}")

    def qd_line(self) -> str:
        """What the report says of the 4QD: linear, or the worst channel's compression."""
        q = self.worst_qd()
        if self.qd_linear or q is None:
            angle = "" if q is None else f" (beam {1e3 * q.angle_rad:.3g} mrad peak on {q.signal})"
            return f"4QD linear in this model: compression not limited{angle}"
        return q.line()

    @property
    def model_words(self) -> str:
        """``"nominal bench model"``, or ``model`` itself when it is already words."""
        return f"{self.model} bench model" if self.model in ("nominal", "true") else self.model

    def verdict(self) -> str:
        """One line: the first violation with the amplitude that would fit, or all fine."""
        w = self.worst()
        q = self.worst_qd()
        if self.fits:
            qd = ("" if self.qd_linear or q is None else
                  f"; 4QD {q.signal} compressed {100 * q.compression:.3g} % at its "
                  f"{1e3 * q.angle_rad:.3g} mrad peak, within "
                  f"{100 * self.max_qd_compression:.3g} %")
            return (f"{self.input}: every converter within range (closest {w.line()}, "
                    f"{self.model_words}){qd}")
        if self.converters_fit and q is not None:
            return (f"{self.input}: an excitation of {self.amplitude_rms_v:.4g} V rms turns the "
                    f"beam on the 4QD ({q.signal}) to {1e3 * q.angle_rad:.3g} mrad peak, "
                    f"compressed {100 * q.compression:.3g} %, beyond the "
                    f"{100 * q.limit:.3g} % limit ({self.model_words}, "
                    f"{self.qd_nonlinearity_pct:.3g} % at its full swing); at most "
                    f"{self.fitting_amplitude_rms_v():.3g} V rms keeps it within")
        return (f"{self.input}: an excitation of {self.amplitude_rms_v:.4g} V rms drives "
                f"{w.converter} {w.signal} to {w.peak_v:.3g} V peak, beyond its "
                f"±{w.limit_v:g} V range ({self.model_words}); at most "
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
                    model: str = "nominal",
                    max_qd_compression: float = DEFAULT_MAX_QD_COMPRESSION,
                    plant: DiscretePlant | None = None) -> LimitReport:
    """Peak of ``design`` at the DAC and at each ADC channel it reaches (see the module notes).

    Parameters
    ----------
    design : ExcitationDesign
    params : BenchParams
        The bench model (``bench.nominal`` for a real bench: its gains are the
        larger ones; ``bench.true`` for the twin).
    model : str
        Name of ``params`` in the report.
    max_qd_compression : float
        Largest compression allowed at a 4QD peak [1] (0.01: 1 %).
    plant : DiscretePlant, optional
        The plant the engine runs for an identified bench
        (:func:`fsmbench.sim.plant.bench_discrete`); default the physics of ``params``.

    Raises
    ------
    ValueError
        The design's sampling rate is not the bench's, or the limit is not > 0.
    """
    if not (math.isfinite(max_qd_compression) and max_qd_compression > 0):
        raise ValueError(f"the 4QD compression limit must be > 0, got {max_qd_compression!r}")
    fs = params.converter.fs_hz
    if abs(design.fs_hz - fs) > 1e-9 * fs:
        raise ValueError(f"{design.input}: the excitation is sampled at {design.fs_hz:g} Hz, "
                         f"the bench at {fs:g} Hz")
    if design.input not in DAC_CHANNELS:
        raise ValueError(f"unknown input {design.input!r}; DAC channels are "
                         f"{', '.join(DAC_CHANNELS)}")
    limit = params.converter.range_v / 2
    if plant is None:
        plant = twin_discrete(params)
    y = response_from_rest(design.samples_v, input=design.input, plant=plant)
    peak = np.abs(y).max(axis=0)
    rms = np.sqrt(np.mean(y * y, axis=0))
    if design.after_end == "repeat":
        steady = response_from_rest(design.one_period(), input=design.input, plant=plant,
                                    periodic=True)
        peak = np.maximum(peak, np.abs(steady).max(axis=0))
        rms = np.sqrt(np.mean(steady * steady, axis=0))
    peaks = [ConverterPeak("DAC", design.input, float(np.max(np.abs(design.samples_v))), limit)]
    peaks += [ConverterPeak("ADC", name, float(p), limit)
              for name, p in zip(ADC_CHANNELS, peak, strict=True)
              if p > _REACHED_FRACTION * limit]
    qd = params.quad_diode
    k = qd.nonlinearity_pct / 100.0
    if k != 0.0 and not qd.nonlinearity_full_swing_rad > 0:
        raise ValueError(f"the 4QD's compression of {qd.nonlinearity_pct:g} % needs a full swing "
                         f"> 0 rad, got {qd.nonlinearity_full_swing_rad:g} rad")
    quad = []
    for name, axis in QD_CHANNELS:
        i = ADC_CHANNELS.index(name)
        gain = abs(qd.gain_v_per_rad[axis])
        if peak[i] > _REACHED_FRACTION * limit:
            quad.append(QuadDiodePeak(name, float(peak[i]), float(rms[i]), gain,
                                      gain * qd.nonlinearity_full_swing_rad, k,
                                      max_qd_compression))
    return LimitReport(input=design.input, model=model, amplitude_rms_v=design.amplitude_rms_v,
                       peaks=tuple(peaks),
                       slowest_time_constant_s=_slowest_decay_samples(plant) * plant.ts_s,
                       quad_diode=tuple(quad), qd_nonlinearity_pct=float(qd.nonlinearity_pct),
                       max_qd_compression=max_qd_compression)


def check_limits(design: ExcitationDesign, *, params: BenchParams,
                 model: str = "nominal",
                 max_qd_compression: float = DEFAULT_MAX_QD_COMPRESSION,
                 plant: DiscretePlant | None = None) -> LimitReport:
    """:func:`converter_peaks`, raising when a converter's range or the 4QD's linear range is left.

    Raises
    ------
    ExcitationLimitError
        One line naming the input, the converter (or the 4QD channel, its
        peak angle and compression), the limit and the rms amplitude that
        would fit.
    """
    report = converter_peaks(design, params=params, model=model,
                             max_qd_compression=max_qd_compression, plant=plant)
    if not report.fits:
        raise ExcitationLimitError(report.verdict())
    return report
