"""Records taken as read from what this process wrote (``load_recordings(written=)``):
the datasets, checks, notices and refusals of reading the files back."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from fsmbench.forked import fork_available
from fsmbench.io import folder as folder_module
from fsmbench.io.errors import RecordingError, SaturationWarning
from fsmbench.io.folder import load_recordings
from fsmbench.io.recording import (
    make_recording,
    mat_variables,
    read_recording,
    recording_as_read,
    write_recording,
)
from fsmbench.twin import TwinRun, write_twin

from .conftest import quantised


@pytest.fixture(scope="module")
def written_folder(short_twin: TwinRun, tmp_path_factory: pytest.TempPathFactory
                   ) -> tuple[Path, dict[Path, dict[str, np.ndarray]]]:
    out = tmp_path_factory.mktemp("twin-data")
    write_twin(short_twin, out)
    written = {out / f"{name}.mat": mat_variables(ds)
               for name, ds in short_twin.recordings.items()}
    return out, written


def _identical(a: xr.Dataset, b: xr.Dataset) -> None:
    """Equal values, dtypes, order and every attribute (the file read names itself)."""
    assert a.identical(b)
    assert list(a.variables) == list(b.variables)
    for name in a.variables:
        assert a[name].dtype == b[name].dtype and a[name].attrs == b[name].attrs


@pytest.mark.parametrize("parallel", [False, pytest.param(True, marks=pytest.mark.skipif(
    not fork_available(), reason="needs fork and two cores"))])
def test_what_was_written_is_what_reading_it_gives(
        written_folder: tuple[Path, dict[Path, dict[str, np.ndarray]]], parallel: bool) -> None:
    folder, written = written_folder
    read = load_recordings(folder, fs_hz=1e4, adc_range_v=20.0, adc_bits=16)
    taken = load_recordings(folder, fs_hz=1e4, adc_range_v=20.0, adc_bits=16,
                            written=written, parallel=parallel)
    assert list(taken.recordings) == list(read.recordings)
    for name, ds in read.recordings.items():
        _identical(taken.recordings[name], ds)
        assert taken.recordings[name].attrs["source"] == str((folder / f"{name}.mat").resolve())
    assert taken.checks == read.checks and taken.notices == read.notices
    assert taken.skipped == read.skipped


def test_only_files_to_decode_go_to_a_forked_reader(
        written_folder: tuple[Path, dict[Path, dict[str, np.ndarray]]]) -> None:
    """A forked reader is worth its fork for decoding: a record taken from memory stays here
    (its checks cost less than the fork's copy-on-write)."""
    _, written = written_folder
    found = {p.stem: p for p in written}
    assert folder_module._child_share(found, written) == set()
    half = dict(list(written.items())[::2])
    share = folder_module._child_share(found, half)
    assert share and not share & {p.stem for p in half}


def test_a_file_not_written_here_is_read(written_folder: tuple[Path, dict[Path, dict[
        str, np.ndarray]]]) -> None:
    """Only the files named are taken from memory: values written elsewhere (here, all
    zeros) never stand in for another file's."""
    folder, written = written_folder
    other = {folder.parent / "elsewhere" / p.name: {k: np.zeros_like(v) for k, v in
                                                   variables.items()}
             for p, variables in written.items()}
    taken = load_recordings(folder, fs_hz=1e4, written=other)
    read = load_recordings(folder, fs_hz=1e4)
    for name, ds in read.recordings.items():
        _identical(taken.recordings[name], ds)


def test_the_reader_s_notices_come_too(tmp_path: Path) -> None:
    """A saturated record: the reader's saturation notice is the same either way."""
    rng = np.random.default_rng(3)
    n = 20_000
    vph = quantised(rng, n, scale_v=1.0)
    vph[100:140] = 10.0 - 20.0 / 2**16  # on the upper rail
    with pytest.warns(SaturationWarning):
        ds = make_recording({"Vph": vph, "Vpv": quantised(rng, n),
                             "Va": 1e-9 * rng.standard_normal(n)},
                            fs_hz=1e4, experiment="data_huddle_test_1")
    path = write_recording(ds, tmp_path / "data_huddle_test_1.mat")
    read = load_recordings(tmp_path, fs_hz=1e4)
    taken = load_recordings(tmp_path, fs_hz=1e4, written={path: mat_variables(ds)})
    assert any("Vph" in n.message for n in read.notices)  # the case is the one meant
    assert taken.notices == read.notices and taken.checks == read.checks
    _identical(taken.recordings["data_huddle_test_1"], read.recordings["data_huddle_test_1"])


@pytest.mark.parametrize("format", ["mat5", "mat73"])
def test_recording_as_read_equals_read_recording(tmp_path: Path, format: str) -> None:
    rng = np.random.default_rng(4)
    ds = make_recording({"Uch": quantised(rng, 5000), "Vph": quantised(rng, 5000),
                         "Vpv": quantised(rng, 5000), "Vch": quantised(rng, 5000)},
                        fs_hz=1e4, experiment="data_uch")
    path = write_recording(ds, tmp_path / "data_uch.mat", format=format)
    _identical(recording_as_read(path, mat_variables(ds), experiment="data_uch"),
               read_recording(path, experiment="data_uch"))


def test_a_nexus_archive_is_not_taken_as_a_mat_file(tmp_path: Path) -> None:
    rng = np.random.default_rng(5)
    ds = make_recording({"Vph": quantised(rng, 100), "Vpv": quantised(rng, 100),
                         "Va": np.zeros(100)}, fs_hz=1e4, experiment="data_huddle_test_1")
    path = write_recording(ds, tmp_path / "data_huddle_test_1.mat", format="nexus")
    with pytest.raises(RecordingError, match="not the MAT-file"):
        recording_as_read(path, mat_variables(ds), experiment="data_huddle_test_1")
