"""fsmbench.io.recording: building, reading, writing and finding recordings."""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import scipy.io
import xarray as xr

from fsmbench.io import matfile, matwrite, nexus
from fsmbench.io.errors import RecordingError
from fsmbench.io.recording import (
    find_experiments,
    make_recording,
    read_recording,
    validate_recording,
    write_recording,
)
from fsmbench.io.signals import EXPERIMENTS, SIGNALS

FORMATS = ["mat5", "mat73", "nexus"]


def _assert_same_samples(a: xr.Dataset, b: xr.Dataset) -> None:
    """Same variables, same bytes (bit-exact), same attrs except ``source``."""
    assert sorted(map(str, a.variables)) == sorted(map(str, b.variables))
    for name in a.variables:
        assert a[name].dtype == b[name].dtype == np.float64
        assert a[name].values.tobytes() == b[name].values.tobytes(), name
        assert a[name].attrs == b[name].attrs, name
    assert a.attrs["fs_hz"] == b.attrs["fs_hz"]
    assert a.attrs["experiment"] == b.attrs["experiment"]


# --------------------------------------------------------------------------- make
def test_make_recording_layout(recording: xr.Dataset, n_samples: int, fs_hz: float) -> None:
    ds = recording
    assert list(ds.data_vars) == list(SIGNALS)  # the seed's table order
    assert ds.sizes == {"t": n_samples}
    assert ds["t"].attrs["units"] == "s"
    assert ds["t"].values.tobytes() == (np.arange(n_samples) / fs_hz).tobytes()
    for name, info in SIGNALS.items():
        assert ds[name].dims == ("t",)
        assert ds[name].dtype == np.float64
        assert ds[name].attrs == {"units": info.units, "long_name": info.long_name}
    assert ds.attrs == {"fs_hz": fs_hz, "experiment": "data_rep_h", "source": ""}
    assert isinstance(ds.attrs["fs_hz"], float)


def test_make_recording_from_t(time_s: np.ndarray, adc_noise: Callable[..., np.ndarray]) -> None:
    ds = make_recording({"Vph": adc_noise()}, t=time_s, experiment="x")
    assert ds.attrs["fs_hz"] == 1e4  # recovered exactly from t
    ds2 = make_recording({"t": time_s, "Vph": adc_noise()}, experiment="x")
    assert ds2["t"].values.tobytes() == time_s.tobytes()


def test_make_recording_orders_and_notes_unknown_signals(
    time_s: np.ndarray, adc_noise: Callable[..., np.ndarray]
) -> None:
    ds = make_recording({"extra": adc_noise(), "Vpv": adc_noise(), "Uch": adc_noise()},
                        t=time_s, experiment="x")
    assert list(ds.data_vars) == ["Uch", "Vpv", "extra"]
    assert ds["extra"].attrs["units"] == ""
    assert "not in the ESRF study's signal table" in ds["extra"].attrs["note"]


@pytest.mark.parametrize("shape", [(-1,), (-1, 1), (1, -1)])
def test_make_recording_copies_and_never_modifies_inputs(
    shape: tuple[int, ...], adc_noise: Callable[..., np.ndarray]
) -> None:
    x = adc_noise().reshape(shape)
    kept = x.copy()
    ds = make_recording({"Vph": x}, fs_hz=1e4, experiment="x")
    x[...] = 0.0  # a later change of the caller's array must not reach the recording
    assert ds["Vph"].values.tobytes() == kept.ravel().tobytes()
    assert not np.shares_memory(ds["Vph"].values, x)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({}, "give t"),
        ({"t": np.arange(3) / 1e4, "signals": {"t": np.arange(3) / 1e4}}, "t is given both"),
        ({"fs_hz": 1e4, "signals": {}}, "no signals and no t"),
    ],
)
def test_make_recording_arguments(kwargs: dict[str, Any], match: str) -> None:
    signals = kwargs.pop("signals", {"Vph": np.zeros(3)})
    with pytest.raises(ValueError, match=match):
        make_recording(signals, experiment="x", **kwargs)


def test_make_recording_fs_must_agree_with_t(time_s: np.ndarray) -> None:
    with pytest.raises(RecordingError, match=r"recording 'x': attribute 'fs_hz' = 5000 Hz "
                       r"disagrees with t.*10000 Hz"):
        make_recording({"Vph": np.zeros(time_s.size)}, t=time_s, fs_hz=5e3, experiment="x")


# --------------------------------------------------------------------------- round trips
@pytest.mark.parametrize("fmt", FORMATS)
def test_round_trip_is_bit_exact(tmp_path: Path, recording: xr.Dataset, fmt: str) -> None:
    path = write_recording(recording, tmp_path / "data_rep_h.dat", format=fmt)  # type: ignore[arg-type]
    back = read_recording(path)
    _assert_same_samples(recording, back)
    if fmt == "nexus":
        xr.testing.assert_identical(back, recording)
    else:
        assert back.attrs["source"] == os.path.abspath(path)


@pytest.mark.parametrize("fmt", FORMATS)
def test_round_trip_unusual_fs_and_offset_t(tmp_path: Path, fmt: str) -> None:
    fs = 12345.678901  # 11 significant digits survive the MAT-file's t
    t = 3.5 + np.arange(500) / fs
    ds = make_recording({"Vph": np.sin(t)}, t=t, experiment="data_x")
    back = read_recording(write_recording(ds, tmp_path / "data_x.mat", format=fmt))  # type: ignore[arg-type]
    _assert_same_samples(ds, back)
    assert back.attrs["fs_hz"] == fs


@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize("suffix", [".mat", ".h5", ".nxs", ""])
def test_format_is_told_from_content(
    tmp_path: Path, recording: xr.Dataset, fmt: str, suffix: str
) -> None:
    path = write_recording(recording, tmp_path / f"data_rep_h{suffix}", format=fmt)  # type: ignore[arg-type]
    _assert_same_samples(recording, read_recording(path))


def test_mat5_is_what_matlab_load_expects(tmp_path: Path, recording: xr.Dataset) -> None:
    path = write_recording(recording, tmp_path / "data_rep_h.mat")
    raw = scipy.io.loadmat(path, variable_names=list(EXPERIMENTS["data_rep_h"].required))
    for name in EXPERIMENTS["data_rep_h"].required:
        assert raw[name].shape == (recording.sizes["t"], 1)
        assert raw[name].dtype == np.float64
        assert raw[name].ravel().tobytes() == recording[name].values.tobytes()


@pytest.mark.parametrize("fmt", FORMATS)
def test_written_files_pass_through_other_readers(
    tmp_path: Path, recording: xr.Dataset, fmt: str
) -> None:
    path = write_recording(recording, tmp_path / "x.bin", format=fmt)  # type: ignore[arg-type]
    expected = {"mat5": "mat5", "mat73": "mat73", "nexus": "hdf5"}[fmt]
    assert matfile.detect_format(path) == expected
    assert nexus.is_nexus(path) == (fmt == "nexus")


# --------------------------------------------------------------------------- reading
def test_row_vector_t_reads_v5(
    tmp_path: Path, write_v5: Callable[..., Path], time_s: np.ndarray,
    adc_noise: Callable[..., np.ndarray],
) -> None:
    x = adc_noise()
    path = write_v5(tmp_path / "rec.mat", {"t": time_s, "Vph": x}, oned_as="row")
    assert scipy.io.loadmat(path)["t"].shape == (1, time_s.size)
    ds = read_recording(path)
    assert ds["t"].values.tobytes() == time_s.tobytes()
    assert ds["Vph"].values.tobytes() == x.tobytes()


def test_row_vector_t_reads_v73(
    tmp_path: Path, write_v73_by_hand: Callable[..., Path], time_s: np.ndarray,
    adc_noise: Callable[..., np.ndarray],
) -> None:
    x = adc_noise()
    path = write_v73_by_hand(tmp_path / "rec.mat", {"t": time_s.reshape(1, -1), "Vph": x})
    ds = read_recording(path)
    assert ds["t"].values.tobytes() == time_s.tobytes()
    assert ds["Vph"].values.tobytes() == x.tobytes()
    assert ds.attrs["fs_hz"] == 1e4


def test_matlab_v73_file_reads_as_recording(
    tmp_path: Path, write_v73_by_hand: Callable[..., Path], time_s: np.ndarray,
    adc_noise: Callable[..., np.ndarray],
) -> None:
    sig = {name: adc_noise() for name in ("Uch", "Vch", "Vph", "Vpv")}
    path = write_v73_by_hand(tmp_path / "data_uch.mat", {"t": time_s, **sig})
    ds = read_recording(path)
    assert ds.attrs["experiment"] == "data_uch"
    assert list(ds.data_vars) == ["Uch", "Vph", "Vpv", "Vch"]
    for name, x in sig.items():
        assert ds[name].values.tobytes() == x.tobytes()
        assert ds[name].attrs["units"] == "V"


def test_v4_file_reads_as_recording(tmp_path: Path, time_s: np.ndarray) -> None:
    scipy.io.savemat(tmp_path / "rec.mat", {"t": time_s, "Va": time_s * 1e-6},
                     format="4", oned_as="column")
    ds = read_recording(tmp_path / "rec.mat")
    assert ds["Va"].attrs["units"] == "m"
    assert ds["Va"].values.tobytes() == (time_s * 1e-6).tobytes()


def test_required_defaults_to_the_seeds_load_list(
    tmp_path: Path, write_v5: Callable[..., Path], time_s: np.ndarray
) -> None:
    z = np.zeros(time_s.size)
    path = write_v5(tmp_path / "data_unh.mat", {"t": time_s, "Unh": z, "Vph": z})
    with pytest.raises(RecordingError) as err:
        read_recording(path)
    msg = str(err.value)
    assert msg.startswith(f"{path}: variable 'Vpv' is missing")
    assert "data_unh needs t, Unh, Vph, Vpv" in msg
    assert "the file holds: t, Unh, Vph" in msg
    # an explicit require replaces the default; an unknown stem needs only t
    assert list(read_recording(path, require=()).data_vars) == ["Unh", "Vph"]
    renamed = write_v5(tmp_path / "mine.mat", {"t": time_s, "Unh": z, "Vph": z})
    assert list(read_recording(renamed).data_vars) == ["Unh", "Vph"]
    assert read_recording(renamed).attrs["experiment"] == "mine"
    with pytest.raises(RecordingError, match=r"mine\.mat: variable 'Vpv' is missing; data_unh "
                       r"needs t, Unh, Vph, Vpv"):
        read_recording(renamed, experiment="data_unh")
    with pytest.raises(RecordingError, match=r"variable 'Vnh' is missing \(and so are 'Vnv'\)"):
        read_recording(renamed, require=["Vph", "Vnh", "Vnv"])


def test_extra_variables(
    tmp_path: Path, write_v5: Callable[..., Path], time_s: np.ndarray,
    adc_noise: Callable[..., np.ndarray],
) -> None:
    x = adc_noise()
    path = write_v5(tmp_path / "rec.mat", {"t": time_s, "Vph": x, "temp": x + 20,
                                           "fs": 1e4, "comment": "hi", "cfg": {"a": 1.0}})
    with pytest.warns(UserWarning) as caught:
        ds = read_recording(path)
    assert list(ds.data_vars) == ["Vph", "temp"]
    assert ds["temp"].attrs["units"] == ""
    assert "not in the ESRF study's signal table" in ds["temp"].attrs["note"]
    messages = sorted(str(w.message) for w in caught)
    assert messages == [
        f"{path}: variable 'cfg' left out: holds a struct (fields: a), not samples",
        f"{path}: variable 'comment' left out: holds text ('hi'), not samples",
        f"{path}: variable 'fs' left out: it has 1 value and t has {time_s.size}, "
        "so it is not sampled on t",
    ]


@pytest.mark.parametrize("fmt", FORMATS)
def test_reading_never_touches_the_input(
    tmp_path: Path, recording: xr.Dataset, fmt: str,
    snapshot: Callable[[Path], tuple[bytes, int]],
) -> None:
    path = write_recording(recording, tmp_path / "data_rep_h.mat", format=fmt)  # type: ignore[arg-type]
    os.chmod(path, 0o444)  # read-only input must still read
    before = snapshot(path)
    read_recording(path)
    assert snapshot(path) == before
    assert [p.name for p in tmp_path.iterdir()] == ["data_rep_h.mat"]


# --------------------------------------------------------------------------- writing
@pytest.mark.parametrize("exc", [OSError("disk full"), KeyboardInterrupt()])
@pytest.mark.parametrize(
    ("fmt", "target", "attr"),
    [("mat5", matwrite, "_deflate"),
     ("mat73", matwrite._H5Writer, "_numeric"),
     ("nexus", nexus.h5py.Group, "create_dataset")],
)
def test_interrupted_write_leaves_no_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, recording: xr.Dataset, fmt: str,
    target: Any, attr: str, exc: BaseException,
) -> None:
    original = getattr(target, attr)
    calls = {"n": 0}

    def fail_midway(*args: Any, **kwargs: Any) -> Any:
        calls["n"] += 1
        if calls["n"] == 4:  # after a few variables are in the file
            raise exc
        return original(*args, **kwargs)

    monkeypatch.setattr(target, attr, fail_midway)
    with pytest.raises(type(exc)):
        write_recording(recording, tmp_path / "data_rep_h.mat", format=fmt)  # type: ignore[arg-type]
    assert calls["n"] >= 4  # mat5 encodes variables in parallel threads
    assert list(tmp_path.iterdir()) == []


def test_invalid_recording_is_not_written(tmp_path: Path, recording: xr.Dataset) -> None:
    bad = recording.copy(deep=True)
    bad["Vph"].values[7] = np.nan
    with pytest.raises(RecordingError, match=r"out\.mat: variable 'Vph' holds 1 NaN value "
                       r"\(first at index 7, t = 0\.0007 s\)"):
        write_recording(bad, tmp_path / "out.mat")
    assert list(tmp_path.iterdir()) == []


def test_unknown_format(tmp_path: Path, recording: xr.Dataset) -> None:
    with pytest.raises(ValueError, match="unknown recording format 'csv'"):
        write_recording(recording, tmp_path / "x", format="csv")  # type: ignore[arg-type]


def test_validate_recording_rejects_foreign_datasets(recording: xr.Dataset) -> None:
    two_d = recording.assign(M=(("t", "k"), np.zeros((recording.sizes["t"], 2))))
    with pytest.raises(RecordingError, match=r"mine: variable 'M' has dims \('t', 'k'\)"):
        validate_recording(two_d, origin="mine")
    no_fs = recording.copy()
    del no_fs.attrs["fs_hz"]
    with pytest.raises(RecordingError, match=r"mine: attribute 'fs_hz' is None"):
        validate_recording(no_fs, origin="mine")
    with pytest.raises(RecordingError, match=r"mine: variable 'Vxx' is missing"):
        validate_recording(recording, origin="mine", require=["Vph", "Vxx"])


# --------------------------------------------------------------------------- finding
def test_find_experiments(tmp_path: Path) -> None:
    for name in ["data_uch.mat", "data_uch.nxs", "data_unh.nxs", "data_rep_v.h5",
                 "data_ucv.txt", "other.mat"]:
        (tmp_path / name).write_bytes(b"")
    (tmp_path / "data_unv.mat").mkdir()  # a folder is not a recording
    found = find_experiments(tmp_path)
    assert found == {"data_uch": tmp_path / "data_uch.mat",
                     "data_unh": tmp_path / "data_unh.nxs",
                     "data_rep_v": tmp_path / "data_rep_v.h5"}
    assert list(found) == ["data_uch", "data_unh", "data_rep_v"]  # EXPERIMENTS order


def test_find_experiments_needs_a_folder(tmp_path: Path) -> None:
    with pytest.raises(NotADirectoryError):
        find_experiments(tmp_path / "missing")


# --------------------------------------------------------------------------- size
@pytest.mark.parametrize("fmt", FORMATS)
def test_large_recording_round_trip(tmp_path: Path, fmt: str) -> None:
    """1,010,000 samples x 12 variables (a seed huddle test) survive a round trip.

    How fast that is, against scipy.io, is measured in benchmarks/bench_io.py.
    """
    rng = np.random.default_rng(0)
    n, lsb = 1_010_000, 20.0 / 2**16
    signals = {name: np.round(rng.standard_normal(n) * 3000) * lsb for name in SIGNALS}
    ds = make_recording(signals, fs_hz=1e4, experiment="data_rep_h")
    path = write_recording(ds, tmp_path / "data_rep_h.mat", format=fmt)  # type: ignore[arg-type]
    _assert_same_samples(ds, read_recording(path))
