"""Report: the model checked on the recorded closed loop (subsection of chapter 11).

Every number and curve comes from :class:`~fsmbench.control.validation.ClosedLoopValidation`;
nothing is computed here.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from fsmbench.report.figures.budget import asd_line
from fsmbench.report.figures.spec import H_COLOR, PALETTE, V_COLOR, Figure, Panel
from fsmbench.report.html import Block, Section, Table

__all__ = ["validation_figure", "validation_subsection"]

UM = 1e6
_AXES = (("h", "Rh", "horizontal", H_COLOR), ("v", "Rv", "vertical", V_COLOR))


def validation_figure(v: Any) -> Figure:
    """Recorded and predicted ASD of the tracking error, with the predicted sources, per axis."""
    panels = []
    for i, (axis, name, words, color) in enumerate(_AXES):
        # One legend entry per colour: the recorded curve is named by its axis.
        lines = [asd_line(v.f_hz, v.measured_psd[:, i], scale=UM,
                          name=f"recorded ASD of {name} ({words}) [µrad/√Hz]",
                          color=color, group=f"recorded {axis}", width=1.5),
                 asd_line(v.f_hz, v.predicted_psd[:, i], scale=UM,
                          name="predicted (simulated on the bench model)", color="#333333",
                          group="predicted", dash="dash", width=1.2)]
        for j, (key, part) in enumerate(v.predicted.parts.items()):
            if np.max(part[:, i], initial=0.0) <= 0.0:
                continue
            lines.append(asd_line(v.predicted.f_hz, part[:, i], scale=UM,
                                  name=f"linear share: {v.predicted.words[key]}",
                                  color=PALETTE[(j + 2) % len(PALETTE)], group=key, width=0.8,
                                  dash="dot"))
        panels.append(Panel(tuple(lines), "Frequency [Hz]",
                            f"ASD of the tracking error {name} [µrad/√Hz]", x_log=True,
                            y_log=True, title=f"{name} ({words}), ratio {v.ratio[axis]:.2f}"))
    return Figure(
        key="validation_tracking_error_asd",
        title="The model against the recorded closed loop",
        caption=(f"Tracking error α = Vp/Gd of {', '.join(v.experiments)} with the periodic "
                 f"motion removed ({v.n_periods} periods), recorded and predicted on "
                 f"{v.bench} with {v.controller}; dotted: each source's share from the linear "
                 f"model. The rms is compared from {v.band_hz[0]:g} Hz to {v.band_hz[1]:g} Hz."),
        panels=tuple(panels), columns=2)


def validation_subsection(v: Any | None, *, skipped: str) -> Section:
    """The model validation, or why it did not run."""
    title = "The model against the recorded closed loop"
    if v is None:
        return Section(title=title, anchor="validation", blocks=(
            "The bench model's predictions are checked against a closed loop it did not see: "
            "the repeatability records, taken with the ESRF study's controller. Not done here: "
            f"{skipped}.",))
    rows = tuple((words, f"{v.measured_rms_rad[a] * UM:.3g}", f"{v.predicted_rms_rad[a] * UM:.3g}",
                  f"{v.ratio[a]:.2f}")
                 for a, _n, words, _c in _AXES)
    verdict = ("within" if v.passed else "outside")
    blocks: list[Block] = [
        (f"The bench model's predictions are checked against a closed loop it did not see: "
         f"{', '.join(v.experiments)}, recorded with {v.controller} while the Newport repeated "
         f"its 1 Hz motion. With the motion that repeats every period removed, what the 4QD "
         f"reads is the loop's response to every noise of the bench. The same experiments "
         f"were simulated on {v.bench} with the same controller, dividing by the 4QD gains "
         f"the recorded loop used ({v.gd_used_v_per_rad[0]:g} / {v.gd_used_v_per_rad[1]:g} "
         f"V/rad), and analysed identically. The recorded rms is "
         + " and ".join(f"{v.ratio[a]:.2f}" for a, *_ in _AXES)
         + f" times the predicted one (h and v), {verdict} the accepted "
           f"{v.limits[0]:g}–{v.limits[1]:g}"
         + (" widened by the records' own scatter (each rms is an estimate from "
            f"{v.n_periods} periods): "
            + ", ".join(f"{a} {lo_:.2f}–{hi_:.2f}" for a, (lo_, hi_) in v.accepted.items())
            if v.accepted else "")
         + "."
         + (f" {v.reason}." if v.reason else "")),
        Table(caption=f"Tracking-error rms, {v.band_hz[0]:g}–{v.band_hz[1]:g} Hz",
              header=("axis", "recorded [µrad]", "predicted [µrad]", "recorded / predicted"),
              rows=rows),
        validation_figure(v),
    ]
    return Section(title=title, anchor="validation", blocks=tuple(blocks))
