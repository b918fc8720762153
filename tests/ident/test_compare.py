"""The model against the records (MATLAB's compare) and the Bode band from the stds."""

from __future__ import annotations

import math

import numpy as np
import pytest
import xarray as xr

from fsmbench.bench.blocks import PlantModel
from fsmbench.bench.params import Bench
from fsmbench.ident.compare import compare_records, nrmse_fit_percent
from fsmbench.ident.evidence.departures import MeasuredKey
from fsmbench.ident.model_band import model_band
from fsmbench.ident.validate import simulate_fit

FS_HZ = 1e4


def test_fit_formula_against_a_hand_computed_case() -> None:
    y = np.array([1.0, 2.0, 3.0, 4.0])  # mean 2.5, ‖y − mean‖ = √5
    assert nrmse_fit_percent(y, np.array([1.0, 2.0, 3.0, 5.0])) == pytest.approx(
        100 * (1 - 1 / math.sqrt(5)))  # ‖y − ŷ‖ = 1: 55.28 %
    assert nrmse_fit_percent(y, y) == 100.0
    assert nrmse_fit_percent(y, np.full(4, 2.5)) == pytest.approx(0.0)
    assert math.isnan(nrmse_fit_percent(np.ones(3), np.ones(3)))


def _records(plant: PlantModel, *, seconds: float, noise_v: float = 0.0,
             seed: int = 3) -> dict[str, xr.Dataset]:
    """data_uch and data_unh recorded without noise by the twin's loop engine
    (:func:`fsmbench.ident.validate.simulate_fit`: another discretisation than the
    comparison's ``to_control``), white noise added when asked."""
    rng = np.random.default_rng(seed)
    n = round(seconds * FS_HZ)
    out = {}
    for experiment, inp, outs in (("data_uch", "Uch", ("Vph", "Vpv", "Vch", "Vcv")),
                                  ("data_unh", "Unh", ("Vph", "Vpv"))):
        sub = plant.subsystem(outputs=list(outs), inputs=[inp])
        u = 0.05 * rng.standard_normal(n) + 0.2  # an offset the comparison removes
        y = simulate_fit(np.asarray(sub.A), np.asarray(sub.B), np.asarray(sub.C),
                         np.asarray(sub.D), u=(u - u.mean())[:, None],
                         delay_s=plant.input_delay_s[inp], ts_s=1 / FS_HZ)
        y = y + 0.3 + noise_v * rng.standard_normal(y.shape)  # a DC offset, and noise
        out[experiment] = xr.Dataset(
            {inp: ("t", u), **{o: ("t", y[:, k]) for k, o in enumerate(outs)}},
            coords={"t": np.arange(n) / FS_HZ}, attrs={"fs_hz": FS_HZ})
    return out


def test_the_true_model_fits_noise_free_twin_records_at_100_percent(
        true_plant: PlantModel) -> None:
    cmp = compare_records(_records(true_plant, seconds=2.0), plant=true_plant,
                          settle_s=0.5)
    fits = {(f.experiment, f.output): f for f in cmp.fits}
    assert set(fits) == {("data_uch", o) for o in ("Vph", "Vpv", "Vch", "Vcv")} | {
        ("data_unh", "Vph"), ("data_unh", "Vpv")}
    for name, f in fits.items():
        assert f.compared_from_s == pytest.approx(0.5)
        assert f.t_s.size == round(cmp.window_s * FS_HZ) == f.y_v.size == f.y_model_v.size
        if name == ("data_uch", "Vcv"):
            assert math.isnan(f.fit_percent)  # no path Uch → Vcv: a zero record, no fit
        else:
            # Two exact discretisations of one model (the twin's engine, to_control's
            # exact delays): equal to rounding.
            assert f.fit_percent > 99.999, f
    assert cmp.skipped == {"data_ucv": "not in the data", "data_unv": "not in the data"}


def test_white_noise_bounds_the_fit_in_closed_form(true_plant: PlantModel) -> None:
    noise_v = 0.15  # Vph's own rms is about 0.35 V
    recs = _records(true_plant, seconds=4.0, noise_v=noise_v)
    cmp = compare_records(recs, plant=true_plant, settle_s=0.5)
    f = next(x for x in cmp.fits if x.experiment == "data_uch" and x.output == "Vph")
    y = recs["data_uch"]["Vph"].values[round(0.5 * FS_HZ):]
    expected = 100 * (1 - math.sqrt(noise_v**2 / np.var(y)))
    assert 20 < expected < 95  # the noise is a real share of the output
    # A perfect model leaves the noise alone: ‖n‖/√N is σn within 1/√(2N) ≈ 0.2 % of
    # itself (N = 35 000), and the cross term y·n/N vanishes as fast.
    assert f.fit_percent == pytest.approx(expected, abs=0.5)


@pytest.mark.parametrize(("key", "inp", "out"),
                         [("nominal.newport.gain_rad_per_v.h", "Unh", "Vph"),
                          ("nominal.sercalo.dc_gain_rad_per_a.v", "Ucv", "Vpv")])
def test_the_band_at_dc_is_the_static_gains_std(bench: Bench, nominal_plant: PlantModel,
                                                key: str, inp: str, out: str) -> None:
    from fsmbench.ident.evidence.departures import get_key

    gain = get_key(bench.nominal, key)
    std = 0.02 * abs(gain)
    band = model_band(nominal_plant, params=bench.nominal,
                      measured=[MeasuredKey(key, gain, std, "", "", "")],
                      f_hz=np.array([0.0, 10.0, 1000.0]))
    p = band.path(inp, out)
    h0 = abs(nominal_plant.dc_gain(output=out, input=inp))
    assert p.magnitude_v_per_v[0] == pytest.approx(h0)
    # |H(0)| = K · (the rest): its ±1σ half-width is K's std times the rest, exactly
    # (the response is linear in K, so the central difference is the derivative).
    assert p.magnitude_std_v_per_v[0] == pytest.approx(h0 * std / abs(gain), rel=1e-9)
    assert np.allclose(p.phase_std_deg, 0.0, atol=1e-9)  # a gain moves no phase
    assert band.keys == (key,)


def test_zero_std_gives_a_zero_width_band(bench: Bench, nominal_plant: PlantModel) -> None:
    key = "nominal.sercalo.resonance_hz.h"
    band = model_band(nominal_plant, params=bench.nominal,
                      measured=[MeasuredKey(key, bench.nominal.sercalo.resonance_hz.h, 0.0,
                                            "Hz", "", "")],
                      f_hz=np.geomspace(1.0, 5e3, 50))
    assert band.keys == ()
    for p in band.paths:
        assert np.all(p.magnitude_std_v_per_v == 0.0)
        assert np.all(p.phase_std_deg == 0.0)


def test_the_lifted_simulation_is_dlsims_recursion(true_plant: PlantModel) -> None:
    import scipy.signal as ss

    from fsmbench.ident.compare import lifted_response

    sys = true_plant.to_control(delays="exact", dt=1 / FS_HZ, inputs=["Uch"],
                                outputs=["Vph", "Vch"])
    a, b, c, d = (np.asarray(x, dtype=float) for x in (sys.A, sys.B, sys.C, sys.D))
    u = np.random.default_rng(5).standard_normal(3001)  # not a whole number of blocks
    _, ref, _ = ss.dlsim((a, b, c, d, 1 / FS_HZ), u[:, None])
    got = lifted_response(a, b, c, d, u, block=64)
    # One recursion in another order: rounding only.
    np.testing.assert_allclose(got, ref, atol=1e-12 * np.max(np.abs(ref)))
