"""Every identified value with its total uncertainty: what ``identification.json``'s
``uncertainty`` holds.

Keys are those of ``twin_truth.json`` (dotted), so a value and its truth
compare key by key. Where the seed or the twin define a quantity otherwise
than the data determine it, both are given:

``qd_gain_v_per_rad.{h,v}``
    The slope a single-axis calibration measures: ``g cos θ`` for a 4QD turned
    by ``θ`` against the Newport's axes (what the plant model's ``Gd`` is).
``qd_diode_gain_v_per_rad.{h,v}``
    Derived: the gain along the diode's own axes, ``g = hypot(g cos θ, g sin θ)``
    with ``g sin θ`` the other calibration's cross slope (the rotation
    measured, assuming the cross-axis response is the diode's rotation, not
    a Newport axis misalignment).
``delay_s.sercalo``
    The pure delay of the converter's path (DAC transport, the hold's half
    sample, latency), measured on ``Uc → Vc`` where no sensor lies and the
    coil's lag is in the model (:mod:`fsmbench.ident.current_amp`).
``effective_delay_s.sercalo``
    The delay a model of ``Uc → Vp`` without the coil's lag and the 4QD
    amplifier needs: the pure one plus their group delays (the mean of the two
    axes' joint fits, :mod:`fsmbench.ident.delay.sercalo`). A delay fit over
    the band sees a lag by its band-averaged group delay, lower than the
    low-frequency one by ``τ (2π f τ)²/3`` at the band's top: that is the
    ``unresolved_lags`` part (a bound).
``effective_delay_s.newport``, ``delay_s.newport``
    The Newport paths' delay with the 4QD amplifier's lag (measured), and
    without it (derived: less the lag the Sercalo's effective and pure delays
    show, ``τ_4QD = effective − pure − τ_coil``).
``newport.{h,v}.internal_delay_s``
    The Newport's own lag: its effective delay less the Sercalo's, plus the
    coil's lag (on the Sercalo's path only; ``Lc g_i``, the nominal inductance).
``newport.{h,v}.natural_freq_hz``, ``damping_ratio``, ``newport_gain_v_per_v.{h,v}``
    The Newport's second order with the 4QD amplifier as the fit had it (the
    bench model's, or resolved by the lines). An amplifier the model lacks and
    the lines do not resolve is a lag the delays measure (``τ_4QD``) but whose
    shape they do not: the ``unresolved_sensor`` part bounds what a first- or
    second-order amplifier of that lag would change
    (:func:`fsmbench.ident.evidence.sensor_shifts.unresolved_sensor_shifts`); an
    amplifier the records decide carries its measured lag's std as the random
    ``qd_amplifier_lag`` part (:func:`fsmbench.ident.evidence.amplifier.decide_amplifier`).
``sercalo.{h,v}.dc_gain_v_per_a``
    ``Gc(0)``: the fit's static gain over the current-amplifier gain, the
    4QD's compression corrected (:mod:`fsmbench.ident.frf.compression`); parts
    from the fit (noise, distortion, leakage, misfit), the current
    amplifier's and the compression correction's.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np

from fsmbench.bench.params import BenchParams
from fsmbench.ident.calibration import CurrentAmplifierGain, QdCalibration
from fsmbench.ident.fit.truncation import TruncationCheck
from fsmbench.ident.frf.compression import CompressionFactors
from fsmbench.ident.uncertainty import Uncertain, bounded

if TYPE_CHECKING:
    from fsmbench.ident.fit.modes import ModeRefinement
    from fsmbench.ident.newport import NewportIdentification, SensorShift
    from fsmbench.ident.sercalo import SercaloIdentification

__all__ = ["coil_lag_s", "qd_amplifier_lag_s", "qd_amplifier_lags_by_axis", "uncertainty_tree"]

_DIRECT = {"h": ("Vph", "Uch"), "v": ("Vpv", "Ucv")}
_NEWPORT = {"h": ("Vph", "Unh"), "v": ("Vpv", "Unv")}


def coil_lag_s(nominal: BenchParams, axis: str, gain_a_per_v: float) -> float:
    """The coil's lag on ``Uc → Ic`` [s]: ``Lc / (R + R_buffer + Rc) = Lc g_i``."""
    return float(nominal.sercalo.l_coil_h[axis]) * float(gain_a_per_v)


def _pure_delay(gi: Mapping[str, CurrentAmplifierGain]) -> tuple[float, float]:
    """The converter path's pure delay [s] and its std: the axes' inverse-variance mean."""
    pure = [(g.delay_s, g.delay_std_s) for g in gi.values()
            if math.isfinite(g.delay_s) and math.isfinite(g.delay_std_s) and g.delay_std_s > 0]
    if not pure:
        return math.nan, math.nan
    w = np.array([1.0 / s**2 for _, s in pure])
    return (float(np.sum(w * np.array([d for d, _ in pure])) / np.sum(w)),
            float(1.0 / math.sqrt(np.sum(w))))


def _effective_delay(sid: SercaloIdentification | None) -> tuple[float, float]:
    """The Sercalo paths' effective delay [s] and its std: the mean of the joint fits."""
    if sid is None or not sid.joint_delays:
        return math.nan, math.nan
    eff = [j.effective_delay_s for j in sid.joint_delays]
    std = (0.5 * math.hypot(*[j.delay_std_s for j in sid.joint_delays]) if len(eff) == 2
           else float(sid.joint_delays[0].delay_std_s))
    return float(np.mean(eff)), std


def qd_amplifier_lags_by_axis(*, sid: SercaloIdentification | None,
                              gi: Mapping[str, CurrentAmplifierGain],
                              nominal: BenchParams) -> dict[str, tuple[float, float]]:
    """Each axis's 4QD lag [s] and std [s]: its direct path's effective delay less its own
    ``Uc → Vc`` pure delay and its coil's lag (empty without the joint fits)."""
    if sid is None or len(sid.joint_delays) != 2 or set(gi) != {"h", "v"}:
        return {}
    out = {}
    for axis, joint in zip("hv", sid.joint_delays, strict=True):
        g = gi[axis]
        out[axis] = (joint.effective_delay_s - g.delay_s
                     - coil_lag_s(nominal, axis, g.gain_a_per_v),
                     math.hypot(joint.delay_std_s, g.delay_std_s))
    return out


def qd_amplifier_lag_s(*, sid: SercaloIdentification | None,
                       gi: Mapping[str, CurrentAmplifierGain],
                       nominal: BenchParams) -> tuple[float, float]:
    """The 4QD amplifier's lag the delays measure [s], and its std [s] (NaN without them).

    ``τ_4QD = effective − pure − τ_coil``: the Sercalo's effective delay on
    ``Uc → Vp`` less the pure one of ``Uc → Vc`` (no sensor there) and the
    coil's lag. Its shape (order, bandwidth) is not measured, only its group
    delay.
    """
    pure_s, pure_std = _pure_delay(gi)
    eff_s, eff_std = _effective_delay(sid)
    if not (math.isfinite(pure_s) and math.isfinite(eff_s)):
        return math.nan, math.nan
    coil = float(np.mean([coil_lag_s(nominal, a, g.gain_a_per_v) for a, g in gi.items()]))
    return eff_s - pure_s - coil, math.hypot(eff_std, pure_std)


def _curvature_bound(lag_s: float, f_top_hz: float) -> float:
    """Half-width [s] of the gap between a lag's low-frequency group delay and the delay a
    fit up to ``f_top_hz`` reads: ``τ (2π f τ)² / 3`` (a first order's phase series)."""
    tau = max(lag_s, 0.0)
    return tau * (2 * math.pi * f_top_hz * tau) ** 2 / 3.0


def _qd(out: dict[str, Uncertain], qd: Mapping[str, QdCalibration]) -> None:
    for axis, cal in qd.items():
        out[f"qd_gain_v_per_rad.{axis}"] = Uncertain(
            cal.gain_v_per_rad, "V/rad",
            f"4QD small-signal gain of axis {axis} along the Newport's axis (g cos θ: the "
            "slope a single-axis calibration measures; the plant model's Gd)",
            {"noise": cal.gain_std_v_per_rad})
    if set(qd) != {"h", "v"}:
        return
    for axis, other in (("h", "v"), ("v", "h")):
        direct, cross = qd[axis], qd[other]
        s, s_std = cross.cross_slope_v_per_rad, cross.cross_slope_std_v_per_rad
        if not (math.isfinite(s) and math.isfinite(s_std)):
            continue
        a, a_std = direct.gain_v_per_rad, direct.gain_std_v_per_rad
        g = math.copysign(math.hypot(a, s), a)
        std = math.hypot(a * a_std, s * s_std) / abs(g)
        out[f"qd_diode_gain_v_per_rad.{axis}"] = Uncertain(
            g, "V/rad", f"4QD gain of axis {axis} along the diode's own axis (g)",
            {"noise": std},
            derived=f"hypot of the on-axis slope and the {other} calibration's cross slope "
                    f"(g sin θ), assuming the cross response is the diode's rotation")


def _sercalo_gain(out: dict[str, Uncertain], sid: SercaloIdentification,
                  gi: Mapping[str, CurrentAmplifierGain],
                  compression: CompressionFactors | None,
                  truncation: Mapping[str, TruncationCheck]) -> None:
    dc = dict(sid.dc_gain_v_per_a())
    pstd = sid.parameter_std
    for axis in "hv":
        parts: dict[str, float] = {}
        check = truncation.get(axis)
        bounded_parts: tuple[str, ...] = ()
        words = ""
        if check is not None:
            # A mode above the band bends the full band's fit (ident.truncation): the half
            # band's value, with the bias it may keep as a bound.
            dc[axis] = check.half_v_per_a
            parts.update(check.half_parts)
            parts["truncation"] = bounded(check.bias_bound_v_per_a)
            bounded_parts = ("truncation",)
            words = (f"; from the fit up to {check.half_band_hz:.0f} Hz (the full band's "
                     f"differs by {check.full_v_per_a - check.half_v_per_a:+.3g} V/A"
                     + (", more than its noise: a mode above the band)" if check.significant
                        else ", within its noise)"))
        elif pstd is not None and axis in pstd.parts:
            parts.update({k: v for k, v in pstd.parts[axis]["dc_gain_v_per_a"].items()
                          if math.isfinite(v)})
        g = gi.get(axis)
        if g is not None and g.gain_a_per_v:
            parts["current_amp"] = abs(dc[axis]) * g.gain_std_a_per_v / abs(g.gain_a_per_v)
        if compression is not None:
            factor, f_std = compression.element(*_DIRECT[axis])
            parts["compression"] = abs(dc[axis]) * f_std / factor
        inp, outp = {"h": ("Ich", "Vph"), "v": ("Icv", "Vpv")}[axis]
        out[f"sercalo.{axis}.dc_gain_v_per_a"] = Uncertain(
            dc[axis], "V/A", f"Sercalo static gain {inp} → {outp} (Gc(0), the 4QD's "
            "small-signal gain in)" + words, parts, bounded_parts=bounded_parts)


def _modes(out: dict[str, Uncertain], modes: Mapping[str, Mapping[str, float]]) -> None:
    for axis, m in modes.items():
        out[f"sercalo.{axis}.resonance_hz"] = Uncertain(
            m["resonance_hz"], "Hz", f"Sercalo natural frequency, axis {axis}",
            {"noise": _finite(m.get("resonance_hz_std"))})
        out[f"sercalo.{axis}.damping_ratio"] = Uncertain(
            m["damping_ratio"], "1", f"Sercalo damping ratio, axis {axis}",
            {"noise": _finite(m.get("damping_ratio_std"))})


def _finite(x: float | None) -> float:
    return float(x) if x is not None and math.isfinite(float(x)) else math.inf


def _delays(out: dict[str, Uncertain], *, sid: SercaloIdentification | None,
            gi: Mapping[str, CurrentAmplifierGain], newport: NewportIdentification | None,
            nominal: BenchParams) -> None:
    pure_s, pure_std = _pure_delay(gi)
    if math.isfinite(pure_s):
        out["delay_s.sercalo"] = Uncertain(
            pure_s, "s", "pure delay of the converter's path (DAC transport, the hold's half "
            "sample, latency), measured on Uc → Vc", {"noise": pure_std})
    coil = float(np.mean([coil_lag_s(nominal, a, g.gain_a_per_v) for a, g in gi.items()])) \
        if gi else 0.0
    eff_s, eff_s_std = _effective_delay(sid)
    lag = qd_amplifier_lag_s(sid=sid, gi=gi, nominal=nominal)[0]
    lag = lag if math.isfinite(lag) else 0.0
    lag_bound = 0.0
    if sid is not None and sid.joint_delays:
        f_top = max(j.band_hz[1] for j in sid.joint_delays)
        lag_bound = _curvature_bound(lag, f_top)
        out["effective_delay_s.sercalo"] = Uncertain(
            eff_s, "s", "effective delay of Uc → Vp: the pure delay with the coil's and the "
            "4QD amplifier's lags (their group delays), the mean of the two axes",
            {"noise": eff_s_std, "unresolved_lags": bounded(lag_bound)},
            bounded_parts=("unresolved_lags",))
    if newport is None or newport.dynamics is None:
        return
    dyn = newport.dynamics
    axes = dyn.axes
    known = newport.identified_axes
    eff_n = float(np.mean([axes[a].effective_delay_s for a in known]))
    eff_n_std = math.hypot(*(axes[a].delay_std_s for a in known)) / len(known)
    f_top_n = max(axes[a].band_hz[1] for a in known)
    bound_n = _curvature_bound(lag, f_top_n)
    # The amplifier's uncertain order (a bound) or measured lag (random) moves the Newport's
    # delay too (ident.evidence.amplifier): a part of every Newport delay.
    sensor = _sensor_part([newport.sensor_shifts[a] for a in known
                           if a in newport.sensor_shifts], "effective_delay_s")
    out["effective_delay_s.newport"] = Uncertain(
        eff_n, "s", "effective delay of Un → Vp: the Newport's pure delay with the 4QD "
        "amplifier's lag, the mean of the axes identified",
        {"noise": eff_n_std, "unresolved_lags": bounded(bound_n)} | sensor,
        bounded_parts=("unresolved_lags", *_bounded(sensor)))
    if not math.isfinite(eff_s):
        return
    both = bounded(max(bound_n, lag_bound))
    if math.isfinite(pure_s):
        out["delay_s.newport"] = Uncertain(
            eff_n - eff_s + pure_s + coil, "s", "pure delay of the Newport's paths (the "
            "converter's and the Newport's own lag), the mean of the two axes",
            {"noise": math.sqrt(eff_n_std**2 + eff_s_std**2 + pure_std**2),
             "unresolved_lags": both} | sensor,
            derived="the effective delay less the 4QD amplifier's lag, which the Sercalo's "
                    "effective and pure delays give",
            bounded_parts=("unresolved_lags", *_bounded(sensor)))
    for a in known:
        out[f"newport.{a}.internal_delay_s"] = Uncertain(
            axes[a].effective_delay_s - eff_s + coil, "s",
            f"the Newport's own lag, axis {a}: its effective delay less the Sercalo's, "
            "plus the coil's lag (on the Sercalo's path only)",
            {"noise": math.hypot(axes[a].delay_std_s, eff_s_std), "unresolved_lags": both}
            | sensor, bounded_parts=("unresolved_lags", *_bounded(sensor)))


def _sensor_part(shifts: Sequence[SensorShift], key: str) -> dict[str, float]:
    """The 4QD amplifier's part of a Newport value: its measured lag's (random,
    ``qd_amplifier_lag``) or its undecided order's (a bound, ``unresolved_sensor``), the
    largest over ``shifts`` (the axes'); empty when nothing moves it."""
    width = max((s.half_width.get(key, 0.0) for s in shifts), default=0.0)
    if not width > 0:
        return {}
    if any(s.measured for s in shifts):
        return {"qd_amplifier_lag": width}
    return {"unresolved_sensor": bounded(width)}


def _bounded(parts: Mapping[str, float]) -> tuple[str, ...]:
    """The names among ``parts`` that are bounds (uniform), not random parts."""
    return tuple(k for k in parts if k == "unresolved_sensor")


def _newport(out: dict[str, Uncertain], newport: NewportIdentification,
             compression: CompressionFactors | None) -> None:
    dyn = newport.dynamics
    if dyn is None:
        return
    for axis, fit in dyn.axes.items():
        if axis in newport.assumed_axes:
            continue  # the bench file's model stood in for a missing record: not reported
        parts = {"noise": fit.gain_std_v_per_v}
        if compression is not None:
            factor, f_std = compression.element(*_NEWPORT[axis])
            parts["compression"] = abs(fit.gain_v_per_v) * f_std / factor
        shift = newport.sensor_shifts.get(axis)
        shifts = [] if shift is None else [shift]
        sensor = _sensor_part(shifts, "gain_v_per_v")
        out[f"newport_gain_v_per_v.{axis}"] = Uncertain(
            fit.gain_v_per_v, "V/V", f"Newport static gain {_NEWPORT[axis][1]} → "
            f"{_NEWPORT[axis][0]}, signed (the 4QD's small-signal gain in)", parts | sensor,
            bounded_parts=_bounded(sensor))
        for key, unit, words, std in (
                ("natural_freq_hz", "Hz", "natural frequency", fit.natural_freq_std_hz),
                ("damping_ratio", "1", "damping ratio", fit.damping_std)):
            extra = _sensor_part(shifts, key)
            note = ("" if shift is None else
                    f" (with the 4QD amplifier the records decide, its lag "
                    f"{shift.lag_s * 1e6:.3g} µs measured with its std)" if shift.measured else
                    f" (the delays put the 4QD amplifier's lag at up to "
                    f"{shift.lag_s * 1e6:.3g} µs, not its order)")
            out[f"newport.{axis}.{key}"] = Uncertain(
                getattr(fit, key), unit, f"Newport {words}, axis {axis}{note}",
                {"noise": std} | extra, bounded_parts=_bounded(extra))


def uncertainty_tree(*, qd: Mapping[str, QdCalibration],
                     current_amp: Mapping[str, CurrentAmplifierGain],
                     sercalo: SercaloIdentification | None,
                     modes: Mapping[str, Mapping[str, float]],
                     newport: NewportIdentification | None,
                     compression: Mapping[str, CompressionFactors],
                     nominal: BenchParams,
                     refinement: ModeRefinement | None = None,
                     truncation: Mapping[str, TruncationCheck] | None = None
                     ) -> dict[str, Uncertain]:
    """Every identified value with its parts, keyed as ``twin_truth.json`` (see the module).

    Parameters
    ----------
    qd, current_amp : mapping axis -> calibration
    sercalo : SercaloIdentification or None
    modes : mapping axis -> {resonance_hz, damping_ratio, and their _std}
        The Sercalo's modes as reported (refined, else the fit's).
    newport : NewportIdentification or None
    compression : mapping {"sercalo", "newport"} -> CompressionFactors
        The 4QD compression factors applied to each FRF.
    nominal : BenchParams
        The coil's inductance (its lag).
    refinement : ModeRefinement, optional
        Unused but for the record (its stds are in ``modes``).
    truncation : mapping axis -> TruncationCheck, optional
        The static gains over half the band (:mod:`fsmbench.ident.fit.truncation`).
    """
    del refinement
    out: dict[str, Uncertain] = {}
    _qd(out, qd)
    for axis, g in current_amp.items():
        out[f"current_amp_gain_a_per_v.{axis}"] = Uncertain(
            g.gain_a_per_v, "A/V", f"current-amplifier gain of axis {axis}, static "
            "(1/(R + R_buffer + Rc)), against the bench file's Ga and Zc",
            {"noise": g.noise_std_a_per_v if math.isfinite(g.noise_std_a_per_v)
             else g.gain_std_a_per_v, "misfit": g.misfit_std_a_per_v})
    if sercalo is not None:
        _sercalo_gain(out, sercalo, current_amp, compression.get("sercalo"), truncation or {})
        _modes(out, modes)
    if newport is not None:
        _newport(out, newport, compression.get("newport"))
    _delays(out, sid=sercalo, gi=current_amp, newport=newport, nominal=nominal)
    return out
