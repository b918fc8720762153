"""The controller ``tune`` starts from (``--running``), as the loop it measures, and the
``tune.json`` it writes."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from fsmbench.atomic import atomic_write_text
from fsmbench.bench.blocks import physical_plant
from fsmbench.bench.esrf import esrf_decentralised_controller
from fsmbench.bench.params import Bench
from fsmbench.control.controller import Controller, controller_of
from fsmbench.control.load import load_controllers, select_controller
from fsmbench.control.preimage import (
    AT_NYQUIST,
    nyquist_pole_distance,
    sections_preimage,
    tustin_preimage,
)
from fsmbench.control.study import design_study
from fsmbench.jsonutil import format_text

__all__ = ["loop_from_file", "running_loop", "write_tune_json"]

def running_loop(kind: str, bench: Bench) -> Controller:
    """The controller running when ``tune`` starts, as ``--running`` names it.

    Parameters
    ----------
    kind : str
        ``seed`` (the ESRF study's controller, 9.2), ``fsmbench`` (fsmbench's designed on
        the bench file's nominal plant) or ``PATH[::NAME]`` of a controllers file
        (:func:`loop_from_file`).
    bench : Bench
        The bench file: converter rate and nominal 4QD gains.
    """
    ts = bench.true.converter.ts_s
    gd = bench.nominal.quad_diode.gain_v_per_rad
    if kind not in ("seed", "fsmbench"):
        return loop_from_file(kind, bench)
    if kind == "seed":
        return controller_of(esrf_decentralised_controller(),
                             name="the ESRF study's controller (9.2)", ts_s=ts,
                             gd_v_per_rad=(float(gd.h), float(gd.v)))
    study = design_study(physical_plant(bench.nominal, source="the bench file"), bench=bench)
    return controller_of(study.controllers["fsmbench_controller"],
                         name="fsmbench's controller (designed on the bench file)", ts_s=ts,
                         gd_v_per_rad=(float(gd.h), float(gd.v)))


def loop_from_file(spec: str, bench: Bench) -> Controller:
    """The controller ``PATH[::NAME]`` of a controllers file, as the device runs it.

    The file holds it discrete at the converter rate (Tustin per section, prewarped);
    ``Controller.continuous`` is its continuous pre-image under plain Tustin
    (:func:`fsmbench.control.preimage.tustin_preimage`; ``z = -1`` is no pole of it), so
    that the loop the twin and the predictions run is the file's, line for line. Named
    ``'NAME (FILE)'``, as ``LoadController`` names it on the device.
    """
    ts = bench.true.converter.ts_s
    path, sep, name = spec.partition("::")
    chosen = select_controller(load_controllers(path, ts_s=ts), name if sep else None)
    if not chosen.maps(("Rh", "Rv"), ("Uch", "Ucv")):
        raise ValueError(f"{path}: controller {chosen.name!r} maps {list(chosen.input_names)} "
                         f"to {list(chosen.output_names)}, not Rh, Rv to Uch, Ucv")
    # Tustin maps s = infinity, and only it, to z = -1: a pole there has no pre-image. Decided
    # on the poles themselves, not det(I + A): fsmbench's integrator sections put entries of
    # ~1e12 in A beside exact poles at z = 1. A pole just inside -1 is legitimate (a lowpass
    # far above Nyquist: 1e-3 from -1 is a roll-off at 640 times the sample rate).
    if nyquist_pole_distance(chosen.a) < AT_NYQUIST:
        raise ValueError(f"{path}: controller {chosen.name!r} has a pole at z = -1 (Nyquist): "
                         "it has no continuous-time equivalent")
    # From the file's sections, root by root, where it has them: a substitution in the
    # realisation puts its zeros at infinity at 1e11 to 1e13 rad/s, and a later zero-pole
    # split (a re-export of it) is then ill-posed (control.preimage).
    if chosen.sections is not None:
        k = sections_preimage(chosen.sections, ts_s=ts, inputs=["Rh", "Rv"],
                              outputs=["Uch", "Ucv"], name=chosen.name)
    else:
        k = tustin_preimage(chosen.a, chosen.b, chosen.c, chosen.d, ts_s=ts,
                            inputs=["Rh", "Rv"], outputs=["Uch", "Ucv"], name=chosen.name)
    nominal = bench.nominal.quad_diode.gain_v_per_rad
    gd = chosen.gd_v_per_rad or (float(nominal.h), float(nominal.v))
    return controller_of(k, name=f"{chosen.name} ({Path(chosen.source).name})", ts_s=ts,
                         gd_v_per_rad=(float(gd[0]), float(gd[1])))


def write_tune_json(path: Path, payload: dict[str, Any]) -> Path:
    """Write ``tune.json`` (``TuneResult.to_json()``, ``watch`` added) atomically.

    ``format`` and ``format_version`` come first, every other key sorted at every depth
    (reproducible files).

    Parameters
    ----------
    path : Path
        The file to write.
    payload : dict
        Its content, stamped ``fsmbench.tune``.

    Returns
    -------
    Path
        ``path``.
    """
    return atomic_write_text(path, format_text(payload, sort_keys=True))
