"""Closed-loop step and disturbance responses of a Sercalo controller, in time and frequency.

What a control engineer reads beside the margins: how the beam angle follows
a step of its reference, and how it rejects a step of the sample motion (the
Newport's rotation, the bench's disturbance). The loop is ``u = K (r - y)``
around the plant path ``Uch, Ucv -> Rh, Rv``; the Newport command ``Un``
enters through ``Gn``. Both axes are closed together (the MIMO loop).

* Frequency: ``T = (I + G K)^-1 G K`` and ``S Gn`` with the plant's delays
  exact (as :func:`fsmbench.control.loops.analyse_loop`).
* Time: the same loop with the delays as Padé approximants, closed by
  state-space algebra and integrated exactly for a step input (zero-order
  hold of the continuous closed loop on the time grid).

The final values are the closed-loop DC gains (``T(0)`` and ``(S Gn)(0)``),
stated beside the curves.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import control as ct
import numpy as np
from scipy.linalg import expm, matrix_balance

from fsmbench.bench.blocks import PlantModel
from fsmbench.control.freq import loop_response, plant_response
from fsmbench.control.loops import delayed_subsystem

__all__ = ["ClosedLoopResponses", "closed_loop_responses", "closed_loop_ss"]


@dataclass(frozen=True, eq=False)
class ClosedLoopResponses:
    """Step and disturbance responses of one controller closed around the plant.

    Column ``i`` of each array is axis ``i`` (h, v): the response of ``R_i``
    to a step on the same axis' input, with both loops closed.

    Attributes
    ----------
    name : str
        The controller, in words.
    t_s : numpy.ndarray, shape (n_t,)
        Time after the step [s], from 0.
    reference_step : numpy.ndarray, shape (n_t, 2)
        Beam angle ``R_i`` after a unit step of the reference ``r_i`` [1]
        (rad per rad).
    disturbance_step_rad_per_v : numpy.ndarray, shape (n_t, 2)
        Beam angle ``R_i`` after a 1 V step of the Newport command ``Un_i``,
        Sercalo loop closed [rad/V].
    open_disturbance_step_rad_per_v : numpy.ndarray, shape (n_t, 2)
        The same step with the Sercalo loop open [rad/V].
    f_hz : numpy.ndarray, shape (n_f,)
        Frequencies [Hz].
    complementary : numpy.ndarray, complex, shape (n_f, 2)
        ``T_ii``, reference to beam angle [1], delays exact.
    disturbance_rad_per_v : numpy.ndarray, complex, shape (n_f, 2)
        ``(S Gn)_ii``, Newport command to beam angle, loop closed [rad/V].
    reference_final : numpy.ndarray, shape (2,)
        ``T_ii(0)``, the reference step's final value [1].
    disturbance_final_rad_per_v : numpy.ndarray, shape (2,)
        ``(S Gn)_ii(0)``, the disturbance step's final value [rad/V].
    pade_order : int
        Order of the delays' Padé approximants in the time responses.
    """

    name: str
    t_s: np.ndarray = field(repr=False)
    reference_step: np.ndarray = field(repr=False)
    disturbance_step_rad_per_v: np.ndarray = field(repr=False)
    open_disturbance_step_rad_per_v: np.ndarray = field(repr=False)
    f_hz: np.ndarray = field(repr=False)
    complementary: np.ndarray = field(repr=False)
    disturbance_rad_per_v: np.ndarray = field(repr=False)
    reference_final: np.ndarray
    disturbance_final_rad_per_v: np.ndarray
    pade_order: int = 6

    def overshoot(self) -> np.ndarray:
        """Peak of the reference step above its final value, per axis [1] (0.1 = 10 %)."""
        return np.asarray(np.max(self.reference_step, axis=0) / self.reference_final - 1.0)


def closed_loop_ss(plant: PlantModel, k: ct.StateSpace, *,
                   disturbances: Sequence[str] = ("Unh", "Unv"),
                   pade_order: int = 6) -> ct.StateSpace:
    """Rational closed loop ``[r, Un] -> R`` of ``u = K (r - y)``, delays as Padé approximants.

    Parameters
    ----------
    plant : PlantModel
    k : control.StateSpace
        Continuous controller ``R -> Uc`` (its input and output labels name the
        plant's signals).
    disturbances : sequence of str
        Plant inputs of the disturbance (the Newport commands) [V].
    pade_order : int

    Returns
    -------
    control.StateSpace
        Inputs ``r_1 … r_p`` then ``disturbances``; outputs ``k.input_labels``.
    """
    meas, cmds = list(k.input_labels), list(k.output_labels)
    g = delayed_subsystem(plant, outputs=meas, inputs=[*cmds, *disturbances],
                          pade_order=pade_order)
    m = len(cmds)
    a_g, b_g, c_g, d_g = (np.asarray(x, dtype=float) for x in (g.A, g.B, g.C, g.D))
    a_k, b_k, c_k, d_k = (np.asarray(x, dtype=float) for x in (k.A, k.B, k.C, k.D))
    b_u, b_d, d_u, d_d = b_g[:, :m], b_g[:, m:], d_g[:, :m], d_g[:, m:]
    p, n_g, n_k, n_d = len(meas), a_g.shape[0], a_k.shape[0], len(disturbances)
    # y = Cg x + Du u + Dd d, u = Ck xk + Dk (r - y): solve for y first.
    e = np.linalg.inv(np.eye(p) + d_u @ d_k)
    y_z = e @ np.hstack([c_g, d_u @ c_k])
    y_w = e @ np.hstack([d_u @ d_k, d_d])
    u_z = np.hstack([np.zeros((m, n_g)), c_k]) - d_k @ y_z
    u_w = np.hstack([d_k, np.zeros((m, n_d))]) - d_k @ y_w
    a = np.block([[a_g, np.zeros((n_g, n_k))], [np.zeros((n_k, n_g)), a_k]])
    a = a + np.vstack([b_u @ u_z, -b_k @ y_z])
    b = np.vstack([b_u @ u_w + np.hstack([np.zeros((n_g, p)), b_d]),
                   b_k @ np.hstack([np.eye(p), np.zeros((p, n_d))]) - b_k @ y_w])
    return ct.ss(a, b, y_z, y_w, inputs=[f"r_{n}" for n in meas] + list(disturbances),
                 outputs=meas)


def _step(sys: ct.StateSpace, t_s: np.ndarray) -> np.ndarray:
    """Unit-step response of every input to every output on uniform ``t_s``, (n_t, p, m).

    Exact for a step (zero-order hold): ``x[k+1] = Ad x[k] + Bd``. The state is
    balanced first (diagonal similarity): the plant's realisation in SI units
    spans ~30 decades, which ``expm`` would not resolve.
    """
    a, b, c, d = (np.asarray(x, dtype=float) for x in (sys.A, sys.B, sys.C, sys.D))
    a, (scale, _) = matrix_balance(a, permute=False, separate=True)
    b, c = b / scale[:, None], c * scale[None, :]
    n, m = b.shape
    dt = float(t_s[1] - t_s[0])
    blk = np.zeros((n + m, n + m))
    blk[:n, :n], blk[:n, n:] = a * dt, b * dt
    phi = expm(blk)
    a_d, b_d = phi[:n, :n], phi[:n, n:]
    x = np.zeros((n, m))
    out = np.empty((t_s.size, c.shape[0], m))
    for i in range(t_s.size):
        out[i] = c @ x + d
        x = a_d @ x + b_d
    return out


def closed_loop_responses(plant: PlantModel, k: ct.StateSpace, *, name: str,
                          f_hz: np.ndarray, duration_s: float = 0.5, dt_s: float = 1e-4,
                          disturbances: Sequence[str] = ("Unh", "Unv"),
                          pade_order: int = 6) -> ClosedLoopResponses:
    """Step and disturbance responses of ``k`` closed around ``plant`` (see the module).

    Parameters
    ----------
    plant : PlantModel
    k : control.StateSpace
        Continuous controller ``Rh, Rv -> Uch, Ucv``.
    name : str
        The controller, in words.
    f_hz : numpy.ndarray, shape (n_f,)
        Frequencies of the frequency responses [Hz].
    duration_s : float
        Length of the time responses [s].
    dt_s : float
        Their time step [s] (the loop's sampling period by default).
    disturbances : sequence of str
        The Newport commands [V].
    pade_order : int

    Returns
    -------
    ClosedLoopResponses
    """
    if duration_s <= 0 or dt_s <= 0:
        raise ValueError("duration_s and dt_s must be positive")
    p = len(k.input_labels)
    t = np.arange(round(duration_s / dt_s) + 1) * dt_s
    cl = closed_loop_ss(plant, k, disturbances=disturbances, pade_order=pade_order)
    steps = _step(cl, t)
    diag = np.arange(p)
    gn = delayed_subsystem(plant, outputs=list(k.input_labels), inputs=list(disturbances),
                           pade_order=pade_order)
    open_steps = _step(gn, t)
    s = 2j * np.pi * np.asarray(f_hz, dtype=float)
    lmat = loop_response(plant, k, s)
    sens = np.linalg.inv(np.eye(p)[None] + lmat)
    comp = lmat @ sens
    dist = sens @ plant_response(plant, s, outputs=list(k.input_labels),
                                 inputs=list(disturbances))
    dc = np.asarray(cl.dcgain(), dtype=float).reshape(p, -1)
    return ClosedLoopResponses(
        name=name, t_s=t, reference_step=steps[:, diag, diag],
        disturbance_step_rad_per_v=steps[:, diag, p + diag],
        open_disturbance_step_rad_per_v=open_steps[:, diag, diag],
        f_hz=np.asarray(f_hz, dtype=float), complementary=comp[:, diag, diag],
        disturbance_rad_per_v=dist[:, diag, diag], reference_final=dc[diag, diag],
        disturbance_final_rad_per_v=dc[diag, p + diag], pade_order=pade_order)
