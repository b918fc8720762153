"""Excitation files: what a real-time target reads, the JSON, the reader's verdicts."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from fsmbench.bench.params import default_bench
from fsmbench.excite.design import design_chirp, design_multisine
from fsmbench.excite.files import (
    EXCITATION_FORMAT,
    ExcitationFileError,
    read_excitation,
    write_excitation,
)
from fsmbench.excite.limits import converter_peaks

FS = 10_000.0


@pytest.fixture(scope="module")
def design():
    return design_multisine(input="Ucv", band_hz=(2.0, 300.0), resolution_hz=2.0,
                            amplitude_rms_v=0.01, fs_hz=FS, seed=9, periods=2,
                            transient_periods=1, grid="odd", phase_method="schroeder")


@pytest.fixture
def written(design, tmp_path: Path) -> tuple[Path, Path]:
    report = converter_peaks(design, params=default_bench().nominal)
    return write_excitation(design, tmp_path, limits=report)


def test_mat_file_holds_columns_a_target_plays(design, written) -> None:
    mat, _ = written
    data = scipy.io.loadmat(mat)  # an independent reader
    assert {k for k in data if not k.startswith("__")} == {"t", "Ucv"}
    assert data["Ucv"].shape == (design.samples_v.size, 1)  # column vectors
    np.testing.assert_array_equal(data["Ucv"][:, 0], design.samples_v)
    np.testing.assert_array_equal(data["t"][:, 0], np.arange(design.samples_v.size) / FS)


def test_json_describes_the_design(design, written) -> None:
    _, js = written
    meta = json.loads(js.read_text())
    assert (meta["format"], meta["format_version"]) == EXCITATION_FORMAT
    assert meta["input"] == "Ucv" and meta["kind"] == "multisine" and meta["fs_hz"] == FS
    assert meta["period_samples"] == 5000 and meta["periods"] == 2
    assert meta["transient_periods"] == 1 and meta["transient_s"] == 0.5
    assert meta["after_end"] == "repeat" and meta["seed"] == 9
    ms = meta["multisine"]
    assert ms["grid"] == "odd" and ms["resolution_hz"] == 2.0
    assert ms["lines_hz"] == design.lines_hz.tolist()  # exact: JSON floats round-trip
    assert all(h % 2 == 1 for h in ms["harmonics"])
    assert meta["limits"]["peaks"][0] == {"converter": "DAC", "signal": "Ucv",
                                          "peak_v": float(np.abs(design.samples_v).max()),
                                          "limit_v": 10.0}


def test_roundtrip(design, written) -> None:
    mat, js = written
    for source in (mat, js, js.parent):
        back = read_excitation(source)
        for field in ("input", "kind", "fs_hz", "period_samples", "periods",
                      "transient_periods", "amplitude_rms_v", "band_hz", "seed",
                      "crest_factor", "line_amplitude_v", "grid", "log_grid", "phase_method",
                      "crest_factor_random_phase", "after_end"):
            assert getattr(back, field) == getattr(design, field), field
        np.testing.assert_array_equal(back.samples_v, design.samples_v)
        np.testing.assert_array_equal(back.phases_rad, design.phases_rad)
        np.testing.assert_array_equal(back.lines_hz, design.lines_hz)


def test_chirp_roundtrip(tmp_path: Path) -> None:
    d = design_chirp(input="Unv", band_hz=(1.0, 100.0), amplitude_rms_v=0.1, fs_hz=FS,
                     duration_s=1.0, method="log")
    _, js = write_excitation(d, tmp_path, stem="sweep")
    back = read_excitation(js)
    assert back.chirp_method == "log" and back.after_end == "zero"
    np.testing.assert_array_equal(back.samples_v, d.samples_v)


def _edit(js: Path, **changes) -> None:
    meta = json.loads(js.read_text())
    meta.update(changes)
    js.write_text(json.dumps(meta))


@pytest.mark.parametrize(("changes", "problem"), [
    ({"format_version": 2}, "has format version 2; this fsmbench reads version 1"),
    ({"format": "fsmbench.other"}, "is not an excitation description"),
    ({"input": "Vch"}, "input 'Vch' is not a DAC channel"),
    ({"periods": 3}, "15000 samples are not 3 + 1 periods of 5000 samples"),
    ({"samples_sha256": "0" * 64}, "Ucv is not the signal excitation.json describes"),
    ({"mat_file": "gone.mat"}, "cannot be read as the excitation's MAT-file"),
    ({"after_end": "loop"}, "after_end 'loop' is not 'zero' or 'repeat'"),
    ({"band_hz": [1.0]}, "band_hz [1.0] is not a pair of frequencies"),
])
def test_bad_files_get_one_line_naming_the_file(written, changes, problem) -> None:
    _, js = written
    _edit(js, **changes)
    with pytest.raises(ExcitationFileError) as info:
        read_excitation(js)
    msg = str(info.value)
    assert "\n" not in msg and problem in msg
    assert msg.startswith(str(js.parent))  # names the JSON or the MAT-file beside it


def test_missing_key_and_broken_json(written) -> None:
    mat, js = written
    meta = json.loads(js.read_text())
    del meta["seed"]
    js.write_text(json.dumps(meta))
    with pytest.raises(ExcitationFileError, match=r"excitation.json: has no 'seed'"):
        read_excitation(js)
    js.write_text("{not json")
    with pytest.raises(ExcitationFileError, match="is not a readable JSON file"):
        read_excitation(mat)
    with pytest.raises(ExcitationFileError, match="holds 0 excitation descriptions"):
        read_excitation(js.parent)


def test_samples_changed_in_the_mat_file_are_caught(written) -> None:
    mat, js = written
    data = scipy.io.loadmat(mat)
    data["Ucv"][10, 0] += 1e-12
    scipy.io.savemat(mat, {"t": data["t"], "Ucv": data["Ucv"]})
    with pytest.raises(ExcitationFileError, match=r"excitation.mat: Ucv is not the signal"):
        read_excitation(js)
