"""Closed-loop verification of a controller on a plant with delays (ESRF study 9.2, 10.2).

:func:`analyse_loop` closes ``u = -K y`` around the plant path from the
controller's outputs to its inputs (``Uch, Ucv -> Rh, Rv`` for the Sercalo
loop, ``Unh, Unv -> Rh, Rv`` for the Newport loop of 10.2) and reports:

* closed-loop poles with the delays replaced by Padé approximants (the only
  place a rational model is needed), and as a second opinion the generalised
  Nyquist count of ``det(I + L)`` with the exact delays;
* per axis (``L_ii``, the loop the ESRF study draws in Fig. 41): gain, phase and
  modulus margins, crossover, ``|S(j 2 pi f0)|`` and the 6.1 objective;
* the MIMO sensitivity and complementary sensitivity, ``S + T = I``;
* the generalised stability margin ``b(G, K)`` on the Table 5-scaled loop;
* the Tustin-discretised controller against the continuous one below 1 kHz.

:func:`newport_to_beam` gives the Newport command to beam angle transfer with
the Sercalo loop closed (ESRF study Fig. 42).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import control as ct
import numpy as np
from scipy.linalg import eigvals

from fsmbench.bench.blocks import PlantModel, ResponseEvaluator
from fsmbench.bench.esrf import ESRF_TS_S, tustin
from fsmbench.control.analysis import ControlObjective
from fsmbench.control.freq import (
    Margins,
    NyquistCount,
    evaluate_ss,
    frequency_grid,
    loop_response,
    nyquist_count,
    plain_json,
    plant_response,
    siso_margins,
)

__all__ = [
    "AXES",
    "AxisLoop",
    "DiscreteComparison",
    "LoopAnalysis",
    "LoopOptions",
    "analyse_loop",
    "closed_loop_poles",
    "delayed_subsystem",
    "discrete_axis_margins",
    "loop_grid",
    "newport_to_beam",
]

AXES = ("h", "v")


@dataclass(frozen=True)
class LoopOptions:
    """Options of :func:`analyse_loop`.

    Attributes
    ----------
    pade_order : int
        Order of the Padé approximant of each input delay for the closed-loop poles.
    ts_s : float
        Sample time of the Tustin controller [s] (ESRF study 9.3: 1e-4 s).
    discrete_f_max_hz : float
        Upper frequency of the discrete/continuous comparison [Hz].
    f_min_hz, f_max_hz : float
        Range of the loop curves [Hz]; the curves and every conclusion drawn from
        them (margins, peaks) stop at the Nyquist frequency ``1 / (2 ts_s)`` of
        the sampled loop, whatever ``f_max_hz``.
    per_decade : int
        Log-grid density of the loop curves.
    gain_margin_min_db, phase_margin_min_deg : float
        Requirements for ``meets_margins`` (6 dB, 30°).
    """

    pade_order: int = 6
    ts_s: float = ESRF_TS_S
    discrete_f_max_hz: float = 1e3
    f_min_hz: float = 1e-2
    f_max_hz: float = 1e4
    per_decade: int = 100
    gain_margin_min_db: float = 6.0
    phase_margin_min_deg: float = 30.0


@dataclass(frozen=True)
class AxisLoop:
    """One diagonal loop ``L_ii = (G K)_ii``.

    Attributes
    ----------
    axis : str
        ``"h"`` or ``"v"``.
    measurement, command : str
        Controller input and output of this axis (e.g. ``Rh``, ``Uch``).
    stable : bool
        This loop alone closed is stable (Nyquist count, exact delay).
    margins : Margins
    sensitivity_at_f0 : float
        ``|1 / (1 + L_ii)|`` at the objective frequency [1].
    loop_gain_at_f0 : float
        ``|L_ii|`` there [1].
    meets_objective : bool
        ``sensitivity_at_f0`` below the 6.1 bound.
    """

    axis: str
    measurement: str
    command: str
    stable: bool
    margins: Margins
    sensitivity_at_f0: float
    loop_gain_at_f0: float
    meets_objective: bool

    def to_json(self) -> dict[str, Any]:
        """``stable, gain_margin_db, phase_margin_deg, modulus_margin, crossover_hz,
        sensitivity_at_1hz`` and the rest of the margins."""
        m = self.margins
        return plain_json({
            "stable": self.stable, "gain_margin_db": m.gain_margin_db,
            "phase_margin_deg": m.phase_margin_deg, "modulus_margin": m.modulus_margin,
            "crossover_hz": m.crossover_hz, "sensitivity_at_1hz": self.sensitivity_at_f0,
            "loop_gain_at_1hz": self.loop_gain_at_f0, "meets_objective": self.meets_objective,
            "gain_reduction_margin_db": m.gain_reduction_margin_db,
            "phase_crossover_hz": m.phase_crossover_hz, "crossovers_hz": m.crossovers_hz,
            "modulus_frequency_hz": m.modulus_frequency_hz,
            "measurement": self.measurement, "command": self.command,
        })


@dataclass(frozen=True, eq=False)
class DiscreteComparison:
    """Tustin controller ``Kd`` against ``K`` below ``f_max_hz``.

    Attributes
    ----------
    kd : control.StateSpace
        The discretised controller (``dt = ts_s``).
    ts_s, f_max_hz : float
        Sample time [s] and comparison range [Hz].
    max_relative_error : float
        ``max |Kd(e^{jwT}) - K(jw)| / |K(jw)|`` over the diagonal, ``f <= f_max_hz``.
        Tustin maps ``K(j w_a)`` to ``w = (2/T) atan(w_a T/2)`` exactly; the
        difference is that frequency warp, largest where ``K`` changes fastest
        (at a notch).
    max_warp : float
        ``tan(pi f T) / (pi f T) - 1`` at ``f_max_hz`` [1] (3.3 % at 1 kHz, 1e-4 s).
    notch_shifts_hz : tuple of (float, float)
        Lightly damped controller zeros (damping < 0.2): continuous frequency
        and where Tustin puts them [Hz].
    margins : dict axis -> Margins
        Of ``G(jw) Kd(e^{jwT})`` below the Nyquist frequency (the plant's
        input delays already hold the DAC's and the hold's lag).
    """

    kd: ct.StateSpace
    ts_s: float
    f_max_hz: float
    max_relative_error: float
    max_warp: float
    notch_shifts_hz: tuple[tuple[float, float], ...]
    margins: Mapping[str, Margins]

    def to_json(self) -> dict[str, Any]:
        """Scalars."""
        return plain_json({"ts_s": self.ts_s, "f_max_hz": self.f_max_hz,
                           "max_relative_error": self.max_relative_error,
                           "max_warp": self.max_warp,
                           "notch_shifts_hz": self.notch_shifts_hz,
                           "margins": {a: m.to_json() for a, m in self.margins.items()}})


@dataclass(frozen=True, eq=False)
class LoopAnalysis:
    """A controller closed around a plant: stability, margins, objective, curves.

    Attributes
    ----------
    name : str
    plant_source : str
    controller : control.StateSpace
    axes : dict axis -> AxisLoop
    poles : array, complex, shape (n,)
        Closed-loop poles [rad/s], delays as Padé approximants of ``pade_order``.
    stable : bool
        All ``poles`` in the open left half-plane.
    nyquist : NyquistCount
        Second opinion with the exact delays.
    sensitivity_at_f0 : float
        ``sigma_max(S(j 2 pi f0))`` [1], the MIMO objective value.
    sensitivity_peak : float
        ``max_f sigma_max(S)`` on the grid [1].
    identity_error : float
        ``max |S + T - I|`` on the grid (rounding only).
    generalized_stability_margin : float
        ``b(G, K) = 1 / max sigma_max([I; K] S [I, G])`` on the scaled loop
        (``scaling``) [1]; 0 if unstable. Compare with the plant's ``b_max``.
    meets_objective : bool
        Stable and ``sensitivity_at_f0`` below the 6.1 bound.
    meets_margins : bool
        Every axis: stable, gain margin and phase margin above the requirements.
    objective : ControlObjective
    f_hz : array, shape (n,)
    loop, sensitivity, complementary : arrays, complex, shape (n, p, p)
        ``L = G K``, ``S``, ``T`` on ``f_hz``.
    discrete : DiscreteComparison
    pade_order : int
    nyquist_hz : float
        Nyquist frequency of the sampled loop, ``1 / (2 ts_s)`` [Hz]: ``f_hz``
        ends there.
    """

    name: str
    plant_source: str
    controller: ct.StateSpace
    axes: Mapping[str, AxisLoop]
    poles: np.ndarray
    stable: bool
    nyquist: NyquistCount
    sensitivity_at_f0: float
    sensitivity_peak: float
    identity_error: float
    generalized_stability_margin: float
    meets_objective: bool
    meets_margins: bool
    objective: ControlObjective
    f_hz: np.ndarray = field(repr=False)
    loop: np.ndarray = field(repr=False)
    sensitivity: np.ndarray = field(repr=False)
    complementary: np.ndarray = field(repr=False)
    discrete: DiscreteComparison | None = None
    pade_order: int = 6
    nyquist_hz: float = 0.5 / ESRF_TS_S

    def to_json(self) -> dict[str, Any]:
        """``{h,v}.{stable, gain_margin_db, ...}``, ``stable``, ``meets_objective`` and more."""
        return plain_json({
            **{a: ax.to_json() for a, ax in self.axes.items()},
            "name": self.name, "plant": self.plant_source, "stable": self.stable,
            "max_pole_real_rad_s": float(np.max(self.poles.real)),
            "pade_order": self.pade_order, "nyquist": self.nyquist.to_json(),
            "meets_objective": self.meets_objective, "meets_margins": self.meets_margins,
            "sensitivity_at_1hz": self.sensitivity_at_f0,
            "sensitivity_peak": self.sensitivity_peak,
            "identity_error": self.identity_error,
            "generalized_stability_margin": self.generalized_stability_margin,
            "discrete": None if self.discrete is None else self.discrete.to_json(),
        })


def delayed_subsystem(plant: PlantModel, *, outputs: Sequence[str], inputs: Sequence[str],
                      pade_order: int = 6) -> ct.StateSpace:
    """Rational plant path ``inputs -> outputs`` with Padé approximants of the delays."""
    g = plant.with_pade(order=pade_order)
    out_idx = [list(g.output_labels).index(n) for n in outputs]
    in_idx = [list(g.input_labels).index(n) for n in inputs]
    return ct.ss(g.A, g.B[:, in_idx], g.C[out_idx, :], g.D[np.ix_(out_idx, in_idx)],
                 inputs=list(inputs), outputs=list(outputs))


def closed_loop_poles(plant: PlantModel, k: ct.StateSpace, *, pade_order: int = 6) -> np.ndarray:
    """Poles [rad/s] of ``u = -K y`` closed around the plant (delays as Padé approximants)."""
    g = delayed_subsystem(plant, outputs=list(k.input_labels), inputs=list(k.output_labels),
                          pade_order=pade_order)
    a_k, b_k, c_k, d_k = (np.asarray(x, dtype=float) for x in (k.A, k.B, k.C, k.D))
    a_g, b_g, c_g, d_g = (np.asarray(x, dtype=float) for x in (g.A, g.B, g.C, g.D))
    # y = Cg xg + Dg u, u = -(Ck xk + Dk y): well posed while I + Dk Dg is invertible. Both
    # have feedthrough when a controller read back from its SOS file (biproper) runs on a
    # plant whose Padé delays pass high frequencies through (a retune from a tuned file).
    loop = np.eye(d_k.shape[0]) + d_k @ d_g
    scale = max(1.0, float(np.linalg.norm(d_k, 2) * np.linalg.norm(d_g, 2)))
    if float(np.linalg.svd(loop, compute_uv=False)[-1]) < 1e-9 * scale:
        raise ValueError("algebraic loop: I + Dk Dg is singular (the controller's and the "
                         "plant's feedthrough cancel); the loop is not well posed")
    e = np.linalg.inv(loop)  # u = -e (Ck xk + Dk Cg xg)
    u_x = -e @ np.hstack([d_k @ c_g, c_k])
    y_x = np.hstack([c_g, np.zeros((c_g.shape[0], a_k.shape[0]))]) + d_g @ u_x
    a = np.block([[a_g, np.zeros((a_g.shape[0], a_k.shape[0]))],
                  [np.zeros((a_k.shape[0], a_g.shape[0])), a_k]])
    a = a + np.vstack([b_g @ u_x, b_k @ y_x])
    return np.linalg.eigvals(a)


def loop_grid(plant: PlantModel, k: ct.StateSpace, *, f_min_hz: float = 1e-2,
              f_max_hz: float = 1e4, per_decade: int = 100) -> np.ndarray:
    """Frequency grid [Hz] resolving the plant path's and the controller's resonances."""
    g = plant.subsystem(outputs=list(k.input_labels), inputs=list(k.output_labels))
    poles = np.concatenate([g.poles(), k.poles(), _zeros(k)])
    return frequency_grid(poles, f_min_hz=f_min_hz, f_max_hz=f_max_hz, per_decade=per_decade)


def _zeros(k: ct.StateSpace) -> np.ndarray:
    """Zeros of each diagonal channel (notches need grid points too)."""
    out = []
    for i in range(min(k.ninputs, k.noutputs)):
        a, b, c, d = (np.asarray(x, dtype=float) for x in (k.A, k.B[:, [i]], k.C[[i], :],
                                                           k.D[[i]][:, [i]]))
        if a.shape[0] == 0:
            continue
        n = a.shape[0]
        mat = np.block([[a, b], [c, d]])
        e = np.zeros_like(mat)
        e[:n, :n] = np.eye(n)
        z = eigvals(mat, e)
        out.append(z[np.isfinite(z)])
    return np.concatenate(out) if out else np.zeros(0, dtype=complex)


#: Where the margin functions are evaluated [Hz]: the loop grids' span (and beyond).
_CHECK_HZ = np.geomspace(1e-4, 1e5, 24)


def _axis_margins_fn(plant: PlantModel, k: ct.StateSpace, i: int,
                     kd: ct.StateSpace | None = None) -> Any:
    g_sub = plant.subsystem(outputs=list(k.input_labels), inputs=list(k.output_labels))
    tau = np.array([plant.input_delay_s.get(n, 0.0) for n in k.output_labels])
    s_check = 2j * np.pi * _CHECK_HZ
    # The root finders call this one frequency at a time: evaluators built once.
    g_eval = ResponseEvaluator(g_sub, check_points=s_check)
    k_eval = (ResponseEvaluator(k, check_points=s_check) if kd is None else
              ResponseEvaluator(kd, check_points=np.exp(s_check[0.5 / kd.dt > _CHECK_HZ]
                                                        * kd.dt)))

    def loop(f: np.ndarray) -> np.ndarray:
        s = 2j * np.pi * np.asarray(f, dtype=float).ravel()
        g = g_eval(s) * np.exp(-s[:, None, None] * tau[None, None, :])
        kk = k_eval(s) if kd is None else k_eval(np.exp(s * kd.dt))
        return np.einsum("fj,fj->f", g[:, i, :], kk[:, :, i])

    return loop


def analyse_loop(plant: PlantModel, k: ct.StateSpace, *, objective: ControlObjective,
                 name: str = "", scaling: tuple[Sequence[float], Sequence[float]] | None = None,
                 options: LoopOptions | None = None) -> LoopAnalysis:
    """Close ``u = -K y`` around ``plant`` and verify it.

    Parameters
    ----------
    plant : PlantModel
        Its path from ``k.output_labels`` to ``k.input_labels`` is the loop's plant.
    k : control.StateSpace
        Continuous controller, 2 inputs (measurements) and 2 outputs (commands).
    objective : ControlObjective
        The 6.1 bound at ``frequency_hz``.
    name : str
        Label for reports.
    scaling : (output_scales, input_scales), optional
        Scales of ``b(G, K)``: ``Gs = diag(1/e) G diag(u)``, ``Ks = diag(1/u) K diag(e)``
        (``e`` per measurement, ``u`` per command); default unscaled.
    options : LoopOptions, optional
    """
    opts = options or LoopOptions()
    meas, cmds = list(k.input_labels), list(k.output_labels)
    nyquist_hz = 0.5 / opts.ts_s  # the loop is sampled: nothing above this is its response
    f = loop_grid(plant, k, f_min_hz=opts.f_min_hz, f_max_hz=min(opts.f_max_hz, nyquist_hz),
                  per_decade=opts.per_decade)
    s = 2j * np.pi * f
    lmat = loop_response(plant, k, s)
    p = lmat.shape[1]
    sens = np.linalg.inv(np.eye(p)[None] + lmat)
    comp = lmat @ sens
    s0 = 2j * np.pi * np.array([objective.frequency_hz])
    l0 = loop_response(plant, k, s0)[0]
    sens0 = np.linalg.inv(np.eye(p) + l0)

    poles = closed_loop_poles(plant, k, pade_order=opts.pade_order)
    stable = bool(np.max(poles.real) < 0)
    g_sub = plant.subsystem(outputs=meas, inputs=cmds)
    ol_poles = np.concatenate([g_sub.poles(), k.poles()])
    nyq = nyquist_count(lambda x: np.linalg.det(np.eye(p)[None] + loop_response(plant, k, x)),
                        open_loop_poles=ol_poles)

    axes: dict[str, AxisLoop] = {}
    for i in range(p):
        fn = _axis_margins_fn(plant, k, i)

        def one_plus_l(x: np.ndarray, i: int = i) -> np.ndarray:
            return 1.0 + _siso_at(plant, k, i, x)

        count = nyquist_count(one_plus_l, open_loop_poles=np.concatenate([g_sub.poles(),
                                                              _channel(k, i).poles()]))
        m = siso_margins(fn, f, stable=count.stable)
        s_ii = float(abs(1.0 / (1.0 + l0[i, i])))
        axes[AXES[i]] = AxisLoop(axis=AXES[i], measurement=meas[i], command=cmds[i],
                                 stable=count.stable, margins=m, sensitivity_at_f0=s_ii,
                                 loop_gain_at_f0=float(abs(l0[i, i])),
                                 meets_objective=objective.met_by(s_ii))
    s_f0 = float(np.linalg.svd(sens0, compute_uv=False)[0])
    b_gk = _generalized_margin(plant, k, s, sens, scaling) if stable else 0.0
    discrete = _discrete(plant, k, f, opts)
    return LoopAnalysis(
        name=name, plant_source=plant.source, controller=k, axes=axes, poles=poles,
        stable=stable, nyquist=nyq, sensitivity_at_f0=s_f0,
        sensitivity_peak=float(np.max(np.linalg.svd(sens, compute_uv=False)[:, 0])),
        identity_error=float(np.max(np.abs(sens + comp - np.eye(p)[None]))),
        generalized_stability_margin=b_gk,
        meets_objective=stable and objective.met_by(s_f0),
        meets_margins=all(a.stable and a.margins.gain_margin_db >= opts.gain_margin_min_db
                          and a.margins.phase_margin_deg >= opts.phase_margin_min_deg
                          for a in axes.values()),
        objective=objective, f_hz=f, loop=lmat, sensitivity=sens, complementary=comp,
        discrete=discrete, pade_order=opts.pade_order, nyquist_hz=nyquist_hz)


def _channel(k: ct.StateSpace, i: int) -> ct.StateSpace:
    return ct.ss(k.A, k.B[:, [i]], k.C[[i], :], k.D[[i]][:, [i]])


def _siso_at(plant: PlantModel, k: ct.StateSpace, i: int, s: np.ndarray) -> np.ndarray:
    """``L_ii`` at complex ``s`` with only loop ``i`` closed (the others open)."""
    g = plant_response(plant, s, outputs=[k.input_labels[i]], inputs=list(k.output_labels))
    return np.einsum("fj,fj->f", g[:, 0, :], evaluate_ss(k, s)[:, :, i])


def _generalized_margin(plant: PlantModel, k: ct.StateSpace, s: np.ndarray, sens: np.ndarray,
                        scaling: tuple[Sequence[float], Sequence[float]] | None) -> float:
    e = np.ones(k.ninputs) if scaling is None else np.asarray(scaling[0], dtype=float)
    u = np.ones(k.noutputs) if scaling is None else np.asarray(scaling[1], dtype=float)
    g = plant_response(plant, s, outputs=list(k.input_labels),
                       inputs=list(k.output_labels)) * (u[None, None, :] / e[None, :, None])
    kk = evaluate_ss(k, s) * (e[None, None, :] / u[None, :, None])
    top = np.concatenate([sens, sens @ g], axis=2)
    bottom = np.concatenate([kk @ sens, kk @ sens @ g], axis=2)
    h = np.concatenate([top, bottom], axis=1)
    return float(1.0 / np.max(np.linalg.svd(h, compute_uv=False)[:, 0]))


def _discrete(plant: PlantModel, k: ct.StateSpace, f: np.ndarray,
              opts: LoopOptions) -> DiscreteComparison:
    ts = opts.ts_s
    kd = tustin(k, ts_s=ts)
    sel = f <= opts.discrete_f_max_hz
    fs = f[sel]
    kc = evaluate_ss(k, 2j * np.pi * fs)
    kz = evaluate_ss(kd, np.exp(2j * np.pi * fs * ts))
    diag = np.arange(min(k.ninputs, k.noutputs))
    rel = np.abs(kz[:, diag, diag] - kc[:, diag, diag]) / np.abs(kc[:, diag, diag])
    f_top = opts.discrete_f_max_hz
    zeros = _zeros(k)
    light = zeros[(zeros.imag > 0) & (-zeros.real < 0.2 * np.abs(zeros))]
    shifts = tuple((float(z.imag / (2 * np.pi)),
                    float(np.arctan(z.imag * ts / 2) / (np.pi * ts))) for z in light)
    nyq = 0.5 / ts
    fd = f[f < 0.999 * nyq]
    margins = {AXES[i]: siso_margins(_axis_margins_fn(plant, k, i, kd), fd)
               for i in range(len(diag))}
    return DiscreteComparison(kd=kd, ts_s=ts, f_max_hz=opts.discrete_f_max_hz,
                              max_relative_error=float(np.max(rel)),
                              max_warp=float(np.tan(np.pi * f_top * ts) / (np.pi * f_top * ts) - 1),
                              notch_shifts_hz=shifts, margins=margins)


def discrete_axis_margins(plant: PlantModel, *, a: np.ndarray, b: np.ndarray, c: np.ndarray,
                          d: np.ndarray, ts_s: float,
                          loop_scale: Sequence[float] = (1.0, 1.0)) -> dict[str, Margins]:
    """Margins of each axis's sampled loop ``L_ii = (G Kd)_ii`` below the Nyquist frequency.

    The discrete controller ``Kd(e^{jωT})`` against the plant's exact response and
    delays (which hold the DAC's and the hold's lag), as the design study's
    :class:`DiscreteComparison` and the Monte Carlo draws judge a controller.

    Parameters
    ----------
    plant : PlantModel
        Its path ``Uch, Ucv -> Rh, Rv`` (command [V] to beam angle [rad]) is ``G``.
    a, b, c, d : ndarray, shapes (n, n), (n, 2), (2, n), (2, 2)
        Discrete ``K``: ``Rh, Rv`` [rad] to ``Uch, Ucv`` [V] (the loop is ``u = -K y``).
    ts_s : float
        Sample time of ``K`` [s].
    loop_scale : (float, float)
        Factor on each axis's loop [1]: the 4QD gain the plant has over the one the
        real-time code divides by (1: the same).

    Returns
    -------
    dict of axis to Margins
        ``h`` and ``v``.
    """
    cmds, meas = ["Uch", "Ucv"], ["Rh", "Rv"]
    g_sub = plant.subsystem(outputs=meas, inputs=cmds)
    tau = np.array([plant.input_delay_s[n] for n in cmds])
    a, b, c, d = (np.asarray(x, dtype=float) for x in (a, b, c, d))
    eig_k = np.linalg.eigvals(a) if a.size else np.zeros(0)
    eig_k = eig_k[np.abs(eig_k) > 0]
    poles = np.concatenate([g_sub.poles(), np.log(eig_k.astype(complex)) / ts_s])
    f = frequency_grid(poles, f_min_hz=1e-2, f_max_hz=0.999 * 0.5 / ts_s, per_decade=60)
    out: dict[str, Margins] = {}
    for i, axis in enumerate(AXES):
        def loop(f_hz: np.ndarray, i: int = i) -> np.ndarray:
            s = 2j * np.pi * np.asarray(f_hz, dtype=float).ravel()
            g = evaluate_ss(g_sub, s) * np.exp(-s[:, None, None] * tau[None, None, :])
            z = np.exp(s * ts_s)
            n = a.shape[0]
            x = np.linalg.solve(z[:, None, None] * np.eye(n)[None] - a[None],
                                np.broadcast_to(b, (z.size, *b.shape)).astype(complex))
            kz = np.einsum("pn,fnm->fpm", c, x) + d[None]
            return np.asarray(loop_scale[i] * np.einsum("fj,fj->f", g[:, i, :], kz[:, :, i]))

        out[axis] = siso_margins(loop, f)
    return out


def newport_to_beam(plant: PlantModel, k: ct.StateSpace | None, f_hz: np.ndarray, *,
                    disturbances: Sequence[str] = ("Unh", "Unv")) -> np.ndarray:
    """Newport command to beam angle [rad/V], shape (n, 2, 2) (ESRF study Fig. 42).

    ``S Gn`` with ``S = (I + G K)^-1`` when ``k`` (``Rh, Rv -> Uch, Ucv``) is
    given, the open-loop ``Gn`` when it is None; exact delays.
    """
    s = 2j * np.pi * np.asarray(f_hz, dtype=float).ravel()
    outputs = ["Rh", "Rv"] if k is None else list(k.input_labels)
    gn = plant_response(plant, s, outputs=outputs, inputs=list(disturbances))
    if k is None:
        return gn
    lmat = loop_response(plant, k, s)
    return np.linalg.solve(np.eye(lmat.shape[1])[None] + lmat, gn)
