"""Seed 2.4: the Newport FSM-300 identified with its dynamics and its delay.

``data_unh`` (3 s removed) and ``data_unv`` (1.5 s removed) give the 2×2
matrix ``Un → Vp``. The seed's ``Gn = mean(abs(H(10–100 Hz)))`` drops the
sign (errata E19); its value, signed, is kept as a diagnostic.

The seed models the Newport as a constant, ``Gn = mean(|H(10–100 Hz)|)``
(0.166 V/V), while its response falls to half of that by 1 kHz: a closed loop
predicted with a flat Newport misjudges every disturbance it injects above a
few hundred hertz. Here each direct path ``Un → Vp`` is fitted, jointly, with the second
order of the datasheet's Fig. 4 (``docs/model.md`` §4) and a delay,

    G(s) = K · wn² / (s² + 2 ζ wn s + wn²) · e^(−s τ),

as the converter samples it: the command held over each sample and a delay of
any fraction of a sample, in closed form (:func:`sampled_response`; the hold's
amplitude droop alone, left out, lowers the fitted ``wn`` by 5 % at 10 kHz).
``τ`` counts the hold's half sample, the DAC transport and the Newport's
internal lag, as the seed's 0.5 ms does. The poles are read from the
magnitude, the delay from what the poles leave of the phase: estimated
together they do not trade off, unlike a delay taken as the residual phase
slope of a model fitted without it. The Newport's own lag is what remains
after the converter's share: the Sercalo path's identified delay when it is
known (same DAC, hold, 4QD and its amplifier, no internal lag), else the
nominal DAC transport plus half a sample.

Lines are used from 5 Hz up to where the coherence (smoothed over 51 lines)
falls below 0.9, at most ``0.4 fs``.
Each line's residual is weighted by its random error; parameter standard
deviations come from the Jacobian at the optimum, scaled by the residual
variance and by the number of lines one Welch window correlates.

From the fit: the amplitude bandwidth (−3 dB), the phase bandwidth (the
frequency where the lag of the poles and the internal lag reaches the
datasheet's 60°; the converter's own delays are removed first) and the
peaking, against the FSM-300 datasheet (600 Hz, 250 Hz, ≤ 3 dB).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import control as ct
import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import median_filter
from scipy.optimize import brentq

from fsmbench.bench.blocks import newport_beam_matrix
from fsmbench.bench.params import BenchParams
from fsmbench.checks import Check
from fsmbench.forked import start_forked
from fsmbench.ident.delay.bode import DelayEstimate, remove_delay
from fsmbench.ident.delay.joint import SensorEstimate, fit_jointly, line_std
from fsmbench.ident.delay.sampled import SensorLowpass, StateSpace3, second_order
from fsmbench.ident.delay.sampled import sampled_response as sampled_path
from fsmbench.ident.frf.response import FrequencyResponse
from fsmbench.ident.sercalo import combined_delay, path_delays

__all__ = ["NEWPORT_PATHS", "NewportAxisFit", "NewportDynamics", "NewportIdentification",
           "SensorShift",
           "fit_newport_axis", "fit_newport_dynamics", "identify_newport", "newport_checks",
           "nominal_newport_axis", "sampled_response"]

FloatArray = NDArray[np.float64]
NEWPORT_PATHS = {"h": ("Vph", "Unh"), "v": ("Vpv", "Unv")}
_PATHS = NEWPORT_PATHS

#: Lines below this coherence are left out (the seed's own threshold for its fits).
MIN_COHERENCE = 0.9
#: Highest line fitted, as a fraction of the sampling rate (a 4QD amplifier's roll-off beyond).
MAX_FRACTION_OF_FS = 0.4
#: Lowest line fitted [Hz] (the records' drift and the window's leakage below).
MIN_FREQUENCY_HZ = 5.0
#: At most this many lines (every k-th) are fitted: the sensor's profile takes tens of fits.
MAX_LINES = 400


@dataclass(frozen=True)
class NewportAxisFit:
    """One direct path ``Un → Vp`` fitted with a second order, a delay and the hold.

    Attributes
    ----------
    axis : str
        ``h`` (Unh → Vph) or ``v`` (Unv → Vpv).
    gain_v_per_v, gain_std_v_per_v : float
        Signed static gain ``K`` and its standard deviation [V/V].
    natural_freq_hz, natural_freq_std_hz : float
        ``wn / 2π`` and its standard deviation [Hz].
    damping_ratio, damping_std : float
        ``ζ`` (> 1: two real poles, as the FSM-300's fit) and its standard deviation.
    delay_s, delay_std_s : float
        Pure delay ``τ`` and its standard deviation [s].
    band_hz : (float, float)
        Lowest and highest line fitted [Hz].
    n_lines : int
        Lines fitted.
    fit_error : float
        Rms of ``|H_model − H| / |H|`` over the lines fitted.
    sensor : SensorEstimate or None
        The 4QD amplifier in the fit and what the lines say of its bandwidth
        (:mod:`fsmbench.ident.delay.joint`); ``delay_s`` excludes its lag.
    weighted_cost, noise_unit : float
        The fit's weighted squared residual and its noise unit
        (:class:`~fsmbench.ident.delay.joint.JointFit`): fits of the same lines with
        other amplifiers compare by their costs' difference in noise units.
    """

    axis: str
    gain_v_per_v: float
    gain_std_v_per_v: float
    natural_freq_hz: float
    natural_freq_std_hz: float
    damping_ratio: float
    damping_std: float
    delay_s: float
    delay_std_s: float
    band_hz: tuple[float, float]
    n_lines: int
    fit_error: float
    sensor: SensorEstimate | None = None
    weighted_cost: float = math.nan
    noise_unit: float = math.nan

    @property
    def effective_delay_s(self) -> float:
        """``delay_s`` plus the sensor's group delay [s]: the delay of a sensor-free model."""
        return self.delay_s + (0.0 if self.sensor is None else self.sensor.group_delay_s)

    def response(self, f_hz: FloatArray, *, fs_hz: float | None = None,
                 delay: bool = True) -> NDArray[np.complex128]:
        """The model at ``f_hz`` [Hz]: continuous, or as sampled at ``fs_hz`` (with the hold;
        ``delay=False`` then removes ``delay_s`` as the measured FRF's figures do)."""
        if fs_hz is not None:
            h = sampled_response(f_hz, gain=self.gain_v_per_v,
                                 natural_freq_hz=self.natural_freq_hz,
                                 damping_ratio=self.damping_ratio, delay_s=self.delay_s,
                                 fs_hz=fs_hz)
            if not delay:
                h = h * np.exp(2j * np.pi * np.asarray(f_hz, dtype=float) * self.delay_s)
            return h
        s = 2j * np.pi * np.asarray(f_hz, dtype=float)
        wn = 2 * np.pi * self.natural_freq_hz
        h = self.gain_v_per_v * wn**2 / (s**2 + 2 * self.damping_ratio * wn * s + wn**2)
        if delay:
            h = h * np.exp(-s * self.delay_s)
        return np.asarray(h, dtype=np.complex128)

    def amplitude_bandwidth_hz(self) -> float:
        """Where the second order's magnitude is 3 dB below its static gain [Hz] (closed form)."""
        z2 = self.damping_ratio**2
        x = (-(4 * z2 - 2) + math.sqrt((4 * z2 - 2) ** 2 + 4)) / 2  # (w/wn)^2 at |P|^2 = 1/2
        return self.natural_freq_hz * math.sqrt(x)

    def peaking_db(self) -> float:
        """Largest magnitude above the static gain [dB]; 0 for ``ζ ≥ 1/√2``."""
        z = self.damping_ratio
        if z >= 1 / math.sqrt(2):
            return 0.0
        return 20 * math.log10(1 / (2 * z * math.sqrt(1 - z * z)))

    def phase_bandwidth_hz(self, *, lag_deg: float, internal_delay_s: float,
                           f_max_hz: float) -> float:
        """Where the poles' lag plus ``internal_delay_s`` reaches ``lag_deg`` [Hz] (nan: beyond
        ``f_max_hz``)."""
        wn = 2 * np.pi * self.natural_freq_hz

        def lag(f: float) -> float:
            w = 2 * np.pi * f
            poles = math.atan2(2 * self.damping_ratio * wn * w, wn**2 - w**2)
            return math.degrees(poles + w * internal_delay_s) - lag_deg

        if lag(f_max_hz) < 0:
            return math.nan
        return float(brentq(lag, 1e-6, f_max_hz, xtol=1e-9))

    def summary(self) -> dict[str, Any]:
        """JSON-ready values."""
        out = {k: (list(v) if isinstance(v, tuple) else v) for k, v in self.__dict__.items()
               if k != "sensor"}
        out["sensor"] = None if self.sensor is None else self.sensor.summary()
        out["effective_delay_s"] = self.effective_delay_s
        return out


@dataclass(frozen=True)
class NewportDynamics:
    """Both Newport axes with the datasheet comparison.

    Attributes
    ----------
    axes : dict {"h", "v"} of NewportAxisFit
    fs_hz : float
        Sampling rate of the records [Hz].
    converter_delay_s : float
        The converter's own delay (DAC transport, half a sample of hold and the
        sensor's lag) [s], removed from the fitted effective delay to give the
        Newport's internal lag.
    amplitude_bandwidth_hz, phase_bandwidth_hz, peaking_db : dict {"h", "v"}
        From the fits (the phase bandwidth at ``phase_lag_deg`` with the internal lag).
    phase_lag_deg : float
        The datasheet's phase-bandwidth lag [deg] (60°).
    """

    axes: dict[str, NewportAxisFit]
    fs_hz: float
    converter_delay_s: float
    amplitude_bandwidth_hz: dict[str, float]
    phase_bandwidth_hz: dict[str, float]
    peaking_db: dict[str, float]
    phase_lag_deg: float

    def internal_delay_s(self, axis: str) -> float:
        """The Newport's own lag on ``axis`` [s]: the fitted delay less the converter's.

        Both with the sensor's lag in (effective delays): the Sercalo path passes the
        same 4QD amplifier."""
        return self.axes[axis].effective_delay_s - self.converter_delay_s

    def gn(self) -> ct.StateSpace:
        """``Unh, Unv → Vpnh, Vpnv`` [V/V]: each axis's second order (delays kept apart)."""
        blocks = []
        for axis in "hv":
            a = self.axes[axis]
            wn = 2 * math.pi * a.natural_freq_hz
            blocks.append(ct.tf([a.gain_v_per_v * wn**2], [1.0, 2 * a.damping_ratio * wn, wn**2]))
        sys = ct.append(ct.ss(blocks[0]), ct.ss(blocks[1]))
        return ct.ss(sys.A, sys.B, sys.C, sys.D, inputs=["Unh", "Unv"],
                     outputs=["Vpnh", "Vpnv"], name="Gn")

    def summary(self) -> dict[str, Any]:
        """JSON-ready values."""
        return {"axes": {k: a.summary() for k, a in self.axes.items()}, "fs_hz": self.fs_hz,
                "converter_delay_s": self.converter_delay_s,
                "internal_delay_s": {k: self.internal_delay_s(k) for k in self.axes},
                "amplitude_bandwidth_hz": self.amplitude_bandwidth_hz,
                "phase_bandwidth_hz": self.phase_bandwidth_hz, "peaking_db": self.peaking_db,
                "phase_lag_deg": self.phase_lag_deg}


def sampled_response(f_hz: FloatArray, *, gain: float, natural_freq_hz: float,
                     damping_ratio: float, delay_s: float, fs_hz: float,
                     sensor: SensorLowpass | None = None) -> NDArray[np.complex128]:
    """The second order and delay as the converter samples them, at ``f_hz`` [Hz] (V/V).

    Exact for a command held over each sample (zero-order hold) and a delay of
    any fraction of a sample (:func:`fsmbench.ident.delay.sampled.sampled_response`),
    with the sensor's low pass when given. ``delay_s`` follows the seed's
    convention: it includes half a sample for the hold.
    """
    path = second_order(gain=gain, natural_freq_hz=natural_freq_hz, damping_ratio=damping_ratio)
    return sampled_path(path, f_hz=f_hz, fs_hz=fs_hz, delay_s=delay_s, sensor=sensor)


def _fit_axis(frf: FrequencyResponse, axis: str, *, fs: float,
              sensor: SensorLowpass, resolve_sensor: bool = True) -> NewportAxisFit:
    output, input_ = _PATHS[axis]
    f = frf.frequency_hz
    h = frf.frf.sel(output=output, input=input_).values
    coh = frf.coherence.sel(output=output, input=input_).values
    sigma = line_std(frf, output, input_)
    # One contiguous band, up to where the coherence smoothed over ±25 lines falls below the
    # threshold: keeping lines by their own coherence would keep those whose noise happened to
    # raise |H| where the coherence is marginal, and bias the roll-off (+0.7 % on wn).
    smooth = median_filter(np.nan_to_num(coh), size=51, mode="nearest")
    low = (f > 100.0) & (smooth < MIN_COHERENCE)
    f_top = min(MAX_FRACTION_OF_FS * fs, float(f[low][0]) if low.any() else math.inf)
    sel = ((f >= MIN_FREQUENCY_HZ) & (f <= f_top) & np.isfinite(h) & np.isfinite(sigma)
           & (sigma > 0))
    if sel.sum() < 20:
        raise ValueError(f"{input_} → {output}: {int(sel.sum())} lines between "
                         f"{MIN_FREQUENCY_HZ:g} Hz and {f_top:g} Hz, where the coherence stays "
                         f"≥ {MIN_COHERENCE}; the Newport's dynamics need 20")
    fl, hl, sl = f[sel], h[sel], sigma[sel]
    low = fl < 10 * fl[0]
    k0 = float(np.mean(hl[low].real)) if low.any() else float(hl[0].real)
    # The phase slope over the band gives the start of the delay; 1 kHz near the FSM-300's
    # corner, ζ = 1 between its under- and over-damped fits.
    slope = np.polyfit(2 * np.pi * fl, np.unwrap(np.angle(hl * np.sign(k0))), 1)[0]

    def path(p: FloatArray) -> StateSpace3:
        return second_order(gain=float(p[0]), natural_freq_hz=float(p[1]),
                            damping_ratio=float(p[2]))

    # A Welch window of L samples zero-padded to nfft correlates ~1.5 nfft/L adjacent lines
    # (Hann's equivalent noise bandwidth): the fit has that many fewer independent lines.
    correlated = 1.5 * frf.nfft / frf.window_length if frf.estimator == "welch" else 1.0
    joint = fit_jointly(fl, hl, sl, path=path, start=np.array([k0, 1000.0, 1.0]),
                        scale=np.array([abs(k0), 1000.0, 1.0]),
                        lower=np.array([-np.inf, 1.0, 0.01]), upper=np.array([np.inf, fs, 20.0]),
                        delay_start_s=max(0.5 / fs, -float(slope) / 2), fs_hz=fs,
                        sensor=sensor, correlated_lines=correlated,
                        resolve_sensor=resolve_sensor, max_lines=MAX_LINES)
    k, fn, z = (float(v) for v in joint.parameters)
    std = joint.parameter_std
    return NewportAxisFit(axis=axis, gain_v_per_v=k, gain_std_v_per_v=float(std[0]),
                          natural_freq_hz=fn, natural_freq_std_hz=float(std[1]),
                          damping_ratio=z, damping_std=float(std[2]), delay_s=joint.delay_s,
                          delay_std_s=joint.delay_std_s, band_hz=(float(fl[0]), float(fl[-1])),
                          n_lines=int(fl.size), fit_error=joint.fit_error, sensor=joint.sensor,
                          weighted_cost=joint.weighted_cost, noise_unit=joint.noise_unit)


def fit_newport_axis(frf: FrequencyResponse, axis: str, *, sensor: SensorLowpass,
                     resolve_sensor: bool = True) -> NewportAxisFit:
    """One direct path ``Un → Vp`` (``axis``: h or v) fitted with ``sensor`` as the 4QD
    amplifier; ``resolve_sensor``: its bandwidth free when the lines resolve it."""
    return _fit_axis(frf, axis, fs=float(frf.fs_hz), sensor=sensor,
                     resolve_sensor=resolve_sensor)


def nominal_newport_axis(params: BenchParams, axis: str, *, fs_hz: float) -> NewportAxisFit:
    """One axis as the bench file models it (a record that could not give it): the static
    gain ``Gd Mn gn``, the second order and the internal lag, every std NaN."""
    gd = params.quad_diode.gain_v_per_rad[axis]
    i = "hv".index(axis)
    gain = float(gd * newport_beam_matrix(params)[i, i] * params.newport.gain_rad_per_v[axis])
    nan = math.nan
    delay = ((params.converter.dac_delay_samples + 0.5) / fs_hz
             + params.converter.dac_extra_delay_s + params.newport.internal_delay_s)
    return NewportAxisFit(axis=axis, gain_v_per_v=gain, gain_std_v_per_v=nan,
                          natural_freq_hz=params.newport.natural_freq_hz, natural_freq_std_hz=nan,
                          damping_ratio=params.newport.damping_ratio, damping_std=nan,
                          delay_s=delay, delay_std_s=nan, band_hz=(nan, nan), n_lines=0,
                          fit_error=nan)


def fit_newport_dynamics(frf: FrequencyResponse, *, dac_delay_samples: float = 1.0,
                         converter_delay_s: float | None = None,
                         phase_lag_deg: float = 60.0,
                         sensor: SensorLowpass | None = None,
                         resolve_sensor: bool = True,
                         fill: Mapping[str, NewportAxisFit] | None = None,
                         parallel: bool = False) -> NewportDynamics:
    """Fit both Newport paths (see the module) and derive their bandwidths.

    Parameters
    ----------
    frf : FrequencyResponse
        ``Unh, Unv → Vph, Vpv`` (at least the direct paths), with coherence.
    dac_delay_samples : float
        The converter's transport delay [samples]; with half a sample of hold it
        is the converter's share of the delay when ``converter_delay_s`` is None.
    converter_delay_s : float, optional
        The delay of the paths without the Newport [s] (the Sercalo's identified
        delay): removed from the fitted delay to give the Newport's internal lag.
    phase_lag_deg : float
        Lag defining the phase bandwidth [deg] (FSM-300 datasheet: 60°).
    sensor : SensorLowpass, optional
        The bench model's 4QD amplifier (default unlimited); its bandwidth is
        fitted when the lines resolve it (:mod:`fsmbench.ident.delay.joint`).
    resolve_sensor : bool
        False: the amplifier is ``sensor``, not fitted (a decision made from more
        records than these lines, :mod:`fsmbench.ident.evidence.amplifier`).
    fill : mapping of axis to NewportAxisFit, optional
        The axes whose path the matrix lacks (its record missing or unusable), as the
        bench file models them (:func:`nominal_newport_axis`).
    parallel : bool
        Fit the v path in a forked process (:mod:`fsmbench.forked`) while this one fits
        the h path: the same fits.

    Raises
    ------
    ValueError
        A path missing or too few coherent lines, naming the path.
    """
    fill = dict(fill or {})
    for axis, (output, input_) in _PATHS.items():
        if axis not in fill and (output not in frf.output_names
                                 or input_ not in frf.input_names):
            raise ValueError(f"the Newport's dynamics need the {input_} → {output} path; the "
                             f"FRF has {frf.input_names} → {frf.output_names}")
    fs = float(frf.fs_hz)
    sensor = sensor or SensorLowpass()
    fit = functools.partial(_fit_axis, frf, fs=fs, sensor=sensor, resolve_sensor=resolve_sensor)
    # The two joint fits are independent and each most of a second: side by side.
    job = start_forked(lambda _say: fit("v"), progress=lambda _msg: None,
                       parallel=parallel and not fill)
    try:
        axes = {"h": fill["h"] if "h" in fill else fit("h"),
                "v": fill["v"] if "v" in fill else job.result()}
    finally:
        job.cancel()
    converter = ((dac_delay_samples + 0.5) / fs + sensor.group_delay_s
                 if converter_delay_s is None else float(converter_delay_s))
    return NewportDynamics(
        axes=axes, fs_hz=fs, converter_delay_s=converter,
        amplitude_bandwidth_hz={k: a.amplitude_bandwidth_hz() for k, a in axes.items()},
        phase_bandwidth_hz={k: a.phase_bandwidth_hz(lag_deg=phase_lag_deg,
                                                    internal_delay_s=(a.effective_delay_s
                                                                      - converter),
                                                    f_max_hz=fs / 2) for k, a in axes.items()},
        peaking_db={k: a.peaking_db() for k, a in axes.items()}, phase_lag_deg=phase_lag_deg)


#: A unit's bandwidths against the datasheet's typical values: the FSM-300's Fig. 4 is read
#: off a plot and units differ; 25 % is where a unit is no longer "as specified".
DATASHEET_BANDWIDTH_TOLERANCE = 0.25


def newport_checks(dyn: NewportDynamics, *, amplitude_bandwidth_hz: float,
                   phase_bandwidth_hz: float, peaking_max_db: float) -> list[Check]:
    """The identified Newport against its datasheet (one check per axis and quantity)."""
    tol = DATASHEET_BANDWIDTH_TOLERANCE
    checks = []
    for axis in "hv":
        subject = f"Newport {axis} ({_PATHS[axis][1]} → {_PATHS[axis][0]})"
        for name, value, nominal in (
                ("newport_amplitude_bandwidth", dyn.amplitude_bandwidth_hz[axis],
                 amplitude_bandwidth_hz),
                ("newport_phase_bandwidth", dyn.phase_bandwidth_hz[axis], phase_bandwidth_hz)):
            ok = math.isfinite(value) and abs(value / nominal - 1) <= tol
            checks.append(Check(
                name, ok, value, f"within {tol:.0%} of the datasheet's {nominal:g} Hz", subject,
                "" if ok else "the mirror or its controller departs from the FSM-300 "
                              "datasheet: check its tuning before trusting a closed-loop "
                              "prediction", unit="Hz"))
        peak = dyn.peaking_db[axis]
        checks.append(Check("newport_peaking", peak <= peaking_max_db, peak,
                            f"≤ {peaking_max_db:g} dB (datasheet)", subject,
                            "" if peak <= peaking_max_db else
                            "the mirror rings more than its datasheet allows", unit="dB"))
    return checks


@dataclass(frozen=True)
class SensorShift:
    """How much the 4QD amplifier's uncertain shape or lag moves one axis's parameters.

    Attributes
    ----------
    axis : str
    lag_s : float
        The amplifier's group delay assumed [s] (the delays' measured lag, plus
        1.96 of its std when nothing decides the amplifier).
    half_width : dict
        Per parameter (``gain_v_per_v`` [V/V], ``natural_freq_hz`` [Hz],
        ``damping_ratio`` [1], ``effective_delay_s`` [s]): the largest shift over
        the orders tried (a bound), or, when ``measured``, its one-sigma response to
        the measured lag's std.
    by_order : dict int -> dict
        The shifts per amplifier order (1: first order, 2: Butterworth).
    measured : bool
        True when the amplifier is decided (its order by the lines, its lag by the
        delays): ``half_width`` is then a random one-sigma part (the lag is measured,
        with noise, on other records than the Newport's), not a uniform bound.
    """

    axis: str
    lag_s: float
    half_width: dict[str, float]
    by_order: dict[int, dict[str, float]]
    measured: bool = False

    def summary(self) -> dict[str, Any]:
        """JSON-ready values."""
        return {"axis": self.axis, "lag_s": self.lag_s, "half_width": dict(self.half_width),
                "by_order": {str(k): dict(v) for k, v in self.by_order.items()},
                "measured": self.measured}


@dataclass(frozen=True, eq=False)
class NewportIdentification:
    """What 2.4 identifies.

    Attributes
    ----------
    frf : FrequencyResponse
        Measured ``Un → Vp`` matrix (delay included).
    delays : tuple of DelayEstimate
        Each direct path's delay from its phase alone (Bode's gain–phase
        relation), a cross-check of the joint fit's.
    delay_s, delay_std_s : float
        Mean delay of the two axes [s]: the joint fit's when it succeeded, else
        the phase's.
    gain_v_per_v : dict {"h", "v"}
        Signed static gain Unh→Vph and Unv→Vpv [V/V]: the fitted ``K``, else the
        seed's band mean.
    seed_gain_v_per_v : dict {"h", "v"}
        The seed's ``mean(|H|)`` over ``band_hz`` with the sign kept [V/V].
    band_hz : tuple
        The seed's averaging band [Hz] (10–100 Hz).
    gn : control.StateSpace
        ``Unh, Unv → Vpnh, Vpnv``: each axis's second order, or the seed's
        constant diagonal when the dynamics could not be fitted.
    dynamics : NewportDynamics or None
    dynamics_skipped : str
        Why the dynamics were not fitted (empty when they were).
    sensor_shifts : dict axis -> SensorShift
        The axes fitted without a 4QD amplifier while the delays measure one:
        how much its unknown shape could move their parameters
        (:mod:`fsmbench.ident.evidence.sensor_shifts`).
    assumed_axes : tuple of str
        Axes whose record was missing or unusable: the bench file's model stands in
        for them (in ``gn`` and the delays), and nothing is reported of them.
    """

    frf: FrequencyResponse
    delays: tuple[DelayEstimate, ...]
    delay_s: float
    delay_std_s: float
    gain_v_per_v: dict[str, float]
    seed_gain_v_per_v: dict[str, float]
    band_hz: tuple[float, float]
    gn: ct.StateSpace
    dynamics: NewportDynamics | None = None
    dynamics_skipped: str = ""
    sensor_shifts: dict[str, SensorShift] = field(default_factory=dict)
    assumed_axes: tuple[str, ...] = ()

    @property
    def identified_axes(self) -> tuple[str, ...]:
        """The axes the records gave."""
        return tuple(a for a in "hv" if a not in self.assumed_axes)

    def input_delays_s(self) -> dict[str, float]:
        """The delay of each Newport input in a plant model without the sensor's low pass [s]
        (per axis with the dynamics: the effective delay, the sensor's lag in)."""
        if self.dynamics is None:
            return {"Unh": self.delay_s, "Unv": self.delay_s}
        return {"Unh": self.dynamics.axes["h"].effective_delay_s,
                "Unv": self.dynamics.axes["v"].effective_delay_s}

    def summary(self) -> dict[str, Any]:
        """JSON-ready diagnostics."""
        return {"delay_s": self.delay_s, "delay_std_s": self.delay_std_s,
                "delays": [d.summary() for d in self.delays],
                "gain_v_per_v": self.gain_v_per_v, "seed_gain_v_per_v": self.seed_gain_v_per_v,
                "band_hz": list(self.band_hz),
                "dynamics": None if self.dynamics is None else self.dynamics.summary(),
                "dynamics_skipped": self.dynamics_skipped,
                "sensor_shifts": {k: v.summary() for k, v in self.sensor_shifts.items()},
                "assumed_axes": list(self.assumed_axes)}


def identify_newport(frf: FrequencyResponse, *, band_hz: tuple[float, float] = (10.0, 100.0),
                     min_coherence: float = 0.9, dac_delay_samples: float = 1.0,
                     converter_delay_s: float | None = None,
                     sensor: SensorLowpass | None = None,
                     resolve_sensor: bool = True,
                     fill: Mapping[str, NewportAxisFit] | None = None,
                     parallel: bool = False) -> NewportIdentification:
    """The Newport paths (seed 2.4) from the ``Un → Vp`` matrix: dynamics, delays, gains.

    Parameters
    ----------
    frf : FrequencyResponse
        ``Unh, Unv → Vph, Vpv``.
    band_hz : (float, float)
        The seed's averaging band of the constant gain [Hz].
    min_coherence : float
        Lines below it are not used by the phase-only delay estimate.
    dac_delay_samples : float
        The converter's transport delay [samples] (``converter.dac_delay_samples``).
    converter_delay_s : float, optional
        The Sercalo path's identified (effective) delay [s], the converter's share
        of the Newport's (see :func:`fit_newport_dynamics`).
    sensor : SensorLowpass, optional
        The bench model's 4QD amplifier (see :func:`fit_newport_dynamics`).
    resolve_sensor : bool
        See :func:`fit_newport_dynamics`.
    fill : mapping of axis to NewportAxisFit, optional
        The axes whose column the matrix lacks, as the bench file models them: the
        other axis is identified alone (:attr:`NewportIdentification.assumed_axes`).
    parallel : bool
        The two paths' fits side by side (see :func:`fit_newport_dynamics`).
    """
    inputs, outputs = frf.input_names, frf.output_names
    fill = dict(fill or {})
    if len(outputs) != 2 or len(inputs) + len(fill) != 2 or not inputs:
        raise ValueError(f"the Newport identification needs a 2x2 matrix (or one column and "
                         f"the other axis's model), got {outputs} x {inputs}")
    delays = path_delays(frf, min_coherence=min_coherence)
    delay, delay_std = combined_delay(delays)
    clean = remove_delay(frf, delay)
    f = clean.frequency_hz
    sel = (f > band_hz[0]) & (f < band_hz[1])
    seed_gains = {}
    for axis in "hv":
        if axis in fill:
            continue
        h = clean.frf.sel(output=_PATHS[axis][0], input=_PATHS[axis][1]).values[sel]
        seed_gains[axis] = float(np.sign(np.mean(h.real)) * np.mean(np.abs(h)))
    try:
        dyn: NewportDynamics | None = fit_newport_dynamics(
            frf, dac_delay_samples=dac_delay_samples, converter_delay_s=converter_delay_s,
            sensor=sensor, resolve_sensor=resolve_sensor, fill=fill, parallel=parallel)
        why = ""
    except ValueError as exc:
        dyn, why = None, f"the constant gains are used: {exc}"
    fitted = [a for a in "hv" if a not in fill]
    if dyn is not None:
        gains = {a: dyn.axes[a].gain_v_per_v for a in "hv"}
        delay = float(np.mean([dyn.axes[a].delay_s for a in fitted]))
        delay_std = math.hypot(*(dyn.axes[a].delay_std_s for a in fitted)) / len(fitted)
        gn = dyn.gn()
    else:
        gains = {**{a: fit.gain_v_per_v for a, fit in fill.items()}, **seed_gains}
        gn = ct.ss([], [], [], np.diag([gains["h"], gains["v"]]), inputs=["Unh", "Unv"],
                   outputs=["Vpnh", "Vpnv"], name="Gn")
    return NewportIdentification(frf=frf, delays=delays, delay_s=delay, delay_std_s=delay_std,
                                 gain_v_per_v=gains, seed_gain_v_per_v=seed_gains,
                                 band_hz=(float(band_hz[0]), float(band_hz[1])), gn=gn,
                                 dynamics=dyn, dynamics_skipped=why,
                                 assumed_axes=tuple(a for a in "hv" if a in fill))
