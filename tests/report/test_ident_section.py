"""The report's identification section."""

from __future__ import annotations

from fsmbench.bench.params import Bench
from fsmbench.ident.pipeline import identify
from fsmbench.report.ident_section import identification_section
from fsmbench.twin import TwinRun


def test_section_has_the_seed_figures_and_the_truth_table(ident_twin: TwinRun,
                                                          bench: Bench) -> None:
    result = identify(ident_twin.recordings, bench=bench)
    sec = identification_section(result, recordings=ident_twin.recordings, bench=bench,
                                 truth=ident_twin.truth)
    refs = " ".join(f.seed_ref for f in sec.figures)
    for fig in ("10", "12–14", "17", "18", "19", "20", "25", "26", "28"):
        assert fig in refs, fig
    table = sec.tables[0]
    assert table.header[2] == "true value (twin)"
    assert all(row[-1] == "yes" for row in table.rows)


def test_without_truth_the_reference_is_nominal(ident_twin: TwinRun, bench: Bench) -> None:
    cal = {k: v for k, v in ident_twin.recordings.items() if k.startswith("data_cal")}
    result = identify(cal, bench=bench)
    sec = identification_section(result, recordings=cal, bench=bench, truth=None)
    assert sec.tables[0].header[2] == "nominal value"
    assert [r[0] for r in sec.tables[0].rows] == ["qd_gain_v_per_rad.h", "qd_gain_v_per_rad.v"]
    assert any("Skipped" in p for p in sec.paragraphs)
