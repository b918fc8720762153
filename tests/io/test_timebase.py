"""Time stamps with clock jitter on a uniform grid (issue 30, item 7).

``t = k/fs + jitter`` with ``|jitter| <= 50 ns`` is what a real-time target's
clock stamps; the samples are uniform, so the record is read at the rate fitted
to the whole of ``t``. Larger irregularities are refused, one line each. The
references are independent of the reader: the rate and jitter the stamps were
made with, and numpy's ``polyfit`` for the least-squares grid.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import scipy.io

from fsmbench.io.errors import RecordingError
from fsmbench.io.folder import load_recordings
from fsmbench.io.lazy import convert_recording, open_recording
from fsmbench.io.recording import read_recording
from fsmbench.io.signals import EXPERIMENTS

N = 50_000  # 5 s at 10 kHz
FS = 1e4
LSB = 20.0 / 2**16


def _signals(t: np.ndarray) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(3)
    return {"t": t, **{k: np.round(rng.standard_normal(t.size) * 3000) * LSB
                       for k in ("Vph", "Vpv")}}


def _jittered(n: int = N, fs: float = FS, amplitude_s: float = 50e-9,
              seed: int = 1) -> np.ndarray:
    return np.arange(n) / fs + np.random.default_rng(seed).uniform(-amplitude_s, amplitude_s, n)


def _deviation(t: np.ndarray) -> float:
    """Largest distance of t from its least-squares line, by numpy.polyfit [s]."""
    k = np.arange(t.size, dtype=float)
    slope, intercept = np.polyfit(k, t - t[0], 1)
    return float(np.max(np.abs(t - t[0] - (intercept + slope * k))))


@pytest.fixture
def write_raw(write_v5: Callable[..., Path],
              write_v73_by_hand: Callable[..., Path]) -> Callable[[str, Path, dict], Path]:
    def write(fmt: str, path: Path, variables: dict[str, Any]) -> Path:
        return (write_v5 if fmt == "mat5" else write_v73_by_hand)(path, variables)

    return write


@pytest.mark.parametrize("fmt", ["mat5", "mat73"])
def test_clock_jitter_reads_at_the_nominal_rate_with_a_notice(
        tmp_path: Path, write_raw: Callable[[str, Path, dict], Path], fmt: str) -> None:
    t = _jittered()
    path = write_raw(fmt, tmp_path / "rec.mat", _signals(t))
    ds = read_recording(path)
    # The rate the stamps were made at; the first step alone says 1/(t[1] - t[0]), off by up
    # to 1e-3 of it.
    assert ds.attrs["fs_hz"] == FS
    assert abs(1 / (t[1] - t[0]) / FS - 1) > 1e-5
    assert np.array_equal(ds["t"].values, t)  # t is kept as it was read
    note = ds.attrs["time_jitter"]
    assert f"up to {_deviation(t) * 1e9:.3g} ns (0.05 % of the 100 µs period" in note
    assert "10000 Hz" in note


def test_a_crystal_off_its_nominal_rate_keeps_its_own_digits(tmp_path: Path) -> None:
    # 30 ppm off 10 kHz, stamped by the same clock: 10000.3 Hz is what the record shows, and
    # the fit fixes it to 3e-4 Hz (3 d / (n T)), so the digits of 10000.3 are kept.
    path = tmp_path / "rec.mat"
    scipy.io.savemat(path, _signals(_jittered(fs=10000.3)), oned_as="column")
    assert read_recording(path).attrs["fs_hz"] == 10000.3


def test_an_exact_grid_reads_as_before_without_a_notice(tmp_path: Path) -> None:
    path = tmp_path / "rec.mat"
    scipy.io.savemat(path, _signals(np.arange(N) / FS), oned_as="column")
    ds = read_recording(path)
    assert ds.attrs["fs_hz"] == FS and "time_jitter" not in ds.attrs


@pytest.mark.parametrize(("fraction", "ok"), [(0.9e-3, True), (1.1e-3, False)])
def test_the_bound_is_a_tenth_of_a_percent_of_a_period(tmp_path: Path, fraction: float,
                                                       ok: bool) -> None:
    t = np.arange(N) / FS
    t[20_000] += fraction / FS  # one stamp late; the fitted line moves by 1/N of it
    path = tmp_path / "rec.mat"
    scipy.io.savemat(path, _signals(t), oned_as="column")
    if ok:
        assert read_recording(path).attrs["time_jitter"].startswith(
            f"t strays up to {_deviation(t) * 1e9:.3g} ns (0.09 % ")
        return
    with pytest.raises(RecordingError, match=r"variable 't' is not uniformly sampled at index "
                                             r"20000: .*\(0\.11 % of a period\)"):
        read_recording(path)


def _dropped(t: np.ndarray, *at: int) -> np.ndarray:
    return np.delete(t, list(at))


def _jump(t: np.ndarray, at: int, by_periods: float) -> np.ndarray:
    out = t.copy()
    out[at:] += by_periods / FS
    return out


IRREGULAR = [
    ("dropped", lambda t: _dropped(t, 1234), "at index 1234: ", "(2 periods; 1 sample missing?)"),
    ("two-dropped", lambda t: _dropped(t, 1234, 1235), "at index 1234: ",
     "(3 periods; 2 samples missing?)"),
    ("jump", lambda t: _jump(t, 3000, 0.5), "at index 3000: ", "(1.5 periods)"),
    ("repeated", lambda t: np.insert(t, 10, t[10]), "is not increasing at index 11: ", ""),
]


@pytest.mark.parametrize(("case", "edit", "where", "what"), IRREGULAR,
                         ids=[c[0] for c in IRREGULAR])
def test_irregular_time_is_refused_in_one_line(tmp_path: Path, case: str,
                                               edit: Callable[[np.ndarray], np.ndarray],
                                               where: str, what: str) -> None:
    t = edit(_jittered())
    path = tmp_path / f"{case}.mat"
    scipy.io.savemat(path, _signals(t), oned_as="column")
    with pytest.raises(RecordingError) as err:
        read_recording(path)
    text = str(err.value)
    assert text.startswith(f"{path}: variable 't' ") and where in text and what in text
    assert "\n" not in text and len(text) < 300 + len(str(path))


def test_out_of_core_reading_agrees_with_reading_whole(tmp_path: Path) -> None:
    pytest.importorskip("dask")
    from fsmbench.io.nexus import write_nexus
    from fsmbench.io.recording import make_recording

    t = _jittered()
    ds = make_recording({k: v for k, v in _signals(t).items() if k != "t"}, t=t,
                        experiment="rec")
    path = write_nexus(ds, tmp_path / "rec.h5", created=0.0)
    whole, lazy = read_recording(path), open_recording(path, chunk_samples=4096)
    assert lazy.attrs["fs_hz"] == whole.attrs["fs_hz"] == FS
    assert lazy.attrs["time_jitter"] == whole.attrs["time_jitter"]


def test_out_of_core_reading_refuses_a_dropped_sample(tmp_path: Path) -> None:
    pytest.importorskip("dask")
    import h5py

    t = _dropped(_jittered(), 4321)
    path = tmp_path / "rec.h5"
    with h5py.File(path, "w") as f:  # a NeXus layout written by hand: no validating writer
        entry = f.create_group("entry")
        entry.attrs["NX_class"] = "NXentry"
        data = entry.create_group("data")
        data.attrs["NX_class"] = "NXdata"
        data.attrs["signal"] = "Vph"
        data["t"] = t
        data["Vph"] = np.zeros(t.size)
    with pytest.raises(RecordingError, match=r"variable 't' is not uniformly sampled at index "
                                             r"4321: .*\(2 periods; 1 sample missing\?\)"):
        open_recording(path, chunk_samples=4096)


def test_convert_takes_the_rate_of_all_of_t(tmp_path: Path) -> None:
    t = _jittered(seed=4)
    src = tmp_path / "rec.mat"
    scipy.io.savemat(src, _signals(t), oned_as="column")
    assert abs(1 / (t[1] - t[0]) / FS - 1) > 2e-4  # the first step: off by more than its error
    out = convert_recording(src, tmp_path / "rec.h5", fs_hz=FS, created=0.0)
    back = read_recording(out)
    assert back.attrs["fs_hz"] == FS and np.array_equal(back["t"].values, t)
    default = convert_recording(src, tmp_path / "default.h5", created=0.0)
    assert read_recording(default).attrs["fs_hz"] == FS


def _folder(root: Path, edit: Callable[[np.ndarray], np.ndarray]) -> Path:
    """Every experiment of the ESRF study with its variables, N/10 samples, t edited."""
    root.mkdir()
    rng = np.random.default_rng(9)
    for name, info in EXPERIMENTS.items():
        t = edit(np.arange(N // 10) / FS + rng.uniform(-50e-9, 50e-9, N // 10))
        v = {k: np.round(rng.standard_normal(t.size) * 300) * LSB for k in info.required}
        v["t"] = t
        if "Va" in v:
            v["Va"] = rng.standard_normal(t.size) * 1e-9
        scipy.io.savemat(root / f"{name}.mat", v, oned_as="column")
    return root


def test_a_folder_of_jittered_files_is_read_with_one_notice_each(tmp_path: Path) -> None:
    loaded = load_recordings(_folder(tmp_path / "data", lambda t: t), fs_hz=FS)
    assert list(loaded.recordings) == list(EXPERIMENTS)
    jitter = [n for n in loaded.notices if n.kind == "time_jitter"]
    assert [n.subject for n in jitter] == [f"{name}.mat: t" for name in EXPERIMENTS]
    assert all(ds.attrs["fs_hz"] == FS for ds in loaded.recordings.values())


def test_a_folder_failing_in_one_way_is_one_short_line(tmp_path: Path) -> None:
    data = _folder(tmp_path / "data", lambda t: _dropped(t, 1234))
    with pytest.raises(RecordingError) as err:
        load_recordings(data, fs_hz=FS)
    text = str(err.value)
    # Before: the thirteen files' problems joined, 4 KB on one line.
    assert "\n" not in text and len(text) < 1000
    assert (f"variable 't' is not uniformly sampled in {len(EXPERIMENTS)} files ("
            + ", ".join(f"{name}.mat" for name in EXPERIMENTS) + "); the first, "
            + str(data / "data_cal_pd_h.mat") + ": variable 't' is not uniformly sampled at "
            "index 1234: ") in text
