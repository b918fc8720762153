"""The report in a real browser: Debian's Chromium, headless, driven by Playwright.

What a reader does: open the page (no console error), see the verdict in the
first screen, see every figure drawn, zoom into a Bode plot; and what a
script does: read the embedded summary, the same as ``summary.json``.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from fsmbench.study import StudyResult

playwright_api = pytest.importorskip("playwright.sync_api")




class Page:
    """A loaded report and every console error it raised."""

    def __init__(self, browser: Any, path: Path) -> None:
        self.page = browser.new_page(viewport={"width": 1280, "height": 1000})
        self.errors: list[str] = []
        self.requests: list[str] = []
        self.page.on("request", lambda r: self.requests.append(r.url))
        self.page.on("console",
                     lambda m: self.errors.append(m.text) if m.type == "error" else None)
        self.page.on("pageerror", lambda e: self.errors.append(str(e)))
        self.page.goto(path.as_uri())

    def wait_all_drawn(self) -> dict[str, int]:
        # Figures near the screen are drawn first, the rest in idle time.
        self.page.wait_for_function(
            "window.fsmbenchFigures && window.fsmbenchFigures.rendered"
            " + window.fsmbenchFigures.failed === window.fsmbenchFigures.total",
            timeout=180_000)
        state: dict[str, int] = self.page.evaluate("window.fsmbenchFigures")
        return state


@pytest.fixture(scope="module")
def twin_page(browser: Any, twin_study: StudyResult) -> Iterator[Page]:
    page = Page(browser, Path(twin_study.report))
    yield page
    page.page.close()


def test_every_figure_is_drawn_without_a_console_error(twin_page: Page) -> None:
    state = twin_page.wait_all_drawn()
    assert state["failed"] == 0
    assert state["total"] >= 30  # every chapter has its figures
    empty = twin_page.page.evaluate("""() => {
        const bad = [];
        for (const div of document.querySelectorAll('div.fsm-plot')) {
            // _length: the points plotly.js decoded from the typed arrays.
            const traces = (div._fullData || []).filter(t => (t._length || 0) > 0);
            const drawn = div.querySelectorAll('.main-svg').length > 0;
            if (!drawn || traces.length === 0) bad.push(div.id);
        }
        return bad;
    }""")
    assert empty == []
    assert twin_page.errors == []
    # Self-contained: the page asked for nothing but itself (and inline data).
    assert {u for u in twin_page.requests if not u.startswith("data:")} == {
        Path(twin_page.page.url[len("file://"):]).as_uri()}


def test_the_verdict_is_in_the_first_screen(twin_page: Page, twin_study: StudyResult) -> None:
    box = twin_page.page.locator("#verdict").bounding_box()
    assert box is not None and box["y"] < 1000
    verdict = twin_page.page.locator("#verdict h2").inner_text()
    assert twin_study.summary is not None
    assert verdict == twin_study.summary.verdict


def test_the_embedded_summary_is_summary_json(twin_page: Page, twin_study: StudyResult) -> None:
    embedded = json.loads(twin_page.page.locator("#fsmbench-summary").text_content() or "")
    on_disk = json.loads((Path(twin_study.out_dir) / "summary.json").read_text())
    assert embedded == on_disk
    assert embedded["format"] == "fsmbench.summary"
    assert {r["name"] for r in embedded["requirements"]} >= {
        "distance_error_budget", "control_objective", "gain_margin", "phase_margin",
        "closed_loop_simulation", "model_validation"}


def test_zooming_a_bode_plot_changes_its_frequency_range(twin_page: Page) -> None:
    twin_page.wait_all_drawn()
    page = twin_page.page
    plot_id = page.evaluate(r"""() => {
        for (const div of document.querySelectorAll('div.fsm-plot')) {
            const l = div._fullLayout;
            if (!(l && l.xaxis && l.xaxis.type === 'log' && l.yaxis.type === 'log')) continue;
            // A Bode plot: log magnitude with a linear phase panel below.
            const phase = Object.keys(l).filter(k => /^yaxis\d+$/.test(k))
                .some(k => l[k].type === 'linear' && /Phase/.test(l[k].title.text));
            if (phase) return div.id;
        }
        return null;
    }""")
    assert plot_id is not None, "no Bode plot (log magnitude over linear phase) in the report"
    plot = page.locator(f"#{plot_id}")
    plot.scroll_into_view_if_needed()
    before = page.evaluate(f"document.getElementById('{plot_id}')._fullLayout.xaxis.range")
    drag = plot.locator(".draglayer .xy .nsewdrag").first
    box = drag.bounding_box()
    assert box is not None
    x0, y0 = box["x"] + 0.35 * box["width"], box["y"] + 0.3 * box["height"]
    x1, y1 = box["x"] + 0.55 * box["width"], box["y"] + 0.7 * box["height"]
    page.mouse.move(x0, y0)
    page.mouse.down()
    page.mouse.move((x0 + x1) / 2, (y0 + y1) / 2, steps=5)
    page.mouse.move(x1, y1, steps=5)
    page.mouse.up()
    page.wait_for_timeout(300)
    after = page.evaluate(f"document.getElementById('{plot_id}')._fullLayout.xaxis.range")
    # A box zoom over 20 % of the width narrows the decades shown to about a fifth.
    assert after[1] - after[0] < 0.5 * (before[1] - before[0])
    assert before[0] < after[0] < after[1] < before[1]


def test_a_broken_file_is_named_in_the_first_screen(browser: Any,
                                                    broken_study: StudyResult) -> None:
    page = Page(browser, Path(broken_study.report))
    verdict = page.page.locator("#verdict").inner_text()
    assert "data_unh" in verdict and "NaN" in verdict
    page.wait_all_drawn()
    assert page.errors == []
    page.page.close()


def test_rules_and_labels_sit_at_their_values_on_log_axes(browser: Any, tmp_path: Path) -> None:
    # plotly.js takes shapes in data units but annotations in decades on a log axis: a
    # rule at 100 must be drawn at 10², its label beside it, the axis not stretched.
    import numpy as np

    from fsmbench.report.figures.spec import Figure, Label, Line, Panel, Rule
    from fsmbench.report.html import Section, render_report

    f = np.logspace(0, 3, 50)
    fig = Figure(key="log_rules", title="t", caption="", panels=(Panel(
        traces=(Line(f, f, name="y = x"),), x_label="x [1]", y_label="y [1]", x_log=True,
        y_log=True, rules=(Rule(100.0, name="y = 100"),), labels=(Label(30.0, 30.0, "here"),)),))
    path = tmp_path / "log.html"
    path.write_text(render_report(title="t", sections=[Section(title="s", blocks=(fig,))]))
    page = Page(browser, path)
    page.wait_all_drawn()
    got = page.page.evaluate("""() => {
        const div = document.getElementById('plot-log_rules');
        const ya = div._fullLayout.yaxis, xa = div._fullLayout.xaxis;
        const d = div.querySelector('.shapelayer path').getAttribute('d');
        const y = parseFloat(d.split(',')[1]);
        const ann = div._fullLayout.annotations.find(a => a.text === 'here');
        return {range: ya.range, shape_y: y, expect_y: ya._offset + ya.l2p(2),
                ann_x: ann.x, ann_y: ann.y, xrange: xa.range};
    }""")
    assert got["range"][1] < 3.2 and got["xrange"][1] < 3.2  # nothing stretched to 10^100
    assert abs(got["shape_y"] - got["expect_y"]) < 1.0  # one pixel: rounding of the path
    assert got["ann_x"] == pytest.approx(np.log10(30.0)) and got["ann_y"] == pytest.approx(
        np.log10(30.0))
    assert page.errors == []
    page.page.close()
