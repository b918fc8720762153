"""The errata of the ESRF study: one table, an appendix of the cited ones, linked citations."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fsmbench.report.errata import cited_errata, link_citations, load_errata
from fsmbench.report.html import ERRATA_TITLE, Note, Section, render_report
from fsmbench.study import StudyResult

ROOT = Path(__file__).resolve().parents[2]


def test_the_errata_are_one_table_in_the_docs_and_the_package() -> None:
    """``docs/seed-errata.md`` is the package's file: one copy, read by the report."""
    from importlib import resources

    packaged = Path(str(resources.files("fsmbench.report").joinpath("seed_errata.md")))
    assert (ROOT / "docs" / "seed-errata.md").resolve() == packaged.resolve()
    errata = load_errata()
    # Every row parsed into its five columns, the ids numbered without a gap.
    assert list(errata) == [f"E{i}" for i in range(1, len(errata) + 1)]
    assert all(e.section and e.study_says and e.derivation for e in errata.values())


@pytest.mark.parametrize(("text", "ids"), [
    ("(errata E27)", ["E27"]),
    ("ref errata E1–E3", ["E1", "E2", "E3"]),
    ("errata E15, E18 and E31", ["E15", "E18", "E31"]),
    ("ESRF study 9.2 (E27 is not a citation without the word)", []),
])
def test_citations_are_found_in_the_errata_order(text: str, ids: list[str]) -> None:
    assert cited_errata([text]) == ids


@pytest.mark.parametrize("text", [
    "errata E2", "xerrata E2 errata E3", "errata errata E4", "errata E5errata E6",
    "_errata E7 (errata E8–E9), errata", "erratum E10 and E11 errata E1 – E2",
    "errata\nerrata E12", "noerrata E3, errata E1,E2"])
def test_citations_found_from_each_errat_are_the_regex_s_own(text: str) -> None:
    """The search starts at each "errat" only: the same matches as the regex scanning
    every position (word boundaries included)."""
    from fsmbench.report import errata

    assert ([m.span() for m in errata._citations(text)]
            == [m.span() for m in errata._CITATION.finditer(text)])


def test_each_citation_links_to_its_entry_and_only_cited_entries_are_listed() -> None:
    sections = [Section(title="1. One", blocks=("A paragraph citing errata E15.",
                                                 Note("A note.", ref="errata E1–E3")))]
    page = render_report(title="t", sections=sections)
    listed = re.findall(r'<tr id="erratum-(E\d+)">', page)
    assert listed == ["E1", "E2", "E3", "E15"]
    for key in ("E1", "E3", "E15"):
        assert f'<a href="#erratum-{key}">{key}</a>' in page
    assert f'<h2 id="errata">{ERRATA_TITLE}</h2>' in page
    # The contents list each section once, with the title's own number only.
    assert '<ul class="toc">' in page and "<ol>" not in page
    assert link_citations("no citation here") == "no citation here"


def test_a_report_citing_nothing_has_no_errata_appendix() -> None:
    page = render_report(title="t", sections=[Section(title="1. One", blocks=("Plain.",))])
    assert ERRATA_TITLE not in page


def test_clicking_a_citation_shows_its_entry(browser: Any, twin_study: StudyResult) -> None:
    pg = browser.new_page(viewport={"width": 1280, "height": 900})
    pg.goto(Path(twin_study.report).as_uri())
    links = pg.locator('p a[href^="#erratum-"]')
    assert links.count() > 0
    target = links.first.get_attribute("href")
    links.first.click()
    row = pg.locator(f"tr{target}")
    assert row.is_visible() and row.bounding_box()["y"] < 900  # scrolled into view
    assert row.inner_text().startswith(target.removeprefix("#erratum-"))
    pg.close()


@given(st.lists(st.sampled_from(["errata", "erratum", " ", "E", "1", "27", ",", "–", "-",
                                 "and", "x", "_", "\n", "(", "errat"]), max_size=30))
def test_citations_found_from_each_errat_are_the_regex_s_own_on_any_text(
        parts: list[str]) -> None:
    from fsmbench.report import errata

    text = "".join(parts)
    assert ([m.span() for m in errata._citations(text)]
            == [m.span() for m in errata._CITATION.finditer(text)])
