"""Seed 2.2 without its bias: the current-amplifier gain from the sampled ``Uc → Vc`` path.

``Uc → Vc`` measures ``Ga·Zc·Gi``. The seed divides the measured magnitude by
the continuous ``|Ga(jω)·Zc(jω)|`` and averages over 20–200 Hz. The
converters do not measure the continuous response: the DAC holds each command
for a sample and the command reaches the plant a delay later (a whole number
of samples plus a latency), and the ADC samples what comes out. The sampled
response's magnitude differs from the continuous one by the hold's droop and
by aliasing, which depends on the delay: +4.2e-4 and −2.5e-4 of bias on an
exact, noise-free FRF of the default and real-bench twins, twenty times the
estimate's noise.

Here the measured FRF (the identification's estimator: Welch, LPM or the
periodic average, each with its per-line variance) is fitted, in the band, by

    H(f) = g · M(f; τ),

``M`` the path ``Uc → Vc`` with ``Gi = 1/(1/g + Lc s)`` — the coil circuit
``Vt = Uc − (R + R_buffer) Ic`` and the voltage amplifier ``Ga`` — as the
converters sample it (:func:`fsmbench.ident.delay.sampled.sampled_response`: hold,
fractional delay, exactly), per unit of ``g``. ``g`` (real) is linear: its
weighted least-squares value for each delay; the delay ``τ`` (the hold's
half sample included) minimises the weighted residual. ``M`` depends on
``g`` only through the coil's pole (125 kHz): two passes. The delay is the
*pure* delay of the converter's path (DAC transport, hold, latency): no
sensor low pass lies on it, and the coil's lag is in ``M``.

Standard deviations: weighted least squares with the lines' own variances,
inflated by the reduced chi-square when above 1 (a misfit) and by the lines
one Welch window correlates (1.5 for a Hann window). ``Ga`` (gain and
cut-off) and ``Zc`` (``Rc``, ``Lc``) are the bench file's, taken as known:
the gain is defined against them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import xarray as xr
from numpy.typing import NDArray
from scipy.optimize import brentq, minimize_scalar

from fsmbench.bench.params import BenchParams
from fsmbench.ident.calibration import CurrentAmplifierGain, require_signals, trim_recording
from fsmbench.ident.delay.joint import bartlett_ratio
from fsmbench.ident.delay.sampled import StateSpace3, sampled_response
from fsmbench.ident.fit.regression import t_scaled_std
from fsmbench.ident.frf.estimate import FrfEstimate
from fsmbench.ident.frf.lpm import LPM_NOISE_SMOOTHING, LpmOptions, local_polynomial_frf
from fsmbench.ident.frf.periodic import PeriodicOptions, periodic_frf
from fsmbench.ident.frf.response import spectral_matrix
from fsmbench.signal.welch import hanning

__all__ = [
    "AmplifierFit",
    "amplifier_path",
    "calibrate_current_amplifier",
    "fit_amplifier",
    "hac_factor",
    "identify_current_amplifier",
    "kink_interval_variance",
]

FloatArray = NDArray[np.float64]
_CURRENT = {"h": ("Uch", "Vch"), "v": ("Ucv", "Vcv")}
#: Lines one Welch estimate correlates with a Hann window (its equivalent noise bandwidth).
WELCH_CORRELATED_LINES = 1.5
#: Delays searched [samples of the rate], hold's half sample included.
_DELAY_RANGE_SAMPLES = (0.5, 8.0)


def amplifier_path(p: BenchParams, *, axis: str, gain_a_per_v: float) -> StateSpace3:
    """``Uc → Vc`` per unit of ``g`` as ``(A, B, C)``: ``Ga · (Rc + Lc s) / (1 + g Lc s)``.

    States: the coil current and ``Vc``. ``Vt = Uc − (1/g − Rc) Ic`` is the coil's
    voltage (``1/g = R + R_buffer + Rc``), ``Vc = Ga Vt``; divided by ``g``.
    """
    lc = p.sercalo.l_coil_h[axis]
    rc = p.sercalo.r_coil_ohm[axis]
    wc = 2 * math.pi * p.voltage_amplifier.cutoff_hz
    # The monitor's sign is the bench's (voltage_amplifier.sign); the amplifier's own sign
    # (an inverting one) is g's, and the coil's pole takes |g|.
    g0 = p.voltage_amplifier.gain * p.voltage_amplifier.sign[axis]
    r_tot = 1.0 / abs(gain_a_per_v)
    a = np.array([[-r_tot / lc, 0.0], [-wc * g0 * (r_tot - rc), -wc]])
    b = np.array([1.0 / lc, wc * g0]) / abs(gain_a_per_v)
    return a, b, np.array([0.0, 1.0])


@dataclass(frozen=True)
class AmplifierFit:
    """``H = g M(τ)`` fitted to one path's lines.

    Attributes
    ----------
    gain_a_per_v, delay_s : float
        ``g`` [A/V] and ``τ`` [s] (hold's half sample included).
    noise_std_a_per_v, misfit_std_a_per_v : float
        The gain's standard deviation from the lines' noise, and what a reduced
        chi-square above 1 adds [A/V].
    delay_std_s : float
        The delay's standard deviation (both parts) [s].
    reduced_chi2 : float
        Weighted squared residual per degree of freedom.
    frequency_hz, gain_per_line_a_per_v : tuple of float
        Each line's ``Re(H / M)`` [Hz], [A/V] (the seed's ``Gi_resp``, sampled).
    """

    gain_a_per_v: float
    delay_s: float
    noise_std_a_per_v: float
    misfit_std_a_per_v: float
    delay_std_s: float
    reduced_chi2: float
    frequency_hz: tuple[float, ...]
    gain_per_line_a_per_v: tuple[float, ...]


def fit_amplifier(f_hz: FloatArray, h: NDArray[np.complex128], var: FloatArray, *,
                  nominal: BenchParams, axis: str, fs_hz: float, start_a_per_v: float,
                  correlated_lines: float = 1.0) -> AmplifierFit:
    """Fit ``g`` and ``τ`` to the lines (see the module).

    Parameters
    ----------
    f_hz : array, shape (F,)
        Lines [Hz] (> 0).
    h : array, complex, shape (F,)
        Measured ``Vc/Uc`` [V/V].
    var : array, shape (F,)
        ``E|H − H_true|²`` of each line [(V/V)²].
    nominal : BenchParams
        ``Ga`` and ``Zc``.
    axis : {"h", "v"}
    fs_hz : float
        Converter rate [Hz].
    start_a_per_v : float
        A first value of ``g`` for the coil's pole [A/V].
    correlated_lines : float
        Adjacent lines one estimate correlates (≥ 1).
    """
    f = np.asarray(f_hz, dtype=float)
    w = 1.0 / np.asarray(var, dtype=float)
    ts = 1.0 / fs_hz
    g = float(start_a_per_v)
    for _ in range(2):
        path = amplifier_path(nominal, axis=axis, gain_a_per_v=g)

        def model(tau: float, path: StateSpace3 = path) -> NDArray[np.complex128]:
            return sampled_response(path, f_hz=f, fs_hz=fs_hz, delay_s=tau)

        def cost(tau: float, model=model) -> float:  # type: ignore[no-untyped-def]
            m = model(tau)
            gain = float(np.sum(w * np.real(h * np.conj(m))) / np.sum(w * np.abs(m) ** 2))
            return float(np.sum(w * np.abs(h - gain * m) ** 2))

        grid = np.arange(*_DELAY_RANGE_SAMPLES, 0.05) * ts
        k = int(np.argmin([cost(t) for t in grid]))
        lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
        tau = float(minimize_scalar(cost, bounds=(lo, hi), method="bounded",
                                    options={"xatol": 1e-6 * ts}).x)
        m = model(tau)
        g = float(np.sum(w * np.real(h * np.conj(m))) / np.sum(w * np.abs(m) ** 2))
    r = h - g * m
    dof = max(2 * f.size - 2, 1)
    # Real and imaginary parts each carry half a line's variance.
    chi2 = float(np.sum(2.0 * w * np.abs(r) ** 2)) / dof
    fisher_g = float(np.sum(2.0 * w * np.abs(m) ** 2))
    # One-sided slopes: at a whole number of samples (the default twin's DAC delay) the
    # sampled response has a kink in the delay (the path's output has a corner at the
    # sampling instant), its phase slope 3-5x steeper on one side than -omega and 0.7x on
    # the other; a central difference read the mean and gave a std 3x optimistic.
    # Each side's information on the delay with the gain profiled out: at a kink a side's
    # slope has a magnitude part the gain can absorb (at a smooth point, -iωm, it has none).
    step = 1e-3 * ts
    fisher_sides = []
    for dm in (g * (model(tau + step) - m) / step, g * (m - model(tau - step)) / step):
        cross = float(np.sum(2.0 * w * np.real(np.conj(m) * dm)))
        fisher_sides.append(float(np.sum(2.0 * w * np.abs(dm) ** 2)) - cross**2 / fisher_g)
    inv_fisher_tau = kink_interval_variance([1.0 / max(f_, 1e-300) for f_ in fisher_sides])
    corr_g = corr_tau = correlated_lines
    if correlated_lines > 1.0:
        # Correlated lines (Welch): the factor each parameter's variance takes from the
        # residual's own correlation (HAC), not a nominal one.
        sw = np.sqrt(2.0 * w)
        res = (sw * r.real, sw * r.imag)
        corr_g = hac_factor(res, (sw * m.real, sw * m.imag), correlated_lines)
        dm = g * (model(tau + step) - m) / step
        corr_tau = hac_factor(res, (sw * dm.real, sw * dm.imag), correlated_lines)
    noise = math.sqrt(corr_g / fisher_g)
    total = noise * math.sqrt(max(chi2, 1.0))
    return AmplifierFit(
        gain_a_per_v=g, delay_s=tau, noise_std_a_per_v=noise,
        misfit_std_a_per_v=math.sqrt(max(total**2 - noise**2, 0.0)),
        delay_std_s=math.sqrt(corr_tau * max(chi2, 1.0) * inv_fisher_tau),
        reduced_chi2=chi2, frequency_hz=tuple(float(x) for x in f),
        gain_per_line_a_per_v=tuple(float(x) for x in np.real(h / m)))


def kink_interval_variance(side_variances: list[float]) -> float:
    """The variance whose ±1.96 std holds 95 % of an estimate at a kink of its model.

    At a kink the estimate lies on either side about half the time, each side a
    half-normal of its own variance (``1/Fisher`` of that side's slope). Their
    mixture is skewed: the mean of the two variances (this function's former
    rule) put ±1.96 std around 92 % of it when one side is 4x steeper, and the
    independent simulator's benches showed 35-37 of 40 seeds within ±1.96 and a
    mean z of +0.6 to +0.8. The half-width ``c`` that holds 95 % solves
    ``½ erf(c/σ₁√2) + ½ erf(c/σ₂√2) = 0.95``; the variance returned is
    ``(c/1.96)²``, so that ``±1.96 std`` is the 95 % interval (it is the spread
    of a normal estimate, ``σ₁ = σ₂``, at a smooth point).

    Parameters
    ----------
    side_variances : list of float
        The two sides' variances [unit²] (> 0).
    """
    lo, hi = sorted(math.sqrt(v) for v in side_variances)
    if hi <= lo * (1.0 + 1e-9):
        return hi * hi

    def held(c: float) -> float:
        return 0.5 * (math.erf(c / (lo * math.sqrt(2.0))) + math.erf(c / (hi * math.sqrt(2.0)))) \
            - 0.95

    c = float(brentq(held, 1.96 * lo, 1.96 * hi, xtol=1e-12 * hi))
    return (c / 1.96) ** 2


#: Bartlett lags per correlated line in :func:`hac_factor`. Measured on the default twin
#: (Welch, 130 seeds in two sets, against the truth): 4 lags per line (10 lags) left the
#: gain's std 1.1-1.2x pessimistic and the delay's 1.2-1.7x (by seed set); 20 (50 lags),
#: floored at 1/nominal and t-scaled, calibrates the gain (std(z) 0.89 and 0.98) and
#: brings the delay to 0.66 and 0.88 (its kink makes its z a mixture of two half-normals:
#: ~0.83 when calibrated).
HAC_LAGS_PER_LINE = 20.0


def hac_factor(residual: tuple[FloatArray, FloatArray], jac: tuple[FloatArray, FloatArray],
                nominal: float) -> float:
    """What a parameter's variance is of the independent-lines one, from the residual.

    The scores ``s_k = J_k r_k`` (real and imaginary parts, lines in frequency
    order) summed with Bartlett weights over ``±HAC_LAGS_PER_LINE·nominal``
    lines (Newey & West), over ``Σ s_k²``. A zero-padded Hann window's scores
    alternate in sign over ~5 bins on the twin (lag 1 +0.34, lags 2-3 −0.3
    and −0.2, lags 8-10 −0.1 to −0.2), so a smooth functional such as a delay
    over 180 lines cancels much of its noise; Bartlett's weights damp the lags
    they keep, so the lags must reach well past that structure. Clipped to
    ``[1/nominal, nominal]``: below, a sum over a few noisy lags claimed too
    much (a floor of 1/nominal² covered 83 % of 70 seeds within ±1.96). Then
    t-scaled: the estimate of a long-run variance over ``L`` lags and ``n``
    scores has a relative variance ``4L/3n`` (Bartlett), i.e.
    ``ν = 3n/(2L)`` degrees of freedom (about 13 here), and the factor is
    multiplied by ``(t₀.₉₇₅(ν)/1.96)²`` so that ±1.96 std is a 95 % interval.
    """
    score = residual[0] * jac[0] + residual[1] * jac[1]
    lags = min(math.ceil(HAC_LAGS_PER_LINE * nominal), score.size - 1)
    ratio = float(bartlett_ratio(score, lags)[0])
    if not math.isfinite(ratio):
        return nominal
    factor = float(np.clip(ratio, 1.0 / nominal, nominal))
    dof = 3.0 * score.size / (2.0 * max(lags, 1))
    return factor * (t_scaled_std(1.0, dof)) ** 2


def _estimate(u: FloatArray, v: FloatArray, *, fs: float, name: str, u_name: str,
              v_name: str, estimator: str, window_s: float,
              periodic: PeriodicOptions | None) -> tuple[FrfEstimate, float]:
    """The path's FRF by the identification's estimator, and the lines it correlates."""
    if estimator == "lpm":
        est = local_polynomial_frf(u, v, fs_hz=fs, input_name=u_name, output_names=[v_name],
                                   options=LpmOptions(stride=2 * LpmOptions().n + 1,
                                                      noise_smoothing=LPM_NOISE_SMOOTHING),
                                   source=f"{name}.mat")
        return est, 1.0
    if estimator == "periodic":
        return periodic_frf(u, v, fs_hz=fs, input_name=u_name, output_names=[v_name],
                            options=periodic or PeriodicOptions(), source=f"{name}.mat"), 1.0
    frf = spectral_matrix(u, v, input_names=[u_name], output_names=[v_name],
                          window=hanning(int(np.ceil(window_s * fs))), fs_hz=fs)
    return FrfEstimate.from_frequency_response(frf), WELCH_CORRELATED_LINES * frf.nfft \
        / frf.window_length


def identify_current_amplifier(ds: xr.Dataset, *, axis: str, nominal: BenchParams,
                               trim_s: float = 1.0,
                               band_hz: tuple[float, float] = (20.0, 200.0),
                               window_s: float = 1.0, estimator: str = "welch",
                               periodic: PeriodicOptions | None = None
                               ) -> CurrentAmplifierGain:
    """``Gi`` of ``axis`` from ``data_uch``/``data_ucv`` (``Uc → Vc``), see the module.

    Parameters
    ----------
    ds : xarray.Dataset
        Recording with ``Uch, Vch`` (h) or ``Ucv, Vcv`` (v) [V].
    axis : {"h", "v"}
    nominal : BenchParams
        Known ``Ga`` and ``Zc``, the resistor ``R`` for the theoretical gain.
    trim_s : float
        Seconds removed at the start [s].
    band_hz : (float, float)
        Lines fitted [Hz], open interval (the seed's 20–200 Hz).
    window_s : float
        Welch's Hann window [s].
    estimator : {"welch", "lpm", "periodic"}
        The FRF estimator (the identification's).
    periodic : PeriodicOptions, optional
        Period and transient of a periodic record.
    """
    if axis not in _CURRENT:
        raise ValueError(f"axis must be 'h' or 'v', got {axis!r}")
    u_name, v_name = _CURRENT[axis]
    name = require_signals(ds, (u_name, v_name), purpose="the current amplifier")
    rec = trim_recording(ds, t0_s=trim_s)
    fs = float(rec.attrs["fs_hz"])
    u, v = (np.asarray(rec[n].values, dtype=float) for n in (u_name, v_name))
    est, correlated = _estimate(u - u.mean(), v - v.mean(), fs=fs, name=name, u_name=u_name,
                                v_name=v_name, estimator=estimator, window_s=window_s,
                                periodic=periodic)
    f = est.frequency_hz
    h = est.frf[:, 0, 0]
    var = est.total_variance[:, 0, 0]
    sel = (f > band_hz[0]) & (f < band_hz[1]) & np.isfinite(h) & np.isfinite(var) & (var > 0)
    if sel.sum() < 3:
        raise ValueError(f"{name}: {int(sel.sum())} lines in {band_hz} Hz with a variance; the "
                         "current amplifier needs 3")
    r_total = nominal.current_amplifier.r_ohm[axis] + nominal.sercalo.r_coil_ohm[axis]
    sign = nominal.current_amplifier.sign[axis]
    fit = fit_amplifier(f[sel], h[sel], var[sel], nominal=nominal, axis=axis, fs_hz=fs,
                        start_a_per_v=sign / r_total, correlated_lines=correlated)
    return CurrentAmplifierGain(
        axis=axis, gain_a_per_v=fit.gain_a_per_v,
        gain_std_a_per_v=math.hypot(fit.noise_std_a_per_v, fit.misfit_std_a_per_v),
        theoretical_a_per_v=float(sign / r_total), band_hz=(float(band_hz[0]),
                                                            float(band_hz[1])),
        frequency_hz=fit.frequency_hz, gi_response_a_per_v=fit.gain_per_line_a_per_v,
        experiment=name, noise_std_a_per_v=fit.noise_std_a_per_v,
        misfit_std_a_per_v=fit.misfit_std_a_per_v, delay_s=fit.delay_s,
        delay_std_s=fit.delay_std_s, reduced_chi2=fit.reduced_chi2, estimator=est.estimator,
        frf=est.to_frequency_response())


def calibrate_current_amplifier(ds: xr.Dataset, *, axis: str, nominal: BenchParams,
                                trim_s: float = 1.0,
                                band_hz: tuple[float, float] = (20.0, 200.0),
                                window_s: float = 1.0,
                                estimator: str = "welch") -> CurrentAmplifierGain:
    """:func:`identify_current_amplifier` with the periodic estimator's default options:
    the name the identification's steps and the public API call it by (ESRF study 2.2)."""
    return identify_current_amplifier(ds, axis=axis, nominal=nominal, trim_s=trim_s,
                                      band_hz=band_hz, window_s=window_s, estimator=estimator)
