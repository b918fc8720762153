"""The self-contained HTML report."""

from __future__ import annotations

import base64
import re
from pathlib import Path

import matplotlib.pyplot as plt
import pytest

from fsmbench.report.html import Section, Table, figure_from_matplotlib, render_report, write_report


def _figure() -> Section:
    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])
    ax.set_xlabel("Time [s]")
    embedded = figure_from_matplotlib(fig, title="A <figure>", caption="x & y", seed_ref="Fig. 8")
    return Section(title="Results & <more>", paragraphs=("a < b",),
                   tables=(Table(caption="t", header=("k", "v"), rows=(("<k>", "1"),)),),
                   figures=(embedded,), subsections=(Section(title="Sub"),))


def test_report_is_self_contained_and_escaped(tmp_path: Path) -> None:
    path = write_report(tmp_path / "r.html", title="T & T", sections=[_figure()], meta=("m",))
    text = path.read_text()
    assert "<script" not in text and "http://" not in text and "https://" not in text
    assert "a &lt; b" in text and "&lt;k&gt;" in text and "Results &amp; &lt;more&gt;" in text
    (png,) = re.findall(r"data:image/png;base64,([A-Za-z0-9+/=]+)", text)
    assert base64.b64decode(png).startswith(b"\x89PNG\r\n\x1a\n")  # a real PNG
    assert '<a href="#results----more">' in text  # navigation to the section
    assert "<h3" in text and "(seed Fig. 8)" in text


def test_table_rows_must_match_the_header() -> None:
    with pytest.raises(ValueError, match=r"row .* has 1 cells, header has 2"):
        Table(caption="bad", header=("a", "b"), rows=(("x",),))


def test_render_is_a_pure_function() -> None:
    sec = Section(title="S", paragraphs=("p",))
    assert render_report(title="T", sections=[sec]) == render_report(title="T", sections=[sec])
