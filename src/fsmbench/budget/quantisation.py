"""Noise sources of the feedback loop (ESRF study 1.6, 4.5a–c) as closed forms.

ADC/DAC quantisation (eqs. 12–15)
    ``Γ = q²/(12 fs)`` with ``q = ΔV/2ⁿ`` [V²/Hz], a *two-sided* density (the
    seed integrates it over ``±fs/2``); one-sided ``2Γ``. With 20 V, 16 bit,
    10 kHz: ``q = 305.2 µV``, ``Γ = 7.76·10⁻¹³ V²/Hz`` (the ESRF study names fs
    ``f_N``, erratum E9), rms ``q/√12 = 88.1 µV``.
Newport angle from its DAC (4.5a)
    ``Γθn = gn0²·Γ = 5.33·10⁻¹⁸ rad²/Hz`` (the ESRF study prints 3.96·10⁻¹⁸, E10);
    over ``±fs/2``: ``gn0·q/√12 = 0.231 µrad`` rms.
Newport angle noise (4.5a, "Important 8")
    datasheet noise-equivalent angle 3 µrad rms, 6 µrad of beam angle (one
    reflection); white over ``±fs/2``: ``Γd = (6 µrad)²/fs = 3.6·10⁻¹⁵ rad²/Hz``.
4QD noise (4.5b)
    the ESRF study's estimate ``δθ = G·δVi/ΣV`` and our reading through Table 2
    (``δθ = δV/|Gd|``), see :class:`NoiseSources`.
Sercalo DAC (4.5c)
    one LSB through the static plant gain, and the ESRF study's procedure (white DAC
    ASD through ``|G(1,1)|`` over 10 Hz–1 kHz, then its linear law
    ``δL = 10⁻⁶·δθ``) repeated on the given plant.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np
from scipy.integrate import cumulative_trapezoid

from fsmbench.bench.blocks import PlantModel, physical_plant
from fsmbench.bench.params import BenchParams
from fsmbench.jsonutil import hv

__all__ = ["SEED_4_5", "NoiseSources", "noise_sources"]

#: The numbers the seed prints in 1.6 and 4.5 (SI units), to be compared with ours.
SEED_4_5: dict[str, float] = {
    "lsb_v": 305e-6,
    "quantisation_psd_v2_per_hz": 7.76e-13,
    "newport_dac_angle_psd_rad2_per_hz": 3.96e-18,
    "newport_dac_angle_rms_rad": 0.2e-6,
    "newport_beam_angle_rms_rad": 6e-6,
    "newport_beam_angle_psd_rad2_per_hz": 3.6e-15,
    "newport_rotation_beam_factor": 1.6,
    "qd_angle_rad": 1.5e-6,
    "qd_distance_m": 1.5e-9,
    "qd_lsb_distance_m": 0.5e-9,
    "sercalo_dac_distance_rms_m": 1.647e-11,
    "sercalo_dac_lsb_beam_angle_rad": 1.0653e-5,
    "sercalo_dac_lsb_distance_m": 1.0653e-11,
}

# The seed's 4.5b assumptions: quadrant voltage ~5 V (sum 20 V), 1 mV error, G = 0.03 rad.
_SEED_QD_SUM_V, _SEED_QD_DV, _SEED_QD_G_RAD = 20.0, 1e-3, 0.03
# The seed's linear law of 4.5b-c: δL = 1e-6 [m/rad] · δθ.
_SEED_LINEAR_M_PER_RAD = 1e-6


@dataclass(frozen=True)
class NoiseSources:
    """The loop's noise sources, closed forms, SI units (key names carry them).

    ``*_psd_*`` without ``one_sided`` are the ESRF study's two-sided densities;
    ``qd_angle_per_volt_rad_per_v`` is ``1/|Gd|`` per axis (h, v).
    """

    fs_hz: float
    range_v: float
    bits: int
    lsb_v: float
    quantisation_rms_v: float
    adc_psd_v2_per_hz: float
    dac_psd_v2_per_hz: float
    adc_psd_one_sided_v2_per_hz: float
    newport_gain_rad_per_v: float
    newport_dac_angle_psd_rad2_per_hz: float
    newport_dac_angle_rms_rad: float
    newport_angle_noise_rms_rad: float
    newport_beam_factor: float
    newport_beam_angle_rms_rad: float
    newport_beam_angle_psd_rad2_per_hz: float
    newport_rotation_beam_factor: float
    qd_gain_v_per_rad: tuple[float, float]
    qd_angle_per_volt_rad_per_v: tuple[float, float]
    qd_noise_v: tuple[float, float]
    qd_noise_angle_rad: tuple[float, float]
    qd_lsb_angle_rad: tuple[float, float]
    seed_qd_angle_rad: float
    seed_qd_lsb_angle_rad: float
    sercalo_dc_gain_rad_per_v: tuple[float, float]
    sercalo_dac_lsb_beam_angle_rad: float
    seed_sercalo_dac_lsb_beam_angle_rad: float
    seed_method_sercalo_dac_distance_rms_m: float

    def to_json(self) -> dict[str, object]:
        """Plain floats, (h, v) pairs as ``{"h", "v"}``; ``seed``: the study's printed numbers."""
        out: dict[str, object] = {}
        for f in fields(self):
            v = getattr(self, f.name)
            out[f.name] = hv(v) if isinstance(v, tuple) else v  # every tuple field is (h, v)
        out["seed"] = dict(SEED_4_5)
        return out


def _esrf_dac_procedure(plant: PlantModel, *, lsb_v: float, fs_hz: float) -> float:
    """ESRF study 4.5c on ``plant``: white DAC ASD × |Rh/Uch|, 10 Hz–1 kHz, × 1e-6 m/rad."""
    freqs = np.logspace(1.0, 3.0, 1000)
    g11 = plant.frequency_response(freqs, outputs=["Rh"], inputs=["Uch"], with_delay=False)
    asd_uc = lsb_v / math.sqrt(12.0 * fs_hz)
    asd_l = _SEED_LINEAR_M_PER_RAD * asd_uc * np.abs(np.asarray(g11.values[:, 0, 0]))
    cps = cumulative_trapezoid(asd_l**2, 2.0 * np.pi * freqs, initial=0.0) / np.pi
    return float(math.sqrt(cps[-1]))


def noise_sources(params: BenchParams, *, plant: PlantModel | None = None,
                  qd_noise_v: tuple[float, float] | None = None) -> NoiseSources:
    """Closed-form noise levels of ESRF study 1.6 and 4.5a–c for one parameter set.

    Parameters
    ----------
    params : BenchParams
        Usually ``bench.nominal``: converter, Newport gain and angle noise,
        4QD gains, Sercalo beam factor, geometry (H, concave radius).
    plant : PlantModel, optional
        Plant for the static Sercalo gain ``Rh,Rv/Uch,Ucv`` and the ESRF study's
        4.5c procedure; default ``physical_plant(params)``.
    qd_noise_v : (float, float), optional
        4QD output noise rms (h, v) [V], e.g. measured in the huddle tests;
        default ``params.quad_diode.noise_rms_v``.

    Returns
    -------
    NoiseSources
    """
    conv = params.converter
    plant = physical_plant(params) if plant is None else plant
    q = conv.lsb_v
    gamma = q**2 / (12.0 * conv.fs_hz)
    gn = params.newport.metrology_gain_rad_per_v
    nea = params.newport.angle_noise_rms_rad
    beam = params.newport.beam_angle_per_mirror_angle
    radius, h = params.newport.concave_radius_m, params.geometry.h_m
    gd = params.quad_diode.gain_v_per_rad.as_array()
    per_v = 1.0 / np.abs(gd)
    qd_v = (params.quad_diode.noise_rms_v.as_array() if qd_noise_v is None
            else np.asarray(qd_noise_v, dtype=float))
    dc = plant.frequency_response(np.array([0.0]), outputs=["Rh", "Rv"], inputs=["Uch", "Ucv"])
    g_dc = np.abs(np.diagonal(np.asarray(dc.values[0])))
    # The seed's 4.5c: "5 degrees for 10 V" of mirror angle, times 4 for the beam.
    seed_lsb_beam = 4.0 * q * math.radians(5.0) / 10.0

    def pair(a: np.ndarray) -> tuple[float, float]:
        return (float(a[0]), float(a[1]))

    return NoiseSources(
        fs_hz=conv.fs_hz, range_v=conv.range_v, bits=conv.bits, lsb_v=q,
        quantisation_rms_v=q / math.sqrt(12.0),
        adc_psd_v2_per_hz=gamma, dac_psd_v2_per_hz=gamma, adc_psd_one_sided_v2_per_hz=2 * gamma,
        newport_gain_rad_per_v=gn,
        newport_dac_angle_psd_rad2_per_hz=gn**2 * gamma,
        newport_dac_angle_rms_rad=math.sqrt(gn**2 * gamma * conv.fs_hz),
        newport_angle_noise_rms_rad=nea, newport_beam_factor=beam,
        newport_beam_angle_rms_rad=beam * nea,
        newport_beam_angle_psd_rad2_per_hz=(beam * nea) ** 2 / conv.fs_hz,
        newport_rotation_beam_factor=2.0 * radius / (h + radius),
        qd_gain_v_per_rad=pair(gd), qd_angle_per_volt_rad_per_v=pair(per_v),
        qd_noise_v=pair(qd_v), qd_noise_angle_rad=pair(qd_v * per_v),
        qd_lsb_angle_rad=pair(q * per_v),
        seed_qd_angle_rad=_SEED_QD_G_RAD * _SEED_QD_DV / _SEED_QD_SUM_V,
        seed_qd_lsb_angle_rad=_SEED_QD_G_RAD * q / _SEED_QD_SUM_V,
        sercalo_dc_gain_rad_per_v=pair(g_dc),
        sercalo_dac_lsb_beam_angle_rad=float(q * np.max(g_dc)),
        seed_sercalo_dac_lsb_beam_angle_rad=seed_lsb_beam,
        seed_method_sercalo_dac_distance_rms_m=_esrf_dac_procedure(plant, lsb_v=q,
                                                                   fs_hz=conv.fs_hz),
    )
