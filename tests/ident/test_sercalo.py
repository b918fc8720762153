"""Seed 2.3/2.4 building blocks: weights, resonances, delays, refit with fixed poles."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from fsmbench.ident.delay.bode import DelayEstimate
from fsmbench.ident.fit.weights import detect_resonances, esrf_weights
from fsmbench.ident.frf.experiment import experiment_frf
from fsmbench.ident.frf.response import spectral_matrix
from fsmbench.ident.newport import identify_newport
from fsmbench.ident.sercalo import (
    combined_delay,
    fit_sercalo,
    refit_with_poles,
    relative_fit_error,
)
from fsmbench.signal.welch import hanning
from fsmbench.twin import TwinRun

TRIMS = {"data_uch": 1.0, "data_ucv": 1.0, "data_unh": 3.0, "data_unv": 1.5}


@pytest.fixture(scope="module")
def sercalo_frf(ident_twin: TwinRun):
    return experiment_frf(ident_twin.recordings, columns=[("data_uch", "Uch"),
                                                          ("data_ucv", "Ucv")], trims_s=TRIMS)


def test_seed_weights_follow_the_seed(sercalo_frf) -> None:
    w = esrf_weights(sercalo_frf, resonances_hz={"Uch": 410.0, "Ucv": 250.0})
    f = sercalo_frf.frequency_hz
    coh = sercalo_frf.coherence
    near_h = (f > 369.0) & (f < 451.0)
    assert np.all(w.sel(input="Uch").values[near_h] == 10.0)
    assert np.all(w.values[f > 1000.0] == 0.0) and np.all(w.values[0] == 0.0)
    far = (f > 10) & (f < 200)
    np.testing.assert_array_equal(w.sel(input="Ucv").values[far], coh.sel(input="Ucv").values[far])


def test_resonances_are_found(sercalo_frf) -> None:
    res = detect_resonances(sercalo_frf)
    # Bin spacing 10 kHz / 16384 = 0.61 Hz; the window smears the peak by about a bin.
    assert res["Uch"] == pytest.approx(411.5, abs=1.0)
    assert res["Ucv"] == pytest.approx(251.2, abs=1.0)


@pytest.mark.parametrize(("lines", "expected_hz"), [
    (1, 411.5),     # one line alone is noise: the h peak stands
    (3, 251.2),     # three lines, as wide as a resonance: the largest peak
])
def test_a_peak_one_line_wide_is_not_a_resonance(sercalo_frf, lines: int,
                                                  expected_hz: float) -> None:
    # The closed-loop case (a live record on the twin): the h column's line at the v
    # resonance estimated at 1.3 times the h peak, its neighbours near their true ~2.
    f = sercalo_frf.frequency_hz
    line = int(np.argmin(np.abs(f - 251.2)))
    h = sercalo_frf.frf.values.copy()
    peak = np.max(np.abs(h[(f > 400) & (f < 420), 0, 0]))
    half = lines // 2
    h[line - half: line + half + 1, 0, 0] = 1.3 * peak
    frf = dataclasses.replace(sercalo_frf, frf=sercalo_frf.frf.copy(data=h))
    # One Welch line (0.61 Hz) either way.
    assert detect_resonances(frf)["Uch"] == pytest.approx(expected_hz, abs=1.0)


def test_combined_delay_is_the_inverse_variance_mean() -> None:
    def est(d: float, s: float) -> DelayEstimate:
        return DelayEstimate(delay_s=d, std_s=s, band_hz=(10.0, 100.0), method="x",
                             phase_offset_rad=0.0, gain_sign=1, n_frequencies=10, n_outliers=0,
                             low_frequency_slope=0.0, high_frequency_slope=-2.0,
                             residual_rms_rad=0.0)
    mean, std = combined_delay([est(1.0, 1.0), est(2.0, 2.0)])
    assert mean == pytest.approx((1.0 + 2.0 / 4) / (1 + 1 / 4))
    assert std == pytest.approx(1 / np.sqrt(1.25))


def test_refit_with_exact_poles_recovers_an_exact_model(sercalo_frf) -> None:
    """Noise-free data from a known 2-mode model: fixed true poles give back its residues."""
    sid = fit_sercalo(sercalo_frf, gi_a_per_v={"h": 0.01275, "v": 0.01382})
    f = sercalo_frf.frequency_hz
    truth = dataclasses.replace(sid.fit)
    exact = np.zeros(sid.frf.frf.shape, dtype=complex)
    exact[f > 0] = truth.response(f[f > 0])
    exact[0] = exact[1]
    frf = dataclasses.replace(sid.frf, frf=sid.frf.frf.copy(data=exact))
    synthetic = dataclasses.replace(sid, frf=frf, delay_s=0.0)
    poles = {inp: complex(p) for inp, p in zip(
        ("Ucv", "Uch"), [p for p in truth.poles if p.imag > 0], strict=True)}
    refit = refit_with_poles(synthetic, poles=poles)
    model = refit.fit.response(f[f > 0])
    # Linear least squares on exact data: rounding only.
    np.testing.assert_allclose(model, exact[f > 0], rtol=1e-8, atol=1e-12)


def test_relative_fit_error_of_the_measurement_itself_is_zero(sercalo_frf) -> None:
    err = relative_fit_error(sercalo_frf, sercalo_frf.frf.values)
    assert all(v == 0.0 for v in err.values())


def test_newport_gain_keeps_its_sign(ident_twin: TwinRun) -> None:
    frf = experiment_frf(ident_twin.recordings, columns=[("data_unh", "Unh"),
                                                         ("data_unv", "Unv")], trims_s=TRIMS)
    n = identify_newport(frf)
    # Gd_h < 0 (Table 2) and the Newport turns the beam positively: Unh -> Vph < 0.
    assert n.gain_v_per_v["h"] < 0 < n.gain_v_per_v["v"]
    flipped = dataclasses.replace(frf, frf=-frf.frf)
    m = identify_newport(flipped)
    assert m.gain_v_per_v["h"] == pytest.approx(-n.gain_v_per_v["h"], rel=1e-12)


def test_missing_variable_is_named(ident_twin: TwinRun) -> None:
    recs = dict(ident_twin.recordings)
    recs["data_ucv"] = recs["data_ucv"].drop_vars("Vpv")
    with pytest.raises(ValueError, match="data_ucv: variable 'Vpv'"):
        experiment_frf(recs, columns=[("data_uch", "Uch"), ("data_ucv", "Ucv")], trims_s=TRIMS)
    with pytest.raises(ValueError, match="data_unv is needed"):
        experiment_frf({}, columns=[("data_unv", "Unv")], trims_s=TRIMS)


def test_non_square_matrix_is_refused(ident_twin: TwinRun) -> None:
    ds = ident_twin.recordings["data_uch"]
    one = spectral_matrix(ds["Uch"].values, ds["Vph"].values, input_names=["Uch"],
                          output_names=["Vph"], window=hanning(10000), fs_hz=1e4)
    with pytest.raises(ValueError, match="2x2"):
        fit_sercalo(one, gi_a_per_v={"h": 0.01, "v": 0.01})
