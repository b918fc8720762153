"""A folder read by two processes: the records, checks, notices and refusals of the
one-process read, and each record's checks carried back with it, not made again."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
import xarray as xr

from fsmbench.forked import fork_available
from fsmbench.io import folder, record_checks
from fsmbench.io.folder import load_recordings
from fsmbench.io.record_checks import check_recording
from fsmbench.twin import TwinRun, write_twin

pytestmark = pytest.mark.skipif(not fork_available(), reason="needs fork and two cores")


@pytest.fixture(scope="module")
def twin_folder(short_twin: TwinRun, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("twin-data")
    write_twin(short_twin, out)
    # One broken file and one odd name: refusals and hints travel too.
    broken = out / "data_huddle_test_4.mat"
    broken.write_bytes(broken.read_bytes()[: broken.stat().st_size // 3])
    (out / "data_unh.mat").rename(out / "Data_unh.mat")
    return out


def _same(a: xr.Dataset, b: xr.Dataset) -> None:
    assert list(a.data_vars) == list(b.data_vars) and a.attrs.keys() == b.attrs.keys()
    for name in (*a.data_vars, *a.coords):
        np.testing.assert_array_equal(a[name].values, b[name].values, strict=True)
    assert all(str(a.attrs[k]) == str(b.attrs[k]) for k in a.attrs)


def test_two_processes_read_what_one_reads(twin_folder: Path) -> None:
    said: list[str] = []
    serial = load_recordings(twin_folder, fs_hz=1e4)
    forked = load_recordings(twin_folder, fs_hz=1e4, parallel=True, progress=said.append)
    assert list(forked.recordings) == list(serial.recordings)  # the ESRF study's order
    for name, ds in serial.recordings.items():
        _same(ds, forked.recordings[name])
    assert forked.skipped == serial.skipped and "data_huddle_test_4" in forked.skipped
    assert "Data_unh.mat" in forked.skipped["data_unh"]
    assert forked.checks == serial.checks and forked.notices == serial.notices
    # Every file present was read once, by one process or the other.
    assert sorted(said) == sorted(f"reading {p.name}" for p in twin_folder.glob("data_*.mat"))


def test_the_checks_come_back_with_the_records(twin_folder: Path,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    """The stages ask for a record's checks again: those read by the forked process are
    not checked a second time here."""
    loaded = load_recordings(twin_folder, parallel=True)
    made: list[str] = []
    real = record_checks._check_recording

    def counted(ds: xr.Dataset, **kwargs: Any) -> Any:
        made.append(str(kwargs.get("name")))
        return real(ds, **kwargs)

    monkeypatch.setattr(record_checks, "_check_recording", counted)
    for name, ds in loaded.recordings.items():
        check_recording(ds, name=name)
    assert made == []
    share = folder._child_share({n: twin_folder / f"{n}.mat" for n in loaded.recordings}, {})
    assert share and set(share) < set(loaded.recordings)  # both processes read some
