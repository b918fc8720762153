"""The errata of the ESRF study, as the report's appendix, and links to them.

The errata are one table, ``seed_errata.md`` in this package (``docs/seed-errata.md``
is a link to it, so there is one copy). The report cites them as "(errata E27)" or
"errata E1–E3"; :func:`link_citations` turns each cited id into a link to its entry,
and :func:`errata_appendix` writes the entries the report cites, in order.
"""

from __future__ import annotations

import html
import re
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from functools import cache
from importlib import resources

__all__ = ["Erratum", "cited_errata", "errata_appendix", "link_citations", "load_errata"]

#: A citation: "errata" then ids, ranges and lists ("E1–E3", "E15, E18").
_CITATION = re.compile(r"\berrat(?:a|um) (E\d+(?:\s*(?:[–,-]|and)\s*E?\d+)*)")
_ID = re.compile(r"E?(\d+)")
_ROW = re.compile(r"^\|\s*(E\d+)\s*\|")


@dataclass(frozen=True)
class Erratum:
    """One entry: where the ESRF study errs, what it says, the derivation, what fsmbench does."""

    id: str
    section: str
    study_says: str
    derivation: str
    fsmbench: str


def _cells(line: str) -> list[str]:
    # Split on unescaped pipes; "\|" inside a cell is a literal bar.
    parts = re.split(r"(?<!\\)\|", line.strip())[1:-1]
    return [p.strip().replace("\\|", "|") for p in parts]


@cache
def load_errata() -> Mapping[str, Erratum]:
    """Every erratum of ``seed_errata.md``, keyed by id (``"E27"``)."""
    text = resources.files("fsmbench.report").joinpath("seed_errata.md").read_text("utf-8")
    out: dict[str, Erratum] = {}
    for line in text.splitlines():
        if _ROW.match(line):
            cells = _cells(line)
            if len(cells) != 5:
                raise ValueError(f"seed_errata.md: row {cells[:1]} has {len(cells)} cells, not 5")
            out[cells[0]] = Erratum(*cells)
    return out


def _expand(ids: str) -> list[str]:
    """``"E1–E3"`` → E1, E2, E3; ``"E15, E18"`` → E15, E18."""
    out: list[str] = []
    for part in re.split(r"\s*(?:,|and)\s*", ids):
        numbers = [int(n) for n in _ID.findall(part)]
        if len(numbers) == 2 and re.search(r"[–-]", part):
            out += [f"E{n}" for n in range(numbers[0], numbers[1] + 1)]
        else:
            out += [f"E{n}" for n in numbers]
    return out


def _citations(text: str) -> Iterator[re.Match[str]]:
    """``_CITATION.finditer(text)``, found from each "errat" ``str.find`` gives: the regex
    tried at every position of a 16 MB page took a second, this takes milliseconds."""
    pos = text.find("errat")
    while pos != -1:
        found = _CITATION.match(text, pos)  # its \b still sees the character before pos
        if found is not None:
            yield found
            pos = text.find("errat", found.end())
        else:
            pos = text.find("errat", pos + 1)


def cited_errata(texts: Iterable[str]) -> list[str]:
    """The ids cited in ``texts``, each once, in the errata's own order."""
    known = load_errata()
    cited = {e for t in texts for m in _citations(t) for e in _expand(m.group(1))}
    return [e for e in known if e in cited]


def link_citations(escaped: str) -> str:
    """HTML-escaped text with each cited erratum id made a link to its appendix entry."""
    known = load_errata()

    def ids(m: re.Match[str]) -> str:
        def one(n: re.Match[str]) -> str:
            key = f"E{n.group(1)}"
            return (f'<a href="#erratum-{key}">{n.group(0)}</a>' if key in known
                    else n.group(0))
        return m.group(0)[: m.start(1) - m.start(0)] + _ID.sub(one, m.group(1))

    return _CITATION.sub(ids, escaped)


def _code(text: str) -> str:
    """Markdown's `code` and **bold** in escaped HTML."""
    out = html.escape(text)
    out = re.sub(r"`([^`]+)`", r"<code>\1</code>", out)
    return re.sub(r"\*\*([^*]+)\*\*", r"<b>\1</b>", out)


def errata_appendix(ids: Iterable[str]) -> str:
    """The appendix's entries (trusted HTML), one per cited erratum, each with its anchor."""
    known = load_errata()
    rows = []
    for key in ids:
        e = known[key]
        rows.append(
            f'<tr id="erratum-{e.id}"><td><b>{e.id}</b></td><td>{_code(e.section)}</td>'
            f"<td>{_code(e.study_says)}</td><td>{_code(e.derivation)}</td>"
            f"<td>{_code(e.fsmbench)}</td></tr>")
    return ('<table class="errata"><caption>Where a derivation disagrees with the ESRF study: '
            "what the study says, the derivation, and what fsmbench uses and tests.</caption>"
            "<thead><tr><th>erratum</th><th>ESRF study section</th><th>the ESRF study says</th>"
            "<th>derivation</th><th>fsmbench</th></tr></thead><tbody>"
            + "".join(rows) + "</tbody></table>")
