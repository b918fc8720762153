"""Time-domain figures of one experiment: one panel per signal, units, shading."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from fsmbench.report.figures.spec import H_COLOR, V_COLOR, Line, Panel
from fsmbench.report.figures.time import SEED_TIME_FIGURES, experiment_figure, signal_panels
from fsmbench.twin import TwinRun

GN0 = 2.62e-3  # seed 2.1, rad/V


def _line(panel: Panel) -> Line:
    (line,) = panel.traces
    assert isinstance(line, Line)
    return line


@pytest.mark.parametrize("name", sorted(SEED_TIME_FIGURES))
def test_one_panel_per_signal_with_units_and_axis_colours(ident_twin: TwinRun, name: str) -> None:
    ds = ident_twin.recordings[name]
    key, ref, _title = SEED_TIME_FIGURES[name]
    fig = experiment_figure(ds, key=key, title=name, caption="c", seed_ref=ref,
                            gn0_rad_per_v=GN0, trim_s=1.0)
    drawn = [p.traces[0].name for p in fig.panels]
    assert sorted(drawn) == sorted(str(v) for v in ds.data_vars)  # every signal, once each
    assert "Vph" in drawn and "Vpv" in drawn  # never one hiding the other
    t = ds["t"].values
    for panel in fig.panels:
        (line,) = panel.traces
        assert isinstance(line, Line) and line.decimate
        assert panel.x_label == "Time [s]"
        assert "[" in panel.y_label and panel.y_label.endswith("]")
        assert line.color == (H_COLOR if line.name.endswith("h") else V_COLOR)
        assert panel.shade == (t[0], 1.0)
        assert np.isfinite(line.y).all() and line.y.size == t.size
    assert fig.share_x and fig.key == key


def test_metrology_is_drawn_as_beam_angle(ident_twin: TwinRun) -> None:
    ds = ident_twin.recordings["data_cal_pd_h"]
    fig = experiment_figure(ds, key="k", title="t", caption="c", seed_ref="", gn0_rad_per_v=GN0,
                            trim_s=0.0)
    (panel,) = [p for p in fig.panels if p.traces[0].name == "Vnh"]
    # Beam angle = 2 x mirror angle = 2 gn0 Vnh, in mrad (seed 2.1).
    np.testing.assert_allclose(_line(panel).y, 2 * GN0 * ds["Vnh"].values * 1e3, rtol=1e-12)
    assert panel.y_label == "Beam angle [mrad]"
    assert all(p.shade is None for p in fig.panels)  # nothing removed, nothing shaded


def test_attocube_drawn_in_nm_mean_removed_and_order_fixed() -> None:
    t = np.arange(1000) / 1e4
    va = 0.1 + 1e-9 * np.sin(2 * np.pi * 50 * t)  # 0.1 m away, ±1 nm
    ds = xr.Dataset({"Va": ("t", va), "Vpv": ("t", np.ones_like(t)), "Uch": ("t", t)},
                    coords={"t": t}, attrs={"fs_hz": 1e4, "experiment": "data_huddle_test_3"})
    fig = experiment_figure(ds, key="k", title="t", caption="c", seed_ref="", gn0_rad_per_v=GN0,
                            trim_s=0.0)
    assert [p.traces[0].name for p in fig.panels] == ["Uch", "Vpv", "Va"]
    y = _line(fig.panels[-1]).y
    np.testing.assert_allclose(y, 1e9 * (va - va.mean()), atol=1e-6)  # float rounding of 0.1 m
    assert fig.panels[-1].y_label == "Distance [nm]"


def test_a_record_without_known_signals_is_named() -> None:
    ds = xr.Dataset({"foo": ("t", np.zeros(4))}, coords={"t": np.arange(4.0)},
                    attrs={"experiment": "data_odd"})
    with pytest.raises(ValueError, match=r"data_odd: none of the ESRF study's signals .*foo"):
        experiment_figure(ds, key="k", title="t", caption="c", seed_ref="", gn0_rad_per_v=GN0,
                          trim_s=0.0)


def test_every_signal_of_the_seed_has_a_panel_spec() -> None:
    from fsmbench.io.signals import SIGNALS

    assert [s.signal for s in signal_panels(GN0)] == [
        "Unh", "Unv", "Uch", "Ucv", "Vnh", "Vnv", "Vch", "Vcv", "Vph", "Vpv", "Va"]
    assert {s.signal for s in signal_panels(GN0)} == set(SIGNALS)
