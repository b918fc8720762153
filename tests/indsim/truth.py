"""``truth.json``: what the bench is, in the keys of fsmbench's identification.

The contracted keys (``fs_hz``, ``qd_gain_v_per_rad``, ``current_amp_gain_a_per_v``,
``sercalo.{h,v}.*``, ``newport_gain_v_per_v``, ``newport.{h,v}.*``, ``delay_s``,
``effective_delay_s``) follow the definitions of docs/results.md, computed
from indsim's own model:

* ``qd_gain_v_per_rad``: signed ``g cos θ``, the slope a single-axis calibration
  measures (:func:`indsim.model.qd_gain_calibrated`);
* ``sercalo.<ax>.dc_gain_v_per_a``: static ``Ich -> Vph`` (``Icv -> Vpv``), the
  static ``Uc -> Vp`` of the full model over the current amplifier's static gain;
  ``resonance_hz`` and ``damping_ratio``: the first mode's pole as the records
  show it (``|s| / 2π``, ``-Re s / |s|``; with back-EMF the electromechanical pole);
* ``delay_s``: pure delays, DAC transport + half a sample of hold + the
  target's latency (Sercalo), plus the Newport's internal delay (Newport);
* ``effective_delay_s``: the pure delay plus the low-frequency group delays of
  the lags a delay fit cannot tell from it, the coil's ``L / R_tot`` (mean of
  the axes, Sercalo only) and the 4QD amplifier's (both).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .bench import HV
from .control import REFERENCE_UC_TO_BEAM_RAD_PER_V, close_loop
from .model import BenchModel
from .plant import INPUTS, OUTPUTS

__all__ = ["GN0", "NOMINAL_BENCH_FILE", "bench_file", "truth"]

GN0 = 2.62e-3  # the study's Newport metrology gain [rad/V] (2.1: gn0)


def _hv(pair: HV | tuple[float, float]) -> dict[str, float]:
    h, v = pair
    return {"h": float(h), "v": float(v)}


#: The values of the user's bench file (``default_bench.toml``, ``[nominal]``)
#: for the keys indsim maps to; a test checks this copy against the file.
NOMINAL_BENCH_FILE: dict[str, Any] = {
    "nominal.converter.fs_hz": 10000.0,
    "nominal.converter.range_v": 20.0,
    "nominal.converter.bits": 16,
    "nominal.converter.dac_delay_samples": 1,
    "nominal.sercalo.resonance_hz": {"h": 411.13, "v": 252.5},
    "nominal.sercalo.damping_ratio": {"h": 0.0009141096903985803, "v": 0.0008222735566507275},
    "nominal.sercalo.dc_gain_rad_per_a": {"h": 0.6145525535191302, "v": 0.4958321738620254},
    "nominal.sercalo.r_coil_ohm": {"h": 9.3, "v": 8.3},
    "nominal.sercalo.l_coil_h": {"h": 1.0e-4, "v": 1.0e-4},
    "nominal.sercalo.coupling_h_to_v": 0.0,
    "nominal.sercalo.coupling_v_to_h": 0.0,
    "nominal.sercalo.beam_angle_per_mirror_angle": {"h": -4.0, "v": 4.0},
    "nominal.current_amplifier.r_ohm": {"h": 41.0, "v": 41.0},
    "nominal.current_amplifier.r_buffer_ohm": {"h": 0.0, "v": 0.0},
    "nominal.voltage_amplifier.gain": 1000.0,
    "nominal.voltage_amplifier.cutoff_hz": 1000.0,
    "nominal.voltage_amplifier.noise_rms_v": 1.0e-3,
    "nominal.newport.gain_rad_per_v": {"h": 2.62e-3, "v": 2.62e-3},
    "nominal.newport.metrology_gain_rad_per_v": 2.62e-3,
    "nominal.newport.natural_freq_hz": 1076.706455916,
    "nominal.newport.damping_ratio": 1.106173492,
    "nominal.newport.internal_delay_s": 3.5e-4,
    "nominal.newport.beam_angle_per_mirror_angle": 2.0,
    "nominal.newport.angle_noise_rms_rad": 3.0e-6,
    "nominal.newport.metrology_noise_rms_rad": 0.5e-6,
    "nominal.quad_diode.gain_v_per_rad": {"h": -31.0, "v": 36.3},
    "nominal.quad_diode.rotation_rad": 0.0,
    "nominal.quad_diode.noise_rms_v": {"h": 1.0e-3, "v": 1.0e-3},
    "nominal.attocube.noise_rms_m": 0.5e-9,
    "nominal.attocube.resolution_m": 1.0e-12,
    "nominal.geometry.sercalo_spot_offset_m": 1.0e-4,
    "nominal.geometry.newport_spot_offset_m": 2.0e-4,
    "nominal.geometry.frame_length_m": 0.05,
    "nominal.geometry.frame_expansion_per_k": 23.0e-6,
    "nominal.environment.room_temperature_rms_k": 0.05,
    "nominal.environment.room_temperature_tau_s": 600.0,
    "nominal.environment.room_pressure_rms_pa": 20.0,
    "nominal.environment.room_pressure_tau_s": 600.0,
    "nominal.environment.room_humidity_rms_pct": 1.0,
    "nominal.environment.room_humidity_tau_s": 900.0,
    "nominal.environment.beam_path_temperature_rms_k": 0.005,
    "nominal.environment.beam_path_temperature_tau_s": 1.0,
    "nominal.environment.shielding_attenuation": 5.0,
    "nominal.environment.ecu_temperature_error_k": 0.005,
    "nominal.environment.ecu_pressure_error_pa": 5.0,
    "nominal.environment.ecu_humidity_error_pct": 0.2,
    "nominal.environment.ecu_error_tau_s": 30.0,
    "nominal.environment.frame_time_constant_s": 900.0,
}

SIGN_CARRIERS = (
    "nominal.quad_diode.gain_v_per_rad carries the sign of the calibration (Vnh -> Vph, "
    "Vnv -> Vpv), the Newport's beam_angle_per_mirror_angle being +2 as in the bench "
    "file; nominal.sercalo.beam_angle_per_mirror_angle carries the rest of the sign of "
    "Ich -> Vph (Icv -> Vpv); every other gain is a positive magnitude. Only these "
    "products are observable. quad_diode.rotation_rad is indsim's θ (d_u = cos θ b_x + "
    "sin θ b_y): its sign convention may differ from fsmbench's; the cross slopes are in "
    "cross_coupling_dc_gain."
)


def _first_mode_pole(model: BenchModel, axis: str) -> complex:
    """The continuous pole of the Sercalo's first mode of ``axis`` as the bench has it."""
    lam = np.linalg.eigvals(model.plant.A)
    f0 = getattr(model.bench.sercalo_resonance_hz, axis)
    z0 = getattr(model.bench.sercalo_damping_ratio, axis)
    w0 = 2.0 * math.pi * f0
    target = complex(-z0 * w0, w0 * math.sqrt(1.0 - z0 * z0))
    return complex(lam[np.argmin(np.abs(lam - target))])


def gain_margin(model: BenchModel, high: float = 64.0) -> float:
    """Largest common factor on both controllers that keeps the loop stable (bisection)."""
    b = model.bench
    sp = model.cl_sampled
    mu, gd = model.closed.multiplier, model.closed.gd_v_per_rad

    def stable(f: float) -> bool:
        return close_loop(b, sp, mu.scaled(f), gd).max_pole_abs < 1.0

    if stable(high):
        return high
    lo, hi = 1.0, high
    for _ in range(20):
        mid = math.sqrt(lo * hi)
        lo, hi = (mid, hi) if stable(mid) else (lo, mid)
    return lo


def bench_file(model: BenchModel, signs: dict[str, float]) -> dict[str, Any]:
    """This bench in the keys of the user's bench file, with its departures from it."""
    b = model.bench
    qd_sign = HV(math.copysign(1.0, signs["Vnh_to_Vph"]), math.copysign(1.0, signs["Vnv_to_Vpv"]))
    beam_sign = HV(signs["Ich_to_Vph"] * qd_sign.h, signs["Icv_to_Vpv"] * qd_sign.v)
    poles = {ax: _first_mode_pole(model, ax) for ax in ("h", "v")}
    np_f = b.newport_natural_freq_hz
    np_z = b.newport_damping_ratio
    vals: dict[str, Any] = {
        "nominal.converter.fs_hz": b.fs_hz,
        "nominal.converter.range_v": b.converter_span_v,
        "nominal.converter.bits": b.converter_bits,
        "nominal.converter.dac_delay_samples": b.dac_transport_samples,
        "nominal.sercalo.resonance_hz": {ax: abs(p) / (2 * math.pi) for ax, p in poles.items()},
        "nominal.sercalo.damping_ratio": {ax: -p.real / abs(p) for ax, p in poles.items()},
        "nominal.sercalo.dc_gain_rad_per_a": _hv(b.sercalo_gain_rad_per_a),
        "nominal.sercalo.r_coil_ohm": _hv(b.r_coil_ohm),
        "nominal.sercalo.l_coil_h": _hv(b.l_coil_h),
        "nominal.sercalo.coupling_h_to_v": b.sercalo_torque_crosstalk.h,
        "nominal.sercalo.coupling_v_to_h": b.sercalo_torque_crosstalk.v,
        "nominal.sercalo.beam_angle_per_mirror_angle": _hv(
            beam_sign.scaled(b.sercalo_beam_factor)),
        "nominal.current_amplifier.r_ohm": _hv(b.r_amp_ohm),
        "nominal.current_amplifier.r_buffer_ohm": _hv(b.r_series_ohm),
        "nominal.voltage_amplifier.gain": b.vc_gain,
        "nominal.voltage_amplifier.cutoff_hz": b.vc_cutoff_hz,
        "nominal.voltage_amplifier.noise_rms_v": b.vc_noise_rms_v,
        "nominal.newport.gain_rad_per_v": _hv(b.newport_gain_rad_per_v),
        "nominal.newport.metrology_gain_rad_per_v": b.newport_metrology_rad_per_v,
        # One value for both axes in the bench file: the axes' mean (the pair is kept
        # under "not_expressible").
        "nominal.newport.natural_freq_hz": (np_f.h + np_f.v) / 2.0,
        "nominal.newport.damping_ratio": (np_z.h + np_z.v) / 2.0,
        "nominal.newport.internal_delay_s": b.newport_internal_delay_s,
        "nominal.newport.beam_angle_per_mirror_angle": b.newport_beam_factor,
        "nominal.newport.angle_noise_rms_rad": b.newport_angle_noise_rms_rad,
        "nominal.newport.metrology_noise_rms_rad": b.newport_metrology_noise_rms_rad,
        "nominal.quad_diode.gain_v_per_rad": _hv(HV(qd_sign.h * b.qd_gain_v_per_rad.h,
                                                    qd_sign.v * b.qd_gain_v_per_rad.v)),
        "nominal.quad_diode.rotation_rad": b.qd_rotation_rad,
        "nominal.quad_diode.noise_rms_v": _hv(b.qd_noise_rms_v),
        "nominal.attocube.noise_rms_m": b.va_noise_rms_m,
        "nominal.attocube.resolution_m": b.va_resolution_m,
        "nominal.geometry.sercalo_spot_offset_m": b.sercalo_spot_offset_m,
        "nominal.geometry.newport_spot_offset_m": b.newport_spot_offset_m,
        "nominal.geometry.frame_length_m": b.frame_length_m,
        "nominal.geometry.frame_expansion_per_k": b.frame_expansion_per_k,
    }
    for key in NOMINAL_BENCH_FILE:
        if key.startswith("nominal.environment."):
            vals[key] = getattr(b, key.rsplit(".", 1)[1])
    real = {
        "true.converter.dac_extra_delay_s": b.dac_latency_s,
        "true.sercalo.mode_shape_angle_rad": _hv(b.sercalo_mode_angle_rad),
        "true.sercalo.second_mode_hz": _hv(b.sercalo_second_mode_hz),
        "true.sercalo.second_mode_damping_ratio": _hv(b.sercalo_second_mode_damping_ratio),
        "true.sercalo.second_mode_relative_gain": _hv(b.sercalo_second_mode_relative_gain),
        "true.sercalo.second_mode_shape_angle_rad": _hv(b.sercalo_second_mode_angle_rad),
        "true.quad_diode.bandwidth_hz": b.qd_amp_bandwidth_hz if b.qd_amp_order else 0.0,
        "true.quad_diode.bandwidth_order": b.qd_amp_order,
        "true.quad_diode.flicker_asd_v_per_rthz": _hv(b.qd_flicker_asd_v_per_rthz),
        "true.quad_diode.flicker_min_hz": b.qd_flicker_min_hz,
        "true.quad_diode.nonlinearity_pct": 100.0 * b.qd_compression,
        "true.quad_diode.nonlinearity_full_swing_rad": b.qd_compression_swing_rad,
    }
    departures = [k for k, v in vals.items() if not _same(v, NOMINAL_BENCH_FILE[k])]
    return {
        "values": vals,
        "sign_carriers": SIGN_CARRIERS,
        "departures": departures,
        "real_bench_keys": real,
        "not_expressible": {k: _hv(v) for k, v in (
            ("nominal.newport.natural_freq_hz", np_f), ("nominal.newport.damping_ratio", np_z))
            if v.h != v.v},
        "not_in_bench_file": {
            "back_emf_v_s_per_rad": _hv(b.back_emf_v_s_per_rad),
            "qd_amp_damping_ratio": b.qd_amp_damping_ratio if b.qd_amp_order == 2 else None,
            "qd_offset_v": _hv(b.qd_offset_v),
        },
        "notes": ("sercalo resonance_hz/damping_ratio are the first modes' poles as the "
                  "records show them (with back-EMF: the electromechanical poles); "
                  "coupling_h_to_v is the fraction of coil h's torque about the v hinge "
                  "(static Ich -> phi_b = coupling x dc_gain_rad_per_a.v)."),
    }


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, dict) or isinstance(b, dict):
        ad = a if isinstance(a, dict) else {"h": a, "v": a}
        bd = b if isinstance(b, dict) else {"h": b, "v": b}
        return all(_same(ad[k], bd[k]) for k in ("h", "v"))
    return math.isclose(float(a), float(b), rel_tol=1e-9, abs_tol=1e-15)


def truth(model: BenchModel) -> dict[str, Any]:
    """The truth of ``model``'s bench (without the per-record parts)."""
    b = model.bench
    G = model.plant.dc_gain()
    gi = b.current_amp_gain_a_per_v
    o, i = OUTPUTS.index, INPUTS.index

    def static(inp: str, out: str) -> float:
        return float(G[o(out), i(inp)])

    gd = model.gd_v_per_rad
    dc = HV(static("Uch", "Vph") / gi.h, static("Ucv", "Vpv") / gi.v)
    newport_gain = HV(static("Unh", "Vph"), static("Unv", "Vpv"))
    # Calibration (study 2.1): Vph against x = 2 gn0 Vnh, Vnh = psi / metrology gain.
    x_per_v = HV(*(2.0 * GN0 * static(u, p) / b.newport_metrology_rad_per_v
                   for u, p in (("Unh", "psi_a"), ("Unv", "psi_b"))))
    cal = HV(static("Unh", "Vph") / x_per_v.h, static("Unv", "Vpv") / x_per_v.v)
    signs = {
        "Ich_to_Vph": math.copysign(1.0, dc.h), "Icv_to_Vpv": math.copysign(1.0, dc.v),
        "Unh_to_Vph": math.copysign(1.0, newport_gain.h),
        "Unv_to_Vpv": math.copysign(1.0, newport_gain.v),
        "Vnh_to_Vph": math.copysign(1.0, cal.h), "Vnv_to_Vpv": math.copysign(1.0, cal.v),
        "Uch_to_Vch": math.copysign(1.0, static("Uch", "Vch")),
        "Ucv_to_Vcv": math.copysign(1.0, static("Ucv", "Vcv")),
    }
    T = b.dt_s
    pure_s = b.dac_transport_samples * T + T / 2.0 + b.dac_latency_s
    pure_n = pure_s + b.newport_internal_delay_s
    coil = [ind / r for ind, r in zip(b.l_coil_h, b.r_total_ohm, strict=True)]
    qd_lag = b.qd_amp_group_delay_s
    sercalo = {}
    for ax in ("h", "v"):
        p = _first_mode_pole(model, ax)
        sercalo[ax] = {"resonance_hz": abs(p) / (2 * math.pi), "damping_ratio": -p.real / abs(p),
                       "dc_gain_v_per_a": getattr(dc, ax)}
    mu = model.closed.multiplier
    bench_gain = HV(static("Uch", "Vph") / gd.h, static("Ucv", "Vpv") / gd.v)
    return {
        "fs_hz": b.fs_hz,
        "qd_gain_v_per_rad": _hv(gd),
        "qd_diode_gain_v_per_rad": _hv(HV(b.qd_polarity.h * b.qd_gain_v_per_rad.h,
                                          b.qd_polarity.v * b.qd_gain_v_per_rad.v)),
        "current_amp_gain_a_per_v": _hv(gi),
        "sercalo": sercalo,
        "newport_gain_v_per_v": _hv(newport_gain),
        "newport": {ax: {"natural_freq_hz": getattr(b.newport_natural_freq_hz, ax),
                         "damping_ratio": getattr(b.newport_damping_ratio, ax),
                         "internal_delay_s": b.newport_internal_delay_s} for ax in ("h", "v")},
        "delay_s": {"sercalo": pure_s, "newport": pure_n},
        "effective_delay_s": {"sercalo": pure_s + float(np.mean(coil)) + qd_lag,
                              "newport": pure_n + qd_lag},
        "delay_components_s": {"dac_transport": b.dac_transport_samples * T,
                               "zero_order_hold": T / 2.0, "dac_latency": b.dac_latency_s,
                               "newport_internal": b.newport_internal_delay_s,
                               "coil_lag": _hv(coil), "qd_amplifier": qd_lag},
        "cross_coupling_dc_gain": {
            "Ich_to_Vpv_v_per_a": static("Uch", "Vpv") / gi.h,
            "Icv_to_Vph_v_per_a": static("Ucv", "Vph") / gi.v,
            "Unh_to_Vpv_v_per_v": static("Unh", "Vpv"),
            "Unv_to_Vph_v_per_v": static("Unv", "Vph"),
        },
        "vc_gain_v_per_v": {"h": static("Uch", "Vch"), "v": static("Ucv", "Vcv")},
        "calibration_slope_v_per_rad": _hv(cal),
        "observable_signs": signs,
        "controller": {
            "name": "ESRF study 9.2 diagonal controller Kh, Kv",
            "input": "R = Vp / gd_used_v_per_rad (beam angle, rad)",
            "output": "Uch, Ucv (V)",
            "loop": "closed with -K: Uc = -multiplier * K(R)",
            "discretisation": "Tustin (bilinear, no prewarping) at fs_hz",
            "fs_hz": b.fs_hz,
            "multiplier": _hv(mu),
            "gd_used_v_per_rad": _hv(gd),
            "reference_uc_to_beam_rad_per_v": _hv(REFERENCE_UC_TO_BEAM_RAD_PER_V),
            "bench_uc_to_beam_rad_per_v": _hv(bench_gain),
            "max_pole_abs": model.closed.max_pole_abs,
            "gain_margin_factor": gain_margin(model),
            "records": ["data_huddle_test_3", "data_huddle_test_5", "data_rep_h", "data_rep_v"],
            "quantisation": ("in the loop: additive uniform noise of one step on the ADC "
                             "reading and the DAC command; records rounded to the grid"),
        },
        "qd_amplifier": {"order": b.qd_amp_order,
                         "bandwidth_hz": b.qd_amp_bandwidth_hz if b.qd_amp_order else None,
                         "damping_ratio": b.qd_amp_damping_ratio if b.qd_amp_order == 2 else None,
                         "group_delay_s": qd_lag},
        "noise_rms": {
            "qd_noise_v": _hv(b.qd_noise_rms_v),
            "qd_flicker_asd_v_per_rthz": _hv(b.qd_flicker_asd_v_per_rthz),
            "newport_angle_noise_rad": b.newport_angle_noise_rms_rad,
            "newport_metrology_noise_rad": b.newport_metrology_noise_rms_rad,
            "vc_noise_v": b.vc_noise_rms_v,
            "attocube_noise_m": b.va_noise_rms_m,
            "adc_quantisation_v": b.lsb_v / math.sqrt(12.0),
        },
        "bench_file": (bf := bench_file(model, signs)),
        "departures": bf["departures"],  # the same list, at the top for a quick look
    }


def bench_file_toml(tr: dict[str, Any]) -> str:
    """The bench in the user's bench-file format: ``base = "default"`` and its nominal keys.

    Parameters
    ----------
    tr : dict
        A truth (``truth.json``'s content).

    Returns
    -------
    str
        TOML text for ``fsmbench ... --params FILE``: the ``[nominal.*]`` keys
        of ``bench_file.values`` (the real-bench keys are in ``bench_file``).
    """
    sections: dict[str, list[str]] = {}
    for key, value in tr["bench_file"]["values"].items():
        section, name = key.rsplit(".", 1)
        if isinstance(value, dict):
            text = "{ " + ", ".join(f"{k} = {_toml_number(v)}" for k, v in value.items()) + " }"
        else:
            text = _toml_number(value)
        sections.setdefault(section, []).append(f"{name} = {text}")
    lines = [f"# indsim bench {tr['name']!r}: {tr['description']}", 'base = "default"', ""]
    for section, rows in sections.items():
        lines += [f"[{section}]", *rows, ""]
    return "\n".join(lines)


def _toml_number(v: Any) -> str:
    if isinstance(v, int):  # bool too
        return str(int(v))
    return repr(float(v))
