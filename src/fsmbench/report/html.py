"""A self-contained HTML report: sections, tables and figures embedded as PNG.

The file opens offline: no scripts, no external style sheets or images.
Text is escaped; figures are base64 ``data:`` URIs.
"""

from __future__ import annotations

import base64
import html
import io
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from matplotlib.figure import Figure as MplFigure

from fsmbench.io.atomic import atomic_write_text

__all__ = ["Figure", "Section", "Table", "figure_from_matplotlib", "render_report", "write_report"]


@dataclass(frozen=True)
class Figure:
    """An embedded figure.

    Attributes
    ----------
    title : str
    caption : str
    png_base64 : str
        PNG image, base64-encoded.
    seed_ref : str
        The seed's figure this corresponds to (e.g. ``"Fig. 8"``), or "".
    """

    title: str
    caption: str
    png_base64: str
    seed_ref: str = ""


@dataclass(frozen=True)
class Table:
    """A table of text cells; ``header`` and every row have the same length."""

    caption: str
    header: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]

    def __post_init__(self) -> None:
        for row in self.rows:
            if len(row) != len(self.header):
                raise ValueError(f"table '{self.caption}': row {row} has {len(row)} cells, "
                                 f"header has {len(self.header)}")


@dataclass(frozen=True)
class Section:
    """A report section: paragraphs, then tables, then figures, then subsections."""

    title: str
    paragraphs: tuple[str, ...] = ()
    tables: tuple[Table, ...] = ()
    figures: tuple[Figure, ...] = ()
    subsections: tuple[Section, ...] = field(default=())
    anchor: str = ""


def figure_from_matplotlib(fig: MplFigure, *, title: str, caption: str, seed_ref: str = "",
                           dpi: int = 110) -> Figure:
    """Render a matplotlib figure to an embeddable :class:`Figure` and close it."""
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    plt.close(fig)
    return Figure(title=title, caption=caption,
                  png_base64=base64.b64encode(buf.getvalue()).decode("ascii"), seed_ref=seed_ref)


_STYLE = """
body { font-family: -apple-system, "Segoe UI", Helvetica, Arial, sans-serif; max-width: 1100px;
       margin: 2em auto; padding: 0 1em; color: #222; line-height: 1.45; }
h1 { border-bottom: 2px solid #345; padding-bottom: .3em; }
h2 { border-bottom: 1px solid #ccc; margin-top: 2em; }
table { border-collapse: collapse; margin: 1em 0; font-size: 0.9em; }
th, td { border: 1px solid #bbb; padding: 3px 8px; text-align: left; vertical-align: top; }
th { background: #eef2f6; }
figure { margin: 1.5em 0; }
figure img { max-width: 100%; border: 1px solid #ddd; }
figcaption { font-size: 0.9em; color: #444; }
caption { caption-side: top; text-align: left; font-weight: bold; padding-bottom: .3em; }
nav ul { columns: 2; }
.meta { color: #666; font-size: 0.9em; }
"""


def _slug(text: str) -> str:
    return "".join(c.lower() if c.isalnum() else "-" for c in text).strip("-")


def _render_section(sec: Section, level: int, out: list[str]) -> None:
    anchor = sec.anchor or _slug(sec.title)
    out.append(f'<h{level} id="{html.escape(anchor)}">{html.escape(sec.title)}</h{level}>')
    for para in sec.paragraphs:
        out.append(f"<p>{html.escape(para)}</p>")
    for tab in sec.tables:
        out.append("<table>")
        out.append(f"<caption>{html.escape(tab.caption)}</caption>")
        out.append("<tr>" + "".join(f"<th>{html.escape(h)}</th>" for h in tab.header) + "</tr>")
        for row in tab.rows:
            out.append("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in row) + "</tr>")
        out.append("</table>")
    for fig in sec.figures:
        ref = f" (seed {fig.seed_ref})" if fig.seed_ref else ""
        out.append("<figure>")
        out.append(f'<img alt="{html.escape(fig.title)}" '
                   f'src="data:image/png;base64,{fig.png_base64}">')
        out.append(f"<figcaption><b>{html.escape(fig.title)}</b>{html.escape(ref)}. "
                   f"{html.escape(fig.caption)}</figcaption>")
        out.append("</figure>")
    for sub in sec.subsections:
        _render_section(sub, min(level + 1, 6), out)


def render_report(*, title: str, sections: Sequence[Section], meta: Sequence[str] = ()) -> str:
    """The whole report as one HTML string."""
    out = ["<!DOCTYPE html>", '<html lang="en">', "<head>", '<meta charset="utf-8">',
           f"<title>{html.escape(title)}</title>", f"<style>{_STYLE}</style>", "</head>", "<body>",
           f"<h1>{html.escape(title)}</h1>"]
    for line in meta:
        out.append(f'<p class="meta">{html.escape(line)}</p>')
    out.append("<nav><ul>")
    for sec in sections:
        out.append(f'<li><a href="#{html.escape(sec.anchor or _slug(sec.title))}">'
                   f"{html.escape(sec.title)}</a></li>")
    out.append("</ul></nav>")
    for sec in sections:
        _render_section(sec, 2, out)
    out.extend(["</body>", "</html>"])
    return "\n".join(out) + "\n"


def write_report(path: str | Path, *, title: str, sections: Sequence[Section],
                 meta: Sequence[str] = ()) -> Path:
    """Render and write the report atomically; returns its path."""
    return atomic_write_text(Path(path), render_report(title=title, sections=sections, meta=meta))
