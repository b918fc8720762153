"""Loop gain, sensitivity, complementary sensitivity and margins on python-control models.

The public face of :mod:`fsmbench.control.freq` for a notebook: a plant (a
:class:`~fsmbench.bench.blocks.PlantModel` or any named python-control system)
and a controller (``u = -K y``, ``docs/model.md``) give

* :func:`loop_gain` ``L = G K`` (from the controller's inputs to the plant's
  outputs with the same names),
* :func:`sensitivity` ``S = (I + L)^-1`` and :func:`complementary`
  ``T = L (I + L)^-1``,

each a minimal realisation (:func:`fsmbench.bench.realization.minimal_realization`),
and :func:`margins` of one loop as a :class:`LoopMargins`. A plant model's
delays become Padé approximants for a continuous controller and exact
zero-order-hold samples for a discrete one. The margins are those of
:func:`fsmbench.control.freq.siso_margins` (the report's), on the rational
loop's own response: they agree with ``control.stability_margins`` on the
same minimal loop, and they stay right where its polynomial roots do not.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, TypeAlias

import control as ct
import numpy as np

from fsmbench.bench.blocks import PlantModel, ss_response
from fsmbench.bench.realization import DEFAULT_TOL, Delays, minimal_realization, select
from fsmbench.control.freq import frequency_grid, siso_margins
from fsmbench.jsonutil import plain_json

__all__ = ["LoopMargins", "complementary", "loop_gain", "margins", "sensitivity"]

System: TypeAlias = "ct.StateSpace | ct.TransferFunction"


def _ss(sys: System) -> ct.StateSpace:
    if isinstance(sys, ct.StateSpace):
        return sys
    if isinstance(sys, ct.TransferFunction):
        out = ct.tf2ss(sys)
        return ct.ss(out.A, out.B, out.C, out.D, sys.dt, inputs=list(sys.input_labels),
                     outputs=list(sys.output_labels))
    raise TypeError(f"expected a python-control StateSpace or TransferFunction, got "
                    f"{type(sys).__name__}")


def _discrete(sys: ct.StateSpace) -> bool:
    return sys.dt not in (0, None)


def _plant_path(plant: PlantModel | System, k: ct.StateSpace, *, delays: Delays | None,
                order: int) -> ct.StateSpace:
    """The plant from the controller's outputs (commands) to its inputs (measurements)."""
    meas, cmds = list(k.input_labels), list(k.output_labels)
    if isinstance(plant, PlantModel):
        how = delays or ("exact" if _discrete(k) else "pade")
        return plant.to_control(delays=how, order=order, dt=k.dt if how == "exact" else None,
                                outputs=meas, inputs=cmds)
    g = _ss(plant)
    if _discrete(k) != _discrete(g):
        raise ValueError("the plant and the controller must both be continuous or both "
                         "sampled (PlantModel.to_control(delays='exact', dt=K.dt) samples a "
                         "plant model)")
    if set(meas) <= set(g.output_labels) and set(cmds) <= set(g.input_labels):
        return select(g, outputs=meas, inputs=cmds)
    if (g.noutputs, g.ninputs) != (len(meas), len(cmds)):
        raise ValueError(f"the plant's signals {list(g.input_labels)} -> "
                         f"{list(g.output_labels)} are not the controller's commands {cmds} "
                         f"-> measurements {meas}, and their sizes differ")
    return g  # unnamed plant of the right size: taken in order


def loop_gain(plant: PlantModel | System, controller: System | None = None, *,
              delays: Delays | None = None, order: int = 6,
              tol: float = DEFAULT_TOL) -> ct.StateSpace:
    """Output loop gain ``L = G K`` of ``u = -K y``, minimal, named like the measurements.

    Parameters
    ----------
    plant : PlantModel or control.StateSpace or control.TransferFunction
        The plant; its path from the controller's outputs to its inputs (by
        signal name) is ``G``. A :class:`PlantModel`'s delays are Padé
        approximants of ``order`` for a continuous controller and exact (sampled
        through a zero-order hold) for a discrete one, unless ``delays`` says.
        With ``controller`` None, ``plant`` is the loop gain itself (returned
        minimal).
    controller : control.StateSpace or control.TransferFunction, optional
        ``K``: measurements (e.g. ``Rh, Rv`` [rad]) to commands (``Uch, Ucv`` [V]).
    delays : {"pade", "exact", "none"}, optional
        How a :class:`PlantModel`'s delays enter (default: by the controller's kind).
    order : int
        Padé order.
    tol : float
        Rank tolerance of the minimal realisation.

    Returns
    -------
    control.StateSpace
        ``L``, square (p, p), inputs and outputs named like ``K``'s inputs, with
        ``K``'s sample time.
    """
    if controller is None:
        return minimal_realization(_ss(_as_system(plant)), tol=tol, name="L")
    k = _ss(controller)
    g = _plant_path(plant, k, delays=delays, order=order)
    lg = g * k
    names = list(k.input_labels)
    lg = ct.ss(lg.A, lg.B, lg.C, lg.D, lg.dt, inputs=names, outputs=names)
    return minimal_realization(lg, tol=tol, name="L")


def _as_system(obj: PlantModel | System) -> System:
    if isinstance(obj, PlantModel):
        raise TypeError("a PlantModel is a plant, not a loop: pass the controller too")
    return obj


def _identity_like(lg: ct.StateSpace) -> ct.StateSpace:
    names = list(lg.output_labels)
    return ct.ss(np.zeros((0, 0)), np.zeros((0, len(names))), np.zeros((len(names), 0)),
                 np.eye(len(names)), lg.dt, inputs=names, outputs=names)


def sensitivity(plant: PlantModel | System, controller: System | None = None, *,
                delays: Delays | None = None, order: int = 6,
                tol: float = DEFAULT_TOL) -> ct.StateSpace:
    """``S = (I + L)^-1``: from an output disturbance to the measurement, minimal.

    Same arguments as :func:`loop_gain` (``controller`` None: ``plant`` is ``L``).
    """
    lg = loop_gain(plant, controller, delays=delays, order=order, tol=tol)
    s = ct.feedback(_identity_like(lg), lg)
    names = list(lg.input_labels)
    return minimal_realization(ct.ss(s.A, s.B, s.C, s.D, lg.dt, inputs=names, outputs=names),
                               tol=tol, name="S")


def complementary(plant: PlantModel | System, controller: System | None = None, *,
                  delays: Delays | None = None, order: int = 6,
                  tol: float = DEFAULT_TOL) -> ct.StateSpace:
    """``T = L (I + L)^-1``: from the reference (or minus the sensor noise) to the
    measurement, minimal. Same arguments as :func:`loop_gain`."""
    lg = loop_gain(plant, controller, delays=delays, order=order, tol=tol)
    t = ct.feedback(lg, _identity_like(lg))
    names = list(lg.input_labels)
    return minimal_realization(ct.ss(t.A, t.B, t.C, t.D, lg.dt, inputs=names, outputs=names),
                               tol=tol, name="T")


@dataclass(frozen=True)
class LoopMargins:
    """Stability margins of one loop ``L`` closed as ``u = -K y``.

    Attributes
    ----------
    gain_margin_db : float
        Gain increase [dB] that puts ``L`` through ``-1``; inf if none.
    gain_reduction_margin_db : float
        Gain decrease [dB] that does (a conditionally stable loop: its phase
        passes -180° where ``|L| > 1``); inf if none.
    phase_margin_deg : float
        Smallest ``180° - |arg L|`` over the gain crossovers [deg]; negative for
        an unstable closed loop.
    delay_margin_s : float
        Smallest extra loop delay [s] that destabilises it:
        ``((arg L + 180°) mod 360°) / (360° f_c)`` over the gain crossovers; 0 if
        unstable, inf if ``|L|`` never crosses 1.
    modulus_margin : float
        ``min |1 + L| = 1 / max |S|`` [1].
    crossover_hz : float
        First gain crossover [Hz]; NaN if none.
    crossovers_hz : tuple of float
        Every gain crossover [Hz].
    phase_crossover_hz : float
        Where the gain margin is read [Hz]; NaN if none.
    modulus_frequency_hz : float
        Where ``|1 + L|`` is smallest [Hz].
    stable : bool
        The closed loop's poles (``eig(A - B (1 + D)^-1 C)`` of the minimal loop)
        are in the open left half-plane (inside the unit circle when sampled).
    dt : float
        Sample time of the loop [s] (0: continuous); frequencies stop at Nyquist.
    """

    gain_margin_db: float
    gain_reduction_margin_db: float
    phase_margin_deg: float
    delay_margin_s: float
    modulus_margin: float
    crossover_hz: float
    crossovers_hz: tuple[float, ...]
    phase_crossover_hz: float
    modulus_frequency_hz: float
    stable: bool
    dt: float

    def to_json(self) -> dict[str, Any]:
        """Plain numbers; inf and NaN become None."""
        return plain_json(self.__dict__)


def _siso(lg: ct.StateSpace, channel: int | str | None) -> ct.StateSpace:
    if lg.ninputs == 1 and lg.noutputs == 1 and channel in (None, 0):
        return lg
    if channel is None:
        raise ValueError(f"the loop is {lg.noutputs}x{lg.ninputs}: name the channel "
                         f"(one of {list(lg.output_labels)}, or its index)")
    i = channel if isinstance(channel, int) else list(lg.output_labels).index(channel)
    # L_ii with the other loops open, as the report's per-axis margins.
    return minimal_realization(ct.ss(lg.A, lg.B[:, [i]], lg.C[[i], :], lg.D[[i]][:, [i]],
                                     lg.dt, inputs=[lg.input_labels[i]],
                                     outputs=[lg.output_labels[i]]), name="L")


def _grid(lg: ct.StateSpace, *, f_min_hz: float | None, f_max_hz: float | None,
          per_decade: int) -> np.ndarray:
    """Log grid [Hz] resolving the loop's lightly damped poles and zeros."""
    roots = np.concatenate([lg.poles(), lg.zeros()])
    roots = roots[np.isfinite(roots)]
    if _discrete(lg):
        roots = roots[np.abs(roots) > 0]
        roots = np.log(roots.astype(complex)) / lg.dt
    w = np.abs(roots[np.abs(roots) > 0])
    lo = f_min_hz or min(1e-2, 1e-2 * float(np.min(w, initial=1.0)) / (2 * np.pi))
    if _discrete(lg):
        hi = (1.0 - 1e-9) * 0.5 / lg.dt if f_max_hz is None else f_max_hz
    else:
        hi = f_max_hz or max(1e4, 1e2 * float(np.max(w, initial=1.0)) / (2 * np.pi))
    return frequency_grid(roots, f_min_hz=lo, f_max_hz=hi, per_decade=per_decade)


def margins(plant: PlantModel | System, controller: System | None = None, *,
            channel: int | str | None = None, delays: Delays | None = None, order: int = 6,
            f_min_hz: float | None = None, f_max_hz: float | None = None,
            per_decade: int = 200) -> LoopMargins:
    """Gain, gain-reduction, phase, delay and modulus margins of one loop.

    Parameters
    ----------
    plant, controller, delays, order
        As :func:`loop_gain` (``controller`` None: ``plant`` is the loop ``L``).
    channel : int or str, optional
        For a MIMO loop, the loop ``L_ii`` (the others open) by index or by the
        measurement's name (``"Rh"``).
    f_min_hz, f_max_hz : float, optional
        Range searched [Hz] (default: two decades around the loop's poles and
        zeros; a sampled loop stops at its Nyquist frequency).
    per_decade : int
        Grid density; lightly damped poles and zeros get points of their own.
    """
    lg = _siso(loop_gain(plant, controller, delays=delays, order=order), channel)
    a, b, c, d = (np.asarray(x, dtype=float) for x in (lg.A, lg.B, lg.C, lg.D))
    if float(d[0, 0]) == -1.0:
        raise ValueError("1 + D = 0: the closed loop is not proper")
    closed = np.linalg.eigvals(a - b @ c / (1.0 + d[0, 0])) if a.size else np.zeros(0)
    stable = bool(np.all(np.abs(closed) < 1.0) if _discrete(lg) else np.all(closed.real < 0))
    dt = float(lg.dt) if _discrete(lg) else 0.0

    def response(f_hz: np.ndarray) -> np.ndarray:
        s = 2j * np.pi * np.asarray(f_hz, dtype=float).ravel()
        return ss_response(lg, np.exp(s * dt) if dt else s)[:, 0, 0]

    m = siso_margins(response, _grid(lg, f_min_hz=f_min_hz, f_max_hz=f_max_hz,
                                     per_decade=per_decade), stable=stable)
    if not stable:
        delay = 0.0
    else:
        lc = response(np.asarray(m.crossovers_hz, dtype=float))
        delay = min((float(np.mod(np.angle(x) + np.pi, 2 * np.pi)) / (2 * np.pi * fc)
                     for x, fc in zip(lc, m.crossovers_hz, strict=True)), default=math.inf)
    return LoopMargins(gain_margin_db=m.gain_margin_db,
                       gain_reduction_margin_db=m.gain_reduction_margin_db,
                       phase_margin_deg=m.phase_margin_deg, delay_margin_s=delay,
                       modulus_margin=m.modulus_margin, crossover_hz=m.crossover_hz,
                       crossovers_hz=m.crossovers_hz, phase_crossover_hz=m.phase_crossover_hz,
                       modulus_frequency_hz=m.modulus_frequency_hz, stable=stable, dt=dt)
