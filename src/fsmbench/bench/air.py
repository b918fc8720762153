"""Refractive index of air along the Attocube beam (ESRF study 4.3).

The ESRF study quotes rounded sensitivities (1 ppm/K, 0.27 ppm/hPa, 0.01 ppm/%RH).
This module computes the phase refractive index of moist air from standard
models at the interferometer wavelength (1530 nm on this bench, a parameter
here), and its sensitivities at an operating point.

Models (formulas as summarised by the NIST Engineering Metrology Toolbox,
"Refractive Index of Air Calculator", J. A. Stone and J. H. Zimmerman,
Appendix A, and the original papers):

``"ciddor"``
    P. E. Ciddor, Appl. Opt. 35, 1566 (1996): dry-air and water-vapour
    refractivities scaled by densities from the BIPM-91 equation of state.
    Valid 300–1690 nm, −40–100 °C, 80–120 kPa, 0–100 %RH; NIST estimates its
    uncertainty at ~2e-8 (k = 2) for ordinary conditions.
``"edlen"``
    Modified Edlén equation: K. P. Birch and M. J. Downs, Metrologia 30, 155
    (1993) and 31, 315 (1994), with the NIST modification of the water-vapour
    term (factor 292.75/T). Standard air holds 450 µmol/mol CO2; other values
    are scaled with the Bönsch–Potulski CO2 coefficient.
``"bonsch_potulski"``
    G. Bönsch and E. Potulski, Metrologia 35, 133 (1998). Its water-vapour
    term has no temperature factor: fine near 20 °C, but 9e-8 below Ciddor at
    30 °C and 100 %RH.

The Edlén forms are fitted to visible data (NIST quotes 350–650 nm); at
1530 nm they are extrapolations, and agree with Ciddor to ~1e-8 anyway (see
the tests). Saturation vapour pressure: IAPWS (Wagner & Pruß) over water for
t ≥ 0 °C, the IAPWS sublimation formula over ice below (NIST A-I).

The interferometer measures ``n·D`` (D the one-way distance), so a change
``δn`` reads as a distance error ``δn·D``; the ESRF study's "beam path of 100 mm"
is D = L + H.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "AirModel",
    "AirPathBudget",
    "AirSensitivity",
    "air_path_budget",
    "refractive_index",
    "refractivity",
    "saturation_vapor_pressure",
    "sensitivities",
]

FloatArray = NDArray[np.float64]
AirModel = Literal["ciddor", "edlen", "bonsch_potulski"]
_MODELS = ("ciddor", "edlen", "bonsch_potulski")

# IAPWS-IF97 saturation line (Wagner & Pruß), NIST A-I.
_K = (
    1.16705214528e3, -7.24213167032e5, -1.70738469401e1, 1.20208247025e4, -3.23255503223e6,
    1.49151086135e1, -4.82326573616e3, 4.05113405421e5, -2.38555575678e-1, 6.50175348448e2,
)

# Ciddor (1996) constants, as listed by NIST A-III.
_W = (295.235, 2.6422, -0.032380, 0.004028)  # water-vapour dispersion [µm^-2k]
_K0, _K1, _K2, _K3 = 238.0185, 5792105.0, 57.362, 167917.0  # dry-air dispersion [µm^-2]
_A0, _A1, _A2 = 1.58123e-6, -2.9331e-8, 1.1043e-10  # compressibility (BIPM-91)
_B0, _B1, _C0, _C1 = 5.707e-6, -2.051e-8, 1.9898e-4, -2.376e-6
_D, _E = 1.83e-11, -0.765e-8
_P_R1, _T_R1, _Z_A = 101325.0, 288.15, 0.9995922115  # standard dry air
_RHO_VS = 0.00985938  # density of standard water vapour [kg/m^3]
_R_GAS, _M_V = 8.314472, 0.018015  # [J/(mol K)], [kg/mol]
_ENH = (1.00062, 3.14e-8, 5.6e-7)  # enhancement factor f = α + βp + γt²


def _check_inputs(
    temperature_c: ArrayLike, pressure_pa: ArrayLike, humidity_pct: ArrayLike,
    wavelength_m: ArrayLike, co2_ppm: ArrayLike,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    t, p, rh, lam, co2 = (
        np.asarray(a, dtype=float)
        for a in np.broadcast_arrays(
            temperature_c, pressure_pa, humidity_pct, wavelength_m, co2_ppm
        )
    )
    for name, arr in (("temperature_c", t), ("pressure_pa", p), ("humidity_pct", rh),
                      ("wavelength_m", lam), ("co2_ppm", co2)):
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{name} must be finite")
    if np.any(t <= -273.15):
        raise ValueError("temperature_c must be above absolute zero")
    if np.any(p <= 0) or np.any(lam <= 0) or np.any(co2 < 0):
        raise ValueError("pressure_pa and wavelength_m must be positive, co2_ppm non-negative")
    if np.any((rh < 0) | (rh > 100)):
        raise ValueError("humidity_pct must be within 0..100 %RH")
    if np.any((lam < 200e-9) | (lam > 2e-6)):
        # Both dispersion formulas have poles in the UV and no basis past 2 µm.
        raise ValueError("wavelength_m must be within 200 nm..2 µm (a vacuum wavelength in m)")
    return t, p, rh, lam, co2


def saturation_vapor_pressure(temperature_c: ArrayLike) -> FloatArray:
    """Saturation vapour pressure [Pa] over water (t ≥ 0 °C) or ice (t < 0 °C).

    Parameters
    ----------
    temperature_c : array_like, any shape
        Air temperature [°C].

    Returns
    -------
    ndarray, same shape
        IAPWS saturation pressure [Pa] (NIST EMT, Appendix A-I).
    """
    t = np.asarray(temperature_c, dtype=float)
    temp = t + 273.15
    omega = temp + _K[8] / (temp - _K[9])
    a = omega**2 + _K[0] * omega + _K[1]
    b = _K[2] * omega**2 + _K[3] * omega + _K[4]
    c = _K[5] * omega**2 + _K[6] * omega + _K[7]
    water = 1e6 * (2 * c / (-b + np.sqrt(b**2 - 4 * a * c))) ** 4
    theta = temp / 273.16
    ice = 611.657 * np.exp(-13.928169 * (1 - theta**-1.5) + 34.7078238 * (1 - theta**-1.25))
    return np.asarray(np.where(t >= 0.0, water, ice), dtype=float)


def _ciddor(t: FloatArray, p: FloatArray, rh: FloatArray, sigma2: FloatArray,
            co2: FloatArray) -> FloatArray:
    temp = t + 273.15
    f = _ENH[0] + _ENH[1] * p + _ENH[2] * t**2
    xv = rh / 100.0 * f * saturation_vapor_pressure(t) / p  # water-vapour mole fraction
    r_as = 1e-8 * (_K1 / (_K0 - sigma2) + _K3 / (_K2 - sigma2))
    r_vs = 1.022e-8 * (_W[0] + _W[1] * sigma2 + _W[2] * sigma2**2 + _W[3] * sigma2**3)
    r_axs = r_as * (1 + 0.534e-6 * (co2 - 450.0))
    m_a = 0.0289635 + 1.2011e-8 * (co2 - 400.0)  # molar mass of dry air [kg/mol]
    pt = p / temp
    z_m = (1 - pt * (_A0 + _A1 * t + _A2 * t**2 + (_B0 + _B1 * t) * xv + (_C0 + _C1 * t) * xv**2)
           + pt**2 * (_D + _E * xv**2))
    rho_axs = _P_R1 * m_a / (_Z_A * _R_GAS * _T_R1)
    rho_v = xv * p * _M_V / (z_m * _R_GAS * temp)
    rho_a = (1 - xv) * p * m_a / (z_m * _R_GAS * temp)
    return np.asarray(rho_a / rho_axs * r_axs + rho_v / _RHO_VS * r_vs, dtype=float)


def _edlen(t: FloatArray, p: FloatArray, rh: FloatArray, sigma2: FloatArray,
           co2: FloatArray) -> FloatArray:
    r_s = 1e-8 * (8342.54 + 2406147.0 / (130.0 - sigma2) + 15998.0 / (38.9 - sigma2))
    # Birch & Downs standard air has 450 µmol/mol CO2; rescale with Bönsch–Potulski.
    r_s = r_s * (1 + 0.5327e-6 * (co2 - 400.0)) / (1 + 0.5327e-6 * 50.0)
    x = (1 + 1e-8 * (0.601 - 0.00972 * t) * p) / (1 + 0.003661 * t)
    pv = rh / 100.0 * saturation_vapor_pressure(t)
    water = 292.75 / (t + 273.15) * (3.7345 - 0.0401 * sigma2) * 1e-10 * pv
    return np.asarray(p * r_s * x / 96095.43 - water, dtype=float)


def _bonsch_potulski(t: FloatArray, p: FloatArray, rh: FloatArray, sigma2: FloatArray,
                     co2: FloatArray) -> FloatArray:
    r_n = 1e-8 * (8091.37 + 2333983.0 / (130.0 - sigma2) + 15518.0 / (38.9 - sigma2))
    r_x = r_n * (1 + 0.5327 * (co2 * 1e-6 - 0.0004))
    r_tp = p * r_x / 93214.60 * (1 + 1e-8 * (0.5953 - 0.009876 * t) * p) / (1 + 0.0036610 * t)
    pv = rh / 100.0 * saturation_vapor_pressure(t)
    return np.asarray(r_tp - pv * (3.8020 - 0.0384 * sigma2) * 1e-10, dtype=float)


_IMPL = {"ciddor": _ciddor, "edlen": _edlen, "bonsch_potulski": _bonsch_potulski}


def refractivity(
    *,
    temperature_c: ArrayLike,
    pressure_pa: ArrayLike,
    humidity_pct: ArrayLike,
    wavelength_m: ArrayLike,
    co2_ppm: ArrayLike = 450.0,
    model: AirModel = "ciddor",
) -> FloatArray:
    """Refractivity ``n − 1`` of moist air (kept apart from 1 to avoid cancellation).

    Parameters
    ----------
    temperature_c : array_like
        Air temperature [°C].
    pressure_pa : array_like
        Total air pressure [Pa].
    humidity_pct : array_like
        Relative humidity [%RH], 0..100.
    wavelength_m : array_like
        Vacuum wavelength [m] (1530e-9 for the Attocube).
    co2_ppm : array_like
        CO2 mole fraction [µmol/mol].
    model : {"ciddor", "edlen", "bonsch_potulski"}
        Equation to use (see the module docstring).

    Returns
    -------
    ndarray
        ``n − 1`` [1], with the broadcast shape of the inputs.
    """
    if model not in _MODELS:
        raise ValueError(f"model must be one of {_MODELS}, not {model!r}")
    t, p, rh, lam, co2 = _check_inputs(temperature_c, pressure_pa, humidity_pct, wavelength_m,
                                       co2_ppm)
    sigma2 = (1e-6 / lam) ** 2  # wavenumber squared [µm^-2]
    return _IMPL[model](t, p, rh, sigma2, co2)


def refractive_index(
    *,
    temperature_c: ArrayLike,
    pressure_pa: ArrayLike,
    humidity_pct: ArrayLike,
    wavelength_m: ArrayLike,
    co2_ppm: ArrayLike = 450.0,
    model: AirModel = "ciddor",
) -> FloatArray:
    """Phase refractive index ``n`` of moist air; arguments as :func:`refractivity`.

    Returns
    -------
    ndarray
        ``n`` [1], with the broadcast shape of the inputs.
    """
    return 1.0 + refractivity(
        temperature_c=temperature_c, pressure_pa=pressure_pa, humidity_pct=humidity_pct,
        wavelength_m=wavelength_m, co2_ppm=co2_ppm, model=model,
    )


@dataclass(frozen=True)
class AirSensitivity:
    """Refractive index and its partial derivatives at one operating point.

    ``dn_dt_per_k`` is taken at constant *relative* humidity (the inputs of
    :func:`refractive_index`), so it includes the rise of the water-vapour
    pressure with temperature; ``dn_dt_const_pv_per_k`` holds the vapour
    pressure fixed instead (the density effect alone).
    """

    model: AirModel
    temperature_c: float
    pressure_pa: float
    humidity_pct: float
    wavelength_m: float
    co2_ppm: float
    refractive_index: float
    dn_dt_per_k: float
    dn_dp_per_pa: float
    dn_drh_per_pct: float
    dn_dt_const_pv_per_k: float

    @property
    def ppm_per_k(self) -> float:
        """∂n/∂T in ppm/K (ESRF study 4.3: K_T ≈ 1 ppm/K)."""
        return 1e6 * self.dn_dt_per_k

    @property
    def ppm_per_hpa(self) -> float:
        """∂n/∂P in ppm/hPa (ESRF study 4.3: K_P ≈ 0.27 ppm/hPa)."""
        return 1e6 * 100.0 * self.dn_dp_per_pa

    @property
    def ppm_per_pct_rh(self) -> float:
        """∂n/∂RH in ppm/%RH (ESRF study 4.3: K_HR ≈ 0.01 ppm/%RH)."""
        return 1e6 * self.dn_drh_per_pct

    def distance_error_m(self, *, path_m: float, delta_t_k: float = 0.0, delta_p_pa: float = 0.0,
                         delta_rh_pct: float = 0.0) -> float:
        """First-order distance error ``D·δn`` [m] for a one-way distance ``path_m`` [m]."""
        dn = (self.dn_dt_per_k * delta_t_k + self.dn_dp_per_pa * delta_p_pa
              + self.dn_drh_per_pct * delta_rh_pct)
        return float(path_m * dn)

    def to_json(self) -> dict[str, object]:
        """Plain floats, units in the keys."""
        out: dict[str, object] = {k: getattr(self, k) for k in self.__dataclass_fields__}
        out.update(ppm_per_k=self.ppm_per_k, ppm_per_hpa=self.ppm_per_hpa,
                   ppm_per_pct_rh=self.ppm_per_pct_rh)
        return out


# Central-difference steps. Truncation ~ h²·f'''/6 with f varying on scales of
# ~300 K, ~1e5 Pa and (nearly linear) in RH: < 1e-9 relative. Rounding of the
# refractivity (~3e-20) over 2h: < 1e-9 relative for all three.
_STEP_T_K, _STEP_P_PA, _STEP_RH_PCT = 0.01, 1.0, 0.01


def sensitivities(
    *,
    temperature_c: float,
    pressure_pa: float,
    humidity_pct: float,
    wavelength_m: float,
    co2_ppm: float = 450.0,
    model: AirModel = "ciddor",
) -> AirSensitivity:
    """∂n/∂T [1/K], ∂n/∂P [1/Pa] and ∂n/∂RH [1/%RH] at one operating point.

    Central differences of the refractivity ``n − 1`` (no cancellation against
    1); see ``_STEP_*`` for the step sizes and why. Arguments and units as in
    :func:`refractivity`, scalars. At 0 or 100 %RH the humidity difference is
    centred one step inside the range (n is linear in RH to ~1e-4 anyway).
    """
    t0, p0, rh0 = float(temperature_c), float(pressure_pa), float(humidity_pct)

    def n1(t: ArrayLike, p: ArrayLike, rh: ArrayLike) -> FloatArray:
        return refractivity(temperature_c=t, pressure_pa=p, humidity_pct=rh,
                            wavelength_m=wavelength_m, co2_ppm=co2_ppm, model=model)

    def slope(values: FloatArray, step: float) -> float:
        return float((values[1] - values[0]) / (2.0 * step))

    hs = np.array([-1.0, 1.0])
    rh_c = min(max(rh0, _STEP_RH_PCT), 100.0 - _STEP_RH_PCT)  # keep both RH steps in range
    t_pm = t0 + hs * _STEP_T_K
    dn_dt = slope(n1(t_pm, p0, rh0), _STEP_T_K)
    dn_drh = slope(n1(t0, p0, rh_c + hs * _STEP_RH_PCT), _STEP_RH_PCT)
    # Constant vapour pressure: RH falls as psv rises, dRH/dT = −RH·psv'/psv
    # (chain rule, so a saturated point needs no supersaturated step).
    dln_psv = slope(np.log(saturation_vapor_pressure(t_pm)), _STEP_T_K)
    return AirSensitivity(
        model=model, temperature_c=t0, pressure_pa=p0, humidity_pct=rh0,
        wavelength_m=float(wavelength_m), co2_ppm=float(co2_ppm),
        refractive_index=1.0 + float(n1(t0, p0, rh0)),
        dn_dt_per_k=dn_dt,
        dn_dp_per_pa=slope(n1(t0, p0 + hs * _STEP_P_PA, rh0), _STEP_P_PA),
        dn_drh_per_pct=dn_drh,
        dn_dt_const_pv_per_k=dn_dt - dn_drh * rh0 * dln_psv,
    )


@dataclass(frozen=True)
class AirPathBudget:
    """Distance errors for given air-property changes over a one-way distance (ESRF study 4.3)."""

    path_m: float
    delta_t_k: float
    delta_p_pa: float
    delta_rh_pct: float
    error_t_m: float
    error_p_m: float
    error_rh_m: float
    rss_m: float
    exact_m: float

    def to_json(self) -> dict[str, object]:
        """Plain floats, units in the keys."""
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


def air_path_budget(
    sensitivity: AirSensitivity,
    *,
    path_m: float,
    delta_t_k: float = 0.0,
    delta_p_pa: float = 0.0,
    delta_rh_pct: float = 0.0,
) -> AirPathBudget:
    """Per-term distance errors ``D·(∂n/∂x)·δx``, their RSS and the exact joint change.

    Parameters
    ----------
    sensitivity : AirSensitivity
        Operating point and derivatives from :func:`sensitivities`.
    path_m : float
        One-way measured distance D [m] (ESRF study 4.3: 0.1 m).
    delta_t_k, delta_p_pa, delta_rh_pct : float
        Changes of temperature [K], pressure [Pa] and relative humidity [%RH].

    Returns
    -------
    AirPathBudget
        Signed errors [m]; ``rss_m`` combines them as independent; ``exact_m``
        re-evaluates the model at the shifted point (all changes at once).
    """
    s = sensitivity
    e_t = path_m * s.dn_dt_per_k * delta_t_k
    e_p = path_m * s.dn_dp_per_pa * delta_p_pa
    e_rh = path_m * s.dn_drh_per_pct * delta_rh_pct
    shifted = refractivity(
        temperature_c=s.temperature_c + delta_t_k, pressure_pa=s.pressure_pa + delta_p_pa,
        humidity_pct=s.humidity_pct + delta_rh_pct, wavelength_m=s.wavelength_m,
        co2_ppm=s.co2_ppm, model=s.model,
    )
    exact = path_m * (float(shifted) - (s.refractive_index - 1.0))
    return AirPathBudget(
        path_m=float(path_m), delta_t_k=float(delta_t_k), delta_p_pa=float(delta_p_pa),
        delta_rh_pct=float(delta_rh_pct), error_t_m=float(e_t), error_p_m=float(e_p),
        error_rh_m=float(e_rh), rss_m=float(np.sqrt(e_t**2 + e_p**2 + e_rh**2)),
        exact_m=float(exact),
    )
