"""The bench's analog part as one continuous state space, and its exact sampling.

Physics (ESRF study sections 1 and 2, in the frames of :mod:`indsim.bench`):

* Coil circuit per axis: the DAC's held voltage ``U`` drives the amplifier
  resistor ``R``, an unmodelled series resistance and the coil
  (``R_c``, ``L_c``): ``L_c di/dt = U - (R + R_s + R_c) i - e``, ``e`` the
  back-EMF. The voltage across the coil is ``U - (R + R_s) i`` (it includes
  ``L di/dt`` and ``e``), amplified by ``vc_gain`` behind a first-order
  low-pass at ``vc_cutoff_hz`` (study 2.2).
* Sercalo mirror: modes ``m`` (the first mode of each axis, optionally a
  second, flexural one), each a second order of static gain ``G_m`` [rad/A]
  with a unit shape vector ``o_m`` in the mirror's ``(a, b)`` plane:
  ``q_m'' + 2 ζ ω q_m' + ω² q_m = ω² G_m o_m·(C i)``, mirror angles
  ``phi = Σ o_m q_m``. ``C = [[1, c_v], [c_h, 1]]`` turns each coil's torque
  (torque crosstalk); identical coil torque constants are assumed, so the
  static compliance is ``Σ G_m o_m o_mᵀ C``. The back-EMF of coil ``j`` is
  ``k_e,j C[:, j]·phi'`` (reciprocal to its torque).
* Newport per axis: ``psi'' + 2 ζ ω psi' + ω² psi = ω² (g U_n(t - τ) + ν)``,
  ``τ`` its internal delay, ``ν`` its angle noise (real mirror motion, seen
  by its metrology too).
* Beam: ``b = (mount_h 4 phi_a + 2 psi_a, mount_v 4 phi_b + 2 psi_b)``; the
  4QD reads it in its turned frame, times its signed gain, behind its
  amplifier's low-pass (order 0, 1 or 2).

Inputs (held, ``INPUTS``): ``Uch, Ucv`` (delay: transport + latency),
``Unh, Unv`` (the same plus the Newport's internal delay), ``nu_a, nu_b``
(Newport angle noise [rad], no delay). Outputs: ``OUTPUTS``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .bench import IndBench
from .lti import DiscreteSS, sample_with_delay

__all__ = ["INPUTS", "OUTPUTS", "ContinuousPlant", "SampledPlant", "build_plant", "sample_plant"]

Array = NDArray[np.float64]

INPUTS = ("Uch", "Ucv", "Unh", "Unv", "nu_a", "nu_b")
OUTPUTS = ("Vph", "Vpv", "Vch", "Vcv", "psi_a", "psi_b", "b_x", "b_y",
           "d_u", "d_w", "phi_a", "phi_b", "i_h", "i_v")


@dataclass(frozen=True)
class ContinuousPlant:
    """Continuous ``dx/dt = A x + B u``, ``y = C x`` with the input delays.

    Parameters
    ----------
    A, B, C : ndarray
        State-space matrices (inputs ``INPUTS``, outputs ``OUTPUTS``).
    delays_s : ndarray, shape (6,)
        Pure delay of each input [s].
    mode_states : dict
        Name of each Sercalo / Newport mode -> index of its position state.
    mode_freqs_hz : dict
        Name of each mode -> its uncoupled natural frequency [Hz].
    """

    A: NDArray[np.float64]
    B: NDArray[np.float64]
    C: NDArray[np.float64]
    delays_s: NDArray[np.float64]
    mode_states: dict[str, int]
    mode_freqs_hz: dict[str, float]

    def dc_gain(self) -> Array:
        """Static gain ``-C A^-1 B`` (every block is stable)."""
        return -self.C @ np.linalg.solve(self.A, self.B)

    def freqresp(self, f_hz: Array) -> NDArray[np.complex128]:
        """Response at ``f_hz`` [Hz] *without* the input delays, (len(f), out, in)."""
        n = self.A.shape[0]
        return np.stack([self.C @ np.linalg.solve(2j * np.pi * f * np.eye(n) - self.A, self.B)
                         for f in np.atleast_1d(f_hz)])

    def out(self, name: str) -> int:
        """Row of output ``name``."""
        return OUTPUTS.index(name)

    def inp(self, name: str) -> int:
        """Column of input ``name``."""
        return INPUTS.index(name)


def _shape(angle: float, axis: str) -> Array:
    """Unit shape vector of a mode of ``axis`` turned by ``angle`` in the mirror plane."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([c, s]) if axis == "h" else np.array([-s, c])


def build_plant(bench: IndBench, with_vc: bool = True) -> ContinuousPlant:
    """Assemble the analog bench of ``bench`` (see the module docstring).

    Parameters
    ----------
    bench : IndBench
        The bench.
    with_vc : bool
        Include the coil-voltage monitors (``Vch``, ``Vcv`` rows are zero
        without them; closed loops leave them out to stay small).
    """
    b = bench
    modes: list[tuple[str, float, float, float, Array]] = []
    for ax in ("h", "v"):
        modes.append((f"sercalo_{ax}", getattr(b.sercalo_resonance_hz, ax),
                      getattr(b.sercalo_damping_ratio, ax),
                      getattr(b.sercalo_gain_rad_per_a, ax),
                      _shape(getattr(b.sercalo_mode_angle_rad, ax), ax)))
    for ax in ("h", "v"):
        f2 = getattr(b.sercalo_second_mode_hz, ax)
        if f2 > 0.0:
            modes.append((f"sercalo2_{ax}", f2, getattr(b.sercalo_second_mode_damping_ratio, ax),
                          getattr(b.sercalo_gain_rad_per_a, ax)
                          * getattr(b.sercalo_second_mode_relative_gain, ax),
                          _shape(getattr(b.sercalo_second_mode_angle_rad, ax), ax)))
    n_qd = b.qd_amp_order
    # State layout: coil currents, mode (q, q') pairs, Newport (psi, psi') pairs,
    # 4QD amplifier states per axis, Vc monitors.
    i_cur = 0
    i_mode = 2
    i_np = i_mode + 2 * len(modes)
    i_qd = i_np + 4
    i_vc = i_qd + 2 * n_qd
    n = i_vc + (2 if with_vc else 0)
    A = np.zeros((n, n))
    B = np.zeros((n, len(INPUTS)))
    C = np.zeros((len(OUTPUTS), n))

    Ct = np.array([[1.0, b.sercalo_torque_crosstalk.v], [b.sercalo_torque_crosstalk.h, 1.0]])
    # Mirror angles and rates as rows over the state.
    phi = np.zeros((2, n))
    phi_dot = np.zeros((2, n))
    mode_states: dict[str, int] = {}
    mode_freqs: dict[str, float] = {}
    for k, (name, f, z, g, o) in enumerate(modes):
        q = i_mode + 2 * k
        w = 2.0 * math.pi * f
        A[q, q + 1] = 1.0
        A[q + 1, q] = -w * w
        A[q + 1, q + 1] = -2.0 * z * w
        A[q + 1, i_cur:i_cur + 2] = w * w * g * (o @ Ct)  # modal force from the currents
        phi[:, q] += o
        phi_dot[:, q + 1] += o
        mode_states[name] = q
        mode_freqs[name] = f
    # Coil circuits: L di/dt = U - R_tot i - k_e C[:, j]·phi'.
    for j, ax in enumerate(("h", "v")):
        L = getattr(b.l_coil_h, ax)
        A[i_cur + j, i_cur + j] -= getattr(b.r_total_ohm, ax) / L
        A[i_cur + j, :] -= getattr(b.back_emf_v_s_per_rad, ax) * (Ct[:, j] @ phi_dot) / L
        B[i_cur + j, j] = 1.0 / L
    # Newport axes.
    for j, ax in enumerate(("h", "v")):
        p = i_np + 2 * j
        w = 2.0 * math.pi * getattr(b.newport_natural_freq_hz, ax)
        z = getattr(b.newport_damping_ratio, ax)
        A[p, p + 1] = 1.0
        A[p + 1, p] = -w * w
        A[p + 1, p + 1] = -2.0 * z * w
        B[p + 1, 2 + j] = w * w * getattr(b.newport_gain_rad_per_v, ax)
        B[p + 1, 4 + j] = w * w
        mode_states[f"newport_{ax}"] = p
        mode_freqs[f"newport_{ax}"] = w / (2.0 * math.pi)
    psi = np.zeros((2, n))
    psi[0, i_np] = psi[1, i_np + 2] = 1.0
    mounts = np.array([b.sercalo_mount_sign.h, b.sercalo_mount_sign.v])
    beam = b.sercalo_beam_factor * mounts[:, None] * phi + b.newport_beam_factor * psi
    th = b.qd_rotation_rad
    rot = np.array([[math.cos(th), math.sin(th)], [-math.sin(th), math.cos(th)]])
    diode = rot @ beam
    signed_gain = np.array([b.qd_polarity.h * b.qd_gain_v_per_rad.h,
                            b.qd_polarity.v * b.qd_gain_v_per_rad.v])
    vd = signed_gain[:, None] * diode  # the diode's signal before its amplifier
    wq = 2.0 * math.pi * b.qd_amp_bandwidth_hz
    vp = np.zeros((2, n))
    for j in range(2):
        if n_qd == 0:
            vp[j] = vd[j]
        elif n_qd == 1:
            s = i_qd + j
            A[s, :] += wq * vd[j]
            A[s, s] -= wq
            vp[j, s] = 1.0
        else:
            s = i_qd + 2 * j
            A[s, s + 1] = 1.0
            A[s + 1, :] += wq * wq * vd[j]
            A[s + 1, s] -= wq * wq
            A[s + 1, s + 1] -= 2.0 * b.qd_amp_damping_ratio * wq
            vp[j, s] = 1.0
    if with_vc:
        wc = 2.0 * math.pi * b.vc_cutoff_hz
        for j, ax in enumerate(("h", "v")):
            s = i_vc + j
            rs = getattr(b.r_amp_ohm, ax) + getattr(b.r_series_ohm, ax)
            # dVc/dt = wc (gain (U - rs i) - Vc)
            A[s, s] = -wc
            A[s, i_cur + j] = -wc * b.vc_gain * rs
            B[s, j] = wc * b.vc_gain
            C[OUTPUTS.index("Vch") + j, s] = 1.0
    C[0:2] = vp
    C[4:6] = psi
    C[6:8] = beam
    C[8:10] = diode
    C[10:12] = phi
    C[12, i_cur] = C[13, i_cur + 1] = 1.0
    d_c = b.dac_transport_samples / b.fs_hz + b.dac_latency_s
    delays = np.array([d_c, d_c, d_c + b.newport_internal_delay_s,
                       d_c + b.newport_internal_delay_s, 0.0, 0.0])
    return ContinuousPlant(A, B, C, delays, mode_states, mode_freqs)


@dataclass(frozen=True)
class SampledPlant:
    """The plant sampled exactly at ``fs`` behind the hold and the input delays.

    ``system`` takes ``2 m`` inputs, ``u_j[k - n_j]`` then ``u_j[k - n_j - 1]``
    (:func:`indsim.lti.delayed_inputs`); ``n_whole`` and ``fractional`` say how.
    """

    system: DiscreteSS
    n_whole: NDArray[np.int64]
    fractional: NDArray[np.bool_]
    Phi: Array
    Gb: Array
    Ga: Array


def sample_plant(plant: ContinuousPlant, dt_s: float) -> SampledPlant:
    """Exact ZOH sampling of ``plant`` with its per-input delays (no feedthrough)."""
    Phi, Gb, Ga, n_whole = sample_with_delay(plant.A, plant.B, dt_s, plant.delays_s)
    fractional = np.any(Ga != 0.0, axis=0)
    m = plant.B.shape[1]
    system = DiscreteSS(Phi, np.hstack([Gb, Ga]), plant.C,
                        np.zeros((plant.C.shape[0], 2 * m)), dt_s)
    return SampledPlant(system, n_whole, fractional, Phi, Gb, Ga)
