"""The ESRF study's diagonal controller (section 9.2) closed around a bench.

``Kh(s) = -0.25598 (s + 112)(s² + 15.93 s + 6.686e6) / (s² (s + 352.5)(1 + s/(2π 2000)))``
``Kv(s) = 10207 (s + 55.15)(s² + 17.45 s + 2.491e6) / (s² (s + 491.2)(s + 7695))``

Input ``R`` = beam angle = ``Vp / Gd`` with ``Gd`` the 4QD gain the
experimenter calibrated (study 2.1, ``g cos θ``), output ``Uc``, the loop
closed with ``-K`` (study 9.2), discretised by Tustin at the bench's rate
(study 9.3 does it at 10 kHz; a target at 5 or 20 kHz does the same at its own).

The seed designed ``K`` on its own plant, whose static gain from ``Uc`` to the
beam angle is ``REFERENCE_UC_TO_BEAM_RAD_PER_V``: its identified current
amplifier (0.01275, 0.01382 A/V, study 2.2) times the datasheet's Sercalo gain
(28.4, 35.2 mA/deg, Table 1) times four reflections, with the sign for which
``-K`` is negative feedback. A sensible experimenter with another bench scales
and, if needed, flips each axis so that the static loop gain is the seed's:
``multiplier = reference / (bench's static Uc -> Vp / Gd)``.

The closed loop is one discrete linear system (plant sampled exactly with its
delays, shift registers for the DAC's transport, the controller) driven by
exogenous noises; the converters' quantisation enters it as additive
uniform noise of one step (ADC on the reading, DAC on the command).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray
from scipy.signal import cont2discrete, tf2ss

from .bench import HV, IndBench
from .lti import DiscreteSS
from .plant import INPUTS, OUTPUTS, ContinuousPlant, SampledPlant

__all__ = [
    "CL_INPUTS",
    "CL_OUTPUTS",
    "REFERENCE_UC_TO_BEAM_RAD_PER_V",
    "ClosedLoop",
    "close_loop",
    "controller_multiplier",
    "seed_controller",
    "seed_controller_tf",
]

Array = NDArray[np.float64]

_DEG = math.pi / 180.0
REFERENCE_UC_TO_BEAM_RAD_PER_V = HV(
    -0.01275 / (28.4e-3 / _DEG) * 4.0,
    +0.01382 / (35.2e-3 / _DEG) * 4.0,
)

#: Exogenous inputs of the closed loop, in order.
CL_INPUTS = ("Unh_d", "Unv_d", "nu_a", "nu_b", "Unh_d1", "Unv_d1",
             "qd_noise_h", "qd_noise_v", "adc_h", "adc_v", "dac_h", "dac_v")
#: Outputs of the closed loop: the plant's outputs, then the DAC commands
#: (the controller's output before the DAC's quantisation).
CL_OUTPUTS = (*OUTPUTS, "Uch", "Ucv")


def seed_controller_tf(axis: str) -> tuple[Array, Array]:
    """Numerator and denominator of ``Kh`` or ``Kv`` (study 9.2), in ``s``, V/rad."""
    if axis == "h":
        num = -0.25598 * np.polymul([1.0, 112.0], [1.0, 15.93, 6.686e6])
        den = np.polymul(np.polymul([1.0, 0.0, 0.0], [1.0, 352.5]),
                         [1.0 / (2.0 * math.pi * 2000.0), 1.0])
    else:
        num = 10207.0 * np.polymul([1.0, 55.15], [1.0, 17.45, 2.491e6])
        den = np.polymul(np.polymul([1.0, 0.0, 0.0], [1.0, 491.2]), [1.0, 7695.0])
    return num, den


@lru_cache(maxsize=16)
def seed_controller(axis: str, fs_hz: float) -> DiscreteSS:
    """``Kh`` or ``Kv`` discretised by Tustin (no prewarping) at ``fs_hz``."""
    num, den = seed_controller_tf(axis)
    A, B, C, D = tf2ss(num, den)
    Ad, Bd, Cd, Dd, _ = cont2discrete((A, B, C, D), 1.0 / fs_hz, method="bilinear")
    return DiscreteSS(Ad, Bd, Cd, Dd, 1.0 / fs_hz)


def controller_multiplier(plant: ContinuousPlant, gd_v_per_rad: HV) -> HV:
    """Per-axis factor (sign included) making the static loop gain the seed's.

    Parameters
    ----------
    plant : ContinuousPlant
        The bench's analog model.
    gd_v_per_rad : HV
        The 4QD gains the experimenter divides by [V/rad], signed.
    """
    G = plant.dc_gain()
    out = []
    for j, ax in enumerate(("h", "v")):
        bench_gain = G[OUTPUTS.index("Vph") + j, INPUTS.index("Uch") + j] / getattr(
            gd_v_per_rad, ax)
        out.append(getattr(REFERENCE_UC_TO_BEAM_RAD_PER_V, ax) / bench_gain)
    return HV(*out)


@dataclass(frozen=True)
class ClosedLoop:
    """The closed loop as one discrete system (inputs ``CL_INPUTS``, outputs ``CL_OUTPUTS``).

    Parameters
    ----------
    system : DiscreteSS
        The loop.
    multiplier : HV
        Controller multiplier per axis (sign included).
    gd_v_per_rad : HV
        The 4QD gains the controller divides by [V/rad].
    """

    system: DiscreteSS
    multiplier: HV
    gd_v_per_rad: HV

    @property
    def max_pole_abs(self) -> float:
        """Largest pole modulus (below 1: stable)."""
        return float(np.abs(self.system.poles).max())


def close_loop(bench: IndBench, sampled: SampledPlant, multiplier: HV,
               gd_v_per_rad: HV) -> ClosedLoop:
    """Close the study's diagonal loop around the sampled plant.

    Parameters
    ----------
    bench : IndBench
        The bench (its rate).
    sampled : SampledPlant
        The plant sampled with its delays (built without the Vc monitors is enough).
    multiplier : HV
        Factor on each controller, sign included.
    gd_v_per_rad : HV
        The calibrated 4QD gains the controller divides by [V/rad].
    """
    Phi, Gb, Ga = sampled.Phi, sampled.Gb, sampled.Ga
    Cp = sampled.system.C
    npl = Phi.shape[0]
    n_c = int(sampled.n_whole[0])
    frac = bool(sampled.fractional[0] or sampled.fractional[1])
    n_reg = n_c + (1 if frac else 0)  # registers hold u[k-1] ... u[k-n_reg]
    ks = [seed_controller(ax, bench.fs_hz) for ax in ("h", "v")]
    nk = [k.A.shape[0] for k in ks]
    n = npl + 2 * n_reg + sum(nk)
    m = len(CL_INPUTS)
    A = np.zeros((n, n))
    B = np.zeros((n, m))
    C = np.zeros((len(CL_OUTPUTS), n))
    D = np.zeros((len(CL_OUTPUTS), m))
    reg = npl  # register (l, axis j) at reg + 2 (l - 1) + j
    k0 = npl + 2 * n_reg
    # Reading R = (Vp + qd noise + adc) / Gd, as rows over (state, input).
    gd = np.array([gd_v_per_rad.h, gd_v_per_rad.v])
    mu = np.array([multiplier.h, multiplier.v])
    rx = Cp[0:2] / gd[:, None]
    rw = np.zeros((2, m))
    for j in range(2):
        rw[j, CL_INPUTS.index("qd_noise_h") + j] = 1.0 / gd[j]
        rw[j, CL_INPUTS.index("adc_h") + j] = 1.0 / gd[j]
    # Command u = -mu K(R) (+ DAC noise in the loop), as rows over (state, input).
    ux = np.zeros((2, n))
    uw = np.zeros((2, m))
    off = k0
    for j, k in enumerate(ks):
        sl = slice(off, off + nk[j])
        # controller state update: xk+ = Ak xk + Bk R
        A[sl, sl] = k.A
        A[sl, :npl] += k.B[:, 0:1] * rx[j]
        B[sl, :] += k.B[:, 0:1] * rw[j]
        ux[j, sl] = -mu[j] * k.C[0]
        ux[j, :npl] += -mu[j] * k.D[0, 0] * rx[j]
        uw[j] = -mu[j] * k.D[0, 0] * rw[j]
        off += nk[j]
    u_in = ux.copy(), uw.copy()
    for j in range(2):
        uw[j, CL_INPUTS.index("dac_h") + j] += 1.0
    # Plant update: Phi x + Gb u[k - n_c] + Ga u[k - n_c - 1] + exogenous columns.
    A[:npl, :npl] = Phi
    for j in range(2):
        A[:npl, reg + 2 * (n_c - 1) + j] += Gb[:, j]
        if frac:
            A[:npl, reg + 2 * n_c + j] += Ga[:, j]
    ex = {"Unh_d": Gb[:, 2], "Unv_d": Gb[:, 3], "nu_a": Gb[:, 4], "nu_b": Gb[:, 5],
          "Unh_d1": Ga[:, 2], "Unv_d1": Ga[:, 3]}
    for name, col in ex.items():
        B[:npl, CL_INPUTS.index(name)] = col
    # Registers: r1+ = u[k], r_l+ = r_{l-1}.
    for j in range(2):
        A[reg + j, :] = ux[j]
        B[reg + j, :] = uw[j]
        for lag in range(2, n_reg + 1):
            A[reg + 2 * (lag - 1) + j, reg + 2 * (lag - 2) + j] = 1.0
    C[: len(OUTPUTS), :npl] = Cp
    C[len(OUTPUTS):] = u_in[0]
    D[len(OUTPUTS):] = u_in[1]
    return ClosedLoop(DiscreteSS(A, B, C, D, bench.dt_s), multiplier, gd_v_per_rad)
