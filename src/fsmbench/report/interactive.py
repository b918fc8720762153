"""A :class:`~fsmbench.report.figure.Figure` as a plotly.js figure (``data`` + ``layout``).

Only the JavaScript library of the ``plotly`` package is used (embedded once
in the page, :func:`plotly_js`); the figure JSON is built here directly from
the spec, with arrays as plotly.js typed arrays (base64), which is compact
and fast to parse. Panels become subplots on a grid of axis domains;
``share_x`` makes the panels of a column zoom together.
"""

from __future__ import annotations

import base64
import importlib.resources
from collections.abc import Iterator
from functools import cache
from typing import Any

import numpy as np

from fsmbench.report.figure import PALETTE, Bars, Figure, Line, Panel, envelope

__all__ = ["figure_json", "plotly_js", "typed_array"]

_DASH = {"solid": "solid", "dash": "dash", "dot": "dot", "dashdot": "dashdot"}
# Gaps between panels, as fractions of the figure.
_H_GAP = 0.08
_V_GAP_PX = 62
# Plotting width of a one-column figure in the report's page (1180 px less margins).
_PAGE_PX = 1050


@cache
def plotly_js() -> str:
    """The plotly.js bundle shipped in the ``plotly`` package (read once)."""
    path = importlib.resources.files("plotly") / "package_data" / "plotly.min.js"
    return path.read_text(encoding="utf-8")


def typed_array(values: np.ndarray) -> dict[str, str]:
    """plotly.js typed-array JSON of ``values``: float32 unless that loses the data.

    float32 keeps 7 significant digits; a series whose spread is below 1e-4
    of its magnitude (an offset plus a small signal) keeps float64.
    """
    v = np.asarray(values, dtype=float)
    finite = v[np.isfinite(v)]
    wide = finite.size > 0 and np.ptp(finite) < 1e-4 * np.max(np.abs(finite))
    dtype = "f8" if wide or (finite.size and np.max(np.abs(finite)) > 3e38) else "f4"
    data = v.astype("<f8" if dtype == "f8" else "<f4")
    return {"dtype": dtype, "bdata": base64.b64encode(data.tobytes()).decode("ascii")}


def _axis_ids(i: int) -> tuple[str, str]:
    """(trace axis refs 'x3','y3'; layout keys use 'xaxis3')."""
    return ("x", "y") if i == 0 else (f"x{i + 1}", f"y{i + 1}")


def _layout_key(ref: str) -> str:
    return ref[0] + "axis" + ref[1:]


def _domains(fig: Figure, height_px: int) -> Iterator[tuple[int, tuple[float, float],
                                                            tuple[float, float]]]:
    """(panel index, x domain, y domain) for every panel."""
    rows = [fig.panels[r * fig.columns:(r + 1) * fig.columns] for r in range(fig.n_rows)]
    heights = np.array([max(p.height for p in row) for row in rows], dtype=float)
    gap = min(0.25, _V_GAP_PX / height_px)
    usable = 1.0 - gap * (len(rows) - 1)
    fractions = usable * heights / heights.sum()
    col_w = (1.0 - _H_GAP * (fig.columns - 1)) / fig.columns
    top = 1.0
    for r, row in enumerate(rows):
        bottom = max(0.0, top - fractions[r])
        for c in range(len(row)):
            x0 = c * (col_w + _H_GAP)
            yield r * fig.columns + c, (x0, min(1.0, x0 + col_w)), (bottom, top)
        top = bottom - gap


def _coord(value: float, *, log: bool) -> float:
    """A data coordinate as plotly.js wants it for an annotation (decades on a log axis)."""
    return float(np.log10(value)) if log and value > 0 else float(value)


def _hover(panel: Panel) -> str:
    return (f"%{{fullData.name}}<br>{panel.x_label}: %{{x:.5g}}<br>"
            f"{panel.y_label}: %{{y:.4g}}<extra></extra>")


class _Arrays:
    """The figure's arrays, each stored once: traces on one frequency grid share it."""

    def __init__(self) -> None:
        self.table: list[dict[str, str]] = []
        self._index: dict[str, int] = {}

    def ref(self, values: np.ndarray) -> dict[str, int]:
        encoded = typed_array(values)
        key = encoded["dtype"] + encoded["bdata"]
        if key not in self._index:
            self._index[key] = len(self.table)
            self.table.append(encoded)
        return {"ref": self._index[key]}


def _line_trace(line: Line, panel: Panel, refs: tuple[str, str], color: str,
                show: bool, arrays: _Arrays, width_px: int) -> dict[str, Any]:
    # A long record is drawn as its min/max per pixel column: every extreme, no more.
    x, y = (envelope(line.x, line.y, columns=width_px) if line.decimate else (line.x, line.y))
    if panel.y_log:  # a log axis cannot show values ≤ 0: leave a gap, not a clipped point
        y = np.where(y > 0, y, np.nan)
    if panel.x_log:
        x = np.where(x > 0, x, np.nan)
    trace: dict[str, Any] = {
        "type": "scatter", "x": arrays.ref(x), "y": arrays.ref(y),
        "xaxis": refs[0], "yaxis": refs[1], "name": line.name or " ",
        "mode": "markers" if line.markers else "lines",
        "hovertemplate": _hover(panel), "showlegend": show and line.legend and bool(line.name),
        "opacity": line.opacity,
    }
    if line.markers:
        trace["marker"] = {"color": color, "size": 6}
    else:
        trace["line"] = {"color": color, "width": line.width, "dash": _DASH[line.dash]}
    if line.group:
        trace["legendgroup"] = line.group
    return trace


def _bars_trace(bars: Bars, refs: tuple[str, str], color: str, show: bool,
                arrays: _Arrays) -> dict[str, Any]:
    trace: dict[str, Any] = {
        "type": "bar", "x": list(bars.categories), "y": arrays.ref(bars.values),
        "xaxis": refs[0], "yaxis": refs[1], "name": bars.name or " ",
        "marker": {"color": color}, "showlegend": show and bars.legend and bool(bars.name),
    }
    if bars.group:
        trace["legendgroup"] = bars.group
    return trace


def _axis(label: str, *, log: bool, fixed: tuple[float, float] | None,
          domain: tuple[float, float], anchor: str, show_title: bool) -> dict[str, Any]:
    axis: dict[str, Any] = {
        "domain": list(domain), "anchor": anchor, "type": "log" if log else "linear",
        "showline": True, "mirror": True, "linecolor": "#888", "gridcolor": "#e4e4e4",
        "zeroline": False, "exponentformat": "power" if log else "SI",
        "title": {"text": label if show_title else "", "font": {"size": 12}},
    }
    if fixed is not None:
        lo, hi = fixed
        axis["range"] = [float(np.log10(lo)), float(np.log10(hi))] if log else [lo, hi]
        axis["autorange"] = False
    else:
        axis["autorange"] = True
    return axis


def figure_json(fig: Figure) -> dict[str, Any]:
    """The plotly.js figure: ``{"data": [...], "layout": {...}, "arrays": [...]}``.

    Every array is stored once in ``arrays`` (typed-array JSON) and traces
    refer to it as ``{"ref": i}``; the page swaps the references in before
    plotting (traces on one frequency grid share it: a third of a Bode
    figure's size).
    """
    height = fig.default_height_px()
    data: list[dict[str, Any]] = []
    layout: dict[str, Any] = {
        "height": height, "margin": {"l": 70, "r": 20, "t": 40, "b": 95},
        "hovermode": "closest", "font": {"size": 12},
        # Below the bottom axis title, whatever the figure's height.
        "legend": {"orientation": "h", "y": -52 / (height - 135), "yanchor": "top", "x": 0,
                   "font": {"size": 11}},
        "paper_bgcolor": "white", "plot_bgcolor": "white",
        "annotations": [], "shapes": [], "barmode": "group",
    }
    if len(fig.panels) > 1 or fig.panels[0].title:
        layout["margin"]["t"] = 50
    arrays = _Arrays()
    shown: set[str] = set()
    color_of: dict[str, str] = {}
    n_rows = fig.n_rows
    for i, (xd, yd) in ((i, (xd, yd)) for i, xd, yd in _domains(fig, height)):
        panel = fig.panels[i]
        refs = _axis_ids(i)
        row, col = divmod(i, fig.columns)
        last_in_column = row == n_rows - 1 or i + fig.columns >= len(fig.panels)
        xaxis = _axis(panel.x_label, log=panel.x_log, fixed=panel.x_range, domain=xd,
                      anchor=refs[1], show_title=last_in_column or not fig.share_x)
        if fig.share_x and row > 0:
            xaxis["matches"] = _axis_ids(col)[0]
        if fig.share_x and not last_in_column:
            xaxis["showticklabels"] = False
        yaxis = _axis(panel.y_label, log=panel.y_log, fixed=panel.y_range, domain=yd,
                      anchor=refs[0], show_title=True)
        if panel.equal_aspect:
            yaxis["scaleanchor"] = refs[0]
            yaxis["scaleratio"] = 1
        layout[_layout_key(refs[0])] = xaxis
        layout[_layout_key(refs[1])] = yaxis
        for trace in panel.traces:
            key = trace.group or trace.name
            if trace.color is not None:
                color = trace.color
            else:
                color = color_of.setdefault(key, PALETTE[len(color_of) % len(PALETTE)])
            show = key not in shown
            shown.add(key)
            data.append(_line_trace(trace, panel, refs, color, show, arrays,
                                    max(200, round(_PAGE_PX * (xd[1] - xd[0]))))
                        if isinstance(trace, Line)
                        else _bars_trace(trace, refs, color, show, arrays))
        for rule in panel.rules:
            horizontal = rule.axis == "y"
            # On a log axis plotly.js (v3+) takes shapes in data units but annotations in
            # decades (checked in Chromium: tests/report/test_browser.py).
            at = rule.value
            at_text = _coord(rule.value, log=panel.y_log if horizontal else panel.x_log)
            layout["shapes"].append({
                "type": "line", "layer": "below",
                "xref": f"{refs[0]} domain" if horizontal else refs[0],
                "yref": refs[1] if horizontal else f"{refs[1]} domain",
                "x0": 0 if horizontal else at, "x1": 1 if horizontal else at,
                "y0": at if horizontal else 0, "y1": at if horizontal else 1,
                "line": {"color": rule.color, "width": 1, "dash": _DASH[rule.dash]}})
            if rule.name:
                layout["annotations"].append({
                    "text": rule.name, "showarrow": False, "font": {"size": 10,
                                                                     "color": rule.color},
                    "xref": f"{refs[0]} domain" if horizontal else refs[0],
                    "yref": refs[1] if horizontal else f"{refs[1]} domain",
                    "x": 1 if horizontal else at_text, "xanchor": "right",
                    "y": at_text if horizontal else 1, "yanchor": "bottom"})
        if panel.shade is not None:
            layout["shapes"].append({
                "type": "rect", "layer": "below", "xref": refs[0], "yref": f"{refs[1]} domain",
                "x0": panel.shade[0], "x1": panel.shade[1], "y0": 0, "y1": 1,
                "fillcolor": "#dddddd", "opacity": 0.6, "line": {"width": 0}})
        for lab in panel.labels:
            layout["annotations"].append({
                "text": lab.text, "x": _coord(lab.x, log=panel.x_log),
                "y": _coord(lab.y, log=panel.y_log), "xref": refs[0], "yref": refs[1],
                "showarrow": False, "xanchor": "left", "yanchor": "bottom",
                "font": {"size": 10}})
        if panel.title:
            layout["annotations"].append({
                "text": f"<b>{panel.title}</b>", "showarrow": False, "x": (xd[0] + xd[1]) / 2,
                "xref": "paper", "y": yd[1], "yref": "paper", "yanchor": "bottom",
                "xanchor": "center", "font": {"size": 12}})
    return {"data": data, "layout": layout, "arrays": arrays.table}
