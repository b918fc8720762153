"""Air index (ESRF study 4.3) and metrology-frame expansion (4.4) as distance errors.

Two views of each:

* the ESRF study's *variations* (ΔT = 1 K, ΔP = 1 hPa, Δ10 %RH without the
  compensation unit; ±0.1 K, ±1 hPa, ±2 %RH with it; eq. (11)) through the
  Ciddor sensitivities of :mod:`fsmbench.bench.air` over the measured
  distance ``D = L + H`` (0.1 m);
* the bench's *model* (``EnvironmentParams``, what the twin simulates): each
  drift a first-order Gauss-Markov process (rms σ, correlation time τ); the
  variance seen in a record of length T with its mean removed is
  ``σ²·w(T/τ)``, ``w(x) = 1 − 2/x + 2(1 − e^{−x})/x²`` (exact for that process).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

from fsmbench.bench.air import AirSensitivity, sensitivities
from fsmbench.bench.params import BenchParams
from fsmbench.budget.spectra import gauss_markov_psd, window_variance

__all__ = [
    "SEED_4_3",
    "SEED_4_4",
    "AirBudget",
    "AirVariation",
    "DriftTerm",
    "FrameBudget",
    "air_budget",
    "air_drift_terms",
    "frame_budget",
    "ou_window_factor",
]

#: Seed 4.3: sensitivities [ppm per unit], its two tables [m] and eq. (11) [m].
SEED_4_3: dict[str, float] = {
    "k_t_ppm_per_k": 1.0, "k_p_ppm_per_hpa": 0.27, "k_rh_ppm_per_pct": 0.01,
    "dt_1k_m": 100e-9, "dp_1hpa_m": 27e-9, "drh_10pct_m": 10e-9,
    "ecu_dt_0p1k_m": 10e-9, "ecu_dp_1hpa_m": 25e-9, "ecu_drh_2pct_m": 2e-9,
    "eq11_m": 54e-9,
}
#: Seed 4.4: aluminium and invar expansion over 5 cm [m/K].
SEED_4_4: dict[str, float] = {"aluminium_m_per_k": 1e-6, "invar_m_per_k": 60e-9,
                              "invar_expansion_per_k": 1.2e-6, "max_dt_k": 0.1}


def ou_window_factor(window_s: float | None, tau_s: float) -> float:
    """Share of a Gauss-Markov variance seen in a mean-removed record of length T [1]."""
    if window_s is None:
        return 1.0
    x = window_s / tau_s
    if x < 1e-4:  # series: x/3 − x²/12 (the closed form cancels catastrophically)
        return x / 3.0 - x * x / 12.0
    return 1.0 - 2.0 / x + 2.0 * (1.0 - math.exp(-x)) / x**2


@dataclass(frozen=True)
class AirVariation:
    """One row of the ESRF study's 4.3 tables: a change, our distance error, the study's [m]."""

    label: str
    delta_t_k: float
    delta_p_pa: float
    delta_rh_pct: float
    error_m: float
    seed_m: float


@dataclass(frozen=True)
class DriftTerm:
    """One drift of the model: distance per unit, rms, correlation time, rms in the window."""

    name: str
    m_per_unit: float
    rms_unit: float
    tau_s: float
    stationary_rms_m: float
    window_rms_m: float


@dataclass(frozen=True)
class AirBudget:
    """ESRF study 4.3 recomputed, and the model's air term for one configuration."""

    path_m: float
    sensitivity: AirSensitivity
    without_compensation: tuple[AirVariation, ...]
    with_compensation: tuple[AirVariation, ...]
    eq11_full_range_rss_m: float
    eq11_half_range_rss_m: float
    compensation_unit: bool
    shielding: bool
    window_s: float | None
    terms: tuple[DriftTerm, ...]
    stationary_rms_m: float
    window_rms_m: float

    def to_json(self) -> dict[str, object]:
        """Plain floats, lists and dicts, SI units."""
        out: dict[str, object] = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name == "sensitivity":
                out[f.name] = v.to_json()
            elif isinstance(v, tuple):
                out[f.name] = [{g.name: getattr(x, g.name) for g in fields(x)} for x in v]
            else:
                out[f.name] = v
        out["seed"] = dict(SEED_4_3)
        return out


def air_drift_terms(params: BenchParams, sens: AirSensitivity, *, compensation_unit: bool,
                    shielding: bool, window_s: float | None) -> tuple[DriftTerm, ...]:
    """The model's air drifts for a configuration (as the twin's ``attocube_distance``)."""
    env, d = params.environment, params.geometry.measured_distance_m
    local = env.beam_path_temperature_rms_k / (env.shielding_attenuation if shielding else 1.0)
    spec = [("beam-path temperature", d * sens.dn_dt_per_k, local,
             env.beam_path_temperature_tau_s)]
    if compensation_unit:
        spec += [("ECU temperature error", d * sens.dn_dt_per_k, env.ecu_temperature_error_k,
                  env.ecu_error_tau_s),
                 ("ECU pressure error", d * sens.dn_dp_per_pa, env.ecu_pressure_error_pa,
                  env.ecu_error_tau_s),
                 ("ECU humidity error", d * sens.dn_drh_per_pct, env.ecu_humidity_error_pct,
                  env.ecu_error_tau_s)]
    else:
        spec += [("room temperature", d * sens.dn_dt_per_k, env.room_temperature_rms_k,
                  env.room_temperature_tau_s),
                 ("room pressure", d * sens.dn_dp_per_pa, env.room_pressure_rms_pa,
                  env.room_pressure_tau_s),
                 ("room humidity", d * sens.dn_drh_per_pct, env.room_humidity_rms_pct,
                  env.room_humidity_tau_s)]
    return tuple(DriftTerm(name, abs(a), rms, tau, abs(a) * rms,
                           abs(a) * rms * math.sqrt(ou_window_factor(window_s, tau)))
                 for name, a, rms, tau in spec)


def air_budget(params: BenchParams, *, compensation_unit: bool = True, shielding: bool = True,
               window_s: float | None = 100.0) -> AirBudget:
    """ESRF study 4.3 with Ciddor sensitivities, and the model's air term.

    Parameters
    ----------
    params : BenchParams
        Environment (reference conditions, drifts), Attocube wavelength, geometry.
    compensation_unit, shielding : bool
        Configuration (ESRF study Table 3) of the model term.
    window_s : float or None
        Record length T [s] over which the mean is removed; None: stationary.
    """
    env = params.environment
    sens = sensitivities(temperature_c=env.reference_temperature_c,
                         pressure_pa=env.reference_pressure_pa,
                         humidity_pct=env.reference_humidity_pct,
                         wavelength_m=params.attocube.wavelength_m)
    d = params.geometry.measured_distance_m
    s = SEED_4_3

    def row(label: str, dt: float, dp: float, drh: float, seed: float) -> AirVariation:
        err = sens.distance_error_m(path_m=d, delta_t_k=dt, delta_p_pa=dp, delta_rh_pct=drh)
        return AirVariation(label, dt, dp, drh, err, seed)

    without = (row("ΔT = 1 K", 1.0, 0.0, 0.0, s["dt_1k_m"]),
               row("ΔP = 1 hPa", 0.0, 100.0, 0.0, s["dp_1hpa_m"]),
               row("ΔRH = 10 %", 0.0, 0.0, 10.0, s["drh_10pct_m"]))
    with_ecu = (row("ΔT = ±0.1 K", 0.1, 0.0, 0.0, s["ecu_dt_0p1k_m"]),
                row("ΔP = ±1 hPa", 0.0, 100.0, 0.0, s["ecu_dp_1hpa_m"]),
                row("ΔRH = ±2 %", 0.0, 0.0, 2.0, s["ecu_drh_2pct_m"]))
    half = math.sqrt(sum(v.error_m**2 for v in with_ecu))
    terms = air_drift_terms(params, sens, compensation_unit=compensation_unit,
                            shielding=shielding, window_s=window_s)
    return AirBudget(
        path_m=d, sensitivity=sens, without_compensation=without, with_compensation=with_ecu,
        eq11_full_range_rss_m=2.0 * half, eq11_half_range_rss_m=half,
        compensation_unit=compensation_unit, shielding=shielding, window_s=window_s,
        terms=terms, stationary_rms_m=math.sqrt(sum(t.stationary_rms_m**2 for t in terms)),
        window_rms_m=math.sqrt(sum(t.window_rms_m**2 for t in terms)))


@dataclass(frozen=True)
class FrameBudget:
    """ESRF study 4.4 recomputed, and the frame term (room temperature through the frame lag)."""

    frame_length_m: float
    expansion_per_k: float
    aluminium_m_per_k: float
    invar_m_per_k: float
    aluminium_at_max_dt_m: float
    invar_at_max_dt_m: float
    frame_temperature_stationary_rms_k: float
    window_s: float | None
    stationary_rms_m: float
    window_rms_m: float

    def to_json(self) -> dict[str, object]:
        """Plain floats, SI units."""
        out: dict[str, object] = {f.name: getattr(self, f.name) for f in fields(self)}
        out["seed"] = dict(SEED_4_4)
        return out


def frame_budget(params: BenchParams, *, window_s: float | None = 100.0) -> FrameBudget:
    """Frame expansion per kelvin (aluminium, invar) and the model's rms over a record.

    The frame temperature is the room's Gauss-Markov drift (σ, τr) through a
    first-order lag τf: PSD ``S_GM(f)/(1 + (2πfτf)²)``, stationary variance
    ``σ²·τr/(τr + τf)``; the windowed variance is integrated numerically.
    """
    geo, env = params.geometry, params.environment
    length = geo.frame_length_m
    sigma, tau_r = env.room_temperature_rms_k, env.room_temperature_tau_s
    tau_f = env.frame_time_constant_s

    def psd(f: object) -> object:
        lag = 1.0 / (1.0 + (2.0 * math.pi * f * tau_f) ** 2)  # type: ignore[operator]
        return gauss_markov_psd(f, rms=sigma, tau_s=tau_r) * lag  # type: ignore[arg-type]

    f_max = params.converter.fs_hz / 2.0
    var_k = window_variance(psd, window_s=window_s, f_max_hz=f_max)
    per_k = geo.frame_expansion_per_k * length
    invar = SEED_4_4["invar_expansion_per_k"] * length
    stat_k = sigma * math.sqrt(tau_r / (tau_r + tau_f))
    return FrameBudget(
        frame_length_m=length, expansion_per_k=geo.frame_expansion_per_k,
        aluminium_m_per_k=per_k, invar_m_per_k=invar,
        aluminium_at_max_dt_m=per_k * SEED_4_4["max_dt_k"],
        invar_at_max_dt_m=invar * SEED_4_4["max_dt_k"],
        frame_temperature_stationary_rms_k=stat_k, window_s=window_s,
        stationary_rms_m=per_k * stat_k, window_rms_m=per_k * math.sqrt(var_k))
