"""``twin_truth.json``: what an identification of the twin's records should find.

The keys are shared with ``identification.json`` so that a result can be
compared with the truth key by key:

``fs_hz``, ``qd_gain_v_per_rad.{h,v}`` (``g cos θ``: the slope a
single-axis calibration measures, θ the 4QD's rotation),
``qd_diode_gain_v_per_rad.{h,v}`` (``g``, along the diode's own axes),
``current_amp_gain_a_per_v.{h,v}``,
``sercalo.{h,v}.{resonance_hz, damping_ratio, dc_gain_v_per_a}`` (Ich → Vph,
Icv → Vpv), ``newport_gain_v_per_v.{h,v}`` (Unh → Vph, Unv → Vpv at low
frequency, signed), ``delay_s.{sercalo, newport}`` (pure: DAC transport, the
hold's half sample, latency; the Newport's lag), ``effective_delay_s.{sercalo,
newport}`` (the pure delay with the group delays of the lags a delay fit
cannot tell from it: the coil's on the Sercalo's path, the mean of the two
axes, and the 4QD amplifier's); then ``noise_rms`` (every
injected noise, stationary values), ``realized`` (the same, measured on each
record; per-axis values as ``{"h", "v"}``), ``cross_coupling_dc_gain``
(``Ich_to_Vpv_v_per_a`` …: input ``_to_`` output) and descriptive extras.
:func:`fsmbench.twin.simulate.write_twin` puts ``format`` and ``format_version``
(:data:`TRUTH_FORMAT`) first.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from fsmbench.bench.blocks import input_delays_s, physical_plant
from fsmbench.bench.params import Bench, BenchParams
from fsmbench.ident.delay.sampled import SensorLowpass
from fsmbench.twin.experiments import ExperimentSpec
from fsmbench.version import __version__

__all__ = ["TRUTH_FORMAT", "model_values", "twin_truth"]

#: ``twin_truth.json``'s format and version (2: ``cross_coupling_dc_gain`` keys
#: ``<input>_to_<output>_<unit>`` instead of ``<input>-><output>_<unit>``; ``realized``
#: per-axis values as ``{"h", "v"}`` instead of flat ``"<name>.h"`` keys; 3: the
#: identification's definitions: ``qd_gain_v_per_rad`` is ``g cos θ``,
#: ``qd_diode_gain_v_per_rad`` and ``effective_delay_s`` added).
TRUTH_FORMAT = ("fsmbench.twin_truth", 3)


def _nest_axes(values: Mapping[str, float]) -> dict[str, Any]:
    """``{"x.h": a, "x.v": b, "y": c}`` → ``{"x": {"h": a, "v": b}, "y": c}``."""
    out: dict[str, Any] = {}
    for key, value in values.items():
        stem, dot, axis = key.rpartition(".")
        if dot and axis in ("h", "v"):
            out.setdefault(stem, {})[axis] = value
        else:
            out[key] = value
    return out


def _dc(sys: Any, out: int, inp: int) -> float:
    return float(np.real(sys.dcgain()[out, inp]))


def model_values(p: BenchParams) -> dict[str, Any]:
    """The contracted keys computed from one parameter set (nominal or true).

    ``fs_hz``, ``qd_gain_v_per_rad`` (``g cos θ``), ``qd_diode_gain_v_per_rad``
    (``g``), ``current_amp_gain_a_per_v``,
    ``sercalo.{h,v}.{resonance_hz, damping_ratio, dc_gain_v_per_a}``,
    ``newport_gain_v_per_v``, ``newport.{h,v}.{natural_freq_hz, damping_ratio,
    internal_delay_s}``, ``delay_s``, ``effective_delay_s`` — what an
    identification reports (the module notes give the definitions).
    """
    plant = physical_plant(p, source="physical")
    gc, gn = plant.blocks["Gc"], plant.blocks["Gn"]
    gi = p.current_amp_gain_a_per_v()
    delays = input_delays_s(p)
    cos = float(np.cos(p.quad_diode.rotation_rad))
    # The lags a delay fit reads as delay: the coil's (L / (R + R_buffer + Rc), the mean of
    # the two axes: the identification's is the two axes' mean) and the 4QD amplifier's.
    coil = 0.5 * (p.sercalo.l_coil_h.h * gi.h + p.sercalo.l_coil_h.v * gi.v)
    sensor = SensorLowpass(bandwidth_hz=float(p.quad_diode.bandwidth_hz),
                           order=int(p.quad_diode.bandwidth_order)).group_delay_s
    return {
        "fs_hz": p.converter.fs_hz,
        "qd_gain_v_per_rad": {"h": p.quad_diode.gain_v_per_rad.h * cos,
                              "v": p.quad_diode.gain_v_per_rad.v * cos},
        "qd_diode_gain_v_per_rad": {"h": p.quad_diode.gain_v_per_rad.h,
                                    "v": p.quad_diode.gain_v_per_rad.v},
        "current_amp_gain_a_per_v": {"h": gi.h, "v": gi.v},
        "sercalo": {
            axis: {"resonance_hz": p.sercalo.resonance_hz[axis],
                   "damping_ratio": p.sercalo.damping_ratio[axis],
                   "dc_gain_v_per_a": _dc(gc, i, i)}
            for i, axis in enumerate(("h", "v"))
        },
        "newport_gain_v_per_v": {"h": _dc(gn, 0, 0), "v": _dc(gn, 1, 1)},
        # The same second order on both axes (docs/model.md, eq. N2).
        "newport": {axis: {"natural_freq_hz": p.newport.natural_freq_hz,
                           "damping_ratio": p.newport.damping_ratio,
                           "internal_delay_s": p.newport.internal_delay_s} for axis in "hv"},
        "delay_s": {"sercalo": delays["Uch"], "newport": delays["Unh"]},
        "effective_delay_s": {"sercalo": delays["Uch"] + coil + sensor,
                              "newport": delays["Unh"] + sensor},
    }


def _noise_rms(p: BenchParams) -> dict[str, Any]:
    """The twin's noise levels (SI: V, rad, m, K, Pa, %)."""
    lsb = p.converter.lsb_v
    env = p.environment
    return {
        "qd_noise_v": {"h": p.quad_diode.noise_rms_v.h, "v": p.quad_diode.noise_rms_v.v},
        "newport_angle_noise_rad": p.newport.angle_noise_rms_rad,
        "newport_metrology_noise_rad": p.newport.metrology_noise_rms_rad,
        "vc_noise_v": p.voltage_amplifier.noise_rms_v,
        "attocube_noise_m": p.attocube.noise_rms_m,
        "adc_quantisation_v": lsb / np.sqrt(12.0),
        "dac_quantisation_v": lsb / np.sqrt(12.0),
        "room_temperature_k": env.room_temperature_rms_k,
        "room_pressure_pa": env.room_pressure_rms_pa,
        "room_humidity_pct": env.room_humidity_rms_pct,
        "beam_path_temperature_k": env.beam_path_temperature_rms_k,
        "ecu_temperature_error_k": env.ecu_temperature_error_k,
        "ecu_pressure_error_pa": env.ecu_pressure_error_pa,
        "ecu_humidity_error_pct": env.ecu_humidity_error_pct,
    }


def _real_bench(p: BenchParams) -> dict[str, Any]:
    """What a real bench adds to the twin (the bench file's ``[true]``)."""
    return {
        "sercalo": {axis: {"mode_shape_angle_rad": p.sercalo.mode_shape_angle_rad[axis],
                           "second_mode_hz": p.sercalo.second_mode_hz[axis],
                           "second_mode_damping_ratio":
                               p.sercalo.second_mode_damping_ratio[axis],
                           "second_mode_relative_gain":
                               p.sercalo.second_mode_relative_gain[axis],
                           "second_mode_shape_angle_rad":
                               p.sercalo.second_mode_shape_angle_rad[axis]}
                    for axis in "hv"},
        "quad_diode": {
            "bandwidth_hz": p.quad_diode.bandwidth_hz,
            "bandwidth_order": p.quad_diode.bandwidth_order,
            "flicker_asd_v_per_rthz": {a: p.quad_diode.flicker_asd_v_per_rthz[a]
                                       for a in "hv"},
            "mains_freq_hz": p.quad_diode.mains_freq_hz,
            "mains_amplitude_v": list(p.quad_diode.mains_amplitude_v),
            "offset_drift_v_per_s": {a: p.quad_diode.offset_drift_v_per_s[a] for a in "hv"},
            "offset_random_walk_v_per_rts": {a: p.quad_diode.offset_random_walk_v_per_rts[a]
                                             for a in "hv"},
            "nonlinearity_pct": p.quad_diode.nonlinearity_pct,
            "nonlinearity_full_swing_rad": p.quad_diode.nonlinearity_full_swing_rad,
        },
    }


def twin_truth(bench: Bench, *, seed: int, experiments: Sequence[ExperimentSpec],
               realized: Mapping[str, Mapping[str, float]],
               controller_name: str | None) -> dict[str, Any]:
    """The truth of a twin run as a JSON-ready dict (SI units, Hz).

    For an identified bench (``bench.model``) the contracted values are the
    identification's (what the simulated bench *is*), the cross-coupling comes
    from the identified plant, and ``bench`` says where each part came from.
    """
    p = bench.true
    if bench.model is None:
        plant = physical_plant(p, source="physical (true)")
        values = model_values(p)
    else:
        plant = bench.model.plant
        values = {"fs_hz": p.converter.fs_hz, **dict(bench.model.values)}
    gc, gn = plant.blocks["Gc"], plant.blocks["Gn"]
    return {
        **values,
        "bench": {"kind": "identified" if bench.is_identified else "packaged",
                  "label": bench.label, "origin": bench.origin,
                  # Parts are named in words: a list, not keys.
                  "provenance": [] if bench.model is None else [
                      {"part": part, "source": source}
                      for part, source in bench.model.provenance.items()]},
        "noise_rms": _noise_rms(p),
        "realized": {name: _nest_axes(values) for name, values in realized.items()},
        "cross_coupling_dc_gain": {
            "Ich_to_Vpv_v_per_a": _dc(gc, 1, 0), "Icv_to_Vph_v_per_a": _dc(gc, 0, 1),
            "Unh_to_Vpv_v_per_v": _dc(gn, 1, 0), "Unv_to_Vph_v_per_v": _dc(gn, 0, 1),
        },
        "delay_components_s": {
            "dac_transport": p.converter.dac_delay_samples * p.converter.ts_s,
            "zero_order_hold": 0.5 * p.converter.ts_s,
            "newport_internal": p.newport.internal_delay_s,
            "dac_extra": p.converter.dac_extra_delay_s,
        },
        # What a real bench adds (bench TOML [true]; zeros: the feature is off).
        "real_bench": _real_bench(p),
        "experiments": {s.name: {k: v for k, v in dataclasses.asdict(s).items() if k != "name"}
                        for s in experiments},
        "seed": seed,
        "controller": controller_name,
        "fsmbench_version": __version__,
    }
