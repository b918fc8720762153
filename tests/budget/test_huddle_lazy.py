"""The huddle analysis out of core (Dask) equals the analysis in memory."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fsmbench.bench.esrf import esrf_decentralised_controller
from fsmbench.bench.params import default_bench
from fsmbench.budget.huddle import analyse_huddle_record, estimate_dac_noise
from fsmbench.io.lazy import open_recording
from fsmbench.io.recording import read_recording
from fsmbench.twin.simulate import stream_bench

pytest.importorskip("dask")
BENCH = default_bench()


@pytest.fixture(scope="module")
def archive(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("long")
    stream_bench(BENCH, out_dir=out, seed=1, duration_s=12.0, experiments=["data_huddle_test_5"])
    return out / "data_huddle_test_5.h5"


@pytest.mark.parametrize(("chunk", "block"), [(7777, 5003), (65536, 1 << 20)])
def test_lazy_huddle_record_equals_in_memory(archive: Path, chunk: int, block: int) -> None:
    from fsmbench.budget.long_record import summarise_long_record

    mem = analyse_huddle_record(read_recording(archive))
    ds = open_recording(archive, chunk_samples=chunk)
    # Blocks shorter than a Welch segment (10 000 samples) and than the 1 s means.
    summary = summarise_long_record(ds, name="data_huddle_test_5", block_samples=block)
    lazy = analyse_huddle_record(ds, summary=summary)
    # Same samples, same estimators; blocks only reorder sums: 1e-12 relative.
    for field in ("va_rms_m", "va_lpf_rms_m", "vph_rms_v", "vpv_rms_v", "duration_s",
                  "welch_averages"):
        assert getattr(lazy, field) == pytest.approx(getattr(mem, field), rel=1e-12), field
    for field in ("psd_va_m2_per_hz", "psd_vph_v2_per_hz", "psd_vpv_v2_per_hz"):
        np.testing.assert_allclose(getattr(lazy, field), getattr(mem, field), rtol=1e-12,
                                   atol=0, err_msg=field)
    for a, b in zip(lazy.bands, mem.bands, strict=True):
        assert a.rms == pytest.approx(b.rms, rel=1e-12) and a.band == b.band


def test_lazy_dac_noise_equals_in_memory(archive: Path) -> None:
    k = esrf_decentralised_controller()
    mem, _ = estimate_dac_noise({"data_huddle_test_5": read_recording(archive)}, controller=k,
                                params=BENCH.nominal, duration_s=5.0)
    lazy, _ = estimate_dac_noise({"data_huddle_test_5": open_recording(archive)}, controller=k,
                                 params=BENCH.nominal, duration_s=5.0)
    assert mem is not None and lazy is not None
    # The long record is cut to the same 5 s before the controller runs: identical.
    assert lazy.rms_v == mem.rms_v


def test_folder_reads_long_huddle_tests_lazily(archive: Path) -> None:
    from fsmbench.budget.signals import is_lazy
    from fsmbench.io.folder import load_recordings

    lazy = load_recordings(archive.parent, fs_hz=10_000.0, lazy_bytes=0)
    whole = load_recordings(archive.parent, fs_hz=10_000.0)
    ds = lazy.recordings["data_huddle_test_5"]
    assert is_lazy(ds["Va"].data) and not is_lazy(whole.recordings["data_huddle_test_5"]["Va"].data)
    # The plausibility checks give the same verdicts and values out of core.
    assert [(c.name, c.subject, c.passed) for c in lazy.checks] == \
        [(c.name, c.subject, c.passed) for c in whole.checks]
    for a, b in zip(lazy.checks, whole.checks, strict=True):
        assert a.value == pytest.approx(b.value, rel=1e-12)


def test_folder_skips_a_long_record_with_a_nan(archive: Path, tmp_path: Path) -> None:
    import h5py

    from fsmbench.io.folder import load_recordings

    bad = tmp_path / archive.name
    bad.write_bytes(archive.read_bytes())
    with h5py.File(bad, "r+") as f:
        f["entry/data/Vpv"][12345] = np.nan
    from fsmbench.io.errors import RecordingError

    # The only record is unusable: the folder is refused, naming file, signal and sample.
    with pytest.raises(RecordingError) as err:
        load_recordings(tmp_path, fs_hz=10_000.0, lazy_bytes=0)
    why = str(err.value)
    assert str(bad) in why and "'Vpv'" in why and "1 NaN or Inf value" in why
    assert "index 12345" in why
