"""Figures of ESRF study section 11 (non-repeatability) as data.

ESRF study Figs. 48 and 51 (Va over every period, without and with the 10 Hz low
pass) cannot be told apart at their scale (µm per period against nm of
filtering): one figure, with Fig. 49 (the non-repeatable part) below. Fig. 52
(the non-repeatable part after the low pass) separates the filter's
start-up transient (first period) from the settled periods (errata E32).
Periods are drawn as their range (smallest and largest value at each
instant, a filled band), which stays readable for any number of periods;
time plots draw each signal's min/max envelope over the record as a band (a
few thousand bins whatever its length). Panels of one quantity share their
vertical axis. Both come folded or binned from the analysis
(:class:`~fsmbench.budget.repeatability.RepeatabilityRecord`), so a night-long
record is drawn without reading it again.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from fsmbench.budget.repeatability import RepeatabilityRecord
from fsmbench.budget.result import NonRepeatability
from fsmbench.report.figures.budget import asd_line, cumulative_line
from fsmbench.report.figures.spec import (
    H_COLOR,
    PALETTE,
    V_COLOR,
    Figure,
    Line,
    Panel,
    Rule,
)
from fsmbench.report.figures.stability import time_axis
from fsmbench.signal.envelope import Envelope

__all__ = [
    "direction_words",
    "nonrep_contributions_figure",
    "nonrep_part_figure",
    "periods_figure",
    "repeatability_time_figure",
    "tracking_asd_figure",
    "tracking_distance_figure",
    "tracking_vs_distance_figure",
]

NM = 1e9
UM = 1e6
MV = 1e3
_PERIOD_COLOR = "#9e9e9e"
_TRANSIENT_COLOR = "#d62728"


def direction_words(r: RepeatabilityRecord) -> str:
    """``"Newport moving horizontally (data_rep_h)"``."""
    way = "horizontally" if r.direction == "h" else "vertically"
    return f"Newport moving {way} ({r.name})"


def _axis_color(direction: str) -> str:
    return H_COLOR if direction == "h" else V_COLOR


def _envelope_line(env: Envelope, *, divisor: float, scale: float, name: str, color: str,
                   group: str = "") -> Line:
    """A min/max envelope as a band: each bin's minimum and maximum over the bin."""
    return Line(env.t_s / divisor, env.minimum * scale, upper=env.maximum * scale, name=name,
                color=color, group=group)


def _aligned_axis(reps: Mapping[str, RepeatabilityRecord]) -> tuple[float, str]:
    """Divisor and label of the time after the alignment (s, min or h by the longest)."""
    divisor, label = time_axis(max(r.n_periods * r.period_s for r in reps.values()))
    return divisor, label.replace("Time", "Time after alignment")


def repeatability_time_figure(reps: Mapping[str, RepeatabilityRecord]) -> Figure:
    """ESRF study Fig. 44: command, Vph, Vpv and Va after the alignment; one column per record."""
    recs = list(reps.values())
    rows: list[list[Panel]] = [[], [], [], []]
    div, x_label = _aligned_axis(reps)
    for r in recs:
        env = r.envelopes
        title = direction_words(r)
        rows[0].append(Panel(
            (_envelope_line(env["command"], divisor=div, scale=1.0,
                            name=f"Newport command {r.channel}", color=_axis_color(r.direction)),),
            x_label, f"Newport command {r.channel} [V]", title=title, share_y="command"))
        for k, (v, color) in enumerate((("Vph", H_COLOR), ("Vpv", V_COLOR))):
            rows[1 + k].append(Panel(
                (_envelope_line(env[v], divisor=div, scale=MV, color=color, group=v,
                                name=f"{v} (4QD {'horizontal' if v == 'Vph' else 'vertical'})"),),
                x_label, f"{v} [mV]", share_y="qd"))
        rows[3].append(Panel(
            (_envelope_line(env["Va"], divisor=div, scale=NM, name="Va, mean removed",
                            color="#333333", group="Va"),),
            x_label, "Va, mean removed [nm]", share_y="va"))
    return Figure(
        key="fig44_repeatability_time", title="Signals of the repeatability measurement",
        caption="From one second after the first Newport command, whole 1 s periods only "
                "(ESRF study 11.1): the Newport command, the 4QD (horizontal and vertical in "
                "separate "
                "rows) and the Attocube distance; one column per record, each row on one "
                "vertical scale. Each band is the smallest and largest value in each of a few "
                "thousand consecutive intervals.",
        panels=tuple(p for row in rows for p in row), seed_ref="Fig. 44", columns=len(recs),
        share_x=True)


def tracking_distance_figure(reps: Mapping[str, RepeatabilityRecord]) -> Figure:
    """ESRF study Fig. 45: the tracking error's distance equivalent over time (traced law)."""
    panels = []
    div, x_label = _aligned_axis(reps)
    for r in reps.values():
        seed_std = float(np.hypot(*r.seed_law_distance_std_m))
        panels.append(Panel(
            (_envelope_line(r.envelopes["tracking_distance"], divisor=div, scale=NM,
                            name="tracking error as distance, traced law (6H + 4L)/16·α²",
                            color=PALETTE[2], group="traced"),),
            x_label, "Distance equivalent [nm]", share_y="distance",
            title=f"{direction_words(r)}: beam angle {r.tracking_rms_rad[0] * UM:.3g} µrad rms "
                  f"(h), {r.tracking_rms_rad[1] * UM:.3g} µrad rms (v); distance "
                  f"{r.tracking_distance_std_m * NM:.3g} nm std (ESRF study's law "
                  f"{seed_std * NM:.3g} nm)"))
    return Figure(
        key="fig45_tracking_error_distance", title="Tracking error as a distance",
        caption="The beam angle measured by the 4QD, α = Vp/Gd(0) (ESRF study 11.3; the 4QD "
                "signals "
                "themselves are in Fig. 44), turned into the distance the Attocube would read "
                "with the traced law. The ESRF study's L·α²/2 per axis (L = 0.1 m) has nearly the "
                "same shape, about 0.05/0.031 times larger; its standard deviation is in each "
                "title. Vp "
                "includes the 4QD's own noise, so this is an upper bound (errata E33).",
        panels=tuple(panels), seed_ref="Fig. 45", share_x=True)


def tracking_asd_figure(reps: Mapping[str, RepeatabilityRecord]) -> Figure:
    """ESRF study Fig. 46: ASD and cumulative rms of Rh (left) and Rv (right), per record."""
    panels = []
    for kind in ("asd", "cum"):
        for i, (ax, axis) in enumerate((("Rh", "horizontal"), ("Rv", "vertical"))):
            color = H_COLOR if i == 0 else V_COLOR
            lines = []
            for r in reps.values():
                kw = {"name": f"{ax}, {direction_words(r)}", "color": color,
                      "dash": "solid" if r.direction == "h" else "dash", "width": 1.0}
                psd = r.psd_tracking_rad2_per_hz[:, i]
                lines.append(asd_line(r.f_hz, psd, scale=UM, **kw) if kind == "asd"
                             else cumulative_line(r.f_hz, psd, scale=UM, **kw))
            if kind == "asd":
                panels.append(Panel(tuple(lines), "Frequency [Hz]",
                                    f"ASD of the tracking error {ax} [µrad/√Hz]", x_log=True,
                                    y_log=True, height=2.0, title=f"{ax} ({axis})",
                                    share_y="asd"))
            else:
                panels.append(Panel(tuple(lines), "Frequency [Hz]",
                                    f"Cumulative rms of {ax} [µrad]", x_log=True,
                                    share_y="cumulative"))
    return Figure(
        key="fig46_tracking_error_asd", title="Spectrum of the tracking errors",
        caption="Welch estimate of α = Vp/Gd(0) with the ESRF study's 1 s Hann window and its "
                "cumulative rms; horizontal left, vertical right; solid: Newport moving "
                "horizontally, dashed: vertically.",
        panels=tuple(panels), seed_ref="Fig. 46", columns=2, share_x=True)


def tracking_vs_distance_figure(reps: Mapping[str, RepeatabilityRecord]) -> Figure:
    """ESRF study Fig. 47: ASD of Va against that of the tracking error's distance equivalent."""
    panels = []
    for r in reps.values():
        panels.append(Panel(
            (asd_line(r.f_hz, r.psd_va_m2_per_hz, scale=NM, name="Va, measured",
                      color="#333333", group="va", width=1.0),
             asd_line(r.f_hz, r.psd_distance_m2_per_hz, scale=NM,
                      name="tracking error as distance, traced law (6H + 4L)/16·α²",
                      color=PALETTE[2], group="traced", width=1.0),
             asd_line(r.f_hz, r.psd_distance_seed_m2_per_hz.sum(axis=1), scale=NM,
                      name="tracking error as distance, ESRF study's L·α²/2 (both axes)",
                      color=PALETTE[7], group="seed", width=1.0, dash="dash")),
            "Frequency [Hz]", "ASD [nm/√Hz]", x_log=True, y_log=True,
            title=direction_words(r), share_y="asd"))
    return Figure(
        key="fig47_tracking_vs_distance_asd",
        title="Tracking error as distance against the measured distance",
        caption="Welch estimates (1 s Hann window). The two laws (the ESRF study's and the traced "
                "one, errata E17) are in terms of the 4QD's beam angle, noise included: an "
                "upper bound of the geometric term.",
        panels=tuple(panels), seed_ref="Fig. 47", columns=len(panels))


def _range_lines(tp: np.ndarray, lo: np.ndarray, hi: np.ndarray, *,
                 name: str) -> tuple[Line]:
    """Minimum and maximum over periods at each instant: a grey band."""
    return (Line(tp, lo * NM, upper=hi * NM, name=name, color=_PERIOD_COLOR, group="range",
                 decimate=True),)


def _rms_rules(rms: float | None) -> tuple[Rule, ...]:
    if rms is None:
        return ()
    return (Rule(rms * NM, name=f"+rms {rms * NM:.3g} nm", color="#000000", dash="dash"),
            Rule(-rms * NM, name="−rms", color="#000000", dash="dash"))


def periods_figure(reps: Mapping[str, RepeatabilityRecord]) -> Figure:
    """ESRF study Figs. 48, 49 (and 51): Va over the period, repeatable and non-repeatable parts.

    Top: the range of Va over the periods at each instant and its mean (the
    repeatable part); bottom: the range of the non-repeatable part (Va less
    that mean) with its rms.
    """
    recs = list(reps.values())
    top, bottom = [], []
    for r in recs:
        tp = np.arange(r.period_samples) / r.fs_hz
        off = r.repeatable_m.mean()  # the record's mean (whole periods)
        top.append(Panel(
            (*_range_lines(tp, r.va_min_m, r.va_max_m, name="range over the periods"),
             Line(tp, (r.repeatable_m - off) * NM, name="mean over periods (repeatable part)",
                  color="#000000", width=1.2, dash="dash", group="mean")),
            "Time in the period [s]", "Va, record mean removed [nm]", share_y="va",
            title=f"{direction_words(r)}: {r.n_periods} periods, repeatable part "
                  f"{r.repeatable_ptp_m * NM:.4g} nm peak to peak"))
        bottom.append(Panel(
            _range_lines(tp, r.va_nonrep_min_m, r.va_nonrep_max_m,
                         name="range over the periods"),
            "Time in the period [s]", "Non-repeatable Va [nm]", share_y="nonrep",
            rules=_rms_rules(r.nonrep_rms_m),
            title=f"Non-repeatable part: {r.nonrep_rms_m * NM:.3g} nm rms"))
    return Figure(
        key="fig48_49_repeatability_periods",
        title="Repeatable and non-repeatable parts of the measured distance",
        caption="Va cut into the Newport's 1 s periods (ESRF study 11.4). Top (ESRF study Fig. "
                "48): the "
                "smallest and largest value over the periods at each instant (a grey band, "
                "thin at this scale) and their mean, the repeatable part. "
                "Bottom (ESRF study Fig. 49): Va less that mean, the non-repeatable part, with its "
                "rms. The ESRF study's Fig. 51 (the top after the 10 Hz low pass) is not repeated: "
                "it cannot be told apart; the low pass's effect is in the next figure.",
        panels=(*top, *bottom), seed_ref="Figs. 48, 49, 51", columns=len(recs), share_x=True)


def nonrep_part_figure(reps: Mapping[str, RepeatabilityRecord]) -> Figure:
    """ESRF study Fig. 52: the non-repeatable part after the 10 Hz low pass, transient apart.

    Top: the settled periods (2 … n, less their own mean, as
    ``nonrep_rms_lpf_settled_m``); bottom: the first period (the ``lsim``
    start-up transient) less the mean over all periods, as the ESRF study computes.
    """
    recs = list(reps.values())
    top, bottom = [], []
    for r in recs:
        tp = np.arange(r.period_samples) / r.fs_hz
        rms = r.nonrep_rms_lpf_settled_m
        top.append(Panel(
            _range_lines(tp, r.va_lpf_settled_nonrep_min_m, r.va_lpf_settled_nonrep_max_m,
                         name="range over the periods"),
            "Time in the period [s]", "Non-repeatable Va [nm]", rules=_rms_rules(rms),
            share_y="nonrep",
            title=f"{direction_words(r)}: periods 2 to {r.n_periods} (settled)"
                  + ("" if rms is None else f", {rms * NM:.3g} nm rms")))
        bottom.append(Panel(
            (Line(tp, r.va_lpf_first_nonrep_m * NM,
                  name="first period (the filter's start-up transient)",
                  color=_TRANSIENT_COLOR, width=1.2, group="transient"),),
            "Time in the period [s]", "First period [nm]", share_y="first",
            title=f"First period; all periods as the ESRF study: {r.nonrep_rms_lpf_m * NM:.3g} nm "
                  "rms"))
    return Figure(
        key="fig52_lowpass_nonrepeatable",
        title="Non-repeatable part after the 10 Hz low pass",
        caption="Va after the ESRF study's 10 Hz first-order low pass (lsim from rest), less the "
                "mean "
                "over periods. Top: periods 2 to n less their own mean (range over the periods "
                "and rms): the steady state. Bottom: the first period less the mean over all "
                "periods: the filter starts from rest on a Va that is not mean-removed, and "
                "its start-up transient lands there and raises the ESRF study's value above the "
                "settled one.",
        panels=(*top, *bottom), seed_ref="Fig. 52", columns=len(recs), share_x=True)


def nonrep_contributions_figure(reps: Mapping[str, RepeatabilityRecord],
                                nonrep: Mapping[str, NonRepeatability], *,
                                huddle_configs: Mapping[str, str] | None = None) -> Figure:
    """ESRF study Fig. 50: non-repeatable Va and the tracking error's share; the huddle-test noise.

    One panel per record (Va's non-repeatable part, and on top the tracking
    error's), then one panel with Va of the huddle test the study compares
    with (``nonrep[d].huddle_window``: the budget stage read it over the longest
    record's length).
    ``huddle_configs`` maps that test's name to its configuration in words.
    """
    panels = []
    div, x_label = _aligned_axis(reps)
    for r in reps.values():
        panels.append(Panel(
            (_envelope_line(r.envelopes["Va_nonrep"], divisor=div, scale=NM,
                            name="Va, non-repeatable part", color="#333333", group="va"),
             _envelope_line(r.envelopes["tracking_distance_nonrep"], divisor=div, scale=NM,
                            name="tracking error as distance, non-repeatable part",
                            color=PALETTE[2], group="tracking")),
            x_label, "Distance [nm]", share_y="distance",
            title=f"{direction_words(r)}: Va {r.nonrep_rms_m * NM:.3g} nm rms, tracking error "
                  f"{r.tracking_distance_nonrep_rms_m * NM:.3g} nm rms"))
    windows = {nr.huddle_window.name: nr.huddle_window for nr in nonrep.values()
               if nr.huddle_window is not None}
    caption = ("The non-repeatable part of Va and, on top, the non-repeatable part of the "
               "tracking error's distance equivalent (traced law), one panel per record")
    for name, win in sorted(windows.items()):
        # The budget stage read it over the longest record's length (it may be out of core).
        number = name.rsplit("_", 1)[-1]
        config = (huddle_configs or {}).get(name, "")
        what = f" ({config})" if config else ""
        panels.append(Panel(
            (_envelope_line(win.envelope, divisor=div, scale=NM, color=PALETTE[0],
                            group="huddle", name=f"Va in huddle test {number} (nothing moves)"),),
            x_label.replace("Time after alignment", "Time"), "Distance [nm]", share_y="distance",
            title=f"Huddle test {number}{what}, nothing moves: "
                  f"{win.va_rms_m * NM:.3g} nm rms over {win.duration_s:g} s"))
        caption += f"; last panel: Va in huddle test {number}{what} over the same length"
    return Figure(
        key="fig50_nonrepeatable_contributions", title="Where the non-repeatability comes from",
        caption=caption + ".", panels=tuple(panels), seed_ref="Fig. 50", share_x=True)
