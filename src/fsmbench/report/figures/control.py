"""Figures of the control chapters (ESRF study sections 5–10) as data.

Each function turns a result of :mod:`fsmbench.control` into a
:class:`~fsmbench.report.figures.spec.Figure`: frequency responses with labels in
words and units, h in blue and v in orange. Nothing here computes a design
or draws; the report's renderers draw.

The loops are sampled: their curves end at the Nyquist frequency the
results carry (``LoopAnalysis.nyquist_hz``, ``PlantAnalysis.nyquist_hz``).
A loop's magnitude is in dB and its phase is drawn unwrapped, placed at the
crossover, over the whole band of the magnitude, with its margins marked
(:func:`margin_markers`). Panels of one quantity share their y axis, so h and v
compare at a glance.
"""

from __future__ import annotations

from collections.abc import Sequence
from itertools import product

import control as ct
import numpy as np

from fsmbench.bench.blocks import ss_frequency_response
from fsmbench.control.analysis import PlantAnalysis
from fsmbench.control.design import Robustness
from fsmbench.control.freq import Margins
from fsmbench.control.iff import IffAnalysis
from fsmbench.control.loops import AXES, LoopAnalysis
from fsmbench.control.study import NewportToBeam
from fsmbench.report.figures.spec import H_COLOR, PALETTE, V_COLOR, Figure, Line, Panel, Rule

__all__ = [
    "AXIS_WORDS",
    "ESRF_COLOR",
    "FSM_COLOR",
    "band_words",
    "bode_phase_deg",
    "controllers_figure",
    "iff_figure",
    "loop_gain_figure",
    "margin_markers",
    "newport_to_beam_figure",
    "nyquist_figure",
    "perturbation_factors",
    "plant_figure",
    "robustness_figure",
    "scaled_plant_figure",
    "sensitivity_figure",
    "unstable_on_axis",
]

AXIS_WORDS = {"h": "horizontal (h)", "v": "vertical (v)"}
_AXIS_COLOR = {"h": H_COLOR, "v": V_COLOR}
# Colours of the controllers where h and v sit in separate panels.
ESRF_COLOR = PALETTE[2]
FSM_COLOR = PALETTE[4]
_UNSTABLE_COLOR = PALETTE[3]
# Nyquist window: ±1.5 around −1 shows the unit circle's left half, the
# modulus-margin circle and every crossing of the negative real axis that matters.
_NYQUIST_HALF_WIDTH = 1.5
# Points of L with |L| above this lie far outside that window; dropping them keeps
# the plot's data small without changing what is visible.
_NYQUIST_MAX_ABS = 100.0
FREQ = "Frequency [Hz]"


def bode_phase_deg(x: np.ndarray, *, f_hz: np.ndarray, anchor_hz: float) -> np.ndarray:
    """Unwrapped phase [deg], shifted by whole turns to lie in (−360, 0] at ``anchor_hz``.

    Anchoring at the crossover puts the −180° line where the phase margin is
    read, whatever the number of integrators.

    Parameters
    ----------
    x : numpy.ndarray, complex, shape (n,)
        Frequency response on ``f_hz``.
    f_hz : numpy.ndarray, shape (n,)
        Increasing frequencies [Hz].
    anchor_hz : float
        Frequency of the anchor [Hz]; NaN: no shift.
    """
    ph = np.degrees(np.unwrap(np.angle(x)))
    if not np.isfinite(anchor_hz):
        return ph
    at = ph[int(np.argmin(np.abs(np.log(f_hz / anchor_hz))))]
    return ph - 360.0 * np.ceil(at / 360.0)


def _fmt_margin(x: float, spec: str) -> str:
    return format(x, spec) if np.isfinite(x) else "∞"


def _phase_from_low(x: np.ndarray) -> np.ndarray:
    """Unwrapped phase [deg], its first value in (−180°, 180°]."""
    ph = np.degrees(np.unwrap(np.angle(x)))
    return np.asarray(ph - 360.0 * np.round(ph[0] / 360.0), dtype=float)


def _db(x: np.ndarray) -> np.ndarray:
    """``20 log10 |x|`` [dB]; −inf where ``x`` is zero."""
    with np.errstate(divide="ignore"):
        return np.asarray(20.0 * np.log10(np.abs(x)), dtype=float)


def band_words(f_hz: np.ndarray) -> str:
    """The drawn band in words: "from 0.01 Hz to 5000 Hz"."""
    return f"from {float(f_hz[0]):.3g} Hz to {float(f_hz[-1]):.4g} Hz"


def margin_markers(m: Margins, *, axis: str, color: str) -> tuple[tuple[Line, ...],
                                                                  tuple[Line, ...]]:
    """The margins drawn as MATLAB's ``margin`` does: (magnitude-panel traces, phase-panel traces).

    The gain margin is a vertical segment [dB] from ``|L|`` up to 0 dB at its
    −180° crossing; the gain-reduction margin (conditionally stable loops) a
    segment from 0 dB up to ``|L|`` at the −180° crossing where ``|L| > 1``;
    the phase margin a segment from −180° to the phase at the crossover.
    Absent margins (∞) draw nothing.
    """
    mag: list[Line] = []
    phase: list[Line] = []
    if np.isfinite(m.gain_margin_db) and np.isfinite(m.phase_crossover_hz):
        f = m.phase_crossover_hz
        mag.append(Line(np.array([f, f]), np.array([-m.gain_margin_db, 0.0]),
                        name=f"{axis}: gain margin {m.gain_margin_db:.1f} dB at {f:.4g} Hz",
                        color=color, width=3.0))
    if np.isfinite(m.gain_reduction_margin_db) and np.isfinite(m.gain_reduction_crossover_hz):
        f = m.gain_reduction_crossover_hz
        mag.append(Line(np.array([f, f]), np.array([0.0, m.gain_reduction_margin_db]),
                        name=(f"{axis}: gain-reduction margin {m.gain_reduction_margin_db:.1f} dB "
                              f"at {f:.4g} Hz (conditionally stable)"),
                        color=_UNSTABLE_COLOR, width=3.0))
    if np.isfinite(m.phase_margin_deg) and np.isfinite(m.crossover_hz):
        f = m.crossover_hz
        phase.append(Line(np.array([f, f]), np.array([-180.0, -180.0 + m.phase_margin_deg]),
                          name=(f"{axis}: phase margin {m.phase_margin_deg:.1f}° at "
                                f"{f:.4g} Hz"),
                          color=color, width=3.0))
    return tuple(mag), tuple(phase)


def loop_gain_figure(lp: LoopAnalysis, *, key: str, title: str, caption: str,
                     seed_ref: str = "", note: str = "") -> Figure:
    """Bode plot of the diagonal loop gains ``L_ii = (G K)_ii``: one column per axis.

    Magnitude in dB and phase over the same band, up to the loop's Nyquist
    frequency. The phase is unwrapped and shifted by whole turns to lie in
    (−360°, 0] at the crossover (:func:`bode_phase_deg`), so the −180° line
    reads the phase margin there, and a conditionally stable loop shows its
    phase below −180° where ``|L| > 1``. The margins are drawn as segments
    (:func:`margin_markers`): the gain margin, the gain-reduction margin when
    the loop has one, the phase margin; the legend names each with its value.
    The caption is completed with the band drawn.

    Parameters
    ----------
    lp : LoopAnalysis
        A verified loop; ``lp.loop`` has shape (n, 2, 2) on ``lp.f_hz`` [Hz].
    key, title, caption, seed_ref, note : str
        As for :class:`~fsmbench.report.figures.spec.Figure`.
    """
    mags, phases = [], []
    inband = lp.f_hz <= lp.nyquist_hz
    f = lp.f_hz[inband]
    for i, axis in enumerate(AXES):
        li = lp.loop[inband, i, i]
        m = lp.axes[axis].margins
        color = _AXIS_COLOR[axis]
        marks: tuple[Rule, ...] = ()
        if np.isfinite(m.crossover_hz):
            marks = (Rule(m.crossover_hz, axis="x", dash="dot", color="#555555"),)
        phase = bode_phase_deg(li, f_hz=f, anchor_hz=m.crossover_hz)
        mag_marks, phase_marks = margin_markers(m, axis=axis, color=color)
        mags.append(Panel(traces=(Line(f, _db(li), name=f"{axis}: loop gain L{axis}",
                                       color=color, group=f"L{axis}"), *mag_marks),
                          x_label=FREQ, y_label=f"|L{axis}| [dB]", x_log=True,
                          title=f"Loop gain, {AXIS_WORDS[axis]}",
                          rules=(Rule(0.0, name="|L| = 1 (0 dB)", dash="dash"), *marks),
                          height=2.0, share_y="gain"))
        phases.append(Panel(traces=(Line(f, phase, name=f"{axis}: loop gain L{axis}",
                                         color=color, group=f"L{axis}", legend=False),
                                    *phase_marks),
                            x_label=FREQ, y_label=f"Phase of L{axis} [deg]", x_log=True,
                            rules=(Rule(-180.0, name="−180°", dash="dash"), *marks),
                            share_y="phase"))
    band = (f" Magnitude and phase are drawn over the same band, {band_words(f)} "
            f"(the Nyquist frequency of the sampled loop).")
    return Figure(key=key, title=title, caption=caption + band, seed_ref=seed_ref, note=note,
                  panels=(mags[0], mags[1], phases[0], phases[1]), columns=2, share_x=True)


def controllers_figure(controllers: Sequence[tuple[str, ct.StateSpace, str]], *,
                       f_hz: np.ndarray, key: str, title: str, caption: str) -> Figure:
    """``|K_ii|`` of each controller (``Rh, Rv → Uch, Ucv``), one panel per axis.

    Parameters
    ----------
    controllers : sequence of (str, control.StateSpace, str)
        Legend text in words, the continuous controller, its colour.
    f_hz : numpy.ndarray, shape (n,)
        Frequencies [Hz].
    key, title, caption : str
    """
    resp = [(name, ss_frequency_response(k, f_hz), color) for name, k, color in controllers]
    panels = tuple(
        Panel(traces=tuple(Line(f_hz, np.abs(r[:, i, i]), name=name, color=color)
                           for name, r, color in resp),
              x_label=FREQ, y_label=f"|K{axis}| [V/rad]", x_log=True, y_log=True,
              title=f"Controller, {AXIS_WORDS[axis]}", share_y="controller")
        for i, axis in enumerate(AXES))
    return Figure(key=key, title=title, caption=caption, panels=panels, columns=2,
                  height_px=440)


def _circle(center: complex, radius: float, n: int = 361) -> tuple[np.ndarray, np.ndarray]:
    th = np.linspace(0.0, 2 * np.pi, n)
    return center.real + radius * np.cos(th), center.imag + radius * np.sin(th)


def nyquist_figure(lp: LoopAnalysis, *, key: str, title: str, caption: str,
                   note: str = "") -> Figure:
    """Nyquist plots of ``L_h`` and ``L_v`` in a fixed window around −1, equal aspect.

    Each panel's title says whether that loop alone is stable (exact-delay
    Nyquist count); the modulus-margin circle is centred on −1.
    """
    panels = []
    w = _NYQUIST_HALF_WIDTH
    inband = lp.f_hz <= lp.nyquist_hz
    for i, axis in enumerate(AXES):
        ax = lp.axes[axis]
        li = lp.loop[inband, i, i]
        keep = np.abs(li) <= _NYQUIST_MAX_ABS
        li = np.where(keep, li, np.nan)
        mm = ax.margins.modulus_margin
        state = ("closed alone: stable" if ax.stable
                 else "closed alone: UNSTABLE (−1 encircled)")
        panels.append(Panel(
            traces=(
                Line(li.real, li.imag, name=f"L(j2πf), 0 < f ≤ {lp.nyquist_hz:g} Hz (Nyquist)",
                     color=_AXIS_COLOR[axis]),
                Line(li.real, -li.imag, name="mirror image, f < 0", color=_AXIS_COLOR[axis],
                     dash="dot", opacity=0.6),
                Line(*_circle(0j, 1.0), name="|L| = 1", color="#555555", dash="dot",
                     width=1.0, group="unit circle"),
                Line(*_circle(-1 + 0j, mm), name=f"modulus margin {mm:.2f} around −1",
                     color=_UNSTABLE_COLOR, dash="dash", width=1.0),
                Line(np.array([-1.0]), np.array([0.0]), name="critical point −1",
                     color="#000000", markers=True, group="critical point"),
            ),
            x_label=f"Real part of L{axis} [1]", y_label=f"Imaginary part of L{axis} [1]",
            title=f"{AXIS_WORDS[axis]}, {state}",
            x_range=(-1.0 - w, -1.0 + w), y_range=(-w, w), equal_aspect=True))
    return Figure(key=key, title=title, caption=caption, note=note, panels=tuple(panels),
                  columns=2, height_px=560)


def sensitivity_figure(lp: LoopAnalysis, *, key: str, title: str, caption: str,
                       note: str = "") -> Figure:
    """``|S_ii|`` and ``|T_ii|`` per axis with the 6.1 bound at its frequency."""
    obj = lp.objective
    panels = []
    inband = lp.f_hz <= lp.nyquist_hz
    f = lp.f_hz[inband]
    for i, axis in enumerate(AXES):
        panels.append(Panel(
            traces=(
                Line(f, np.abs(lp.sensitivity[inband, i, i]), name="sensitivity |S|",
                     color=_AXIS_COLOR[axis], group="S"),
                Line(f, np.abs(lp.complementary[inband, i, i]),
                     name="complementary sensitivity |T|", color=_AXIS_COLOR[axis],
                     dash="dash", group="T"),
                Line(np.array([obj.frequency_hz]), np.array([obj.sensitivity_bound]),
                     name=(f"objective of 6.1: |S({obj.frequency_hz:g} Hz)| ≤ "
                           f"{obj.sensitivity_bound:.0e}"),
                     color=_UNSTABLE_COLOR, markers=True, group="objective"),
            ),
            x_label=FREQ, y_label=f"|S{axis}|, |T{axis}| [1]", x_log=True, y_log=True,
            title=AXIS_WORDS[axis], rules=(Rule(1.0, dash="dot", color="#888888"),),
            share_y="sensitivity"))
    return Figure(key=key, title=title, caption=caption, note=note, panels=tuple(panels),
                  columns=2, height_px=460)


def perturbation_factors(rob: Robustness, *, frequency_scales: Sequence[float],
                         damping_scales: Sequence[float]) -> list[tuple[float, float]]:
    """(resonance factor, damping factor) of each case of ``rob``, in its order.

    :func:`fsmbench.control.design.perturbed_plants` runs the resonance
    factors outermost, the damping factors inside.
    """
    pairs = list(product(frequency_scales, damping_scales))
    if len(pairs) != len(rob.loops):
        raise ValueError(f"robustness: {len(rob.loops)} perturbed plants for "
                         f"{len(frequency_scales)} × {len(damping_scales)} factors")
    return pairs


def unstable_on_axis(lp: LoopAnalysis, axis: str) -> bool:
    """Whether ``axis`` is to blame for an unstable closed loop.

    The axis whose loop alone is unstable; if the MIMO loop is unstable while
    each axis alone is stable (coupling), both axes.
    """
    if lp.stable and lp.nyquist.stable:
        return False
    alone = [a for a in AXES if not lp.axes[a].stable]
    return axis in alone or not alone


def robustness_figure(rob: Robustness, *, factors: Sequence[tuple[float, float]],
                      band_hz: tuple[float, float], key: str, title: str, caption: str,
                      note: str = "") -> Figure:
    """Loop-gain magnitudes over the perturbed plants as small multiples.

    One column per resonance factor, one row per axis; the damping factors
    are distinct curves. A case whose closed loop is unstable is drawn thick
    in red and named so in the legend, in the row of the axis that causes it
    (:func:`unstable_on_axis`).

    Parameters
    ----------
    rob : Robustness
    factors : sequence of (float, float)
        (resonance factor, damping factor) of each case, from :func:`perturbation_factors`.
    band_hz : (float, float)
        Frequencies drawn [Hz]: the band around the resonances, where the
        perturbed loops differ (elsewhere they coincide).
    key, title, caption, note : str
    """
    fs_values = sorted({fs for fs, _ in factors})
    ds_values = sorted({ds for _, ds in factors})
    ds_color = {ds: PALETTE[(2, 4, 5, 6, 8, 9)[j % 6]] for j, ds in enumerate(ds_values)}
    panels = []
    for i, axis in enumerate(AXES):
        for fs in fs_values:
            traces = []
            for (f_s, d_s), lp in zip(factors, rob.loops, strict=True):
                if f_s != fs:
                    continue
                stable = not unstable_on_axis(lp, axis)
                name = f"damping ×{d_s:g}"
                if not stable:
                    name = f"resonance ×{f_s:g}, damping ×{d_s:g}: closed loop UNSTABLE"
                sel = ((lp.f_hz >= band_hz[0]) & (lp.f_hz <= band_hz[1])
                       & (lp.f_hz <= lp.nyquist_hz))
                traces.append(Line(lp.f_hz[sel], _db(lp.loop[sel, i, i]), name=name,
                                   color=ds_color[d_s] if stable else _UNSTABLE_COLOR,
                                   width=1.2 if stable else 2.4,
                                   dash="solid" if stable else "dash"))
            panels.append(Panel(traces=tuple(traces), x_label=FREQ,
                                y_label=f"|L{axis}| [dB]", x_log=True,
                                title=f"{axis}, resonances ×{fs:g}",
                                rules=(Rule(0.0, dash="dot", color="#555555"),),
                                share_y="gain"))
    return Figure(key=key, title=title, caption=caption, note=note, panels=tuple(panels),
                  columns=len(fs_values), share_x=True, height_px=640)


def newport_to_beam_figure(n2b: NewportToBeam, *, key: str, title: str, caption: str,
                           seed_ref: str = "") -> Figure:
    """``|Un_i → R_i|`` open loop and with each Sercalo controller closed (ESRF study Fig. 42)."""
    words = {"seed_controller": ("with the ESRF study's controller", ESRF_COLOR),
             "fsmbench_controller": ("with fsmbench's controller", FSM_COLOR)}
    panels = []
    for i, axis in enumerate(AXES):
        traces = [Line(n2b.f_hz, np.abs(n2b.open_loop[:, i, i]), name="Sercalo loop open",
                       color="#000000")]
        for name, resp in n2b.closed.items():
            label, color = words.get(name, (f"with {name}", None))
            traces.append(Line(n2b.f_hz, np.abs(resp[:, i, i]), name=label, color=color))
        panels.append(Panel(traces=tuple(traces), x_label=FREQ,
                            y_label=f"|R{axis} / Un{axis}| [rad/V]", x_log=True, y_log=True,
                            title=f"Newport command Un{axis} to beam angle R{axis}",
                            share_y="gain"))
    return Figure(key=key, title=title, caption=caption, seed_ref=seed_ref,
                  panels=tuple(panels), columns=2, height_px=460)


def scaled_plant_figure(pa: PlantAnalysis, *, key: str, title: str, caption: str) -> Figure:
    """Smallest singular value of the scaled plant and largest of the scaled disturbance,
    up to the Nyquist frequency."""
    sel = pa.f_hz <= pa.nyquist_hz
    f = pa.f_hz[sel]
    panel = Panel(
        traces=(Line(f, pa.scaled_min_singular_value[sel],
                     name="smallest singular value of the scaled plant (Uc / 10 V → R / 10 µrad)",
                     color=PALETTE[0]),
                Line(f, pa.scaled_disturbance_gain[sel],
                     name="largest singular value of the scaled Newport path (Un / 1 V → R / "
                          "10 µrad)", color=PALETTE[3])),
        x_label=FREQ, y_label="Scaled gain [1]", x_log=True, y_log=True,
        rules=(Rule(1.0, dash="dot", color="#555555"),))
    return Figure(key=key, title=title, caption=caption, panels=(panel,), height_px=440)


def plant_figure(pa: PlantAnalysis, *, key: str, title: str, caption: str,
                 note: str = "") -> Figure:
    """RGA number and singular values of ``Uch, Ucv → Rh, Rv`` (ESRF study 7.2), up to Nyquist."""
    sel = pa.f_hz <= pa.nyquist_hz
    f = pa.f_hz[sel]
    rga = Panel(traces=(Line(f, pa.rga_number[sel], name="RGA number", color=PALETTE[2]),),
                x_label=FREQ, y_label="RGA number Σ|Λ − I| [1]", x_log=True, y_log=True,
                title="Relative gain array number")
    sv = Panel(traces=(Line(f, pa.singular_values[sel, 0], name="largest singular value",
                            color=PALETTE[0]),
                       Line(f, pa.singular_values[sel, 1], name="smallest singular value",
                            color=PALETTE[1], dash="dash")),
               x_label=FREQ, y_label="Singular value of G [rad/V]", x_log=True, y_log=True,
               title="Singular values", height=1.5)
    return Figure(key=key, title=title, caption=caption, note=note, panels=(rga, sv),
                  share_x=True)


def iff_figure(iff: IffAnalysis, *, key: str, title: str, caption: str,
               note: str = "") -> Figure:
    """``Uc_i → Vp_i`` without and with the ESRF study's IFF: one column per axis."""
    mags, phases = [], []
    f_lo = float(iff.f_hz[0])
    for i, axis in enumerate(AXES):
        open_i, closed_i = iff.open_loop[:, i, i], iff.closed_loop[:, i, i]
        closed_name = ("with the ESRF study's IFF (closed loop stable)" if iff.loop_stable else
                       "with the ESRF study's IFF (closed loop unstable: not a steady state)")
        mags.append(Panel(
            traces=(Line(iff.f_hz, np.abs(open_i), name=f"without IFF, {axis}",
                         color=_AXIS_COLOR[axis],
                         group=f"open {axis}"),
                    Line(iff.f_hz, np.abs(closed_i), name=closed_name, color="#000000",
                         dash="dash", group="closed")),
            x_label=FREQ, y_label=f"|Vp{axis} / Uc{axis}| [V/V]", x_log=True, y_log=True,
            title=f"Uc{axis} → Vp{axis}, {AXIS_WORDS[axis]}", height=2.0, share_y="gain"))
        phases.append(Panel(
            traces=(Line(iff.f_hz, _phase_from_low(open_i),
                         name=f"without IFF, {axis}",
                         color=_AXIS_COLOR[axis], group=f"open {axis}", legend=False),
                    Line(iff.f_hz,
                         _phase_from_low(closed_i),
                         name=closed_name,
                         color="#000000", dash="dash", group="closed", legend=False)),
            x_label=FREQ, y_label=f"Phase of Vp{axis} / Uc{axis} [deg]", x_log=True,
            share_y="phase"))
    band = (f" Magnitude and phase over the same band, {band_words(iff.f_hz)}; the phase is "
            f"unwrapped from its value at {f_lo:.3g} Hz, taken in (−180°, 180°].")
    return Figure(key=key, title=title, caption=caption + band, note=note,
                  panels=(mags[0], mags[1], phases[0], phases[1]), columns=2, share_x=True)
