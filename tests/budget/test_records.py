"""Huddle and repeatability processing on synthetic records: the study's semantics, bad input."""

from __future__ import annotations

import math
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
import xarray as xr

from fsmbench.bench.params import default_bench
from fsmbench.budget import align_periods, analyse_huddle_record, analyse_repeatability
from fsmbench.budget.huddle import analyse_huddle, huddle_number, trim_huddle

FS = 1000.0  # a low rate keeps the synthetic records small; the code takes fs from the attrs


def _dataset(signals: dict[str, np.ndarray], name: str, fs: float = FS) -> xr.Dataset:
    n = next(iter(signals.values())).size
    return xr.Dataset({k: ("t", v) for k, v in signals.items()},
                      coords={"t": np.arange(n) / fs}, attrs={"fs_hz": fs, "experiment": name})


def _rep(n: int, *, first: int, sigma: float, seed: int = 0, name: str = "data_rep_h"):
    rng = np.random.default_rng(seed)
    t = np.arange(n) / FS
    un = np.where(np.arange(n) >= first, np.sin(2 * np.pi * (t - first / FS)) + 1e-3, 0.0)
    va = 500e-9 * np.cos(2 * np.pi * t) + sigma * rng.standard_normal(n)
    zero = np.zeros(n)
    sig = {"Unh": un if name.endswith("h") else zero, "Unv": un if name.endswith("v") else zero,
           "Vph": 1e-3 * rng.standard_normal(n), "Vpv": 1e-3 * rng.standard_normal(n), "Va": va}
    return _dataset(sig, name)


@pytest.fixture(scope="module")
def nominal():
    return default_bench().nominal


def test_alignment_follows_matlab_indices():
    n, first = 12_345, 777
    rec = align_periods(_rep(n, first=first, sigma=0.0), period_s=1.0)
    # MATLAB: i0 = find(Un ~= 0, 1) + fs (1-based); keep i0 .. i0 + fs·floor((N − i0)/fs) − 1.
    i0 = (first + 1) + int(FS)
    n_per = math.floor((n - i0) / FS)
    assert rec.first_command_index == first
    assert rec.start_index == i0 - 1
    assert rec.n_periods == n_per
    assert rec.signals["Va"].size == n_per * FS


def test_nonrepeatable_part_of_a_periodic_signal_plus_noise(nominal):
    sigma = 2e-9
    r = analyse_repeatability(_rep(41_000, first=1000, sigma=sigma), params=nominal)
    assert r.n_periods == 38
    # White noise: the mean over n periods leaves (n−1)/n of its variance; 38 000 samples
    # estimate σ to 0.4 %; allow 2 %.
    assert r.nonrep_rms_m == pytest.approx(sigma * math.sqrt(37 / 38), rel=0.02)
    assert r.nonrep_rms_unbiased_m == pytest.approx(sigma, rel=0.02)
    # The repeatable part is the periodic signal (noise averaged over 38 periods: σ/√38).
    tp = np.arange(1000) / FS + r.start_s
    np.testing.assert_allclose(r.repeatable_m, 500e-9 * np.cos(2 * np.pi * tp),
                               atol=5 * sigma / math.sqrt(38))


def test_lowpass_start_transient_is_non_repeatable(nominal):
    """lsim from rest on a signal moving ~µm per period: the filtered rms exceeds the raw one."""
    r = analyse_repeatability(_rep(21_000, first=1000, sigma=0.2e-9), params=nominal)
    assert r.nonrep_rms_lpf_m > r.nonrep_rms_m  # 500 nm start step → ~60 nm over 16 ms
    # Dropping the first period removes it; what is left is the filtered noise (~0.03 nm).
    assert r.nonrep_rms_lpf_settled_m is not None
    assert r.nonrep_rms_lpf_settled_m < 0.25 * r.nonrep_rms_m  # 10 Hz of 500 Hz white: 0.18


def test_too_short_names_the_experiment(nominal):
    ds = _rep(2500, first=100, sigma=0.0)  # 1.4 s after alignment: one whole period
    with pytest.raises(ValueError, match=r"data_rep_h: 1 whole period"):
        analyse_repeatability(ds, params=nominal)


def test_no_command_names_the_experiment(nominal):
    ds = _rep(5000, first=10**9, sigma=0.0, name="data_rep_v")
    with pytest.raises(ValueError, match=r"data_rep_v: .*Unv is zero throughout"):
        analyse_repeatability(ds, params=nominal)
    other = ds.assign(Unv=ds["Unh"]).assign_attrs(experiment="my_rep")
    with pytest.raises(ValueError, match=r"my_rep: no Newport command"):
        analyse_repeatability(other, params=nominal)
    with pytest.raises(ValueError, match=r"data_rep_v: missing \['Va'\]"):
        analyse_repeatability(ds.drop_vars("Va"), params=nominal)


# ---------------------------------------------------------------- huddle
def _huddle(n: int, number: int, *, seed: int = 0, va_sigma: float = 1e-9) -> xr.Dataset:
    rng = np.random.default_rng(seed)
    return _dataset({"Vph": 0.2 + 1e-3 * rng.standard_normal(n),
                     "Vpv": -0.1 + 1e-3 * rng.standard_normal(n),
                     "Va": 3e-6 + va_sigma * rng.standard_normal(n)}, f"data_huddle_test_{number}")


def test_huddle_trimming_and_means(nominal):
    ds = _huddle(5500, 1)
    sig = trim_huddle(ds, name="data_huddle_test_1")
    assert sig["t"][0] == 0.0 and sig["Va"].size == 4500  # t < 1 s dropped, the rest < 100 s
    cut = trim_huddle(ds, name="data_huddle_test_1", duration_s=3.0)
    assert cut["Va"].size == 3000  # tend·fs samples
    r = analyse_huddle_record(ds)
    assert r.va_rms_m == pytest.approx(1e-9, rel=0.05)  # mean (3 µm) removed; 4500 samples
    assert r.vph_rms_v == pytest.approx(1e-3, rel=0.05)  # idem: std of σ known to ~1 %
    assert r.band("total").rms == r.va_rms_m
    # Welch with a Hann window keeps the power: cumulative rms ends at the rms (within 5 %).
    assert r.cumulative_rms("Vph")[-1] == pytest.approx(r.vph_rms_v, rel=0.05)


def test_huddle_comparison_sentence(nominal):
    recs = {"data_huddle_test_1": _huddle(6000, 1, seed=1, va_sigma=1e-9),
            "data_huddle_test_2": _huddle(6000, 2, seed=2, va_sigma=3e-9)}
    h = analyse_huddle(recs, params=nominal)
    (c,) = h.comparisons
    assert c.ratios["total"] == pytest.approx(3.0, rel=0.05)  # two 5000-sample rms: ~1.5 %
    assert c.significant["50–500 Hz"]  # white noise ×3 in a band of ~450 Hz × 5 s
    assert "test 2 / test 1" in c.sentence
    assert (f"increases the total rms by {100 * (c.ratios['total'] - 1):.0f} % "
            f"(×{c.ratios['total']:.2f}, significant)") in c.sentence
    assert "ESRF study (3.6)" in h.conclusion


@pytest.mark.parametrize(("name", "n", "match"), [
    ("data_huddle_test_1", 2500, r"data_huddle_test_1: 1\.5 s left"),
    ("data_huddle_test_9", 5000, "not a huddle test"),
    ("data_rep_h", 5000, "not a huddle test"),
])
def test_huddle_bad_input(name, n, match):
    ds = _huddle(n, 1).assign_attrs(experiment=name)
    with pytest.raises(ValueError, match=match):
        analyse_huddle_record(ds, name=name)


def test_huddle_missing_signal():
    with pytest.raises(ValueError, match=r"data_huddle_test_2: missing \['Vpv'\]"):
        analyse_huddle_record(_huddle(5000, 2).drop_vars("Vpv"))
    assert huddle_number("data_huddle_test_5") == 5
    with pytest.raises(ValueError, match="no huddle test"):
        analyse_huddle({}, params=default_bench().nominal)


# ------------------------------------------------ huddle comparisons: significance and practice
@pytest.mark.parametrize(("ratio", "rel_std", "words", "practical"), [
    # 1 % spread each: ×1.05 is significant (log 0.049 > 2·0.014) but within ±10 %.
    (1.05, 0.01, "no change in practice in the 50–5000 Hz rms (×1.05: statistically "
                 "significant, but within ±10 %)", False),
    (1.40, 0.02, "increases the 50–5000 Hz rms by 40 % (×1.40, significant)", True),
    (0.60, 0.02, "reduces the 50–5000 Hz rms by 40 % (×0.60, significant)", True),
    # 30 % spread each: ×1.4 is within the noise (log 0.34 < 2·0.42).
    (1.40, 0.30, "no significant change in the 50–5000 Hz rms (×1.40)", True),
])
def test_a_huddle_comparison_says_significance_and_practice(
        ratio: float, rel_std: float, words: str, practical: bool) -> None:
    from fsmbench.budget.huddle import BandRms, compare_huddle_records

    def record(number: int, rms: float) -> Any:
        band = BandRms(band="50–5000 Hz", f_lo_hz=50.0, f_hi_hz=5000.0, rms=rms,
                       rel_std=rel_std)
        return SimpleNamespace(number=number, name=f"data_huddle_test_{number}", bands=(band,),
                               band=lambda name, b=band: b)

    c = compare_huddle_records("closed loop", record(3, ratio * 1e-9), record(2, 1e-9))
    assert words in c.sentence
    assert c.practical["50–5000 Hz"] is practical
    changed = c.significant["50–5000 Hz"] and practical
    assert ("changes Va in practice in 50–5000 Hz" in c.sentence) is changed
    assert "-fold" not in c.sentence
