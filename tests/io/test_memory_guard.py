"""A record too large to analyse in memory is refused in one line, before it is read.

Without the dask extra the loader reads every file whole; the guard estimates the
samples from the file's headers and refuses, with the way to analyse it, when the
analyses would not fit (:data:`fsmbench.io.folder.IN_MEMORY_FACTOR`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import fsmbench.io.folder as folder
import fsmbench.io.matfile as matfile
from fsmbench.io.errors import RecordingError
from fsmbench.io.folder import IN_MEMORY_FACTOR, load_recordings, sample_bytes
from fsmbench.io.matfile import detect_format
from fsmbench.io.recording import make_recording, write_recording

FS = 10_000.0
N = 20_000


def _huddle(n: int = N):
    rng = np.random.default_rng(0)
    return make_recording({"Vph": rng.normal(0, 0.01, n), "Vpv": rng.normal(0, 0.01, n),
                           "Va": rng.normal(0, 1e-9, n)}, fs_hz=FS,
                          experiment="data_huddle_test_1", source="test")


@pytest.fixture(params=["mat5", "mat73", "nexus"])
def huddle_file(request: pytest.FixtureRequest, tmp_path: Path) -> Path:
    suffix = ".h5" if request.param == "nexus" else ".mat"
    data = tmp_path / "data"
    data.mkdir()
    return write_recording(_huddle(), data / f"data_huddle_test_1{suffix}",
                           format=request.param, created=0.0)


def test_the_estimate_is_the_samples_the_file_holds(huddle_file: Path) -> None:
    # t and three signals of N float64 samples, read from the headers alone.
    assert sample_bytes(huddle_file, detect_format(huddle_file)) == 4 * N * 8


@pytest.mark.parametrize("dask_installed", [False, True])
def test_too_large_is_refused_with_the_way_to_analyse_it(
        huddle_file: Path, monkeypatch: pytest.MonkeyPatch, dask_installed: bool) -> None:
    if not dask_installed:
        monkeypatch.setitem(__import__("sys").modules, "dask", None)
    elif detect_format(huddle_file) != "mat5":
        pytest.skip("with dask, HDF5 files above LAZY_BYTES are read lazily, never whole")
    monkeypatch.setattr(folder, "_MEMORY_CHECK_BYTES", 0)
    # Just too little memory for the analysis of these samples.
    monkeypatch.setattr(matfile, "available_memory_bytes",
                        lambda: int(IN_MEMORY_FACTOR * 4 * N * 8) - 1)
    with pytest.raises(RecordingError) as err:  # the folder's only file is refused
        load_recordings(huddle_file.parent, fs_hz=FS)
    why = str(err.value)
    assert huddle_file.name in why and "GiB of samples" in why
    if detect_format(huddle_file) == "mat5":
        assert "fsmbench convert" in why and "--format nexus" in why
    else:
        assert "pip install 'fsmbench[dask]'" in why
    # Enough memory: read whole, as before.
    monkeypatch.setattr(matfile, "available_memory_bytes",
                        lambda: int(IN_MEMORY_FACTOR * 4 * N * 8))
    assert list(load_recordings(huddle_file.parent, fs_hz=FS).recordings) == [
        "data_huddle_test_1"]
