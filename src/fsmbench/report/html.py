"""The self-contained HTML report: a verdict, then sections of text, tables and figures.

A :class:`Section` is a sequence of blocks in reading order: paragraphs
(``str``), :class:`Table`, :class:`~fsmbench.report.figures.spec.Figure` and
:class:`Note` (why a result differs from the ESRF study or looks odd). Figures are
drawn in the browser by plotly.js, embedded once; each figure's data sits in
its own ``<script type="application/json">`` and is plotted when it nears the
screen, the rest in idle time, so the first screen is up at once. The file
opens offline: nothing is loaded from elsewhere. Text is escaped.
"""

from __future__ import annotations

import html
import json
import re
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from fsmbench.atomic import atomic_write_text
from fsmbench.forked import child_share, start_forked
from fsmbench.report.errata import cited_errata, errata_appendix, link_citations
from fsmbench.report.figures.interactive import ZOOM_JS, figure_json, plotly_js
from fsmbench.report.figures.spec import Figure, Line

__all__ = ["ERRATA_TITLE", "Block", "EncodedFigures", "Note", "Section", "Table",
           "encode_figures", "export_stem", "iter_figures", "render_report", "visible_text",
           "write_report"]

#: The errata appendix's title (after the report's own Appendix A).
ERRATA_TITLE = "Appendix B. Errata of the ESRF study"


@dataclass(frozen=True)
class Table:
    """A table of text cells; ``header`` and every row have the same length.

    Cells are words and numbers with their units in the header
    (``"4QD gain, h [V/rad]"``), never code keys.
    """

    caption: str
    header: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]
    note: str = ""

    def __post_init__(self) -> None:
        for row in self.rows:
            if len(row) != len(self.header):
                raise ValueError(f"table '{self.caption}': row {row} has {len(row)} cells, "
                                 f"header has {len(self.header)}")


@dataclass(frozen=True)
class Note:
    """An explanation next to a result: why it differs from the ESRF study or looks odd.

    ``ref`` names the source (``"errata E25"``), shown with the text.
    """

    text: str
    ref: str = ""


Block = str | Table | Figure | Note


@dataclass(frozen=True, eq=False)
class Section:
    """A report section: blocks in reading order, then subsections."""

    title: str
    blocks: tuple[Block, ...] = ()
    subsections: tuple[Section, ...] = field(default=())
    anchor: str = ""


def _figures(sections: Sequence[Section]) -> Iterator[Figure]:
    for sec in sections:
        for block in sec.blocks:
            if isinstance(block, Figure):
                yield block
        yield from _figures(sec.subsections)


def iter_figures(sections: Sequence[Section]) -> Iterator[Figure]:
    """Every figure of the report, in reading order, each with its number in the report.

    The numbers are the page's ("Figure 12"): figures are counted in this
    order by :func:`render_report` too. Each figure comes back as a copy
    whose ``number`` is set (exported files are named by it,
    :func:`export_stem`).
    """
    for number, fig in enumerate(_figures(sections), start=1):
        yield fig if fig.number == number else replace(fig, number=number)


_SEED_PREFIX = re.compile(r"^fig\d+(?:_\d+)*_")


def export_stem(fig: Figure, *, total: int = 99) -> str:
    """File stem of an exported figure: its number in the report, then what it shows.

    ``fig10_qd_regression`` (the ESRF study's Fig. 10), Figure 3 of the report,
    gives ``fig03_qd_regression``: numbers have two digits at least (more when
    ``total``, the report's count, needs them) so that the files list in
    reading order. A figure without a number (not from :func:`iter_figures`)
    keeps its key.
    """
    if fig.number is None:
        return fig.key
    what = _SEED_PREFIX.sub("", fig.key) or fig.key
    width = max(2, len(str(total)), len(str(fig.number)))
    return f"fig{fig.number:0{width}d}_{what}"


def visible_text(sections: Sequence[Section]) -> Iterator[str]:
    """Every string a reader sees, in reading order: titles, paragraphs, table cells, notes,
    figure titles, captions, axis labels, legend names and labels (for checks of wording)."""
    for sec in sections:
        yield sec.title
        for block in sec.blocks:
            if isinstance(block, str):
                yield block
            elif isinstance(block, Table):
                yield from (block.caption, block.note, *block.header)
                for row in block.rows:
                    yield from row
            elif isinstance(block, Note):
                yield from (block.text, block.ref)
            else:
                yield from (block.title, block.caption, block.note)
                for p in block.panels:
                    yield from (p.title, p.x_label, p.y_label)
                    yield from (t.name for t in p.traces)
                    yield from (r.name for r in p.rules)
                    yield from (lab.text for lab in p.labels)
        yield from visible_text(sec.subsections)


_STYLE = """
body { font-family: -apple-system, "Segoe UI", Helvetica, Arial, sans-serif; max-width: 1180px;
       margin: 1.2em auto; padding: 0 1em; color: #222; line-height: 1.45; }
h1 { font-size: 1.6em; margin: 0.2em 0; }
h2 { border-bottom: 1px solid #ccc; margin-top: 2.2em; }
h3 { margin-top: 1.6em; }
table { border-collapse: collapse; margin: 0.8em 0; font-size: 0.9em; }
th, td { border: 1px solid #bbb; padding: 3px 8px; text-align: left; vertical-align: top; }
th { background: #eef2f6; }
thead { display: table-header-group; }
tr { page-break-inside: avoid; }
caption { caption-side: top; text-align: left; font-weight: bold; padding-bottom: .3em; }
figure { margin: 1.2em 0 1.8em 0; page-break-inside: avoid; }
.fsm-plot { width: 100%; border: 1px solid #e2e2e2; }
.fsm-plot.pending::before { content: "drawing…"; color: #999; display: block; padding: 1em; }
figcaption { font-size: 0.9em; color: #333; margin-top: .4em; }
.note { border-left: 4px solid #d9a400; background: #fff8e1; padding: .4em .8em; margin: .6em 0;
        font-size: 0.92em; }
.meta { color: #666; font-size: 0.85em; }
.verdict { border: 2px solid #345; border-radius: 6px; padding: .6em 1em; margin: .6em 0 1em 0; }
.verdict h2 { margin-top: .2em; border: none; }
.verdict table { width: 100%; }
.pass { color: #1b7e1b; font-weight: bold; }
.fail { color: #b00020; font-weight: bold; }
.info { color: #555; font-weight: bold; }
.skips li { margin: .15em 0; }
nav ul.toc { columns: 2; font-size: .92em; list-style: none; padding-left: 0; }
@media print { nav, .modebar-container { display: none !important; }
               body { max-width: none; } h2 { page-break-before: auto; } }
"""

# Lazy drawing: plots near the screen first, the rest one per idle slot; the
# page records its progress in window.fsmbenchFigures (read by the tests).
_SCRIPT = """
(function () {
  var plots = Array.prototype.slice.call(document.querySelectorAll('div.fsm-plot'));
  var state = window.fsmbenchFigures = {total: plots.length, rendered: 0, failed: 0};
  var config = {responsive: true, displaylogo: false, scrollZoom: false,
                toImageButtonOptions: {format: 'svg'}};
  var pending = new Set(plots);
  function draw(div) {
    if (!pending.has(div)) { return Promise.resolve(); }
    pending.delete(div);
    var spec;
    try { spec = JSON.parse(document.getElementById(div.dataset.spec).textContent); }
    catch (e) { return Promise.resolve(fail(div, e)); }
    spec.data.forEach(function (trace) {
      ['x', 'y'].forEach(function (k) {
        if (trace[k] && trace[k].ref !== undefined) { trace[k] = spec.arrays[trace[k].ref]; }
      });
    });
    return Plotly.newPlot(div, spec.data, spec.layout, config).then(function () {
      if (window.fsmbenchZoom) { window.fsmbenchZoom(div, spec); }
      div.classList.remove('pending'); div.dataset.rendered = '1'; state.rendered += 1;
    }, function (e) { fail(div, e); });
  }
  function fail(div, e) {
    state.failed += 1; div.classList.remove('pending');
    div.textContent = 'This figure could not be drawn: ' + e;
    console.error('fsmbench figure ' + div.id + ': ' + e);
  }
  var seen = new IntersectionObserver(function (entries) {
    entries.forEach(function (e) {
      if (e.isIntersecting) { seen.unobserve(e.target); draw(e.target); }
    });
  }, {rootMargin: '600px 0px'});
  plots.forEach(function (d) { seen.observe(d); });
  function idle() {
    var next = pending.values().next();
    if (next.done) { return; }
    draw(next.value).then(function () { setTimeout(idle, 0); });
  }
  window.addEventListener('load', function () { setTimeout(idle, 200); });
})();
"""


def _slug(text: str) -> str:
    return "".join(c.lower() if c.isalnum() else "-" for c in text).strip("-")


def _script_json(payload: Any) -> str:
    """JSON safe inside a <script> element."""
    return json.dumps(payload, separators=(",", ":"), allow_nan=False).replace("</", "<\\/")


def _text(text: str) -> str:
    """Escaped text, with each cited erratum linked to the appendix."""
    return link_citations(html.escape(text))


def _table(tab: Table, out: list[str]) -> None:
    out.append("<table>")
    out.append(f"<caption>{_text(tab.caption)}</caption>")
    out.append("<thead><tr>" + "".join(f"<th>{html.escape(h)}</th>" for h in tab.header)
               + "</tr></thead><tbody>")
    for row in tab.rows:
        out.append("<tr>" + "".join(f"<td>{_text(c)}</td>" for c in row) + "</tr>")
    out.append("</tbody></table>")
    if tab.note:
        out.append(f'<div class="note">{_text(tab.note)}</div>')


@dataclass(frozen=True)
class _Spec:
    """A figure's plotly spec as the page embeds it, and its height [px]."""

    text: str
    height_px: int


def _spec(fig: Figure) -> _Spec:
    spec = figure_json(fig)
    return _Spec(_script_json(spec), spec["layout"]["height"])


def _points(fig: Figure) -> int:
    """A figure's samples: what its spec costs (decimation, bands, encoding)."""
    return sum(t.x.size for p in fig.panels for t in p.traces if isinstance(t, Line))


def _specs(figures: Sequence[Figure], *, parallel: bool) -> dict[str, _Spec]:
    """Each figure's spec, by key; with ``parallel`` about half of the samples' figures are
    encoded in a forked process (:mod:`fsmbench.forked`): the same text."""
    share = child_share({f.key: _points(f) for f in figures})
    job = start_forked(lambda _say: {f.key: _spec(f) for f in figures if f.key in share},
                       progress=lambda _msg: None, parallel=parallel and bool(share))
    try:
        # Run here, the job makes its share when its result is taken: every spec once.
        mine = {f.key: _spec(f) for f in figures if not job.forked or f.key not in share}
        theirs = job.result() if job.forked else {}
    finally:
        job.cancel()
    return {**mine, **theirs}


@dataclass(frozen=True, eq=False)
class EncodedFigures:
    """Figures encoded for the page ahead of it (:func:`encode_figures`), each kept with
    the figure it encodes: :func:`render_report` uses a spec only for that same figure
    object, and encodes any other."""

    _specs: Mapping[str, tuple[Figure, _Spec]]

    def spec(self, fig: Figure) -> _Spec | None:
        """``fig``'s spec when it was encoded here (the same object), else None."""
        hit = self._specs.get(fig.key)
        return hit[1] if hit is not None and hit[0] is fig else None


def encode_figures(sections: Sequence[Section]) -> EncodedFigures:
    """The figures of ``sections`` encoded as :func:`render_report` embeds them, in this
    process, for a page whose other parts are not known yet (the study encodes its
    chapters while its last stage runs elsewhere).

    Parameters
    ----------
    sections : sequence of Section
        Sections that will be on the page, unchanged (their figures, the same objects).
    """
    return EncodedFigures({f.key: (f, _spec(f)) for f in _figures(sections)})


def _figure(fig: Figure, number: int, out: list[str], spec: _Spec) -> None:
    ref = f" (ESRF study {fig.seed_ref})" if fig.seed_ref else ""
    out.append(f'<figure id="fig-{fig.key}">')
    out.append(f'<div class="fsm-plot pending" id="plot-{fig.key}" data-spec="spec-{fig.key}" '
               f'style="height:{spec.height_px}px"></div>')
    out.append(f'<script type="application/json" id="spec-{fig.key}">{spec.text}</script>')
    out.append(f"<figcaption><b>Figure {number}. {html.escape(fig.title)}</b>"
               f"{html.escape(ref)}. {_text(fig.caption)}</figcaption>")
    if fig.note:
        out.append(f'<div class="note">{_text(fig.note)}</div>')
    out.append("</figure>")


def _section(sec: Section, level: int, out: list[str], counter: list[int],
             specs: Mapping[str, _Spec]) -> None:
    anchor = sec.anchor or _slug(sec.title)
    out.append(f'<h{level} id="{html.escape(anchor)}">{html.escape(sec.title)}</h{level}>')
    for block in sec.blocks:
        if isinstance(block, str):
            out.append(f"<p>{_text(block)}</p>")
        elif isinstance(block, Table):
            _table(block, out)
        elif isinstance(block, Note):
            ref = f" ({block.ref})" if block.ref else ""
            out.append(f'<div class="note">{_text(block.text)}{_text(ref)}</div>')
        else:
            counter[0] += 1
            _figure(block, counter[0], out, specs[block.key])
    for sub in sec.subsections:
        _section(sub, min(level + 1, 6), out, counter, specs)


def render_report(*, title: str, sections: Sequence[Section], verdict_html: str = "",
                  summary: Mapping[str, Any] | None = None, meta: Sequence[str] = (),
                  parallel: bool = False, encoded: EncodedFigures | None = None) -> str:
    """The whole report as one HTML string.

    Parameters
    ----------
    title : str
    sections : sequence of Section
    verdict_html : str
        The verdict block (trusted HTML built by :mod:`fsmbench.report.summary`),
        shown first.
    summary : mapping, optional
        Embedded as ``<script type="application/json" id="fsmbench-summary">``.
    meta : sequence of str
        Lines under the title (source, version).
    parallel : bool
        Encode about half of the figures in a forked process (:mod:`fsmbench.forked`):
        the same page.
    encoded : EncodedFigures, optional
        Figures of ``sections`` already encoded (:func:`encode_figures`): the same page,
        the others encoded now.
    """
    keys = [f.key for f in _figures(sections)]
    dup = sorted({k for k in keys if keys.count(k) > 1})
    if dup:
        raise ValueError(f"figure keys used twice: {', '.join(dup)}")
    out = ["<!DOCTYPE html>", '<html lang="en">', "<head>", '<meta charset="utf-8">',
           '<meta name="viewport" content="width=device-width, initial-scale=1">',
           f"<title>{html.escape(title)}</title>", f"<style>{_STYLE}</style>", "</head>",
           "<body>", f"<h1>{html.escape(title)}</h1>"]
    for line in meta:
        out.append(f'<p class="meta">{html.escape(line)}</p>')
    if summary is not None:
        out.append(f'<script type="application/json" id="fsmbench-summary">'
                   f"{_script_json(summary)}</script>")
    verdict = link_citations(verdict_html)
    out.append(verdict)
    counter = [0]
    body: list[str] = []
    ready = {f.key: spec for f in _figures(sections)
             if encoded is not None and (spec := encoded.spec(f)) is not None}
    specs = {**ready, **_specs([f for f in _figures(sections) if f.key not in ready],
                               parallel=parallel)}
    for sec in sections:
        _section(sec, 2, body, counter, specs)
    # The appendix of the errata the report cites (each citation links to its entry).
    cited = cited_errata([re.sub(r"<[^>]+>", "", "".join([verdict, *body]))])
    toc = [(sec.anchor or _slug(sec.title), sec.title) for sec in sections]
    if cited:
        toc.append(("errata", ERRATA_TITLE))
        body += [f'<h2 id="errata">{ERRATA_TITLE}</h2>', errata_appendix(cited)]
    # The titles carry their own numbers ("1. The bench"): an unnumbered list.
    out.append('<nav><b>Contents</b><ul class="toc">')
    for anchor, text in toc:
        out.append(f'<li><a href="#{html.escape(anchor)}">{html.escape(text)}</a></li>')
    out.append("</ul></nav>")
    out.extend(body)
    if counter[0]:
        out.append(f"<script>{plotly_js()}</script>")
        out.append(f"<script>{ZOOM_JS}</script>")
        out.append(f"<script>{_SCRIPT}</script>")
    out.extend(["</body>", "</html>"])
    return "\n".join(out) + "\n"


def write_report(path: str | Path, *, title: str, sections: Sequence[Section],
                 verdict_html: str = "", summary: Mapping[str, Any] | None = None,
                 meta: Sequence[str] = (), parallel: bool = False,
                 encoded: EncodedFigures | None = None) -> Path:
    """Render and write the report atomically (see :func:`render_report`); returns its path."""
    return atomic_write_text(Path(path), render_report(
        title=title, sections=sections, verdict_html=verdict_html, summary=summary, meta=meta,
        parallel=parallel, encoded=encoded))
