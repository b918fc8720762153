"""The identification chapter's model-against-records figure (NRMSE fit) and model Bode band."""

from __future__ import annotations

import numpy as np
import pytest

from fsmbench.bench.params import Bench
from fsmbench.ident.pipeline import Identification, identify
from fsmbench.report.html import iter_figures
from fsmbench.report.sections.ident import identification_section
from fsmbench.twin import TwinRun

_IDENT = ("data_cal_pd_h", "data_cal_pd_v", "data_uch", "data_ucv", "data_unh", "data_unv")


@pytest.fixture(scope="module")
def result(short_twin: TwinRun, bench: Bench) -> Identification:
    return identify({k: short_twin.recordings[k] for k in _IDENT}, bench=bench)


def test_the_fits_and_the_band_ride_on_the_identification(result: Identification) -> None:
    cmp = result.comparison
    assert cmp is not None and result.bode_band is not None
    assert {(f.experiment, f.output) for f in cmp.fits} == {
        *((e, o) for e in ("data_uch", "data_ucv") for o in ("Vph", "Vpv")),
        ("data_uch", "Vch"), ("data_ucv", "Vcv"),  # the other coil's is not recorded
        *((e, o) for e in ("data_unh", "data_unv") for o in ("Vph", "Vpv"))}
    # The direct 4QD paths: the model reproduces the records up to the twin's noise.
    for e, o in (("data_uch", "Vph"), ("data_ucv", "Vpv")):
        assert cmp.fit_percent(e, o) > 95.0
    for e, o in (("data_unh", "Vph"), ("data_unv", "Vpv")):
        assert cmp.fit_percent(e, o) > 75.0
    js = result.to_json()["diagnostics"]
    assert len(js["model_fit"]["fits"]) == len(cmp.fits)
    assert set(js["bode_band"]["max_relative_magnitude_std"]) == {
        "Uch_to_Vph", "Ucv_to_Vpv", "Unh_to_Vph", "Unv_to_Vpv"}
    for p in result.bode_band.paths:
        assert np.all(np.isfinite(p.magnitude_std_v_per_v)) and np.all(
            p.magnitude_std_v_per_v > 0)


def test_the_chapter_draws_both_with_words_and_units(result: Identification,
                                                      short_twin: TwinRun,
                                                      bench: Bench) -> None:
    sec = identification_section(result, recordings=short_twin.recordings, bench=bench,
                                 truth=None, skipped={})
    figs = {f.key: f for f in iter_figures([sec])}
    cmp, band = figs["ident_model_compare"], figs["ident_model_bode_band"]
    assert "100 (1 − ‖y − ŷ‖ / ‖y − mean(y)‖)" in cmp.caption
    assert "mean" in cmp.caption and "settl" in cmp.caption and "at rest" in cmp.caption
    assert "±3 standard-deviation band" in band.caption and "independent" in band.caption
    assert "Sercalo static gains" in band.caption
    for fig in (cmp, band):
        for panel in fig.panels:
            assert "[" in panel.x_label and "[" in panel.y_label
    assert all("fit" in p.title and "%" in p.title for p in cmp.panels)
