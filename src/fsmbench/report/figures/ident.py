"""Figures of the identification as data (ESRF study Figs. 10, 12–14, 17–22, 25–28).

Each function turns an identification result into a
:class:`~fsmbench.report.figures.spec.Figure`; nothing is drawn here. FRF matrices
are small multiples, one panel per element (magnitude over phase), coloured
by the input's axis (h blue, v orange); fitted models are dashed black.
Every frequency line of a Welch estimate is kept in the magnitude. The phase
is drawn as control engineers read it: unwrapped along the line, the delay
removed, and only where the measurement knows it (a standard deviation of at
most :data:`PHASE_STD_MAX_DEG`, from the coherence and the number of
averages); runs of such lines are placed on the model's branch
(:func:`unwrapped_phase_deg`). When the FRF estimator gives the variance of
each line (periodic averaging, the local polynomial method) the matrix
figure draws its confidence bounds around the measured curve; a Welch
estimate has none drawn (:func:`estimator_description`).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import xarray as xr

from fsmbench.bench.params import BenchParams
from fsmbench.ident.calibration import (
    CurrentAmplifierGain,
    QdCalibration,
    known_ga_zc,
    trim_recording,
)
from fsmbench.ident.delay.bode import remove_delay
from fsmbench.ident.frf.response import FrequencyResponse
from fsmbench.ident.newport import NewportIdentification
from fsmbench.ident.sercalo import SercaloIdentification
from fsmbench.report.figures.spec import H_COLOR, V_COLOR, Figure, Line, Panel

__all__ = [
    "PHASE_MIN_RUN",
    "PHASE_STD_MAX_DEG",
    "axis_color",
    "coherence_figure",
    "current_amplifier_figure",
    "estimator_description",
    "frf_matrix_figure",
    "newport_delay_figure",
    "newport_model",
    "qd_regression_figure",
    "sercalo_model",
    "unwrapped_phase_deg",
    "weights_figure",
]

_QD_SIGNALS = {"h": ("Vph", "Vnh"), "v": ("Vpv", "Vnv")}
_AMP_SIGNALS = {"h": ("data_uch", "Uch", "Vch"), "v": ("data_ucv", "Ucv", "Vcv")}
_AXIS_WORD = {"h": "horizontal", "v": "vertical"}
_MODEL_COLOR = "#000000"
# Scatter points drawn per axis in the regression plot: enough to show the
# cloud's width, few enough to stay light (the fit uses every sample).
_SCATTER_POINTS = 3000
# A measured line's phase is drawn when its standard deviation is at most this [deg]:
# noise of ±10° still reads as a curve, and a step of 180° between two such lines is a
# change of the response, not of the noise.
PHASE_STD_MAX_DEG = 10.0
# ... and when at least this many neighbouring lines are: where the coherence is low a
# few lines pass by chance (a coherence estimate scatters), and alone they say nothing.
PHASE_MIN_RUN = 5


def axis_color(signal: str) -> str:
    """H_COLOR for a horizontal signal (name ends in ``h``), V_COLOR for a vertical one."""
    return H_COLOR if signal.endswith("h") else V_COLOR


def qd_regression_figure(qd: Mapping[str, QdCalibration],
                         recordings: Mapping[str, xr.Dataset]) -> Figure:
    """Fig. 10: 4QD voltage against beam angle with the fitted line, one panel per axis.

    Parameters
    ----------
    qd : mapping axis -> QdCalibration
        The fits of 2.1.
    recordings : mapping
        Holds ``data_cal_pd_h``/``_v`` (``Vph``/``Vpv`` and ``Vnh``/``Vnv`` [V]).
    """
    panels = []
    for axis, cal in qd.items():
        vp, vn = _QD_SIGNALS[axis]
        ds = trim_recording(recordings[cal.experiment], t0_s=cal.trim_s)
        x = cal.beam_factor * cal.metrology_gain_rad_per_v * np.asarray(ds[vn].values, float)
        y = np.asarray(ds[vp].values, dtype=float)
        step = max(1, x.size // _SCATTER_POINTS)
        xx = np.array([x.min(), x.max()])
        panels.append(Panel(
            traces=(Line(1e3 * x[::step], y[::step], name=f"measured {vp}", color=axis_color(vp),
                         markers=True, opacity=0.35),
                    Line(1e3 * xx, cal.gain_v_per_rad * xx + cal.offset_v,
                         name="fitted line", color=_MODEL_COLOR, dash="dash", width=1.2,
                         group="fit")),
            x_label="Beam angle 2·gn0·" + vn + " [mrad]", y_label=f"4QD output {vp} [V]",
            title=(f"{_AXIS_WORD[axis].capitalize()}: {cal.gain_v_per_rad:.2f} V/rad, "
                   f"R² = {cal.r_squared:.5f}")))
    return Figure(key="fig10_qd_regression", title="4QD calibration: linear regression",
                  caption=("4QD voltage against the beam angle (twice the Newport mirror angle "
                           "read by its metrology), after the first second is removed; "
                           f"about {_SCATTER_POINTS} samples per axis drawn, every sample "
                           "fitted."),
                  panels=tuple(panels), seed_ref="Fig. 10", columns=len(panels))


def current_amplifier_figure(gi: Mapping[str, CurrentAmplifierGain],
                             nominal: BenchParams) -> Figure:
    """Figs. 12–14: ``|Vc/Uc|`` measured against ``Ga·Zc·Gi``; ``Gi`` over the averaging band.

    Top row: the ``Uc → Vc`` estimate the identification fitted (``g.frf``, by its
    own estimator) with ``Ga·Zc·Gi`` for the theoretical ``Gi = 1/(R + Rc)``
    (dashed) and the identified ``Gi`` (black). Bottom row: the per-bin
    estimate ``|Ga Zc Gi| / |Ga Zc|`` over the band with its mean, the
    identified gain. Axes without an estimate are left out.
    """
    top, bottom = [], []
    how = ""
    for axis, g in gi.items():
        if g.frf is None:
            continue
        _exp, u, v = _AMP_SIGNALS[axis]
        color = axis_color(u)
        est = g.frf
        how = estimator_description(est)
        keep = est.frequency_hz > 0  # a log axis cannot show 0 Hz
        f = est.frequency_hz[keep]
        h = np.abs(est.frf.values[keep, 0, 0])
        gazc = known_ga_zc(nominal, axis=axis, f_hz=f)
        top.append(Panel(
            traces=(Line(f, h, name=f"measured {u} → {v}", color=color, width=2.5),
                    Line(f, gazc * g.theoretical_a_per_v,
                         name="Ga·Zc·Gi, theoretical Gi = 1/(R + Rc)", color="#7f7f7f",
                         dash="dash", group="theory"),
                    Line(f, gazc * g.gain_a_per_v, name="Ga·Zc·Gi, identified Gi",
                         color=_MODEL_COLOR, width=1.0, group="identified")),
            x_label="Frequency [Hz]", y_label=f"|{v}/{u}| [V/V]", x_log=True, y_log=True,
            title=f"{_AXIS_WORD[axis].capitalize()}: Gi = {1e3 * g.gain_a_per_v:.3f} mA/V",
            height=2.0, share_y="gain"))
        fb = np.asarray(g.frequency_hz)
        bottom.append(Panel(
            traces=(Line(fb, 1e3 * np.asarray(g.gi_response_a_per_v), name=f"|Ga Zc Gi| / |Ga Zc|"
                         f", {_AXIS_WORD[axis]}", color=color, markers=True),
                    Line(np.array([fb.min(), fb.max()]), np.full(2, 1e3 * g.gain_a_per_v),
                         name="mean over the band (identified Gi)", color=_MODEL_COLOR,
                         group="identified_mean")),
            x_label="Frequency [Hz]", y_label="Current-amplifier gain Gi [mA/V]", x_log=True))
    return Figure(key="fig12_14_current_amplifier",
                  title="Current amplifier: measured and modelled Uc → Vc",
                  caption=(f"Uc → Vc as the identification estimated it ({how}) against "
                           "Ga·Zc·Gi with Ga (1000, 1 kHz low pass) and Zc = Rc + Lc·s taken as "
                           "known; below, Gi per frequency line over the averaging band and its "
                           "mean."),
                  panels=tuple(top + bottom), seed_ref="Figs. 12–14", columns=len(top))


def _element_panels(frf: FrequencyResponse, values: xr.DataArray, *, y_label: str,
                    name: str, y_log: bool = False) -> tuple[Panel, ...]:
    """One panel per element, all on one y axis (the elements are compared)."""
    f = frf.frequency_hz
    sel = f > 0
    panels = []
    for out in frf.output_names:
        for inp in frf.input_names:
            panels.append(Panel(
                traces=(Line(f[sel], values.sel(output=out, input=inp).values[sel],
                             name=f"{name}, from {inp}", color=axis_color(inp), width=1.0),),
                x_label="Frequency [Hz]", y_label=y_label, x_log=True, y_log=y_log,
                title=f"{inp} → {out}", share_y="element"))
    return tuple(panels)


def coherence_figure(frf: FrequencyResponse, *, key: str, title: str, caption: str,
                     seed_ref: str) -> Figure:
    """Figs. 17, 25: coherence of every element of an FRF matrix, one panel each."""
    return Figure(key=key, title=title, caption=caption, seed_ref=seed_ref,
                  panels=_element_panels(frf, frf.coherence, y_label="Coherence [1]",
                                         name="coherence"),
                  columns=len(frf.input_names), share_x=True)


def weights_figure(sercalo: SercaloIdentification) -> Figure:
    """Fig. 20: the fit weights of each element of the Sercalo FRF matrix (the study's or 1/std)."""
    if sercalo.options.weights == "variance":
        caption = ("Inverse standard deviation of each line of the measured response (from the "
                   "estimator's noise variance), 0 above 1 kHz: the fit's residuals have unit "
                   "variance and the identified parameters carry standard deviations.")
        label = "Weight 1/std [V/V]⁻¹"
    else:
        caption = ("The ESRF study's weights: the coherence, 10 within ±10 % of the column's "
                   "resonance, 0 above 1 kHz; the fit divides them by |H| so that it "
                   "minimises the relative error.")
        label = "Weight [1]"
    return Figure(key="fig20_fit_weights", title="Sercalo: weights of the rational fit",
                  caption=caption,
                  panels=_element_panels(sercalo.frf, sercalo.weights, y_label=label,
                                         name="weight", y_log=sercalo.options.weights ==
                                         "variance"),
                  seed_ref="Fig. 20", columns=len(sercalo.frf.input_names), share_x=True)


def estimator_description(frf: FrequencyResponse) -> str:
    """How an FRF was estimated, in words, for captions (e.g. "Welch H1, 1 s Hann window")."""
    if frf.estimator == "periodic":
        return (f"averaged over the periods of the periodic excitation (period "
                f"{frf.window_length / frf.fs_hz:g} s, excited lines only), with the noise "
                "variance of each line from the spread between periods")
    if frf.estimator == "lpm":
        return (f"local polynomial method on the whole {frf.window_length / frf.fs_hz:g} s "
                "record (transient removed, noise variance per line), every 13th line shown")
    return f"Welch H1, {frf.window_length / frf.fs_hz:g} s Hann window"


def _runs(keep: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) of each run of True in ``keep``."""
    edges = np.flatnonzero(np.diff(np.r_[0, keep.astype(np.int8), 0]))
    return list(zip(edges[0::2].tolist(), edges[1::2].tolist(), strict=True))


def unwrapped_phase_deg(h: np.ndarray, *, keep: np.ndarray | None = None,
                        reference_deg: np.ndarray | None = None) -> np.ndarray:
    """Phase [deg] unwrapped along the line where ``keep``, NaN elsewhere.

    Each run of kept lines is unwrapped (consecutive lines never differ by
    more than 180°) and then moved by whole turns: onto the branch of
    ``reference_deg`` (the model's unwrapped phase) where the run has one,
    else to continue the run before it; the first run starts in (−180°, 180°].

    Parameters
    ----------
    h : numpy.ndarray, complex, shape (n,)
        Response on increasing frequencies.
    keep : numpy.ndarray of bool, shape (n,), optional
        Lines to draw (default: every finite one).
    reference_deg : numpy.ndarray, shape (n,), optional
        Unwrapped phase to follow [deg]; NaN where there is none.
    """
    h = np.asarray(h, dtype=complex)
    ok = np.isfinite(h) if keep is None else (np.asarray(keep, dtype=bool) & np.isfinite(h))
    out = np.full(h.shape, np.nan)
    previous: float | None = None
    for a, b in _runs(ok):
        run = np.degrees(np.unwrap(np.angle(h[a:b])))
        ref = None if reference_deg is None else reference_deg[a:b]
        if ref is not None and np.isfinite(ref).any():
            run += 360.0 * np.round(np.nanmedian(ref - run) / 360.0)
        elif previous is not None:
            run += 360.0 * np.round((previous - run[0]) / 360.0)
        out[a:b] = run
        previous = float(run[-1])
    return out


def _bound_lines(h: np.ndarray, r: np.ndarray, f: np.ndarray, phase_deg: np.ndarray, *,
                 color: str, confidence: float) -> tuple[list[Line], list[Line]]:
    """Magnitude and phase confidence bounds of a circular region of radius ``r``.

    The region ``|H_hat - H| <= r`` (``FrequencyResponse.bound_radius``: the F
    quantile of an estimated variance, Hotelling); its magnitude range is
    ``|H| -/+ r`` and its phase range ``+/- asin(r / |H|)`` (all phases when
    ``r >= |H|``), around the drawn (unwrapped) phase.
    """
    mag = np.abs(h)
    with np.errstate(invalid="ignore", divide="ignore"):
        half = np.degrees(np.where(r < mag, np.arcsin(np.minimum(r / mag, 1.0)), np.pi))
    lo = np.where(mag - r > 0, mag - r, np.nan)  # a gap on the log axis where it reaches 0
    name = f"{100 * confidence:g} % confidence bounds"

    def bound(y: np.ndarray, legend: bool) -> Line:
        return Line(f, y, name=name, color=color, width=0.6, opacity=0.45, group="bounds",
                    legend=legend)

    return ([bound(lo, True), bound(mag + r, False)],
            [bound(phase_deg - half, True), bound(phase_deg + half, False)])


def _phase_std_deg(frf: FrequencyResponse, out: str, inp: str) -> np.ndarray:
    """Standard deviation of each line's phase [deg]: the estimator's variance where it
    gives one, else Bendat & Piersol's random error (coherence and averages)."""
    if frf.frf_variance is not None:
        var = frf.frf_variance.sel(output=out, input=inp).values
        mag = np.abs(frf.frf.sel(output=out, input=inp).values)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.degrees(np.sqrt(var / 2.0) / mag)
    return np.degrees(np.asarray(frf.random_error.sel(output=out, input=inp).values))


def frf_matrix_figure(frf: FrequencyResponse, *, delay_s: float, model: np.ndarray | None,
                      key: str, title: str, caption: str, seed_ref: str,
                      model_name: str = "fitted model") -> Figure:
    """Figs. 18/19/21/22, 26/27: magnitude and phase of each element, the model over it.

    Parameters
    ----------
    frf : FrequencyResponse
        Measured matrix (delay included), F frequencies.
    delay_s : float
        Delay removed from the measurement before drawing [s], as the ESRF study
        removes it before fitting (said in the phase axes' labels).
    model : numpy.ndarray, shape (F, outputs, inputs), optional
        Delay-free model on ``frf``'s grid [V/V]; NaN where there is none.
    key, title, caption, seed_ref, model_name : str

    Each element gets a magnitude panel over a phase panel; the matrix keeps
    the ESRF study's layout (rows: outputs, columns: inputs). The phase is
    unwrapped and drawn where its standard deviation is at most
    :data:`PHASE_STD_MAX_DEG` (:func:`unwrapped_phase_deg`, on the model's
    branch), in runs of at least five lines; an element with no such run
    shows the model's phase alone, or without a model its measured phase as
    faint dots, wrapped. With
    ``frf.frf_variance`` (periodic, LPM) each measured curve has its
    confidence bounds at ``frf.confidence`` (thin lines).
    """
    clean = remove_delay(frf, delay_s)
    f = clean.frequency_hz
    sel = f > 0
    n_in = len(frf.input_names)
    mags: list[Panel] = []
    phases: list[Panel] = []
    phase_label = "Phase, delay removed [deg]" if delay_s else "Phase [deg]"
    for i, out in enumerate(frf.output_names):
        for j, inp in enumerate(frf.input_names):
            h = clean.frf.sel(output=out, input=inp).values[sel]
            color = axis_color(inp)
            label = f"measured, from {inp}"
            m = model[sel, i, j] if model is not None else np.full(h.shape, np.nan, complex)
            has_model = bool(np.isfinite(m).any())
            m_phase = unwrapped_phase_deg(m) if has_model else None
            known = _phase_std_deg(clean, out, inp)[sel] <= PHASE_STD_MAX_DEG
            for a, b in _runs(known):
                if b - a < PHASE_MIN_RUN:
                    known[a:b] = False
            ph = unwrapped_phase_deg(h, keep=known, reference_deg=m_phase)
            mag_tr: list[Line] = [Line(f[sel], np.abs(h), name=label, color=color, width=1.0,
                                       group=label)]
            ph_tr: list[Line] = []
            if known.any():
                ph_tr = [Line(f[sel], ph, name=label, color=color, width=1.0, group=label)]
            elif not has_model:  # nothing known, nothing to follow: the phase of noise
                ph_tr = [Line(f[sel], np.degrees(np.angle(h)), name=label, color=color,
                              markers=True, opacity=0.15, group=label, legend=False)]
            if clean.frf_variance is not None and known.any():
                radius = clean.bound_radius().sel(output=out, input=inp).values[sel]
                mb, pb = _bound_lines(h, radius, f[sel], ph, color=color,
                                      confidence=frf.confidence)
                mag_tr += mb
                ph_tr += pb
            if has_model and m_phase is not None:
                mag_tr.append(Line(f[sel], np.abs(m), name=model_name, color=_MODEL_COLOR,
                                   dash="dash", width=1.2, group="model"))
                ph_tr.append(Line(f[sel], m_phase, name=model_name, color=_MODEL_COLOR,
                                  dash="dash", width=1.2, group="model"))
            mags.append(Panel(traces=tuple(mag_tr), x_label="Frequency [Hz]",
                              y_label=f"|{out}/{inp}| [V/V]", x_log=True, y_log=True,
                              title=f"{inp} → {out}", height=2.0))
            phases.append(Panel(traces=tuple(ph_tr), x_label="Frequency [Hz]",
                                y_label=phase_label, x_log=True, height=1.3))
    # Rows: magnitude of output 1, its phase, magnitude of output 2, its phase.
    panels: list[Panel] = []
    for r in range(len(frf.output_names)):
        panels += mags[r * n_in:(r + 1) * n_in] + phases[r * n_in:(r + 1) * n_in]
    return Figure(key=key, title=title, caption=caption, panels=tuple(panels),
                  seed_ref=seed_ref, columns=n_in, share_x=True)


def sercalo_model(sercalo: SercaloIdentification) -> np.ndarray:
    """The fitted delay-free ``Uc → Vp`` model on the measured grid, shape (F, 2, 2).

    NaN at 0 Hz, where the fit is not evaluated.
    """
    f = sercalo.frf.frequency_hz
    model = np.full(sercalo.frf.frf.shape, np.nan, dtype=complex)
    model[f > 0] = sercalo.fit.response(f[f > 0])
    return model


def newport_model(newport: NewportIdentification) -> np.ndarray:
    """The identified Newport on the grid, delay-free, shape (F, 2, 2).

    With its dynamics: each axis's second order (with the hold's droop, as
    measured) over the band it was fitted on. Otherwise the ESRF study's signed
    constant gains over their averaging band. NaN off the diagonal (``Gn`` is
    diagonal) and outside the band, so the figure shows where the model holds.
    """
    f = newport.frf.frequency_hz
    model = np.full(newport.frf.frf.shape, np.nan, dtype=complex)
    dyn = newport.dynamics
    outputs = list(newport.frf.output_names)
    # The matrix's own columns: an axis whose record was missing has none.
    for j, inp in enumerate(newport.frf.input_names):
        axis = inp[-1]
        i = outputs.index(f"Vp{axis}")
        if dyn is not None:
            a = dyn.axes[axis]
            band = (f >= a.band_hz[0]) & (f <= a.band_hz[1])
            model[band, i, j] = a.response(f[band], fs_hz=dyn.fs_hz, delay=False)
        else:
            band = (f >= newport.band_hz[0]) & (f <= newport.band_hz[1])
            model[band, i, j] = newport.gain_v_per_v[axis]
    return model


def newport_delay_figure(newport: NewportIdentification, *, f_max_hz: float = 2000.0) -> Figure:
    """Fig. 28: unwrapped phase of the Newport's direct paths with and without the delay."""
    f = newport.frf.frequency_hz
    sel = (f > 0) & (f <= f_max_hz)
    clean = remove_delay(newport.frf, newport.delay_s)
    panels = []
    ms = 1e3 * newport.delay_s
    for inp in newport.frf.input_names:
        out = f"Vp{inp[-1]}"
        raw = np.unwrap(np.angle(newport.frf.frf.sel(output=out, input=inp).values[sel]))
        fixed = np.unwrap(np.angle(clean.frf.sel(output=out, input=inp).values[sel]))
        panels.append(Panel(
            traces=(Line(f[sel], np.degrees(raw), name=f"measured, from {inp}",
                         color=axis_color(inp), width=1.0),
                    Line(f[sel], np.degrees(fixed), name=f"delay {ms:.3f} ms removed",
                         color=_MODEL_COLOR, width=1.0, group="clean")),
            x_label="Frequency [Hz]", y_label="Phase, unwrapped [deg]", x_log=True,
            title=f"{inp} → {out}", share_y="phase"))
    return Figure(key="fig28_newport_delay", title="Newport: phase with and without the delay",
                  caption=(f"Unwrapped phase of the direct paths up to {f_max_hz:g} Hz, before "
                           f"and after removing the delay estimated from the phase ({ms:.3f} ms; "
                           "the ESRF study assumes 0.5 ms)."),
                  panels=tuple(panels), seed_ref="Fig. 28", columns=len(panels))
