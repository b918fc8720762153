"""The report's bench, parameter and recording sections."""

from __future__ import annotations

from fsmbench.bench.params import Bench, param_rows
from fsmbench.report.bench_section import bench_section, parameters_section, recordings_section
from fsmbench.twin import TwinRun


def test_bench_text_quotes_derived_numbers(bench: Bench) -> None:
    text = " ".join(bench_section(bench).paragraphs)
    # Gi = 1/(R + Rc) with R = 41 Ω and Rc = 9.3 Ω (seed 2.2): 19.88 mA/V.
    assert "19.88 mA/V" in text
    # One 16-bit step over ±10 V: 20/2^16 = 305.2 µV.
    assert "305.2 µV" in text


def test_parameter_table_has_every_parameter(bench: Bench) -> None:
    (table,) = parameters_section(bench).tables
    assert len(table.rows) == len(param_rows(bench))
    assert all(row[3] for row in table.rows)  # every row has a unit


def test_recordings_section_lists_skipped(short_twin: TwinRun, bench: Bench) -> None:
    recs = {k: v for k, v in short_twin.recordings.items() if k in ("data_uch", "data_rep_h")}
    sec = recordings_section(recs, bench=bench, skipped={"data_ucv": "no data_ucv.mat"},
                             source="test")
    rows = sec.tables[0].rows
    assert [r[0] for r in rows] == ["data_uch", "data_rep_h", "data_ucv"]
    assert rows[-1][-1] == "skipped: no data_ucv.mat"
    assert len(sec.figures) == 2
