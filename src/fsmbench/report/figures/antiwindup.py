"""The twin's saturating step without and with anti-windup, as a figure.

Draws :class:`fsmbench.control.antiwindup_loop.SaturatingStep`; nothing here computes.
One column per axis; top: the beam angle over the step's height, bottom: the
command the DAC applied, with its rails.
"""

from __future__ import annotations

from collections.abc import Sequence

from fsmbench.control.antiwindup_loop import SaturatingStep
from fsmbench.report.figures.spec import Dash, Figure, Line, Panel, Rule

__all__ = ["saturating_step_figure"]

MS = 1e3
_RUNS: tuple[tuple[str, str, str, Dash], ...] = (
    ("without", "without anti-windup", "#d62728", "solid"),
    ("with", "with anti-windup (back-calculation)", "#1f77b4", "solid"),
    ("linear", "ideal DAC (no rails)", "#7f7f7f", "dot"))
_WORDS = {"h": "horizontal (h)", "v": "vertical (v)"}


_EVERY = 2  # samples drawn: every other one

def saturating_step_figure(steps: Sequence[SaturatingStep], *, key: str, title: str,
                           caption: str) -> Figure:
    """Beam angle and DAC command through a step beyond the DAC's reach, per axis.

    Parameters
    ----------
    steps : sequence of SaturatingStep
        One per axis, drawn left to right.
    key, title, caption : str
        As for :class:`~fsmbench.report.figures.spec.Figure`.
    """
    if not steps:
        raise ValueError("no steps to draw")
    top: list[Panel] = []
    bottom: list[Panel] = []
    for j, st in enumerate(steps):
        sig = "R" + st.axis
        # Every other sample (5 kHz: 12 points a period of the 411 Hz ripple), as plain lines:
        # a band with its zoom pyramid cost the page 379 kB for 0.3 s of records.
        t = st.t_s[::_EVERY] * MS
        beam = tuple(Line(t, st.beam_rad[k][::_EVERY] / st.step_rad, name=words, color=c,
                          dash=d, group=k, legend=j == 0)
                     for k, words, c, d in _RUNS)
        command = tuple(Line(t, st.command_v[k][::_EVERY], name=words, color=c, dash=d,
                             group=k, legend=False)
                        for k, words, c, d in _RUNS if k != "linear")
        # Unnamed: a label at the top would sit on the panel's title; the caption says it.
        back = Rule(st.hold_s * MS, axis="x", dash="dash", color="#888888")
        top.append(Panel(beam, "Time [ms]", f"{sig} / step height [1]",
                         title=f"Beam angle, {_WORDS[st.axis]}, step {1e3 * st.step_rad:.3g} mrad",
                         share_y="beam",
                         rules=(back, Rule(0.0, color="#888888", dash="dot"),
                                Rule(1.0, color="#888888", dash="dot"))))
        bottom.append(Panel(command, "Time [ms]", f"Uc{st.axis} applied [V]",
                            title=f"DAC command, {_WORDS[st.axis]}", share_y="command",
                            rules=(back,
                                   Rule(st.dac_limit_v, color="#000000", dash="dash",
                                        name=f"DAC rails ±{st.dac_limit_v:.3g} V"),
                                   Rule(-st.dac_limit_v, color="#000000", dash="dash"))))
    return Figure(key=key, title=title, caption=caption, panels=(*top, *bottom),
                  columns=len(steps), height_px=720)
