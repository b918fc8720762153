"""Reuse a previous identification: read ``plant.mat`` back into a plant.

``fsmbench budget`` and ``fsmbench design`` take ``--identification DIR``, a
folder written by ``fsmbench identify`` or ``fsmbench study`` holding
``identification.json`` and ``plant.mat`` (layout:
:mod:`fsmbench.ident.export`), instead of identifying the plant again.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import control as ct
import numpy as np
import scipy.io
from scipy.io.matlab import MatReadError

from fsmbench.bench.blocks import PLANT_INPUTS, PLANT_OUTPUTS, PlantModel
from fsmbench.ident.noise_model import NoiseModelFit
from fsmbench.ident.result import PlantChoice, SavedIdentification
from fsmbench.io.errors import RecordingError

__all__ = ["BLOCK_NAMES", "excitation_transients", "load_identified_plant",
           "read_identification_json", "read_plant_mat"]

#: The blocks ``plant.mat`` holds besides the full system ``sys``.
BLOCK_NAMES = ("Gi", "Zc", "Ga", "Gc", "Gn", "Gd")
_FIELDS = ("A", "B", "C", "D", "InputName", "OutputName", "StateName", "InputDelay")


def _names(value: Any) -> list[str]:
    # loadmat(simplify_cells=True) turns a 1-element cell into its string.
    if isinstance(value, str):
        return [value]
    return [str(x) for x in np.atleast_1d(np.asarray(value, dtype=object)).ravel()]


def _matrix(value: Any, shape: tuple[int, int], where: str, path: Path) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.size != shape[0] * shape[1]:
        raise RecordingError(path, f"has {arr.size} values, expected {shape[0]}x{shape[1]}",
                             variable=where)
    if not np.all(np.isfinite(arr)):
        raise RecordingError(path, "holds NaN or Inf values", variable=where)
    return arr.reshape(shape)


def _ss(struct: Any, name: str, path: Path) -> tuple[ct.StateSpace, dict[str, float]]:
    if not isinstance(struct, Mapping):
        raise RecordingError(path, "is not a struct", variable=name)
    missing = [f for f in _FIELDS if f not in struct]
    if missing:
        raise RecordingError(path, f"lacks the field(s) {', '.join(missing)}", variable=name)
    if float(np.asarray(struct.get("Ts", 0.0), dtype=float)) != 0.0:
        raise RecordingError(path, "is a discrete model (Ts != 0); a continuous one is expected",
                             variable=name)
    ins, outs = _names(struct["InputName"]), _names(struct["OutputName"])
    states = _names(struct["StateName"])
    n, m, p = len(states), len(ins), len(outs)
    a = _matrix(struct["A"], (n, n), f"{name}.A", path)
    b = _matrix(struct["B"], (n, m), f"{name}.B", path)
    c = _matrix(struct["C"], (p, n), f"{name}.C", path)
    d = _matrix(struct["D"], (p, m), f"{name}.D", path)
    delay = np.asarray(struct["InputDelay"], dtype=float).ravel()
    if delay.size != m or not np.all(np.isfinite(delay)) or np.any(delay < 0):
        raise RecordingError(path, f"must hold {m} finite delays >= 0 [s]",
                             variable=f"{name}.InputDelay")
    kwargs: dict[str, Any] = {"inputs": ins, "outputs": outs, "name": name}
    if n:
        kwargs["states"] = states
    return ct.ss(a, b, c, d, **kwargs), dict(zip(ins, delay.tolist(), strict=True))


def read_plant_mat(path: str | Path) -> PlantModel:
    """Read a ``plant.mat`` written by :func:`fsmbench.ident.export.write_plant_mat`.

    Parameters
    ----------
    path : str or Path
        The MAT-file.

    Returns
    -------
    PlantModel
        Blocks ``Gi, Zc, Ga, Gc, Gn, Gd``, the full system ``sys`` (inputs
        :data:`~fsmbench.bench.blocks.PLANT_INPUTS`, outputs
        :data:`~fsmbench.bench.blocks.PLANT_OUTPUTS`), its input delays [s]
        and the recorded ``source``.

    Raises
    ------
    RecordingError
        The file is missing, unreadable, or a struct is missing or malformed
        (the variable is named).
    """
    p = Path(path)
    if not p.is_file():
        raise RecordingError(p, "does not exist" if not p.exists() else "is not a file")
    try:
        data = scipy.io.loadmat(p, simplify_cells=True)
    except (OSError, ValueError, TypeError, NotImplementedError, MatReadError) as exc:
        raise RecordingError(p, f"is not a readable MAT-file ({exc})") from exc
    missing = [k for k in ("sys", *BLOCK_NAMES) if k not in data]
    if missing:
        raise RecordingError(p, f"lacks the variable(s) {', '.join(missing)}; it is not a "
                                "plant.mat written by fsmbench identify")
    sys, delays = _ss(data["sys"], "sys", p)
    if tuple(sys.input_labels) != PLANT_INPUTS or tuple(sys.output_labels) != PLANT_OUTPUTS:
        raise RecordingError(p, f"has inputs {list(sys.input_labels)} and outputs "
                                f"{list(sys.output_labels)}; expected {list(PLANT_INPUTS)} "
                                f"and {list(PLANT_OUTPUTS)}", variable="sys")
    blocks = {name: _ss(data[name], name, p)[0] for name in BLOCK_NAMES}
    source = data.get("source")
    return PlantModel(blocks=blocks, sys=sys, input_delay_s=delays,
                      source=source if isinstance(source, str) else "identified")


def read_identification_json(folder: str | Path, *,
                             option: str = "--bench") -> tuple[Path, dict[str, Any]]:
    """``FOLDER/identification.json`` of a previous ``identify`` or ``study`` run, parsed.

    ``option``: what named the folder, as the user typed it (``--bench``, its alias
    ``--identification``, a device property), for the messages.

    Raises
    ------
    RecordingError
        The folder or file is missing, unreadable, or not a JSON object (one line).
    """
    d = Path(folder)
    if not d.is_dir():
        raise RecordingError(d, f"{option} must be a folder written by fsmbench identify or "
                                "study; " + ("it does not exist" if not d.exists()
                                             else "it is a file"))
    ident_path = d / "identification.json"
    if not ident_path.is_file():
        raise RecordingError(ident_path, f"does not exist; {option} must be a folder written "
                                         "by fsmbench identify or study")
    try:
        ident = json.loads(ident_path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        raise RecordingError(ident_path, f"cannot be read ({exc})") from exc
    except json.JSONDecodeError as exc:
        raise RecordingError(ident_path, f"is not valid JSON: {exc.msg} at line {exc.lineno}, "
                                         f"column {exc.colno}") from exc
    if not isinstance(ident, dict):
        raise RecordingError(ident_path, "is not a JSON object")
    return ident_path, ident


def load_identified_plant(folder: str | Path, *, option: str = "--bench") -> PlantChoice:
    """The plant of a previous ``identify`` or ``study`` run in ``folder``.

    Parameters
    ----------
    folder : str or Path
        Output folder holding ``identification.json`` and ``plant.mat``.
    option : str
        What named the folder, as the user typed it (``--bench`` or ``--identification``).

    Returns
    -------
    fsmbench.ident.result.PlantChoice
        The plant, its source ``"identified (from FOLDER/identification.json)"``
        and no in-memory identification.

    Raises
    ------
    RecordingError
        A file is missing or malformed, or the identification does not
        describe a trustworthy identified plant (the Sercalo was not
        identified, or the identification raised warnings): then the reason
        is named and the command should run without ``option``.
    """

    ident_path, ident = read_identification_json(folder, option=option)
    d = ident_path.parent
    diagnostics = ident.get("diagnostics") or {}
    warnings = diagnostics.get("warnings") if isinstance(diagnostics, dict) else None
    if "sercalo" not in ident:
        raise RecordingError(ident_path, "has no identified Sercalo (data_uch/data_ucv were "
                                         f"missing or failed); run without {option} to use "
                                         "the nominal model")
    if warnings:
        raise RecordingError(ident_path, f"the identification raised warnings ({warnings[0]}); "
                                         f"its plant is not trusted, run without {option}")
    plant = read_plant_mat(d / "plant.mat")
    return PlantChoice(plant, source=f"identified (from {ident_path})", identification=None,
                       saved=_saved(ident_path, ident))


def _saved(path: Path, ident: Mapping[str, Any]) -> Any:
    """What the budget reads of ``identification.json`` besides the plant: the fitted noise
    model, the recorded loop's 4QD gains and the checks (as the study has them in memory)."""

    raw = ident.get("noise_model")
    noise = None
    if isinstance(raw, dict) and raw:
        try:
            noise = NoiseModelFit.from_json(raw)
        except (KeyError, TypeError, ValueError) as exc:
            raise RecordingError(path, f"has a malformed noise_model ({exc})") from exc
    diagnostics = ident.get("diagnostics")
    loops = diagnostics.get("recorded_loop") if isinstance(diagnostics, dict) else None
    checks = ident.get("checks")
    return SavedIdentification(
        path=str(path), noise_model=noise,
        recorded_loops={str(a): v for a, v in (loops or {}).items() if isinstance(v, dict)},
        checks=tuple(c for c in (checks or ()) if isinstance(c, dict)))


#: The experiment each excitation input is recorded in.
_EXPERIMENT_OF_INPUT = {"Uch": "data_uch", "Ucv": "data_ucv", "Unh": "data_unh",
                        "Unv": "data_unv"}


def excitation_transients(folder: str | Path) -> dict[str, int]:
    """The transient periods of every excitation described in ``folder``, by experiment.

    Reads each ``*.json`` of format ``fsmbench.excitation`` (what ``fsmbench
    excite`` writes beside the file it plays) and maps its ``input`` to the
    experiment that records it (``Uch`` → ``data_uch`` …): the value of
    :class:`fsmbench.ident.pipeline.IdentifyOptions`'s ``transient_periods``.
    Other JSON files are ignored; a description without ``input`` or
    ``transient_periods`` is skipped.

    Parameters
    ----------
    folder : str or Path
        The recording folder.
    """
    out: dict[str, int] = {}
    for path in sorted(Path(folder).glob("*.json")):
        try:
            meta = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError):
            continue
        if not isinstance(meta, dict) or meta.get("format") != "fsmbench.excitation":
            continue
        experiment = _EXPERIMENT_OF_INPUT.get(str(meta.get("input")))
        transient = meta.get("transient_periods")
        if experiment is not None and isinstance(transient, int) and transient >= 0:
            out[experiment] = max(out.get(experiment, 0), transient)
    return out
