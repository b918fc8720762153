"""The self-contained HTML report: blocks in reading order, escaped, nothing from elsewhere."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from fsmbench.forked import fork_available
from fsmbench.report.figures.spec import Figure, Line, Panel
from fsmbench.report.html import (
    Note,
    Section,
    Table,
    encode_figures,
    iter_figures,
    render_report,
    write_report,
)
from fsmbench.study import StudyResult


def _figure(key: str = "fig8_test") -> Figure:
    return Figure(key=key, title="A <figure>", caption="x & y", seed_ref="Fig. 8",
                  panels=(Panel(traces=(Line(np.arange(3.0), np.arange(3.0), name="a</script>"),),
                                x_label="Time [s]", y_label="Vph [V]"),))


def _section() -> Section:
    return Section(title="Results & <more>", blocks=(
        "a < b", Table(caption="t", header=("k", "v"), rows=(("<k>", "1"),)), _figure(),
        Note("odd & explained", ref="errata E1"), "after the figure"),
        subsections=(Section(title="Sub", blocks=(_figure("fig9_sub"),)),))


def test_report_is_self_contained_escaped_and_in_reading_order(tmp_path: Path) -> None:
    path = write_report(tmp_path / "r.html", title="T & T", sections=[_section()],
                        summary={"verdict": "</script><b>"})
    text = path.read_text()
    # Nothing is loaded from elsewhere (plotly.js itself names URLs in strings; the browser
    # test checks that the page requests nothing but itself).
    markup = re.sub(r"<script>.*?</script>", "", text, flags=re.S)
    assert "src=" not in markup and "<link" not in markup and "@import" not in markup
    assert "a &lt; b" in text and "&lt;k&gt;" in text and "Results &amp; &lt;more&gt;" in text
    # Blocks keep their order: paragraph, table, figure, note, paragraph.
    order = [text.index(s) for s in ("a &lt; b", "<caption>t</caption>", 'id="fig-fig8_test"',
                                     "odd &amp; explained (errata <a "
                                     "href=\"#erratum-E1\">E1</a>)", "after the figure")]
    assert order == sorted(order)
    assert "<h3" in text and "(ESRF study Fig. 8)" in text and "Figure 2. A &lt;figure&gt;" in text
    # JSON inside <script> cannot close it early: "</" is escaped, and it parses back.
    for payload in re.findall(r'<script type="application/json" id="[^"]+">(.*?)</script>', text,
                              flags=re.S):
        assert "</" not in payload
        json.loads(payload)
    # One table, and the appendix of the errata it cites: header rows repeat across pages.
    assert text.count("<thead>") == 2


def test_plotly_is_embedded_once_and_only_with_figures() -> None:
    with_figs = render_report(title="T", sections=[_section()])
    assert with_figs.count("plotly.js v") == 1
    assert "plotly.js" not in render_report(title="T", sections=[Section(title="S",
                                                                         blocks=("p",))])


def test_figure_keys_must_be_unique() -> None:
    sec = Section(title="S", blocks=(_figure("same"), _figure("same")))
    with pytest.raises(ValueError, match="figure keys used twice: same"):
        render_report(title="T", sections=[sec])


def test_iter_figures_walks_subsections_in_order() -> None:
    assert [f.key for f in iter_figures([_section()])] == ["fig8_test", "fig9_sub"]


def test_table_rows_must_match_the_header() -> None:
    with pytest.raises(ValueError, match=r"row .* has 1 cells, header has 2"):
        Table(caption="bad", header=("a", "b"), rows=(("x",),))


def test_render_is_a_pure_function() -> None:
    sec = _section()
    assert render_report(title="T", sections=[sec]) == render_report(title="T", sections=[sec])


@pytest.mark.skipif(not fork_available(), reason="needs fork and two cores")
def test_figures_encoded_two_by_two_make_the_same_page(twin_study: StudyResult) -> None:
    """About half of the figures' samples are encoded in a forked process: the page is the
    one encoded here, byte for byte."""
    pages = [render_report(title="study", sections=twin_study.sections, summary={"a": 1},
                           parallel=parallel) for parallel in (False, True)]
    assert pages[0] == pages[1]
    assert pages[0].count('type="application/json" id="spec-') == len(
        list(iter_figures(twin_study.sections)))


def test_figures_encoded_ahead_make_the_same_page() -> None:
    """The study encodes its chapters while its last stage runs, then adds one: the page
    is the one encoded at once, and a figure that is not the object encoded (the same key,
    other data) is encoded anew, never given another's spec."""
    first, later = _section(), Section(title="Later", blocks=(_figure("fig10_later"),))
    ahead = encode_figures([first])
    whole = render_report(title="T", sections=[first, later])
    assert render_report(title="T", sections=[first, later], encoded=ahead) == whole
    changed = Figure(key="fig8_test", title="A <figure>", caption="x & y", seed_ref="Fig. 8",
                     panels=(Panel(traces=(Line(np.arange(3.0), np.arange(3.0) + 1.0,
                                                name="a</script>"),),
                                   x_label="Time [s]", y_label="Vph [V]"),))
    other = Section(title=first.title, blocks=(changed,))
    assert (render_report(title="T", sections=[other], encoded=ahead)
            == render_report(title="T", sections=[other]))
