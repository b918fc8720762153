"""The twin's plant: the physical blocks with the exact coil circuit, discretised.

Unlike :func:`fsmbench.bench.blocks.physical_plant` (the ESRF study's block
diagram, with a static ``Zc``), the twin computes the coil voltage from the
circuit itself, ``Vt = Rc Ic + Lc dIc/dt = Uc - (R + R_buffer) Ic``, so the
inductance acts where physics puts it.

Outputs of :func:`twin_continuous` (noise-free; the engine adds noise):

- ADC channels, in this order: ``Vch, Vcv, Vph, Vpv, Vnh, Vnv`` [V]
- internal signals: ``theta_ch, theta_cv`` (Sercalo mirror angles),
  ``theta_nh, theta_nv`` (Newport mirror angles), ``Rh, Rv`` (beam angle in
  the 4QD frame) [rad]
"""

from __future__ import annotations

import control as ct
import numpy as np

from fsmbench.bench.blocks import (
    current_amplifier,
    newport_angles,
    newport_beam_matrix,
    quad_diode_lowpass,
    sercalo_angles,
    sercalo_beam_matrix,
    voltage_amplifier,
)
from fsmbench.bench.params import Bench, BenchParams
from fsmbench.sim.discretize import DiscretePlant, zoh_with_delays

__all__ = [
    "ADC_CHANNELS",
    "DAC_CHANNELS",
    "INTERNAL_SIGNALS",
    "bench_discrete",
    "twin_continuous",
    "twin_discrete",
]

DAC_CHANNELS = ("Uch", "Ucv", "Unh", "Unv")
ADC_CHANNELS = ("Vch", "Vcv", "Vph", "Vpv", "Vnh", "Vnv")
INTERNAL_SIGNALS = ("theta_ch", "theta_cv", "theta_nh", "theta_nv", "Rh", "Rv")


def twin_continuous(p: BenchParams) -> ct.StateSpace:
    """Continuous plant of the twin, inputs :data:`DAC_CHANNELS`, outputs ADC + internal."""
    r_ext = p.current_amplifier.r_ohm.as_array() + p.current_amplifier.r_buffer_ohm.as_array()
    sign = np.diag(p.current_amplifier.sign.as_array())
    coil = ct.ss([], [], [], np.hstack([sign, -np.diag(r_ext)]),
                 inputs=["Uch", "Ucv", "Ich", "Icv"], outputs=["Vtch", "Vtcv"], name="coil")
    beam = ct.ss([], [], [], np.hstack([sercalo_beam_matrix(p), newport_beam_matrix(p)]),
                 inputs=["theta_ch", "theta_cv", "theta_nh", "theta_nv"], outputs=["Rh", "Rv"],
                 name="optics")
    lowpass = quad_diode_lowpass(p)
    qd_out = ["Vph", "Vpv"] if lowpass is None else ["Vph_in", "Vpv_in"]
    qd = ct.ss([], [], [], np.diag(p.quad_diode.gain_v_per_rad.as_array()),
               inputs=["Rh", "Rv"], outputs=qd_out, name="qd")
    extra = [] if lowpass is None else [lowpass]
    metrology = ct.ss([], [], [], np.diag(p.newport.metrology_sign.as_array())
                      / p.newport.metrology_gain_rad_per_v,
                      inputs=["theta_nh", "theta_nv"], outputs=["Vnh", "Vnv"], name="metrology")
    outputs = list(ADC_CHANNELS + INTERNAL_SIGNALS)
    sys = ct.interconnect(
        [current_amplifier(p), coil, voltage_amplifier(p), sercalo_angles(p), newport_angles(p),
         beam, qd, metrology, *extra],
        inplist=list(DAC_CHANNELS), outlist=outputs, inputs=list(DAC_CHANNELS), outputs=outputs,
        name="twin")
    return ct.ss(sys.A, sys.B, sys.C, sys.D, inputs=list(DAC_CHANNELS), outputs=outputs,
                 states=list(sys.state_labels), name="twin")


def twin_discrete(p: BenchParams) -> DiscretePlant:
    """The twin's plant at the converter rate with its DAC and Newport delays.

    Sercalo commands reach the plant ``dac_delay_samples`` (plus the
    converter's ``dac_extra_delay_s``, any fraction of a sample) after they
    are computed; Newport commands additionally pass the FSM's internal lag.
    Fractional delays are exact for the held commands (modified z-transform,
    :func:`~fsmbench.sim.discretize.zoh_with_delays`), at any sampling rate.
    """
    sys = twin_continuous(p)
    if np.any(np.asarray(sys.D) != 0):
        raise ValueError("twin plant must have no direct feedthrough")
    ts = p.converter.ts_s
    dac = float(p.converter.dac_delay_samples)
    if p.converter.dac_extra_delay_s:
        dac += p.converter.dac_extra_delay_s / ts
    nport = dac + p.newport.internal_delay_s / ts
    return zoh_with_delays(np.asarray(sys.A), np.asarray(sys.B), np.asarray(sys.C), ts_s=ts,
                           input_delay_samples=[dac, dac, nport, nport],
                           input_names=DAC_CHANNELS, output_names=ADC_CHANNELS + INTERNAL_SIGNALS)


def bench_discrete(bench: Bench) -> DiscretePlant:
    """The plant the engine steps for ``bench``: packaged (physics) or identified.

    A packaged bench is :func:`twin_discrete` of its ``true`` parameters; an
    identified bench (:func:`fsmbench.twin.identified.identified_bench`) is its
    identified plant, wired by :func:`fsmbench.bench.identified.engine_model`,
    with the same exact hold and fractional delays.
    """
    if bench.model is None:
        return twin_discrete(bench.true)
    m = bench.model
    return zoh_with_delays(m.a, m.b, m.c, d=m.d, ts_s=bench.true.converter.ts_s,
                           input_delay_samples=m.input_delay_samples,
                           input_names=DAC_CHANNELS, output_names=ADC_CHANNELS + INTERNAL_SIGNALS)
