"""Long records: NeXus written block by block, read lazily, v5 converted in pieces."""

from __future__ import annotations

import datetime
import itertools
from pathlib import Path

import h5py
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fsmbench.io.errors import RecordingError
from fsmbench.io.lazy import convert_recording, open_recording, v5_stream_variable
from fsmbench.io.nexus import read_nexus
from fsmbench.io.nexus_stream import NexusAppender
from fsmbench.io.recording import make_recording, read_recording, write_recording

pytest.importorskip("dask")

FS = 10_000.0


def _record(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    lsb = 20.0 / 2**16
    return make_recording({"Vph": np.round(rng.normal(0, 0.01, n) / lsb) * lsb,
                           "Vpv": np.round(rng.normal(0, 0.01, n) / lsb) * lsb,
                           "Va": rng.normal(0, 1e-9, n)}, fs_hz=FS, experiment="data_huddle_test_4",
                          source="test")


def _same(a, b) -> None:
    # Bit for bit: the writers copy float64 samples, they never compute on them.
    assert list(a.data_vars) == list(b.data_vars)
    for name in ("t", *a.data_vars):
        np.testing.assert_array_equal(np.asarray(a[name].values), np.asarray(b[name].values),
                                      err_msg=name)


@settings(max_examples=15, deadline=None)
@given(cuts=st.lists(st.integers(0, 5000), max_size=6), chunk=st.sampled_from([7, 1000, 65536]))
def test_appended_archive_equals_the_whole_record(tmp_path_factory, cuts, chunk) -> None:
    ds = _record(5000)
    path = tmp_path_factory.mktemp("nx") / "rec.h5"
    edges = [0, *sorted(cuts), 5000]
    with NexusAppender(path, signals=list(ds.data_vars), fs_hz=FS,
                       attrs={"experiment": "data_huddle_test_4", "source": "test"},
                       chunk_samples=chunk) as nx:
        for a, b in itertools.pairwise(edges):
            nx.append({k: ds[k].values[a:b] for k in ds.data_vars})
    _same(read_nexus(path), ds)
    assert read_nexus(path).attrs["fs_hz"] == FS


def test_failed_append_leaves_no_file(tmp_path: Path) -> None:
    path = tmp_path / "rec.h5"
    with pytest.raises(ValueError, match="lacks Va"), \
            NexusAppender(path, signals=["Vph", "Va"], fs_hz=FS, attrs={}) as nx:
        nx.append({"Vph": np.zeros(10), "Va": np.zeros(10)})
        nx.append({"Vph": np.zeros(10)})
    assert list(tmp_path.iterdir()) == []


def test_an_appended_archive_has_the_start_and_end_time_it_is_told(tmp_path: Path) -> None:
    # NXentry's start_time and end_time: what the writer is told (a live record says when
    # its samples were taken), with its offset, never the clock of the writing.
    path = tmp_path / "timed.h5"
    start = datetime.datetime(2026, 3, 1, 9, 30, tzinfo=datetime.timezone(
        datetime.timedelta(hours=1)))
    end = start + datetime.timedelta(seconds=0.01)
    with NexusAppender(path, signals=["Vph"], fs_hz=10_000.0, attrs={}) as app:
        app.append({"Vph": np.zeros(100)})
        app.set_times(start=start.isoformat(), end=end.isoformat())
        app.note(ended="complete")
    with h5py.File(path, "r") as f:
        got = [datetime.datetime.fromisoformat(f["entry"][k][()].decode())
               for k in ("start_time", "end_time")]
        assert f["entry"].attrs["ended"] == "complete"
        assert "start_time_note" not in f["entry"].attrs
    assert got == [start, end] and got[0].utcoffset() == datetime.timedelta(hours=1)
    back = read_recording(path, require=())
    assert back.sizes["t"] == 100 and back.attrs["start_time"] == start.isoformat()


def test_an_appended_archive_without_times_says_so(tmp_path: Path) -> None:
    path = tmp_path / "untimed.h5"
    with NexusAppender(path, signals=["Vph"], fs_hz=10_000.0, attrs={},
                       times_unknown="none: simulated") as app:
        app.append({"Vph": np.zeros(100)})
    with h5py.File(path, "r") as f:
        assert "start_time" not in f["entry"] and "end_time" not in f["entry"]
        assert f["entry"].attrs["start_time_note"] == "none: simulated"
    assert "start_time_note" not in read_recording(path, require=()).attrs  # the file's, not
    with pytest.raises(ValueError, match="no UTC offset"), \
            NexusAppender(tmp_path / "naive.h5", signals=["Vph"], fs_hz=1.0, attrs={}) as app:
        app.set_times(start="2026-03-01T09:30:00", end=None)  # which 09:30? refused
    assert not (tmp_path / "naive.h5").exists()


@pytest.mark.parametrize("fmt", ["nexus", "mat73"])
def test_lazy_reading_equals_reading_whole(tmp_path: Path, fmt: str) -> None:
    import dask.array as da

    ds = _record(12_345)
    path = write_recording(ds, tmp_path / f"data_huddle_test_4.{'h5' if fmt == 'nexus' else 'mat'}",
                           format=fmt)
    lazy = open_recording(path, chunk_samples=1000)
    assert all(isinstance(lazy[k].data, da.Array) for k in ("t", *lazy.data_vars))
    assert lazy["Vph"].data.chunks[0][:2] == (1000, 1000)
    _same(lazy.compute(), read_recording(path))
    assert lazy.attrs["fs_hz"] == pytest.approx(FS, rel=1e-9)


@pytest.mark.parametrize("compress", [True, False])
def test_v5_converted_in_pieces(tmp_path: Path, compress: bool) -> None:
    ds = _record(30_001, seed=2)
    src = write_recording(ds, tmp_path / "data_huddle_test_4.mat", format="mat5",
                          compress=compress)
    # Pieces of 4096 samples: the streamed inflate crosses many zlib buffer edges.
    pieces = list(v5_stream_variable(src, "Va", block=4096))
    assert max(p.size for p in pieces) == 4096
    np.testing.assert_array_equal(np.concatenate(pieces), ds["Va"].values)
    out = convert_recording(src, tmp_path / "converted.h5")
    _same(read_nexus(out), read_recording(src))


def test_v5_too_large_for_memory_says_convert(tmp_path: Path, monkeypatch) -> None:
    import fsmbench.io.lazy as lazy

    src = write_recording(_record(20_000), tmp_path / "data_huddle_test_4.mat", format="mat5")
    monkeypatch.setattr(lazy, "available_memory_bytes", lambda: 100_000)
    with pytest.raises(RecordingError, match=r"fsmbench convert .* --format nexus"):
        open_recording(src)
    # Converting still works: it never holds more than a piece.
    _same(read_nexus(convert_recording(src, tmp_path / "c.h5")), read_recording(src))
