"""Figures of the long-term view of the huddle tests: Allan deviation, drift, envelopes.

The time plots of a long record draw the per-bin minimum and maximum (the
envelope :mod:`fsmbench.budget.stability` computed out of core) as a filled
band, never the samples: a day at 10 kHz is 864 million of them.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from numpy.typing import NDArray

from fsmbench.budget.stability import SignalDrift, StabilityRecord
from fsmbench.report.figures.spec import H_COLOR, PALETTE, V_COLOR, Figure, Line, Panel

__all__ = [
    "allan_figure",
    "drift_figure",
    "envelope_line",
    "time_axis",
]

FloatArray = NDArray[np.float64]
NM = 1e9
URAD = 1e6


def time_axis(duration_s: float) -> tuple[float, str]:
    """Divisor and label of a time axis in s, min or h, by the record's length."""
    if duration_s >= 3 * 3600:
        return 3600.0, "Time [h]"
    if duration_s >= 3 * 60:
        return 60.0, "Time [min]"
    return 1.0, "Time [s]"


def envelope_line(d: SignalDrift, *, scale: float, offset: float, divisor: float, name: str,
                  color: str, group: str = "") -> Line:
    """The min/max envelope as a band: each bin's minimum and maximum over the bin."""
    return Line(d.t_s / divisor, (d.minimum - offset) * scale,
                upper=(d.maximum - offset) * scale, name=name, color=color, group=group)


def allan_figure(stability: Mapping[int, StabilityRecord]) -> Figure:
    """Allan deviation of Va and of the 4QD beam angle, every huddle test."""
    va_lines, qd_lines = [], []
    for i, n in enumerate(sorted(stability)):
        s = stability[n]
        color = PALETTE[i % len(PALETTE)]
        a = s.allan["Va"]
        va_lines.append(Line(a.tau_s, a.adev * NM, name=f"test {n}", color=color,
                             group=f"test{n}"))
        for key in ("Rh", "Rv"):
            r = s.allan[key]
            qd_lines.append(Line(r.tau_s, r.adev * URAD, name=f"test {n}, "
                                 f"{'horizontal' if key == 'Rh' else 'vertical'}",
                                 color=color, dash="solid" if key == "Rh" else "dot",
                                 group=f"test{n}"))
    longest = max(s.duration_s for s in stability.values())
    unit = time_axis(longest)[1].split("[")[1].rstrip("]")
    return Figure(
        key="huddle_allan", title="Allan deviation of the distance and of the beam angle",
        caption=("Overlapping Allan deviation (IEEE Std 1139) over the whole of each huddle "
                 "test after the ESRF study's trim, the longest "
                 f"{longest / time_axis(longest)[0]:.3g} {unit}. A slope of −1 is a bounded "
                 "quantity (one the loop holds, like the beam angle in closed loop), −1/2 "
                 "white noise, 0 flicker, +1/2 random walk, +1 drift; the table below names each "
                 "region. Top: the Attocube distance Va; bottom: the beam angle the 4QD "
                 "reads (Vph, Vpv over their calibrated gains)."),
        panels=(Panel(traces=tuple(va_lines), x_label="Averaging time τ [s]",
                      y_label="Allan deviation [nm]", x_log=True, y_log=True,
                      title="Attocube distance Va"),
                Panel(traces=tuple(qd_lines), x_label="Averaging time τ [s]",
                      y_label="Allan deviation [µrad]", x_log=True,
                      y_log=True, title="4QD beam angle (solid horizontal, dotted vertical)")),
        share_x=True, height_px=760)


def drift_figure(stability: Mapping[int, StabilityRecord]) -> Figure:
    """The bin means of Va and of the 4QD beam angle over each whole record."""
    longest = max(s.duration_s for s in stability.values())
    divisor, x_label = time_axis(longest)
    va, qd = [], []
    for i, n in enumerate(sorted(stability)):
        s = stability[n]
        color = PALETTE[i % len(PALETTE)]
        d = s.drift["Va"]
        t, mean = d.means()
        va.append(Line(t / divisor, (mean - d.overall_mean) * NM, name=f"test {n}",
                       color=color, group=f"test{n}"))
        for key, col in (("Rh", H_COLOR), ("Rv", V_COLOR)):
            r = s.drift[key]
            t, mean = r.means()
            qd.append(Line(t / divisor, (mean - r.overall_mean) * URAD,
                           name=f"test {n}, {'horizontal' if key == 'Rh' else 'vertical'}",
                           color=color if len(stability) > 1 else col,
                           dash="solid" if key == "Rh" else "dot", group=f"test{n}"))
    t_longest, _ = max((s.drift["Va"].means() for s in stability.values()),
                       key=lambda tm: tm[0].size)
    bin_s = longest / max(1, t_longest.size)
    return Figure(
        key="huddle_drift", title="Drift of the distance and of the 4QD offset",
        caption=(f"Means over consecutive bins of at least 1 s ({t_longest.size} bins of "
                 f"{bin_s:.3g} s for the longest record), from the record's mean: how the "
                 "distance and the beam angle the 4QD reads wander over the record. The "
                 "ESRF study's 100 s records show seconds of this; long records show the hours."),
        panels=(Panel(traces=tuple(va), x_label=x_label,
                      y_label="Va, from its mean [nm]", title="Attocube distance"),
                Panel(traces=tuple(qd), x_label=x_label, y_label="Beam angle, from its mean "
                      "[µrad]", title="4QD beam angle (offset drift; solid horizontal, dotted "
                      "vertical)")),
        share_x=True, height_px=700)
