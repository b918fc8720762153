"""Section 11 read in blocks: lazy (Dask) = in memory = any block size = the former in-memory code.

``_reference`` is the in-memory analysis as it was before the block reads
(commit 62bb1c5: the periods reshaped to (n, P), then reduced), kept here as
the independent check; ``data/repeatability_reference.json`` holds that
code's own output on ``_rep_record`` (see its ``about``).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import dask.array as da
import numpy as np
import pytest
import xarray as xr

from fsmbench.bench.blocks import rotation
from fsmbench.bench.params import default_bench
from fsmbench.budget.propagation import distance_coefficients
from fsmbench.budget.repeatability import (
    SEED_11,
    analyse_repeatability,
    find_alignment,
)
from fsmbench.budget.spectra import esrf_welch, first_order_lowpass
from fsmbench.twin import esrf_experiments, simulate_experiment
from fsmbench.twin.experiments import with_duration

FS = 500.0  # a low rate keeps the records small; the code takes fs from the attrs
FIXTURE = Path(__file__).parent / "data" / "repeatability_reference.json"
# Same arithmetic on the same samples, summed in another order (blocks, fsum) and Va less
# its first sample: rounding differences of a few 1e-16 relative, at most ~1e-13 on
# the nm ranges of µm-scale Va; 1e-12 leaves a decade.
RTOL = 1e-12
SCALARS = ("nonrep_rms_m", "nonrep_rms_unbiased_m", "nonrep_rms_lpf_m",
           "nonrep_rms_lpf_settled_m", "repeatable_ptp_m", "tracking_distance_mean_m",
           "tracking_distance_std_m", "tracking_distance_nonrep_rms_m")
PAIRS = ("tracking_rms_rad", "seed_law_distance_std_m")
ARRAYS = ("repeatable_m", "repeatable_lpf_m", "va_min_m", "va_max_m", "va_nonrep_min_m",
          "va_nonrep_max_m", "va_lpf_settled_nonrep_min_m", "va_lpf_settled_nonrep_max_m",
          "va_lpf_first_nonrep_m", "tracking_distance_repeatable_m", "f_hz",
          "psd_tracking_rad2_per_hz", "psd_distance_m2_per_hz", "psd_distance_seed_m2_per_hz",
          "psd_va_m2_per_hz")
ENVELOPES = ("command", "Vph", "Vpv", "Va", "tracking_distance", "Va_nonrep",
             "tracking_distance_nonrep")


def _rep_record(*, name: str = "data_rep_h", n: int = 7000, first: int = 600,
                offset_m: float = 0.0, seed: int = 7) -> xr.Dataset:
    """A Newport sine from ``first`` on; Va: 0.8 µm per period, random walk, 3 nm white."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / FS
    k = np.arange(n)
    un = np.where(k >= first, 0.8 * np.sin(2 * np.pi * (t - first / FS)) + 0.3, 0.0)
    va = (offset_m + 0.8e-6 * np.cos(2 * np.pi * t) + np.cumsum(5e-11 * rng.standard_normal(n))
          + 3e-9 * rng.standard_normal(n))
    zero = np.zeros(n)
    sig = {"Unh": un if name.endswith("h") else zero, "Unv": un if name.endswith("v") else zero,
           "Vph": 2e-3 + 1e-3 * rng.standard_normal(n),
           "Vpv": -1e-3 + 1e-3 * rng.standard_normal(n), "Va": va}
    return xr.Dataset({k2: ("t", v) for k2, v in sig.items()}, coords={"t": t},
                      attrs={"fs_hz": FS, "experiment": name})


def _lazy(ds: xr.Dataset, chunks: tuple[int, ...] | int) -> xr.Dataset:
    """The record over Dask arrays: the given chunk lengths, or chunks of that many samples."""
    spec = chunks if isinstance(chunks, int) else (chunks,)
    return ds.copy(data={k: da.from_array(np.asarray(v.values), chunks=spec)
                         for k, v in ds.data_vars.items()})


def _odd_chunks(n: int) -> tuple[int, ...]:
    """Irregular chunks (1 sample, a prime, longer than a period, …) covering n samples."""
    sizes, total = [], 0
    for c in [1, 997, 77, 1500, 3]:
        sizes.append(c)
        total += c
    sizes.append(n - total)
    return tuple(sizes)


def _reference(ds: xr.Dataset, params) -> dict[str, object]:
    """The former in-memory analysis: every period as a row of an (n, P) array."""
    name = str(ds.attrs["experiment"])
    fs = float(ds.attrs["fs_hz"])
    channel = {"data_rep_h": "Unh", "data_rep_v": "Unv"}[name]
    first = int(np.flatnonzero(ds[channel].values != 0)[0])
    per = round(fs)
    start = first + per
    n = (ds.sizes["t"] - start - 1) // per
    sig = {s: np.asarray(ds[s].values, dtype=float)[start:start + n * per]
           for s in ("Vph", "Vpv", "Va")}
    va = sig["Va"]
    vaf = first_order_lowpass(va, cutoff_hz=10.0, fs_hz=fs)
    va_p, vaf_p = va.reshape(n, per), vaf.reshape(n, per)
    rep, rep_f = va_p.mean(axis=0), vaf_p.mean(axis=0)
    settled = vaf_p[1:] - vaf_p[1:].mean(axis=0)
    gd = params.quad_diode.gain_v_per_rad.as_array()
    r = np.stack([sig["Vph"] / gd[0], sig["Vpv"] / gd[1]])
    alpha = rotation(params.quad_diode.rotation_rad).T @ r
    dist = np.asarray(distance_coefficients(params)) @ alpha**2
    seed_dist = 0.5 * SEED_11["law_length_m"] * r**2
    dist_p = dist.reshape(n, per)
    nonrep = float(np.sqrt(np.mean((va_p - rep) ** 2)))
    psd = [np.asarray(esrf_welch(x, fs_hz=fs).values, dtype=float)
           for x in (r[0], r[1], dist, seed_dist[0], seed_dist[1], va - va.mean())]
    return {
        "n_periods": n, "start_s": start / fs,
        "nonrep_rms_m": nonrep, "nonrep_rms_unbiased_m": nonrep * math.sqrt(n / (n - 1)),
        "nonrep_rms_lpf_m": float(np.sqrt(np.mean((vaf_p - rep_f) ** 2))),
        "nonrep_rms_lpf_settled_m": float(np.sqrt(np.mean(settled**2))),
        "repeatable_ptp_m": float(np.ptp(rep)),
        "tracking_rms_rad": tuple(float(np.sqrt(np.mean(x**2))) for x in r),
        "tracking_distance_mean_m": float(dist.mean()),
        "tracking_distance_std_m": float(dist.std()),
        "tracking_distance_nonrep_rms_m": float(np.sqrt(np.mean((dist_p - dist_p.mean(0)) ** 2))),
        "seed_law_distance_std_m": tuple(float(x.std()) for x in seed_dist),
        "repeatable_m": rep, "repeatable_lpf_m": rep_f,
        "va_min_m": (va_p - va.mean()).min(axis=0), "va_max_m": (va_p - va.mean()).max(axis=0),
        "va_nonrep_min_m": (va_p - rep).min(axis=0), "va_nonrep_max_m": (va_p - rep).max(axis=0),
        "va_lpf_settled_nonrep_min_m": settled.min(axis=0),
        "va_lpf_settled_nonrep_max_m": settled.max(axis=0),
        "va_lpf_first_nonrep_m": vaf_p[0] - rep_f,
        "tracking_distance_repeatable_m": dist_p.mean(axis=0),
        "psd_tracking_rad2_per_hz": np.stack(psd[:2], axis=1), "psd_distance_m2_per_hz": psd[2],
        "psd_distance_seed_m2_per_hz": np.stack(psd[3:5], axis=1), "psd_va_m2_per_hz": psd[5],
        # What the time plots draw, whole (their envelopes must hold exactly these samples).
        "series": {"Va": va - va.mean(), "Va_nonrep": (va_p - rep).ravel(),
                   "tracking_distance": dist,
                   "tracking_distance_nonrep": (dist_p - dist_p.mean(0)).ravel()},
    }


def _close(a: object, b: object, what: str, rtol: float = RTOL, atol: float = 0.0) -> None:
    """Equal relative to the largest magnitude of ``b`` (arrays: nm ranges cross zero)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    assert a.shape == b.shape, what
    scale = float(np.max(np.abs(b)))
    assert float(np.max(np.abs(a - b))) <= rtol * scale + atol, what


def _same(r, ref: dict[str, object], *, va_abs_m: float = 0.0) -> None:
    """``va_abs_m``: largest |Va|; the (n, P) reference rounds every sample of Va and of its
    low pass at eps·|Va|, and the ranges of Va's periods are differences of such samples:
    8 eps·|Va| absolute on top (a 0.35 nm settled range of a µm Va is 1e-12 at 2 eps)."""
    assert r.n_periods == ref["n_periods"]
    assert r.start_s == ref["start_s"]
    for k in (*SCALARS, *PAIRS):
        _close(getattr(r, k), ref[k], k)
    floor = 8 * np.finfo(float).eps * va_abs_m
    for k in ARRAYS:
        if k in ref:
            _close(getattr(r, k), ref[k], k, atol=floor if k.startswith("va_") else 0.0)


@pytest.fixture(scope="module")
def params():
    return default_bench().nominal


@pytest.fixture(scope="module")
def twin_rep():
    spec = {s.name: s for s in with_duration(esrf_experiments(), duration_s=6.0)}["data_rep_h"]
    return simulate_experiment(default_bench(), spec, seed=3).recording


def test_equals_the_former_code_on_its_fixture(params):
    """Against the numbers the former in-memory code wrote (data/…json)."""
    fixture = json.loads(FIXTURE.read_text())
    for key, kw in {"h": {"name": "data_rep_h"}, "v": {"name": "data_rep_v", "seed": 8}}.items():
        r = analyse_repeatability(_rep_record(**kw), params=params)
        j, want = r.to_json(), fixture[key]
        assert set(j) - {"seed"} == set(want) - {"arrays"}, "the keys of the former JSON"
        for k, v in want.items():
            if k in ("arrays", "seed"):
                continue
            if isinstance(v, dict):
                _close([j[k]["h"], j[k]["v"]], [v["h"], v["v"]], k)
            elif isinstance(v, float):
                _close(j[k], v, k)
            else:
                assert j[k] == v, k
        for k, v in want.get("arrays", {}).items():
            _close(getattr(r, k), v, k)


@pytest.mark.parametrize("block", [137, 333, 500, 10**7])  # < P, odd, = P, > the record
def test_any_block_size_equals_the_reference(params, block):
    ds = _rep_record()
    _same(analyse_repeatability(ds, params=params, block_samples=block), _reference(ds, params))


@pytest.mark.parametrize("name", ["data_rep_h", "data_rep_v"])
def test_lazy_odd_chunks_equal_in_memory(params, name):
    ds = _rep_record(name=name, seed=11)
    mem = analyse_repeatability(ds, params=params)
    for chunks, block in ((_odd_chunks(ds.sizes["t"]), 211), (4096, 1 << 20), (700, 999)):
        lazy = analyse_repeatability(_lazy(ds, chunks), params=params, block_samples=block)
        _same(lazy, {**{k: getattr(mem, k) for k in (*SCALARS, *PAIRS, *ARRAYS)},
                     "n_periods": mem.n_periods, "start_s": mem.start_s})
        for k in ENVELOPES:
            for part in ("minimum", "maximum", "mean"):
                _close(getattr(lazy.envelopes[k], part), getattr(mem.envelopes[k], part),
                       f"{k}.{part}")


def test_twin_record_equals_the_reference(params, twin_rep):
    for block in (3333, 1 << 20):
        r = analyse_repeatability(twin_rep, params=params, block_samples=block)
        _same(r, _reference(twin_rep, params),
              va_abs_m=float(np.max(np.abs(twin_rep["Va"].values))))


def test_envelopes_hold_every_extreme(params):
    """Each envelope's overall min and max are those of the whole series it bins."""
    ds = _rep_record()
    r = analyse_repeatability(ds, params=params, block_samples=137, n_bins=64)
    ref = _reference(ds, params)
    for k, x in ref["series"].items():  # type: ignore[union-attr]
        env = r.envelopes[k]
        assert env.minimum.size == 64
        _close([env.minimum.min(), env.maximum.max()], [x.min(), x.max()], k)
    cmd = np.asarray(ds["Unh"].values)[round(r.start_s * FS):][: r.n_periods * 500]
    assert r.envelopes["command"].minimum.min() == cmd.min()
    assert r.envelopes["command"].maximum.max() == cmd.max()


def test_a_metre_offset_loses_no_nanometre(params):
    """Va on a 1.5 m offset: the offset-free numbers are those without it, to 1e-12.

    (The former code, reducing raw Va, rounded at eps·1.5 m = 3e-16 m: measured
    4.5e-9 relative on the settled low-passed rms, 6e-11 on the repeatable ptp.)
    """
    far = _rep_record(offset_m=1.5)
    near = far.assign(Va=far["Va"] - 1.5)  # exact (Sterbenz): the same samples, offset apart
    plain = analyse_repeatability(near, params=params, block_samples=333)
    shifted = analyse_repeatability(far, params=params, block_samples=333)
    for k in ("nonrep_rms_m", "nonrep_rms_unbiased_m", "nonrep_rms_lpf_settled_m",
              "repeatable_ptp_m", "va_min_m", "va_max_m", "va_nonrep_min_m", "va_nonrep_max_m",
              "va_lpf_settled_nonrep_min_m", "va_lpf_settled_nonrep_max_m", "psd_va_m2_per_hz"):
        _close(getattr(shifted, k), getattr(plain, k), k)


def test_alignment_reads_the_command_only_until_it_moves(params):
    """The first command is in the third block; the chunks after it cannot be read."""
    ds = _rep_record(first=600)

    def unreadable(x: np.ndarray) -> np.ndarray:
        raise AssertionError("a block after the first command was read")

    n = ds.sizes["t"]
    head = da.from_array(np.asarray(ds["Unh"].values[:768]), chunks=256)
    tail = da.map_blocks(unreadable, da.zeros(n - 768, chunks=256), dtype=float)
    lazy = ds.copy(data={**{k: v.values for k, v in ds.data_vars.items()},
                         "Unh": da.concatenate([head, tail])})
    al = find_alignment(lazy, block_samples=256)
    assert al.first_command_index == 600
    assert al.start_index == 600 + 500
    assert al.n_periods == (n - 1100 - 1) // 500
    # The same on another experiment name: both commands scanned together.
    other = lazy.assign_attrs(experiment="my_rep")
    assert find_alignment(other, block_samples=256).channel == "Unh"


def test_short_record_message_unchanged(params):
    ds = _lazy(_rep_record(n=1300, first=100), 64)  # 1.4 s after alignment at 500 Hz
    with pytest.raises(ValueError) as err:
        analyse_repeatability(ds, params=params, block_samples=100)
    assert str(err.value) == ("data_rep_h: 1 whole period(s) of 1 s after Unh's first command "
                              "+ 1 s (1.4 s left); at least two are needed")


def test_nan_names_the_signal(params):
    ds = _rep_record()
    va = ds["Va"].values.copy()
    va[4321] = np.nan
    with pytest.raises(ValueError, match=r"data_rep_h\.Va contains NaN .* sample 4321"):
        analyse_repeatability(ds.assign(Va=("t", va)), params=params, block_samples=1000)


def test_memory_does_not_grow_with_the_periods(params):
    """Folded arrays are (P,) and envelopes a fixed number of bins, for 11 or 40 periods."""
    short = analyse_repeatability(_rep_record(), params=params)
    long = analyse_repeatability(_rep_record(n=22_000), params=params, n_bins=300)
    assert (short.n_periods, long.n_periods) == (11, 41)
    for k in ARRAYS:
        assert getattr(long, k).shape == getattr(short, k).shape, k
    for k in ARRAYS[:10]:
        assert getattr(long, k).shape == (500,), k
    for k in ENVELOPES:
        assert long.envelopes[k].minimum.shape == (300,), k


def test_progress_reports_both_reads(params):
    lines: list[str] = []
    analyse_repeatability(_rep_record(), params=params, block_samples=700, progress=lines.append)
    assert any(x.startswith("data_rep_h: folding the periods: 100 %") for x in lines)
    assert lines[-1].startswith("data_rep_h: non-repeatable parts and spectra: 100 %")
    # A record of seconds is counted in seconds, not in hundredths of an hour.
    assert " h of " not in lines[-1] and lines[-1].endswith(" s)")


def test_records_in_memory_need_no_dask() -> None:
    """The core installs without the dask extra: ESRF study 11 on a record in memory runs."""
    import subprocess
    import sys

    code = ("import sys; sys.modules['dask'] = None; sys.modules['distributed'] = None\n"
            "from fsmbench.bench.params import default_bench\n"
            "from fsmbench.twin import simulate_bench\n"
            "from fsmbench.budget.repeatability import analyse_repeatability\n"
            "b = default_bench()\n"
            "run = simulate_bench(b, seed=1, duration_s=6.0, experiments=['data_rep_h'])\n"
            "r = analyse_repeatability(run.recordings['data_rep_h'], params=b.nominal)\n"
            "print(r.n_periods)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["3"]  # 6 s less the start and alignment: 3 whole periods
