"""Refractive index of air (ESRF study 4.3): published check values, model agreement, sensitivities.

Reference data used below (the README of each source, in short):

* Ciddor (1996) check values. P. E. Ciddor, "Refractive index of air: new
  equations for the visible and near infrared", Appl. Opt. 35, 1566 (1996),
  Table 1 (dry air) and Table 3 (moist air): (n − 1)·1e8 at 633 nm, 450 µmol/mol
  CO2, printed to 0.1. Transcribed from a public test suite that cites these
  tables (not re-read from the paper here). Its 40 °C / 80 kPa / 75 %RH entry
  is printed 19996.5, a misprint for 19896.5 (the value the NIST calculator
  returns); the corrected value is used.
* IAPWS-IF97 (Wagner et al., IAPWS Industrial Formulation 1997), Table 35,
  verification values of the saturation-pressure equation, 9 significant
  digits: 300 K → 3.53658941e-3 MPa, 500 K → 2.63889776 MPa,
  600 K → 12.3443146 MPa; triple point 611.657 Pa.
* ref_index 1.0 (PyPI, BSD, P. Nair, 2011): an implementation of the NIST
  Engineering Metrology Toolbox procedure ("Refractive Index of Air
  Calculator", Stone & Zimmerman, Appendix A). Its README publishes six
  example values at 633 nm, 101 325 Pa, used here as a cross-implementation
  check; if the package is importable, it is also compared point by point.
  The NIST documentation's own table of example values could not be
  retrieved for this work (only the page's opening is on record).
"""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from fsmbench.bench.air import (
    AirSensitivity,
    air_path_budget,
    refractive_index,
    refractivity,
    saturation_vapor_pressure,
    sensitivities,
)

LAMBDA_ATTOCUBE_M = 1530e-9
SEED_POINT = {"temperature_c": 20.0, "pressure_pa": 101325.0, "humidity_pct": 50.0}

# (t °C, p Pa, RH %, (n − 1)·1e8) — Ciddor (1996) Table 1 (dry) and Table 3 (moist), 633 nm.
CIDDOR_DRY = [
    (20.0, 80e3, 0.0, 21458.0),
    (20.0, 100e3, 0.0, 26824.4),
    (20.0, 120e3, 0.0, 32191.6),
    (10.0, 100e3, 0.0, 27774.7),
    (30.0, 100e3, 0.0, 25937.2),
]
CIDDOR_MOIST = [
    (20.0, 80e3, 75.0, 21394.0),
    (20.0, 120e3, 75.0, 32127.8),
    (40.0, 80e3, 75.0, 19896.5),  # printed 19996.5 (misprint, see module docstring)
    (40.0, 120e3, 75.0, 29941.8),
    (50.0, 80e3, 100.0, 19058.4),
    (50.0, 120e3, 100.0, 28792.4),
]
# ref_index README: (model, t °C, RH %, n) at 633 nm, 101 325 Pa, 450 µmol/mol.
REF_INDEX_README = [
    ("ciddor", 20.0, 20.0, 1.0002716285340578),
    ("edlen", 20.0, 20.0, 1.0002716291691649),
    ("edlen", 20.0, 80.0, 1.0002711197635226),
    ("ciddor", 20.0, 80.0, 1.0002711183472626),
    ("edlen", 60.0, 80.0, 1.0002339748542823),
    ("ciddor", 60.0, 80.0, 1.0002340241754055),
]


# ---------------------------------------------------------------- published check values
@pytest.mark.parametrize(("t", "p", "rh", "published"), CIDDOR_DRY)
def test_ciddor_table_1_dry_air(t, p, rh, published) -> None:
    got = 1e8 * float(refractivity(temperature_c=t, pressure_pa=p, humidity_pct=rh,
                                   wavelength_m=633e-9))
    assert got == pytest.approx(published, abs=0.05)  # half a unit of the printed 0.1


@pytest.mark.parametrize(("t", "p", "rh", "published"), CIDDOR_MOIST)
def test_ciddor_table_3_moist_air(t, p, rh, published) -> None:
    got = 1e8 * float(refractivity(temperature_c=t, pressure_pa=p, humidity_pct=rh,
                                   wavelength_m=633e-9))
    # One unit of the printed 0.1: Ciddor's table used the BIPM saturation-pressure
    # formula (5e-5 off IAPWS at 50 °C) where NIST, and this module, use IAPWS.
    assert got == pytest.approx(published, abs=0.1)


@pytest.mark.parametrize(
    ("temperature_k", "published_pa"),
    [(300.0, 3.53658941e3), (500.0, 2.63889776e6), (600.0, 12.3443146e6), (273.16, 611.657)],
)
def test_saturation_pressure_iapws_verification_values(temperature_k, published_pa) -> None:
    got = float(saturation_vapor_pressure(temperature_k - 273.15))
    assert got == pytest.approx(published_pa, rel=2e-9)  # half a unit of the 9th digit


def test_saturation_pressure_over_ice_meets_water_at_the_triple_point() -> None:
    ice = float(saturation_vapor_pressure(-1e-9))
    water = float(saturation_vapor_pressure(0.0))
    # Both IAPWS curves pass through 611.657 Pa at 273.16 K; 0.01 K below it the
    # two slopes (50 vs 44 Pa/K) separate them by < 0.1 Pa.
    assert abs(ice - water) < 0.1
    assert float(saturation_vapor_pressure(-10.0)) < float(saturation_vapor_pressure(-5.0)) < ice


@pytest.mark.parametrize("t", [-10.0, -20.0, -40.0])
def test_saturation_pressure_over_ice_against_murphy_koop(t) -> None:
    """Below 0 °C the ice curve is used (over supercooled water −10 °C would give ~286 Pa)."""
    temp = t + 273.15
    # Murphy & Koop, Q. J. R. Meteorol. Soc. 131, 1539 (2005), eq. (7): an independent fit.
    mk = math.exp(9.550426 - 5723.265 / temp + 3.53068 * math.log(temp) - 0.00728332 * temp)
    assert float(saturation_vapor_pressure(t)) == pytest.approx(mk, rel=5e-4)  # fits differ ~1e-4


@pytest.mark.parametrize(("model", "t", "rh", "published"), REF_INDEX_README)
def test_matches_ref_index_readme_values(model, t, rh, published) -> None:
    got = float(refractive_index(temperature_c=t, pressure_pa=101325.0, humidity_pct=rh,
                                 wavelength_m=633e-9, model=model))
    assert got == pytest.approx(published, rel=0, abs=1e-15)  # same formulas: a few ulp of 1


@pytest.mark.parametrize("model", ["ciddor", "edlen"])
@pytest.mark.parametrize("lam_nm", [633.0, 1064.0, 1530.0])
@pytest.mark.parametrize(("t", "p", "rh"), [(10.0, 60e3, 0.0), (20.0, 101325.0, 50.0),
                                            (30.0, 110e3, 100.0), (25.0, 90e3, 30.0)])
def test_cross_check_with_ref_index_package(model, lam_nm, t, p, rh) -> None:
    ref_index = pytest.importorskip("ref_index")  # optional peer, not a dependency
    want = getattr(ref_index, model)(wave=lam_nm, t=t, p=p, rh=rh)
    got = float(refractive_index(temperature_c=t, pressure_pa=p, humidity_pct=rh,
                                 wavelength_m=lam_nm * 1e-9, model=model))
    assert got == pytest.approx(want, rel=0, abs=1e-15)  # same formulas: a few ulp of 1


# ---------------------------------------------------------------- models agree
GRID = np.meshgrid(np.linspace(10, 30, 9), np.linspace(60e3, 110e3, 11), np.linspace(0, 100, 11),
                   indexing="ij")


@pytest.mark.parametrize("lam", [633e-9, LAMBDA_ATTOCUBE_M])
def test_ciddor_and_modified_edlen_agree_within_1e_8(lam) -> None:
    """10–30 °C, 60–110 kPa, 0–100 %RH: within the ~1e-8 both are credited with (NIST)."""
    t, p, rh = GRID
    kw = {"temperature_c": t, "pressure_pa": p, "humidity_pct": rh, "wavelength_m": lam}
    diff = refractivity(**kw, model="edlen") - refractivity(**kw)
    assert np.abs(diff).max() < 1e-8  # their stated ~1e-8 uncertainty


def test_bonsch_potulski_agrees_where_it_was_fitted() -> None:
    t, p, rh = GRID
    kw = {"pressure_pa": p, "wavelength_m": LAMBDA_ATTOCUBE_M}
    dry = (refractivity(temperature_c=t, humidity_pct=0 * rh, model="bonsch_potulski", **kw)
           - refractivity(temperature_c=t, humidity_pct=0 * rh, **kw))
    assert np.abs(dry).max() < 1e-8  # dry air: within the stated ~1e-8
    at_20 = (refractivity(temperature_c=20.0, humidity_pct=rh, model="bonsch_potulski", **kw)
             - refractivity(temperature_c=20.0, humidity_pct=rh, **kw))
    # Its water term (3.8020 vs Ciddor's effective ~3.72e-10/Pa) adds ~2e-8 at 20 °C, 100 %RH.
    assert np.abs(at_20).max() < 2.5e-8
    hot = (refractivity(temperature_c=30.0, humidity_pct=100.0, model="bonsch_potulski", **kw)
           - refractivity(temperature_c=30.0, humidity_pct=100.0, **kw))
    assert np.all(hot < -5e-8)  # no 1/T factor in its water term: documented limitation


def test_vectorised_equals_pointwise() -> None:
    t, p, rh = (a[::4, ::5, ::5] for a in GRID)
    grid = refractive_index(temperature_c=t, pressure_pa=p, humidity_pct=rh,
                            wavelength_m=LAMBDA_ATTOCUBE_M)
    assert grid.shape == t.shape
    for idx in np.ndindex(t.shape):
        one = refractive_index(temperature_c=float(t[idx]), pressure_pa=float(p[idx]),
                               humidity_pct=float(rh[idx]), wavelength_m=LAMBDA_ATTOCUBE_M)
        assert float(grid[idx]) == pytest.approx(float(one), rel=0, abs=4e-16)  # SIMD vs scalar


# ---------------------------------------------------------------- sensitivities
def _edlen_analytic(t: float, p: float, rh: float, lam: float) -> dict[str, float]:
    """Exact derivatives of the NIST modified Edlén equation (450 µmol/mol CO2)."""
    s2 = (1e-6 / lam) ** 2
    r_s = 1e-8 * (8342.54 + 2406147.0 / (130 - s2) + 15998.0 / (38.9 - s2))
    e, f, g, d = 0.601, 0.00972, 0.003661, 96095.43
    temp = t + 273.15
    psv = float(saturation_vapor_pressure(t))
    water = (3.7345 - 0.0401 * s2) * 1e-10
    num = 1 + 1e-8 * (e - f * t) * p
    dry_dt = p * r_s / d * ((-1e-8 * f * p) * (1 + g * t) - g * num) / (1 + g * t) ** 2
    return {
        "dp": r_s / (d * (1 + g * t)) * (1 + 2e-8 * (e - f * t) * p),
        "drh": -292.75 / temp * water * psv / 100.0,
        "dt_const_pv": dry_dt + 292.75 / temp**2 * water * rh / 100.0 * psv,
    }


@pytest.mark.parametrize(("t", "p", "rh"), [(20.0, 101325.0, 50.0), (10.0, 60e3, 0.0),
                                            (30.0, 110e3, 100.0)])
@pytest.mark.parametrize("lam", [633e-9, LAMBDA_ATTOCUBE_M])
def test_sensitivities_match_analytic_edlen_derivatives(t, p, rh, lam) -> None:
    sens = sensitivities(temperature_c=t, pressure_pa=p, humidity_pct=rh, wavelength_m=lam,
                         model="edlen")
    want = _edlen_analytic(t, p, rh, lam)
    # n is quadratic in p and linear in RH: central differences exact up to rounding (~1e-10).
    assert sens.dn_dp_per_pa == pytest.approx(want["dp"], rel=1e-8)
    assert sens.dn_drh_per_pct == pytest.approx(want["drh"], rel=1e-8)
    # Temperature: step 0.01 K, truncation (h/T)² ~ 1e-9 plus ln psv'' terms ~ 1e-7.
    assert sens.dn_dt_const_pv_per_k == pytest.approx(want["dt_const_pv"], rel=1e-6)


def test_sensitivities_at_the_seed_operating_point() -> None:
    """Derived at 1530 nm, 20 °C, 101 325 Pa, 50 %RH (Ciddor), with the study's rounded values."""
    sens = sensitivities(**SEED_POINT, wavelength_m=LAMBDA_ATTOCUBE_M)
    edlen = sensitivities(**SEED_POINT, wavelength_m=LAMBDA_ATTOCUBE_M, model="edlen")
    # The two models' derivatives agree: T and P within 0.1 %, RH (water term) within 1 %.
    assert sens.dn_dt_per_k == pytest.approx(edlen.dn_dt_per_k, rel=1e-3)
    assert sens.dn_dp_per_pa == pytest.approx(edlen.dn_dp_per_pa, rel=1e-3)
    assert sens.dn_drh_per_pct == pytest.approx(edlen.dn_drh_per_pct, rel=1e-2)
    # Reported values (3 significant digits):
    assert sens.ppm_per_k == pytest.approx(-0.9445, abs=5e-4)  # at constant RH
    assert 1e6 * sens.dn_dt_const_pv_per_k == pytest.approx(-0.9175, abs=5e-4)
    assert sens.ppm_per_hpa == pytest.approx(0.2652, abs=5e-5)
    assert sens.ppm_per_pct_rh == pytest.approx(-0.00872, abs=5e-6)
    # Seed 4.3 quotes magnitudes to one significant digit (two for pressure):
    assert round(abs(sens.ppm_per_k), 0) == 1.0  # K_T ≈ 1 ppm/K
    assert round(sens.ppm_per_hpa, 2) == 0.27  # K_P ≈ 0.27 ppm/hPa
    assert round(abs(sens.ppm_per_pct_rh), 2) == 0.01  # K_HR ≈ 0.01 ppm/%RH
    # ... but the seed's K_T overstates |∂n/∂T| by 6 % and K_HR |∂n/∂RH| by 15 %.
    assert 1.0 / abs(sens.ppm_per_k) == pytest.approx(1.059, abs=1e-3)  # 3-digit report
    assert 0.01 / abs(sens.ppm_per_pct_rh) == pytest.approx(1.146, abs=1e-3)  # 3-digit report


def test_humidity_sensitivity_depends_on_wavelength() -> None:
    """−0.0085 ppm/%RH is the 633 nm value; the water term shrinks less at 1530 nm."""
    at_633 = sensitivities(**SEED_POINT, wavelength_m=633e-9)
    at_1530 = sensitivities(**SEED_POINT, wavelength_m=LAMBDA_ATTOCUBE_M)
    assert at_633.ppm_per_pct_rh == pytest.approx(-0.00850, abs=5e-6)
    assert at_1530.ppm_per_pct_rh < at_633.ppm_per_pct_rh


# ---------------------------------------------------------------- seed 4.3 tables and eq. (11)
PATH_M = 0.1  # seed 4.3: "a beam path of 100 mm" = L + H, the one-way measured distance


def test_seed_first_table_follows_from_its_rounded_constants_not_from_the_physics() -> None:
    # Seed: ΔT = 1 °C → 100 nm, ΔP = 1 hPa → 27 nm, ΔRH = 10 % → 10 nm.
    seed_k = {"t": 1e-6, "p": 0.27e-6 / 100.0, "rh": 0.01e-6}
    assert PATH_M * seed_k["t"] * 1.0 == pytest.approx(100e-9)  # its own arithmetic holds
    assert PATH_M * seed_k["p"] * 100.0 == pytest.approx(27e-9)
    assert PATH_M * seed_k["rh"] * 10.0 == pytest.approx(10e-9)
    sens = sensitivities(**SEED_POINT, wavelength_m=LAMBDA_ATTOCUBE_M)
    t_row = air_path_budget(sens, path_m=PATH_M, delta_t_k=1.0)
    p_row = air_path_budget(sens, path_m=PATH_M, delta_p_pa=100.0)
    rh_row = air_path_budget(sens, path_m=PATH_M, delta_rh_pct=10.0)
    assert t_row.error_t_m == pytest.approx(-94.45e-9, abs=0.01e-9)  # rounding of the report
    assert p_row.error_p_m == pytest.approx(26.52e-9, abs=0.01e-9)
    assert rh_row.error_rh_m == pytest.approx(-8.72e-9, abs=0.01e-9)
    for row in (t_row, p_row, rh_row):
        # Linearisation vs exact re-evaluation: curvature over 1 K / 1 hPa / 10 %RH < 0.5 %.
        assert row.exact_m == pytest.approx(row.error_t_m + row.error_p_m + row.error_rh_m,
                                            rel=5e-3)


def test_seed_second_table_and_eq_11() -> None:
    # Seed: ±0.1 °C → ±10 nm, ±1 hPa → ±25 nm, ±2 %RH → ±2 nm; eq. (11) √(20²+50²+4²) = 54 nm.
    assert math.sqrt(20**2 + 50**2 + 4**2) == 54.0  # the arithmetic itself is exact
    assert tuple(2 * v for v in (10, 25, 2)) == (20, 50, 4)  # eq. 11 uses the full ± spans
    assert abs(PATH_M * 0.27e-6 * 1.0 - 25e-9) > 1.9e-9  # its own K_P gives 27 nm, not 25
    sens = sensitivities(**SEED_POINT, wavelength_m=LAMBDA_ATTOCUBE_M)
    half = air_path_budget(sens, path_m=PATH_M, delta_t_k=0.1, delta_p_pa=100.0,
                           delta_rh_pct=2.0)
    assert abs(half.error_t_m) == pytest.approx(9.45e-9, abs=0.01e-9)
    assert abs(half.error_p_m) == pytest.approx(26.52e-9, abs=0.01e-9)
    assert abs(half.error_rh_m) == pytest.approx(1.74e-9, abs=0.01e-9)
    assert half.rss_m == pytest.approx(math.hypot(half.error_t_m, half.error_p_m,
                                                  half.error_rh_m), rel=1e-15)
    assert half.rss_m == pytest.approx(28.2e-9, abs=0.05e-9)  # ± half-spans
    span = air_path_budget(sens, path_m=PATH_M, delta_t_k=0.2, delta_p_pa=200.0,
                           delta_rh_pct=4.0)
    assert span.rss_m == pytest.approx(56.4e-9, abs=0.05e-9)  # full spans, as eq. (11) counts


# ---------------------------------------------------------------- API behaviour
def test_result_is_frozen_and_json_plain() -> None:
    sens = sensitivities(**SEED_POINT, wavelength_m=LAMBDA_ATTOCUBE_M)
    assert isinstance(sens, AirSensitivity)
    with pytest.raises(dataclasses.FrozenInstanceError):
        sens.dn_dt_per_k = 0.0  # type: ignore[misc]
    for obj in (sens, air_path_budget(sens, path_m=0.1, delta_t_k=1.0)):
        data = obj.to_json()
        assert json.loads(json.dumps(data)) == data
        assert all(isinstance(v, (float, str)) for v in data.values())


def test_sensitivity_at_saturation_stays_in_range() -> None:
    sens = sensitivities(temperature_c=25.0, pressure_pa=101325.0, humidity_pct=100.0,
                         wavelength_m=LAMBDA_ATTOCUBE_M)
    assert sens.dn_drh_per_pct < 0 < sens.dn_dp_per_pa
    assert sens.dn_dt_per_k < sens.dn_dt_const_pv_per_k < 0  # RH at constant pv drops with T


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"humidity_pct": 120.0}, "humidity_pct"),
        ({"wavelength_m": 1530.0}, "wavelength_m"),  # nm passed by mistake
        ({"pressure_pa": -1.0}, "pressure_pa"),
        ({"temperature_c": float("nan")}, "temperature_c"),
        ({"model": "edlen1966"}, "model"),
    ],
)
def test_bad_inputs_are_rejected(kwargs, match) -> None:
    args = {**SEED_POINT, "wavelength_m": LAMBDA_ATTOCUBE_M, **kwargs}
    with pytest.raises(ValueError, match=match):
        refractive_index(**args)
