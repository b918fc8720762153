"""A :class:`~fsmbench.report.figures.spec.Figure` as a plotly.js figure (``data`` + ``layout``).

Only the JavaScript library of the ``plotly`` package is used (embedded once
in the page, :func:`plotly_js`); the figure JSON is built here directly from
the spec, with arrays as plotly.js typed arrays (base64), which is compact
and fast to parse. Panels become subplots on a grid of axis domains, with
room between rows for what sits there (tick labels, axis title, the next
panel's title); ``share_x`` makes the panels of a column zoom together and
``Panel.share_y`` the panels of one key. Every trace is in a legend group
(its group, else its name), so one legend entry toggles it in every panel.

Long records and bands are drawn as filled bands (each bin's minimum and
maximum, as steps over the bin). For a decimated record the figure JSON
also holds ``pyramids``: finer levels of bins, quantised to 16 bits
(minimum rounded down, maximum up, so the band still holds every sample),
which the page's script (:data:`ZOOM_JS`) swaps in when the view narrows.
"""

from __future__ import annotations

import base64
import importlib.resources
import math
from collections.abc import Iterator, Sequence
from functools import cache
from typing import Any

import numpy as np

from fsmbench.report.figures.interactive_layout import _DASH, _panel_axes, _panel_marks
from fsmbench.report.figures.spec import (
    PALETTE,
    Bars,
    Figure,
    Line,
    Panel,
    minmax_bins,
    pyramid_samples_per_bin,
    wrap_words,
)

__all__ = ["ZOOM_JS", "figure_json", "plotly_js", "typed_array"]

# Gap between panel columns, as a fraction of the figure's width.
_H_GAP = 0.08
# Room between panel rows [px]: always, for the tick labels of the upper panel, for its
# x-axis title, and for the lower panel's title (12 px text with plotly's offsets).
_GAP_BASE_PX = 14
_GAP_TICKS_PX = 24
_GAP_X_TITLE_PX = 26
_GAP_TITLE_PX = 24
_MARGIN = {"l": 70, "r": 20, "t": 40, "b": 95}
_MARGIN_TOP_TITLES = 50
# A line of 12 px text [px], and the width of its bold characters on average (measured in
# Chromium: 7–7.5 px): titles longer than their panel are wrapped.
_LINE_PX = 16
_BOLD_CHAR_PX = 7.5
# Plotting width of a one-column figure in the report's page (1180 px less margins).
_PAGE_PX = 1050
# 16-bit levels of a pyramid: 0 … 65534 are values, 65535 marks a bin without a sample.
_U2_GAP = 65535


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


def _plot_height(fig: Figure, height_px: int) -> float:
    """Height of the area the panels share [px]: the figure less its top and bottom margins."""
    return float(height_px - _margin_top(fig) - _MARGIN["b"])


def _margin_top(fig: Figure) -> int:
    if not (len(fig.panels) > 1 or fig.panels[0].title):
        return _MARGIN["t"]
    first = _title_lines(fig)[:fig.columns]
    return _MARGIN_TOP_TITLES + _LINE_PX * (max(first) - 1)


def _column_px(fig: Figure) -> float:
    """Width of one panel column in the page [px]."""
    return _PAGE_PX * (1.0 - _H_GAP * (fig.columns - 1)) / fig.columns


def _title_lines(fig: Figure) -> list[int]:
    """Lines of each panel's title once wrapped to its column (0: no title)."""
    chars = int(_column_px(fig) / _BOLD_CHAR_PX)
    return [len(wrap_words(p.title, chars)) if p.title else 0 for p in fig.panels]


def _shows_x_title(fig: Figure, i: int) -> bool:
    """Whether panel ``i`` shows its x tick labels and title (shared x: the column's last)."""
    return not fig.share_x or i + fig.columns >= len(fig.panels)


def _row_gaps_px(fig: Figure) -> list[float]:
    """Room below each row but the last [px]: what the row shows under its panels and the
    title of the row below."""
    rows = [range(r * fig.columns, min(len(fig.panels), (r + 1) * fig.columns))
            for r in range(fig.n_rows)]
    lines = _title_lines(fig)
    gaps: list[float] = []
    for r in range(len(rows) - 1):
        below = any(_shows_x_title(fig, i) for i in rows[r])
        titled = max(lines[i] for i in rows[r + 1])
        gaps.append(_GAP_BASE_PX + (_GAP_TICKS_PX + _GAP_X_TITLE_PX) * below
                    + (_GAP_TITLE_PX + _LINE_PX * (titled - 1)) * (titled > 0))
    return gaps


def _domains(fig: Figure, height_px: int) -> Iterator[tuple[int, tuple[float, float],
                                                            tuple[float, float]]]:
    """(panel index, x domain, y domain) for every panel."""
    rows = [fig.panels[r * fig.columns:(r + 1) * fig.columns] for r in range(fig.n_rows)]
    heights = np.array([max(p.height for p in row) for row in rows], dtype=float)
    area = _plot_height(fig, height_px)
    gaps = [min(0.3, g / area) for g in _row_gaps_px(fig)]
    usable = max(0.2, 1.0 - sum(gaps))
    fractions = usable * heights / heights.sum()
    col_w = (1.0 - _H_GAP * (fig.columns - 1)) / fig.columns
    top = 1.0
    for r, row in enumerate(rows):
        bottom = max(0.0, top - fractions[r])
        for c in range(len(row)):
            x0 = c * (col_w + _H_GAP)
            yield r * fig.columns + c, (x0, min(1.0, x0 + col_w)), (bottom, top)
        if r < len(gaps):
            top = bottom - gaps[r]


def _hover(panel: Panel) -> str:
    return (f"%{{fullData.name}}<br>{panel.x_label}: %{{x:.5g}}<br>"
            f"{panel.y_label}: %{{y:.4g}}<extra></extra>")


def _band_hover(panel: Panel, *, half_width: float, y_format: str, samples: int | None) -> str:
    """Hover of a band point: the bin's time span and the value at its edge, no more."""
    what = (f"least or greatest of the {samples} samples in this bin" if samples
            else "least or greatest value in this bin")
    return (f"%{{fullData.name}}<br>{panel.x_label}: %{{x:.7g}} ± {half_width:.3g}<br>"
            f"{panel.y_label}: %{{y:{y_format}}} ({what})<extra></extra>")


class _Arrays:
    """The figure's arrays, each stored once: traces on one frequency grid share it."""

    def __init__(self) -> None:
        self.table: list[dict[str, str]] = []
        self._index: dict[str, int] = {}

    def ref(self, values: np.ndarray) -> dict[str, int]:
        return self._ref(typed_array(values))

    def ref_u2(self, codes: np.ndarray) -> dict[str, int]:
        """A 16-bit code array (a pyramid level), stored as plotly's ``u2`` typed array."""
        data = np.asarray(codes, dtype="<u2")
        return self._ref({"dtype": "u2", "bdata": base64.b64encode(data.tobytes()).decode()})

    def _ref(self, encoded: dict[str, str]) -> dict[str, int]:
        key = encoded["dtype"] + encoded["bdata"]
        if key not in self._index:
            self._index[key] = len(self.table)
            self.table.append(encoded)
        return {"ref": self._index[key]}


def _rgba(color: str, alpha: float) -> str:
    """A CSS ``#rgb``/``#rrggbb`` colour with an alpha; other colours as they are."""
    h = color.lstrip("#")
    if color.startswith("#") and len(h) in (3, 6):
        h = "".join(c * 2 for c in h) if len(h) == 3 else h
        r, g, b = (int(h[k:k + 2], 16) for k in (0, 2, 4))
        return f"rgba({r},{g},{b},{alpha:.3g})"
    return color


def _polygon(x: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A band as closed outlines: each run of finite bins forward on ``hi``, back on ``lo``,
    runs apart by a NaN (plotly.js fills each outline on its own)."""
    ok = np.isfinite(lo) & np.isfinite(hi) & np.isfinite(x)
    edges = np.flatnonzero(np.diff(np.r_[0, ok.astype(np.int8), 0]))
    xs: list[np.ndarray] = []
    ys: list[np.ndarray] = []
    for a, b in zip(edges[0::2], edges[1::2], strict=True):
        if xs:
            xs.append(np.array([np.nan]))
            ys.append(np.array([np.nan]))
        xs.append(np.r_[x[a:b], x[a:b][::-1]])
        ys.append(np.r_[hi[a:b], lo[a:b][::-1]])
    if not xs:
        return np.array([np.nan]), np.array([np.nan])
    return np.concatenate(xs), np.concatenate(ys)


def _uniform_step(x: np.ndarray) -> float | None:
    """The step of an evenly spaced ``x`` (within a thousandth of a step), else None."""
    if x.size < 2:
        return None
    step = (x[-1] - x[0]) / (x.size - 1)
    if not (np.isfinite(step) and step > 0):
        return None
    return float(step) if np.max(np.abs(np.diff(x) - step)) <= 1e-3 * step else None


def _quantise(lo: np.ndarray, hi: np.ndarray, offset: float, scale: float
              ) -> tuple[np.ndarray, np.ndarray]:
    """16-bit codes of a level: minimum rounded down, maximum up (the band only widens)."""
    with np.errstate(invalid="ignore"):
        qlo = np.floor((lo - offset) / scale)
        qhi = np.ceil((hi - offset) / scale)
    out = []
    for q in (qlo, qhi):
        out.append(np.where(np.isfinite(q), np.clip(q, 0, _U2_GAP - 1), _U2_GAP).astype("<u2"))
    return out[0], out[1]


def _decimals(scale: float, values: np.ndarray) -> str:
    """Hover format of a quantised band: fixed decimals down to its 16-bit step."""
    finite = values[np.isfinite(values)]
    top = float(np.max(np.abs(finite))) if finite.size else 1.0
    if not (scale > 0 and top > 0):
        return ".4g"
    d = max(0, min(12, math.ceil(-math.log10(scale))))
    return f".{d}f" if top * 10.0 ** d < 1e9 else ".4g"


def _band_trace(*, x: np.ndarray, lo: np.ndarray, hi: np.ndarray, decimate: bool,
                panel: Panel, refs: tuple[str, str], color: str, name: str, width: float,
                fill_alpha: float, show: bool, group: str, arrays: _Arrays, width_px: int,
                index: int, pyramids: list[dict[str, Any]]) -> dict[str, Any]:
    """A band (min/max per bin) as one filled plotly trace, with its pyramid if decimated.

    A decimated band of more than two points per pixel column is binned to
    the column width (level 0, drawn); its finer levels go to ``pyramids``.
    """
    n = x.size
    # The page's zoom script reads a linear axis (time): no pyramid on a log axis.
    step = _uniform_step(x) if decimate and not panel.x_log else None
    y_all = np.r_[lo, hi]
    finite = y_all[np.isfinite(y_all)]
    offset = float(finite.min()) if finite.size else 0.0
    span = float(finite.max()) - offset if finite.size else 0.0
    scale = span / (_U2_GAP - 1) if span > 0 else 1.0
    fmt = _decimals(scale, finite) if decimate else ".4g"
    if decimate and n > 2 * width_px:
        levels = pyramid_samples_per_bin(n, width_px)
        first, blo, bhi = minmax_bins(lo, hi, levels[0])
        last = np.r_[first[1:], n] - 1
        centres = 0.5 * (x[first] + x[last])
        hover = _band_hover(panel, half_width=0.5 * levels[0] * float(np.median(np.diff(x))),
                            y_format=fmt, samples=levels[0])
        if step is not None:
            pyramids.append(_pyramid(x0=float(x[0]), step=step, lo=lo, hi=hi, levels=levels,
                                     offset=offset, scale=scale, panel=panel, fmt=fmt,
                                     trace=index, xaxis=refs[0], width=width, arrays=arrays))
    else:
        centres, blo, bhi = x, lo, hi
        steps = np.diff(x)
        hover = _band_hover(panel, half_width=0.5 * float(np.median(steps)) if steps.size
                            else 0.0, y_format=".4g", samples=None)
    px, py = _polygon(centres, blo, bhi)
    return {
        "type": "scatter", "x": arrays.ref(px), "y": arrays.ref(py), "xaxis": refs[0],
        "yaxis": refs[1], "name": name or " ", "mode": "lines", "fill": "toself",
        "fillcolor": _rgba(color, fill_alpha), "hoveron": "points",
        "line": {"color": color, "width": 0.6, "shape": "hvh"},
        "hovertemplate": hover, "showlegend": show, "legendgroup": group,
    }


def _pyramid(*, x0: float, step: float, lo: np.ndarray, hi: np.ndarray, levels: Sequence[int],
             offset: float, scale: float, panel: Panel, fmt: str, trace: int, xaxis: str,
             width: float, arrays: _Arrays) -> dict[str, Any]:
    """The finer levels of a band for the page's zoom script (level 0 included, for a reset).

    Each level: samples per bin, 16-bit codes of each bin's minimum and
    maximum (or, at one sample per bin, the samples themselves as float32)
    and the hover text of its points.
    """
    out = []
    for per in levels:
        _, blo, bhi = minmax_bins(lo, hi, per)
        if per == 1 and np.array_equal(blo, bhi, equal_nan=True):
            ref = arrays.ref(blo)
            out.append({"per": 1, "lo": ref, "hi": ref, "hover": _hover(panel)})
            continue
        qlo, qhi = _quantise(blo, bhi, offset, scale)
        out.append({"per": per, "lo": arrays.ref_u2(qlo), "hi": arrays.ref_u2(qhi),
                    "hover": _band_hover(panel, half_width=0.5 * per * step, y_format=fmt,
                                         samples=per)})
    return {"trace": trace, "xaxis": _layout_key(xaxis), "x0": x0, "dx": step, "n": lo.size,
            "offset": offset, "scale": scale, "width": width, "levels": out}


def _line_trace(line: Line, panel: Panel, refs: tuple[str, str], color: str, show: bool,
                arrays: _Arrays, width_px: int, index: int,
                pyramids: list[dict[str, Any]]) -> dict[str, Any]:
    group = line.group or line.name
    if line.upper is not None or (line.decimate and line.x.size > 2 * width_px):
        # A band, or a long record as each bin's least and greatest sample (never a zigzag).
        return _band_trace(x=line.x, lo=line.y, hi=line.y if line.upper is None else line.upper,
                           decimate=line.decimate, panel=panel, refs=refs, color=color,
                           name=line.name, width=line.width, fill_alpha=0.5 * line.opacity,
                           show=show and line.legend and bool(line.name), group=group,
                           arrays=arrays, width_px=width_px, index=index, pyramids=pyramids)
    x, y = line.x, line.y
    if panel.y_log:  # a log axis cannot show values ≤ 0: leave a gap, not a clipped point
        y = np.where(y > 0, y, np.nan)
    if panel.x_log:
        x = np.where(x > 0, x, np.nan)
    trace: dict[str, Any] = {
        "type": "scatter", "x": arrays.ref(x), "y": arrays.ref(y),
        "xaxis": refs[0], "yaxis": refs[1], "name": line.name or " ",
        "mode": "markers" if line.markers else "lines",
        "hovertemplate": _hover(panel), "showlegend": show and line.legend and bool(line.name),
        "opacity": line.opacity, "legendgroup": group,
    }
    if line.markers:
        trace["marker"] = {"color": color, "size": 6}
    else:
        trace["line"] = {"color": color, "width": line.width, "dash": _DASH[line.dash]}
    return trace


def _bars_trace(bars: Bars, refs: tuple[str, str], color: str, show: bool,
                arrays: _Arrays) -> dict[str, Any]:
    trace: dict[str, Any] = {
        "type": "bar", "x": list(bars.categories), "y": arrays.ref(bars.values),
        "xaxis": refs[0], "yaxis": refs[1], "name": bars.name or " ",
        "marker": {"color": color}, "showlegend": show and bars.legend and bool(bars.name),
        "legendgroup": bars.group or bars.name,
    }
    return trace


class _Legend:
    """Each trace's colour and legend entry, by its key (its group, else its name).

    The first trace of a key shows it in the legend; a trace without a colour
    takes its key's, the palette's next at the key's first use.
    """

    def __init__(self) -> None:
        self._shown: set[str] = set()
        self._color_of: dict[str, str] = {}

    def entry(self, trace: Line | Bars) -> tuple[str, bool]:
        """(the trace's colour, whether it shows its key in the legend)."""
        key = trace.group or trace.name
        if trace.color is not None:
            color = trace.color
        else:
            color = self._color_of.setdefault(key, PALETTE[len(self._color_of) % len(PALETTE)])
        show = key not in self._shown
        self._shown.add(key)
        return color, show


def _base_layout(fig: Figure, *, height_px: int, area_px: float) -> dict[str, Any]:
    """The figure's layout before its panels: size, margins, legend, empty mark lists.

    Parameters
    ----------
    fig : Figure
        The figure.
    height_px : int
        Its height [px].
    area_px : float
        Height of the area the panels share [px] (the legend sits below it).
    """
    return {
        "height": height_px, "margin": {**_MARGIN, "t": _margin_top(fig)},
        "hovermode": "closest", "font": {"size": 12},
        # Below the bottom axis title, whatever the figure's height.
        "legend": {"orientation": "h", "y": -(_GAP_TICKS_PX + _GAP_X_TITLE_PX + 6) / area_px,
                   "yanchor": "top", "x": 0, "font": {"size": 11}},
        "paper_bgcolor": "white", "plot_bgcolor": "white",
        "annotations": [], "shapes": [], "barmode": "group",
    }


def _panel_title(fig: Figure, title: str, *, x_domain: tuple[float, float],
                 y_domain: tuple[float, float]) -> dict[str, Any]:
    """A panel's title: bold, centred above it, wrapped to its column."""
    lines = "<br>".join(wrap_words(title, int(_column_px(fig) / _BOLD_CHAR_PX)))
    return {
        "text": f"<b>{lines}</b>", "showarrow": False, "x": (x_domain[0] + x_domain[1]) / 2,
        "xref": "paper", "y": y_domain[1], "yref": "paper", "yanchor": "bottom",
        "xanchor": "center", "font": {"size": 12}, "name": "panel title"}


def figure_json(fig: Figure) -> dict[str, Any]:
    """The plotly.js figure: ``{"data", "layout", "arrays", "pyramids"}``.

    Every array is stored once in ``arrays`` (typed-array JSON) and traces
    refer to it as ``{"ref": i}``; the page swaps the references in before
    plotting (traces on one frequency grid share it: a third of a Bode
    figure's size). ``pyramids`` lists the finer levels of each decimated
    band (:data:`ZOOM_JS` draws them on zoom).
    """
    height = fig.default_height_px()
    data: list[dict[str, Any]] = []
    area = _plot_height(fig, height)
    layout = _base_layout(fig, height_px=height, area_px=area)
    arrays = _Arrays()
    pyramids: list[dict[str, Any]] = []
    legend = _Legend()
    y_owner: dict[str, str] = {}
    for i, xd, yd in _domains(fig, height):
        panel = fig.panels[i]
        refs = _axis_ids(i)
        row, col = divmod(i, fig.columns)
        # The first panel of a share_y key owns its y axis; the others zoom with it.
        owner = y_owner.setdefault(panel.share_y, refs[1]) if panel.share_y else refs[1]
        axes = _panel_axes(panel, refs=refs, x_domain=xd, y_domain=yd, area_px=area,
                           show_x_title=_shows_x_title(fig, i),
                           x_matches=_axis_ids(col)[0] if fig.share_x and row > 0 else None,
                           y_matches=owner if owner != refs[1] else None)
        layout[_layout_key(refs[0])] = axes.x
        layout[_layout_key(refs[1])] = axes.y
        width_px = max(200, round(_PAGE_PX * (xd[1] - xd[0])))
        for trace in panel.traces:
            color, show = legend.entry(trace)
            if isinstance(trace, Line):
                data.append(_line_trace(trace, panel, refs, color, show, arrays, width_px,
                                        len(data), pyramids))
            else:
                data.append(_bars_trace(trace, refs, color, show, arrays))
        marks = _panel_marks(panel, refs=refs)
        layout["shapes"].extend(marks.shapes)
        layout["annotations"].extend(marks.annotations)
        if panel.title:
            layout["annotations"].append(_panel_title(fig, panel.title, x_domain=xd,
                                                      y_domain=yd))
    return {"data": data, "layout": layout, "arrays": arrays.table, "pyramids": pyramids}


# The page's zoom on long records: after a relayout (zoom, pan, reset) each decimated band
# is redrawn from the coarsest level of its pyramid that still has a bin per two pixel columns
# over the visible range (the finest level when none has), for the visible range and 5 %
# either side (so that an autoranged y axis fits what is seen; a pan redraws). At one sample
# per bin the band becomes the line of the samples. ``div._fsmZoom[trace]`` records the
# level drawn.
ZOOM_JS = r"""
(function () {
  function decode(arr) {
    var bin = atob(arr.bdata), bytes = new Uint8Array(bin.length);
    for (var i = 0; i < bin.length; i++) { bytes[i] = bin.charCodeAt(i); }
    var Type = {f4: Float32Array, f8: Float64Array, u2: Uint16Array}[arr.dtype];
    return new Type(bytes.buffer);
  }
  window.fsmbenchZoom = function (div, spec) {
    var pyramids = spec.pyramids || [];
    if (!pyramids.length) { return; }
    var cache = {};
    div._fsmZoom = {};
    function values(p, lv, which) {
      var ref = lv[which].ref, key = p.trace + ':' + ref;
      if (cache[key]) { return cache[key]; }
      var arr = spec.arrays[ref], raw = decode(arr), out = raw;
      if (arr.dtype === 'u2') {
        out = new Float64Array(raw.length);
        for (var i = 0; i < raw.length; i++) {
          out[i] = raw[i] === 65535 ? NaN : p.offset + raw[i] * p.scale;
        }
      }
      cache[key] = out;
      return out;
    }
    function draw(p) {
      var xa = div._fullLayout[p.xaxis];
      if (!xa || !xa.range) { return; }
      var full = xa.autorange === true;
      var i0 = Math.max(0, Math.floor((xa.range[0] - p.x0) / p.dx));
      var i1 = Math.min(p.n, Math.ceil((xa.range[1] - p.x0) / p.dx) + 1);
      var seen = Math.max(1, i1 - i0), px = Math.max(1, xa._length || 1);
      var k = 0;
      while (k + 1 < p.levels.length && 2 * seen / p.levels[k].per < px) { k++; }
      var lv = p.levels[k], per = lv.per, nb = Math.ceil(p.n / per);
      var pad = Math.ceil(0.05 * seen);
      var b0 = full ? 0 : Math.max(0, Math.floor((i0 - pad) / per));
      var b1 = full ? nb : Math.min(nb, Math.ceil((i1 + pad) / per));
      var now = div._fsmZoom[p.trace];
      if (now && now.level === k && now.b0 * per <= i0 && i1 <= Math.min(p.n, now.b1 * per)
          && (!full || (now.b0 === 0 && now.b1 === nb))) { return; }
      var lo = values(p, lv, 'lo'), hi = values(p, lv, 'hi');
      var centre = function (b) {
        return p.x0 + p.dx * (b * per + (Math.min(per, p.n - b * per) - 1) / 2);
      };
      var update, xs = [], ys = [], b;
      if (per === 1 && lv.lo.ref === lv.hi.ref) {
        for (b = b0; b < b1; b++) { xs.push(centre(b)); ys.push(lo[b]); }
        update = {fill: ['none'], 'line.shape': ['linear'], 'line.width': [p.width]};
      } else {
        var run = [];
        var close = function () {
          if (!run.length) { return; }
          if (xs.length) { xs.push(NaN); ys.push(NaN); }
          var j;
          for (j = 0; j < run.length; j++) { xs.push(centre(run[j])); ys.push(hi[run[j]]); }
          for (j = run.length - 1; j >= 0; j--) { xs.push(centre(run[j])); ys.push(lo[run[j]]); }
          run = [];
        };
        for (b = b0; b < b1; b++) {
          if (isNaN(lo[b]) || isNaN(hi[b])) { close(); } else { run.push(b); }
        }
        close();
        update = {fill: ['toself'], 'line.shape': ['hvh'], 'line.width': [0.6]};
      }
      update.x = [xs];
      update.y = [ys];
      update.hovertemplate = [lv.hover];
      div._fsmZoom[p.trace] = {level: k, per: per, b0: b0, b1: b1};
      Plotly.restyle(div, update, [p.trace]);
    }
    div.on('plotly_relayout', function () { pyramids.forEach(draw); });
    pyramids.forEach(function (p) {
      div._fsmZoom[p.trace] = {level: 0, per: p.levels[0].per, b0: 0,
                               b1: Math.ceil(p.n / p.levels[0].per)};
    });
  };
})();
"""
