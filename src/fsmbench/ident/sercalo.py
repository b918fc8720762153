"""Seed 2.3 and 2.4: the FRF matrices of the Sercalo and the Newport, their
delays, the weighted rational fit of the Sercalo and the Newport gains.

Sercalo (2.3)
    ``data_uch`` and ``data_ucv`` (first second removed, Sercalo off) give the
    2×2 H1 matrix ``Uc → Vp`` with the seed's ``hanning(ceil(fs))`` window.
    The delay of each diagonal path is estimated from its phase
    (:mod:`fsmbench.ident.delay.bode`) instead of the seed's hard-coded ``Ts``;
    their weighted mean is removed from both columns. The weights are the
    seed's (coherence, 10 within ±10 % of each column's resonance, 0 above
    1 kHz; :func:`esrf_weights`), divided by ``|H|`` so that the fit
    minimises *relative* error whatever the element's scale (the cross terms
    are 30× below the diagonal). Vector fitting uses common poles for the
    whole matrix, one pair per resonance (the seed's 410 Hz and 250 Hz
    starting poles), and converges instead of running 5 iterations.
    ``Gc = fit · Gi⁻¹`` with ``Gi`` from 2.2.

Newport (2.4): :mod:`fsmbench.ident.newport`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import control as ct
import numpy as np
import xarray as xr

from fsmbench.ident.delay.bode import DelayEstimate, estimate_delay, remove_delay
from fsmbench.ident.delay.joint import JointFit
from fsmbench.ident.delay.sampled import SensorLowpass
from fsmbench.ident.delay.sercalo import joint_path_delays
from fsmbench.ident.fit.fixed_poles import fit_residues
from fsmbench.ident.fit.parameter_std import ParameterStd, sercalo_parameter_std
from fsmbench.ident.fit.vectfit import VectorFit, VectorFitOptions, vector_fit
from fsmbench.ident.fit.weights import (
    detect_resonances,
    esrf_weights,
    fit_weights,
    variance_weights,
)
from fsmbench.ident.frf.experiment import OUTPUTS
from fsmbench.ident.frf.response import FrequencyResponse

__all__ = [
    "OUTPUTS",
    "SercaloFitOptions",
    "SercaloIdentification",
    "combined_delay",
    "fit_sercalo",
    "path_delays",
    "refit_with_poles",
    "with_frf",
]

# Both mirrors are second-order mechanical systems: above their modes the
# magnitude falls as f^-2. Given to the delay estimator, it removes its most
# fragile automatic choice (the slope it continues the magnitude with).
MIRROR_HIGH_FREQUENCY_SLOPE = -2.0
# Below their modes both are flat (a spring's static deflection; the Newport's position
# loop): given, the low-frequency continuation no longer rounds a closed-loop estimate's
# noisy lowest lines to +1 or +2, which put the Bode delay 0.6 ms off and the fit's start
# with it (a stage-2 closed-loop fit lost a mode, another came out 1.35 samples
# off, when its excitation changed by 4 %).
MIRROR_LOW_FREQUENCY_SLOPE = 0.0


def path_delays(frf: FrequencyResponse, *, min_coherence: float) -> tuple[DelayEstimate, ...]:
    """Delay of each direct path; low coherence becomes advice, not just a failure."""
    out = []
    for j, in_name in enumerate(frf.input_names):
        # The direct output of each input (Uch → Vph, Unv → Vpv), also for one column.
        direct = f"Vp{in_name[-1]}"
        out_name = direct if direct in frf.output_names else frf.output_names[j]
        try:
            out.append(estimate_delay(frf, output_name=out_name, input_name=in_name,
                                      min_coherence=min_coherence,
                                      low_frequency_slope=MIRROR_LOW_FREQUENCY_SLOPE,
                                      high_frequency_slope=MIRROR_HIGH_FREQUENCY_SLOPE))
        except ValueError as exc:
            raise ValueError(f"{exc}. The coherence of {in_name} -> {out_name} is too low to "
                             "identify this path: raise the excitation level, lengthen the "
                             "record, or check that the sensor sees the beam") from exc
    return tuple(out)


def combined_delay(estimates: Sequence[DelayEstimate]) -> tuple[float, float]:
    """Inverse-variance mean of several delay estimates and its standard error [s]."""
    return _inverse_variance_mean([e.delay_s for e in estimates], [e.std_s for e in estimates])


def _inverse_variance_mean(values: Sequence[float], stds: Sequence[float]
                           ) -> tuple[float, float]:
    w = 1.0 / np.maximum(np.asarray(stds, dtype=float), 1e-12) ** 2
    return (float(np.sum(w * np.asarray(values, dtype=float)) / np.sum(w)),
            float(1.0 / np.sqrt(np.sum(w))))


@dataclass(frozen=True)
class SercaloFitOptions:
    """Options of :func:`fit_sercalo`.

    Attributes
    ----------
    alpha, boost, f_max_hz : float
        The seed's weights (:func:`fsmbench.ident.fit.weights.esrf_weights`).
    min_coherence : float
        Coherence threshold of the delay band.
    delay_s : float, optional
        Impose the delay instead of estimating it [s].
    n_poles : int, optional
        Model order; default two per detected resonance (one pair each).
    weights : {"seed", "variance"}
        The seed's coherence recipe over ``|H|``, or the inverse standard
        deviation of each line (:mod:`fsmbench.ident.fit.weights`).
    joint_delay : bool
        Fit each direct path's delay with its poles and the 4QD amplifier
        (:mod:`fsmbench.ident.delay.sercalo`); False keeps the phase-only delay.
    weights_fallback : str
        Set by :func:`fit_sercalo` when the seed's weights did not converge and the
        variance weights were used instead (why, in words); empty otherwise.
    """

    alpha: float = 0.1
    boost: float = 10.0
    f_max_hz: float = 1000.0
    min_coherence: float = 0.9
    delay_s: float | None = None
    n_poles: int | None = None
    weights: Literal["seed", "variance"] = "seed"
    joint_delay: bool = True
    weights_fallback: str = ""

    def __post_init__(self) -> None:
        if self.weights not in ("seed", "variance"):
            raise ValueError(f"weights must be 'seed' (the ESRF study's coherence recipe) or "
                             f"'variance', got {self.weights!r}")


@dataclass(frozen=True, eq=False)
class SercaloIdentification:
    """What 2.3 identifies.

    Attributes
    ----------
    frf : FrequencyResponse
        Measured ``Uc → Vp`` matrix (delay included).
    delays : tuple of DelayEstimate
        Per diagonal path.
    delay_s, delay_std_s : float
        Common delay removed before the fit [s].
    resonances_hz : dict
        Detected peak per input (the starting poles).
    weights : xarray.DataArray
        Seed weights used (before the ``1/|H|`` normalisation), or the
        inverse standard deviations (``options.weights == "variance"``).
    fit : VectorFit
        Rational fit of the delay-free ``Uc → Vp`` matrix.
    gi_a_per_v : dict
        Current-amplifier gains used to form ``Gc``.
    gc : control.StateSpace
        ``Ich, Icv → Vpch, Vpcv`` [V/A].
    fit_error : dict
        Per element ``"Vph/Uch"``: rms relative magnitude error of the fit
        over 10 Hz–1 kHz where coherence > 0.9 (without the share of the
        measurement noise when the FRF has a variance, :func:`relative_fit_error`).
    options : SercaloFitOptions
    parameter_std : ParameterStd or None
        Resonance, damping and static gain per axis with standard deviations
        propagated from the lines' variances (:mod:`fsmbench.ident.fit.parameter_std`;
        with the seed's weights by the weighted fit's sandwich).
    joint_delays : tuple of JointFit
        Each direct path fitted with its poles, delay and the 4QD amplifier;
        ``delay_s`` is their combined effective delay (the sensor's lag in:
        ``Gc`` has no sensor block). Empty when ``joint_delay_skipped`` says why.
    joint_delay_skipped : str
    """

    frf: FrequencyResponse
    delays: tuple[DelayEstimate, ...]
    delay_s: float
    delay_std_s: float
    resonances_hz: dict[str, float]
    weights: xr.DataArray
    fit: VectorFit
    gi_a_per_v: dict[str, float]
    gc: ct.StateSpace
    fit_error: dict[str, float]
    options: SercaloFitOptions = field(default_factory=SercaloFitOptions)
    parameter_std: ParameterStd | None = None
    joint_delays: tuple[JointFit, ...] = ()
    joint_delay_skipped: str = ""

    @property
    def pure_delay_s(self) -> float:
        """The paths' delay without the sensor's lag [s] (``delay_s`` without a joint fit)."""
        if not self.joint_delays:
            return self.delay_s
        return self.delay_s - float(np.mean([j.sensor.group_delay_s for j in self.joint_delays]))

    def dc_gain_v_per_a(self) -> dict[str, float]:
        """``Gc(0)`` diagonal: Ich→Vph (h), Icv→Vpv (v) [V/A]."""
        g = np.real(np.asarray(self.gc.dcgain()))
        return {"h": float(g[0, 0]), "v": float(g[1, 1])}

    def summary(self) -> dict[str, Any]:
        """JSON-ready diagnostics."""
        return {
            "delay_s": self.delay_s, "delay_std_s": self.delay_std_s,
            "delays": [d.summary() for d in self.delays],
            "pure_delay_s": self.pure_delay_s,
            "joint_delays": [{"output": d.output, "input": d.input, **j.summary()}
                             for d, j in zip(self.delays, self.joint_delays, strict=False)],
            "joint_delay_skipped": self.joint_delay_skipped,
            "resonances_detected_hz": self.resonances_hz,
            "fit": {"n_poles": self.fit.n_poles, "iterations": self.fit.iterations,
                    "converged": self.fit.converged,
                    "rms_error_weighted": np.asarray(self.fit.rms_error).tolist(),
                    "modes": [m.__dict__ for m in self.fit.modes()]},
            "fit_error_rms_relative": self.fit_error,
            "dc_gain_v_per_a": self.dc_gain_v_per_a(),
            "frf_estimator": self.frf.estimator,
            "parameter_std": None if self.parameter_std is None else self.parameter_std.to_json(),
            "options": self.options.__dict__,
        }


def relative_fit_error(frf: FrequencyResponse, model: np.ndarray, *,
                       band_hz: tuple[float, float] = (10.0, 1000.0),
                       min_coherence: float = 0.9) -> dict[str, float]:
    """Rms of ``|model|/|H| - 1`` per element over the band where coherence > threshold.

    ``model`` has shape (F, p, m) on ``frf``'s grid. Elements with no such
    bin get NaN. The part the measurement noise explains is removed (each
    line's own variance: periodic, LPM, or Bendat & Piersol's for Welch): a
    circular error of variance ``var`` gives ``|H|`` a relative variance
    ``var / (2 |H|^2)``, so the misfit is
    ``sqrt(max(0, mean(err^2) - mean(var / (2 |H|^2))))``. A Welch average of
    a short record on a weak bench (the corpus's ``weak`` at a fifth of the
    study's lengths: 5.9 % and 6.6 %, its lines' noise alone ~5 %) is no
    misfit of the model.
    """
    f = frf.frequency_hz
    out = {}
    for i, o in enumerate(frf.output_names):
        for j, inp in enumerate(frf.input_names):
            h = frf.frf.sel(output=o, input=inp).values
            c = frf.coherence.sel(output=o, input=inp).values
            sel = (f >= band_hz[0]) & (f <= band_hz[1]) & (c > min_coherence)
            err = np.abs(model[sel, i, j]) / np.abs(h[sel]) - 1
            ms = float(np.mean(err**2)) if sel.any() else float("nan")
            if sel.any():
                noise = frf.variance_parts.get("noise", frf.line_variance())
                var = noise.sel(output=o, input=inp).values[sel]
                ms = max(0.0, ms - float(np.mean(var / (2.0 * np.abs(h[sel]) ** 2))))
            out[f"{o}/{inp}"] = float(np.sqrt(ms))
    return out


def fit_sercalo(frf: FrequencyResponse, *, gi_a_per_v: Mapping[str, float],
                options: SercaloFitOptions | None = None,
                sensor: SensorLowpass | None = None) -> SercaloIdentification:
    """Delay, weights, rational fit and ``Gc`` from the ``Uc → Vp`` matrix (seed 2.3).

    Parameters
    ----------
    frf : FrequencyResponse
        Inputs ``Uch, Ucv``, outputs ``Vph, Vpv``
        (:func:`fsmbench.ident.frf.experiment.experiment_frf`).
    gi_a_per_v : mapping {"h", "v"} -> float
        Current-amplifier gains [A/V] (2.2).
    options : SercaloFitOptions, optional
    sensor : SensorLowpass, optional
        The bench model's 4QD amplifier (default: unlimited), for the joint delay fit.
    """
    opts = options or SercaloFitOptions()
    sensor = sensor or SensorLowpass()
    inputs, outputs = frf.input_names, frf.output_names
    if len(inputs) != 2 or len(outputs) != 2:
        raise ValueError(f"the Sercalo fit needs a 2x2 matrix, got {outputs} x {inputs}")
    delays, opts = _phase_delays(frf, opts)
    removed = _delay_to_remove(frf, delays, opts=opts, sensor=sensor)
    clean = remove_delay(frf, removed.delay_s)
    fit, resonances, opts = _converged_vector_fit(clean, opts)
    weights = _weights(clean, resonances, opts)
    f = clean.frequency_hz
    h = clean.frf.values
    keep = f > 0  # vector fitting works on s = j2πf; the DC bin carries no weight anyway
    w = fit_weights(weights, h, keep, opts.weights)
    gi = np.array([gi_a_per_v["h"], gi_a_per_v["v"]], dtype=float)
    gc = _current_to_sensor(fit, gi)
    model = np.zeros_like(h)
    model[keep] = fit.response(f[keep])
    model[~keep] = np.nan
    err = relative_fit_error(clean, model)
    pstd = _parameter_std(fit, clean, keep, w, resonances=resonances, gi=gi, fixed_poles=False)
    return SercaloIdentification(frf=frf, delays=delays, delay_s=removed.delay_s,
                                 delay_std_s=removed.delay_std_s, resonances_hz=resonances,
                                 weights=weights, fit=fit,
                                 gi_a_per_v={"h": float(gi[0]), "v": float(gi[1])}, gc=gc,
                                 fit_error=err, options=opts, parameter_std=pstd,
                                 joint_delays=removed.joint,
                                 joint_delay_skipped=removed.joint_skipped)


def _phase_delays(frf: FrequencyResponse, opts: SercaloFitOptions
                  ) -> tuple[tuple[DelayEstimate, ...], SercaloFitOptions]:
    """The direct paths' phase-only delays, and ``opts`` (a weak bench's fallback set).

    Where no line reaches ``opts.min_coherence`` the lines down to
    :data:`LOW_COHERENCE` are used, weighted by their own variances.
    """
    try:
        delays = path_delays(frf, min_coherence=opts.min_coherence)
    except ValueError as exc:
        if opts.min_coherence <= LOW_COHERENCE or "coherence" not in str(exc):
            raise
        # A weak bench (an independent simulator's with a fifth of the 4QD gain and of the
        # amplifier's: coherence 0.65 below 200 Hz, 0.98 at the mode) never reaches the
        # seed's 0.9; each line's own variance (coherence and averages) weighs it instead.
        opts = dataclasses.replace(
            _with_variance_weights(opts), min_coherence=LOW_COHERENCE,
            weights_fallback=(f"{exc.args[0].split(';')[0]}: the lines with coherence ≥ "
                              f"{LOW_COHERENCE:g}, weighted by their own variances, are used"))
        delays = path_delays(frf, min_coherence=opts.min_coherence)
    return delays, opts


@dataclass(frozen=True)
class _RemovedDelay:
    """The delay removed before the vector fit and how it was found."""

    delay_s: float  # [s]
    delay_std_s: float  # [s]
    joint: tuple[JointFit, ...]  # the joint fits of the direct paths (empty: not made)
    joint_skipped: str  # why there is no joint fit, in words ("" when there is)


def _delay_to_remove(frf: FrequencyResponse, delays: tuple[DelayEstimate, ...], *,
                     opts: SercaloFitOptions, sensor: SensorLowpass) -> _RemovedDelay:
    """The imposed delay, the phase-only one, or the joint fits' combined effective delay.

    ``delays`` are the direct paths' phase-only estimates; ``sensor`` the 4QD amplifier.
    """
    if opts.delay_s is not None:
        return _RemovedDelay(float(opts.delay_s), 0.0, (), "the delay was imposed")
    delay, delay_std = combined_delay(delays)
    if not opts.joint_delay:
        return _RemovedDelay(delay, delay_std, (), "disabled by option")
    # The phase-only delay starts a first vector fit; each direct path is then fitted
    # with its poles, its delay and the 4QD amplifier, and that delay is removed.
    first = _vector_fit(remove_delay(frf, delay), opts)
    if not first[0].converged and opts.weights == "seed":
        retried = _vector_fit(remove_delay(frf, delay), _with_variance_weights(opts))
        if retried[0].converged:
            first = retried
    joint: tuple[JointFit, ...] = ()
    try:
        joint = joint_path_delays(frf, fit=first[0], starts=delays,
                                  resonances_hz=first[1], sensor=sensor,
                                  min_coherence=opts.min_coherence)
        delay, delay_std = _combined_effective(joint)
    except ValueError as exc:
        return _RemovedDelay(delay, delay_std, joint, f"the phase-only delay is used: {exc}")
    return _RemovedDelay(delay, delay_std, joint, "")


def _converged_vector_fit(clean: FrequencyResponse, opts: SercaloFitOptions
                          ) -> tuple[VectorFit, dict[str, float], SercaloFitOptions]:
    """The vector fit of the delay-free matrix, its resonances and ``opts`` as used.

    With the seed's weights unconverged, the inverse-variance weights' fit when it
    converges (``opts`` then says so in ``weights_fallback``).
    """
    fit, resonances = _vector_fit(clean, opts)
    if fit.converged or opts.weights != "seed":
        return fit, resonances, opts
    # The ESRF study's coherence weights let the poles wander on benches it was not
    # tuned on (an independent simulator's: a second mode at 1850 Hz, a 4QD amplifier
    # at 2 kHz gave a 376 Hz mode at 3.5 % damping for 411 Hz at 0.1 %); the lines'
    # own inverse standard deviations converge there. Used only when they do.
    alternative, alt_resonances = _vector_fit(clean, _with_variance_weights(opts))
    if not alternative.converged:
        return fit, resonances, opts
    opts = dataclasses.replace(
        _with_variance_weights(opts), weights_fallback=(
            f"the ESRF study's coherence weights did not converge in "
            f"{fit.iterations} iterations: inverse-variance weights used"))
    return alternative, alt_resonances, opts


def _current_to_sensor(fit: VectorFit, gi: np.ndarray) -> ct.StateSpace:
    """``Gc``: ``Ich, Icv → Vpch, Vpcv`` [V/A], the fit's inputs divided by the gains ``gi``
    [A/V] (h, v)."""
    fitted = fit.to_statespace()
    return ct.ss(fitted.A, np.asarray(fitted.B) / gi[None, :], fitted.C,
                 np.asarray(fitted.D) / gi[None, :], inputs=["Ich", "Icv"],
                 outputs=["Vpch", "Vpcv"], name="Gc")


#: Adjacent lines one Welch estimate correlates with a Hann window: its equivalent noise
#: bandwidth, 1.5 bins (the Newport's fit and the current amplifier use the same).
WELCH_CORRELATED_LINES = 1.5


def correlated_lines(frf: FrequencyResponse) -> float:
    """Lines one estimate correlates: ``1.5 nfft / L`` for Welch, 1 for LPM (strided) and
    periodic averaging."""
    return (WELCH_CORRELATED_LINES * frf.nfft / frf.window_length if frf.estimator == "welch"
            else 1.0)


def _parameter_std(fit: VectorFit, clean: FrequencyResponse, keep: np.ndarray, w: np.ndarray,
                   *, resonances: Mapping[str, float], gi: np.ndarray,
                   fixed_poles: bool) -> ParameterStd:
    """The fit's parameters with their stds from every part of the lines' variance but the
    4QD compression's (a factor common to all lines of an element: added to the static
    gain directly by the pipeline)."""
    parts = dict(clean.variance_parts) or {"noise": clean.line_variance()}
    arrays = {k: np.asarray(v.values, dtype=float)[keep] for k, v in parts.items()
              if k != "compression"}
    return sercalo_parameter_std(fit, clean.frequency_hz[keep], clean.frf.values[keep], w,
                                 resonances_hz=resonances, gi_a_per_v=gi,
                                 fixed_poles=fixed_poles, variance_parts=arrays,
                                 correlated_lines=correlated_lines(clean))


def _weights(clean: FrequencyResponse, resonances: Mapping[str, float],
             opts: SercaloFitOptions) -> xr.DataArray:
    if opts.weights == "variance":
        return variance_weights(clean, f_max_hz=opts.f_max_hz)
    return esrf_weights(clean, resonances_hz=resonances, alpha=opts.alpha, boost=opts.boost,
                        f_max_hz=opts.f_max_hz)


#: Coherence down to which a weak bench's lines are fitted when none reaches the seed's
#: 0.9: with the Welch estimate's 60 averages, a line at γ² = 0.5 has a random error of
#: √(1 − γ²)/(|γ|√(2n)) ≈ 9 %, and the variance weights give it that much less weight.
LOW_COHERENCE = 0.5


def _with_variance_weights(opts: SercaloFitOptions) -> SercaloFitOptions:
    """``opts`` with the lines' inverse standard deviations as weights."""
    return dataclasses.replace(opts, weights="variance")


def _vector_fit(clean: FrequencyResponse, opts: SercaloFitOptions
                ) -> tuple[VectorFit, dict[str, float]]:
    """The common-pole fit of a delay-free matrix and the resonances that started it."""
    resonances = detect_resonances(clean, f_max_hz=opts.f_max_hz)
    weights = _weights(clean, resonances, opts)
    f = clean.frequency_hz
    h = clean.frf.values
    keep = f > 0
    w = fit_weights(weights, h, keep, opts.weights)
    n_poles = opts.n_poles or 2 * len(set(np.round(list(resonances.values()), 0)))
    fit = vector_fit(f[keep], h[keep], weights=w, input_names=list(clean.input_names),
                     output_names=list(clean.output_names),
                     options=VectorFitOptions(n_poles=n_poles, asymptote="d"))
    return fit, resonances


def _combined_effective(joint: Sequence[JointFit]) -> tuple[float, float]:
    """Inverse-variance mean of the paths' effective delays (the sensor's lag in) [s]."""
    return _inverse_variance_mean([j.effective_delay_s for j in joint],
                                  [j.delay_std_s for j in joint])


def _fit_inputs(sid: SercaloIdentification) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    clean = remove_delay(sid.frf, sid.delay_s)
    f = clean.frequency_hz
    keep = f > 0
    h = clean.frf.values
    return f[keep], h[keep], fit_weights(sid.weights, h, keep, sid.options.weights)


def refit_with_poles(sid: SercaloIdentification, *, poles: Mapping[str, complex]
                     ) -> SercaloIdentification:
    """Replace the fitted modes' poles and re-solve residues and ``D`` by linear least squares.

    Parameters
    ----------
    sid : SercaloIdentification
    poles : mapping input name -> complex pole [rad/s]
        Upper-half-plane pole replacing the fitted pole nearest to it (its
        conjugate follows), e.g. from the leakage-free modal estimates.

    Returns
    -------
    SercaloIdentification
        Same weights and data; ``fit`` with the new poles (their covariance
        entries set to NaN: they come from another estimator), ``gc`` and
        ``fit_error`` recomputed.
    """
    fit = sid.fit
    new_poles, cov = _with_poles(fit, poles)
    f, h, w = _fit_inputs(sid)
    # The Welch estimate is smeared within about the window's main lobe
    # (±2 bins of 1/window_s) of a resonance: the sharper, correct poles
    # cannot and should not match it there, so those bins get no weight.
    lobe_hz = 3.0 * sid.frf.fs_hz / sid.frf.window_length
    w = w.copy()
    for target in poles.values():
        w[np.abs(f - abs(target) / (2 * np.pi)) < lobe_hz] = 0.0
    s = 2j * np.pi * f
    linear = fit_residues(s, h, w=w, poles=new_poles)
    residues, d = linear.residues, linear.d
    model = np.einsum("nf,npm->fpm", 1 / (s[None, :] - new_poles[:, None]), residues) + d
    num = np.sqrt(np.sum(np.abs(w * (model - h)) ** 2, axis=0))
    den = np.sqrt(np.sum(np.abs(w * h) ** 2, axis=0))
    new_fit = dataclasses.replace(fit, poles=new_poles, residues=residues, d=d,
                                  e=np.zeros_like(d), pole_covariance=cov,
                                  rms_error=num / np.where(den > 0, den, 1.0))
    gi = np.array([sid.gi_a_per_v["h"], sid.gi_a_per_v["v"]])
    gc = _current_to_sensor(new_fit, gi)
    full = np.full(sid.frf.frf.shape, np.nan, dtype=complex)
    full[sid.frf.frequency_hz > 0] = model
    clean = remove_delay(sid.frf, sid.delay_s)
    pstd = _parameter_std(new_fit, clean, sid.frf.frequency_hz > 0, w,
                          resonances=sid.resonances_hz, gi=gi, fixed_poles=True)
    return dataclasses.replace(sid, fit=new_fit, gc=gc, parameter_std=pstd,
                               fit_error=relative_fit_error(clean, full))


def _with_poles(fit: VectorFit, poles: Mapping[str, complex]) -> tuple[np.ndarray, np.ndarray]:
    """The fit's poles with each of ``poles`` [rad/s] replacing the nearest upper one (and
    its conjugate), and the pole covariance with their rows and columns NaN."""
    new_poles = np.array(fit.poles, dtype=complex)
    cov = np.array(fit.pole_covariance, dtype=float)
    for target in poles.values():
        upper = [k for k in range(new_poles.size) if new_poles[k].imag > 0]
        k = min(upper, key=lambda i: abs(new_poles[i] - target))
        j = int(np.flatnonzero(np.isclose(new_poles, np.conj(new_poles[k])))[0])
        new_poles[k], new_poles[j] = complex(target), complex(np.conj(target))
        cov[[k, j], :] = np.nan
        cov[:, [k, j]] = np.nan
    return new_poles, cov


def with_frf(sid: SercaloIdentification, frf: FrequencyResponse, *,
             poles: Mapping[str, complex] | None = None) -> SercaloIdentification:
    """The identification on ``frf`` (the same lines with more variance parts): weights,
    residues, ``D`` and standard deviations again, the delay and the poles kept.

    Parameters
    ----------
    sid : SercaloIdentification
    frf : FrequencyResponse
        Same lines as ``sid.frf`` (e.g. with a ``leakage`` part).
    poles : mapping input -> complex, optional
        The modes' poles to keep (the refined ones); None: the fit is made again
        with the delay imposed.
    """
    if poles is None:
        again = fit_sercalo(frf, gi_a_per_v=sid.gi_a_per_v,
                            options=dataclasses.replace(sid.options, delay_s=sid.delay_s))
        return dataclasses.replace(again, delays=sid.delays, delay_std_s=sid.delay_std_s,
                                   joint_delays=sid.joint_delays,
                                   joint_delay_skipped=sid.joint_delay_skipped,
                                   options=sid.options)
    clean = remove_delay(frf, sid.delay_s)
    weights = _weights(clean, sid.resonances_hz, sid.options)
    return refit_with_poles(dataclasses.replace(sid, frf=frf, weights=weights), poles=poles)
