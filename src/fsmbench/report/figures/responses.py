"""The closed-loop step and disturbance responses as a figure.

Draws :class:`fsmbench.control.responses.ClosedLoopResponses`; nothing here
computes a response. One column per axis; rows: the reference step in time,
the Newport (sample-motion) step in time, then both in frequency, in dB.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from fsmbench.control.responses import ClosedLoopResponses
from fsmbench.report.figures.spec import Figure, Line, Panel, Rule

__all__ = ["step_response_figure"]

_AXES = (("h", "Rh", "horizontal (h)"), ("v", "Rv", "vertical (v)"))
UM = 1e6
MS = 1e3


def _db(x: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore"):
        return np.asarray(20.0 * np.log10(np.abs(x)), dtype=float)


def step_response_figure(responses: Sequence[tuple[ClosedLoopResponses, str]], *, key: str,
                         title: str, caption: str) -> Figure:
    """Reference and disturbance steps, time and frequency, of each controller.

    Parameters
    ----------
    responses : sequence of (ClosedLoopResponses, str)
        Each controller's responses and its colour; the legend names each by
        ``ClosedLoopResponses.name``.
    key, title, caption : str
        As for :class:`~fsmbench.report.figures.spec.Figure`.
    """
    if not responses:
        raise ValueError("no responses to draw")
    first = responses[0][0]
    rows: list[list[Panel]] = [[], [], [], []]
    for i, (_axis, sig, words) in enumerate(_AXES):
        ref, dist, t_freq, d_freq = [], [], [], []
        for r, color in responses:
            ref.append(Line(r.t_s * MS, r.reference_step[:, i], name=f"with {r.name}",
                            color=color, group=r.name))
            dist.append(Line(r.t_s * MS, r.disturbance_step_rad_per_v[:, i] * UM,
                             name=f"with {r.name}", color=color, group=r.name, legend=False))
            t_freq.append(Line(r.f_hz, _db(r.complementary[:, i]), name=f"with {r.name}",
                               color=color, group=r.name, legend=False))
            d_freq.append(Line(r.f_hz, _db(r.disturbance_rad_per_v[:, i]),
                               name=f"with {r.name}", color=color, group=r.name,
                               legend=False))
        dist.append(Line(first.t_s * MS, first.open_disturbance_step_rad_per_v[:, i] * UM,
                         name="Sercalo loop open", color="#000000", dash="dot",
                         group="open loop", legend=i == 0))
        rows[0].append(Panel(tuple(ref), "Time after the step [ms]",
                             f"{sig} per unit step [1]",
                             title=f"Reference step, {words}", share_y="reference",
                             rules=(Rule(float(first.reference_final[i]), dash="dash",
                                         color="#888888",
                                         name=f"final value T(0) = "
                                              f"{first.reference_final[i]:.3g}"),)))
        rows[1].append(Panel(tuple(dist), "Time after the step [ms]",
                             f"{sig} per Newport volt [µrad/V]",
                             title=f"Sample-motion step (Newport Un{sig[-1]}), {words}",
                             share_y="disturbance",
                             rules=(Rule(0.0, dash="dash", color="#888888"),)))
        rows[2].append(Panel(tuple(t_freq), "Frequency [Hz]",
                             f"|T{sig[-1]}| [dB]", x_log=True,
                             title=f"Reference to beam angle, {words}", share_y="T",
                             rules=(Rule(0.0, dash="dot", color="#888888"),)))
        rows[3].append(Panel(tuple(d_freq), "Frequency [Hz]",
                             f"|{sig} / Un{sig[-1]}| [dB re 1 rad/V]", x_log=True,
                             title=f"Sample motion to beam angle, {words}",
                             share_y="disturbance dB"))
    panels = tuple(p for row in rows for p in row)
    return Figure(key=key, title=title, caption=caption, panels=panels, columns=2,
                  height_px=980)
