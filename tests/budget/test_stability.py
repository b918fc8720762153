"""Drift and Allan deviation of whole records: closed forms, lazy = in memory."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from fsmbench.budget.stability import FULL_OVERLAP_MAX_TAU_S, allan_of, analyse_stability
from fsmbench.io.recording import make_recording

pytest.importorskip("dask")
FS = 1000.0


def test_long_taus_on_a_drift_equal_the_closed_form() -> None:
    # A linear drift a·t has Allan deviation a·τ/√2 exactly, at every τ, whichever
    # averages are used: the strided part must give it as the full overlap does.
    a = 3e-9
    x = a * np.arange(round(400 * FS)) / FS
    res = allan_of(x, fs_hz=FS, unit="m", name="drift")
    assert res.tau_s.max() > 4 * FULL_OVERLAP_MAX_TAU_S  # the strided part is exercised
    # Rounding of the block means and sums of 4e5 samples: 1e-7 relative.
    np.testing.assert_allclose(res.adev, a * res.tau_s / np.sqrt(2), rtol=1e-7)


def test_long_taus_on_white_noise() -> None:
    s = 2e-9
    x = s * np.random.default_rng(3).standard_normal(round(800 * FS))
    res = allan_of(x, fs_hz=FS, unit="m", name="white")
    m = res.tau_s * FS
    ratio = res.adev / (s / np.sqrt(m))
    long = res.tau_s > FULL_OVERLAP_MAX_TAU_S
    assert long.any()
    # Overlapping ADEV of white noise: N/m ≥ 4 averages give ≥ ~3 degrees of freedom;
    # at 800 s and τ ≤ 200 s the 99.9 % chi-square band is within a factor 0.3–2.
    assert np.all((ratio[long] > 0.3) & (ratio[long] < 2.0))
    assert np.all(np.abs(ratio[res.tau_s < 1.0] - 1) < 0.1)  # hundreds of dof: 10 %


@pytest.fixture(scope="module")
def record() -> xr.Dataset:
    rng = np.random.default_rng(1)
    n = round(120 * FS)
    t = np.arange(n) / FS
    lsb = 20.0 / 2**16
    return make_recording({"Vph": np.round((1e-3 * rng.standard_normal(n) + 2e-4 * t) / lsb) * lsb,
                           "Vpv": np.round(1e-3 * rng.standard_normal(n) / lsb) * lsb,
                           "Va": 1e-9 * rng.standard_normal(n) + 5e-11 * t},
                          fs_hz=FS, experiment="data_huddle_test_4", source="synthetic")


@pytest.mark.parametrize("block", [4099, 1 << 20])
def test_lazy_equals_in_memory(record: xr.Dataset, tmp_path: Path, block: int) -> None:
    from fsmbench.budget.long_record import summarise_long_record
    from fsmbench.io.lazy import open_recording
    from fsmbench.io.recording import write_recording

    path = write_recording(record, tmp_path / "data_huddle_test_4.h5", format="nexus")
    mem = analyse_stability(record, name="x", qd_gain_v_per_rad=(-5.0, 5.0), n_bins=300)
    ds = open_recording(path, chunk_samples=3333)
    # Blocks smaller than the longest Allan span (2 x 8192 samples) and than a drift bin.
    summary = summarise_long_record(ds, name="x", n_bins=300, block_samples=block)
    lazy = analyse_stability(ds, name="x", qd_gain_v_per_rad=(-5.0, 5.0), n_bins=300,
                             summary=summary)
    assert lazy.out_of_core and not mem.out_of_core
    for key in mem.allan:
        # Same estimator, blocks only reorder sums: 1e-12.
        np.testing.assert_allclose(lazy.allan[key].adev, mem.allan[key].adev, rtol=1e-12)
    for key in mem.drift:
        for f in ("mean", "minimum", "maximum", "t_s"):
            np.testing.assert_allclose(getattr(lazy.drift[key], f), getattr(mem.drift[key], f),
                                       rtol=1e-12, atol=1e-30, err_msg=f"{key}.{f}")


def test_drift_and_regions(record: xr.Dataset) -> None:
    res = analyse_stability(record, name="x", qd_gain_v_per_rad=(-5.0, 5.0), n_bins=300)
    # Vph drifts 2e-4 V/s over 119 s: the bin means span 119 s·2e-4 V/s / 5 V/rad.
    assert res.drift["Rh"].peak_to_peak == pytest.approx(119 * 2e-4 / 5.0, rel=0.02)
    kinds = {r.noise for r in res.allan["Va"].regions()}
    assert {"white", "drift"} <= kinds
    doc = res.to_json()
    assert set(doc["allan"]) == {"Va", "Rh", "Rv"} and doc["duration_s"] == pytest.approx(119.0)


def test_records_in_memory_need_no_dask(record: xr.Dataset) -> None:
    import subprocess
    import sys

    # The core installs without the dask extra: drift and Allan deviation of records in
    # memory must not import it.
    code = ("import sys; sys.modules['dask'] = None; sys.modules['distributed'] = None\n"
            "import numpy as np\n"
            "from fsmbench.io.recording import make_recording\n"
            "from fsmbench.budget.stability import analyse_stability\n"
            "rng = np.random.default_rng(0); n = 20000\n"
            "ds = make_recording({'Vph': 1e-3 * rng.standard_normal(n), 'Vpv': 1e-3 * "
            "rng.standard_normal(n), 'Va': 1e-9 * rng.standard_normal(n)}, fs_hz=1000.0, "
            "experiment='data_huddle_test_4')\n"
            "r = analyse_stability(ds, name='x', qd_gain_v_per_rad=(-5.0, 5.0))\n"
            "print(len(r.allan['Va'].tau_s), r.drift['Va'].t_s.size)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    # 19 s after the trim at 1 kHz: τ = 2^k samples up to N/4 = 4750, k = 0..12.
    assert out.stdout.split() == ["13", "2000"]


@pytest.mark.parametrize("block", [1000, 4097, 1 << 20])
def test_streamed_allan_equals_in_memory(block: int) -> None:
    from fsmbench.signal.allan import allan_deviation
    from fsmbench.signal.streaming import AllanStream, read_blocks

    rng = np.random.default_rng(5)
    x = 1.0 + 1e-9 * np.cumsum(rng.standard_normal(50_000)) + 1e-9 * rng.standard_normal(50_000)
    m = 2 ** np.arange(0, 14)
    ref = allan_deviation(x, fs_hz=FS, taus_s=m / FS, unit="m")
    stream = AllanStream(n_samples=x.size, fs_hz=FS, factors=m, unit="m", name="x")
    for _, part in read_blocks({"x": x}, start=0, stop=x.size, block_samples=block):
        stream.update(part["x"])
    got = stream.result()
    # Same terms, summed per block: rounding only (a metre offset on nm noise, removed first).
    np.testing.assert_allclose(got.adev, ref.adev, rtol=1e-10)
    np.testing.assert_array_equal(got.n_terms, ref.n_terms)
