"""One-pass FRF matrices: equality with the pairwise functions, bounds, combining, errors."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
import scipy.signal as ss
import scipy.stats as st

from fsmbench.ident.frf.response import FrequencyResponse, combine_columns, spectral_matrix
from fsmbench.signal.welch import cpsd, hanning, mscohere, pwelch, tfestimate

FS_HZ = 1e4
WIN = hanning(512)


def _sm(inputs: np.ndarray, outputs: np.ndarray, ins: list[str], outs: list[str],
        **kw: object) -> FrequencyResponse:
    return spectral_matrix(inputs, outputs, input_names=ins, output_names=outs,
                           window=kw.pop("window", WIN), fs_hz=FS_HZ, **kw)  # type: ignore[arg-type]


def test_one_pass_equals_pairwise_functions(esrf_experiments: dict) -> None:
    e = esrf_experiments["Uch"]
    r = _sm(e.inputs, e.outputs, ["Uch"], ["Vph", "Vpv"])
    x = e.inputs[:, 0]
    kw = {"window": WIN, "fs_hz": FS_HZ}
    for k, out in enumerate(["Vph", "Vpv"]):
        y = e.outputs[:, k]
        cell = {"output": out, "input": "Uch"}
        # rtol 1e-12: identical FFTs and products, only summation order may differ
        np.testing.assert_allclose(r.frf.sel(cell).values, tfestimate(x, y, **kw).values,
                                   rtol=1e-12)
        np.testing.assert_allclose(r.coherence.sel(cell).values, mscohere(x, y, **kw).values,
                                   rtol=1e-12)
        np.testing.assert_allclose(r.input_psd.sel(cell).values, pwelch(x, **kw).values, rtol=1e-12)
        np.testing.assert_allclose(r.output_psd.sel(cell).values, pwelch(y, **kw).values,
                                   rtol=1e-12)
        np.testing.assert_allclose(r.cross_psd.sel(cell).values, cpsd(y, x, **kw).values,
                                   rtol=1e-12)
    assert r.n_segments == (pwelch(x, **kw).n_segments,)


def test_layout_units_and_options(esrf_experiments: dict) -> None:
    e = esrf_experiments["Ucv"]
    r = _sm(e.inputs, e.outputs, ["Ucv"], ["Vph", "Vpv"], noverlap=128, nfft=1024)
    for name in FrequencyResponse._ARRAYS:
        arr = getattr(r, name)
        assert arr.dims == ("frequency", "output", "input")
        assert list(arr["output"].values) == ["Vph", "Vpv"] and list(arr["input"].values) == ["Ucv"]
    assert r.frf["frequency"].attrs["units"] == "Hz"
    assert np.iscomplexobj(r.frf.values) and not np.iscomplexobj(r.coherence.values)
    assert (r.window_length, r.noverlap, r.nfft, r.fs_hz) == (512, 128, 1024, FS_HZ)
    assert r.n_segments == ((e.inputs.shape[0] - 128) // 384,)
    with pytest.raises(dataclasses.FrozenInstanceError):
        r.nfft = 2048  # type: ignore[misc]


def test_random_error_is_bendat_piersol_and_bounds_scale_with_z(esrf_experiments: dict) -> None:
    e = esrf_experiments["Uch"]
    r95 = _sm(e.inputs, e.outputs, ["Uch"], ["Vph", "Vpv"])
    r99 = _sm(e.inputs, e.outputs, ["Uch"], ["Vph", "Vpv"], confidence=0.99)
    g2 = r95.coherence.values
    n_d = r95.effective_averages[0]
    expected = np.sqrt(1 - g2) / (np.sqrt(g2) * np.sqrt(2 * n_d))  # B&P, independent evaluation
    np.testing.assert_allclose(r95.random_error.values, expected, rtol=1e-9)  # sqrt(1-g2) rounding
    mag = np.abs(r95.frf.values)
    # The variance is estimated on n_d - 1 complex dof: Student's t on twice that.
    z95, z99 = (float(st.t.ppf(q, 2 * (n_d - 1))) for q in (0.975, 0.995))
    np.testing.assert_allclose(r95.magnitude_upper.values, mag * (1 + z95 * expected), rtol=1e-9)
    width = lambda r: r.phase_upper_rad.values - r.phase_lower_rad.values  # noqa: E731
    narrow = expected < 0.5  # below the pi cap on the phase half-width
    np.testing.assert_allclose(width(r99)[narrow] / width(r95)[narrow], z99 / z95, rtol=1e-12)
    assert np.all(r95.magnitude_lower.values >= 0) and np.all(r95.magnitude_lower.values <= mag)


def test_two_input_h1_matches_independent_solve_and_its_bounds_cover(
    rng: np.random.Generator, resonance_ba: tuple[np.ndarray, np.ndarray]
) -> None:
    b2, a2 = resonance_ba
    b1, a1 = np.array([0.1]), np.array([1.0, -0.9])
    n = 2**17 + 2000
    u = rng.standard_normal((n, 2))
    y = np.column_stack([
        ss.lfilter(b1, a1, u[:, 0]) + 0.5 * ss.lfilter(b2, a2, u[:, 1]),
        0.3 * ss.lfilter(b2, a2, u[:, 0]) + ss.lfilter(b1, a1, u[:, 1]),
    ])[2000:] + 0.05 * rng.standard_normal((n - 2000, 2))
    u = u[2000:]
    r = spectral_matrix(u, y, input_names=["u1", "u2"], output_names=["y1", "y2"],
                        window=hanning(1024), fs_hz=FS_HZ, confidence=0.99)
    # independent H = Syx Sxx^-1 from the pairwise cpsd, one frequency at a time
    kw = {"window": hanning(1024), "fs_hz": FS_HZ}
    sxx = np.array([[cpsd(u[:, i], u[:, j], **kw).values for j in range(2)] for i in range(2)])
    syx = np.array([[cpsd(y[:, k], u[:, i], **kw).values for i in range(2)] for k in range(2)])
    h = np.stack([np.linalg.solve(sxx[:, :, f].T, syx[:, :, f].T).T for f in range(sxx.shape[2])])
    np.testing.assert_allclose(r.frf.values, h, rtol=1e-9)  # cond(Sxx) ~ 1-10: few-ulp solves
    truth = {
        (0, 0): (b1, a1, 1.0), (0, 1): (b2, a2, 0.5), (1, 0): (b2, a2, 0.3), (1, 1): (b1, a1, 1.0)
    }
    for (k, i), (b, a, g) in truth.items():
        _, h_true = ss.freqz(g * b, a, worN=r.frequency_hz, fs=FS_HZ)
        sl = slice(1, -1)
        lo, hi = r.magnitude_lower.values[sl, k, i], r.magnitude_upper.values[sl, k, i]
        inside = (np.abs(h_true[sl]) >= lo) & (np.abs(h_true[sl]) <= hi)
        assert np.mean(inside) >= 0.95  # 99 % bounds, >= 95 % of frequencies
        half = (r.phase_upper_rad.values[sl, k, i] - r.phase_lower_rad.values[sl, k, i]) / 2
        dphi = np.abs(np.angle(h_true[sl] / r.frf.values[sl, k, i]))
        assert np.mean(dphi <= half) >= 0.95  # 99 % bounds, >= 95 % of frequencies


# ------------------------------------------------------------------ combine_columns
def _seed_columns(esrf_experiments: dict, **kw: object) -> list[FrequencyResponse]:
    return [_sm(e.inputs, e.outputs, [name], ["Vph", "Vpv"], **kw)
            for name, e in esrf_experiments.items()]


def test_combine_columns_builds_named_matrix(esrf_experiments: dict) -> None:
    uch, ucv = _seed_columns(esrf_experiments)
    g = combine_columns([uch, ucv])
    assert g.input_names == ("Uch", "Ucv") and g.output_names == ("Vph", "Vpv")
    assert g.frf.shape == (257, 2, 2)
    for col in (uch, ucv):
        name = col.input_names[0]
        for field in FrequencyResponse._ARRAYS:
            np.testing.assert_array_equal(getattr(g, field).sel(input=name).values,
                                          getattr(col, field).sel(input=name).values)
    assert g.n_segments == uch.n_segments + ucv.n_segments


def test_combine_columns_aligns_outputs_by_name(esrf_experiments: dict) -> None:
    e = esrf_experiments["Ucv"]
    swapped = _sm(e.inputs, e.outputs[:, ::-1], ["Ucv"], ["Vpv", "Vph"])
    uch = _seed_columns(esrf_experiments)[0]
    g = combine_columns([uch, swapped])
    assert g.output_names == ("Vph", "Vpv")
    np.testing.assert_array_equal(g.frf.sel(output="Vph", input="Ucv").values,
                                  swapped.frf.sel(output="Vph", input="Ucv").values)


def test_combine_columns_rejects_inconsistent_responses(esrf_experiments: dict) -> None:
    uch = _seed_columns(esrf_experiments)[0]
    e = esrf_experiments["Ucv"]
    with pytest.raises(ValueError, match=r"response 1 has nfft=1024 but response 0 has 512"):
        combine_columns([uch, _sm(e.inputs, e.outputs, ["Ucv"], ["Vph", "Vpv"], nfft=1024)])
    with pytest.raises(ValueError, match=r"outputs \['Vph', 'Vx'\]"):
        combine_columns([uch, _sm(e.inputs, e.outputs, ["Ucv"], ["Vph", "Vx"])])
    with pytest.raises(ValueError, match="input names must be distinct"):
        combine_columns([uch, uch])
    with pytest.raises(ValueError, match="at least one"):
        combine_columns([])


def test_summary_is_json(esrf_experiments: dict) -> None:
    g = combine_columns(_seed_columns(esrf_experiments))
    s = json.loads(g.to_json())
    assert s["inputs"] == ["Uch", "Ucv"] and s["outputs"] == ["Vph", "Vpv"]
    assert s["nfft"] == 512 and s["fs_hz"] == FS_HZ and s["confidence"] == 0.95
    assert set(s["effective_averages"]) == {"Uch", "Ucv"}
    assert len(s["pairs"]) == 4 and all(0 <= p["median_coherence"] <= 1 for p in s["pairs"])


# ------------------------------------------------------------------ bad input
@pytest.mark.parametrize("level", [0.0, 1.5])
def test_input_without_power_is_named(rng: np.random.Generator, level: float) -> None:
    u = np.column_stack([rng.standard_normal(5000), np.full(5000, level)])
    with pytest.raises(ValueError, match=r"'Ucv' \(input\) is constant .*coherence and the "
                                         r"frequency response are undefined"):
        _sm(u, rng.standard_normal((5000, 2)), ["Uch", "Ucv"], ["Vph", "Vpv"])


def test_nan_in_an_output_is_named(rng: np.random.Generator) -> None:
    y = rng.standard_normal((5000, 2))
    y[123, 1] = np.nan
    with pytest.raises(ValueError, match=r"'Vpv' \(output\) contains 1 NaN .*index 123"):
        _sm(rng.standard_normal(5000), y, ["Uch"], ["Vph", "Vpv"])


def test_unequal_lengths_are_named(rng: np.random.Generator) -> None:
    with pytest.raises(ValueError, match=r"'Uch' \(input\) has 5000, 'Vph' \(output\) has 4000"):
        _sm(rng.standard_normal(5000), rng.standard_normal(4000), ["Uch"], ["Vph"])


@pytest.mark.parametrize("n", [9000, 14_999])  # shorter than the window; than two segments
def test_short_record_says_how_many_samples_for_which_window(
    rng: np.random.Generator, n: int
) -> None:
    with pytest.raises(ValueError, match=rf"'Uch' \(input\), 'Vph' \(output\): record of {n} "
                                         r"samples is too short for a 10000-sample window \(1 s at "
                                         r"10000 Hz\); at least 15000 samples \(1.5 s\) are needed "
                                         r"for 2 segments"):
        _sm(rng.standard_normal(n), rng.standard_normal(n), ["Uch"], ["Vph"],
            window=hanning(10_000))


def test_name_count_must_match_columns(rng: np.random.Generator) -> None:
    with pytest.raises(ValueError, match=r"output_names has 1 name\(s\) but the data has 2"):
        _sm(rng.standard_normal(5000), rng.standard_normal((5000, 2)), ["Uch"], ["Vph"])
    with pytest.raises(ValueError, match="duplicate"):
        _sm(rng.standard_normal(5000), rng.standard_normal((5000, 2)), ["Uch"], ["Vph", "Vph"])


def test_linearly_dependent_inputs(rng: np.random.Generator) -> None:
    u1 = rng.standard_normal(20_000)
    y = rng.standard_normal((20_000, 1))
    with pytest.raises(ValueError, match=r"inputs 'Uch', 'Ucv' are linearly dependent at every"):
        _sm(np.column_stack([u1, 2 * u1]), y, ["Uch", "Ucv"], ["Vph"], window=hanning(256))
    # a weak tone makes them independent only near 1 kHz: NaN elsewhere, with a warning
    tone = 1e-2 * np.sin(2 * np.pi * 1000 * np.arange(20_000) / FS_HZ)
    with pytest.warns(RuntimeWarning, match=r"linearly dependent at \d+ of 129 frequencies"):
        r = _sm(np.column_stack([u1, 2 * u1 + tone]), y, ["Uch", "Ucv"], ["Vph"],
                window=hanning(256))
    finite = np.isfinite(r.frf.values[:, 0, 0])
    assert finite[int(1000 / (FS_HZ / 256))] and not finite.all()


def test_bad_confidence(rng: np.random.Generator) -> None:
    with pytest.raises(ValueError, match=r"confidence must be in \(0, 1\)"):
        _sm(rng.standard_normal(5000), rng.standard_normal(5000), ["Uch"], ["Vph"], confidence=95)
