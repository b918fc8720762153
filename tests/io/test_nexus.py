"""fsmbench.io.nexus: the NeXus archive of a recording."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np
import pytest
import xarray as xr

from fsmbench.io.errors import RecordingError
from fsmbench.io.nexus import is_nexus, read_nexus, write_nexus
from fsmbench.io.recording import make_recording, read_recording
from fsmbench.io.signals import SIGNALS


def test_layout(tmp_path: Path, recording: xr.Dataset, n_samples: int) -> None:
    path = write_nexus(recording, tmp_path / "rec.nxs")
    with h5py.File(path, "r") as f:
        assert f.attrs["default"] == "entry"
        entry = f["entry"]
        assert entry.attrs["NX_class"] == "NXentry"
        assert entry.attrs["default"] == "data"
        assert entry.attrs["experiment"] == "data_rep_h"
        assert entry.attrs["fs_hz"] == 1e4
        data = entry["data"]
        assert data.attrs["NX_class"] == "NXdata"
        assert data.attrs["signal"] == "Uch"
        assert data.attrs["axes"] == "t"
        assert list(data.attrs["auxiliary_signals"]) == list(SIGNALS)[1:]
        assert data["t"].attrs["units"] == "s"
        assert data["t"].shape == (n_samples,)
        for name, info in SIGNALS.items():
            assert data[name].dtype == np.float64 and data[name].shape == (n_samples,)
            assert data[name].attrs["units"] == info.units
            assert data[name].attrs["long_name"] == info.long_name
            assert data[name][()].tobytes() == recording[name].values.tobytes()


@pytest.mark.parametrize("compress", [False, True])
def test_round_trip_is_identical(tmp_path: Path, recording: xr.Dataset, compress: bool) -> None:
    path = write_nexus(recording, tmp_path / "rec.nxs", compress=compress)
    back = read_nexus(path)
    xr.testing.assert_identical(back, recording)
    assert list(back.data_vars) == list(recording.data_vars)
    for name in back.variables:
        assert back[name].values.tobytes() == recording[name].values.tobytes()
    with h5py.File(path, "r") as f:
        assert (f["entry/data/Vph"].compression == "gzip") == compress


def test_round_trip_keeps_unknown_variables_attrs_and_order(
    tmp_path: Path, time_s: np.ndarray, adc_noise: Callable[..., np.ndarray]
) -> None:
    ds = make_recording({"zeta": adc_noise(), "Vpv": adc_noise()}, t=time_s,
                        experiment="bench_check", source="/data/bench_check.mat")
    ds.attrs["operator"] = "TD"
    ds["zeta"].attrs["units"] = "K"
    back = read_nexus(write_nexus(ds, tmp_path / "a.nxs"))
    xr.testing.assert_identical(back, ds)
    assert list(back.data_vars) == ["Vpv", "zeta"]
    assert back["zeta"].attrs["note"] == ds["zeta"].attrs["note"]
    assert back.attrs["source"] == "/data/bench_check.mat"


def test_read_recording_uses_the_stored_attributes(tmp_path: Path, recording: xr.Dataset) -> None:
    path = write_nexus(recording, tmp_path / "renamed.nxs")
    assert read_recording(path).attrs["experiment"] == "data_rep_h"
    assert read_recording(path, experiment="x").attrs["experiment"] == "x"
    # the stored experiment's load list applies: data_rep_h needs Vnh
    with pytest.raises(RecordingError, match=r"renamed\.nxs: variable 'Vnh' is missing"):
        read_recording(write_nexus(recording.drop_vars("Vnh"), tmp_path / "renamed.nxs"))


def test_is_nexus(tmp_path: Path, recording: xr.Dataset) -> None:
    assert is_nexus(write_nexus(recording, tmp_path / "a.nxs"))
    with h5py.File(tmp_path / "plain.h5", "w") as f:
        f.create_group("entry")  # no NX_class
    assert not is_nexus(tmp_path / "plain.h5")
    (tmp_path / "text.nxs").write_text("not hdf5")
    assert not is_nexus(tmp_path / "text.nxs")


def _archive(tmp_path: Path, recording: xr.Dataset) -> Path:
    return write_nexus(recording, tmp_path / "bad.nxs")


@pytest.mark.parametrize(
    ("damage", "match"),
    [
        (lambda f: f["entry"].attrs.__setitem__("NX_class", "NXcollection"),
         r"bad\.nxs: is not a NeXus archive: no NXentry group /entry"),
        (lambda f: f["entry"].move("data", "other"),
         r"bad\.nxs: is not a recording archive: no NXdata group /entry/data"),
        (lambda f: f["entry/data"].__delitem__("t"),
         r"bad\.nxs: variable 't' is missing from /entry/data"),
        (lambda f: f["entry/data"].__delitem__("Vph"),
         r"bad\.nxs: variable 'Vph' is named by /entry/data's signal attributes"),
        (lambda f: (f["entry/data"].__delitem__("Vpv"),
                    f["entry/data"].create_dataset("Vpv", data=np.zeros((3, 4)))),
         r"bad\.nxs: variable 'Vpv' is a 3x4 matrix, not a vector"),
        (lambda f: (f["entry/data"].__delitem__("Va"),
                    f["entry/data"].create_dataset("Va", data=np.zeros(17))),
         r"bad\.nxs: variable 'Va' has 17 samples but variable 't' has 2000"),
        (lambda f: (f["entry/data"].__delitem__("Vnh"),
                    f["entry/data"].create_dataset("Vnh", data=np.array([b"ab"] * 2000))),
         r"bad\.nxs: variable 'Vnh' is not numeric"),
    ],
    ids=["no-entry", "no-data", "no-t", "dangling-signal", "matrix", "length", "text"],
)
def test_damaged_archives(
    tmp_path: Path, recording: xr.Dataset, damage: Callable[[h5py.File], object], match: str
) -> None:
    path = _archive(tmp_path, recording)
    with h5py.File(path, "r+") as f:
        damage(f)
    with pytest.raises(RecordingError, match=match):
        read_nexus(path)
