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

import dataclasses
from pathlib import Path

from fsmbench.bench.esrf import esrf_decentralised_controller
from fsmbench.bench.params import Bench
from fsmbench.control.controller import Controller, controller_of
from fsmbench.control.load import load_controllers, select_controller

__all__ = ["SEED_SPEC", "running_controller"]

#: The name of the ESRF study's controller on the command line.
SEED_SPEC = "seed"


def running_controller(spec: str | Path | None, *, bench: Bench,
                       gd_v_per_rad: tuple[float, float] | None = None) -> Controller:
    """The controller ``spec`` names (see the module notes), for ``bench``.

    Parameters
    ----------
    spec : str, Path or None
        ``None`` or ``"seed"``, ``PATH`` or ``PATH::NAME``.
    bench : Bench
        Its converter rate; its nominal 4QD gains where the controller has none.
    gd_v_per_rad : (float, float), optional
        4QD gains to divide by instead [V/rad].

    Returns
    -------
    Controller
        Its ``feedback`` is wired into the engine (``u = -K Vp / Gd``); ``source`` is
        ``seed`` or ``FILE::NAME``.

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
        return controller_of(esrf_decentralised_controller(), ts_s=ts, gd_v_per_rad=gd,
                             name="the ESRF study's controller (9.2)", source=SEED_SPEC)

    text = str(spec)
    path, sep, name = text.partition("::")
    chosen = select_controller(load_controllers(path, ts_s=ts), name if sep else None)
    gd = gd_v_per_rad or chosen.gd_v_per_rad or (float(nominal.h), float(nominal.v))
    return dataclasses.replace(chosen, ts_s=ts, gd_v_per_rad=gd,
                               name=f"{chosen.name} of {chosen.source}",
                               source=f"{chosen.source}::{chosen.name}")
