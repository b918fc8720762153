"""One experiment in two files of a folder: data_uch.mat beside data_uch.h5 (issue 30, item 7).

The .mat is written by scipy and the .h5 by ``fsmbench convert`` (what a user does to
read a long record in pieces) or by raw h5py when it must differ; each test knows the
samples it wrote.
"""

from __future__ import annotations

import os
from pathlib import Path

import h5py
import numpy as np
import pytest
import scipy.io

import fsmbench.io.folder as folder
from fsmbench.io.folder import load_recordings
from fsmbench.io.lazy import convert_recording

N = 2000
FS = 1e4
LSB = 20.0 / 2**16


def _variables(**changes: np.ndarray | None) -> dict[str, np.ndarray]:
    """data_uch's variables (t in s, the rest in V) with some replaced or removed (None)."""
    rng = np.random.default_rng(11)
    out = {"t": np.arange(N) / FS}
    out.update({k: np.round(rng.standard_normal(N) * 3000) * LSB
                for k in ("Uch", "Vch", "Vph", "Vpv")})
    for key, value in changes.items():
        if value is None:
            del out[key]
        else:
            out[key] = value
    return out


def _nexus(path: Path, variables: dict[str, np.ndarray]) -> Path:
    """A NeXus archive in fsmbench's layout, by raw h5py (no validating writer)."""
    with h5py.File(path, "w") as f:
        entry = f.create_group("entry")
        entry.attrs["NX_class"] = "NXentry"
        entry.attrs["fs_hz"] = FS
        data = entry.create_group("data")
        data.attrs["NX_class"] = "NXdata"
        data.attrs["signal"] = "Vph"
        for name, values in variables.items():
            data[name] = values
    return path


@pytest.fixture
def data(tmp_path: Path) -> Path:
    """A folder holding data_uch.mat (scipy)."""
    root = tmp_path / "data"
    root.mkdir()
    scipy.io.savemat(root / "data_uch.mat", _variables(), oned_as="column")
    return root


def test_a_faithful_conversion_is_named_and_the_mat_read(data: Path) -> None:
    convert_recording(data / "data_uch.mat", data / "data_uch.h5", created=0.0)
    loaded = load_recordings(data, fs_hz=FS)
    ds = loaded.recordings["data_uch"]
    assert ds.attrs["source"] == str(data / "data_uch.mat")
    assert np.array_equal(ds["Vph"].values, _variables()["Vph"])
    (notice,) = [n for n in loaded.notices if n.kind == "file_choice"]
    assert notice.subject == "data_uch.mat"
    assert notice.message == ("read instead of data_uch.h5, which holds the same 5 variables "
                              f"of {N} samples (compared sample by sample)")


def test_one_sample_apart_refuses_the_experiment_naming_both(data: Path) -> None:
    vph = _variables()["Vph"].copy()
    before = vph[1017]
    vph[1017] += LSB
    _nexus(data / "data_uch.h5", _variables(Vph=vph))
    with pytest.raises(folder.RecordingError) as err:
        load_recordings(data, fs_hz=FS)  # the only experiment: the folder is refused
    text = str(err.value)
    assert (f"{data}: data_uch.mat and data_uch.h5 both hold data_uch but differ: Vph differs "
            f"first at sample 1017 (t = 0.1017 s): {before:.10g} V in data_uch.mat, "
            f"{vph[1017]:.10g} V in data_uch.h5 (1 sample differs); remove or rename the one "
            "that is not the record") in text
    assert "\n" not in text


def test_a_shorter_copy_is_told_from_the_headers(data: Path,
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    _nexus(data / "data_uch.h5", {k: v[:-1] for k, v in _variables().items()})
    reads: list[Path] = []
    real = folder._read
    monkeypatch.setattr(folder, "_read", lambda path, *a, **k: (reads.append(path),
                                                                real(path, *a, **k))[1])
    with pytest.raises(folder.RecordingError,
                       match=f"t has {N} samples in data_uch.mat and {N - 1} in data_uch.h5"):
        load_recordings(data, fs_hz=FS)
    assert reads == [data / "data_uch.mat"]  # the .h5's samples were never read


def test_a_variable_in_one_file_only_is_named(data: Path) -> None:
    _nexus(data / "data_uch.h5", _variables(Vch=None))
    with pytest.raises(folder.RecordingError, match=r"Vch is in data_uch\.mat only"):
        load_recordings(data, fs_hz=FS)


def test_an_unreadable_mat_beside_an_archive_names_both(data: Path) -> None:
    convert_recording(data / "data_uch.mat", data / "data_uch.h5", created=0.0)
    (data / "data_uch.mat").write_bytes(b"not a MAT-file")
    with pytest.raises(folder.RecordingError) as err:
        load_recordings(data, fs_hz=FS)
    assert ("data_uch.mat: is not a MAT-file (v4, v5/v7, v7.3) or HDF5 file: it holds text "
            "('not a MAT-file'); data_uch.h5 beside it holds data_uch too: remove or rename "
            "the file that is not the record") in str(err.value)


def test_a_link_to_the_same_file_is_not_a_second_file(data: Path) -> None:
    os.symlink("data_uch.mat", data / "data_uch.h5")
    loaded = load_recordings(data, fs_hz=FS)
    assert list(loaded.recordings) == ["data_uch"]
    assert not [n for n in loaded.notices if n.kind == "file_choice"]


def test_the_other_files_warnings_are_not_the_read_files(data: Path) -> None:
    convert_recording(data / "data_uch.mat", data / "data_uch.h5", created=0.0)
    os.truncate(data / "data_uch.h5", (data / "data_uch.h5").stat().st_size + 4096)
    loaded = load_recordings(data, fs_hz=FS)
    assert [n.kind for n in loaded.notices] == ["file_choice"]
