"""Figures as data: what a figure shows, not how it is drawn.

A :class:`Figure` is a grid of :class:`Panel` objects, each holding traces
(:class:`Line`, which may be a filled band, and :class:`Bars`), reference lines
(:class:`Rule`), text (:class:`Label`) and axis settings, with labels in words
and units. The
report draws it interactively (:mod:`fsmbench.report.figures.interactive`, plotly.js
in the page) and, on request, as PNG/PDF (:mod:`fsmbench.report.figures.static`,
matplotlib), so the two can never disagree about what is shown.

Axes autoscale to the data unless a panel fixes a range on purpose (the
Nyquist plot's window around −1): nothing is clipped. Panels meant to be
compared share an axis (``Panel.share_y``, ``Figure.share_x``). Long time
series are marked ``decimate=True``; the renderers draw them as a band, the
minimum and maximum of the samples in each bin (:func:`minmax_bins`), which
keeps every extreme and never invents a value; the page stores a pyramid of
finer bins (:func:`pyramid_samples_per_bin`) and swaps in a finer level on
zoom.
"""

from __future__ import annotations

import textwrap
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

__all__ = [
    "H_COLOR",
    "PALETTE",
    "V_COLOR",
    "Bars",
    "Dash",
    "Figure",
    "Label",
    "Line",
    "Panel",
    "Rule",
    "Trace",
    "envelope",
    "minmax_bins",
    "pyramid_samples_per_bin",
    "rows_of",
    "wrap_words",
]

Dash = Literal["solid", "dash", "dot", "dashdot"]

# One colour per axis everywhere in the report: h blue, v orange.
H_COLOR = "#1f77b4"
V_COLOR = "#ff7f0e"
# The cycle for figures with more curves (matplotlib's tab10, CSS hex for both renderers).
PALETTE = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2",
           "#7f7f7f", "#bcbd22", "#17becf")


@dataclass(frozen=True, eq=False)
class Line:
    """A curve (or markers) on a panel.

    Attributes
    ----------
    x, y : numpy.ndarray, shape (n,)
        Coordinates in the panel's display units (the builder scales: µrad,
        nm …). Non-finite values leave gaps; on a log axis so do values ≤ 0.
    name : str
        Legend text, in words (``"Vph, closed loop"``).
    color : str, optional
        CSS colour (``"#1f77b4"``); default: the palette in order.
    dash : {"solid", "dash", "dot", "dashdot"}
    width : float
        Line width in px.
    markers : bool
        Draw markers at the points instead of a line.
    group : str
        Legend group: traces of one group toggle together and the legend
        shows the group's first trace only (e.g. the same signal on several
        panels). Empty: the name is the group, so traces of one name toggle
        together in every panel.
    legend : bool
        Whether this trace may appear in the legend.
    opacity : float
    decimate : bool
        A long time series on a uniform ``x``: drawn as a band, the minimum and
        maximum of the samples in each bin (one bin per pixel column; finer
        bins on zoom in the page). With ``upper``, the bins merge the band's
        own (minimum of ``y``, maximum of ``upper``).
    upper : numpy.ndarray, shape (n,), optional
        Makes the line a band: filled between ``y`` (its lower edge) and
        ``upper``, each value held over the half-way points to its
        neighbours (a bin centred on ``x``), so that it claims no value at a
        time it does not cover. For envelopes (each bin's minimum and
        maximum) and ranges (over periods); ``opacity`` scales the fill.
    """

    x: np.ndarray
    y: np.ndarray
    name: str = ""
    color: str | None = None
    dash: Dash = "solid"
    width: float = 1.5
    markers: bool = False
    group: str = ""
    legend: bool = True
    opacity: float = 1.0
    decimate: bool = False
    upper: np.ndarray | None = None

    def __post_init__(self) -> None:
        x = np.asarray(self.x, dtype=float).ravel()
        y = np.asarray(self.y, dtype=float).ravel()
        if x.shape != y.shape:
            raise ValueError(f"line '{self.name}': x has {x.size} points, y has {y.size}")
        object.__setattr__(self, "x", x)
        object.__setattr__(self, "y", y)
        if self.upper is not None:
            hi = np.asarray(self.upper, dtype=float).ravel()
            if hi.shape != y.shape:
                raise ValueError(f"band '{self.name}': y has {y.size} points, upper {hi.size}")
            object.__setattr__(self, "upper", hi)


@dataclass(frozen=True, eq=False)
class Bars:
    """A bar series over named categories (several series are drawn side by side).

    Attributes
    ----------
    categories : tuple of str
        One label per bar, in words.
    values : numpy.ndarray, shape (n,)
    name, color, group, legend : as for :class:`Line`.
    """

    categories: tuple[str, ...]
    values: np.ndarray
    name: str = ""
    color: str | None = None
    group: str = ""
    legend: bool = True

    def __post_init__(self) -> None:
        v = np.asarray(self.values, dtype=float).ravel()
        if v.size != len(self.categories):
            raise ValueError(f"bars '{self.name}': {v.size} values for "
                             f"{len(self.categories)} categories")
        object.__setattr__(self, "values", v)

Trace = Line | Bars


@dataclass(frozen=True)
class Rule:
    """A reference line across the whole panel: ``axis="y"`` is horizontal at ``value``.

    It extends over any zoom, unlike a two-point line.
    """

    value: float
    axis: Literal["x", "y"] = "y"
    name: str = ""
    color: str = "#000000"
    dash: Dash = "solid"


@dataclass(frozen=True)
class Label:
    """Text at a data point."""

    x: float
    y: float
    text: str


@dataclass(frozen=True, eq=False)
class Panel:
    """One set of axes.

    Attributes
    ----------
    traces : tuple of Line or Bars
    x_label, y_label : str
        Quantity in words with its unit (``"Frequency [Hz]"``).
    x_log, y_log : bool
        Logarithmic axes.
    title : str
        Panel title (optional; the figure has its own).
    rules : tuple of Rule
    labels : tuple of Label
    x_range, y_range : (float, float), optional
        A fixed window, only where the window itself is the point (the
        Nyquist plot around −1); otherwise the axis autoscales to the data.
        On a log axis the range is in data units, not decades.
    equal_aspect : bool
        Same scale on x and y (Nyquist, beam path).
    shade : (float, float), optional
        An x interval drawn grey (e.g. the part of a record the ESRF study's
        processing removes).
    height : float
        Relative height of this panel's row (Bode: magnitude 2, phase 1).
    share_y : str
        Panels of a figure with the same non-empty key share one y axis: the
        same range, zoomed together (rows of spectra meant to be compared).
        They must have the same ``y_log``.
    """

    traces: tuple[Trace, ...]
    x_label: str
    y_label: str
    x_log: bool = False
    y_log: bool = False
    title: str = ""
    rules: tuple[Rule, ...] = ()
    labels: tuple[Label, ...] = ()
    x_range: tuple[float, float] | None = None
    y_range: tuple[float, float] | None = None
    equal_aspect: bool = False
    shade: tuple[float, float] | None = None
    height: float = 1.0
    share_y: str = ""


@dataclass(frozen=True, eq=False)
class Figure:
    """A figure of the report.

    Attributes
    ----------
    key : str
        Stable identifier and file stem (``"fig31_huddle_attocube_asd"``):
        lower case, digits and underscores.
    title : str
        In words.
    caption : str
        What it shows and how it was computed.
    panels : tuple of Panel
        Laid out row by row in ``columns`` columns.
    seed_ref : str
        The ESRF study's figure (``"Fig. 31"``), or "".
    columns : int
    share_x : bool
        Panels of one column share their x axis (zoom one, all follow).
    height_px : int, optional
        Height of the whole figure; default from the number of rows.
    note : str
        Why a result looks the way it does when it differs from the ESRF study or
        looks odd (the errata entry, in short); shown under the caption.
    number : int, optional
        Its number in the report ("Figure 12"), set by
        :func:`fsmbench.report.html.iter_figures`; exported files are named by it.
    """

    key: str
    title: str
    caption: str
    panels: tuple[Panel, ...]
    seed_ref: str = ""
    columns: int = 1
    share_x: bool = False
    height_px: int | None = None
    note: str = ""
    number: int | None = None

    def __post_init__(self) -> None:
        if not self.key or not all(c.islower() or c.isdigit() or c == "_" for c in self.key):
            raise ValueError(f"figure key {self.key!r}: use lower case, digits and underscores")
        if not self.panels:
            raise ValueError(f"figure {self.key}: no panel")
        if self.columns < 1:
            raise ValueError(f"figure {self.key}: columns must be ≥ 1")
        logs: dict[str, bool] = {}
        for p in self.panels:
            if p.share_y and logs.setdefault(p.share_y, p.y_log) != p.y_log:
                raise ValueError(f"figure {self.key}: panels sharing y axis {p.share_y!r} mix "
                                 "linear and log scales")

    @property
    def n_rows(self) -> int:
        """Number of panel rows."""
        return -(-len(self.panels) // self.columns)

    def default_height_px(self) -> int:
        """Height when none is given: 170 px per unit of relative row height, 360 px at least."""
        if self.height_px is not None:
            return self.height_px
        heights = [max(p.height for p in row) for row in rows_of(self)]
        units = sum(h / min(heights) for h in heights)
        return max(360, int(90 + 170 * units))


def rows_of(fig: Figure) -> Iterator[Sequence[Panel]]:
    """The figure's panels, row by row."""
    for r in range(fig.n_rows):
        yield fig.panels[r * fig.columns:(r + 1) * fig.columns]


def envelope(x: np.ndarray, y: np.ndarray, *, columns: int = 2000
             ) -> tuple[np.ndarray, np.ndarray]:
    """Min/max envelope of ``y`` in ``columns`` bins, interleaved for a line plot.

    Every bin contributes its minimum and maximum in time order, so every
    extreme of the record is drawn; records shorter than ``2 * columns``
    are returned as they are.

    Parameters
    ----------
    x, y : numpy.ndarray, shape (n,)
        Monotonic abscissa (time, s) and values.
    columns : int
        Number of bins (about the pixel width of a plot).
    """
    n = y.size
    if n <= 2 * columns:
        return x, y
    per = n // columns
    m = per * columns
    yb = y[:m].reshape(columns, per)
    xb = x[:m].reshape(columns, per)
    finite = np.isfinite(yb)
    lo = np.where(finite, yb, np.inf).argmin(axis=1)
    hi = np.where(finite, yb, -np.inf).argmax(axis=1)
    first, second = np.minimum(lo, hi), np.maximum(lo, hi)
    rows = np.arange(columns)
    xx = np.column_stack([xb[rows, first], xb[rows, second]]).ravel()
    yy = np.column_stack([yb[rows, first], yb[rows, second]]).ravel()
    if m < n:  # the tail that did not fill a whole bin
        xx = np.concatenate([xx, x[m:]])
        yy = np.concatenate([yy, y[m:]])
    return xx, yy


def minmax_bins(lower: np.ndarray, upper: np.ndarray, per: int
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Minimum of ``lower`` and maximum of ``upper`` in consecutive bins of ``per`` samples.

    Parameters
    ----------
    lower, upper : numpy.ndarray, shape (n,)
        The samples (the same array twice for a record) or a range.
    per : int
        Samples per bin (≥ 1); the last bin holds the remainder.

    Returns
    -------
    first : numpy.ndarray of int, shape (m,)
        Index of each bin's first sample.
    lo, hi : numpy.ndarray, shape (m,)
        Each bin's minimum and maximum; NaN where the bin has no finite sample.
    """
    lo_in = np.asarray(lower, dtype=float)
    hi_in = np.asarray(upper, dtype=float)
    n = lo_in.size
    per = max(1, int(per))
    first = np.arange(0, n, per)
    if per == 1:
        return first, lo_in.copy(), hi_in.copy()
    with np.errstate(invalid="ignore"):
        lo = np.fmin.reduceat(lo_in, first)
        hi = np.fmax.reduceat(hi_in, first)
    return first, lo, hi


# Zoom factor down to which the page's pyramid still draws a bin per pixel column, in
# levels of LEVEL_FACTOR times the bins of the one above: zoomed 16 times (100 s to 6 s),
# a long record is still drawn at full resolution, for 21 bins per pixel column stored.
ZOOM_DEPTH = 16
LEVEL_FACTOR = 4


def pyramid_samples_per_bin(n: int, columns: int) -> list[int]:
    """Samples per bin of each level of a record's pyramid, coarsest first.

    Level 0 has about ``columns`` bins (one per pixel column); each finer
    level has :data:`LEVEL_FACTOR` times as many, down to :data:`ZOOM_DEPTH`
    times as many as level 0, or to one sample per bin.
    """
    levels = [max(1, -(-n // max(1, columns)))]
    depth = 1
    while levels[-1] > 1 and depth < ZOOM_DEPTH:
        levels.append(-(-levels[-1] // LEVEL_FACTOR))
        depth *= LEVEL_FACTOR
    return levels


def wrap_words(text: str, width: int) -> list[str]:
    """``text`` in lines of at most ``width`` characters, broken between words (a word
    longer than that stays whole): a title that fits its panel."""
    return textwrap.wrap(text, width=max(1, width), break_long_words=False,
                         break_on_hyphens=False) or [text]
