"""Chapter 2: identification of the system dynamics, on the twin and on recorded data."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from fsmbench.bench.params import Bench
from fsmbench.checks import Check, Notice
from fsmbench.ident.pipeline import Identification, identify
from fsmbench.report.figures.spec import Bars, Figure, Line
from fsmbench.report.html import Section, Table, iter_figures, render_report, visible_text
from fsmbench.report.sections.ident import identification_section, quantity
from fsmbench.twin import TwinRun
from fsmbench.twin.compare import TARGETS, comparison_rows

PASSED = "passed its quality checks"


@pytest.fixture(scope="module")
def result(ident_twin: TwinRun, bench: Bench) -> Identification:
    return identify(ident_twin.recordings, bench=bench)


def _tables(sec: Section) -> list[Table]:
    own = [b for b in sec.blocks if isinstance(b, Table)]
    return own + [t for sub in sec.subsections for t in _tables(sub)]


def _figures_sound(sec: Section) -> list[Figure]:
    """Unique keys; every trace non-empty and finite somewhere; units on every axis."""
    figs = list(iter_figures([sec]))
    keys = [f.key for f in figs]
    assert len(keys) == len(set(keys)), keys
    for fig in figs:
        for panel in fig.panels:
            for label in (panel.x_label, panel.y_label):
                assert "[" in label and label.endswith("]"), (fig.key, label)
            assert panel.traces, fig.key
            for trace in panel.traces:
                values = trace.values if isinstance(trace, Bars) else trace.y
                assert values.size > 0 and np.isfinite(values).any(), (fig.key, trace.name)
    return figs


def test_twin_section_has_every_seed_figure_and_the_truth_table(
        result: Identification, ident_twin: TwinRun, bench: Bench) -> None:
    sec = identification_section(result, recordings=ident_twin.recordings, bench=bench,
                                 truth=ident_twin.truth, skipped={})
    figs = _figures_sound(sec)
    assert [f.seed_ref for f in figs] == [
        "Fig. 8", "Fig. 9", "Fig. 10", "Fig. 15", "Fig. 16", "Figs. 12–14", "Fig. 17",
        "Figs. 18, 19, 21, 22", "Fig. 20", "Fig. 23", "Fig. 24", "Fig. 25", "Figs. 26, 27",
        "Fig. 28", "", ""]  # the model's Bode band and the model against the records
    assert [f.key for f in figs[-2:]] == ["ident_model_bode_band", "ident_model_compare"]
    assert [s.title[:3] for s in sec.subsections] == ["2.1", "2.2", "2.3", "2.4", "2.5"]
    table = _tables(sec)[0]
    assert table.header == ("quantity", "identified", "± total",
                            "largest part of the uncertainty (share of the variance)",
                            "true value (twin)", "difference", "accuracy target", "within target")
    rows = comparison_rows(result.to_json(), reference=ident_twin.truth, bench=bench)
    assert len(table.rows) == len(rows) == len(TARGETS)
    for cells, row in zip(table.rows, rows, strict=True):
        name, _unit, scale = quantity(row.key)
        assert cells[0] == name
        assert float(cells[1]) == pytest.approx(row.identified * scale, rel=1e-5)  # 6 digits
        assert cells[-1] == "yes"
        # every compared value carries its total uncertainty and names its largest part
        u = result.uncertain(row.key)
        # (two significant digits: within 5 %)
        assert u is not None and float(cells[2]) == pytest.approx(u.std * scale, rel=0.05)
        assert cells[3] != "–" and cells[3].endswith("%)")
    by_name = {r[0]: r for r in table.rows}
    assert by_name["Delay of the Sercalo path [ms]"][6] == "±0.1 ms (1 sample)"  # at 10 kHz
    assert by_name["4QD gain, h [V/rad]"][6] == "±1 %"
    text = _joined(sec)
    assert PASSED in text and "identification issue" not in text
    assert "errata E21" in text


def test_every_target_key_reads_in_words_with_a_unit() -> None:
    for key in TARGETS:
        name, _unit, _scale = quantity(key)
        assert "_" not in name and "." not in name.split("[")[0], name
        assert name.endswith("]") and "[" in name, name
    assert quantity("qd_gain_v_per_rad.h") == ("4QD gain, h [V/rad]", "V/rad", 1.0)
    assert quantity("current_amp_gain_a_per_v.v")[0] == "Current-amplifier gain, v [mA/V]"


def test_recorded_data_are_compared_with_nominal_values(
        result: Identification, ident_twin: TwinRun, bench: Bench) -> None:
    sec = identification_section(result, recordings=ident_twin.recordings, bench=bench,
                                 truth=None, skipped={})
    table = _tables(sec)[0]
    assert table.header == ("quantity", "identified", "± total",
                            "largest part of the uncertainty (share of the variance)",
                            "nominal value", "difference")
    text = _joined(sec).lower()
    assert "twin" not in text and "true value" not in text
    # The nominal 4QD gain of the seed's Table 2: −31.0 V/rad.
    assert {r[0]: r[4] for r in table.rows}["4QD gain, h [V/rad]"] == "-31"


def test_skipped_sercalo_fit_is_said_and_no_quality_claim(
        result: Identification, ident_twin: TwinRun, bench: Bench) -> None:
    reason = "failed (data_uch, data_ucv): vector fitting found no stable pole"
    broken = dataclasses.replace(result, sercalo=None, modes=None, validation=(),
                                 skipped={"sercalo": reason}, warnings=(),
                                 plant_blocks={**result.plant_blocks, "Gc": "nominal"})
    sec = identification_section(broken, recordings=ident_twin.recordings, bench=bench,
                                 truth=None, skipped={})
    text = _joined(sec)
    assert PASSED not in text and "converged" not in text
    assert reason in text
    keys = {f.key for f in _figures_sound(sec)}
    assert not any(k.startswith(("fig17", "fig18", "fig20")) for k in keys)
    assert "fig15_uch_time" in keys  # the records that exist are still shown
    blocks = {r[0]: r[1] for r in _tables(sec.subsections[4])[0].rows}
    assert blocks["Gc, Sercalo"].startswith("nominal")
    assert blocks["Gi, current amplifier"] == "identified (2.2)"


def test_warnings_replace_the_quality_claim(result: Identification, ident_twin: TwinRun,
                                            bench: Bench) -> None:
    warned = dataclasses.replace(result, warnings=("Vph/Uch: the fit misses by 7.0 %",))
    text = _joined(identification_section(warned, recordings=ident_twin.recordings,
                                        bench=bench, truth=None, skipped={}))
    assert PASSED not in text and "the fit misses by 7.0 %" in text


def test_failed_checks_and_notices_are_said(result: Identification, ident_twin: TwinRun,
                                           bench: Bench) -> None:
    bad = Check("calibration_r2", False, 0.5, "≥ 0.9", "data_cal_pd_h: Vph",
                "Vph does not follow the Newport's sweep")
    note = Notice("saturation", "data_uch: Vch", "2 samples at the ADC rail")
    text = _joined(identification_section(
        dataclasses.replace(result, checks=(bad,), notices=(note,)),
        recordings=ident_twin.recordings, bench=bench, truth=None, skipped={}))
    assert "data_cal_pd_h: Vph: Vph does not follow the Newport's sweep." in text
    assert "data_uch: Vch: 2 samples at the ADC rail." in text


def test_missing_records_are_explained(ident_twin: TwinRun, bench: Bench) -> None:
    cal = {k: v for k, v in ident_twin.recordings.items() if k.startswith("data_cal")}
    res = identify(cal, bench=bench)
    sec = identification_section(res, recordings=cal, bench=bench, truth=None,
                                 skipped={"data_uch": "no data_uch.mat in the folder"})
    text = _joined(sec)
    assert ("Missing recordings: data_uch (not loaded: no data_uch.mat in the folder); "
            "data_ucv (not in the data).") in text
    assert [r[0] for r in _tables(sec)[0].rows] == ["4QD gain, h [V/rad]", "4QD gain, v [V/rad]"]
    assert PASSED not in text
    assert {f.key for f in _figures_sound(sec)} == {"fig8_cal_pd_h_time", "fig9_cal_pd_v_time",
                                                   "fig10_qd_regression"}


def test_without_identification_the_records_are_still_shown(ident_twin: TwinRun,
                                                            bench: Bench) -> None:
    recs = {k: ident_twin.recordings[k] for k in ("data_unh", "data_unv")}
    sec = identification_section(None, recordings=recs, bench=bench, truth=None,
                                 skipped={"data_uch": "file is truncated"})
    text = _joined(sec)
    assert "The identification did not run" in text and "file is truncated" in text
    assert PASSED not in text
    assert {f.key for f in _figures_sound(sec)} == {"fig23_unh_time", "fig24_unv_time"}
    assert "nominal model" in text


def test_section_renders_with_unique_figure_keys(result: Identification, ident_twin: TwinRun,
                                                 bench: Bench) -> None:
    sec = identification_section(result, recordings=ident_twin.recordings, bench=bench,
                                 truth=ident_twin.truth, skipped={})
    html = render_report(title="t", sections=[sec])
    assert html.count('class="fsm-plot pending"') == len(list(iter_figures([sec])))


def _figure(sec: Section, key: str) -> Figure:
    (fig,) = [f for f in iter_figures([sec]) if f.key == key]
    return fig


def test_regression_points_are_the_calibration_data(result: Identification,
                                                    ident_twin: TwinRun, bench: Bench) -> None:
    sec = identification_section(result, recordings=ident_twin.recordings, bench=bench,
                                 truth=None, skipped={})
    fig = _figure(sec, "fig10_qd_regression")
    for panel, cal in zip(fig.panels, result.qd.values(), strict=True):
        points = panel.traces[0]
        assert isinstance(points, Line) and points.markers
        slope, offset = np.polyfit(1e-3 * points.x, points.y, 1)  # mrad -> rad
        # 3000 of 100 000 samples of a line with R² > 0.9999: the slope of the subset agrees
        # with the fit of all samples to well under 0.1 %.
        assert slope == pytest.approx(cal.gain_v_per_rad, rel=1e-3)
        # The intercept of the subset: ~1 mV residual rms / sqrt(3000) ≈ 2e-5 V of scatter.
        assert offset == pytest.approx(cal.offset_v, abs=1e-4)


def test_frf_figure_shows_the_measured_magnitude_and_the_model(
        result: Identification, ident_twin: TwinRun, bench: Bench) -> None:
    sec = identification_section(result, recordings=ident_twin.recordings, bench=bench,
                                 truth=None, skipped={})
    s = result.sercalo
    assert s is not None
    fig = _figure(sec, "fig18_22_sercalo_frf")
    assert len(fig.panels) == 8 and fig.columns == 2  # 2x2 matrix, magnitude over phase
    mag = fig.panels[0]  # Uch -> Vph
    # measured, its two confidence bounds (the line variance, issue 20), the model
    measured, model = mag.traces[0], mag.traces[-1]
    assert isinstance(measured, Line) and isinstance(model, Line)
    assert [t.group for t in mag.traces[1:-1]] == ["bounds", "bounds"]
    raw = np.abs(s.frf.frf.sel(output="Vph", input="Uch").values[1:])
    # Removing a delay only turns the phase: the magnitude drawn is the measured one.
    np.testing.assert_allclose(measured.y, raw, rtol=1e-12)
    assert model.dash == "dash" and np.isfinite(model.y).all()
    n = result.newport
    assert n is not None
    nfig = _figure(sec, "fig26_27_newport_frf")
    gain_line = nfig.panels[0].traces[-1]  # after the measured line and its bounds
    assert isinstance(gain_line, Line)
    # The fitted second order (with the hold's droop) over the band it was fitted on.
    dyn = n.dynamics
    assert dyn is not None
    shown = np.isfinite(gain_line.y)
    expected = np.abs(dyn.axes["h"].response(gain_line.x[shown], fs_hz=dyn.fs_hz, delay=False))
    np.testing.assert_allclose(gain_line.y[shown], expected, rtol=1e-12)
    band = gain_line.x[shown]
    assert band.min() >= dyn.axes["h"].band_hz[0] and band.max() <= dyn.axes["h"].band_hz[1]
    assert gain_line.y[shown][-1] < 0.5 * abs(n.gain_v_per_v["h"])  # it rolls off, unlike Gn


def _joined(sec: Section) -> str:
    return "\n".join(visible_text([sec]))


def test_every_identified_value_is_listed_with_its_total_and_largest_part(
        result: Identification, ident_twin: TwinRun, bench: Bench) -> None:
    sec = identification_section(result, recordings=ident_twin.recordings, bench=bench,
                                 truth=None, skipped={})
    table = next(t for t in _tables(sec) if t.header[2] == "± total"
                 and t.header[1] == "value")
    assert len(table.rows) == len(result.uncertainty) >= 20
    words = {r[0].split(" [")[0].lower() for r in table.rows}
    for u in result.uncertainty.values():
        assert u.quantity.lower() in words
        # the total is the root sum of squares of the parts, each a std
        assert u.std == pytest.approx(float(np.sqrt(sum(v**2 for v in u.parts.values()))))
    assert all(r[3].endswith("%)") and "_" not in r[3] for r in table.rows)  # words, no keys


def test_current_amplifier_figure_draws_the_estimate_the_identification_fitted(
        result: Identification, ident_twin: TwinRun, bench: Bench) -> None:
    """The report estimates nothing again: Figs. 12–14 draw ``gi.frf``, the lines the
    gain was fitted on, whichever estimator made them."""
    sec = identification_section(result, recordings=ident_twin.recordings, bench=bench,
                                 truth=None, skipped={})
    fig = _figure(sec, "fig12_14_current_amplifier")
    amps = list(result.current_amp.values())
    for panel, g in zip(fig.panels[:len(amps)], amps, strict=True):  # the top row, per axis
        assert g.frf is not None
        keep = g.frf.frequency_hz > 0
        measured = panel.traces[0]
        assert isinstance(measured, Line)
        np.testing.assert_array_equal(measured.x, g.frf.frequency_hz[keep])
        np.testing.assert_array_equal(measured.y, np.abs(g.frf.frf.values[keep, 0, 0]))
    assert "frf" not in result.current_amp["h"].to_json()


def test_the_report_calls_no_estimator() -> None:
    """Numerics never draw, and the report never estimates: no report module imports an
    FRF or spectrum estimator (the stages hand it every array it draws)."""
    import ast
    from pathlib import Path

    import fsmbench.report

    estimators = {"spectral_matrix", "tfestimate", "pwelch", "cpsd", "mscohere",
                  "local_polynomial_frf", "periodic_frf", "esrf_welch", "first_order_lowpass"}
    for path in Path(fsmbench.report.__file__).parent.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom):
                names = {a.name for a in node.names}
                assert not names & estimators, (path.name, sorted(names & estimators))
