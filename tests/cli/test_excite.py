"""``fsmbench excite`` and ``fsmbench simulate --excitation`` end to end."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from fsmbench.bench.params import load_bench
from fsmbench.cli import main
from fsmbench.excite.design import design_noise
from fsmbench.excite.limits import converter_peaks

#: The one-line refusal of an excitation that leaves a converter's range.
OVER_RANGE = re.compile(r"Uch: an excitation of 0\.05 V rms drives ADC Vch to (?P<peak>\S+) V "
                        r"peak, beyond its ±10 V range \(nominal bench model\); at most "
                        r"(?P<fit>\S+) V rms fits")


def test_excite_writes_mat_json_and_prints_the_summary(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "ms"
    assert main(["excite", str(out), "--input", "Uch", "--kind", "multisine", "--band", "1",
                 "500", "--resolution", "1", "--amplitude-rms", "0.015", "--periods", "2",
                 "--transient-periods", "1", "--odd", "--seed", "3"]) == 0
    text = capsys.readouterr().out
    assert sorted(p.name for p in out.iterdir()) == ["excitation.json", "excitation.mat",
                                                     "run.json"]
    meta = json.loads((out / "excitation.json").read_text())
    assert meta["multisine"]["grid"] == "odd" and len(meta["multisine"]["lines_hz"]) == 250
    assert scipy.io.loadmat(out / "excitation.mat")["Uch"].shape == (30000, 1)
    lines = text.splitlines()
    assert lines[0] == ("Uch multisine: 250 lines from 1 to 499 Hz (odd grid, every 1 Hz), "
                        "0.015 V rms")
    assert lines[1] == "2 periods of 1 s + 1 transient period: 30000 samples at 10000 Hz (3 s)"
    cf = meta["crest_factor"]
    assert lines[2].startswith(f"crest factor {cf:.3f} (minimised phases; random phases: ")
    assert any(x.strip().startswith("ADC Vch: ") and "of ±10 V" in x for x in lines)


def test_excite_refuses_over_range_before_writing(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "loud"
    assert main(["excite", str(out), "--input", "Uch", "--kind", "noise", "--duration", "30",
                 "--amplitude-rms", "0.05"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    prefix = "fsmbench excite: error: "
    assert err[0].startswith(prefix)
    m = OVER_RANGE.fullmatch(err[0][len(prefix):])
    assert m is not None, err[0]
    # The numbers are those of the report of the same design (the command's defaults: the
    # nominal model, 1-2000 Hz, seed 0), to 3 significant digits.
    nominal = load_bench(None).nominal
    report = converter_peaks(design_noise(input="Uch", band_hz=(1.0, 2000.0),
                                          amplitude_rms_v=0.05, fs_hz=nominal.converter.fs_hz,
                                          duration_s=30.0, seed=0), params=nominal)
    assert float(m["peak"]) == float(f"{report.worst().peak_v:.3g}")
    assert float(m["fit"]) == report.fitting_amplitude_rms_v()
    assert not out.exists()  # nothing written


@pytest.mark.parametrize(("argv", "message"), [
    (["--input", "Vch", "--amplitude-rms", "0.01"], "invalid choice: 'Vch'"),
    (["--input", "Uch", "--amplitude-rms", "-1"], "not a finite positive number of volts"),
    (["--input", "Uch", "--amplitude-rms", "0.01", "--resolution", "0.3"],
     "whole number of samples"),
    (["--input", "Uch", "--amplitude-rms", "0.01", "--odd", "--odd-odd"], "not allowed with"),
])
def test_excite_bad_arguments_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                     argv: list[str], message: str) -> None:
    assert main(["excite", str(tmp_path / "x"), *argv]) == 2
    assert message in capsys.readouterr().err


def test_simulate_plays_the_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    exc = tmp_path / "chirp"
    assert main(["excite", str(exc), "--input", "Unv", "--kind", "chirp", "--band", "1", "100",
                 "--duration", "2", "--amplitude-rms", "0.1"]) == 0
    sim = tmp_path / "sim"
    assert main(["simulate", str(sim), "--excitation", str(exc / "excitation.mat"),
                 "--seed", "4"]) == 0
    assert sorted(p.name for p in sim.iterdir()) == ["data_unv.mat", "excitation_unv.json",
                                                     "run.json", "twin_truth.json"]
    # Its description beside the record: identify reads the transient periods from it.
    from fsmbench.ident.load import excitation_transients

    meta = json.loads((exc / "excitation.json").read_text())
    assert excitation_transients(sim) == {"data_unv": meta["transient_periods"]}
    data = scipy.io.loadmat(sim / "data_unv.mat")
    played = scipy.io.loadmat(exc / "excitation.mat")["Unv"][:, 0]
    # data_unv's 3.5 s minimum: 1.5 s before the start, the 2 s chirp, nothing after.
    assert data["Unv"].shape == (35000, 1)
    # The DAC rounds each sample to its 16-bit step (0.305 mV): half a step at most.
    np.testing.assert_allclose(data["Unv"][15000:, 0], played, atol=20 / 2**16 / 2 + 1e-15)
    assert np.all(data["Unv"][:15000, 0] == 0.0)
    truth = json.loads((sim / "twin_truth.json").read_text())
    assert truth["excitation_file"]["kind"] == "chirp"
    ex = truth["experiments"]["data_unv"]["excitations"][0]
    assert ex["kind"] == "samples" and ex["samples_v"]["n_samples"] == 20000
    # The seed's other experiments can join the played one in the same folder.
    assert main(["simulate", str(tmp_path / "s2"), "--excitation", str(exc),
                 "--experiments", "data_uch"]) == 0
    both = json.loads((tmp_path / "s2" / "twin_truth.json").read_text())
    assert sorted(both["experiments"]) == ["data_uch", "data_unv"]
    assert both["experiments"]["data_unv"]["excitations"][0]["kind"] == "samples"


def test_excite_twice_gives_byte_identical_files(tmp_path: Path) -> None:
    argv = ["--input", "Ucv", "--kind", "multisine", "--band", "10", "300", "--resolution",
            "2", "--amplitude-rms", "0.01", "--log-grid", "--seed", "7"]
    for name in ("a", "b"):
        assert main(["excite", str(tmp_path / name / "run"), *argv]) == 0
    for file in ("excitation.mat", "excitation.json", "run.json"):
        a = (tmp_path / "a" / "run" / file).read_bytes()
        assert a == (tmp_path / "b" / "run" / file).read_bytes(), file
    assert b"/a/" not in (tmp_path / "a" / "run" / "run.json").read_bytes()  # no folder path


def test_identify_drops_the_transient_periods_the_excitation_describes(tmp_path: Path) -> None:
    """excite → simulate --excitation → identify: the designed transient periods reach
    the periodic averaging through the description written beside the record."""
    exc = tmp_path / "ms"
    assert main(["excite", str(exc), "--input", "Uch", "--kind", "multisine", "--band", "5",
                 "500", "--resolution", "2", "--periods", "4", "--transient-periods", "3",
                 "--amplitude-rms", "0.03"]) == 0
    sim = tmp_path / "sim"
    assert main(["simulate", str(sim), "--excitation", str(exc), "--experiments",
                 "data_cal_pd_h", "data_cal_pd_v", "data_ucv", "--duration", "4"]) == 0
    out = tmp_path / "id"
    assert main(["identify", str(sim), "--out", str(out)]) == 0
    ident = json.loads((out / "identification.json").read_text())
    assert ident["diagnostics"]["options"]["transient_periods"] == {"data_uch": 3}
