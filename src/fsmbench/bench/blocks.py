"""The bench's transfer-function blocks from physics, and the assembled plant.

Blocks and signal names follow the ESRF study (sections 1.1, 2.2, 2.5):

====  ===========================  ==========================  =======
name  from                         to                          unit
====  ===========================  ==========================  =======
Gi    Uch, Ucv  (DAC voltage)      Ich, Icv  (coil current)    A/V
Zc    Ich, Icv                     Vtch, Vtcv (coil voltage)   V/A
Ga    Vtch, Vtcv                   Vch, Vcv  (amplified)       V/V
Gc    Ich, Icv                     Vpch, Vpcv (4QD part)       V/A
Gn    Unh, Unv  (Newport command)  Vpnh, Vpnv (4QD part)       V/V
Gd    Rh, Rv    (beam angle)       Vph, Vpv  (4QD output)      V/rad
====  ===========================  ==========================  =======

The full system has inputs ``Uch, Ucv, Unh, Unv`` and outputs
``Vch, Vcv, Ich, Icv, Rh, Rv, Vph, Vpv`` and is assembled exactly as the
ESRF study's ``connect(Gi, Zc, Ga, Gc, Gn, inv(Gd), Sh, Sv, inputs, outputs)``.

Every dynamic block is realised in modal (block-diagonal) form with states
scaled to the block's output unit: a lightly damped mode with
``x = [angle, angle_rate / w0]`` has A = [[0, w0], [-w0, -2 xi w0]], whose
condition number is independent of w0, unlike the companion form.

Pure delays cannot live in a python-control state-space model; the plant
carries them as per-input delays (like MATLAB's ``InputDelay``) and
:meth:`PlantModel.frequency_response` applies them exactly.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import control as ct
import numpy as np
import xarray as xr

from fsmbench.bench.params import BenchParams
from fsmbench.bench.realization import DEFAULT_TOL, Delays, plant_model
from fsmbench.bench.response import (
    ResponseEvaluator,
    solve_response,
    ss_frequency_response,
    ss_response,
)

__all__ = [
    "PLANT_INPUTS",
    "PLANT_OUTPUTS",
    "PlantModel",
    "ResponseEvaluator",
    "assemble_plant",
    "coil_impedance",
    "current_amplifier",
    "input_delays_s",
    "mode_block",
    "mode_shape",
    "newport",
    "newport_angles",
    "newport_beam_matrix",
    "physical_plant",
    "quad_diode",
    "quad_diode_lowpass",
    "rotation",
    "sercalo",
    "sercalo_angles",
    "sercalo_beam_matrix",
    "solve_response",
    "ss_frequency_response",
    "ss_response",
    "voltage_amplifier",
]

PLANT_INPUTS = ("Uch", "Ucv", "Unh", "Unv")
PLANT_OUTPUTS = ("Vch", "Vcv", "Ich", "Icv", "Rh", "Rv", "Vph", "Vpv")


def mode_block(*, freq_hz: float, damping_ratio: float) -> ct.StateSpace:
    """Modal realisation of ``1 / (1 + 2 xi s/w0 + s**2/w0**2)`` with unit DC gain.

    Parameters
    ----------
    freq_hz : float
        Natural frequency f0 [Hz].
    damping_ratio : float
        Damping ratio xi [1] (> 1 gives two real poles; the form still holds).

    Returns
    -------
    control.StateSpace
        SISO, A (2, 2), B (2, 1), C (1, 2); states are ``[y, dy/dt / w0]``.
    """
    w0 = 2.0 * np.pi * freq_hz
    a = np.array([[0.0, w0], [-w0, -2.0 * damping_ratio * w0]])
    b = np.array([[0.0], [w0]])
    c = np.array([[1.0, 0.0]])
    return ct.ss(a, b, c, np.zeros((1, 1)))


def rotation(angle_rad: float) -> np.ndarray:
    """Coordinates of a vector in a frame rotated by ``angle_rad``, shape (2, 2)."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[c, s], [-s, c]])


def current_amplifier(p: BenchParams) -> ct.StateSpace:
    """Gi: ``Ic/Uc = 1 / (R + R_buffer + Rc + Lc s)`` per axis [A/V] (ESRF study 2.2 eq. 2)."""
    r_tot = (p.current_amplifier.r_ohm.as_array() + p.current_amplifier.r_buffer_ohm.as_array()
             + p.sercalo.r_coil_ohm.as_array())
    l_h = p.sercalo.l_coil_h.as_array()
    # State: coil current [A]. The pole (R_tot/Lc, ~125 kHz) is kept: it is physics,
    # and exact discretisation handles the stiffness.
    sign = p.current_amplifier.sign.as_array()  # an inverting amplifier or reversed coil
    return ct.ss(np.diag(-r_tot / l_h), np.diag(sign / l_h), np.eye(2), np.zeros((2, 2)),
                 inputs=["Uch", "Ucv"], outputs=["Ich", "Icv"], states=["Ich", "Icv"], name="Gi")


def coil_impedance(p: BenchParams) -> ct.StateSpace:
    """Zc: static coil resistance Rc [V/A] (ESRF study 2.2, "Important 2").

    The inductive term ``Lc s`` has its zero at Rc/Lc (14.8 kHz for the h axis),
    above the 5 kHz Nyquist frequency: |1 + j w Lc/Rc| - 1 < 0.25 % below 1 kHz.
    A state-space model cannot hold the improper ``Rc + Lc s``; the twin uses
    the exact circuit equation instead.
    """
    return ct.ss([], [], [], np.diag(p.sercalo.r_coil_ohm.as_array()),
                 inputs=["Ich", "Icv"], outputs=["Vtch", "Vtcv"], name="Zc")


def voltage_amplifier(p: BenchParams) -> ct.StateSpace:
    """Ga: ``Ga0 / (1 + s/wc)`` per axis [V/V] (ESRF study 2.2 eq. 7)."""
    wc = 2.0 * np.pi * p.voltage_amplifier.cutoff_hz
    g = p.voltage_amplifier.gain * p.voltage_amplifier.sign.as_array()
    return ct.ss(-wc * np.eye(2), wc * np.diag(g), np.eye(2), np.zeros((2, 2)),
                 inputs=["Vtch", "Vtcv"], outputs=["Vch", "Vcv"], states=["Vch", "Vcv"],
                 name="Ga")


def mode_shape(axis_index: int, angle_rad: float) -> np.ndarray:
    """Unit mode shape in (h, v) mirror angles of the mode of axis 0 (h) or 1 (v), shape (2,).

    The h mode's shape is ``(cos a, sin a)``, the v mode's ``(-sin a, cos a)``:
    at ``a = 0`` each mode moves its own axis only.
    """
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([c, s]) if axis_index == 0 else np.array([-s, c])


def sercalo_angles(p: BenchParams) -> ct.StateSpace:
    """Coil currents to Sercalo mirror angles ``theta_ch, theta_cv`` [rad/A] (ESRF study 1.2).

    Per axis a mass-spring-damper ``theta/I = g0 / (1 + 2 xi s/w0 + s**2/w0**2)``;
    the coils' torques couple the axes through ``coupling_*``. A real bench
    (docs/model.md, "real-bench features") adds:

    - rotated mode shapes: the mode of axis ``i`` moves the mirror along
      :func:`mode_shape` ``phi_i`` and is driven by the torque's projection on
      it, ``theta = sum_i phi_i g_i H_i(s) phi_i^T T I`` (reciprocal: the
      coupling is symmetric and strongest at each resonance, ``tan a``);
    - a second, weaker mode per axis (``second_mode_*``), with its own shape
      and DC gain relative to the first mode's; its two states follow the
      first four, so a bench without it has exactly the ESRF study's states.
    """
    s = p.sercalo
    axes = ("h", "v")
    second = [i for i, axis in enumerate(axes) if s.second_mode_hz[axis] > 0]
    n = 4 + 2 * len(second)
    a = np.zeros((n, n))
    b = np.zeros((n, 2))
    c = np.zeros((2, n))
    torque = np.array([[1.0, s.coupling_v_to_h], [s.coupling_h_to_v, 1.0]])

    def place(k: int, i: int, freq_hz: float, damping: float, gain: float,
              angle_rad: float) -> None:
        mode = mode_block(freq_hz=freq_hz, damping_ratio=damping)
        a[k:k + 2, k:k + 2] = mode.A
        if angle_rad == 0.0:
            # The seed's decoupled modes, with its exact arithmetic.
            b[k:k + 2, :] = mode.B @ (gain * torque[i:i + 1, :])
            c[i, k:k + 2] += mode.C[0]
            return
        phi = mode_shape(i, angle_rad)
        b[k:k + 2, :] = mode.B @ (gain * (phi[None, :] @ torque))
        c[:, k:k + 2] += phi[:, None] @ mode.C

    for i, axis in enumerate(axes):
        place(2 * i, i, s.resonance_hz[axis], s.damping_ratio[axis], s.dc_gain_rad_per_a[axis],
              s.mode_shape_angle_rad[axis])
    states = ["theta_ch", "dtheta_ch", "theta_cv", "dtheta_cv"]
    for j, i in enumerate(second):
        axis = axes[i]
        place(4 + 2 * j, i, s.second_mode_hz[axis], s.second_mode_damping_ratio[axis],
              s.second_mode_relative_gain[axis] * s.dc_gain_rad_per_a[axis],
              s.second_mode_shape_angle_rad[axis])
        states += [f"q2_c{axis}", f"dq2_c{axis}"]
    return ct.ss(a, b, c, np.zeros((2, 2)), inputs=["Ich", "Icv"],
                 outputs=["theta_ch", "theta_cv"], states=states, name="Gc_angles")


def newport_angles(p: BenchParams) -> ct.StateSpace:
    """Newport commands to mirror angles ``theta_nh, theta_nv`` [rad/V] (ESRF study 1.4).

    ``theta_n = gn * wn**2 / (s**2 + 2 zeta wn s + wn**2) * Un``, the datasheet
    fit of ``docs/model.md``; the internal lag is a pure delay (:func:`input_delays_s`).
    """
    n = p.newport
    a = np.zeros((4, 4))
    b = np.zeros((4, 2))
    c = np.zeros((2, 4))
    for i, axis in enumerate(("h", "v")):
        mode = mode_block(freq_hz=n.natural_freq_hz, damping_ratio=n.damping_ratio)
        ai, bi, ci = mode.A, mode.B, mode.C
        a[2 * i:2 * i + 2, 2 * i:2 * i + 2] = ai
        b[2 * i:2 * i + 2, i:i + 1] = bi * n.gain_rad_per_v[axis]
        c[i, 2 * i:2 * i + 2] = ci[0]
    return ct.ss(a, b, c, np.zeros((2, 2)), inputs=["Unh", "Unv"],
                 outputs=["theta_nh", "theta_nv"],
                 states=["theta_nh", "dtheta_nh", "theta_nv", "dtheta_nv"], name="Gn_angles")


def sercalo_beam_matrix(p: BenchParams) -> np.ndarray:
    """Beam angle in the 4QD frame per Sercalo mirror angle, shape (2, 2) [rad/rad].

    Two reflections (``beam_angle_per_mirror_angle``, signed), then the 4QD's rotation.
    """
    return rotation(p.quad_diode.rotation_rad) @ np.diag(
        p.sercalo.beam_angle_per_mirror_angle.as_array())


def newport_beam_matrix(p: BenchParams) -> np.ndarray:
    """Beam angle in the 4QD frame per Newport mirror angle, shape (2, 2) [rad/rad]."""
    return rotation(p.quad_diode.rotation_rad) * p.newport.beam_angle_per_mirror_angle


def sercalo(p: BenchParams) -> ct.StateSpace:
    """Gc: coil currents to the Sercalo's share of the 4QD outputs [V/A] (ESRF study 1.2, 2.3).

    Mirror angles (:func:`sercalo_angles`), two reflections and the 4QD
    rotation (:func:`sercalo_beam_matrix`), then the 4QD gain.
    """
    m = sercalo_angles(p)
    c = np.diag(p.quad_diode.gain_v_per_rad.as_array()) @ sercalo_beam_matrix(p) @ m.C
    return ct.ss(m.A, m.B, c, np.zeros((2, 2)), inputs=["Ich", "Icv"],
                 outputs=["Vpch", "Vpcv"], states=list(m.state_labels), name="Gc")


def newport(p: BenchParams) -> ct.StateSpace:
    """Gn: Newport commands to the Newport's share of the 4QD outputs [V/V] (ESRF study 1.4, 2.4).

    Mirror angles (:func:`newport_angles`), beam angle twice the mirror angle
    (ESRF study 2.1) in the 4QD frame, then the 4QD gain.
    """
    m = newport_angles(p)
    c = np.diag(p.quad_diode.gain_v_per_rad.as_array()) @ newport_beam_matrix(p) @ m.C
    return ct.ss(m.A, m.B, c, np.zeros((2, 2)), inputs=["Unh", "Unv"],
                 outputs=["Vpnh", "Vpnv"], states=list(m.state_labels), name="Gn")


def quad_diode(p: BenchParams) -> ct.StateSpace:
    """Gd: beam angle to 4QD output, static diagonal [V/rad] (ESRF study 2.1, Table 2)."""
    return ct.ss([], [], [], np.diag(p.quad_diode.gain_v_per_rad.as_array()),
                 inputs=["Rh", "Rv"], outputs=["Vph", "Vpv"], name="Gd")


def quad_diode_lowpass(p: BenchParams) -> ct.StateSpace | None:
    """The 4QD amplifier's low pass on ``Vph, Vpv`` (unit DC gain), or None when unlimited.

    First order ``1/(1 + s/wb)`` or second-order Butterworth
    ``1/(1 + sqrt(2) s/wb + s**2/wb**2)``; both are -3 dB at ``bandwidth_hz``.
    """
    qd = p.quad_diode
    if qd.bandwidth_hz == 0.0:
        return None
    if qd.bandwidth_order == 1:
        wb = 2.0 * np.pi * qd.bandwidth_hz
        return ct.ss(-wb * np.eye(2), wb * np.eye(2), np.eye(2), np.zeros((2, 2)),
                     inputs=["Vph_in", "Vpv_in"], outputs=["Vph", "Vpv"],
                     states=["qd_lp_h", "qd_lp_v"], name="qd_lowpass")
    m = mode_block(freq_hz=qd.bandwidth_hz, damping_ratio=1.0 / np.sqrt(2.0))
    a = np.kron(np.eye(2), m.A)
    b = np.kron(np.eye(2), m.B)
    c = np.kron(np.eye(2), m.C)
    return ct.ss(a, b, c, np.zeros((2, 2)), inputs=["Vph_in", "Vpv_in"], outputs=["Vph", "Vpv"],
                 states=["qd_lp_h", "dqd_lp_h", "qd_lp_v", "dqd_lp_v"], name="qd_lowpass")


def input_delays_s(p: BenchParams) -> dict[str, float]:
    """Pure delay of each plant input [s], as an identification sees it.

    DAC commands reach the plant ``dac_delay_samples`` (plus any fractional
    ``dac_extra_delay_s``) later and are then held for one sample; a
    zero-order hold looks like a delay of half a sample below Nyquist. The
    Newport adds its internal lag (ESRF study 2.4: 0.5 ms in total).
    """
    ts = p.converter.ts_s
    dac = (p.converter.dac_delay_samples + 0.5) * ts + p.converter.dac_extra_delay_s
    return {"Uch": dac, "Ucv": dac, "Unh": dac + p.newport.internal_delay_s,
            "Unv": dac + p.newport.internal_delay_s}


@dataclass(frozen=True)
class PlantModel:
    """The bench as named LTI blocks plus the assembled system and its input delays.

    Attributes
    ----------
    blocks : mapping of str to control.StateSpace
        ``Gi, Zc, Ga, Gc, Gn, Gd`` with the ESRF study's signal names.
    sys : control.StateSpace
        Delay-free full system, inputs :data:`PLANT_INPUTS`, outputs :data:`PLANT_OUTPUTS`.
    input_delay_s : mapping of str to float
        Pure delay at each input of ``sys`` [s].
    source : str
        Where the model comes from, e.g. ``"physical (true)"`` or ``"identified"``.
    """

    blocks: Mapping[str, ct.StateSpace]
    sys: ct.StateSpace
    input_delay_s: Mapping[str, float]
    source: str
    # Sub-systems already built, by (outputs, inputs): the loop analyses ask for the same
    # path thousands of times (root finding, contour counts) and building the python-control
    # object cost more than evaluating it. The model is frozen, so they never go stale.
    _subsystems: dict[tuple[tuple[str, ...], tuple[str, ...]], ct.StateSpace] = \
        dataclasses.field(default_factory=dict, init=False, compare=False, repr=False)

    def frequency_response(self, f_hz: np.ndarray, *, outputs: Sequence[str] | None = None,
                           inputs: Sequence[str] | None = None,
                           with_delay: bool = True) -> xr.DataArray:
        """Exact frequency response including the input delays.

        Parameters
        ----------
        f_hz : array, shape (nf,)
            Frequencies [Hz].
        outputs, inputs : sequence of str, optional
            Signal names to keep (default: all).
        with_delay : bool
            Apply the pure input delays (default True).

        Returns
        -------
        xarray.DataArray, complex, dims (frequency, output, input).
        """
        outs = list(self.sys.output_labels if outputs is None else outputs)
        ins = list(self.sys.input_labels if inputs is None else inputs)
        sub = self.subsystem(outputs=outs, inputs=ins)
        f = np.asarray(f_hz, dtype=float).ravel()
        h = ss_frequency_response(sub, f)
        if with_delay:
            tau = np.array([self.input_delay_s.get(name, 0.0) for name in ins])
            h = h * np.exp(-2j * np.pi * f[:, None, None] * tau[None, None, :])
        return xr.DataArray(h, dims=("frequency", "output", "input"),
                            coords={"frequency": f, "output": outs, "input": ins},
                            attrs={"units_frequency": "Hz", "source": self.source})

    def subsystem(self, *, outputs: Sequence[str], inputs: Sequence[str]) -> ct.StateSpace:
        """The delay-free sub-system between named inputs and outputs (built once)."""
        key = (tuple(outputs), tuple(inputs))
        if key not in self._subsystems:
            out_idx = [_index(self.sys.output_labels, n, "output") for n in outputs]
            in_idx = [_index(self.sys.input_labels, n, "input") for n in inputs]
            self._subsystems[key] = ct.ss(
                self.sys.A, self.sys.B[:, in_idx], self.sys.C[out_idx, :],
                self.sys.D[np.ix_(out_idx, in_idx)], inputs=list(inputs),
                outputs=list(outputs), states=self.sys.state_labels)
        return self._subsystems[key]

    def dc_gain(self, *, output: str, input: str) -> float:
        """Static gain from ``input`` to ``output`` [output unit / input unit]."""
        return float(np.real(self.frequency_response(np.array([0.0]), outputs=[output],
                                                     inputs=[input]).values[0, 0, 0]))

    def with_pade(self, *, order: int = 6) -> ct.StateSpace:
        """``sys`` with each input delay replaced by a Pade approximation of ``order``."""
        parts = []
        for name in self.sys.input_labels:
            tau = self.input_delay_s.get(name, 0.0)
            if tau > 0:
                num, den = ct.pade(tau, order)
                d = ct.tf2ss(ct.tf(num, den))
            else:
                d = ct.ss([], [], [], [[1.0]])
            parts.append(ct.ss(d.A, d.B, d.C, d.D, inputs=[name], outputs=[f"{name}_delayed"]))
        delays = ct.append(*parts)
        delays = ct.ss(delays.A, delays.B, delays.C, delays.D,
                       inputs=list(self.sys.input_labels),
                       outputs=[f"{n}_delayed" for n in self.sys.input_labels])
        plant = ct.ss(self.sys.A, self.sys.B, self.sys.C, self.sys.D,
                      inputs=[f"{n}_delayed" for n in self.sys.input_labels],
                      outputs=list(self.sys.output_labels))
        return ct.interconnect([delays, plant], inplist=list(self.sys.input_labels),
                               outlist=list(self.sys.output_labels),
                               inputs=list(self.sys.input_labels),
                               outputs=list(self.sys.output_labels))

    def to_control(self, *, delays: Delays = "pade", order: int = 6, dt: float | None = None,
                   outputs: Sequence[str] | None = None, inputs: Sequence[str] | None = None,
                   tol: float = DEFAULT_TOL) -> ct.StateSpace:
        """Minimal python-control model of the path ``inputs -> outputs`` with its delays.

        ``delays="pade"`` (continuous, Padé of ``order``), ``"exact"`` (sampled at
        ``dt`` through a zero-order hold, delays exact) or ``"none"``; signals
        named; see :func:`fsmbench.bench.realization.plant_model`.
        """
        sub = self.subsystem(outputs=list(self.sys.output_labels if outputs is None else outputs),
                             inputs=list(self.sys.input_labels if inputs is None else inputs))
        return plant_model(sub, self.input_delay_s, delays=delays, order=order, dt=dt, tol=tol,
                           name="G")

    def to_frd(self, f_hz: np.ndarray, *, outputs: Sequence[str] | None = None,
               inputs: Sequence[str] | None = None) -> ct.FrequencyResponseData:
        """The exact response with its delays at ``f_hz`` [Hz] as a named python-control FRD
        (frequencies in rad/s, as python-control keeps them)."""
        h = self.frequency_response(f_hz, outputs=outputs, inputs=inputs)
        return ct.frd(np.moveaxis(h.values, 0, -1), 2 * np.pi * h["frequency"].values,
                      inputs=[str(x) for x in h["input"].values],
                      outputs=[str(x) for x in h["output"].values], name="G")

    def summary(self) -> dict[str, Any]:
        """JSON-ready description: source, sizes, delays, DC gains of the main paths."""
        paths = [("Vch", "Uch"), ("Vcv", "Ucv"), ("Ich", "Uch"), ("Icv", "Ucv"),
                 ("Vph", "Uch"), ("Vpv", "Ucv"), ("Vph", "Unh"), ("Vpv", "Unv")]
        return {
            "source": self.source,
            "n_states": int(self.sys.nstates),
            "inputs": list(self.sys.input_labels),
            "outputs": list(self.sys.output_labels),
            "input_delay_s": {k: float(v) for k, v in self.input_delay_s.items()},
            "dc_gain": {f"{i}->{o}": self.dc_gain(output=o, input=i) for o, i in paths},
        }


def _index(labels: Sequence[str], name: str, kind: str) -> int:
    try:
        return list(labels).index(name)
    except ValueError:
        raise KeyError(f"no {kind} named {name!r}; {kind}s are {list(labels)}") from None


def assemble_plant(*, gi: ct.StateSpace, zc: ct.StateSpace, ga: ct.StateSpace,
                   gc: ct.StateSpace, gn: ct.StateSpace, gd: ct.StateSpace,
                   input_delay_s: Mapping[str, float], source: str) -> PlantModel:
    """Connect the blocks as the ESRF study's 2.5 ``connect`` does and return the plant.

    ``Vph = Vpch + Vpnh``, ``Vpv = Vpcv + Vpnv`` and ``[Rh, Rv] = inv(Gd) [Vph, Vpv]``.
    Used for the physical model and for the identified one alike, so the two
    can be compared and swapped.
    """
    sh = ct.summing_junction(inputs=["Vpch", "Vpnh"], output="Vph", name="Sh")
    sv = ct.summing_junction(inputs=["Vpcv", "Vpnv"], output="Vpv", name="Sv")
    gd_inv = ct.ss([], [], [], np.linalg.inv(np.asarray(gd.D, dtype=float)),
                   inputs=["Vph", "Vpv"], outputs=["Rh", "Rv"], name="Gd_inv")
    sys = ct.interconnect([gi, zc, ga, gc, gn, gd_inv, sh, sv], inplist=list(PLANT_INPUTS),
                          outlist=list(PLANT_OUTPUTS), inputs=list(PLANT_INPUTS),
                          outputs=list(PLANT_OUTPUTS), name="sys")
    sys = ct.ss(sys.A, sys.B, sys.C, sys.D, inputs=list(PLANT_INPUTS),
                outputs=list(PLANT_OUTPUTS), states=list(sys.state_labels), name="sys")
    blocks = {"Gi": gi, "Zc": zc, "Ga": ga, "Gc": gc, "Gn": gn, "Gd": gd}
    return PlantModel(blocks=blocks, sys=sys, input_delay_s=dict(input_delay_s), source=source)


def physical_plant(p: BenchParams, *, source: str = "physical") -> PlantModel:
    """The plant from physics for one parameter set (``bench.nominal`` or ``bench.true``)."""
    return assemble_plant(gi=current_amplifier(p), zc=coil_impedance(p), ga=voltage_amplifier(p),
                          gc=sercalo(p), gn=newport(p), gd=quad_diode(p),
                          input_delay_s=input_delays_s(p), source=source)


def replace_params(p: BenchParams, **changes: Any) -> BenchParams:
    """``dataclasses.replace`` on a nested group, e.g. ``sercalo={"damping_ratio": ...}``."""
    groups = {name: dataclasses.replace(getattr(p, name), **values)
              for name, values in changes.items()}
    return dataclasses.replace(p, **groups)
