"""Figures a controls engineer reads without friction (issue 22), checked as a reader sees them.

The study's report opened in headless Chromium (Debian's, driven by Playwright, as in
``test_browser.py``): phases unwrapped and continuous, sampled loops drawn up to the
Nyquist frequency only, compared panels on one axis, one legend entry per trace in
every panel, long records as bands that get finer on zoom and stay true to the
samples, no title struck through by a frame. Then, without a browser: the
conclusions that use only that band, one unit word for "dimensionless", exported
files named by the report's figure numbers, and the page's size.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from fsmbench.io.recording import read_recording
from fsmbench.report.figures.static import export_figures, render_matplotlib
from fsmbench.report.html import iter_figures, visible_text
from fsmbench.study import StudyResult

playwright_api = pytest.importorskip("playwright.sync_api")

# The twin's converters and controller run at 10 kHz: its loops end at 5 kHz.
NYQUIST_HZ = 5000.0
# Figures with a phase panel, and the figures of sampled quantities (loops, the plant the
# loop acts on, its controllers) that must end at the Nyquist frequency.
PHASE_FIGURES = ("fig18_22_sercalo_frf", "fig26_27_newport_frf", "fig28_newport_delay",
                 "fig41_seed_loop_gain", "fsmbench_controller_loop_gain",
                 "fig43_newport_loop_gain", "iff_uc_to_vp")
SAMPLED_FIGURES = ("fig41_seed_loop_gain", "fsmbench_controller_loop_gain",
                   "fig43_newport_loop_gain", "seed_controller_sensitivity",
                   "fsmbench_controller_sensitivity", "scaled_plant_and_disturbance",
                   "plant_rga_singular_values", "controllers_compared",
                   "seed_controller_robustness", "fsmbench_controller_robustness",
                   "fig42_newport_to_beam", "iff_uc_to_vp")
# The report's whole page (plotly.js's 4.6 MB included): 11.1 MB before long records
# carried their zoom pyramid, at most 21 bins of 4 bytes per pixel column of each; 16.13 MB
# with the figures a control engineer asked for (closed-loop step and disturbance
# responses, model against each record, model bands, the saturating step drawn as plain
# lines at 5 kHz): the budget keeps 2 % above that, so a figure that doubles is caught.
PAGE_BUDGET_BYTES = 16_500_000



@pytest.fixture(scope="module")
def page(browser: Any, twin_study: StudyResult) -> Iterator[Any]:
    """The twin study's report with every figure drawn, and no console error."""
    pg = browser.new_page(viewport={"width": 1280, "height": 1000})
    errors: list[str] = []
    pg.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    pg.on("pageerror", lambda e: errors.append(str(e)))
    pg.goto(Path(twin_study.report).as_uri())
    pg.wait_for_function("window.fsmbenchFigures && window.fsmbenchFigures.rendered"
                         " + window.fsmbenchFigures.failed === window.fsmbenchFigures.total",
                         timeout=180_000)
    assert pg.evaluate("window.fsmbenchFigures.failed") == 0
    yield pg
    assert errors == []
    pg.close()


# Every trace of a drawn figure: its name, group, legend flag, visibility, mode, fill, hover
# and data as drawn, with the titles of its axes.
TRACES_JS = """(key) => {
    const div = document.getElementById('plot-' + key);
    const L = div._fullLayout;
    return div._fullData.map((t) => {
        const xa = L['xaxis' + (t.xaxis === 'x' ? '' : t.xaxis.slice(1))];
        const ya = L['yaxis' + (t.yaxis === 'y' ? '' : t.yaxis.slice(1))];
        return {name: t.name, group: t.legendgroup, legend: t.showlegend,
                visible: t.visible, mode: t.mode, fill: t.fill, hover: t.hovertemplate,
                x: Array.from(t.x || []), y: Array.from(t.y || []),
                xaxis: t.xaxis, yaxis: t.yaxis, ytitle: ya.title.text.replace(/<br>/g, ' '),
                xtitle: xa.title.text,
                xrange: xa.range, xtype: xa.type, yrange: ya.range};
    });
}"""


def _traces(page: Any, key: str) -> list[dict[str, Any]]:
    traces: list[dict[str, Any]] = page.evaluate(TRACES_JS, key)
    for t in traces:
        for k in ("x", "y"):
            t[k] = np.array([np.nan if v is None else v for v in t[k]], dtype=float)
    return traces


def test_phase_is_unwrapped_and_continuous(page: Any) -> None:
    for key in PHASE_FIGURES:
        phase = [t for t in _traces(page, key) if "Phase" in t["ytitle"] and t["mode"] == "lines"]
        assert phase, key
        for t in phase:
            step = np.abs(np.diff(t["y"]))
            step = step[np.isfinite(step)]
            assert step.size, (key, t["name"])
            # Consecutive drawn points never jump by more than half a turn (float32
            # rounding of phases up to ~1e3°: 1e-4°).
            assert step.max() <= 180.0 + 1e-3, (key, t["name"], step.max())
    for key in ("fig18_22_sercalo_frf", "fig26_27_newport_frf"):
        traces = _traces(page, key)
        assert {t["ytitle"] for t in traces if "Phase" in t["ytitle"]} == {
            "Phase, delay removed [deg]"}
        # Where the measured phase is drawn it follows the model's branch: a direct path's
        # measured line is within 45° of its model (10° of noise, a model that fits).
        for out, inp in (("Vph", "Uch"), ("Vpv", "Ucv"), ("Vph", "Unh"), ("Vpv", "Unv")):
            panel = [t for t in traces if "Phase" in t["ytitle"]
                     and t["name"] in (f"measured, from {inp}", "fitted model",
                                       "second order (model)")]
            by_axis: dict[str, list[dict[str, Any]]] = {}
            for t in panel:
                by_axis.setdefault(t["yaxis"], []).append(t)
            for group in by_axis.values():
                measured = [t for t in group if t["name"].startswith("measured")]
                model = [t for t in group if not t["name"].startswith("measured")]
                if not (measured and model):
                    continue
                both = np.isfinite(measured[0]["y"]) & np.isfinite(model[0]["y"])
                if both.any():
                    gap = np.abs(measured[0]["y"][both] - model[0]["y"][both])
                    # Loose enough for the 4QD's own noise at the band's ends.
                    assert np.median(gap) < 45.0, (key, inp, out, np.median(gap))


def test_loop_phase_is_drawn_over_the_band_of_its_magnitude(page: Any,
                                                            twin_study: StudyResult) -> None:
    res = twin_study.design.result
    for key, lp in (("fig41_seed_loop_gain", res.seed), ("fsmbench_controller_loop_gain",
                                                         res.fsmbench),
                    ("fig43_newport_loop_gain", res.newport)):
        traces = _traces(page, key)
        mag = [t for t in traces if t["ytitle"].endswith("[dB]") and t["x"].size > 2]
        phase = [t for t in traces if "Phase" in t["ytitle"] and t["x"].size > 2]
        for m_t, t, axis in zip(mag, phase, "hv", strict=True):
            m = lp.axes[axis].margins
            f = t["x"][np.isfinite(t["y"])]
            # the magnitude's band, as drawn (float32-rounded)
            assert f.min() == pytest.approx(m_t["x"].min(), rel=1e-6), (key, axis)
            assert f.max() == pytest.approx(m_t["x"].max(), rel=1e-6), (key, axis)
            assert f.max() <= NYQUIST_HZ * (1 + 1e-6)
            # The phase at the crossover reads the phase margin (the grid's resolution,
            # 1 % of frequency around a crossover, moves the phase by well under 2°).
            at = float(np.interp(np.log(m.crossover_hz), np.log(t["x"]), t["y"]))
            assert at + 180.0 == pytest.approx(m.phase_margin_deg, abs=2.0), (key, axis)
            # the magnitude axis is in dB, linear
            assert m_t["ytitle"] == f"|L{axis}| [dB]"


def test_sampled_quantities_end_at_the_nyquist_frequency(page: Any) -> None:
    for key in SAMPLED_FIGURES:
        traces = _traces(page, key)
        assert traces, key
        for t in traces:
            assert t["xtype"] == "log", key
            f = t["x"][np.isfinite(t["x"])]
            # float32 storage rounds 5000 Hz by at most 2.4e-4 Hz.
            assert f.max() <= NYQUIST_HZ * (1 + 1e-6), (key, t["name"], f.max())
            # The axis ends there too (its range is in decades on a log axis).
            assert t["xrange"][1] <= np.log10(NYQUIST_HZ) + 1e-6, (key, t["xrange"])


def test_conclusions_use_only_the_band_below_nyquist(twin_study: StudyResult) -> None:
    res = twin_study.design.result
    pa = res.plant
    assert pa.nyquist_hz == NYQUIST_HZ
    assert pa.f_hz.max() <= NYQUIST_HZ
    above = pa.scaled_disturbance_gain > 1.0
    short = above & (pa.scaled_min_singular_value < pa.scaled_disturbance_gain - 1.0)
    assert pa.inputs_suffice == (not short.any())
    # The sentence names where the commands fall short, below Nyquist.
    if short.any():
        assert pa.inputs_short_from_hz == pa.f_hz[short][0] <= NYQUIST_HZ
    else:
        assert np.isnan(pa.inputs_short_from_hz)
    for lp in (res.seed, res.fsmbench, res.newport):
        assert lp.nyquist_hz == NYQUIST_HZ and lp.f_hz.max() <= NYQUIST_HZ
        # Margins come from that grid: every crossover lies in it.
        for axis in lp.axes.values():
            assert all(f <= NYQUIST_HZ for f in axis.margins.crossovers_hz)


def test_a_plant_conclusion_ignores_frequencies_above_nyquist(
        twin_study: StudyResult, bench: Any) -> None:
    from fsmbench.control.analysis import analyse_plant

    # On a grid twice as wide, what lies above 5 kHz does not count.
    wide = analyse_plant(twin_study.plant, params=bench.nominal,
                         f_hz=np.logspace(-2, np.log10(2 * NYQUIST_HZ), 1200))
    inband = (wide.f_hz <= NYQUIST_HZ) & (wide.scaled_disturbance_gain > 1.0)
    assert wide.inputs_suffice == bool(np.all(
        wide.scaled_min_singular_value[inband] >= wide.scaled_disturbance_gain[inband] - 1.0))


def test_compared_panels_share_their_axes(page: Any) -> None:
    traces = _traces(page, "fig32_huddle_qd_asd")
    asd = {t["yaxis"]: tuple(t["yrange"]) for t in traces if t["ytitle"].startswith("ASD")}
    cum = {t["yaxis"]: tuple(t["yrange"]) for t in traces
           if t["ytitle"].startswith("Cumulative")}
    assert len(asd) == 10 and len(set(asd.values())) == 1  # five tests × Vph, Vpv
    assert len(cum) == 2 and len(set(cum.values())) == 1
    # Zooming one spectrum zooms every other.
    first = sorted(asd, key=lambda a: int(a[1:] or 1))[0]
    key = "yaxis" + first[1:]
    page.evaluate(f"Plotly.relayout('plot-fig32_huddle_qd_asd', {{'{key}.range': [0, 2]}})")
    page.wait_for_timeout(300)
    zoomed = {t["yaxis"]: tuple(t["yrange"]) for t in _traces(page, "fig32_huddle_qd_asd")
              if t["ytitle"].startswith("ASD")}
    assert set(zoomed.values()) == {(0, 2)}
    page.evaluate(f"Plotly.relayout('plot-fig32_huddle_qd_asd', {{'{key}.autorange': true}})")
    for key in ("fig41_seed_loop_gain", "seed_controller_sensitivity", "fig17_sercalo_coherence",
                "fig29_huddle_attocube_time"):
        ranges = {tuple(t["yrange"]) for t in _traces(page, key)
                  if not t["ytitle"].startswith("Phase")}
        assert len(ranges) == 1, (key, ranges)


def test_static_figures_share_the_same_axes(twin_study: StudyResult) -> None:
    fig = next(f for f in iter_figures(twin_study.sections) if f.key == "fig32_huddle_qd_asd")
    mfig = render_matplotlib(fig)
    axes = [ax for ax, p in zip(mfig.axes, fig.panels, strict=True) if p.share_y == "asd"]
    assert len(axes) == 10
    assert all(axes[0].get_shared_y_axes().joined(axes[0], ax) for ax in axes)
    assert len({ax.get_ylim() for ax in axes}) == 1


def test_one_legend_entry_toggles_a_trace_in_every_panel(page: Any) -> None:
    for key in page.evaluate("Array.from(document.querySelectorAll('div.fsm-plot'))"
                             ".map(d => d.id.slice(5))"):
        groups: dict[str, list[dict[str, Any]]] = {}
        for t in _traces(page, key):
            assert t["group"], (key, t["name"])  # every trace is in a legend group
            groups.setdefault(t["group"], []).append(t)
        for group, members in groups.items():
            assert sum(bool(t["legend"]) for t in members) <= 1, (key, group)
    key = "fig18_22_sercalo_frf"
    name = "measured, from Uch"
    before = [t for t in _traces(page, key) if t["name"] == name]
    assert len({t["yaxis"] for t in before}) == 4  # two magnitudes and two phases
    entry = page.locator(f"#plot-{key} .legend .traces").filter(has_text=name)
    entry.scroll_into_view_if_needed()
    hidden = (f"document.getElementById('plot-{key}')._fullData"
              f".filter(t => t.name === '{name}').every(t => t.visible === 'legendonly')")
    # plotly.js waits out its double-click delay (300 ms) before acting on a click.
    entry.locator(".legendtoggle").click()
    page.wait_for_function(hidden, timeout=5_000)
    after = _traces(page, key)
    assert {t["visible"] for t in after if t["name"] == name} == {"legendonly"}
    assert {t["visible"] for t in after if t["name"] != name} == {True}
    entry.locator(".legendtoggle").click()
    page.wait_for_function(f"!({hidden})", timeout=5_000)
    assert {t["visible"] for t in _traces(page, key)} == {True}


def test_long_records_are_bands_that_get_finer_on_zoom(page: Any,
                                                       twin_study: StudyResult) -> None:
    key = "fig8_cal_pd_h_time"
    traces = _traces(page, key)
    assert {t["fill"] for t in traces} == {"toself"}
    assert all("±" in t["hover"] and "samples in this bin" in t["hover"] for t in traces)
    spec = page.evaluate(f"JSON.parse(document.getElementById('spec-{key}').textContent)"
                         ".pyramids")
    index = next(i for i, t in enumerate(traces) if t["name"] == "Vph")
    pyr = next(p for p in spec if p["trace"] == index)
    before = page.evaluate(f"document.getElementById('plot-{key}')._fsmZoom[{index}]")
    t0, t1 = pyr["x0"], pyr["x0"] + pyr["dx"] * pyr["n"]
    view = (t0 + 0.5 * (t1 - t0), t0 + 0.55 * (t1 - t0))  # a twentieth of the record
    page.evaluate(f"Plotly.relayout('plot-{key}', {{'xaxis.range': [{view[0]}, {view[1]}]}})")
    page.wait_for_function(f"document.getElementById('plot-{key}')._fsmZoom[{index}].per"
                           f" < {before['per']}")
    now = page.evaluate(f"document.getElementById('plot-{key}')._fsmZoom[{index}]")
    drawn = _traces(page, key)[index]
    assert drawn["fill"] == "toself" and now["level"] > before["level"]
    # True to the samples: each drawn bin holds every sample of it, and its edges are the
    # bin's least and greatest sample to within the page's 16-bit step.
    vph = np.asarray(read_recording(Path(twin_study.data_dir) / "data_cal_pd_h.mat")["Vph"]
                     .values, dtype=float)
    per, b0, b1 = now["per"], now["b0"], now["b1"]
    n_bins = b1 - b0
    upper, lower = drawn["y"][:n_bins], drawn["y"][n_bins:][::-1]
    assert upper.size == lower.size == n_bins  # one run: the record has no gap
    true_hi = np.array([vph[b * per:(b + 1) * per].max() for b in range(b0, b1)])
    true_lo = np.array([vph[b * per:(b + 1) * per].min() for b in range(b0, b1)])
    step = pyr["scale"]
    # The codes round outwards; float64 arithmetic on them adds ~1e-16 V.
    assert np.all(upper >= true_hi - 1e-12) and np.all(upper - true_hi <= step + 1e-12)
    assert np.all(lower <= true_lo + 1e-12) and np.all(true_lo - lower <= step + 1e-12)
    centres = drawn["x"][:n_bins]
    t = pyr["x0"] + pyr["dx"] * (np.arange(b0, b1) * per + (per - 1) / 2)
    np.testing.assert_allclose(centres, t, rtol=1e-12)  # each bin at its own samples' time
    page.evaluate(f"Plotly.relayout('plot-{key}', {{'xaxis.autorange': true}})")
    page.wait_for_function(f"document.getElementById('plot-{key}')._fsmZoom[{index}].level"
                           " === 0")


# Boxes [left, top, right, bottom] in page pixels: every panel's plot area, axis title,
# panel title (annotations named so) and the legend.
BOXES_JS = """(key) => {
    const div = document.getElementById('plot-' + key);
    const L = div._fullLayout, o = div.getBoundingClientRect();
    const box = (r) => [r.left, r.top, r.right, r.bottom];
    const areas = [], axes = [];
    for (const k of Object.keys(L)) {
        const m = k.match(/^xaxis(\\d*)$/);
        if (!m) continue;
        const xa = L[k], ya = L['yaxis' + m[1]];
        if (!ya) continue;
        areas.push([o.left + xa._offset, o.top + ya._offset, o.left + xa._offset + xa._length,
                    o.top + ya._offset + ya._length]);
        axes.push([ya._length]);
    }
    const titles = (sel) => Array.from(div.querySelectorAll(sel))
        .map(e => e.getBoundingClientRect()).filter(r => r.width > 0).map(box);
    const panelTitles = [];
    L.annotations.forEach((a, i) => {
        if (a.name !== 'panel title') return;
        const e = div.querySelector(`.annotation[data-index="${i}"] .annotation-text`);
        if (e) panelTitles.push(box(e.getBoundingClientRect()));
    });
    const yTitles = Array.from(div.querySelectorAll('[class^="g-y"][class$="title"] text'))
        .filter(e => e.getBoundingClientRect().height > 0);
    const legend = div.querySelector('.legend .bg');
    return {figure: box(o), areas: areas,
            xtitles: titles('[class^="g-x"][class$="title"] text'),
            ytitles: yTitles.map(e => box(e.getBoundingClientRect())),
            ylengths: yTitles.map(e => {
                const id = e.parentNode.getAttribute('class').match(/g-y(\\d*)title/)[1];
                return L['yaxis' + id]._length;
            }),
            panelTitles: panelTitles,
            legend: legend ? box(legend.getBoundingClientRect()) : null};
}"""


def _hits(a: list[float], b: list[float]) -> bool:
    """Whether two boxes [px] overlap by more than a pixel each way (anti-aliasing at a
    shared edge is not an overlap)."""
    w = min(a[2], b[2]) - max(a[0], b[0])
    h = min(a[3], b[3]) - max(a[1], b[1])
    return w > 1.0 and h > 1.0


def test_no_title_is_struck_through(page: Any) -> None:
    keys = page.evaluate("Array.from(document.querySelectorAll('div.fsm-plot'))"
                         ".map(d => d.id.slice(5))")
    assert len(keys) >= 30
    for key in keys:
        page.locator(f"#plot-{key}").scroll_into_view_if_needed()
        b = page.evaluate(BOXES_JS, key)
        texts = b["xtitles"] + b["ytitles"] + b["panelTitles"]
        for title in texts:
            for area in b["areas"]:
                assert not _hits(title, area), (key, title, area)
            # Inside the figure's own box (a pixel of glyph overhang).
            f = b["figure"]
            assert (f[0] - 1 <= title[0] and title[2] <= f[2] + 1 and f[1] - 1 <= title[1]
                    and title[3] <= f[3] + 1), (key, title, f)
        for i, a in enumerate(texts):
            for c in texts[i + 1:]:
                assert not _hits(a, c), (key, a, c)
        for box, length in zip(b["ytitles"], b["ylengths"], strict=True):
            # A y title no longer than its axis (two pixels of glyph overhang).
            assert box[3] - box[1] <= length + 2.0, (key, box, length)
        if b["legend"] is not None:
            for other in b["areas"] + b["xtitles"]:
                assert not _hits(b["legend"], other), (key, b["legend"], other)


def test_the_beam_path_fills_its_panel(page: Any) -> None:
    traces = _traces(page, "fig35_beam_path")
    xs = np.concatenate([t["x"] for t in traces])
    lo, hi = np.nanmin(xs), np.nanmax(xs)
    r = traces[0]["xrange"]
    # The x range is the data's with 5 % either side (and the labels'), not 60 % empty.
    assert r[0] <= lo and hi <= r[1]
    assert (r[1] - r[0]) <= 1.25 * (hi - lo), (r, lo, hi)


def test_dimensionless_is_one_unit_word(twin_study: StudyResult) -> None:
    text = "\n".join(visible_text(twin_study.sections))
    assert "[1]" in text
    assert not re.search(r"\[\s*[–—-]\s*\]", text)


def test_exported_files_carry_the_report_numbers(twin_study: StudyResult,
                                                 tmp_path: Path) -> None:
    page = Path(twin_study.report).read_text(encoding="utf-8")
    numbers = {k: int(n) for k, n in re.findall(
        r'<figure id="fig-([a-z0-9_]+)">.*?<b>Figure (\d+)\.', page, flags=re.S)}
    figures = list(iter_figures(twin_study.sections))
    assert [f.number for f in figures] == [numbers[f.key] for f in figures]
    some = [f for f in figures if f.key in ("fig10_qd_regression", "fig32_huddle_qd_asd",
                                            "fig43_newport_loop_gain")]
    paths = export_figures(some, tmp_path, formats=("png",), workers=1)
    assert [p.name for p in paths] == [
        f"fig{numbers['fig10_qd_regression']:02d}_qd_regression.png",
        f"fig{numbers['fig32_huddle_qd_asd']:02d}_huddle_qd_asd.png",
        f"fig{numbers['fig43_newport_loop_gain']:02d}_newport_loop_gain.png"]


def test_the_page_stays_within_its_size_budget(twin_study: StudyResult) -> None:
    assert Path(twin_study.report).stat().st_size <= PAGE_BUDGET_BYTES
