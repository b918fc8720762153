"""Static calibrations of the seed's section 2: the 4QD gains (2.1) and the
current-amplifier gains (2.2).

4QD (2.1)
    The Newport moves slowly; its metrology ``Vn`` [V] times its gain
    ``gn0`` [rad/V] is the mirror angle, and the beam turns by twice that
    (one reflection). A straight-line fit ``Vp = a·(2·gn0·Vn) + b`` gives the
    4QD gain ``a`` [V/rad], the seed's ``bh = [1 2*gn0*Vnh] \\ Vph``. The
    seed reads ``a`` as rad/V in its text (errata E6); it is V/rad, and its
    inverse is reported in µrad/mV. R² and residual rms come from the ordinary
    least-squares fit; the standard errors from the residual's spectrum near
    the sweep's frequency (:mod:`fsmbench.ident.fit.regression`: 1/f noise, drift
    and mains are not white). The metrology noise (0.5 µrad) is
    errors-in-variables noise on the regressor, which biases ``a`` towards 0
    by ``var(noise)/var(x) < 1e-7`` here: negligible.

Current amplifier (2.2)
    ``Uc → Vc`` measures ``Ga·Zc·Gi``. The seed takes the voltage amplifier
    ``Ga = 1000/(1 + s/ω_c)`` and the coil ``Zc = Rc + Lc·s`` as known and
    divides them out of ``|tfestimate(Uc, Vc)|``, then averages over
    20–200 Hz, where ``Gi`` is flat. Delays do not enter (magnitudes only).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields
from typing import TYPE_CHECKING, Any

import numpy as np
import xarray as xr

from fsmbench.bench.params import BenchParams
from fsmbench.checks import Check
from fsmbench.ident.fit.regression import spectral_sandwich

if TYPE_CHECKING:
    from fsmbench.ident.frf.response import FrequencyResponse

__all__ = [
    "MAX_CALIBRATION_RESIDUAL",
    "MAX_GAIN_FACTOR",
    "MIN_CALIBRATION_R2",
    "CurrentAmplifierGain",
    "QdCalibration",
    "calibrate_qd",
    "current_amp_checks",
    "known_ga_zc",
    "qd_checks",
    "require_signals",
    "trim_recording",
]

_AXES = {"h": ("Vph", "Vnh"), "v": ("Vpv", "Vnv")}
_CURRENT = {"h": ("Uch", "Vch"), "v": ("Ucv", "Vcv")}


def trim_recording(ds: xr.Dataset, *, t0_s: float) -> xr.Dataset:
    """The record from ``t >= t0_s`` on, as the seed's ``x(t < t0) = []`` (a copy; input untouched).

    Raises ``ValueError`` naming the experiment if nothing is left.
    """
    t = np.asarray(ds["t"].values)
    keep = t >= t0_s
    if keep.sum() < 2:
        raise ValueError(f"{ds.attrs.get('experiment', 'recording')}: nothing left after "
                         f"removing t < {t0_s:g} s (record ends at {t[-1]:g} s)")
    return ds.isel(t=np.flatnonzero(keep))


def require_signals(ds: xr.Dataset, names: tuple[str, ...], *, purpose: str) -> str:
    """The recording's experiment name; ``ValueError`` naming it and the first missing signal."""
    experiment = str(ds.attrs.get("experiment", "recording"))
    for var in names:
        if var not in ds:
            raise ValueError(f"{experiment}: variable '{var}' is needed for {purpose}")
    return experiment


@dataclass(frozen=True)
class QdCalibration:
    """4QD gain of one axis from the Newport metrology (seed 2.1, Fig. 10, Table 2).

    Attributes
    ----------
    axis : {"h", "v"}
    gain_v_per_rad : float
        Small-signal slope ``a`` [V/rad] of 4QD voltage against beam angle at the
        detector's centre (signed): the straight line's (the seed's), or the
        linear term of ``b + a x + c x³`` when the cubic term is significant.
    offset_v : float
        Intercept ``b`` [V].
    gain_std_v_per_rad : float
        Standard deviation of the slope [V/rad]: the spectral sandwich's standard
        error t-scaled to the degrees of freedom of its noise density
        (:meth:`fsmbench.ident.fit.regression.SandwichCovariance.std`).
    linear_slope_v_per_rad : float
        The seed's straight-line slope over the whole swing [V/rad].
    cubic_v_per_rad3 : float
        ``c`` [V/rad³] (0 when the straight line is kept).
    cubic_std_v_per_rad3 : float
        Standard deviation of the cubic term [V/rad³] (when the line is kept: of
        the cubic fit's, a bound on the compression left undetected).
    r_squared : float
        Coefficient of determination of the fit.
    residual_rms_v : float
        Rms of the residuals [V].
    n_samples : int
    beam_angle_range_rad : float
        Peak-to-peak beam angle covered by the record [rad].
    trim_s, metrology_gain_rad_per_v, beam_factor : float
        Options used: first seconds removed, Newport metrology gain ``gn0``,
        beam angle per mirror angle (2).
    experiment : str
    cross_slope_v_per_rad, cross_slope_std_v_per_rad : float
        Slope of the *other* 4QD output against this axis's beam angle and its
        standard deviation [V/rad] (NaN without that output): ``−g_v sin θ``
        (h record, ``Vpv``) or ``g_h sin θ`` (v record, ``Vph``) for a 4QD
        turned by ``θ``.
    """

    axis: str
    gain_v_per_rad: float
    offset_v: float
    gain_std_v_per_rad: float
    linear_slope_v_per_rad: float
    cubic_v_per_rad3: float
    r_squared: float
    residual_rms_v: float
    n_samples: int
    beam_angle_range_rad: float
    trim_s: float
    metrology_gain_rad_per_v: float
    beam_factor: float
    experiment: str
    cubic_std_v_per_rad3: float = 0.0
    cross_slope_v_per_rad: float = math.nan
    cross_slope_std_v_per_rad: float = math.nan

    @property
    def sensitivity_urad_per_mv(self) -> float:
        """Inverse gain in µrad/mV (the seed's 32.3 and 27.6 figures, errata E6/E7)."""
        return 1e3 / self.gain_v_per_rad

    def to_json(self) -> dict[str, Any]:
        """Plain floats; units in the keys."""
        return {**asdict(self), "sensitivity_urad_per_mv": self.sensitivity_urad_per_mv}


def calibrate_qd(ds: xr.Dataset, *, axis: str, metrology_gain_rad_per_v: float,
                 beam_factor: float = 2.0, trim_s: float = 1.0) -> QdCalibration:
    """Fit the 4QD gain of ``axis`` from a calibration record (``data_cal_pd_h``/``_v``).

    Parameters
    ----------
    ds : xarray.Dataset
        Recording with ``t`` [s], ``Vph``/``Vpv`` [V] and ``Vnh``/``Vnv`` [V].
    axis : {"h", "v"}
    metrology_gain_rad_per_v : float
        Newport metrology gain ``gn0`` [rad/V] (seed: 2.62e-3).
    beam_factor : float
        Beam angle per Newport mirror angle (2: one reflection).
    trim_s : float
        Seconds removed at the start (seed: 1 s).

    Raises
    ------
    ValueError
        Unknown axis, a missing signal, or a metrology signal that does not
        move (no regression possible) — the message names the experiment.
    """
    if axis not in _AXES:
        raise ValueError(f"axis must be 'h' or 'v', got {axis!r}")
    vp_name, vn_name = _AXES[axis]
    name = require_signals(ds, (vp_name, vn_name), purpose="the 4QD calibration")
    rec = trim_recording(ds, t0_s=trim_s)
    x = beam_factor * metrology_gain_rad_per_v * np.asarray(rec[vn_name].values, dtype=float)
    y = np.asarray(rec[vp_name].values, dtype=float)
    sxx = float(np.sum((x - x.mean()) ** 2))
    if sxx <= 0.0 or np.ptp(x) < 10 * np.finfo(float).eps * max(1.0, float(np.abs(x).max())):
        raise ValueError(f"{name}: '{vn_name}' does not move; the Newport must be swept to "
                         "calibrate the 4QD")
    # A drifting offset (the 4QD's, thermal) is a ramp over a few seconds, and a ramp is
    # not orthogonal to a sweep that starts at zero phase: it would enter the slope, and
    # coherently — a trend's lines all sit in one quadrature, so a spectral std that
    # splits each line's power evenly under-states it (1.3x on the real-bench twin).
    # The trend is fitted with the line and left out of the slope.
    t_s = np.asarray(rec["t"].values, dtype=float)
    trend = (t_s - t_s.mean()) / max(float(np.ptp(t_s)), 1e-12)
    design = np.column_stack([np.ones_like(x), x, trend])
    (b, a, _drift), *_ = np.linalg.lstsq(design, y, rcond=None)
    resid = y - design @ np.array([b, a, _drift])
    n = x.size
    # Standard errors from the residual's spectrum near the sweep (ident.regression): the
    # ordinary s²(XᵀX)⁻¹ assumes white residuals, 5x optimistic under 1/f noise and drift.
    # Their degrees of freedom are few where the sweep's lowest lines carry 1/f noise and
    # drift: the std is t-scaled to them (SandwichCovariance.std), so ±1.96 std covers 95 %.
    sandwich2 = spectral_sandwich(design, resid, columns=[1])
    # The ESRF study's straight line without the trend, kept to compare with its numbers.
    seed_slope = float(np.linalg.lstsq(design[:, :2], y, rcond=None)[0][1])
    gain, gain_std = float(a), sandwich2.std(1)
    cubic = _cubic_compression(x, y, trend=trend)
    if cubic.significant:
        b, gain, gain_std = cubic.offset_v, cubic.gain_v_per_rad, cubic.gain_std_v_per_rad
        resid = cubic.residual_v
    syy = float(np.sum((y - y.mean()) ** 2))
    cross, cross_std = _cross_slope(rec, design, axis=axis)
    return QdCalibration(
        axis=axis, gain_v_per_rad=gain, offset_v=float(b),
        gain_std_v_per_rad=gain_std, linear_slope_v_per_rad=seed_slope,
        cubic_v_per_rad3=cubic.cubic_v_per_rad3, cubic_std_v_per_rad3=cubic.cubic_std_v_per_rad3,
        r_squared=float(1.0 - float(resid @ resid) / syy) if syy > 0 else float("nan"),
        residual_rms_v=float(np.sqrt(np.mean(resid**2))), n_samples=int(n),
        beam_angle_range_rad=float(np.ptp(x)), trim_s=float(trim_s),
        metrology_gain_rad_per_v=float(metrology_gain_rad_per_v),
        beam_factor=float(beam_factor), experiment=name,
        cross_slope_v_per_rad=float(cross), cross_slope_std_v_per_rad=float(cross_std))


@dataclass(frozen=True)
class _CubicFit:
    """``y = b + a x + c x³ (+ trend)`` of a calibration sweep (see :func:`_cubic_compression`).

    ``significant``: the cubic term is kept, and ``offset_v``, ``gain_v_per_rad``,
    ``gain_std_v_per_rad``, ``residual_v`` replace the straight line's; otherwise
    ``cubic_v_per_rad3`` is 0 and ``cubic_std_v_per_rad3`` the bound on the
    compression the record leaves undetected.
    """

    significant: bool
    offset_v: float
    gain_v_per_rad: float
    gain_std_v_per_rad: float
    cubic_v_per_rad3: float
    cubic_std_v_per_rad3: float
    residual_v: np.ndarray


def _cubic_compression(x: np.ndarray, y: np.ndarray, *, trend: np.ndarray) -> _CubicFit:
    """The cubic fit of a 4QD's compression and whether it replaces the straight line.

    Parameters
    ----------
    x : ndarray, shape (N,)
        Beam angle [rad].
    y : ndarray, shape (N,)
        4QD output [V].
    trend : ndarray, shape (N,)
        The normalised time ramp fitted with the line (the offset's drift).
    """
    # A 4QD compresses towards the edges of its range (the spot leaves the quadrants): the
    # seed's straight line then averages the slope over the swing, ~1.5 % low for 2 %
    # compression. Fit y = b + a x + c x^3 as well, and take its small-signal slope a at the
    # detector's centre when the cubic term is significant (t > 5: a chance of 6e-7).
    scale = float(np.max(np.abs(x)))
    u = x / scale
    cub = np.column_stack([np.ones_like(u), u, u**3, trend])
    coef, *_ = np.linalg.lstsq(cub, y, rcond=None)
    resid3 = y - cub @ coef
    sandwich3 = spectral_sandwich(cub, resid3, columns=[1, 2])
    cov3 = sandwich3.covariance
    # ... and large enough to matter: 1e-4 of the line at full swing (a noise-free line's
    # rounding-level cubic is "significant" against a rounding-level residual).
    if (x.size > 3 and abs(coef[2]) > 5 * math.sqrt(max(cov3[2, 2], 0.0))
            and abs(coef[2]) > 1e-4 * abs(coef[1])):
        return _CubicFit(True, float(coef[0]), float(coef[1]) / scale,
                         sandwich3.std(1) / scale, float(coef[2]) / scale**3,
                         math.sqrt(cov3[2, 2]) / scale**3, resid3)
    # Not significant: the line is kept; the cubic term's bound (its std) says how much
    # compression the record leaves undetected.
    return _CubicFit(False, math.nan, math.nan, math.nan, 0.0,
                     math.sqrt(max(cov3[2, 2], 0.0)) / scale**3, resid3)


def _cross_slope(rec: xr.Dataset, design: np.ndarray, *, axis: str) -> tuple[float, float]:
    """Slope of the other axis's 4QD output on this sweep and its std [V/rad] (NaN without it).

    ``design`` holds the straight line's columns (1, beam angle [rad], trend).
    """
    other = _AXES["v" if axis == "h" else "h"][0]
    if other not in rec:
        return math.nan, math.nan
    yo = np.asarray(rec[other].values, dtype=float)
    coef_o, *_ = np.linalg.lstsq(design, yo, rcond=None)
    return float(coef_o[1]), spectral_sandwich(design, yo - design @ coef_o, columns=[1]).std(1)


@dataclass(frozen=True)
class CurrentAmplifierGain:
    """Current-amplifier gain of one axis (seed 2.2, Figs. 12–14).

    Attributes
    ----------
    axis : {"h", "v"}
    gain_a_per_v : float
        ``g`` of the sampled path fitted over the band [A/V]
        (:mod:`fsmbench.ident.current_amp`).
    gain_std_a_per_v : float
        Its total standard deviation [A/V] (noise and misfit).
    theoretical_a_per_v : float
        ``1/(R + Rc)`` from the nominal components [A/V].
    band_hz : tuple of float
        Band of the lines fitted [Hz] (seed: 20–200 Hz).
    frequency_hz, gi_response_a_per_v : tuple of float
        The per-line estimate ``Re(H/M)`` over the band (the seed's ``Gi_resp``,
        against the sampled model).
    experiment : str
    noise_std_a_per_v, misfit_std_a_per_v : float
        The parts of ``gain_std_a_per_v`` [A/V].
    delay_s, delay_std_s : float
        The path's pure delay (DAC transport, hold, latency) and its std [s].
    reduced_chi2 : float
        Of the fit.
    estimator : str
        FRF estimator of the lines (``welch``, ``lpm``, ``periodic``).
    frf : FrequencyResponse or None
        The ``Uc → Vc`` estimate the gain was fitted on, every line (drawn by
        the report; not in JSON).
    """

    axis: str
    gain_a_per_v: float
    gain_std_a_per_v: float
    theoretical_a_per_v: float
    band_hz: tuple[float, float]
    frequency_hz: tuple[float, ...]
    gi_response_a_per_v: tuple[float, ...]
    experiment: str
    noise_std_a_per_v: float = math.nan
    misfit_std_a_per_v: float = 0.0
    delay_s: float = math.nan
    delay_std_s: float = math.nan
    reduced_chi2: float = math.nan
    estimator: str = "welch"
    frf: FrequencyResponse | None = field(default=None, repr=False, compare=False)

    @property
    def ratio_to_theoretical(self) -> float:
        """Identified over theoretical gain."""
        return self.gain_a_per_v / self.theoretical_a_per_v

    def to_json(self) -> dict[str, Any]:
        """Scalars only (the per-bin curve is left out); units in the keys."""
        out: dict[str, Any] = {
            f.name: getattr(self, f.name) for f in fields(self)
            if f.name not in ("frequency_hz", "gi_response_a_per_v", "frf")}
        out["band_hz"] = list(self.band_hz)
        out["ratio_to_theoretical"] = self.ratio_to_theoretical
        return out


def known_ga_zc(p: BenchParams, *, axis: str, f_hz: np.ndarray) -> np.ndarray:
    """``|Ga(j2πf)·Zc(j2πf)|`` [V/A] with ``Zc = Rc + Lc·s`` (seed 2.2b), shape (F,)."""
    w = 2 * np.pi * np.asarray(f_hz, dtype=float)
    ga = p.voltage_amplifier.gain / (1 + 1j * w / (2 * np.pi * p.voltage_amplifier.cutoff_hz))
    zc = p.sercalo.r_coil_ohm[axis] + 1j * w * p.sercalo.l_coil_h[axis]
    return np.abs(ga * zc)


# A working 4QD channel swept over the Newport's ±10 mrad is linear to well under
# 1 % (twin: r² = 0.99998, seed Fig. 10 a straight line); below 0.9 more than a
# tenth of its variance is not the beam angle: a dead, swapped or saturated channel.
MIN_CALIBRATION_R2 = 0.9
# The residual rms against the fitted swing: the 4QD's noise (~1 mV) against a
# swing of ~0.7 V is 0.1 %; 5 % means a curved response (spot near a quadrant's
# edge) or a channel that does not see the beam.
MAX_CALIBRATION_RESIDUAL = 0.05
# Identified gains against the bench file: the bench file is a prior, and a bench
# that differs from it is a finding (ident.evidence.departures), not a fault: the
# 4QD's gain scales with the spot's power and size (tens of % on realignment, ×5
# between detectors), the seed measured its current amplifier at 0.64 of 1/(R + Rc),
# another amplifier or detector is several times off. Only beyond a factor 10 does
# the value stop being a plausible bench; even then a device that different is not
# excluded, so the check names it beside a gain or unit slip and advises no change.
# The sign is the records' own (ident.evidence.signs), not judged here.
MAX_GAIN_FACTOR = 10.0


def _factor_check(name: str, value: float, nominal: float, subject: str, what: str) -> Check:
    ratio = abs(value / nominal) if nominal else float("nan")
    ok = bool(np.isfinite(ratio) and 1 / MAX_GAIN_FACTOR <= ratio <= MAX_GAIN_FACTOR)
    return Check(name, ok, float(ratio), f"{1 / MAX_GAIN_FACTOR:g} to {MAX_GAIN_FACTOR:g} "
                 f"times the bench file's {abs(nominal):.4g} in magnitude", subject,
                 "" if ok else f"the identified {what} is {value:.4g}, {ratio:.3g}× the bench "
                 f"file's {nominal:.4g}: either a device that far from the bench file's, or a "
                 "gain or unit slip in the records (an amplifier range, mV for V), or a wrong "
                 "channel; the records cannot tell which: check the channel's gain, unit and "
                 "cable, and the device's datasheet", unit="×")


def qd_checks(cal: QdCalibration, *, nominal_v_per_rad: float) -> list[Check]:
    """Plausibility of one 4QD calibration: r², residual and gain against the nominal.

    Parameters
    ----------
    cal : QdCalibration
        The fit of one axis.
    nominal_v_per_rad : float
        The bench's nominal 4QD gain of that axis [V/rad], signed.

    Returns
    -------
    list of Check
        ``calibration_r2`` (≥ 0.9), ``calibration_residual`` (residual rms
        ≤ 5 % of the fitted swing ``|a|·range``) and ``qd_gain_vs_nominal``
        (magnitude 0.1–10 times the bench file's).
    """
    vp = _AXES[cal.axis][0]
    subject = f"{cal.experiment}: {vp}"
    r2_ok = bool(np.isfinite(cal.r_squared) and cal.r_squared >= MIN_CALIBRATION_R2)
    swing = abs(cal.gain_v_per_rad) * cal.beam_angle_range_rad
    rel = cal.residual_rms_v / swing if swing > 0 else float("inf")
    res_ok = bool(rel <= MAX_CALIBRATION_RESIDUAL)
    return [
        Check("calibration_r2", r2_ok, cal.r_squared, f"≥ {MIN_CALIBRATION_R2:g}", subject,
              "" if r2_ok else f"{vp} does not follow the Newport's sweep (r² = "
              f"{cal.r_squared:.2g}): the 4QD channel is dead, swapped or saturated; check "
              "its cable and amplifier and that the Newport swept this axis"),
        Check("calibration_residual", res_ok, float(rel), f"≤ {MAX_CALIBRATION_RESIDUAL:g} of "
              "the fitted swing (residual rms / (|gain| × beam-angle range))", subject,
              "" if res_ok else f"the residual ({1e3 * cal.residual_rms_v:.3g} mV rms) is large "
              f"against the fitted swing ({1e3 * swing:.3g} mV): the response is not a line"),
        _factor_check("qd_gain_vs_nominal", cal.gain_v_per_rad, nominal_v_per_rad, subject,
                      "4QD gain [V/rad]"),
    ]


def current_amp_checks(gain: CurrentAmplifierGain) -> list[Check]:
    """``current_amp_gain_vs_theoretical``: the identified Gi within a factor 10 of
    1/(R + Rc) in magnitude (:data:`MAX_GAIN_FACTOR`)."""
    u_name, v_name = _CURRENT[gain.axis]
    return [_factor_check("current_amp_gain_vs_theoretical", gain.gain_a_per_v,
                          gain.theoretical_a_per_v, f"{gain.experiment}: {u_name} → {v_name}",
                          "current-amplifier gain [A/V]")]
