"""fsmbench.io.nexus_meta: what a NeXus archive says besides its samples.

Compression, the instrument, the times and the format are read back with h5py
(and GNU Octave when installed), never through fsmbench's own reader alone.
"""

from __future__ import annotations

import dataclasses
import datetime
import shutil
import subprocess
from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np
import pytest
import scipy.io
import xarray as xr

from fsmbench.bench.axes import PerAxis
from fsmbench.bench.params import Bench, default_bench, real_bench
from fsmbench.io.matwrite import wall_clock_headers
from fsmbench.io.nexus import read_nexus, write_nexus
from fsmbench.io.nexus_meta import NEXUS_FORMAT, UNSTAMPED_S
from fsmbench.io.nexus_stream import NexusAppender
from fsmbench.live.jobs import JobOutcome, JobWriter, plan_job

OCTAVE = shutil.which("octave")
# The NeXus base classes each part is described by (the NeXus manual's base classes).
PART_CLASSES = {"adc": "NXcollection", "dac": "NXcollection", "quad_diode": "NXdetector",
                "attocube": "NXdetector", "sercalo": "NXpositioner", "newport": "NXpositioner",
                "current_amplifier": "NXcollection", "voltage_amplifier": "NXcollection"}


def _signals(f: h5py.File) -> list[h5py.Dataset]:
    data = f["entry/data"]
    return [data[k] for k in data]


def _time(text: str | bytes) -> datetime.datetime:
    return datetime.datetime.fromisoformat(text.decode() if isinstance(text, bytes) else text)


def test_written_archives_are_gzip_chunked_and_bit_exact(tmp_path: Path,
                                                         recording: xr.Dataset) -> None:
    one = write_nexus(recording, tmp_path / "whole.h5")
    streamed = tmp_path / "streamed.h5"
    names = [str(n) for n in recording.data_vars]
    with NexusAppender(streamed, signals=names, fs_hz=recording.attrs["fs_hz"], attrs={},
                       chunk_samples=300) as app:
        for k in range(0, recording.sizes["t"], 700):  # blocks straddle the chunks
            app.append({n: recording[n].values[k:k + 700] for n in names})
    for path in (one, streamed):
        with h5py.File(path, "r") as f:
            for dset in _signals(f):  # t and every signal
                assert dset.compression == "gzip" and dset.shuffle and dset.chunks, dset.name
                name = dset.name.rsplit("/", 1)[1]
                if name != "t":  # the appender makes its own t: k / fs
                    assert dset[()].tobytes() == recording[name].values.tobytes(), name
    # The raw option stays: contiguous, no filter.
    with h5py.File(write_nexus(recording, tmp_path / "raw.h5", compress=False), "r") as f:
        assert all(d.compression is None and d.chunks is None for d in _signals(f))
    # Quantised ADC samples shrink (shuffle groups the constant exponent bytes).
    assert one.stat().st_size < 0.8 * (tmp_path / "raw.h5").stat().st_size


def _expected_fields(bench: Bench) -> dict[str, tuple[np.ndarray, str]]:
    """Every instrument field: its value and unit from the bench's own dataclasses."""
    c = bench.nominal.converter
    out: dict[str, tuple[np.ndarray, str]] = {}
    for g in ("adc", "dac"):
        out.update({f"{g}/sampling_rate": (np.asarray(c.fs_hz), "Hz"),
                    f"{g}/range": (np.asarray(c.range_v), "V"),
                    f"{g}/bits": (np.asarray(c.bits), "bit"),
                    f"{g}/lsb": (np.asarray(c.range_v / 2**c.bits), "V")})
    out["dac/delay"] = (np.asarray(c.dac_delay_samples / c.fs_hz + c.dac_extra_delay_s), "s")
    for part in PART_CLASSES:
        if part in ("adc", "dac"):
            continue
        params = getattr(bench.nominal, part)
        for f in dataclasses.fields(params):
            value = getattr(params, f.name)
            if value == ():
                continue
            array = (np.array([value.h, value.v]) if isinstance(value, PerAxis)
                     else np.asarray(value))
            out[f"{part}/{f.name}"] = (array, f.metadata["unit"].split(" ")[0])
    return out


@pytest.mark.parametrize("make_bench", [default_bench, real_bench], ids=["default", "real"])
def test_the_instrument_is_the_bench_file_with_units(tmp_path: Path, recording: xr.Dataset,
                                                     make_bench: Callable[[], Bench]) -> None:
    bench = make_bench()
    path = tmp_path / "rec.h5"
    names = [str(n) for n in recording.data_vars]
    with NexusAppender(path, signals=names, fs_hz=1e4, attrs={}, bench=bench) as app:
        app.append({n: recording[n].values for n in names})
    expected = _expected_fields(bench)
    with h5py.File(path, "r") as f:
        inst = f["entry/instrument"]
        assert inst.attrs["NX_class"] == "NXinstrument"
        assert inst.attrs["bench_file"] == bench.origin and "assumed" not in inst.attrs
        assert {k: inst[k].attrs["NX_class"] for k in PART_CLASSES} == PART_CLASSES
        found = {}

        def visit(name: str, obj: object) -> None:
            if isinstance(obj, h5py.Dataset) and obj.dtype.kind in "fiu":
                found[name] = obj

        inst.visititems(visit)
        assert sorted(found) == sorted(expected)  # every bench number, nothing else
        for name, dset in found.items():
            value, unit = expected[name]
            assert dset.attrs["units"] == unit, name
            np.testing.assert_array_equal(dset[()], value, err_msg=name)  # stored exactly
        assert f["entry/instrument/quad_diode/gain_v_per_rad"].attrs["axes_order"] == "h, v"
    # The samples' own reading is untouched by the instrument's numbers.
    xr.testing.assert_equal(read_nexus(path)[names], recording[names])


def test_without_a_bench_the_packaged_one_is_marked_assumed(tmp_path: Path,
                                                            recording: xr.Dataset) -> None:
    with h5py.File(write_nexus(recording, tmp_path / "rec.h5"), "r") as f:
        inst = f["entry/instrument"]
        assert inst.attrs["bench_file"] == "default_bench.toml"
        assert "not told" in inst.attrs["assumed"]


def test_file_time_is_the_writing_time_or_absent(tmp_path: Path, recording: xr.Dataset) -> None:
    before = datetime.datetime.now(datetime.UTC)
    now = write_nexus(recording, tmp_path / "now.h5")
    after = datetime.datetime.now(datetime.UTC)
    fixed = write_nexus(recording, tmp_path / "fixed.h5", created=1.7e9)
    bare = write_nexus(recording, tmp_path / "bare.h5", created=UNSTAMPED_S)
    with h5py.File(now, "r") as a, h5py.File(fixed, "r") as b, h5py.File(bare, "r") as c:
        assert (a.attrs["format"], a.attrs["format_version"]) == NEXUS_FORMAT
        stamp = _time(a.attrs["file_time"])
        assert stamp.tzinfo is not None and before <= stamp <= after  # ISO 8601, this run
        assert _time(b.attrs["file_time"]) == datetime.datetime.fromtimestamp(1.7e9,
                                                                              datetime.UTC)
        # Reproducible output: no false 1970 date, a note why.
        assert "file_time" not in c.attrs and "reproducible" in c.attrs["file_time_note"]
    again = write_nexus(recording, tmp_path / "again.h5", created=UNSTAMPED_S)
    assert again.read_bytes() == bare.read_bytes()
    with wall_clock_headers():  # --timestamp: the reproducible writers stamp the clock too
        asked = write_nexus(recording, tmp_path / "asked.h5", created=UNSTAMPED_S)
    with h5py.File(asked, "r") as f:
        assert before <= _time(f.attrs["file_time"]) and "file_time_note" not in f.attrs


def test_a_recordings_times_are_fields_and_read_back(tmp_path: Path,
                                                     recording: xr.Dataset) -> None:
    timed = recording.copy()
    timed.attrs.update(start_time="2026-03-01T09:30:00+01:00",
                       end_time="2026-03-01T09:30:00.200000+01:00")
    path = write_nexus(timed, tmp_path / "timed.h5")
    with h5py.File(path, "r") as f:
        entry = f["entry"]
        assert _time(entry["start_time"][()]) == _time(timed.attrs["start_time"])
        assert entry["start_time"].dtype.kind == "S"  # fixed-length: Octave's load reads it
        assert "start_time" not in entry.attrs and "start_time_note" not in entry.attrs
    xr.testing.assert_identical(read_nexus(path), timed)
    with h5py.File(write_nexus(recording, tmp_path / "untimed.h5"), "r") as f:
        assert "start_time" not in f["entry"]  # never invented
        assert f["entry"].attrs["start_time_note"].startswith("not known")
    timed.attrs["start_time"] = "2026-03-01 09:30"  # no offset: which 09:30?
    with pytest.raises(ValueError, match="no UTC offset"):
        write_nexus(timed, tmp_path / "naive.h5")


def test_a_live_record_is_timed_by_its_samples_and_describes_the_bench(tmp_path: Path) -> None:
    bench = real_bench()
    plan = dataclasses.replace(
        plan_job(kind="record", name="rec", folder=tmp_path, fmt="nexus",
                 signals=("Vph", "Vpv"), n_samples=2000, start_sample=0, t0_s=0.0,
                 fs_hz=1e4, source="test", overwrite=False),
        bench=bench)
    outcomes: list[JobOutcome] = []
    writer = JobWriter(plan, on_done=outcomes.append)
    before = datetime.datetime.now(datetime.UTC)
    for _ in range(4):
        assert writer.put({"Vph": np.zeros(500), "Vpv": np.ones(500)})
    handed = datetime.datetime.now(datetime.UTC)
    writer.finish()
    writer.join(60.0)
    assert outcomes and outcomes[0].path == plan.path and not outcomes[0].error
    with h5py.File(plan.path, "r") as f:
        entry = f["entry"]
        start, end = (_time(entry[k][()]) for k in ("start_time", "end_time"))
        # 1 µs: the file's time is time.time() as ISO text, to the microsecond, and
        # datetime.now() rounds the same instant to the microsecond on its own.
        tick = datetime.timedelta(microseconds=1)
        assert start.utcoffset() is not None and before - tick <= start <= end <= handed + tick
        assert entry.attrs["ended"] == "complete"
        assert entry["instrument"].attrs["bench_file"] == "real_bench.toml"
        assert entry["data/Vpv"].compression == "gzip"


@pytest.mark.skipif(OCTAVE is None, reason="GNU Octave is not installed (Debian: apt-get install "
                    "-y --no-install-recommends octave)")
def test_octave_reads_a_compressed_archive(tmp_path: Path, recording: xr.Dataset) -> None:
    # Octave has no h5read; its load -hdf5 reads any HDF5 file's groups as structs
    # (attributes, so units, are not read: h5py checks those above).
    path = tmp_path / "rec.h5"
    with NexusAppender(path, signals=["Vph", "Va"], fs_hz=1e4, attrs={}) as app:
        app.append({"Vph": recording["Vph"].values, "Va": recording["Va"].values})
        app.set_times(start="2026-03-01T09:30:00+01:00", end="2026-03-01T09:30:00.2+01:00")
    res = tmp_path / "octave.mat"
    script = (f"s = load('-hdf5', '{path}'); e = s.entry; vph = e.data.Vph; va = e.data.Va; "
              "fs = e.instrument.adc.sampling_rate; start = e.start_time; "
              f"save('-v7', '{res}', 'vph', 'va', 'fs', 'start');")
    run = subprocess.run([str(OCTAVE), "--no-gui", "--no-window-system", "--quiet", "--eval",
                          script], capture_output=True, text=True, timeout=120, check=False)
    assert run.returncode == 0 and res.exists(), run.stdout + run.stderr
    r = scipy.io.loadmat(res, squeeze_me=True)
    for name in ("Vph", "Va"):
        assert np.ravel(r[name.lower()]).tobytes() == recording[name].values.tobytes(), name
    assert float(r["fs"]) == 1e4 and str(r["start"]) == "2026-03-01T09:30:00+01:00"
    with h5py.File(path, "r") as f:
        assert f["entry/data/Vph"].compression == "gzip"  # what Octave decompressed
