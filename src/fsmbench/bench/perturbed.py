"""A bench moved within its uncertainty: which plant parameters move, and the bench they give.

The Monte Carlo's draws (:mod:`fsmbench.twin.draws`), the robust set of the closed-loop
excitations (:func:`fsmbench.excite.closed_loop.robust_loops`) and ``tune``'s model
checks all move a bench the same way: by factors on its Sercalo modes and its gains and
by offsets on its delays (:data:`PARAMETERS`). A physical bench moves in its parameters;
an identified bench (``bench.model``) in its identified blocks.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

import control as ct
import numpy as np

from fsmbench.bench.axes import PerAxis
from fsmbench.bench.blocks import assemble_plant
from fsmbench.bench.identified import engine_model
from fsmbench.bench.params import Bench

__all__ = ["PARAMETERS", "perturbed_bench", "perturbed_identified"]

#: Drawn factors and offsets, per key: what it multiplies or shifts.
PARAMETERS: dict[str, str] = {
    **{f"resonance_scale.{a}": f"Sercalo resonance, {a} axis, × [1]" for a in "hv"},
    **{f"damping_scale.{a}": f"Sercalo damping ratio, {a} axis, × [1]" for a in "hv"},
    **{f"qd_gain_scale.{a}": f"4QD gain, {a} axis, × [1]" for a in "hv"},
    **{f"current_amp_gain_scale.{a}": f"current-amplifier gain, {a} axis, × [1]" for a in "hv"},
    **{f"newport_gain_scale.{a}": f"Newport gain, {a} axis, × [1]" for a in "hv"},
    "dac_delay_offset_s": "DAC delay, + [s]",
    "newport_delay_offset_s": "Newport internal delay, + [s]",
}


def _scaled(value: PerAxis, factors: Mapping[str, float], kind: str) -> PerAxis:
    return PerAxis(h=value.h * factors[f"{kind}.h"], v=value.v * factors[f"{kind}.v"])


def perturbed_bench(bench: Bench, factors: Mapping[str, float]) -> Bench:
    """``bench`` with its ``true`` plant moved by ``factors`` (:data:`PARAMETERS` keys).

    The current-amplifier gain ``1/(R + R_buffer + Rc)`` is scaled through
    ``R_buffer`` (the coil's resistance also sets the coil voltage); the DAC
    delay may become fractional (the twin's discretisation and the plant's
    delays take it as a float). An identified bench (``bench.model``) is moved
    in its identified plant instead (:func:`perturbed_identified`).
    """
    if bench.model is not None:
        return perturbed_identified(bench, factors)
    p = bench.true
    ts = p.converter.ts_s
    r_tot = (p.current_amplifier.r_ohm.as_array() + p.current_amplifier.r_buffer_ohm.as_array()
             + p.sercalo.r_coil_ohm.as_array())
    gi = np.array([factors["current_amp_gain_scale.h"], factors["current_amp_gain_scale.v"]])
    # Written as a change, so that a factor of 1 leaves the value bit for bit.
    r_buffer = p.current_amplifier.r_buffer_ohm.as_array() + r_tot * (1.0 / gi - 1.0)
    dac = max(0.0, p.converter.dac_delay_samples + factors["dac_delay_offset_s"] / ts)
    newport_delay = max(0.0, p.newport.internal_delay_s + factors["newport_delay_offset_s"])
    true = dataclasses.replace(
        p,
        sercalo=dataclasses.replace(
            p.sercalo, resonance_hz=_scaled(p.sercalo.resonance_hz, factors, "resonance_scale"),
            damping_ratio=_scaled(p.sercalo.damping_ratio, factors, "damping_scale")),
        current_amplifier=dataclasses.replace(
            p.current_amplifier, r_buffer_ohm=PerAxis(h=float(r_buffer[0]),
                                                      v=float(r_buffer[1]))),
        quad_diode=dataclasses.replace(
            p.quad_diode, gain_v_per_rad=_scaled(p.quad_diode.gain_v_per_rad, factors,
                                                 "qd_gain_scale")),
        newport=dataclasses.replace(
            p.newport, gain_rad_per_v=_scaled(p.newport.gain_rad_per_v, factors,
                                              "newport_gain_scale"),
            internal_delay_s=newport_delay),
        # A fractional DAC delay (analog lag of the path) in the int field: twin_discrete and
        # input_delays_s both take it as a float.
        converter=dataclasses.replace(p.converter, dac_delay_samples=dac),  # type: ignore[arg-type]
    )
    return dataclasses.replace(bench, true=true)


def _scaled_modes(block: ct.StateSpace, modes: Mapping[str, tuple[float, float, float]]
                  ) -> ct.StateSpace:
    """``block`` with each named mode's frequency and damping scaled, its DC gain kept.

    ``modes``: axis → (identified resonance [Hz], frequency factor, damping factor).
    The poles within 5 % of a resonance move to ``ω0' = r ω0``, ``ζ' = d ζ``; in modal
    coordinates each moved pole's input row is scaled by ``λ'/λ``, which keeps the
    mode's static gain ``−2 Re(res/λ)``. A block without such a pole is returned as is.
    """
    a, b = np.asarray(block.A, dtype=float), np.asarray(block.B, dtype=float)
    lam, vec = np.linalg.eig(a)
    new = lam.copy()
    for f0, r, d in modes.values():
        if r == 1.0 and d == 1.0:
            continue
        w0 = 2 * np.pi * f0
        near = np.abs(np.abs(lam) - w0) < 0.05 * w0
        for i in np.flatnonzero(near & (lam.imag != 0)):
            w = abs(lam[i]) * r
            zeta = min(-lam[i].real / abs(lam[i]) * d, 0.999)
            new[i] = complex(-zeta * w, np.sign(lam[i].imag) * w * np.sqrt(1 - zeta**2))
    if np.array_equal(new, lam):
        return block
    modal_b = np.linalg.solve(vec, b) * (new / lam)[:, None]
    a_new = vec @ np.diag(new) @ np.linalg.inv(vec)
    b_new = vec @ modal_b
    return ct.ss(np.real(a_new), np.real(b_new), block.C, block.D,
                 inputs=list(block.input_labels), outputs=list(block.output_labels),
                 name=block.name)


def perturbed_identified(bench: Bench, factors: Mapping[str, float]) -> Bench:
    """An identified bench moved by Monte-Carlo ``factors`` (:data:`PARAMETERS` keys).

    The identified blocks are scaled as the physical parameters would scale them:
    the Sercalo's first mode on each axis in frequency and damping (its static gain
    kept), the current-amplifier gain (``Gi``), the 4QD gain (``Gd`` and the 4QD's
    share of ``Gc`` and ``Gn``), the Newport gain (``Gn``); the delays are offset.
    """
    model = bench.model
    if model is None:
        raise ValueError("perturbed_identified needs an identified bench")
    plant = model.plant
    sercalo = model.values.get("sercalo") or {}
    modes = {a: (float(sercalo[a]["resonance_hz"]), factors[f"resonance_scale.{a}"],
                 factors[f"damping_scale.{a}"]) for a in ("h", "v") if a in sercalo}
    qd = np.array([factors["qd_gain_scale.h"], factors["qd_gain_scale.v"]])
    gi = np.array([factors["current_amp_gain_scale.h"], factors["current_amp_gain_scale.v"]])
    gn = np.array([factors["newport_gain_scale.h"], factors["newport_gain_scale.v"]])

    def rows(block: ct.StateSpace, scale: np.ndarray) -> ct.StateSpace:
        if np.all(scale == 1.0):
            return block
        return ct.ss(block.A, block.B, np.diag(scale) @ np.asarray(block.C),
                     np.diag(scale) @ np.asarray(block.D), inputs=list(block.input_labels),
                     outputs=list(block.output_labels), name=block.name)

    blocks = dict(plant.blocks)
    blocks["Gi"] = rows(blocks["Gi"], gi)
    blocks["Gc"] = rows(_scaled_modes(blocks["Gc"], modes), qd)
    blocks["Gn"] = rows(blocks["Gn"], qd * gn)
    blocks["Gd"] = rows(blocks["Gd"], qd)
    dac = factors["dac_delay_offset_s"]
    newport = factors["newport_delay_offset_s"]
    delays = {name: max(0.0, tau + dac + (newport if name.startswith("Un") else 0.0))
              for name, tau in plant.input_delay_s.items()}
    moved = assemble_plant(gi=blocks["Gi"], zc=blocks["Zc"], ga=blocks["Ga"], gc=blocks["Gc"],
                           gn=blocks["Gn"], gd=blocks["Gd"], input_delay_s=delays,
                           source=plant.source + " (perturbed)")
    gd0 = np.diag(np.asarray(plant.blocks["Gd"].D, dtype=float))
    true = dataclasses.replace(bench.true, quad_diode=dataclasses.replace(
        bench.true.quad_diode, gain_v_per_rad=PerAxis(h=float(gd0[0] * qd[0]),
                                                      v=float(gd0[1] * qd[1]))))
    sys, engine_delays = engine_model(moved, params=true)
    values = dict(model.values)
    if sercalo:
        values["sercalo"] = {a: {**sercalo[a], "resonance_hz": modes[a][0] * modes[a][1],
                                 "damping_ratio": float(sercalo[a]["damping_ratio"])
                                 * modes[a][2]} for a in modes}
    return dataclasses.replace(bench, true=true, model=dataclasses.replace(
        model, a=np.asarray(sys.A, dtype=float), b=np.asarray(sys.B, dtype=float),
        c=np.asarray(sys.C, dtype=float), d=np.asarray(sys.D, dtype=float),
        input_delay_samples=engine_delays, plant=moved, values=values))
