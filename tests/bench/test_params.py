"""Bench parameters: derivations, TOML round trip, bad files."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from fsmbench.bench.params import (
    Bench,
    ParamsError,
    PerAxis,
    load_bench,
    param_rows,
    save_bench,
)


def test_nominal_sercalo_follows_from_datasheet(bench: Bench) -> None:
    """Nominal model parameters are the docs/model.md derivation of Table 1 (eqs. S1, S4)."""
    ds = bench.datasheet.sercalo
    nom = bench.nominal
    for axis in ("h", "v"):
        # S1: Table 1 gives current per angle; the model wants angle per current.
        dc = 1.0 / (ds.dc_gain_ma_per_deg[axis] * 1e-3 * 180.0 / math.pi)
        assert nom.sercalo.dc_gain_rad_per_a[axis] == pytest.approx(dc, rel=1e-12)
        # S4: |x/Uc|(jw0) = Gi0 g0 / (2 xi) with Gi0 = 1/(R + Rc) (no buffer resistance).
        gi0 = 1.0 / (nom.current_amplifier.r_ohm[axis] + nom.sercalo.r_coil_ohm[axis])
        gain_res = ds.gain_at_resonance_deg_per_v[axis] * math.pi / 180.0
        xi = gi0 * dc / (2.0 * gain_res)
        assert nom.sercalo.damping_ratio[axis] == pytest.approx(xi, rel=1e-12)
        assert nom.sercalo.resonance_hz[axis] == ds.resonance_hz[axis]


def test_numbers_the_seed_states(bench: Bench) -> None:
    """Converter step and the ESRF study's eq. 13 PSD; the Newport gain 26.2 mrad / 10 V."""
    conv = bench.nominal.converter
    assert conv.lsb_v == pytest.approx(20.0 / 65536)  # definition, exact
    # Seed 1.6 and eq. 13: 7.76e-13 V^2/Hz, printed to 3 digits.
    assert conv.quantisation_psd_v2_per_hz == pytest.approx(7.76e-13, rel=5e-3)
    ds = bench.datasheet.newport
    assert bench.nominal.newport.gain_rad_per_v.h == pytest.approx(ds.range_rad / ds.range_v)


def test_true_current_amplifier_is_the_seeds_identified_one(bench: Bench) -> None:
    """ESRF study 2.2 prints Gi = 0.01275 and 0.01382 A/V; the twin's circuit reproduces them."""
    g = bench.true.current_amp_gain_a_per_v()
    assert g.h == pytest.approx(0.01275, rel=1e-12)
    assert g.v == pytest.approx(0.01382, rel=1e-12)
    nominal = bench.nominal.current_amp_gain_a_per_v()
    assert nominal.h == pytest.approx(1 / 50.3, rel=1e-12)


def test_toml_round_trip_is_exact(bench: Bench, tmp_path: Path) -> None:
    path = save_bench(bench, tmp_path / "bench.toml")
    assert load_bench(path) == bench


def test_true_section_may_be_partial(bench: Bench, tmp_path: Path) -> None:
    text = bench.to_toml()
    head = text.split("\n[true.converter]")[0]
    path = tmp_path / "partial.toml"
    path.write_text(head + "\n[true.sercalo]\nresonance_hz = { h = 400.0 }\n")
    loaded = load_bench(path)
    expected = PerAxis(h=400.0, v=bench.nominal.sercalo.resonance_hz.v)
    assert loaded.true.sercalo.resonance_hz == expected
    assert loaded.true.newport == bench.nominal.newport


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda t: t.replace("fs_hz = 10000.0\n", "", 1), "missing key 'nominal.converter.fs_hz'"),
        (lambda t: t.replace("bits = 16", "bits = 16\nbitz = 3", 1), "unknown key(s) ['bitz']"),
        (lambda t: t.replace("bits = 16", "bits = 16.5", 1), "must be an integer"),
        (lambda t: t.replace("gain = 1000.0", 'gain = "big"', 1), "must be a number"),
        (lambda t: t.replace("gain = 1000.0", "gain = nan", 1), "must be finite"),
        (lambda t: t.replace("r_ohm = { h = 41.0, v = 41.0 }", "r_ohm = 41.0", 1),
         "must be a table { h = ..., v = ... }"),
        (lambda t: t + "\n[extra]\nx = 1\n", "unknown top-level table(s) ['extra']"),
        (lambda t: t + "\n = broken", "not valid TOML"),
    ],
)
def test_bad_parameter_files_name_file_and_key(bench: Bench, tmp_path: Path, edit, message) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(edit(bench.to_toml()))
    with pytest.raises(ParamsError) as err:
        load_bench(path)
    assert message in str(err.value)
    assert str(path) in str(err.value)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(ParamsError, match="no such parameter file"):
        load_bench(tmp_path / "nope.toml")


def test_every_parameter_has_unit_and_source(bench: Bench) -> None:
    rows = param_rows(bench)
    leaves = 0
    for group in (bench.nominal,):
        for f in dataclasses.fields(group):
            leaves += len(dataclasses.fields(getattr(group, f.name)))
    leaves += len(dataclasses.fields(bench.datasheet.sercalo))
    leaves += len(dataclasses.fields(bench.datasheet.newport))
    assert len(rows) == leaves
    for row in rows:
        assert row.unit and row.source and row.doc, row.key
    keys = [r.key for r in rows]
    assert "sercalo.damping_ratio" in keys and "converter.fs_hz" in keys


def test_per_axis() -> None:
    v = PerAxis(h=1.0, v=2.0)
    assert v["h"] == 1.0 and v["v"] == 2.0
    np.testing.assert_array_equal(v.as_array(), [1.0, 2.0])
    with pytest.raises(KeyError):
        v["x"]
