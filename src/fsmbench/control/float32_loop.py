"""Is the twin's loop still stable with the exported controller rounded to float32?

The export's own check (:mod:`fsmbench.control.export_check`) compares
responses without a plant. Here the plant is the twin's: the controller's
coefficients are rounded to float32 in each exported form, the closed loop
is built as the engine closes it
(:func:`fsmbench.sim.controller.closed_loop_spectral_radius`, converters
ideal) and its poles are compared with the float64 loop's: the largest modulus
(below 1: stable) and the largest move of any pole (each float32 pole matched to
a float64 one by an optimal assignment).

* ``sos``: each channel's sections (:func:`fsmbench.control.export.discretise_channel`),
  rounded, realised in direct form II transposed
  (:func:`fsmbench.control.antiwindup.df2t_cascade`) as a target runs them;
* ``state_space``: ``controllers.mat``'s ``Kd``
  (:func:`fsmbench.control.export.discretise`), its ``A, B, C, D`` rounded.

Only the coefficients are rounded; the eigenvalues are computed in float64.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import control as ct
import numpy as np
from scipy.optimize import linear_sum_assignment

from fsmbench.bench.params import Bench
from fsmbench.control.antiwindup import df2t_cascade
from fsmbench.control.export import DEFAULT_DISCRETISATION, discretise, discretise_channel
from fsmbench.control.export_check import float32_sos_check, float32_state_space_check
from fsmbench.sim.closed_loop import closed_loop_plant
from fsmbench.sim.controller import sercalo_feedback
from fsmbench.sim.plant import ADC_CHANNELS, bench_discrete

__all__ = ["Float32Loop", "float32_closed_loop"]


@dataclass(frozen=True)
class Float32Loop:
    """Largest closed-loop pole modulus on the twin, float64 against float32 coefficients.

    Attributes
    ----------
    name : str
        The controller, in words.
    radius_float64 : float
        With the sections in float64 [1] (below 1: stable).
    radius_float32_sos : float
        With the sections rounded to float32 [1].
    radius_float32_state_space : float
        With ``controllers.mat``'s ``Kd`` rounded to float32 [1].
    pole_shift_sos, pole_shift_state_space : float
        Largest distance in the z-plane between a float32 closed-loop pole and
        its float64 counterpart [1].
    response_error_sos, response_error_state_space : dict of str to float
        The export's own check per axis (``h``, ``v``): largest relative
        response error of the float32 form
        (:mod:`fsmbench.control.export_check`) [1].
    """

    name: str
    radius_float64: float
    radius_float32_sos: float
    radius_float32_state_space: float
    pole_shift_sos: float
    pole_shift_state_space: float
    response_error_sos: dict[str, float]
    response_error_state_space: dict[str, float]

    @property
    def sos_stable(self) -> bool:
        """The float32 sections keep the twin's loop stable."""
        return self.radius_float32_sos < 1.0

    @property
    def state_space_stable(self) -> bool:
        """The float32 ``Kd`` keeps the twin's loop stable."""
        return self.radius_float32_state_space < 1.0

    def to_json(self) -> dict[str, Any]:
        """Plain numbers."""
        return {"controller": self.name, "radius_float64": self.radius_float64,
                "radius_float32_sos": self.radius_float32_sos,
                "radius_float32_state_space": self.radius_float32_state_space,
                "pole_shift_sos": self.pole_shift_sos,
                "pole_shift_state_space": self.pole_shift_state_space,
                "response_error_sos": dict(self.response_error_sos),
                "response_error_state_space": dict(self.response_error_state_space),
                "sos_stable": self.sos_stable, "state_space_stable": self.state_space_stable}


def _f32(x: Any) -> np.ndarray:
    return np.asarray(x, dtype=float).astype(np.float32).astype(float)


def _sections_controller(k: ct.StateSpace, *, ts_s: float, method: str,
                         rounded: bool) -> tuple[np.ndarray, ...]:
    parts = []
    for i in range(2):
        sos = np.array([s.sos for s in discretise_channel(k, ts_s=ts_s, output=i, input=i,
                                                          method=method)])
        parts.append(df2t_cascade(_f32(sos) if rounded else sos))
    n = [p[0].shape[0] for p in parts]
    a = np.zeros((sum(n), sum(n)))
    b = np.zeros((sum(n), 2))
    c = np.zeros((2, sum(n)))
    d = np.zeros((2, 2))
    at = 0
    for i, (ai, bi, ci, di) in enumerate(parts):
        sl = slice(at, at + n[i])
        a[sl, sl], b[sl, i], c[i, sl], d[i, i] = ai, bi[:, 0], ci[0], di[0, 0]
        at += n[i]
    return a, b, c, d


def float32_closed_loop(bench: Bench, k: ct.StateSpace, *, name: str,
                        method: str = DEFAULT_DISCRETISATION) -> Float32Loop:
    """Closed-loop pole radius on ``bench``'s twin with ``k`` in float64 and rounded to float32.

    Parameters
    ----------
    bench : Bench
        The twin (true plant, nominal 4QD gains).
    k : control.StateSpace
        Continuous diagonal ``Rh, Rv`` [rad] to ``Uch, Ucv`` [V].
    name : str
        The controller, in words.
    method : str
        Discretisation (:data:`fsmbench.control.export.DISCRETISATIONS`).
    """
    ts = bench.true.converter.ts_s
    plant = bench_discrete(bench)
    gd_nom = bench.nominal.quad_diode.gain_v_per_rad
    gd = (float(gd_nom.h), float(gd_nom.v))
    n_adc = len(ADC_CHANNELS)

    def poles(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray) -> np.ndarray:
        fb = sercalo_feedback(a=a, b=b, c=c, d=d, gd_v_per_rad=gd, name=name)
        return np.linalg.eigvals(closed_loop_plant(plant, fb, n_adc=n_adc).a)

    def shift(p64: np.ndarray, p32: np.ndarray) -> float:
        rows, cols = linear_sum_assignment(np.abs(p64[:, None] - p32[None, :]))
        return float(np.max(np.abs(p64[rows] - p32[cols])))

    kd = discretise(k, ts_s=ts, method=method)
    p64 = poles(*_sections_controller(k, ts_s=ts, method=method, rounded=False))
    p32 = poles(*_sections_controller(k, ts_s=ts, method=method, rounded=True))
    # Kd's own float64 loop: another realisation of the same controller, compared to itself.
    q64 = poles(*(np.asarray(x, dtype=float) for x in (kd.A, kd.B, kd.C, kd.D)))
    q32 = poles(*(_f32(x) for x in (kd.A, kd.B, kd.C, kd.D)))
    err_sos = {axis: float32_sos_check(
        np.array([s.sos for s in discretise_channel(k, ts_s=ts, output=i, input=i,
                                                    method=method)]),
        ts_s=ts).max_relative_error for i, axis in enumerate(("h", "v"))}
    a, b, c, d = (np.asarray(x, dtype=float) for x in (kd.A, kd.B, kd.C, kd.D))
    err_ss = {axis: float32_state_space_check(a, b[:, [i]], c[[i]], d[[i]][:, [i]],
                                              ts_s=ts).max_relative_error
              for i, axis in enumerate(("h", "v"))}
    return Float32Loop(name=name, radius_float64=float(np.max(np.abs(p64))),
                       radius_float32_sos=float(np.max(np.abs(p32))),
                       radius_float32_state_space=float(np.max(np.abs(q32))),
                       pole_shift_sos=shift(p64, p32), pole_shift_state_space=shift(q64, q32),
                       response_error_sos=err_sos, response_error_state_space=err_ss)
