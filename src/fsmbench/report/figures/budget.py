"""Figures of ESRF study sections 3 (huddle test) and 4 (error budget) as data.

Builders return :class:`~fsmbench.report.figures.spec.Figure` objects; the
sections (:mod:`fsmbench.report.sections.huddle`,
:mod:`fsmbench.report.sections.budget`) place them next to their text.
Arrays the results do not carry (the trimmed time records, the ray trace)
are recomputed here with the numerics' public functions; nothing here
changes a number.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from fsmbench.bench.geometry import esrf_theta_range, small_angle_law, trace_bench
from fsmbench.budget.huddle import HuddleAnalysis, HuddleRecord, trim_huddle
from fsmbench.budget.optics import SEED_4_1, GeometryBudget
from fsmbench.budget.spectra import cumulative_power, window_weight
from fsmbench.budget.stability import StabilityRecord
from fsmbench.budget.table import ErrorBudget
from fsmbench.report.figures.spec import H_COLOR, PALETTE, V_COLOR, Figure, Label, Line, Panel
from fsmbench.report.figures.stability import envelope_line, time_axis

__all__ = [
    "angle_asd_figure",
    "asd_line",
    "beam_path_figure",
    "cumulative_line",
    "distance_cumulative_figure",
    "distance_cumulative_m",
    "huddle_attocube_asd_figure",
    "huddle_attocube_time_figure",
    "huddle_config_words",
    "huddle_qd_asd_figure",
    "huddle_qd_time_figure",
    "huddle_test_label",
    "log_envelope",
    "path_error_figure",
]

FloatArray = NDArray[np.float64]

NM = 1e9  # m → nm
UM = 1e6  # rad → µrad, V → µV
MV = 1e3  # V → mV
# Light/dark of one hue: the raw record and its low-passed version (Fig. 29).
_RAW_COLOR = "#9ecae1"
_LPF_COLOR = "#08519c"


def huddle_config_words(rec: HuddleRecord) -> str:
    """The test's configuration (ESRF study Table 3) in words."""
    parts = ["closed loop" if rec.closed_loop else "open loop",
             "compensation unit on" if rec.compensation_unit else "no compensation unit"]
    if rec.shielding:
        parts.append("aluminium shielding")
    return ", ".join(parts)


def huddle_test_label(rec: HuddleRecord) -> str:
    """Legend text: ``"test 3: closed loop, compensation unit on"``."""
    return f"test {rec.number}: {huddle_config_words(rec)}"


def log_envelope(x: FloatArray, y: FloatArray, *, bins: int = 2000
                 ) -> tuple[FloatArray, FloatArray]:
    """Min/max of ``y`` in ``bins`` logarithmic bins of ``x``, for a log frequency axis.

    The renderer's envelope bins linearly, which on a log axis would merge
    the first decades into a few columns. Here every bin keeps its smallest
    and largest value in frequency order, so every peak (a 1 Hz wide mode on
    a 0.1 Hz grid) and every notch is drawn. Shorter records than
    ``2 * bins`` points are returned as they are.

    Parameters
    ----------
    x : numpy.ndarray, shape (n,)
        Increasing, positive abscissa (frequency, Hz).
    y : numpy.ndarray, shape (n,)
        Finite values.
    bins : int
        Number of bins (about the pixel width of a plot).
    """
    if x.size <= 2 * bins:
        return x, y
    edges = np.geomspace(x[0], x[-1], bins + 1)
    b = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, bins - 1)
    order = np.lexsort((y, b))  # by bin, then by value
    starts = np.flatnonzero(np.r_[True, np.diff(b[order]) != 0])
    ends = np.r_[starts[1:], order.size] - 1
    keep = np.unique(np.concatenate([order[starts], order[ends]]))  # frequency order
    return x[keep], y[keep]


def asd_line(f_hz: FloatArray, psd: FloatArray, *, scale: float, **kw: object) -> Line:
    """ASD ``√psd · scale`` without the 0 Hz bin (a log axis cannot show it), log-binned.

    PSD values below ``eps · max`` are the rounding residue of an exact zero
    (e.g. the discrete controller's zero at fs/2) and are drawn as zero: a gap
    on the log axis, instead of a point twenty decades down.
    """
    sel = f_hz > 0
    p = np.asarray(psd[sel], dtype=float)
    p = np.where(p > np.finfo(float).eps * np.max(p, initial=0.0), p, 0.0)
    x, y = log_envelope(f_hz[sel], np.sqrt(p) * scale)
    return Line(x, y, **kw)  # type: ignore[arg-type]


def cumulative_line(f_hz: FloatArray, psd: FloatArray, *, scale: float, **kw: object) -> Line:
    """Cumulative rms from 0 Hz (trapezoid, the ESRF study's ``cumtrapz``), 0 Hz left out."""
    cum = np.sqrt(cumulative_power(f_hz, np.maximum(psd, 0.0))) * scale
    sel = f_hz > 0
    x, y = log_envelope(f_hz[sel], cum[sel])
    return Line(x, y, **kw)  # type: ignore[arg-type]


def _records(h: HuddleAnalysis) -> list[HuddleRecord]:
    return [h.records[n] for n in sorted(h.records)]


def _source_color(j: int) -> str:
    # Blue and orange mean h and v in this report: sources take the rest of the palette.
    return PALETTE[2 + j % (len(PALETTE) - 2)]


def _test_color(rec: HuddleRecord) -> str:
    # Blue and orange mean h and v in this report: the tests take the rest of the palette.
    return PALETTE[2 + (rec.number - 1) % (len(PALETTE) - 2)]


def huddle_attocube_time_figure(h: HuddleAnalysis, recordings: Mapping[str, xr.Dataset], *,
                                stability: Mapping[int, StabilityRecord] | None = None
                                ) -> Figure:
    """ESRF study Fig. 29: Va of every test, one panel per test, raw and 50 Hz low pass.

    A record analysed out of core is drawn from its min/max envelope
    (``stability``), never sample by sample.
    """
    panels = []
    for rec in _records(h):
        title = (f"Test {rec.number}: {huddle_config_words(rec)} "
                 f"({rec.va_rms_m * NM:.3g} nm rms raw, "
                 f"{rec.va_lpf_rms_m * NM:.3g} nm low-passed)")
        stab = (stability or {}).get(rec.number)
        if stab is not None and stab.out_of_core:
            divisor, x_label = time_axis(stab.duration_s)
            raw, lpf = stab.drift["Va"], stab.drift["Va_lowpass"]
            panels.append(Panel(
                traces=(envelope_line(raw, scale=NM, offset=raw.overall_mean, divisor=divisor,
                                      name="Va, raw (min/max per bin)", color=_RAW_COLOR,
                                      group="raw"),
                        envelope_line(lpf, scale=NM, offset=0.0, divisor=divisor,
                                      name="Va, 50 Hz first-order low pass (min/max per bin)",
                                      color=_LPF_COLOR, group="lpf")),
                x_label=x_label, y_label="Va, mean removed [nm]", title=title, share_y="va"))
            continue
        sig = trim_huddle(recordings[rec.name], name=rec.name, duration_s=rec.duration_s)
        va = sig["Va"] - sig["Va"].mean()
        # The low pass comes from the budget stage (the report draws, it does not filter).
        vaf = rec.va_lowpass_m
        raw_line = Line(sig["t"], va * NM, name="Va, raw", color=_RAW_COLOR, width=1.0,
                        group="raw", decimate=True)
        lines = (raw_line,) if vaf is None else (
            raw_line, Line(sig["t"], vaf * NM, name="Va, 50 Hz first-order low pass",
                           color=_LPF_COLOR, width=1.2, group="lpf", decimate=True))
        panels.append(Panel(
            traces=lines,
            x_label="Time [s]", y_label="Va, mean removed [nm]", title=title, share_y="va"))
    return Figure(
        key="fig29_huddle_attocube_time", title="Attocube distance during the huddle tests",
        caption="Va after the ESRF study's trimming (t < 1 s dropped), mean "
                "removed: light, as recorded; dark, after the ESRF study's first-order low pass at "
                "50 Hz (lsim from rest). One panel per test of Table 3, all on one vertical "
                "scale so that the tests compare. Each record is drawn as a band, the "
                "smallest and largest sample in each bin of time; zooming in draws finer "
                "bins.",
        panels=tuple(panels), seed_ref="Fig. 29", share_x=True)


def huddle_qd_time_figure(h: HuddleAnalysis, recordings: Mapping[str, xr.Dataset], *,
                          stability: Mapping[int, StabilityRecord] | None = None) -> Figure:
    """ESRF study Fig. 30: Vph (left, blue) and Vpv (right, orange) of every test."""
    panels = []
    for rec in _records(h):
        stab = (stability or {}).get(rec.number)
        for v, color, rms in (("Vph", H_COLOR, rec.vph_rms_v), ("Vpv", V_COLOR, rec.vpv_rms_v)):
            axis = "horizontal" if v == "Vph" else "vertical"
            title = (f"Test {rec.number}: {huddle_config_words(rec)}: {v} "
                     f"({rms * MV:.3g} mV rms)")
            if stab is not None and stab.out_of_core:
                divisor, x_label = time_axis(stab.duration_s)
                d = stab.drift["Rh" if v == "Vph" else "Rv"]
                gain = stab.qd_gain_v_per_rad[0 if v == "Vph" else 1]
                panels.append(Panel(
                    traces=(envelope_line(d, scale=gain * MV, offset=d.overall_mean,
                                          divisor=divisor, name=f"{v} (4QD {axis}, min/max "
                                          "per bin)", color=color, group=v),),
                    x_label=x_label, y_label=f"{v}, mean removed [mV]", title=title,
                    share_y="qd"))
                continue
            sig = trim_huddle(recordings[rec.name], name=rec.name, duration_s=rec.duration_s)
            panels.append(Panel(
                traces=(Line(sig["t"], (sig[v] - sig[v].mean()) * MV,
                             name=f"{v} (4QD {axis})", color=color, width=1.0, group=v,
                             decimate=True),),
                x_label="Time [s]", y_label=f"{v}, mean removed [mV]", title=title,
                share_y="qd"))
    return Figure(
        key="fig30_huddle_qd_time", title="4QD signals during the huddle tests",
        caption="Vph (horizontal, left) and Vpv (vertical, right) after the ESRF study's trimming, "
                "mean removed, one row per test of Table 3, all on one vertical scale; each "
                "record drawn as the band of the smallest and largest sample in each bin of "
                "time (finer bins on zoom).",
        panels=tuple(panels), seed_ref="Fig. 30", columns=2, share_x=True)


def huddle_attocube_asd_figure(h: HuddleAnalysis) -> Figure:
    """ESRF study Fig. 31: ASD of Va, one panel per test, and the cumulative rms of all tests."""
    panels = []
    cum = []
    for rec in _records(h):
        kw = {"name": huddle_test_label(rec), "color": _test_color(rec), "group": rec.name,
              "width": 1.0}
        panels.append(Panel((asd_line(rec.f_hz, rec.psd_va_m2_per_hz, scale=NM, **kw),),
                            "Frequency [Hz]", "ASD of Va [nm/√Hz]", x_log=True, y_log=True,
                            title=f"Test {rec.number}: {huddle_config_words(rec)}",
                            share_y="asd"))
        cum.append(cumulative_line(rec.f_hz, rec.psd_va_m2_per_hz, scale=NM, **kw))
    panels.append(Panel(tuple(cum), "Frequency [Hz]", "Cumulative rms of Va [nm]", x_log=True,
                        title="Cumulative rms, every test"))
    return Figure(
        key="fig31_huddle_attocube_asd", title="Spectrum of the Attocube distance in the "
                                               "huddle tests",
        caption="Welch estimate with the ESRF study's 1 s Hann window (mean removed), one panel "
                "per "
                "test, all on one vertical scale so that the tests compare, and the cumulative "
                "rms from 0 Hz of every test (last panel); the end of each curve is the test's "
                "Va rms.",
        panels=tuple(panels), seed_ref="Fig. 31", columns=2, share_x=True)


def huddle_qd_asd_figure(h: HuddleAnalysis) -> Figure:
    """ESRF study Fig. 32: ASD of Vph (left) and Vpv (right) per test; cumulative rms of all."""
    recs = _records(h)
    signals = (("Vph", "psd_vph_v2_per_hz", "horizontal"), ("Vpv", "psd_vpv_v2_per_hz",
                                                             "vertical"))
    panels = []
    for rec in recs:
        for v, attr, axis in signals:
            panels.append(Panel(
                (asd_line(rec.f_hz, getattr(rec, attr), scale=UM, name=f"{v} (4QD {axis})",
                          color=H_COLOR if v == "Vph" else V_COLOR, group=v, width=1.0),),
                "Frequency [Hz]", f"ASD of {v} [µV/√Hz]", x_log=True, y_log=True,
                title=f"Test {rec.number}: {huddle_config_words(rec)}: {v}", share_y="asd"))
    for v, attr, _axis in signals:
        panels.append(Panel(
            tuple(cumulative_line(rec.f_hz, getattr(rec, attr), scale=MV,
                                  name=huddle_test_label(rec), color=_test_color(rec),
                                  group=rec.name, width=1.0) for rec in recs),
            "Frequency [Hz]", f"Cumulative rms of {v} [mV]", x_log=True,
            title=f"Cumulative rms of {v}, every test", share_y="cumulative"))
    closed = [r for r in recs if r.closed_loop]
    peak = ""
    if closed:
        r = closed[0]
        sel = r.f_hz > 100.0  # above the loop's bandwidth: the Sercalo modes
        i = int(np.argmax(np.where(sel, r.psd_vph_v2_per_hz, -np.inf)))
        peak = (f" In closed loop (test {r.number}) the 4QD sees the Sercalo mode driven by the "
                f"DAC's rounding: {np.sqrt(r.psd_vph_v2_per_hz[i]) * UM:.0f} µV/√Hz at "
                f"{r.f_hz[i]:.0f} Hz on Vph (errata E30).")
    return Figure(
        key="fig32_huddle_qd_asd", title="Spectrum of the 4QD signals in the huddle tests",
        caption="Welch estimate with the ESRF study's 1 s Hann window, Vph left and Vpv right, one "
                "row per test, every spectrum on one vertical scale so that open and closed "
                "loop compare; last row: the cumulative rms from 0 Hz of every test." + peak,
        panels=tuple(panels), seed_ref="Fig. 32", columns=2, share_x=True)


def path_error_figure(g: GeometryBudget) -> Figure:
    """ESRF study Fig. 34: distance error against the Sercalo angle error, trace and law."""
    th = esrf_theta_range()
    trace = trace_bench(th, h_m=g.h_m, l_m=g.l_m).path_error_m
    law = small_angle_law(h_m=g.h_m, l_m=g.l_m)
    seed_th = np.asarray(SEED_4_1["table4_theta_rad"], dtype=float)
    seed_err = np.asarray(SEED_4_1["table4_error_m"], dtype=float)
    panel = Panel(
        traces=(Line(th * UM, trace, name="exact ray trace, round-trip path", markers=True,
                     color=PALETTE[0]),
                Line(th * UM, law.path_error_m(th),
                     name=f"law k·δθc², k = 12H + 8L = {law.k_m_per_rad2:.3g} m/rad²",
                     color="#000000", width=1.0),
                Line(th * UM, 0.5 * trace, name="measured by the Attocube (half the round trip)",
                     color=PALETTE[2], dash="dash"),
                Line(seed_th * UM, seed_err, name="ESRF study Table 4 (1000× too large, errata "
                                                  "E15)",
                     markers=True, color=PALETTE[3])),
        x_label="Sercalo angle error δθc [µrad]", y_label="Distance error [m]",
        x_log=True, y_log=True)
    return Figure(
        key="fig34_angle_error_distance",
        title="Distance error against the Sercalo angle error",
        caption=f"Ray trace O → S → Y → M → T for H = {g.h_m * 1e3:g} mm, L = {g.l_m * 1e3:g} mm "
                f"over the ESRF study's range. Fitted k = {g.fit.k_fit_m_per_rad2:.6g} m/rad² "
                "against "
                f"the derived 12H + 8L = {law.k_m_per_rad2:.6g} m/rad² (log-log slope "
                f"{g.fit.loglog_slope:.4f}).",
        panels=(panel,), seed_ref="Fig. 34")


def beam_path_figure(g: GeometryBudget) -> Figure:
    """ESRF study Fig. 35: the traced beam path at a large angle error."""
    d = g.figure
    mm = 1e3
    traces = [Line(d.nominal_beam[:, 0] * mm, d.nominal_beam[:, 1] * mm,
                   name="nominal beam (δθc = 0)", color="#000000", dash="dot"),
              Line(d.beam[:, 0] * mm, d.beam[:, 1] * mm,
                   name=f"beam with δθc = {np.degrees(d.theta_rad):g}°", color=PALETTE[3])]
    for seg, lab, color in ((d.sercalo_mirror, "Sercalo mirror", H_COLOR),
                            (d.newport_mirror, "Newport mirror", V_COLOR),
                            (d.attocube_plane, "Attocube reference plane", PALETTE[2])):
        traces.append(Line(seg[:, 0] * mm, seg[:, 1] * mm, name=lab, color=color, width=3.0))
    labels = tuple(Label(float(p[0] * mm), float(p[1] * mm), name)
                   for name, p in zip(d.labels, d.beam, strict=True))
    return Figure(
        key="fig35_beam_path", title="Beam path at a large Sercalo angle error",
        caption=f"Exact trace O → S → Y → M → T at δθc = {np.degrees(d.theta_rad):g}° (large, "
                "so that the deviation is visible), against the nominal path O → S → X → S → O.",
        panels=(Panel(tuple(traces), "x [mm]", "y [mm]", labels=labels, equal_aspect=True),),
        seed_ref="Fig. 35", height_px=520)


def angle_asd_figure(b: ErrorBudget) -> Figure:
    """Beam-angle ASD and cumulative rms per source, h (left) and v (right)."""
    panels = []
    names = list(b.sources)
    for kind in ("asd", "cum"):
        for i, axis in enumerate(("horizontal", "vertical")):
            lines = []
            for j, (name, s) in enumerate(b.sources.items()):
                psd = np.real(s.angle_psd[:, i, i])
                kw = {"name": name, "color": _source_color(j), "group": name,
                      "width": 1.0}
                lines.append(asd_line(s.f_hz, psd, scale=UM, **kw) if kind == "asd"
                             else cumulative_line(s.f_hz, psd, scale=UM, **kw))
            if kind == "cum":
                f_all = next(iter(b.sources.values())).f_hz
                lines.append(cumulative_line(f_all, np.real(b.angle_psd_all[:, i, i]), scale=UM,
                                             name="all sources together, cumulative rms [µrad]",
                                             color="#000000", dash="dash", width=2.0,
                                             group="total"))
            ax = "Rh" if i == 0 else "Rv"
            if kind == "asd":
                panels.append(Panel(tuple(lines), "Frequency [Hz]",
                                    f"Beam-angle ASD, {axis} [µrad/√Hz]", x_log=True,
                                    y_log=True, height=2.0,
                                    title=f"Beam angle {ax} ({axis})", share_y="asd"))
            else:
                panels.append(Panel(tuple(lines), "Frequency [Hz]",
                                    f"Cumulative rms, {axis} [µrad]", x_log=True,
                                    share_y="cumulative"))
    return Figure(
        key="budget_beam_angle_per_source", title="Beam-angle error per noise source",
        caption=f"Each of the {len(names)} sources of 4.5 through the plant and the loop "
                f"({b.configuration}; U = −K R) to the beam angle at the 4QD, horizontal left, "
                "vertical right; cumulative rms from 0 Hz below (stationary, no record "
                "length), with all sources together (dashed black): it ends at the root sum of "
                "squares of the sources' rms. The fall of the 4QD sources (ADC, electronic "
                "noise) towards 5 kHz is the discrete controller's zero at half the sampling "
                "frequency.",
        panels=tuple(panels), seed_ref="4.5", columns=2, share_x=True)


def distance_cumulative_m(b: ErrorBudget) -> dict[str, tuple[FloatArray, FloatArray]]:
    """Cumulative rms of the distance error per angle source and for all together [m].

    Piston plus geometric spectra, weighted by the record's mean removal
    (``1 − sinc²(f T)``) and summed with the budget's rectangle rule, so each
    curve ends at the source's row of the table (and "all angle sources
    together" at the RSS of those rows and the cross terms).
    """
    out = {}
    first = next(iter(b.sources.values()))
    f = first.f_hz
    w = window_weight(f, window_s=b.window_s)
    df = float(f[1] - f[0])
    for name, s in b.sources.items():
        psd = s.perpendicular_psd_m2_per_hz + s.quadratic.psd_m2_per_hz
        out[name] = (f, np.sqrt(np.cumsum(psd * w) * df))
    total = sum(s.perpendicular_psd_m2_per_hz for s in b.sources.values())
    total = total + b.geometric_all.psd_m2_per_hz
    out["all angle sources together"] = (f, np.sqrt(np.cumsum(total * w) * df))
    return out


def distance_cumulative_figure(b: ErrorBudget) -> Figure:
    """Cumulative rms of the distance error per angle source (piston + geometric)."""
    lines = []
    for j, (name, (f, cum)) in enumerate(distance_cumulative_m(b).items()):
        together = name == "all angle sources together"
        x, y = log_envelope(f, cum * NM)
        lines.append(Line(x, y, name=name, width=2.0 if together else 1.2,
                          color="#000000" if together else _source_color(j),
                          dash="dash" if together else "solid", group=name))
    window = "" if b.window_s is None else f" over a {b.window_s:g} s record, mean removed"
    return Figure(
        key="budget_distance_per_source", title="Distance error per noise source",
        caption="Cumulative rms of the Attocube distance error from 0 Hz" + window + ": piston "
                "(4.2, linear in the mirror angles) plus geometric term (4.1, quadratic: the "
                "autoconvolution of the beam-angle spectra). Each curve ends at its row of "
                "the budget table; the dashed curve includes the cross terms between "
                "sources.",
        panels=(Panel(tuple(lines), "Frequency [Hz]", "Cumulative rms of the distance error [nm]",
                      x_log=True),),
        seed_ref="4.5")
