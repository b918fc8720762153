"""A :class:`~fsmbench.report.figures.spec.Figure` as a static PNG/PDF, drawn by matplotlib (Agg).

``fsmbench study --figures png,pdf`` writes every figure of the report to
``OUT/figures/figNN_<what>.png`` (150 dpi) and/or ``.pdf`` (vector), ``NN`` its
number in the report (:func:`fsmbench.report.html.export_stem`). The spec is
drawn as the interactive renderer (:mod:`fsmbench.report.figures.interactive`) draws
it: the same grid of panels, shared x per column and y per ``share_y`` key,
log axes that leave values ≤ 0 out, fixed ranges only where the panel gives
one (nothing is clipped), equal aspect (the box shrinks to the data), rules,
labels, shaded intervals, colours, legend (one entry per group), wrapped
titles, bands filled as steps, and long records reduced to their min/max per
pixel column (:func:`~fsmbench.report.figures.spec.envelope`).

matplotlib is imported inside the functions only, so importing
:mod:`fsmbench.report` does not import it. Figures are built on
:class:`matplotlib.figure.Figure` directly (no pyplot), so nothing is kept
in a global figure registry; layout is matplotlib's constrained layout,
computed once per figure (tight_layout costs several draws).
"""

from __future__ import annotations

import multiprocessing as mp
import os
import re
from collections.abc import Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fsmbench.atomic import atomic_path
from fsmbench.report.figures.spec import (
    PALETTE,
    Bars,
    Figure,
    Line,
    Panel,
    Trace,
    envelope,
    minmax_bins,
    rows_of,
    wrap_words,
)
from fsmbench.report.html import export_stem

if TYPE_CHECKING:
    import matplotlib.axes
    import matplotlib.figure

__all__ = ["FORMATS", "PNG_DPI", "export_figures", "render_matplotlib"]

FORMATS = ("png", "pdf")
PNG_DPI = 150
# Width of every figure [in]: a full text width of a paper, wider for 3+ columns.
_WIDTH_IN = 8.0
_WIDE_WIDTH_IN = 11.0
# The page's plotly figures are ~1150 px wide; this keeps their proportions at 8 in.
_PX_PER_IN = 110.0
_MIN_HEIGHT_IN = 3.0
# Padding around labels and between the figure's parts [in] (4 pt).
_PAD_IN = 4 / 72
# plotly sizes lines and markers in CSS px (1/96 in); matplotlib in points (1/72 in).
_PT_PER_PX = 72.0 / 96.0
_LINESTYLE = {"solid": "-", "dash": "--", "dot": ":", "dashdot": "-."}
_GRID_COLOR = "#e4e4e4"
_SHADE_COLOR = "#dddddd"
_STYLE: Any = {
    "font.size": 9.0,
    "axes.titlesize": 9.5,
    "axes.labelsize": 9.0,
    "xtick.labelsize": 8.0,
    "ytick.labelsize": 8.0,
    "legend.fontsize": 8.0,
    "figure.titlesize": 10.5,
    "axes.edgecolor": "#888888",
    "axes.linewidth": 0.8,
    "axes.axisbelow": True,
    "lines.solid_capstyle": "butt",
    # Type 3 (matplotlib's default) embeds the used glyphs in a few ms; TrueType (42)
    # subsetting with fontTools costs ~0.4 s per PDF, half the export time of a figure.
    "pdf.fonttype": 3,
    "path.simplify": True,
    "agg.path.chunksize": 20000,
}


# matplotlib's log tick labels are mathtext ("$\\mathdefault{2\\times10^{-3}}$"), whose parsing
# is most of a figure's drawing time; the same label as plain text with Unicode superscripts
# ("2×10⁻³") looks the same and costs nothing.
_MATHTEXT_POWER = re.compile(r"^\$\\mathdefault\{(?:([0-9.]+)\\times)?10\^\{(-?[0-9]+)\}\}\$$")
_SUPERSCRIPT = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")


def _plain_power(label: str) -> str:
    """A mathtext power-of-ten tick label as plain text; other labels as they are."""
    m = _MATHTEXT_POWER.match(label)
    if m is None:
        return label
    coefficient, exponent = m.groups()
    power = "10" + exponent.translate(_SUPERSCRIPT)
    return f"{coefficient}×{power}" if coefficient else power


@cache
def _log_formatter() -> Any:
    """matplotlib's log-axis tick formatter, returning plain text instead of mathtext."""
    import matplotlib.ticker as mticker

    class PlainLogFormatter(mticker.LogFormatterSciNotation):
        def __call__(self, x: float, pos: int | None = None) -> str:
            return _plain_power(super().__call__(x, pos))

    return PlainLogFormatter


def _cheap_minor_ticks(ax: matplotlib.axes.Axes) -> None:
    """Minor ticks of a log axis spanning over a decade as one marker line per axis.

    matplotlib makes every minor tick a set of five artists, which doubles a
    log-log figure's drawing time; above one decade its minor ticks carry no
    label, so the same tick marks drawn as markers of one line look the same.
    Call once the view limits are final (after every trace of the figure).
    """
    import matplotlib.lines as mlines
    import matplotlib.ticker as mticker

    for name in ("x", "y"):
        axis = ax.xaxis if name == "x" else ax.yaxis
        if axis.get_scale() != "log":
            continue
        lo, hi = sorted(ax.get_xlim() if name == "x" else ax.get_ylim())
        decades = np.log10(hi / lo) if lo > 0 else np.inf
        if not 1.0 < decades <= 10.0:  # narrow: labelled minor ticks; wide: none (as matplotlib)
            continue
        ticks = mticker.LogLocator(subs=[2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0])
        locs = np.asarray(ticks.tick_values(lo, hi), dtype=float)
        locs = locs[(locs >= lo) & (locs <= hi)]
        axis.set_minor_locator(mticker.NullLocator())
        size = _rc(f"{name}tick.minor.size")
        style: dict[str, Any] = {"linestyle": "none", "markersize": size, "clip_on": False,
                 "markeredgewidth": _rc(f"{name}tick.minor.width"),
                 "color": _rc(f"{name}tick.color"), "zorder": 2.6}
        if name == "x":
            marks = mlines.Line2D(locs, np.zeros_like(locs), marker=3,  # TICKDOWN
                                  transform=ax.get_xaxis_transform(), **style)
        else:
            marks = mlines.Line2D(np.zeros_like(locs), locs, marker=0,  # TICKLEFT
                                  transform=ax.get_yaxis_transform(), **style)
        # add_artist, not add_line: the marks must not widen the data limits.
        marks.set_label("_nolegend_")
        ax.add_artist(marks)


def _rc(key: str) -> Any:
    """The current matplotlib setting ``key``."""
    import matplotlib as mpl

    params: Any = mpl.rcParams
    return params[key]


def _check_formats(formats: Sequence[str]) -> tuple[str, ...]:
    out: list[str] = []
    for f in formats:
        name = f.strip().lower().lstrip(".")
        if name not in FORMATS:
            raise ValueError(f"figure format {f!r}: use {' or '.join(FORMATS)}")
        if name not in out:
            out.append(name)
    if not out:
        raise ValueError(f"no figure format given: use {' or '.join(FORMATS)}")
    return tuple(out)


def _size_in(fig: Figure) -> tuple[float, float]:
    """(width, height) [in] of the figure: the page's proportions at paper width."""
    width = _WIDTH_IN if fig.columns < 3 else _WIDE_WIDTH_IN
    height = max(_MIN_HEIGHT_IN, fig.default_height_px() / _PX_PER_IN)
    return width, height


def _envelope_columns(fig: Figure) -> int:
    """Envelope bins of a decimated line: one per pixel column of a panel in the PNG."""
    return min(2000, int(_size_in(fig)[0] / fig.columns * PNG_DPI))


def _finite(v: np.ndarray, *, log: bool) -> np.ndarray:
    """Non-finite values (and values ≤ 0 on a log axis) as NaN: a gap, never a clipped point."""
    keep = np.isfinite(v) & (v > 0) if log else np.isfinite(v)
    return v if keep.all() else np.where(keep, v, np.nan)


def _include(ax: matplotlib.axes.Axes, x: float | None, y: float | None) -> None:
    """Make autoscaling include a point (a label's anchor), like plotly's autorange does."""
    xs = np.array([x if x is not None else np.nan])
    ys = np.array([y if y is not None else np.nan])
    ax.update_datalim(np.column_stack([xs, ys]), updatex=x is not None, updatey=y is not None)


def _draw_line(ax: matplotlib.axes.Axes, line: Line, panel: Panel, color: str,
               label: str, columns: int, gid: str) -> None:
    x, y = envelope(line.x, line.y, columns=columns) if line.decimate else (line.x, line.y)
    x = _finite(x, log=panel.x_log)
    y = _finite(y, log=panel.y_log)
    style: dict[str, Any] = {"color": color, "alpha": line.opacity, "label": label, "gid": gid}
    if line.markers:
        # plotly's marker size 6 px is a diameter.
        ax.plot(x, y, linestyle="none", marker="o", markersize=6 * _PT_PER_PX,
                markeredgewidth=0, **style)
    else:
        ax.plot(x, y, linestyle=_LINESTYLE[line.dash], linewidth=line.width * _PT_PER_PX,
                **style)


def _band_bins(band: Line, columns: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A band's centres and edges, merged into at most ``columns`` bins when decimated."""
    n, upper = band.x.size, band.y if band.upper is None else band.upper
    if not band.decimate or n <= 2 * columns:
        return band.x, band.y, upper
    first, lo, hi = minmax_bins(band.y, upper, -(-n // columns))
    return 0.5 * (band.x[first] + band.x[np.r_[first[1:], n] - 1]), lo, hi


def _draw_band(ax: matplotlib.axes.Axes, band: Line, panel: Panel, color: str, label: str,
               columns: int, gid: str) -> None:
    """A band filled as steps over its bins, its edges drawn thin in the full colour."""
    x, lo, hi = _band_bins(band, columns)
    x = _finite(x, log=panel.x_log)
    lo, hi = (_finite(v, log=panel.y_log) for v in (lo, hi))
    ax.fill_between(x, lo, hi, step="mid", color=color, alpha=0.5 * band.opacity,
                    linewidth=0, label=label, gid=gid)
    for edge in (lo, hi):
        ax.step(x, edge, where="mid", color=color, linewidth=0.45, label="_nolegend_")


def _draw_bars(ax: matplotlib.axes.Axes, panel: Panel,
               bars: Sequence[tuple[Bars, str, str]]) -> None:
    """All bar series of a panel, side by side within each category (plotly's "group" mode)."""
    categories: list[str] = []
    for b, _, _ in bars:  # plotly orders categories by first appearance
        categories.extend(c for c in b.categories if c not in categories)
    index = {c: i for i, c in enumerate(categories)}
    n = len(bars)
    width = 0.8 / n
    for k, (b, color, label) in enumerate(bars):
        pos = np.array([index[c] for c in b.categories], dtype=float) - 0.4 + (k + 0.5) * width
        values = _finite(b.values, log=panel.y_log)
        ok = np.isfinite(values)
        ax.bar(pos[ok], values[ok], width=width, color=color, label=label, linewidth=0)
    step = max(1, -(-len(categories) // 40))  # at most ~40 category names on the axis
    ticks = list(range(0, len(categories), step))
    ax.set_xticks(ticks, [categories[i] for i in ticks])
    if len(ticks) > 8 or max((len(c) for c in categories), default=0) > 12:
        for tick in ax.get_xticklabels():
            tick.set_rotation(60)
            tick.set_horizontalalignment("right")
            tick.set_rotation_mode("anchor")
    ax.grid(False, axis="x")


def _set_range(ax: matplotlib.axes.Axes, fig: Figure, panel_no: int, axis: str,
               rng: tuple[float, float] | None, log: bool) -> None:
    if rng is None:
        return
    lo, hi = float(rng[0]), float(rng[1])
    if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
        raise ValueError(f"figure {fig.key}, panel {panel_no + 1}: {axis} range ({lo:g}, {hi:g}) "
                         "is not an increasing pair of finite numbers")
    if log and lo <= 0:
        raise ValueError(f"figure {fig.key}, panel {panel_no + 1}: {axis} range ({lo:g}, {hi:g}) "
                         "on a log axis must be positive")
    (ax.set_xlim if axis == "x" else ax.set_ylim)(lo, hi)


def _draw_panel(ax: matplotlib.axes.Axes, fig: Figure, panel_no: int, *,
                color_of: dict[str, str], shown: set[str], show_x: bool) -> None:
    panel = fig.panels[panel_no]
    columns = _envelope_columns(fig)
    formatter = _log_formatter()
    if panel.x_log:
        ax.set_xscale("log")
        ax.xaxis.set_major_formatter(formatter())
        ax.xaxis.set_minor_formatter(formatter(labelOnlyBase=False))
    if panel.y_log:
        ax.set_yscale("log")
        ax.yaxis.set_major_formatter(formatter())
        ax.yaxis.set_minor_formatter(formatter(labelOnlyBase=False))
    bars: list[tuple[Bars, str, str]] = []
    for k, trace in enumerate(panel.traces):
        # Colour and legend exactly as interactive.figure_json: by group, else by name.
        key = trace.group or trace.name
        if trace.color is not None:
            color = trace.color
        else:
            color = color_of.setdefault(key, PALETTE[len(color_of) % len(PALETTE)])
        show = key not in shown and trace.legend and bool(trace.name)
        shown.add(key)
        # matplotlib leaves labels starting with "_" out of the legend.
        label = trace.name if show else "_nolegend_"
        if isinstance(trace, Line) and trace.upper is not None:
            _draw_band(ax, trace, panel, color, label, columns, f"p{panel_no}t{k}")
        elif isinstance(trace, Line):
            # The gid names the trace (panel, trace index) for tests and SVG ids.
            _draw_line(ax, trace, panel, color, label, columns, f"p{panel_no}t{k}")
        else:
            bars.append((trace, color, label))
    if bars:
        _draw_bars(ax, panel, bars)
    for rule in panel.rules:
        log = panel.y_log if rule.axis == "y" else panel.x_log
        if not np.isfinite(rule.value) or (log and rule.value <= 0):
            continue  # cannot be placed on this axis
        style: dict[str, Any] = {"color": rule.color, "linewidth": 0.8,
                                 "linestyle": _LINESTYLE[rule.dash],
                 "zorder": 1.5}
        if rule.axis == "y":
            ax.axhline(rule.value, **style)
            if rule.name:
                ax.text(0.995, rule.value, rule.name, transform=ax.get_yaxis_transform(),
                        ha="right", va="bottom", fontsize=7.5, color=rule.color)
        else:
            ax.axvline(rule.value, **style)
            if rule.name:
                ax.text(rule.value, 0.98, rule.name + " ", transform=ax.get_xaxis_transform(),
                        ha="right", va="top", fontsize=7.5, color=rule.color)
    if panel.shade is not None:
        lo, hi = panel.shade
        ax.axvspan(lo, hi, color=_SHADE_COLOR, alpha=0.6, linewidth=0, zorder=0.5)
    for lab in panel.labels:
        ax.annotate(lab.text, (lab.x, lab.y), xytext=(2, 2), textcoords="offset points",
                    ha="left", va="bottom", fontsize=7.5)
        _include(ax, lab.x, lab.y)
    _set_range(ax, fig, panel_no, "x", panel.x_range, panel.x_log)
    _set_range(ax, fig, panel_no, "y", panel.y_range, panel.y_log)
    if panel.equal_aspect:
        # The box shrinks to the data's aspect (as the page's "constrain: domain"), so no
        # axis is padded with empty range and a fixed window is kept as given.
        ax.set_aspect("equal", adjustable="box")
    ax.grid(True, which="major", color=_GRID_COLOR, linewidth=0.6)
    # Titles longer than their panel are wrapped (average glyph widths of the 9 pt labels
    # and the 9.5 pt bold titles: 5.2 and 5.7 pt), as the page wraps its own.
    box = ax.get_position(original=True)
    fig_w, fig_h = _size_in(fig)
    ax.set_ylabel("\n".join(wrap_words(panel.y_label, int(box.height * fig_h * 72 / 5.2))))
    ax.set_xlabel(panel.x_label if show_x else "")
    if not show_x:
        ax.tick_params(axis="x", labelbottom=False)
    if panel.title:
        # The panel's width once laid out: the figure less ~1 in of labels, per column.
        width_in = (fig_w - 1.0) / fig.columns - 0.3 * (fig.columns > 1)
        ax.set_title("\n".join(wrap_words(panel.title, int(width_in * 72 / 5.7))),
                     fontweight="bold")


def _legend(mfig: matplotlib.figure.Figure, per_row: int) -> Any:
    """The figure's legend (one entry per shown name) at the bottom centre, or None."""
    handles, labels = [], []
    for ax in mfig.axes:
        h, lab = ax.get_legend_handles_labels()
        handles.extend(h)
        labels.extend(lab)
    if not handles:
        return None
    return mfig.legend(handles, labels, loc="lower center",
                       bbox_to_anchor=(0.5, _PAD_IN / mfig.get_figheight()),
                       ncols=max(1, min(len(labels), per_row)), frameon=False,
                       handlelength=2.2, columnspacing=1.4, borderaxespad=0.0)


def _layout(mfig: matplotlib.figure.Figure, fig: Figure, grid: Any, title: Any) -> None:
    """Place the panels so that every label fits: one measuring pass.

    matplotlib's constrained layout measures every axes twice and a layout
    engine re-runs before each save; here the room each panel's tick labels,
    axis labels and title take outside its box is measured once
    (``get_tightbbox``) and the grid's margins and gaps are set from it.
    """
    width_in, height_in = mfig.get_size_inches()
    renderer = _agg_canvas(mfig).get_renderer()
    dpi = mfig.dpi
    # The legend: as many entries per row as fit the width, fewer if it is too wide.
    per_row = 12
    legend = _legend(mfig, per_row)
    while legend is not None and per_row > 1 and (
            legend.get_window_extent(renderer).width / dpi > width_in - 2 * _PAD_IN):
        legend.remove()
        per_row = min(per_row, len(legend.get_texts())) - 1
        legend = _legend(mfig, per_row)
    legend_in = 0.0 if legend is None else legend.get_window_extent(renderer).height / dpi
    title_in = title.get_window_extent(renderer).height / dpi
    rows, cols = fig.n_rows, fig.columns
    # Room outside each panel's box [in]: left, right, bottom, top.
    room = np.zeros((rows, cols, 4))
    for i, ax in enumerate(mfig.axes):
        r, c = divmod(i, cols)
        box = ax.get_position(original=True).transformed(mfig.transFigure)
        tight = ax.get_tightbbox(renderer)
        if tight is None:  # an axes with nothing drawn
            continue
        room[r, c] = np.maximum(0.0, [box.x0 - tight.x0, tight.x1 - box.x1,
                                      box.y0 - tight.y0, tight.y1 - box.y1]) / dpi
    left = room[:, 0, 0].max() + _PAD_IN
    right = room[:, -1, 1].max() + _PAD_IN
    top = title_in + room[0, :, 3].max() + 2 * _PAD_IN
    bottom = legend_in + room[-1, :, 2].max() + (2 if legend_in else 1) * _PAD_IN
    gap_w = max((room[:, c, 1].max() + room[:, c + 1, 0].max() for c in range(cols - 1)),
                default=0.0) + _PAD_IN
    gap_h = max((room[r, :, 2].max() + room[r + 1, :, 3].max() for r in range(rows - 1)),
                default=0.0) + _PAD_IN
    # gridspec gaps are fractions of the mean panel width and height.
    panel_w = max(0.5, (width_in - left - right - (cols - 1) * gap_w) / cols)
    panel_h = max(0.3, (height_in - top - bottom - (rows - 1) * gap_h) / rows)
    grid.update(left=left / width_in, right=1 - right / width_in,
                bottom=bottom / height_in, top=1 - top / height_in,
                wspace=gap_w / panel_w, hspace=gap_h / panel_h)
    for ax in mfig.axes:  # GridSpec.update moves the axes of pyplot figures only
        spec = ax.get_subplotspec()
        if spec is not None:
            ax.set_position(spec.get_position(mfig))


def render_matplotlib(fig: Figure) -> matplotlib.figure.Figure:
    """Draw a figure spec with matplotlib, as the report's interactive figure shows it.

    Parameters
    ----------
    fig : Figure
        The spec; data in the panels' display units.

    Returns
    -------
    matplotlib.figure.Figure
        An Agg-backed figure (no pyplot state), ``8 in`` wide (``11 in``
        for three or more columns), its height from
        :meth:`Figure.default_height_px`, laid out (panel positions final).
        Its title is the figure's title with the ESRF study's figure number; the
        legend (one entry per group) sits below the panels.
    """
    import matplotlib as mpl
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure as MplFigure

    with mpl.rc_context(_STYLE):
        mfig = MplFigure(figsize=_size_in(fig))
        FigureCanvasAgg(mfig)
        heights = [max(p.height for p in row) for row in rows_of(fig)]
        grid = mfig.add_gridspec(fig.n_rows, fig.columns, height_ratios=heights)
        n = len(fig.panels)
        color_of: dict[str, str] = {}
        shown: set[str] = set()
        column_top: dict[int, matplotlib.axes.Axes] = {}
        y_owner: dict[str, matplotlib.axes.Axes] = {}
        # Share x within a column (plotly's "matches"), only between axes of one scale.
        shared = [fig.share_x and p.x_log == fig.panels[i % fig.columns].x_log
                  for i, p in enumerate(fig.panels)]
        for i, panel in enumerate(fig.panels):
            row, col = divmod(i, fig.columns)
            below = i + fig.columns
            # The x ticks and label are shown once per column, under its last shared panel.
            hide_x = shared[i] and below < n and shared[below]
            ax = mfig.add_subplot(grid[row, col],
                                  sharex=column_top.get(col) if shared[i] else None,
                                  sharey=y_owner.get(panel.share_y) if panel.share_y else None)
            column_top.setdefault(col, ax)
            if panel.share_y:
                y_owner.setdefault(panel.share_y, ax)
            _draw_panel(ax, fig, i, color_of=color_of, shown=shown, show_x=not hide_x)
        for ax, panel in zip(mfig.axes, fig.panels, strict=True):
            if not panel.equal_aspect:  # equal aspect may still widen the limits when drawn
                _cheap_minor_ticks(ax)
        ref = f" (ESRF study {fig.seed_ref})" if fig.seed_ref else ""
        title = mfig.suptitle(fig.title + ref, fontweight="bold", va="top",
                              y=1 - _PAD_IN / mfig.get_figheight())
        _layout(mfig, fig, grid, title)
    return mfig


def _agg_canvas(mfig: matplotlib.figure.Figure) -> Any:
    """The figure's Agg canvas (attached by :func:`render_matplotlib`)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = mfig.canvas
    return canvas if isinstance(canvas, FigureCanvasAgg) else FigureCanvasAgg(mfig)


def _write_png(mfig: matplotlib.figure.Figure, path: Path) -> None:
    """Draw at :data:`PNG_DPI` and write an RGB PNG.

    matplotlib's own PNG writer keeps the (opaque) alpha channel and compresses
    at zlib level 6: for a dense time record that is twice the time of the
    RGB image at level 4, for a 5 % larger file.
    """
    from PIL import Image

    mfig.set_dpi(PNG_DPI)
    canvas = _agg_canvas(mfig)
    canvas.draw()
    width, height = canvas.get_width_height(physical=True)
    rgba = Image.frombuffer("RGBA", (width, height), canvas.buffer_rgba(), "raw", "RGBA", 0, 1)
    rgba.convert("RGB").save(path, format="PNG", dpi=(PNG_DPI, PNG_DPI), compress_level=4)


def _decimated(fig: Figure) -> Figure:
    """The figure with its long records already reduced to their envelope (small to send)."""
    columns = _envelope_columns(fig)

    def light(trace: Trace) -> Trace:
        if isinstance(trace, Line) and trace.upper is not None and trace.decimate:
            x, lo, hi = _band_bins(trace, columns)
            return replace(trace, x=x, y=lo, upper=hi, decimate=False)
        if not isinstance(trace, Line) or not trace.decimate:
            return trace
        x, y = envelope(trace.x, trace.y, columns=columns)
        # Still marked decimate: the worker's envelope of it returns it as it is.
        return replace(trace, x=x, y=y)

    panels = tuple(replace(p, traces=tuple(light(t) for t in p.traces)) for p in fig.panels)
    return replace(fig, panels=panels)


def _export_one(fig: Figure, out: Path, fmts: tuple[str, ...], stem: str) -> list[Path]:
    """Draw one figure and write it in every format as ``stem.<fmt>``; the files written."""
    import matplotlib as mpl

    mfig = render_matplotlib(fig)
    written = []
    with mpl.rc_context(_STYLE):
        for fmt in fmts:
            dest = out / f"{stem}.{fmt}"
            with atomic_path(dest) as tmp:
                if fmt == "png":
                    _write_png(mfig, tmp)
                else:
                    # No creation date: the same figure gives the same file.
                    mfig.savefig(tmp, format="pdf", metadata={"CreationDate": None})
            written.append(dest)
    return written


def export_figures(figures: Iterable[Figure], out_dir: Path, *,
                   formats: Sequence[str], workers: int | None = None) -> list[Path]:
    """Write every figure as ``<stem>.png`` (150 dpi) and/or ``<stem>.pdf`` (vector).

    The stem is the figure's number in the report and what it shows
    (:func:`fsmbench.report.html.export_stem`); without a number, its key.

    Parameters
    ----------
    figures : iterable of Figure
        The report's figures, numbered (:func:`fsmbench.report.html.iter_figures`).
    out_dir : Path
        Folder of the files, created if missing.
    formats : sequence of str
        ``"png"`` and/or ``"pdf"``.
    workers : int, optional
        Processes drawing figures side by side (matplotlib draws on one
        core, ~0.3–0.7 s per figure); default: the CPU count, at most 4.
        1 draws in this process.

    Returns
    -------
    list of Path
        The files written, in order (figure by figure, formats in the order given).

    Raises
    ------
    ValueError
        An unknown format, or two figures with one key (the second would
        overwrite the first).

    Notes
    -----
    Each file is written atomically (:func:`fsmbench.atomic.atomic_path`):
    it is either complete or absent, never half-written. PDFs carry no
    creation date, so the same data give the same file. Worker processes
    receive the figures with long records already reduced to the envelope
    they draw.
    """
    fmts = _check_formats(formats)
    out = Path(out_dir)
    figs = list(figures)
    stems = [export_stem(fig, total=len(figs)) for fig in figs]
    seen: set[str] = set()
    for fig, stem in zip(figs, stems, strict=True):
        if fig.key in seen or stem in seen:
            raise ValueError(f"figure key {fig.key!r} used twice: {out / stem}.* "
                             "would be overwritten")
        seen.update((fig.key, stem))
    out.mkdir(parents=True, exist_ok=True)
    n_workers = min(4, os.cpu_count() or 1) if workers is None else max(1, workers)
    n_workers = min(n_workers, len(figs))
    if n_workers <= 1:
        return [path for fig, stem in zip(figs, stems, strict=True)
                for path in _export_one(fig, out, fmts, stem)]
    # forkserver/spawn, not fork: the caller may hold threads (BLAS, numba) a fork would copy.
    method = "forkserver" if "forkserver" in mp.get_all_start_methods() else "spawn"
    with ProcessPoolExecutor(n_workers, mp_context=mp.get_context(method)) as pool:
        jobs = [pool.submit(_export_one, _decimated(fig), out, fmts, stem)
                for fig, stem in zip(figs, stems, strict=True)]
        try:
            return [path for job in jobs for path in job.result()]
        except BaseException:
            for job in jobs:
                job.cancel()
            raise
