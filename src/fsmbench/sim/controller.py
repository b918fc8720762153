"""Controllers wired into the twin, and the stability check of its loop."""

from __future__ import annotations

from collections.abc import Sequence

import control as ct
import numpy as np

from fsmbench.bench.esrf import tustin
from fsmbench.bench.params import PerAxis
from fsmbench.sim.discretize import DiscretePlant
from fsmbench.sim.engine import DiscreteController
from fsmbench.sim.plant import ADC_CHANNELS, DAC_CHANNELS

__all__ = ["closed_loop_spectral_radius", "feedback_controller", "sercalo_discrete",
           "sercalo_feedback"]


def feedback_controller(k: ct.StateSpace, *, gd_v_per_rad: PerAxis, ts_s: float,
                        name: str = "K") -> DiscreteController:
    """Wire a controller ``K: [Rh, Rv] -> [Uch, Ucv]`` into the twin as ``u = -K R``.

    Parameters
    ----------
    k : control.StateSpace
        Continuous (discretised here by Tustin at ``ts_s``) or already discrete
        with sampling time ``ts_s``; inputs ``Rh, Rv`` [rad], outputs ``Uch, Ucv`` [V].
    gd_v_per_rad : PerAxis
        4QD gains the real-time code divides by to get radians (the calibrated
        ones, not the twin's truth).
    ts_s : float
        Controller sampling period [s].
    """
    kd = sercalo_discrete(k, ts_s=ts_s)
    return sercalo_feedback(a=kd.A, b=kd.B, c=kd.C, d=kd.D,
                            gd_v_per_rad=tuple(gd_v_per_rad.as_array()), name=name)


def sercalo_discrete(k: ct.StateSpace, *, ts_s: float) -> ct.StateSpace:
    """``K: [Rh, Rv] -> [Uch, Ucv]`` discrete at ``ts_s``: Tustin of a continuous ``k``,
    or ``k`` itself when it is sampled at ``ts_s`` already.

    Raises
    ------
    ValueError
        ``k`` maps other signals, or is sampled at another rate.
    """
    if list(k.input_labels) != ["Rh", "Rv"] or list(k.output_labels) != ["Uch", "Ucv"]:
        raise ValueError(f"controller must map Rh, Rv to Uch, Ucv; got {k.input_labels} -> "
                         f"{k.output_labels}")
    if k.dt == 0 or k.dt is None:
        return tustin(k, ts_s=ts_s)
    if not np.isclose(k.dt, ts_s):
        raise ValueError(f"controller sampled at {k.dt} s, twin runs at {ts_s} s")
    return k


def sercalo_feedback(*, a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray,
                     gd_v_per_rad: Sequence[float], name: str) -> DiscreteController:
    """A discrete ``K: [Rh, Rv] -> [Uch, Ucv]`` wired as the real-time code runs it.

    The code reads ``Vph, Vpv``, divides by the calibrated 4QD gains to get the
    beam angle ``R`` and commands ``u = -K R``.

    Parameters
    ----------
    a, b, c, d : arrays (n, n), (n, 2), (2, n), (2, 2)
        Discrete ``K`` at the converter rate, beam angle [rad] to command [V].
    gd_v_per_rad : (float, float)
        Calibrated 4QD gains (h, v) [V/rad].
    name : str
    """
    scale = np.diag(1.0 / np.asarray(gd_v_per_rad, dtype=float))
    return DiscreteController(
        a=np.asarray(a, dtype=float), b=np.asarray(b, dtype=float) @ scale,
        c=-np.asarray(c, dtype=float), d=-np.asarray(d, dtype=float) @ scale,
        adc_inputs=(ADC_CHANNELS.index("Vph"), ADC_CHANNELS.index("Vpv")),
        dac_outputs=(DAC_CHANNELS.index("Uch"), DAC_CHANNELS.index("Ucv")), name=name)


def closed_loop_spectral_radius(plant: DiscretePlant, controller: DiscreteController, *,
                                n_adc: int) -> float:
    """Largest |eigenvalue| of the linear closed loop (converters ideal).

    Below 1 means the twin's loop is stable. The engine's ordering is
    respected: the controller reads ``y[k] = C z[k]`` and its output enters
    the plant in the same step.
    """
    a, b, c = plant.a, plant.b, plant.c[:n_adc]
    nz, nk = a.shape[0], controller.a.shape[0]
    sel_in = np.zeros((len(controller.adc_inputs), n_adc))
    sel_in[np.arange(len(controller.adc_inputs)), controller.adc_inputs] = 1.0
    sel_out = np.zeros((b.shape[1], len(controller.dac_outputs)))
    sel_out[controller.dac_outputs, np.arange(len(controller.dac_outputs))] = 1.0
    e_from_z = sel_in @ c
    big = np.zeros((nz + nk, nz + nk))
    big[:nz, :nz] = a + b @ sel_out @ controller.d @ e_from_z
    big[:nz, nz:] = b @ sel_out @ controller.c
    big[nz:, :nz] = controller.b @ e_from_z
    big[nz:, nz:] = controller.a
    return float(np.max(np.abs(np.linalg.eigvals(big))))
