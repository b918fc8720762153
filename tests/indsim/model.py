"""Everything computed once per bench: sampled plant, closed loop, noise scalings."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import solve_discrete_lyapunov

from .bench import HV, IndBench
from .control import ClosedLoop, close_loop, controller_multiplier
from .plant import INPUTS, OUTPUTS, ContinuousPlant, SampledPlant, build_plant, sample_plant

__all__ = ["BenchModel", "bench_model", "output_rms_per_unit_input", "qd_amp_response",
           "qd_gain_calibrated"]

Array = NDArray[np.float64]


def qd_gain_calibrated(bench: IndBench) -> HV:
    """What a single-axis calibration measures: signed ``g cos θ`` per axis [V/rad].

    The Newport metrology reads ``psi`` exactly and the beam moves by
    ``newport_beam_factor * psi`` (2, as the study assumes), so the slope of
    ``Vph`` on the beam angle ``2 gn0 Vnh`` is the diode's ``u`` gain times
    ``cos θ`` (and ``newport_beam_factor / 2``, which is 1 unless changed).
    """
    c = math.cos(bench.qd_rotation_rad) * bench.newport_beam_factor / 2.0
    c *= bench.newport_metrology_rad_per_v / 2.62e-3
    return HV(bench.qd_polarity.h * bench.qd_gain_v_per_rad.h * c,
              bench.qd_polarity.v * bench.qd_gain_v_per_rad.v * c)


def output_rms_per_unit_input(sampled: SampledPlant, input_name: str) -> Array:
    """Stationary rms of every output for a white input of unit rms (exact).

    The fractional delay feeds ``u[k-n]`` and ``u[k-n-1]``: one register
    ``r[k] = u[k-n-1]`` makes the driven state Markov, and the discrete
    Lyapunov equation gives the covariance.
    """
    j = INPUTS.index(input_name)
    Phi, Gb, Ga = sampled.Phi, sampled.Gb[:, j], sampled.Ga[:, j]
    n = Phi.shape[0]
    A = np.zeros((n + 1, n + 1))
    A[:n, :n] = Phi
    A[:n, n] = Ga
    Bv = np.concatenate([Gb, [1.0]])[:, None]
    P = solve_discrete_lyapunov(A, Bv @ Bv.T)
    C = np.hstack([sampled.system.C, np.zeros((sampled.system.C.shape[0], 1))])
    return np.sqrt(np.clip(np.einsum("ij,jk,ik->i", C, P, C), 0.0, None))


def qd_amp_response(bench: IndBench, f_hz: Array) -> Array | None:
    """The 4QD amplifier's continuous response at ``f_hz`` (None without one) [1].

    It carries the compression's residual (:func:`indsim.experiments`): applied
    line by line to the sampled ``d³``, which is exact for a ``d³`` band-limited
    below Nyquist. A ZOH-sampled amplifier would lag that residual by half a
    sample and droop it by ``sinc(f/fs)``: a shape the plant does not have, which
    moved an over-damped Newport's fitted frequency by +0.4 Hz (1.3 of its std)
    on ``qd_amp2_5k``.
    """
    if bench.qd_amp_order == 0:
        return None
    s = 2j * math.pi * np.asarray(f_hz, dtype=float)
    w = 2.0 * math.pi * bench.qd_amp_bandwidth_hz
    if bench.qd_amp_order == 1:
        return w / (s + w)
    z = bench.qd_amp_damping_ratio
    return w * w / (s * s + 2.0 * z * w * s + w * w)


@dataclass(frozen=True)
class BenchModel:
    """A bench with its models.

    Parameters
    ----------
    bench : IndBench
        The parameters.
    plant : ContinuousPlant
        The analog bench with the Vc monitors.
    sampled : SampledPlant
        ``plant`` sampled exactly at ``fs`` with its delays.
    gd_v_per_rad : HV
        The 4QD gains the experimenter calibrated (signed ``g cos θ``) [V/rad].
    closed : ClosedLoop
        The study's 9.2 loop on this bench, with the experimenter's multiplier.
    nu_per_rad : HV
        Rms of the held white noise ``nu`` per rad of Newport angle-noise rms.
    cl_sampled : SampledPlant
        The plant without the Vc monitors, sampled: what the loop is closed around.
    """

    bench: IndBench
    plant: ContinuousPlant
    sampled: SampledPlant
    gd_v_per_rad: HV
    closed: ClosedLoop
    nu_per_rad: HV
    cl_sampled: SampledPlant


def bench_model(bench: IndBench) -> BenchModel:
    """Build and check every model of ``bench`` (raises if its closed loop is unstable)."""
    plant = build_plant(bench)
    sampled = sample_plant(plant, bench.dt_s)
    gd = qd_gain_calibrated(bench)
    cl_plant = sample_plant(build_plant(bench, with_vc=False), bench.dt_s)
    mu = controller_multiplier(plant, gd)
    closed = close_loop(bench, cl_plant, mu, gd)
    if not closed.max_pole_abs < 1.0:
        raise ValueError(f"bench {bench.name!r}: the study's loop is unstable on it "
                         f"(largest pole modulus {closed.max_pole_abs:.6f})")
    nu = []
    for j, ax in enumerate(("a", "b")):
        rms = output_rms_per_unit_input(sampled, f"nu_{ax}")[OUTPUTS.index("psi_a") + j]
        nu.append(1.0 / rms)
    return BenchModel(bench, plant, sampled, gd, closed, HV(*nu), cl_plant)
