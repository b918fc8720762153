"""A panel's part of the plotly.js layout: its two axes, and the rules, shade and labels on them.

Internal to :mod:`fsmbench.report.figures.interactive`, which builds the
figure JSON (the panel grid, the traces, the panel titles) and takes each
panel's axes and marks from here.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from fsmbench.report.figures.spec import Line, Panel, Rule, wrap_words

__all__: list[str] = []  # internal to fsmbench.report.figures.interactive

_DASH = {"solid": "solid", "dash": "dash", "dot": "dot", "dashdot": "dashdot"}
# The width of a character of 12 px plain text on average [px] (measured in Chromium:
# 6–7 px): axis titles longer than their axis are wrapped.
_CHAR_PX = 7.0


@dataclass(frozen=True)
class _PanelAxes:
    """The layout entries of a panel's x and y axes."""

    x: dict[str, Any]
    y: dict[str, Any]


@dataclass(frozen=True)
class _PanelMarks:
    """What a panel draws besides its traces, in drawing order: shapes and annotations."""

    shapes: list[dict[str, Any]]
    annotations: list[dict[str, Any]]


def _margin_of(panel: Panel, axis: str) -> list[float]:
    """5 % of the data's span beyond each end (what the static renderer's margins give):
    plotly.js pads no line-only axis, and the outermost lines would sit on the frame."""
    values = [t.x if axis == "x" else t.y for t in panel.traces if isinstance(t, Line)]
    values += [np.array([lab.x if axis == "x" else lab.y]) for lab in panel.labels]
    v = np.concatenate(values) if values else np.zeros(0)
    v = v[np.isfinite(v)]
    if not v.size:
        return []
    lo, hi = float(v.min()), float(v.max())
    pad = 0.05 * (hi - lo)
    return [lo - pad, hi + pad]


def _coord(value: float, *, log: bool) -> float:
    """A data coordinate as plotly.js wants it for an annotation (decades on a log axis)."""
    return float(np.log10(value)) if log and value > 0 else float(value)


def _axis(label: str, *, log: bool, fixed: tuple[float, float] | None,
          domain: tuple[float, float], anchor: str, show_title: bool,
          length_px: float | None = None) -> dict[str, Any]:
    """An axis; a title longer than ``length_px`` (the axis's length) is wrapped."""
    text = label if show_title else ""
    if text and length_px is not None:
        text = "<br>".join(wrap_words(text, int(length_px / _CHAR_PX)))
    axis: dict[str, Any] = {
        "domain": list(domain), "anchor": anchor, "type": "log" if log else "linear",
        "showline": True, "mirror": True, "linecolor": "#888", "gridcolor": "#e4e4e4",
        "zeroline": False, "exponentformat": "power" if log else "SI",
        "title": {"text": text, "font": {"size": 12}},
    }
    if fixed is not None:
        lo, hi = fixed
        axis["range"] = [float(np.log10(lo)), float(np.log10(hi))] if log else [lo, hi]
        axis["autorange"] = False
    else:
        axis["autorange"] = True
    return axis


def _panel_axes(panel: Panel, *, refs: tuple[str, str], x_domain: tuple[float, float],
                y_domain: tuple[float, float], area_px: float, show_x_title: bool,
                x_matches: str | None, y_matches: str | None) -> _PanelAxes:
    """The x and y axes of a panel.

    Parameters
    ----------
    panel : Panel
        The panel.
    refs : tuple of str
        Its trace axis references (``"x3"``, ``"y3"``).
    x_domain, y_domain : tuple of float
        Where the panel sits, as fractions of the plotting area.
    area_px : float
        Height of the plotting area [px] (the y axis title wraps to the panel's height).
    show_x_title : bool
        Whether the panel shows its x tick labels and title.
    x_matches, y_matches : str or None
        The axis reference this panel's x or y axis zooms with, if any.
    """
    xaxis = _axis(panel.x_label, log=panel.x_log, fixed=panel.x_range, domain=x_domain,
                  anchor=refs[1], show_title=show_x_title)
    if x_matches is not None:
        xaxis["matches"] = x_matches
    if not show_x_title:
        xaxis["showticklabels"] = False
    yaxis = _axis(panel.y_label, log=panel.y_log, fixed=panel.y_range, domain=y_domain,
                  anchor=refs[0], show_title=True,
                  length_px=(y_domain[1] - y_domain[0]) * area_px)
    if y_matches is not None:
        yaxis["matches"] = y_matches
    if panel.equal_aspect:
        # The box shrinks to the data's aspect, so no axis is padded with empty range.
        yaxis["scaleanchor"] = refs[0]
        yaxis["scaleratio"] = 1
        xaxis["constrain"] = yaxis["constrain"] = "domain"
        for axis, name in ((xaxis, "x"), (yaxis, "y")):
            if axis["autorange"]:
                axis["autorangeoptions"] = {"include": _margin_of(panel, name)}
    return _PanelAxes(x=xaxis, y=yaxis)


def _rule_marks(rule: Rule, panel: Panel, refs: tuple[str, str]
                ) -> tuple[dict[str, Any], dict[str, Any] | None]:
    """A rule's line across the panel, and its name's annotation (None: no name)."""
    horizontal = rule.axis == "y"
    # On a log axis plotly.js (v3+) takes shapes in data units but annotations in
    # decades (checked in Chromium: tests/report/test_browser.py).
    at = rule.value
    at_text = _coord(rule.value, log=panel.y_log if horizontal else panel.x_log)
    line: dict[str, Any] = {
        "type": "line", "layer": "below",
        "xref": f"{refs[0]} domain" if horizontal else refs[0],
        "yref": refs[1] if horizontal else f"{refs[1]} domain",
        "x0": 0 if horizontal else at, "x1": 1 if horizontal else at,
        "y0": at if horizontal else 0, "y1": at if horizontal else 1,
        "line": {"color": rule.color, "width": 1, "dash": _DASH[rule.dash]}}
    if not rule.name:
        return line, None
    return line, {
        "text": rule.name, "showarrow": False, "font": {"size": 10, "color": rule.color},
        "xref": f"{refs[0]} domain" if horizontal else refs[0],
        "yref": refs[1] if horizontal else f"{refs[1]} domain",
        "x": 1 if horizontal else at_text, "xanchor": "right",
        "y": at_text if horizontal else 1, "yanchor": "bottom"}


def _panel_marks(panel: Panel, *, refs: tuple[str, str]) -> _PanelMarks:
    """A panel's rules, shade and labels (its title is the figure's: the grid places it)."""
    shapes: list[dict[str, Any]] = []
    annotations: list[dict[str, Any]] = []
    for rule in panel.rules:
        line, name = _rule_marks(rule, panel, refs)
        shapes.append(line)
        if name is not None:
            annotations.append(name)
    if panel.shade is not None:
        shapes.append({
            "type": "rect", "layer": "below", "xref": refs[0], "yref": f"{refs[1]} domain",
            "x0": panel.shade[0], "x1": panel.shade[1], "y0": 0, "y1": 1,
            "fillcolor": "#dddddd", "opacity": 0.6, "line": {"width": 0}})
    for lab in panel.labels:
        annotations.append({
            "text": lab.text, "x": _coord(lab.x, log=panel.x_log),
            "y": _coord(lab.y, log=panel.y_log), "xref": refs[0], "yref": refs[1],
            "showarrow": False, "xanchor": "left", "yanchor": "bottom",
            "font": {"size": 10}})
    return _PanelMarks(shapes=shapes, annotations=annotations)
