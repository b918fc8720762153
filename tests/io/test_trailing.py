"""A MAT or HDF5 file of valid variables followed by zeros (issue 30, item 7).

The files are written by scipy and raw h5py (conftest), then padded with
``os.truncate``, which makes a sparse hole: 20 GiB of zeros cost nothing on disk.
Each test checks against what it knows independently of the reader: the bytes
appended, scipy's or h5py's reading of the file before it was padded, and the
bytes the process read (``/proc/self/io``), never the time it took (the
benchmark ``benchmarks/bench_padding.py`` times it).
"""

from __future__ import annotations

import os
import shutil
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest
import scipy.io

from fsmbench.io.errors import RecordingError
from fsmbench.io.folder import load_recordings
from fsmbench.io.lazy import convert_recording, v5_vectors
from fsmbench.io.matfile import load_mat
from fsmbench.io.recording import read_recording
from fsmbench.io.trailing import TrailingBytesWarning, data_end

N = 3000
MIB = 1 << 20
GIB = 1 << 30
FORMATS = ["mat5-compressed", "mat5", "mat4", "mat73"]


def _variables() -> dict[str, np.ndarray]:
    """data_uch's variables (t in s, the rest in V), N samples."""
    rng = np.random.default_rng(30)
    lsb = 20.0 / 2**16
    out = {"t": np.arange(N) / 1e4}
    out.update({k: np.round(rng.standard_normal(N) * 3000) * lsb
                for k in ("Uch", "Vch", "Vph", "Vpv")})
    return out


@pytest.fixture
def write(write_v73_by_hand: Callable[..., Path]) -> Callable[[str, Path], Path]:
    """``write(fmt, path)``: data_uch's variables in ``fmt``, by scipy or raw h5py."""

    def make(fmt: str, path: Path) -> Path:
        v = _variables()
        if fmt == "mat73":
            return write_v73_by_hand(path, v)
        scipy.io.savemat(path, {k: x.reshape(-1, 1) for k, x in v.items()},
                         format="4" if fmt == "mat4" else "5",
                         do_compression=fmt == "mat5-compressed")
        return path

    return make


def _pad(path: Path, nbytes: int) -> int:
    """Append ``nbytes`` zeros as a hole (no disk used); return the size before."""
    size = path.stat().st_size
    os.truncate(path, size + nbytes)
    return size


def _bytes_read() -> int:
    """Bytes this process has read through read() and friends (Linux, /proc/self/io)."""
    with open("/proc/self/io") as fh:
        return int(next(line for line in fh if line.startswith("rchar:")).split()[1])


def _reference(fmt: str, path: Path) -> dict[str, np.ndarray]:
    """The unpadded file as scipy or h5py read it (MATLAB's N x 1 columns, flattened)."""
    if fmt == "mat73":
        with h5py.File(path, "r") as f:
            return {k: np.asarray(f[k][()]).ravel() for k in f}
    raw = scipy.io.loadmat(path)
    return {k: np.asarray(v).ravel() for k, v in raw.items() if not k.startswith("__")}


@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize("pad", [8, 64 * MIB, 20 * GIB], ids=["8B", "64MiB", "20GiB"])
def test_variables_before_zeros_are_read_and_the_zeros_named(
        tmp_path: Path, write: Callable[[str, Path], Path], fmt: str, pad: int) -> None:
    path = write(fmt, tmp_path / "data_uch.mat")
    clean = tmp_path / "clean.mat"
    shutil.copyfile(path, clean)
    size = _pad(path, pad)
    stamp = os.stat(path).st_mtime_ns
    before = _bytes_read()
    with pytest.warns(TrailingBytesWarning) as caught:
        got = load_mat(path)
    read = _bytes_read() - before
    # Nothing of the padding is read: the file's own bytes plus 1 MiB of imports and headers.
    assert read < size + MIB
    want = _reference(fmt, clean)
    assert list(got) == list(want)
    for name, values in want.items():
        assert np.array_equal(np.asarray(got[name]).ravel(), values), name
    (w,) = [w for w in caught if isinstance(w.message, TrailingBytesWarning)]
    text = str(w.message)
    assert text.startswith(f"{path}: its data end at byte {size}, ")
    assert f"{pad} bytes" in text and "ignored, not read" in text and "\n" not in text
    assert os.stat(path).st_size == size + pad and os.stat(path).st_mtime_ns == stamp


@pytest.mark.parametrize("fmt", ["mat5-compressed", "mat73"])
def test_the_folder_keeps_the_record_and_says_what_was_ignored(
        tmp_path: Path, write: Callable[[str, Path], Path], fmt: str) -> None:
    data = tmp_path / "data"
    data.mkdir()
    path = write(fmt, data / "data_uch.mat")
    size = _pad(path, 20 * GIB)
    loaded = load_recordings(data, fs_hz=1e4)
    assert list(loaded.recordings) == ["data_uch"]
    ds = loaded.recordings["data_uch"]
    assert np.array_equal(ds["Vph"].values, _variables()["Vph"])
    (notice,) = [n for n in loaded.notices if n.kind == "trailing_bytes"]
    assert notice.subject == "data_uch.mat"
    assert f"at byte {size}" in notice.message and f"({20 * GIB} bytes)" in notice.message
    # Once: the loader's warning capture does not repeat the recording's own note.
    assert [n.kind for n in loaded.notices].count("trailing_bytes") == 1


def test_a_record_read_lazily_says_so_too(tmp_path: Path,
                                          write: Callable[[str, Path], Path]) -> None:
    pytest.importorskip("dask")
    data = tmp_path / "data"
    data.mkdir()
    _pad(write("mat73", data / "data_uch.mat"), 64 * MIB)
    loaded = load_recordings(data, lazy_bytes=0)  # every HDF5 record through Dask
    assert [n.kind for n in loaded.notices] == ["trailing_bytes"]
    assert f"({64 * MIB} bytes)" in loaded.notices[0].message


def test_zeros_right_after_the_header_are_refused_in_one_line(tmp_path: Path) -> None:
    path = tmp_path / "data_uch.mat"
    scipy.io.savemat(path, {})  # the 128-byte header alone
    assert path.stat().st_size == 128
    _pad(path, 64 * MIB)
    with pytest.raises(RecordingError) as err:
        read_recording(path)
    assert str(err.value) == (f"{path}: holds no variable: its data end at byte 128, where an "
                              "element of type 0 begins (zeros, not a variable): the 64 MiB "
                              f"({64 * MIB} bytes) after them were ignored, not read")


def test_hdf5_superblock_version_3_is_read_too(tmp_path: Path) -> None:
    path = tmp_path / "rec.h5"
    with h5py.File(path, "w", libver="latest", userblock_size=1024) as f:
        f["x"] = np.arange(10.0)
    size = _pad(path, 4096)
    end = data_end(path, "hdf5")
    assert (end.end, end.trailing) == (size, 4096)


def test_a_truncated_hdf5_file_is_not_called_padded(tmp_path: Path,
                                                    write: Callable[[str, Path], Path]) -> None:
    path = write("mat73", tmp_path / "data_uch.mat")
    os.truncate(path, path.stat().st_size - 100)
    assert data_end(path, "mat73").trailing == 0
    with warnings.catch_warnings():
        warnings.simplefilter("error", TrailingBytesWarning)
        with pytest.raises(RecordingError, match=r"cannot be read as a MATLAB v7\.3 file"):
            load_mat(path)


def test_v5_headers_and_conversion_stop_at_the_zeros(tmp_path: Path,
                                                     write: Callable[[str, Path], Path]) -> None:
    path = write("mat5-compressed", tmp_path / "data_uch.mat")
    _pad(path, 20 * GIB)
    assert dict(v5_vectors(path)) == dict.fromkeys(_variables(), N)
    out = convert_recording(path, tmp_path / "data_uch.h5", created=0.0)
    back = read_recording(out)
    assert np.array_equal(back["Vch"].values, _variables()["Vch"])
    assert back.attrs["fs_hz"] == 1e4


def test_the_notes_of_a_reading_are_not_written_into_an_archive(
        tmp_path: Path, write: Callable[[str, Path], Path]) -> None:
    from fsmbench.io.recording import write_recording

    path = write("mat5", tmp_path / "data_uch.mat")
    _pad(path, 1024)
    with pytest.warns(TrailingBytesWarning):
        ds = read_recording(path)
    assert "trailing_bytes" in ds.attrs
    copy = write_recording(ds, tmp_path / "copy.h5", format="nexus", created=0.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error", TrailingBytesWarning)
        again: Any = read_recording(copy)
    assert "trailing_bytes" not in again.attrs


def test_an_empty_element_ends_the_data_too(tmp_path: Path,
                                            write: Callable[[str, Path], Path]) -> None:
    # A miMATRIX tag of 0 bytes (type 14): scipy refuses the file at it ("Did not read any
    # bytes"); the variables before it are kept, and what follows is not read.
    path = write("mat5", tmp_path / "data_uch.mat")
    size = path.stat().st_size
    with open(path, "ab") as fh:
        fh.write((14).to_bytes(4, "little") + bytes(4) + b"\xff" * 64)
    with pytest.raises(ValueError, match="Did not read any bytes"):
        scipy.io.loadmat(path)
    with pytest.warns(TrailingBytesWarning, match=f"at byte {size}, where an element of type "
                                                  r"14 and 0 bytes begins .*the 72 bytes"):
        got = load_mat(path)
    assert np.array_equal(got["Vph"].ravel(), _variables()["Vph"])
