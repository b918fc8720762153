"""An identified bench: the user's bench, as its recordings describe it, for the one engine.

:func:`identified_bench` reads an identification folder (written by
``fsmbench identify`` or ``fsmbench study``) and returns a :class:`~fsmbench.bench.params.Bench`
whose simulation runs *that* bench rather than the packaged one:

==========================  ====================================================  ==========
what the engine simulates   from                                                  provenance
==========================  ====================================================  ==========
plant (Gi, Ga Zc, Gc, Gn)   ``plant.mat``, the identified blocks and delays         measured
4QD gains, compression      the calibration (``identification.json``, 2.1)          measured
4QD noise (white, 1/f,      the open-loop huddle tests' spectra                     measured
mains, drift)               (``identification.json`` ``noise_model``)
``Va`` noise floor          the huddle tests' ``Va`` spectrum                       measured
Newport angle noise,        the bench file                                          assumed
optics, metrology gain,
environment, converters
==========================  ====================================================  ==========

A part the identification could not measure (its experiment missing or
failed) keeps the bench file's value and is marked *assumed*. The same
streaming engine runs it, block for block, as it runs the packaged twin
(:func:`fsmbench.sim.plant.bench_discrete`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from fsmbench.bench.axes import PerAxis
from fsmbench.bench.blocks import PlantModel
from fsmbench.bench.identified import IdentifiedModel, engine_model
from fsmbench.bench.params import Bench, BenchParams
from fsmbench.excite.identified import quad_diode_from_identification
from fsmbench.ident.load import load_identified_plant, read_identification_json
from fsmbench.ident.noise_model import NoiseModelFit
from fsmbench.io.errors import RecordingError

__all__ = ["CONTRACTED_KEYS", "bench_from_identification", "identified_bench"]

#: The keys of ``identification.json`` a simulation of the identified bench is the truth of.
CONTRACTED_KEYS = ("qd_gain_v_per_rad", "current_amp_gain_a_per_v", "sercalo",
                   "newport_gain_v_per_v", "newport", "delay_s")

_BLOCK_WORDS = {"Gi": "current amplifier", "Zc": "coil resistance", "Ga": "voltage amplifier",
                "Gc": "Sercalo", "Gn": "Newport", "Gd": "4QD gain"}
_BLOCK_SOURCE = {"Gi": "data_uch, data_ucv", "Gc": "data_uch, data_ucv",
                 "Gn": "data_unh, data_unv", "Gd": "data_cal_pd_h, data_cal_pd_v"}


def _quad_diode(params: BenchParams, ident: Mapping[str, Any], gd: np.ndarray, path: Path,
                provenance: dict[str, str]) -> BenchParams:
    """The 4QD as the identification measured it; its lag is in the plant's delays."""
    qd = params.quad_diode
    diagnostics = ident.get("diagnostics") or {}
    calibrated = isinstance(diagnostics.get("qd"), dict) and all(
        a in diagnostics["qd"] for a in "hv")
    if calibrated:
        params = quad_diode_from_identification(params, dict(ident), path=path)
        qd = params.quad_diode
        provenance["4QD gain and compression"] = "measured: data_cal_pd_h, data_cal_pd_v"
    else:
        qd = dataclasses.replace(qd, gain_v_per_rad=PerAxis(h=float(gd[0, 0]),
                                                            v=float(gd[1, 1])))
        provenance["4QD gain and compression"] = "assumed: bench file (no calibration)"
    # The identified delays are effective ones: they already hold the amplifier's lag.
    qd = dataclasses.replace(qd, bandwidth_hz=0.0)
    conv = dataclasses.replace(params.converter, dac_extra_delay_s=0.0)
    return dataclasses.replace(params, quad_diode=qd, converter=conv)


def identified_bench(folder: str | Path, *, bench: Bench, label: str = "",
                     option: str = "--bench") -> Bench:
    """The bench identified in ``folder``, ready for every simulation.

    Parameters
    ----------
    folder : str or Path
        Output of ``fsmbench identify`` or ``fsmbench study``: ``identification.json``
        and ``plant.mat``.
    bench : Bench
        The bench file: converters, optics, environment and every value no
        recording measured (``bench.nominal``).
    label : str
        The bench in words (default "the bench identified in FOLDER").
    option : str
        What named ``folder``, as the user typed it (``--bench``, ``--identification``, the
        device's ``BenchFolder`` property), for the messages.

    Returns
    -------
    Bench
        ``nominal`` and ``datasheet`` from ``bench``; ``true`` what the engine
        reads (identified 4QD, fitted noise); ``model`` the identified plant.

    Raises
    ------
    RecordingError
        The folder is not an identification, its Sercalo was not identified,
        the identification raised warnings, or its files are malformed (one line).
    """

    ident_path, ident = read_identification_json(folder, option=option)
    plant = load_identified_plant(ident_path.parent, option=option).plant
    return bench_from_identification(ident, plant=plant, bench=bench, path=ident_path,
                                     label=label)


def bench_from_identification(ident: Mapping[str, Any], *, plant: PlantModel, bench: Bench,
                              path: Path, label: str = "") -> Bench:
    """The identified bench from a parsed ``identification.json`` and its plant.

    Parameters
    ----------
    ident : mapping
        ``identification.json`` (or :meth:`Identification.to_json`).
    plant : PlantModel
        The identified plant (``plant.mat``).
    bench : Bench
        The bench file.
    path : Path
        Where the identification is (or will be) written: named in errors and as
        the bench's folder.
    label : str
        The bench in words.
    """
    provenance: dict[str, str] = {}
    blocks = (ident.get("diagnostics") or {}).get("plant_blocks") or {}
    for name, words in _BLOCK_WORDS.items():
        how = blocks.get(name, "identified" if name in _BLOCK_SOURCE else "nominal")
        provenance[words] = (f"measured: {_BLOCK_SOURCE[name]}" if how == "identified"
                             and name in _BLOCK_SOURCE else "assumed: bench file")
    gd = np.asarray(plant.blocks["Gd"].D, dtype=float)
    true = _quad_diode(bench.nominal, ident, gd, path, provenance)
    noise_fit: dict[str, Any] = {}
    raw = ident.get("noise_model")
    if isinstance(raw, dict) and raw:
        try:
            fit = NoiseModelFit.from_json(raw)
        except (KeyError, TypeError, ValueError) as exc:
            raise RecordingError(path, f"has a malformed noise_model ({exc})") from exc
        true = fit.apply(true)
        noise_fit = fit.to_json()
        provenance.update({f"noise: {k}": v for k, v in fit.provenance.items()})
    else:
        provenance["noise"] = ("assumed: bench file (no open-loop huddle test in the "
                               "identification)")
    provenance["Newport angle noise, optics, environment, converters"] = "assumed: bench file"
    try:
        sys, delays = engine_model(plant, params=true)
    except ValueError as exc:
        raise RecordingError(path.parent / "plant.mat", str(exc)) from exc
    folder = path.parent
    model = IdentifiedModel(
        a=np.asarray(sys.A, dtype=float), b=np.asarray(sys.B, dtype=float),
        c=np.asarray(sys.C, dtype=float), d=np.asarray(sys.D, dtype=float),
        input_delay_samples=delays, plant=plant, folder=str(folder),
        values={k: ident[k] for k in CONTRACTED_KEYS if k in ident},
        provenance=provenance, noise_fit=noise_fit, label=label)
    return Bench(datasheet=bench.datasheet, nominal=bench.nominal, true=true,
                 origin=str(folder), model=model)
