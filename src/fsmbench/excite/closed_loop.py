"""Limits of an excitation played with the loop closed, checked through the closed-loop bench.

With the Sercalo loop running, an excitation is added either to the
controller's output (the DAC command of its input, ``at="output"``) or to the
loop's reference (``at="reference"``: the loop makes the 4QD reading of the
input's axis follow it, in 4QD volts). The loop then shapes what every
converter sees: the commands carry the controller's answer, the 4QD sees the
beam the loop lets through. So the peaks are taken on the closed loop of the
same sampled bench the engine runs (:func:`fsmbench.sim.closed_loop.closed_loop_plant`
of :func:`fsmbench.sim.plant.bench_discrete` or ``twin_discrete``), from rest
and, for a repeated excitation, in its periodic steady state, exactly as
:mod:`fsmbench.excite.limits` does in open loop:

* the DAC: each command the controller drives (its feedback plus the
  excitation on that channel), and the excited channel if the controller does
  not drive it;
* every ADC channel the loop carries the excitation to, and the 4QD's
  compression at the peak of ``Vph``, ``Vpv`` (:class:`~fsmbench.excite.limits.QuadDiodePeak`);
* the **beam-angle error** the excitation adds, ``Rh`` and ``Rv`` (the beam on
  the 4QD, noise-free), against the bound a user tolerates during the
  measurement (``max_error_rad``; ``--max-error-urad``): its rms, the measure of
  a tracking error everywhere in fsmbench (the periodic steady state's for a
  repeated excitation; the peak is reported beside). The loop's own error, there
  with or without the measurement, adds to it in quadrature.

Every quantity is linear in the excitation, so the rms that fits is the
requested one times the smallest ratio of limit to peak (the 4QD's compression,
quadratic, by the square root of its ratio).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from fsmbench.bench.params import Bench, BenchParams
from fsmbench.bench.perturbed import PARAMETERS, perturbed_bench
from fsmbench.excite.design import ExcitationDesign
from fsmbench.excite.limits import (
    DEFAULT_MAX_QD_COMPRESSION,
    QD_CHANNELS,
    ConverterPeak,
    ExcitationLimitError,
    LimitReport,
    QuadDiodePeak,
    response_from_rest,
)
from fsmbench.sim.closed_loop import (
    closed_loop_plant,
    feedback_name,
    reference_feedthrough,
    reference_name,
)
from fsmbench.sim.discretize import DiscretePlant
from fsmbench.sim.engine import DiscreteController
from fsmbench.sim.plant import ADC_CHANNELS, DAC_CHANNELS, bench_discrete

__all__ = ["INJECTION_POINTS", "BeamError", "ClosedLoopLimitReport",
           "check_closed_loop_limits", "closed_loop_peaks", "injection_input", "robust_loops"]

#: Where an excitation enters the running loop.
INJECTION_POINTS = ("output", "reference")

_BEAM = (("Rh", "h"), ("Rv", "v"))
# A channel whose peak stays below this fraction of its range is not reached.
_REACHED_FRACTION = 1e-9


@dataclass(frozen=True)
class BeamError:
    """The beam-angle error an excitation adds on one axis with the loop closed.

    Attributes
    ----------
    signal : str
        ``"Rh"`` or ``"Rv"``.
    rms_rad, peak_rad : float
        Rms and largest absolute value of the excitation's share [rad] (the
        periodic steady state's rms for a repeated excitation).
    limit_rad : float
        The bound on the rms (inf: not bounded).
    """

    signal: str
    rms_rad: float
    peak_rad: float
    limit_rad: float = math.inf

    @property
    def fits(self) -> bool:
        """The rms is within the bound."""
        return self.rms_rad <= self.limit_rad

    @property
    def factor(self) -> float:
        """Scale of the excitation that brings the rms to the bound [1] (inf if unbounded)."""
        return math.inf if not math.isfinite(self.limit_rad) or self.rms_rad == 0 \
            else self.limit_rad / self.rms_rad

    def line(self) -> str:
        """``beam Rh: 4.1 µrad rms added (12.3 µrad peak), bound 20 µrad rms``."""
        bound = "not bounded" if not math.isfinite(self.limit_rad) \
            else f"bound {1e6 * self.limit_rad:.3g} µrad rms"
        return (f"beam {self.signal}: {1e6 * self.rms_rad:.3g} µrad rms added "
                f"({1e6 * self.peak_rad:.3g} µrad peak), {bound}")


@dataclass(frozen=True)
class ClosedLoopLimitReport:
    """Peaks of one excitation with the loop closed (see the module notes).

    Attributes
    ----------
    limits : LimitReport
        The converters (the DAC commands with the controller's part) and the 4QD.
    at : {"output", "reference"}
    controller : str
        The controller closing the loop, in words.
    beam : tuple of BeamError
    """

    limits: LimitReport
    at: str
    controller: str
    beam: tuple[BeamError, ...]

    @property
    def fits(self) -> bool:
        """Converters, 4QD and beam error within their limits."""
        return self.limits.fits and all(b.fits for b in self.beam)

    def fitting_amplitude_rms_v(self) -> float:
        """Largest rms [V] that fits every limit, 3 significant digits, rounded down."""
        lim = self.limits
        factor = min([1.0 / lim.worst().fraction] + [q.amplitude_factor() for q in lim.quad_diode]
                     + [b.factor for b in self.beam])
        x = lim.amplitude_rms_v * factor
        step = 10.0 ** (math.floor(math.log10(x)) - 2)
        return float(f"{math.floor(x / step * (1 + 1e-12)) * step:.3g}")

    def where(self) -> str:
        """``at the controller output (Uch)`` or ``at the reference of Vph``."""
        if self.at == "output":
            return f"at the controller's output ({self.limits.input})"
        return f"at the loop's reference of {_paired_adc_name(self.limits.input)}"

    def verdict(self) -> str:
        """One line: the first violation with the amplitude that fits, or all fine."""
        lim = self.limits
        head = (f"{lim.input} {self.where()}, loop closed by {self.controller}")
        worst_beam = max(self.beam, key=lambda b: b.rms_rad / b.limit_rad
                         if math.isfinite(b.limit_rad) else 0.0, default=None)
        if self.fits:
            extra = "" if worst_beam is None else f"; {worst_beam.line()}"
            return f"{head}: {lim.verdict().split(': ', 1)[1]}{extra}"
        if not lim.fits:
            return f"{head}: {lim.verdict().split(': ', 1)[1]}".replace(
                f"at most {lim.fitting_amplitude_rms_v():.3g} V rms",
                f"at most {self.fitting_amplitude_rms_v():.3g} V rms")
        assert worst_beam is not None
        return (f"{head}: an excitation of {lim.amplitude_rms_v:.4g} V rms adds "
                f"{1e6 * worst_beam.rms_rad:.3g} µrad rms to the beam's error "
                f"({worst_beam.signal}), beyond the {1e6 * worst_beam.limit_rad:.3g} µrad rms "
                "tolerated during the measurement "
                f"({lim.model_words}); at most {self.fitting_amplitude_rms_v():.3g} V rms keeps "
                "it within")

    def lines(self) -> list[str]:
        """What ``fsmbench excite --closed-loop`` prints about the peaks."""
        out = [f"peaks with the loop closed by {self.controller}, excitation {self.where()}, "
               f"through the {self.limits.model_words}:"]
        out += [f"  {c.line()}" for c in self.limits.peaks]
        out += [f"  {self.limits.qd_line()}"] if self.limits.qd_linear \
            else [f"  {q.line()}" for q in self.limits.quad_diode]
        out += [f"  {b.line()}" for b in self.beam]
        return out

    def to_json(self) -> dict[str, Any]:
        """``excitation.json``'s ``closed_loop`` block (SI units)."""
        return {"at": self.at, "controller": self.controller,
                "beam_error": [{"signal": b.signal, "rms_rad": b.rms_rad, "peak_rad": b.peak_rad,
                                "limit_rms_rad": b.limit_rad if math.isfinite(b.limit_rad)
                                else None} for b in self.beam],
                "verdict": self.verdict()}


def _paired_adc_name(dac_channel: str) -> str:
    return {"Uch": "Vph", "Ucv": "Vpv"}.get(dac_channel, dac_channel)


def injection_input(controller: DiscreteController, *, channel: str, at: str) -> str:
    """Input of the closed loop an excitation of ``channel`` enters at ``at``.

    Raises
    ------
    ValueError
        ``at`` unknown, or a reference on a channel the controller does not drive.
    """
    if at not in INJECTION_POINTS:
        raise ValueError(f"an excitation enters at {' or '.join(INJECTION_POINTS)}, not {at!r}")
    if at == "output":
        return channel
    j = DAC_CHANNELS.index(channel)
    if j not in controller.dac_outputs:
        raise ValueError(f"--at reference: the controller {controller.name!r} does not drive "
                         f"{channel}, so it has no reference on that axis")
    return reference_name(ADC_CHANNELS[controller.adc_inputs[list(controller.dac_outputs)
                                                             .index(j)]])


class _LoopResponse(NamedTuple):
    """The closed loop's outputs for an excitation, the DAC commands with the excitation in."""

    #: Largest absolute value of each output over the runs (from rest, periodic).
    peak: np.ndarray
    #: Rms of each output over the last run: the periodic steady state's when repeated.
    rms: np.ndarray


def _check_peak_options(design: ExcitationDesign, *, fs_hz: float, max_qd_compression: float,
                        max_error_rad: float | None) -> None:
    """Raise ValueError on a bound that is not positive or a design sampled at another rate.

    Parameters
    ----------
    design : ExcitationDesign
        The excitation.
    fs_hz : float
        The bench's sampling rate [Hz].
    max_qd_compression : float
        Largest 4QD compression at a peak [1].
    max_error_rad : float or None
        Bound on the rms beam-angle error [rad] (None: not bounded).
    """
    if not (math.isfinite(max_qd_compression) and max_qd_compression > 0):
        raise ValueError(f"the 4QD compression limit must be > 0, got {max_qd_compression!r}")
    if max_error_rad is not None and not (math.isfinite(max_error_rad) and max_error_rad > 0):
        raise ValueError(f"the beam-error bound must be a positive angle, got {max_error_rad!r}")
    if abs(design.fs_hz - fs_hz) > 1e-9 * fs_hz:
        raise ValueError(f"{design.input}: the excitation is sampled at {design.fs_hz:g} Hz, "
                         f"the bench at {fs_hz:g} Hz")


def _stable_loop(plant: DiscretePlant, controller: DiscreteController, *,
                 model: str) -> tuple[DiscretePlant, float]:
    """The loop closed around ``plant`` and its spectral radius [1].

    Raises
    ------
    ValueError
        The controller does not stabilise the plant (``model`` names it).
    """
    loop = closed_loop_plant(plant, controller)
    rho = float(np.max(np.abs(np.linalg.eigvals(loop.a))))
    if rho >= 1.0:
        raise ValueError(f"the controller {controller.name!r} does not stabilise the "
                         f"{model} bench model (closed-loop spectral radius {rho:.6f})")
    return loop, rho


def _loop_response(design: ExcitationDesign, *, loop: DiscretePlant,
                   controller: DiscreteController, inp: str, at: str,
                   outputs: tuple[str, ...]) -> _LoopResponse:
    """Peaks and rms of the closed loop's ``outputs`` for ``design`` entering at ``inp``.

    From rest and, for a repeated excitation, in its periodic steady state.
    The feedback outputs are the controller's part of each DAC command; the
    excitation on that command (at the output) or the reference's direct
    path through the controller (at the reference) is added to it.
    """
    x = np.asarray(design.samples_v, dtype=float)
    runs = [(x, response_from_rest(x, input=inp, plant=loop, outputs=outputs))]
    if design.after_end == "repeat":
        one = np.asarray(design.one_period(), dtype=float)
        runs.append((one, response_from_rest(one, input=inp, plant=loop, outputs=outputs,
                                             periodic=True)))
    n_adc = len(ADC_CHANNELS)
    direct = reference_feedthrough(controller)
    col = None if at == "output" else list(loop.input_names).index(inp) - len(DAC_CHANNELS)
    peak = np.zeros(len(outputs))
    for samples, y in runs:
        y = y.copy()
        for i, j in enumerate(controller.dac_outputs):
            out = n_adc + 2 + i
            if at == "output" and DAC_CHANNELS[j] == design.input:
                y[:, out] += samples
            elif col is not None:
                y[:, out] += direct[i, col] * samples
        peak = np.maximum(peak, np.abs(y).max(axis=0))
        last = y
    rms = np.sqrt(np.mean(last * last, axis=0))  # the steady state's when repeated
    return _LoopResponse(peak=peak, rms=rms)


def _converter_peaks(design: ExcitationDesign, *, peak: np.ndarray,
                     controller: DiscreteController, at: str,
                     limit_v: float) -> list[ConverterPeak]:
    """The DAC commands' peaks (the controller's and the excitation's), then every ADC
    channel the loop carries the excitation to.

    Parameters
    ----------
    peak : ndarray
        Largest absolute value of each closed-loop output (ADC channels, beam, feedback).
    limit_v : float
        Half the converters' range [V].
    """
    n_adc = len(ADC_CHANNELS)
    dac_peak: dict[str, float] = {}
    for i, j in enumerate(controller.dac_outputs):
        dac_peak[DAC_CHANNELS[j]] = float(peak[n_adc + 2 + i])
    if at == "output" and design.input not in dac_peak:
        # A channel the controller does not drive carries the excitation alone.
        x = np.asarray(design.samples_v, dtype=float)
        dac_peak[design.input] = float(np.max(np.abs(x)))
    peaks = [ConverterPeak("DAC", ch, p, limit_v) for ch, p in dac_peak.items()]
    peaks += [ConverterPeak("ADC", name, float(peak[i]), limit_v)
              for i, name in enumerate(ADC_CHANNELS) if peak[i] > _REACHED_FRACTION * limit_v]
    return peaks


def _quad_diode_peaks(params: BenchParams, *, response: _LoopResponse, limit_v: float,
                      max_qd_compression: float) -> list[QuadDiodePeak]:
    """The 4QD's compression at the peak of each 4QD output the excitation reaches.

    Parameters
    ----------
    limit_v : float
        Half the converters' range [V].
    max_qd_compression : float
        Largest 4QD compression at a peak [1].
    """
    qd = params.quad_diode
    k = qd.nonlinearity_pct / 100.0
    quad = []
    for name, axis in QD_CHANNELS:
        i = ADC_CHANNELS.index(name)
        gain = abs(qd.gain_v_per_rad[axis])
        if response.peak[i] > _REACHED_FRACTION * limit_v:
            quad.append(QuadDiodePeak(name, float(response.peak[i]), float(response.rms[i]), gain,
                                      gain * qd.nonlinearity_full_swing_rad, k,
                                      max_qd_compression))
    return quad


def closed_loop_peaks(design: ExcitationDesign, *, params: BenchParams, plant: DiscretePlant,
                      controller: DiscreteController, controller_name: str = "",
                      at: str = "output", model: str = "nominal",
                      max_qd_compression: float = DEFAULT_MAX_QD_COMPRESSION,
                      max_error_rad: float | None = None) -> ClosedLoopLimitReport:
    """Peaks of ``design`` with the loop closed (see the module notes).

    Parameters
    ----------
    design : ExcitationDesign
        Its samples [V]: a command added at the controller's output, or a reference
        in 4QD volts on the axis of its input.
    params : BenchParams
        Converters and 4QD of the bench model.
    plant : DiscretePlant
        The engine's plant of that model (:func:`fsmbench.sim.plant.bench_discrete`).
    controller : DiscreteController
        The loop's controller as the engine runs it.
    controller_name : str
        In words, for the report.
    at : {"output", "reference"}
    model : str
        Name of the model in the report.
    max_qd_compression : float
        Largest 4QD compression at a peak [1].
    max_error_rad : float, optional
        Bound on the rms beam-angle error the excitation adds [rad] (None: reported only).

    Raises
    ------
    ValueError
        Rates differ, the loop is unstable, a bound is not positive, ``at`` unknown.
    """
    _check_peak_options(design, fs_hz=params.converter.fs_hz,
                        max_qd_compression=max_qd_compression, max_error_rad=max_error_rad)
    inp = injection_input(controller, channel=design.input, at=at)
    loop, rho = _stable_loop(plant, controller, model=model)
    fb = tuple(feedback_name(DAC_CHANNELS[j]) for j in controller.dac_outputs)
    outputs = (*ADC_CHANNELS, "Rh", "Rv", *fb)
    response = _loop_response(design, loop=loop, controller=controller, inp=inp, at=at,
                              outputs=outputs)
    limit = params.converter.range_v / 2
    peaks = _converter_peaks(design, peak=response.peak, controller=controller, at=at,
                             limit_v=limit)
    quad = _quad_diode_peaks(params, response=response, limit_v=limit,
                             max_qd_compression=max_qd_compression)
    bound = math.inf if max_error_rad is None else float(max_error_rad)
    n_adc = len(ADC_CHANNELS)
    beam = tuple(BeamError(sig, float(response.rms[n_adc + i]), float(response.peak[n_adc + i]),
                           bound)
                 for i, (sig, _axis) in enumerate(_BEAM))
    tau = 1.0 / max(1e-300, -math.log(rho)) * plant.ts_s
    report = LimitReport(input=design.input, model=model, amplitude_rms_v=design.amplitude_rms_v,
                         peaks=tuple(peaks), slowest_time_constant_s=tau, quad_diode=tuple(quad),
                         qd_nonlinearity_pct=float(params.quad_diode.nonlinearity_pct),
                         max_qd_compression=max_qd_compression)
    return ClosedLoopLimitReport(limits=report, at=at,
                                 controller=controller_name or controller.name, beam=beam)


def check_closed_loop_limits(design: ExcitationDesign, **kwargs: Any) -> ClosedLoopLimitReport:
    """:func:`closed_loop_peaks`, raising when a converter, the 4QD or the beam bound is exceeded.

    Raises
    ------
    ExcitationLimitError
        One line: what is exceeded, by how much, and the rms amplitude that fits.
    """
    report = closed_loop_peaks(design, **kwargs)
    if not report.fits:
        raise ExcitationLimitError(report.verdict())
    return report


def robust_loops(bench: Bench, controller: DiscreteController, *,
                 frequency_scales: Sequence[float] = (0.95, 1.0, 1.05),
                 damping_scales: Sequence[float] = (0.5, 1.0, 2.0)) -> list[DiscretePlant]:
    """The loop closed around ``bench`` with its Sercalo modes moved, every combination.

    The design's robust set by default (:class:`fsmbench.control.design.DesignOptions`);
    the unmoved bench first. Each is the engine's plant of the moved bench
    (:func:`fsmbench.bench.perturbed.perturbed_bench`), closed as the engine closes it.
    """

    loops = [closed_loop_plant(bench_discrete(bench), controller)]
    for fs in frequency_scales:
        for ds in damping_scales:
            if fs == 1.0 and ds == 1.0:
                continue
            factors = {k: (0.0 if k.endswith("_s") else 1.0) for k in PARAMETERS}
            factors.update({f"resonance_scale.{a}": fs for a in "hv"})
            factors.update({f"damping_scale.{a}": ds for a in "hv"})
            loops.append(closed_loop_plant(bench_discrete(perturbed_bench(bench, factors)),
                                           controller))
    return loops
