"""The plotly.js JSON of figure specs, and the HTML page around it."""

from __future__ import annotations

import base64
import json
import re
from typing import Any

import numpy as np
import pytest

from fsmbench.report.figures.interactive import figure_json
from fsmbench.report.figures.spec import H_COLOR, V_COLOR, Bars, Figure, Line, Panel, Rule
from fsmbench.report.html import Section, render_report

N_RECORD = 1_000_000


def _decode(spec: dict[str, Any], ref: dict[str, int]) -> np.ndarray:
    """The array a trace refers to (``{"ref": i}`` into the figure's shared arrays)."""
    arr = spec["arrays"][ref["ref"]]
    return np.frombuffer(base64.b64decode(arr["bdata"]), dtype="<" + arr["dtype"])


def _bode() -> Figure:
    f_hz = np.logspace(0, 4, 400)
    mag = 1.0 / np.abs(1 + 1j * f_hz / 300.0)
    mag[:2] = [0.0, -1.0]  # not drawable on a log axis
    phase = -np.degrees(np.arctan(f_hz / 300.0))
    return Figure("fig5_bode", "Plant", "c", share_x=True, panels=(
        Panel((Line(f_hz, mag, name="h", color=H_COLOR, group="h"),
               Line(f_hz, 0.5 * mag, name="v", color=V_COLOR, group="v")),
              "Frequency [Hz]", "Gain [V/V]", x_log=True, y_log=True, height=2,
              y_range=(1e-3, 10.0)),
        Panel((Line(f_hz, phase, name="h", color=H_COLOR, group="h"),
               Line(f_hz, phase, name="v", color=V_COLOR, group="v")),
              "Frequency [Hz]", "Phase [deg]", x_log=True, rules=(Rule(-45.0),))))


def _time() -> Figure:
    rng = np.random.default_rng(2)
    t_s = np.arange(N_RECORD) / 10_000.0
    y = np.sin(2 * np.pi * 0.3 * t_s) + 0.1 * rng.standard_normal(N_RECORD)
    y[123_457] = 9.0  # a lone spike
    offset = 1000.0 + 1e-3 * np.sin(2 * np.pi * t_s[:5000])  # an offset plus a small signal
    return Figure("time_record", "Time", "c", share_x=True, panels=(
        Panel((Line(t_s, y, name="command", group="command", decimate=True),),
              "Time [s]", "Command [V]"),
        Panel((Line(t_s[:5000], offset, name="offset"),), "Time [s]", "Pressure [hPa]")))


def _bars() -> Figure:
    cats = ("sensor", "actuator")
    return Figure("budget", "Budget", "c", panels=(Panel(
        (Bars(cats, np.array([1.0, 2.0]), name="h"), Bars(cats, np.array([3.0, 4.0]), name="v")),
        "Contributor", "rms [µrad]"),))


def test_typed_arrays_decode_to_the_data() -> None:
    fig = _bode()
    spec = figure_json(fig)
    data = spec["data"]
    f_hz = fig.panels[0].traces[0].x
    mag = fig.panels[0].traces[0].y
    x = _decode(spec, data[0]["x"])
    assert x.dtype == np.float32
    assert data[1]["x"] == data[0]["x"]  # one frequency grid, stored once
    # float32 keeps 24 bits: the decoded values are the data rounded to float32, no worse.
    assert np.array_equal(x, f_hz.astype(np.float32))
    np.testing.assert_allclose(x, f_hz, rtol=2.0**-24)
    y = _decode(spec, data[0]["y"])
    assert np.isnan(y[:2]).all()  # 0 and −1 left out on the log axis
    np.testing.assert_allclose(y[2:], mag[2:], rtol=2.0**-24)  # float32 rounding, as above
    time_spec = figure_json(_time())
    offset = _decode(time_spec, time_spec["data"][1]["y"])
    assert offset.dtype == np.float64  # the offset rule: float32 would lose the signal
    assert np.array_equal(offset, _time().panels[1].traces[0].y)


def test_envelope_keeps_min_and_max() -> None:
    fig = _time()
    spec = figure_json(fig)
    y = _decode(spec, spec["data"][0]["y"])
    record = fig.panels[0].traces[0].y
    assert y.size <= 2 * 2000 + 2000  # two points per bin and a short tail
    assert y.max() == np.float32(record.max()) == np.float32(9.0)
    assert y.min() == np.float32(record.min())


def test_axes_sharing_ranges_and_legend() -> None:
    spec = figure_json(_bode())
    layout, data = spec["layout"], spec["data"]
    assert [layout[k]["type"] for k in ("xaxis", "yaxis", "xaxis2", "yaxis2")] == [
        "log", "log", "log", "linear"]
    assert layout["xaxis2"]["matches"] == "x" and "matches" not in layout["xaxis"]
    assert layout["xaxis"]["showticklabels"] is False  # only under the bottom panel
    assert layout["yaxis"]["range"] == pytest.approx([-3.0, 1.0])  # decades on a log axis
    assert layout["yaxis"]["autorange"] is False
    assert layout["xaxis"]["autorange"] is True and "range" not in layout["xaxis"]
    assert [(t["name"], t["showlegend"]) for t in data] == [
        ("h", True), ("v", True), ("h", False), ("v", False)]
    assert [t["legendgroup"] for t in data] == ["h", "v", "h", "v"]
    assert [t["line"]["color"] for t in data] == [H_COLOR, V_COLOR] * 2
    bars = figure_json(_bars())
    assert bars["layout"]["barmode"] == "group"
    assert [t["x"] for t in bars["data"]] == [["sensor", "actuator"]] * 2
    assert [_decode(bars, t["y"]).tolist() for t in bars["data"]] == [[1.0, 2.0], [3.0, 4.0]]


def _script_json(page: str, key: str) -> Any:
    m = re.search(rf'<script type="application/json" id="spec-{key}">(.*?)</script>', page,
                  re.S)
    assert m is not None
    return json.loads(m.group(1))


def test_html_escapes_script_end_and_refuses_duplicate_keys() -> None:
    evil = "h </script><script>alert(1)</script>"
    fig = Figure("evil", "t", "c", (Panel((Line([0.0, 1.0], [0.0, 1.0], name=evil),),
                                          "x [s]", "y [V]"),))
    page = render_report(title="t", sections=[Section("s", blocks=(fig,))])
    assert "alert(1)</script>" not in page
    assert _script_json(page, "evil")["data"][0]["name"] == evil  # "<\/" decodes back
    with pytest.raises(ValueError, match="figure keys used twice: evil"):
        render_report(title="t", sections=[Section("a", blocks=(fig,)),
                                           Section("b", blocks=(fig,))])
