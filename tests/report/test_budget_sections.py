"""Report sections 3 (huddle test), 4 (error budget) and 11 (non-repeatability) on twin data."""

from __future__ import annotations

import itertools
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import fsmbench.budget
from fsmbench.budget.study import BudgetResult, budget_study
from fsmbench.report.figures.budget import distance_cumulative_m, log_envelope
from fsmbench.report.figures.spec import Figure, Line
from fsmbench.report.html import Note, Section, Table, iter_figures, render_report
from fsmbench.report.sections.budget import budget_section
from fsmbench.report.sections.huddle import huddle_section
from fsmbench.report.sections.repeatability import repeatability_section
from fsmbench.twin import simulate_bench

HUDDLES = [f"data_huddle_test_{i}" for i in range(1, 6)]
# 8 s: 7 s of huddle record after the seed's 1 s trim (seven 1 s Welch windows) and six
# whole repeatability periods after the first command + 1 s (three needed for the settled
# low-pass value).
DURATION_S = 8.0
EXPECTED_KEYS = {
    "fig29_huddle_attocube_time", "fig30_huddle_qd_time", "fig31_huddle_attocube_asd",
    "fig32_huddle_qd_asd", "fig34_angle_error_distance", "fig35_beam_path",
    "budget_beam_angle_per_source", "budget_distance_per_source", "fig44_repeatability_time",
    "fig45_tracking_error_distance", "fig46_tracking_error_asd",
    "fig47_tracking_vs_distance_asd", "fig48_49_repeatability_periods",
    "fig50_nonrepeatable_contributions", "fig52_lowpass_nonrepeatable", "huddle_allan",
    "huddle_drift",
}


@pytest.fixture(scope="module")
def run():
    return simulate_bench(seed=0, duration_s=DURATION_S,
                          experiments=[*HUDDLES, "data_rep_h", "data_rep_v"])


@pytest.fixture(scope="module")
def result(run, bench) -> BudgetResult:
    return budget_study(run.recordings, bench=bench, df_hz=1.0)


@pytest.fixture(scope="module")
def sections(result, run) -> list[Section]:
    return [huddle_section(result, recordings=run.recordings),
            budget_section(result, plant_source="physical (nominal)"),
            repeatability_section(result)]


@pytest.fixture(scope="module")
def figures(sections) -> list[Figure]:
    return list(iter_figures(sections))


def _blocks(sec: Section):
    yield from sec.blocks
    for sub in sec.subsections:
        yield from _blocks(sub)


def _lines(fig: Figure):
    for p in fig.panels:
        for t in p.traces:
            if isinstance(t, Line):
                yield p, t


def test_entry_points_and_order(sections):
    huddle, budget, rep = sections
    assert huddle.title == "3. Huddle test"
    assert budget.title == "4. Error budget"
    assert [s.title.split(" ")[0] for s in budget.subsections] == ["4.1", "4.2", "4.3", "4.4",
                                                                   "4.5"]
    assert rep.title == "11. Measurement of the non-repeatability"
    assert [s.title.split(" ")[0] for s in rep.subsections] == ["11.1–11.2", "11.3", "11.4",
                                                                "11.5", "11.6–11.7"]
    # Reading order: every figure follows some text of its section.
    for sec in [huddle, *budget.subsections, *rep.subsections]:
        blocks = list(sec.blocks)
        for i, b in enumerate(blocks):
            if isinstance(b, Figure):
                assert any(isinstance(x, str) for x in blocks[:i]), b.key
    html = render_report(title="t", sections=sections)
    for title in ("3. Huddle test", "4.5 Noise", "11.6–11.7"):
        assert title in html


def test_figure_keys_unique_and_complete(figures):
    keys = [f.key for f in figures]
    assert len(keys) == len(set(keys))
    assert set(keys) == EXPECTED_KEYS
    refs = " ".join(f.seed_ref for f in figures)
    for n in (29, 30, 31, 32, 34, 35, 44, 45, 46, 47, 48, 49, 50, 51, 52):
        assert str(n) in refs, n


def test_traces_finite_and_labels_with_units(figures):
    unit = re.compile(r"\[[^\]]+\]$")
    for fig in figures:
        for p in fig.panels:
            assert unit.search(p.x_label), (fig.key, p.x_label)
            assert unit.search(p.y_label), (fig.key, p.y_label)
            # Axes autoscale: no figure of these sections fixes a window.
            assert p.x_range is None and p.y_range is None, fig.key
        for p, line in _lines(fig):
            assert line.x.size >= 2, (fig.key, line.name)
            assert np.isfinite(line.x).all() and np.isfinite(line.y).all(), (fig.key, line.name)
            if p.y_log:  # a log axis shows positive values only; some must be there
                assert (line.y > 0).any(), (fig.key, line.name)


def test_words_not_code_keys(figures):
    code = re.compile(r"\b[a-z]+_[a-z0-9_]+\b")
    for fig in figures:
        texts = [fig.title, fig.caption, fig.note]
        texts += [t for p in fig.panels for t in (p.title, p.x_label, p.y_label)]
        texts += [line.name for _, line in _lines(fig)]
        for text in texts:
            # Recording names (data_rep_h, data_huddle_test_3) are file names the user knows.
            left = re.sub(r"data_(rep_[hv]|huddle_test_\d)", "", text)
            assert not code.search(left), (fig.key, text)


def test_no_duplicate_traces_between_figures(figures):
    def sig(line: Line) -> tuple[int, bytes]:
        return line.y.size, np.round(line.y, 12).tobytes()
    owners: dict[tuple[int, bytes], str] = {}
    for fig in figures:
        mine = {sig(line) for _, line in _lines(fig)}
        for s in mine:
            assert s not in owners, f"{fig.key} repeats a trace of {owners.get(s)}"
        owners.update({s: fig.key for s in mine})
    datas = {f.key: np.concatenate([line.y for _, line in _lines(f)]) for f in figures}
    for a, b in itertools.combinations(datas, 2):
        assert not (datas[a].shape == datas[b].shape and np.allclose(datas[a], datas[b])), (a, b)


def test_fig32_closed_loop_peak_visible(figures, result, bench):
    fig = next(f for f in figures if f.key == "fig32_huddle_qd_asd")
    mode_hz = bench.true.sercalo.resonance_hz.h
    for n in (3, 5):
        rec = result.huddle.records[n]
        panel = next(p for p in fig.panels if p.title.startswith(f"Test {n}:")
                     and p.title.endswith("Vph"))
        (line,) = panel.traces
        above = line.x > 100.0
        peak = int(np.argmax(np.where(above, line.y, -np.inf)))
        # Welch with a 1 s Hann window: 1 Hz bins, main lobe ±2 Hz around the mode.
        assert abs(line.x[peak] - mode_hz) <= 2.0
        # The drawn maximum is the record's own (nothing clipped or decimated away) and
        # the axis autoscales to it.
        assert line.y[peak] == pytest.approx(np.sqrt(rec.psd_vph_v2_per_hz.max()) * 1e6,
                                             rel=1e-12)  # same numbers, float rounding
        assert line.y[peak] == line.y.max() and panel.y_range is None
        # The mode stands well out of the floor (seed: 481 µV/√Hz on a ~10 µV/√Hz floor).
        assert line.y[peak] > 10 * np.median(line.y[above])


def test_distance_curves_end_at_budget_rows(result):
    b = result.budget
    cum = distance_cumulative_m(b)
    rows = {r.name: r for r in b.rows}
    for name in b.sources:
        # Same spectra, weights and rectangle sum as the table: equal to rounding.
        assert cum[name][1][-1] == pytest.approx(rows[name].rms_m, rel=1e-9)
    angle_rows = [rows[n].rms_m for n in b.sources]
    angle_rows.append(rows["geometric cross terms between angle sources"].rms_m)
    assert cum["all angle sources together"][1][-1] == pytest.approx(
        np.sqrt(np.sum(np.square(angle_rows))), rel=1e-9)  # RSS of rows, rounding only


def test_budget_table_complete(sections, result):
    table = next(b for b in _blocks(sections[1]) if isinstance(b, Table)
                 and b.caption.startswith("Error budget"))
    names = [row[0].lower() for row in table.rows]
    for r in result.budget.rows:
        assert r.name.lower() in names
    assert names[-1].startswith("total")
    assert table.rows[-1][3] == f"{result.budget.total_rms_m * 1e9:.3g}"
    refs = " ".join(b.ref for b in _blocks(sections[1]) if isinstance(b, Note))
    for e in ("E15", "E18", "E28", "E29", "E30", "E31", "E34"):
        assert e in refs, e


def test_repeatability_low_pass_settled_shown(sections, result):
    blocks = list(_blocks(sections[2]))
    table = next(b for b in blocks if isinstance(b, Table))
    for r in result.repeatability.values():
        assert r.nonrep_rms_lpf_settled_m is not None
        row = next(row for row in table.rows if r.name in row[0])
        assert row[3] == f"{r.nonrep_rms_lpf_m * 1e9:.3g}"
        assert row[4] == f"{r.nonrep_rms_lpf_settled_m * 1e9:.3g}"
    assert any(isinstance(b, Note) and "E32" in b.ref for b in blocks)


def test_sections_without_data(run, bench):
    recs = {"data_rep_h": run.recordings["data_rep_h"]}
    res = budget_study(recs, bench=bench, df_hz=1.0)
    huddle = huddle_section(res, recordings=recs)
    assert not list(iter_figures([huddle]))
    text = " ".join(b for b in huddle.blocks if isinstance(b, str))
    for name in HUDDLES:
        assert f"{name}.mat" in text
    rep = repeatability_section(res)
    assert [f.key for f in iter_figures([rep])][:1] == ["fig44_repeatability_time"]
    assert "data_rep_v" in " ".join(b for b in _blocks(rep) if isinstance(b, str))
    budget = budget_section(res, plant_source="physical (nominal)")
    assert {f.key for f in iter_figures([budget])} == {
        "fig34_angle_error_distance", "fig35_beam_path", "budget_beam_angle_per_source",
        "budget_distance_per_source"}
    res_none = budget_study({}, bench=bench, df_hz=1.0)
    rep_none = repeatability_section(res_none)
    assert not list(iter_figures([rep_none]))
    assert "data_rep_h.mat" in " ".join(b for b in rep_none.blocks if isinstance(b, str))


def test_log_envelope_keeps_every_bin_extreme():
    rng = np.random.default_rng(3)
    f = np.arange(1, 40001) * 0.125
    y = rng.lognormal(size=f.size)
    y[3287] = 1e3  # a narrow peak
    x2, y2 = log_envelope(f, y, bins=500)
    assert np.all(np.diff(x2) > 0)
    edges = np.geomspace(f[0], f[-1], 501)
    b = np.clip(np.searchsorted(edges, f, side="right") - 1, 0, 499)
    b2 = np.clip(np.searchsorted(edges, x2, side="right") - 1, 0, 499)
    for k in np.unique(b):  # brute force: each bin's min and max survive, nothing else
        assert set(y2[b2 == k]) == {y[b == k].min(), y[b == k].max()}
    short = f[:900], y[:900]
    assert log_envelope(*short, bins=500)[0] is short[0]


def test_budget_package_draws_nothing():
    # python-control imports matplotlib.pyplot itself (its plotting functions), so the
    # check is that fsmbench.budget adds no matplotlib module to what control loads, and
    # that no numerics module mentions matplotlib.
    code = ("import sys, importlib.util\n"
            "mpl = lambda: {m for m in sys.modules if m.split('.')[0] == 'matplotlib'}\n"
            "import control\n"
            "before = mpl()\n"
            "import fsmbench.budget\n"
            "assert importlib.util.find_spec('fsmbench.budget.figures') is None\n"
            "assert mpl() == before, sorted(mpl() - before)\n")
    subprocess.run([sys.executable, "-c", code], check=True)
    budget_dir = Path(fsmbench.budget.__file__).parent
    for path in budget_dir.glob("*.py"):
        assert "matplotlib" not in path.read_text(encoding="utf-8"), path.name


def test_the_huddle_time_figure_draws_the_budget_stages_low_pass(result, figures, run):
    """The report draws the low-passed Va the budget stage computed (it filters nothing),
    and that array is the ESRF study's lsim: y[k+1] = a y[k] + (1 - a) x[k] from rest."""
    from scipy.signal import lfilter

    from fsmbench.budget.huddle import trim_huddle

    fig = next(f for f in figures if f.key == "fig29_huddle_attocube_time")
    for panel, rec in zip(fig.panels, sorted(result.huddle.records.values(),
                                             key=lambda r: r.name), strict=True):
        lowpassed = next(t for t in panel.traces if "low pass" in t.name)
        assert rec.va_lowpass_m is not None
        np.testing.assert_array_equal(lowpassed.y, rec.va_lowpass_m * 1e9)  # the same array
        sig = trim_huddle(run.recordings[rec.name], name=rec.name, duration_s=rec.duration_s)
        x = sig["Va"] - sig["Va"].mean()
        a = np.exp(-2 * np.pi * 50.0 / rec.fs_hz)
        ref = lfilter([0.0, 1.0 - a], [1.0, -a], x)  # one-sample delay: y[0] = 0
        # One recursion against another on nanometre signals: rounding only.
        np.testing.assert_allclose(rec.va_lowpass_m, ref, rtol=0, atol=1e-12 * np.abs(x).max())
        assert "va_lowpass_m" not in rec.to_json()


def test_fig50_draws_the_huddle_window_the_budget_stage_read(result, figures, run):
    """Fig. 50's huddle panel comes from the budget stage (the report reads no recording):
    its rms is the definition on the trimmed record over the repeatability length."""
    windows = {nr.huddle_window.name: nr.huddle_window for nr in result.nonrep.values()
               if nr.huddle_window is not None}
    assert len(windows) == 1
    (name, win), = windows.items()
    longest = max(r.n_periods * r.period_samples for r in result.repeatability.values())
    ds = run.recordings[name]
    t = ds["t"].values
    va = ds["Va"].values[t >= 1.0][:longest]
    assert win.n_samples == va.size
    # Two streamed passes against one in-memory pass over the same samples: rounding only.
    np.testing.assert_allclose(win.va_rms_m, np.std(va), rtol=1e-9)
    fig = next(f for f in figures if f.key == "fig50_nonrepeatable_contributions")
    assert f"{win.va_rms_m * 1e9:.3g} nm rms over {win.duration_s:g} s" in fig.panels[-1].title
    assert result.nonrep[next(iter(result.nonrep))].to_json()["huddle_window"]["name"] == name


def test_fig23_cumulative_panels_end_with_the_total(figures, result):
    """The cumulative-rms panels carry all sources together, the RSS of the parts (issue 33)."""
    fig = next(f for f in figures if f.key == "budget_beam_angle_per_source")
    cum = [p for p in fig.panels if p.y_label.startswith("Cumulative rms")]
    assert len(cum) == 2
    for i, p in enumerate(cum):
        total = [t for t in p.traces if t.name.startswith("all sources together")]
        assert len(total) == 1 and total[0].name.endswith("[µrad]")
        parts = [t for t in p.traces if t is not total[0]]
        assert len(parts) == len(result.budget.sources)
        rss = np.sqrt(sum(t.y[-1] ** 2 for t in parts))
        assert total[0].y[-1] == pytest.approx(rss, rel=1e-9)
        assert total[0].x[-1] == parts[0].x[-1]
        # and the sources' own rms (rectangle rule): the same to the grid's step
        own = np.sqrt(sum(s.angle_rms_rad[i] ** 2 for s in result.budget.sources.values()))
        assert total[0].y[-1] == pytest.approx(1e6 * own, rel=1e-2)


def test_every_legend_entry_is_one_colour(figures):
    """Traces that share a legend entry share its colour (issue 33: Fig. 46 had one
    "recorded" entry for two colours)."""
    for fig in figures:
        colours: dict[str, set[str]] = {}
        for _, t in _lines(fig):
            if t.color is not None:
                colours.setdefault(t.group or t.name, set()).add(t.color)
        bad = {g: c for g, c in colours.items() if len(c) > 1}
        assert not bad, (fig.key, bad)
