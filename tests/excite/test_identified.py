"""``fsmbench excite --bench DIR``: the 4QD a calibration measured limits the excitation.

Reference: the real-bench twin's 4QD, 2 % compressed at 10.6 mrad of beam,
calibrated by ``identify`` from its own ``data_cal_pd_h/v`` records.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from fsmbench.bench.params import real_bench
from fsmbench.cli import main
from fsmbench.excite.identified import with_identified_quad_diode
from fsmbench.ident.pipeline import identify, write_identification
from fsmbench.io.errors import RecordingError
from fsmbench.twin import simulate_bench

TRUE_PCT, TRUE_SWING_RAD = 2.0, 0.0106  # real_bench.toml


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory: pytest.TempPathFactory) -> Path:
    bench = real_bench()
    run = simulate_bench(bench, seed=0, experiments=["data_cal_pd_h", "data_cal_pd_v"])
    out = tmp_path_factory.mktemp("ident")
    write_identification(identify(run.recordings, bench=bench, source="twin"), out)
    return out


def test_the_identified_compression_is_the_twins(calibrated: Path) -> None:
    bench = real_bench()
    params = with_identified_quad_diode(bench.nominal, calibrated)
    qd = params.quad_diode
    # The twin's compression is exactly cubic: k(θ) = 2 % (θ / 10.6 mrad)².
    expected = TRUE_PCT * (qd.nonlinearity_full_swing_rad / TRUE_SWING_RAD) ** 2
    # 10 %: the cubic term of one 11 s calibration, the larger of the two axes (3.4 % high
    # on this seed).
    assert qd.nonlinearity_pct == pytest.approx(expected, rel=0.10)
    # The gains are the identified ones (within the identification's 1 % target of the truth).
    for axis in "hv":
        true_gain = getattr(bench.true.quad_diode.gain_v_per_rad, axis)
        assert getattr(qd.gain_v_per_rad, axis) == pytest.approx(true_gain, rel=0.01)
    # Nothing else of the model changes.
    assert params.sercalo == bench.nominal.sercalo
    assert params.converter == bench.nominal.converter


def test_excite_refuses_what_the_identified_4qd_cannot_take(
        calibrated: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    args = ["--input", "Uch", "--band", "1", "2000", "--resolution", "1", "--periods", "2",
            "--odd", "--bench", str(calibrated)]
    assert main(["excite", str(tmp_path / "loud"), "--amplitude-rms", "0.015", *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "4QD (Vph)" in err[0] and "4QD identified in" in err[0], err
    assert not (tmp_path / "loud").exists()
    fitting = float(err[0].split("at most ")[1].split(" V rms")[0])
    assert main(["excite", str(tmp_path / "ok"), "--amplitude-rms", f"{fitting}", *args]) == 0
    meta = json.loads((tmp_path / "ok" / "excitation.json").read_text())
    assert "4QD identified in" in json.dumps(meta)


def test_a_model_without_a_calibration_is_one_line(tmp_path: Path) -> None:
    (tmp_path / "identification.json").write_text(json.dumps({"diagnostics": {}}))
    with pytest.raises(RecordingError, match="no 4QD calibration of both axes"):
        with_identified_quad_diode(real_bench().nominal, tmp_path)
    with pytest.raises(RecordingError, match="does not exist"):
        with_identified_quad_diode(real_bench().nominal, tmp_path / "nowhere")
