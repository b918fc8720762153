"""The bench's discrete feedback controller as one value, and its wiring into the engine.

A :class:`Controller` is the discrete ``K`` from the beam angle ``r = [Rh, Rv]`` [rad]
to the Sercalo commands ``v = [Uch, Ucv]`` [V], whatever it came from: a design file
(:func:`fsmbench.control.load.load_controllers`), the ESRF study's controller or a
design discretised here (:func:`controller_of`), a command line's ``--closed-loop``
(:func:`fsmbench.control.loaded.running_controller`). The loop is closed as
``u = -K y`` (the ESRF study's ``connect(sys, -K, ...)``): the matrices are ``K``'s
and the command applied is ``-v``.

The engine (:mod:`fsmbench.sim.engine`, a layer below) runs its own wiring,
:class:`~fsmbench.sim.engine.DiscreteController`, with the volts-to-radians scaling
and the feedback sign folded in; :attr:`Controller.feedback` builds it, once per
controller, by :func:`fsmbench.sim.controller.sercalo_feedback`.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import control as ct
import numpy as np
from numpy.typing import ArrayLike, NDArray

from fsmbench.sim.controller import sercalo_discrete, sercalo_feedback
from fsmbench.sim.engine import DiscreteController

__all__ = ["BEAM_ANGLES", "SERCALO_COMMANDS", "Controller", "controller_of"]

#: Inputs of the bench's feedback controllers: the 4QD beam angle [rad].
BEAM_ANGLES = ("Rh", "Rv")
#: Outputs of the Sercalo loop's controllers: the DAC commands [V].
SERCALO_COMMANDS = ("Uch", "Ucv")

FloatArray = NDArray[np.float64]


def _read_only(x: ArrayLike) -> FloatArray:
    """A read-only float copy of ``x`` (the caller's array stays writable)."""
    out = np.array(x, dtype=float)
    out.setflags(write=False)
    return out


@dataclass(frozen=True, eq=False)
class Controller:
    """A discrete controller ``K``: ``x[k+1] = a x[k] + b r[k]``, ``v[k] = c x[k] + d r[k]``.

    For the bench's feedback controllers ``r = [Rh, Rv]`` is the 4QD beam angle [rad]
    and ``v = [Uch, Ucv]`` the Sercalo commands [V] (``input_names``,
    ``output_names``); the loop applies ``-v``. The arrays are read-only copies.

    Attributes
    ----------
    name : str
        In words, e.g. ``"the ESRF study's controller (9.2)"``, or the name in its file
        (``"fsmbench_controller"``).
    ts_s : float
        Sample time [s].
    a : ndarray, shape (n, n)
        State matrix [1].
    b : ndarray, shape (n, 2)
        Input matrix, state units per input unit (per rad for the beam angle).
    c : ndarray, shape (2, n)
        Output matrix, output unit (V) per state unit.
    d : ndarray, shape (2, 2)
        Feedthrough, output unit per input unit [V/rad].
    gd_v_per_rad : (float, float) or None
        The 4QD gains ``Gd`` (h, v) [V/rad], sign included, the real-time code divides
        the readings ``Vp`` by (``r = Vp / Gd``); None when a file does not record them
        (:attr:`gd` refuses it).
    source : str
        Where it comes from, in words: ``"seed"``, a file, ``"FILE::NAME"``, a design.
    continuous : control.StateSpace or None
        The continuous ``K`` it was discretised from, when known (inputs ``Rh, Rv``
        [rad], outputs ``Uch, Ucv`` [V]).
    description : str
        A file's description of it ("" if none).
    input_names, output_names : tuple of str
        Signal names of ``r`` and ``v``; by default ``("Rh", "Rv")`` and ``("Uch", "Ucv")``.
    source_path : Path or None
        The file it was read from (None: not read from a file).
    discretisation : str
        How a file says it was discretised, e.g. ``"tustin_prewarp"`` ("" if not said).
    sections : tuple of ndarray, shape (n_sections, 6), or None
        A ``controllers_sos.json``'s own cascades, one per axis (input ``i`` to output
        ``i``), ``[b0, b1, b2, a0, a1, a2]`` [1]; None otherwise.
    """

    name: str
    ts_s: float
    a: FloatArray
    b: FloatArray
    c: FloatArray
    d: FloatArray
    gd_v_per_rad: tuple[float, float] | None = None
    source: str = ""
    continuous: ct.StateSpace | None = None
    description: str = ""
    input_names: tuple[str, ...] = BEAM_ANGLES
    output_names: tuple[str, ...] = SERCALO_COMMANDS
    source_path: Path | None = None
    discretisation: str = ""
    sections: tuple[FloatArray, ...] | None = None

    def __post_init__(self) -> None:
        for key in "abcd":
            object.__setattr__(self, key, _read_only(getattr(self, key)))
        n, (p, m) = self.a.shape[0] if self.a.ndim else -1, np.shape(np.atleast_2d(self.d))
        if (self.d.ndim != 2 or self.a.shape != (n, n) or self.b.shape != (n, m)
                or self.c.shape != (p, n)):
            raise ValueError(f"controller {self.name!r}: inconsistent sizes, A {self.a.shape}, "
                             f"B {self.b.shape}, C {self.c.shape}, D {self.d.shape}")
        if self.gd_v_per_rad is not None:
            h, v = self.gd_v_per_rad
            object.__setattr__(self, "gd_v_per_rad", (float(h), float(v)))

    @property
    def n_states(self) -> int:
        """Number of states ``n``."""
        return int(self.a.shape[0])

    @property
    def gd(self) -> tuple[float, float]:
        """:attr:`gd_v_per_rad` (h, v) [V/rad], which the loop needs.

        Raises
        ------
        ValueError
            The controller has none (a file that does not record them).
        """
        if self.gd_v_per_rad is None:
            raise ValueError(f"controller {self.name!r} has no 4QD gains to divide the "
                             "readings by")
        return self.gd_v_per_rad

    @functools.cached_property
    def feedback(self) -> DiscreteController:
        """The engine's wiring of it: ``u = -K Vp / Gd`` from ``Vph, Vpv`` to ``Uch, Ucv``.

        Built once (:func:`fsmbench.sim.controller.sercalo_feedback`, from writable copies
        of the matrices), named as the controller.
        """
        return sercalo_feedback(a=np.array(self.a), b=np.array(self.b), c=np.array(self.c),
                                d=np.array(self.d), gd_v_per_rad=self.gd, name=self.name)

    def response(self, f_hz: ArrayLike) -> NDArray[np.complex128]:
        """``c (zI - a)^-1 b + d`` at ``z = exp(j 2 pi f ts_s)``.

        Parameters
        ----------
        f_hz : array_like, shape (F,)
            Frequencies [Hz].

        Returns
        -------
        ndarray, complex, shape (F, 2, 2)
            Output unit per input unit [V/rad]; ``[:, i, j]`` from input ``j`` to output ``i``.
        """
        z = np.exp(2j * np.pi * np.asarray(f_hz, dtype=float).ravel() * self.ts_s)
        if self.n_states == 0:
            return np.broadcast_to(self.d, (z.size, *self.d.shape)).astype(complex)
        lhs = z[:, None, None] * np.eye(self.n_states)[None] - self.a[None]
        x = np.linalg.solve(lhs, np.broadcast_to(self.b, (z.size, *self.b.shape)).astype(complex))
        return np.asarray(np.einsum("pn,fnm->fpm", self.c, x) + self.d[None])

    def maps(self, inputs: Sequence[str], outputs: Sequence[str]) -> bool:
        """Whether it goes from exactly ``inputs`` to exactly ``outputs``, in order."""
        return self.input_names == tuple(inputs) and self.output_names == tuple(outputs)


def controller_of(k: ct.StateSpace, *, name: str, ts_s: float,
                  gd_v_per_rad: Sequence[float], source: str | None = None,
                  **fields: Any) -> Controller:
    """``k`` as the real-time code runs it: Tustin at ``ts_s``, readings divided by ``Gd``.

    Parameters
    ----------
    k : control.StateSpace
        ``Rh, Rv`` [rad] to ``Uch, Ucv`` [V], continuous (discretised by Tustin at
        ``ts_s``) or already discrete at ``ts_s``
        (:func:`fsmbench.sim.controller.sercalo_discrete`).
    name : str
        In words.
    ts_s : float
        The converter's sample time [s].
    gd_v_per_rad : (float, float)
        The 4QD gains (h, v) the readings are divided by [V/rad].
    source : str, optional
        Where it comes from, in words; by default ``name``.
    **fields
        Other :class:`Controller` fields.

    Returns
    -------
    Controller
        ``continuous`` is ``k`` when ``k`` is continuous, else None.
    """
    kd = sercalo_discrete(k, ts_s=ts_s)
    h, v = gd_v_per_rad
    return Controller(name=name, ts_s=ts_s, a=kd.A, b=kd.B, c=kd.C, d=kd.D,
                      gd_v_per_rad=(float(h), float(v)),
                      source=name if source is None else source,
                      continuous=k if kd is not k else None, **fields)
