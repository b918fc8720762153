"""Chapter 1 (the bench and its recordings) and Appendix A (bench parameters)."""

from __future__ import annotations

import re

from fsmbench.bench.params import Bench, param_rows
from fsmbench.report.html import Section, Table, visible_text
from fsmbench.report.sections.bench import bench_section, parameters_appendix
from fsmbench.twin import TwinRun


def _table(sec: Section, caption_start: str) -> Table:
    (table,) = [b for b in sec.blocks if isinstance(b, Table)
                and b.caption.startswith(caption_start)]
    return table


def test_bench_text_quotes_numbers_derived_from_the_parameters(bench: Bench,
                                                              ident_twin: TwinRun) -> None:
    sec = bench_section(bench, recordings=ident_twin.recordings, skipped={}, source="twin",
                        is_twin=True)
    text = _joined(sec)
    # Gi = 1/(R + Rc) with R = 41 Ω and Rc = 9.3 Ω / 8.3 Ω (seed 2.2): 19.88 and 20.28 mA/V.
    assert "19.88 mA/V (h) and 20.28 mA/V (v)" in text
    # One 16-bit step over ±10 V: 20/2^16 = 305.2 µV; q²/(12 fs) = 7.76e-13 V²/Hz (seed 1.6).
    assert "305.2 µV" in text and "7.76e-13 V²/Hz" in text
    # The Sercalo path's delay: 1.5 samples at 10 kHz (errata E20).
    assert "0.15 ms on the Sercalo path" in text
    # The twin's current-amplifier gain 1/(41 + 9.3 + 28.13) Ω = 12.75 mA/V.
    assert "12.75 mA/V" in text and "digital twin" in text


def test_recordings_table_lists_records_and_skipped_experiments(bench: Bench,
                                                                ident_twin: TwinRun) -> None:
    recs = {k: ident_twin.recordings[k] for k in ("data_unh", "data_cal_pd_h")}
    sec = bench_section(bench, recordings=recs, source="/data/bench",
                        skipped={"data_ucv": "no data_ucv.mat in the folder"}, is_twin=False)
    table = _table(sec, "Recordings")
    assert table.header[2:5] == ("length [s]", "sampling rate [Hz]", "samples")
    # The seed's order, whatever the order of the mapping.
    assert [r[0] for r in table.rows] == ["data_cal_pd_h", "data_ucv", "data_unh"]
    cal, ucv, unh = table.rows
    ds = recs["data_cal_pd_h"]
    assert cal[4] == str(ds.sizes["t"]) and cal[3] == "10000"
    # Length from the samples: n / fs.
    assert float(cal[2]) == round(ds.sizes["t"] / 1e4, 2)
    assert cal[5] == "Vph, Vpv, Vnh"
    assert ucv[5] == "not loaded: no data_ucv.mat in the folder"
    assert "ESRF study 2.4" in unh[1]


def test_recorded_data_get_no_twin_wording(bench: Bench, ident_twin: TwinRun) -> None:
    sec = bench_section(bench, recordings=ident_twin.recordings, skipped={}, source="/data",
                        is_twin=False)
    app = parameters_appendix(bench, is_twin=False)
    for text in (_joined(sec), _joined(app)):
        assert "twin" not in text.lower() and "true" not in text.lower()


def test_parameter_appendix_has_every_parameter_in_words(bench: Bench) -> None:
    rows = param_rows(bench)
    twin = _table(parameters_appendix(bench, is_twin=True), "Bench parameters")
    recorded = _table(parameters_appendix(bench, is_twin=False), "Bench parameters")
    assert len(twin.rows) == len(recorded.rows) == len(rows)
    assert "true (twin)" in twin.header and "true (twin)" not in recorded.header
    col = twin.header.index("true (twin)")
    by_key = {r.key: r for r in rows}
    for row in twin.rows:
        src = by_key[row[-1]]
        assert row[1] == src.doc and row[2] == src.nominal
        assert row[col] == (src.true or "–")
        assert not row[0][0].islower() and "_" not in row[0] and "." not in row[0]  # words
    # Units everywhere; dimensionless as a dash, not "1".
    assert all(re.fullmatch(r"\S.*", r[recorded.header.index("unit")]) for r in recorded.rows)
    assert "1" not in {r[recorded.header.index("unit")] for r in recorded.rows}


def _joined(sec: Section) -> str:
    return "\n".join(visible_text([sec]))
