"""A running controller named on a command line, wired into the engine's loop.

``--closed-loop CONTROLLER`` (``excite``, ``simulate``) and ``tune`` name the
controller that closes the Sercalo loop:

* ``seed`` (the default): the ESRF study's decentralised controller of 9.2,
  Tustin at the converter rate, dividing the 4QD readings by the bench file's
  gains (what the ESRF study's real-time code did, and what the live device's
  ``CloseLoop`` runs when nothing is loaded);
* ``PATH`` or ``PATH::NAME``: a ``controllers.mat``, ``controllers_sos.json`` or
  ``fsmbench design`` output folder (:func:`fsmbench.control.load.load_controllers`),
  the controller ``NAME`` in it or by default fsmbench's own
  (:func:`fsmbench.control.load.select_controller`), dividing by the 4QD gains the
  file records (else the bench file's), exactly as ``LoadController`` does.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fsmbench.bench.axes import PerAxis
from fsmbench.bench.esrf import esrf_decentralised_controller, tustin
from fsmbench.bench.params import Bench
from fsmbench.control.load import load_controllers, select_controller
from fsmbench.sim.controller import feedback_controller, sercalo_feedback
from fsmbench.sim.engine import DiscreteController

__all__ = ["SEED_SPEC", "RunningController", "running_controller"]

#: The name of the ESRF study's controller on the command line.
SEED_SPEC = "seed"


@dataclass(frozen=True, eq=False)
class RunningController:
    """A controller as the engine runs it, and its discrete ``K`` for the analyses.

    Attributes
    ----------
    feedback : DiscreteController
        Wired into the engine (``u = -K Vp / Gd``).
    a, b, c, d : ndarray
        Discrete ``K``: ``Rh, Rv`` [rad] to ``Uch, Ucv`` [V] at ``ts_s``
        (``x[k+1] = a x + b r``, ``v = c x + d r``; the loop applies ``-v``).
    ts_s : float
        Sample time [s].
    gd_v_per_rad : (float, float)
        4QD gains the readings are divided by [V/rad].
    name : str
        In words, e.g. "the ESRF study's controller (9.2)".
    source : str
        ``seed`` or the file (and the controller's name in it).
    """

    feedback: DiscreteController
    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    d: np.ndarray
    ts_s: float
    gd_v_per_rad: tuple[float, float]
    name: str
    source: str

    def response(self, f_hz: np.ndarray) -> np.ndarray:
        """``K(e^{j 2 pi f ts})``, shape (F, 2, 2) [V/rad]."""
        z = np.exp(2j * np.pi * np.asarray(f_hz, dtype=float).ravel() * self.ts_s)
        n = self.a.shape[0]
        if n == 0:
            return np.broadcast_to(self.d, (z.size, 2, 2)).astype(complex)
        lhs = z[:, None, None] * np.eye(n)[None] - self.a[None]
        x = np.linalg.solve(lhs, np.broadcast_to(self.b, (z.size, *self.b.shape)).astype(complex))
        return np.asarray(np.einsum("pn,fnm->fpm", self.c, x) + self.d[None])


def running_controller(spec: str | Path | None, *, bench: Bench,
                       gd_v_per_rad: tuple[float, float] | None = None) -> RunningController:
    """The controller ``spec`` names (see the module notes), wired for ``bench``.

    Parameters
    ----------
    spec : str, Path or None
        ``None`` or ``"seed"``, ``PATH`` or ``PATH::NAME``.
    bench : Bench
        Its converter rate; its nominal 4QD gains where the controller has none.
    gd_v_per_rad : (float, float), optional
        4QD gains to divide by instead [V/rad].

    Raises
    ------
    ValueError
        (a :class:`~fsmbench.io.errors.RecordingError` for a file) One line: the
        file is missing or not a controllers file, has no such controller, its
        sample time is not the bench's.
    """

    ts = bench.true.converter.ts_s
    nominal = bench.nominal.quad_diode.gain_v_per_rad
    if spec is None or str(spec) == SEED_SPEC:
        gd = gd_v_per_rad or (float(nominal.h), float(nominal.v))

        kd = tustin(esrf_decentralised_controller(), ts_s=ts)
        fb = feedback_controller(kd, gd_v_per_rad=PerAxis(h=gd[0], v=gd[1]), ts_s=ts,
                                 name="seed K (9.2)")
        return RunningController(feedback=fb, a=np.asarray(kd.A, dtype=float),
                                 b=np.asarray(kd.B, dtype=float), c=np.asarray(kd.C, dtype=float),
                                 d=np.asarray(kd.D, dtype=float), ts_s=ts, gd_v_per_rad=gd,
                                 name="the ESRF study's controller (9.2)", source=SEED_SPEC)

    text = str(spec)
    path, sep, name = text.partition("::")
    chosen = select_controller(load_controllers(path, ts_s=ts), name if sep else None)
    gd = gd_v_per_rad or chosen.qd_gain_v_per_rad or (float(nominal.h), float(nominal.v))
    fb = sercalo_feedback(a=chosen.a, b=chosen.b, c=chosen.c, d=chosen.d, gd_v_per_rad=gd,
                          name=chosen.name)
    return RunningController(feedback=fb, a=np.array(chosen.a), b=np.array(chosen.b),
                             c=np.array(chosen.c), d=np.array(chosen.d), ts_s=ts,
                             gd_v_per_rad=(float(gd[0]), float(gd[1])),
                             name=f"{chosen.name} of {chosen.source_path}",
                             source=f"{chosen.source_path}::{chosen.name}")
