"""MATLAB-loadable outputs of the identification: ``frf.mat`` and ``plant.mat``.

``frf.mat`` holds the frequency vector ``f`` [Hz] (a column) and, for each
measured pair, ``tf_<input>_<output>`` (complex FRF, column) and
``coh_<input>_<output>`` (coherence, column) — the seed's variable names, so a
MATLAB user can lay them over their own ``tfestimate``/``mscohere`` results
(see :func:`frf_variables` for responses on other grids and their std).

``plant.mat`` holds one struct per block (``Gi, Zc, Ga, Gc, Gn, Gd``) and one
for the full system (``sys``), each with fields ``A, B, C, D`` (double
matrices), ``InputName``, ``OutputName``, ``StateName`` (cell arrays of
char) and ``InputDelay`` [s] (column, one per input); in MATLAB
``ss(s.A, s.B, s.C, s.D, 'InputName', s.InputName, ...)`` rebuilds it.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import control as ct
import numpy as np

from fsmbench.atomic import atomic_write_text
from fsmbench.bench.blocks import PlantModel
from fsmbench.ident.frf.response import FrequencyResponse
from fsmbench.io.matwrite import save_mat
from fsmbench.jsonutil import format_text, stamped

__all__ = ["IDENTIFICATION_FORMAT", "frf_variables", "plant_variables", "ss_struct",
           "write_frf_mat", "write_identification_folder", "write_plant_mat"]

#: ``identification.json``'s format and version (open-loop and closed-loop identifications).
IDENTIFICATION_FORMAT = ("fsmbench.identification", 4)


def frf_variables(responses: Mapping[str, FrequencyResponse]) -> dict[str, Any]:
    """The seed's variables for every (input, output) pair of ``responses``.

    ``f`` is the first response's grid; a response on another grid (e.g. the
    Sercalo averaged over a multisine's periods, the Newport by Welch) gets its
    own ``f_<key>`` column, named in ``frf_grid_<input>`` (written only when the
    grids differ). An estimate with a
    variance adds ``std_tf_<input>_<output>`` (standard deviation of the complex
    FRF, column).
    """
    out: dict[str, Any] = {}
    f_ref: np.ndarray | None = None
    for key, resp in responses.items():
        f = resp.frequency_hz
        grid = "f"
        if f_ref is None:
            f_ref = f
            out["f"] = f.reshape(-1, 1)
        elif f.shape != f_ref.shape or not np.allclose(f, f_ref, rtol=0, atol=1e-9):
            grid = f"f_{key}"
            out[grid] = f.reshape(-1, 1)
        for inp in resp.input_names:
            out[f"frf_grid_{inp}"] = grid
            for outp in resp.output_names:
                h = resp.frf.sel(input=inp, output=outp).values
                c = resp.coherence.sel(input=inp, output=outp).values
                out[f"tf_{inp}_{outp}"] = np.asarray(h, dtype=complex).reshape(-1, 1)
                out[f"coh_{inp}_{outp}"] = np.asarray(c, dtype=float).reshape(-1, 1)
                if resp.frf_variance is not None:
                    var = resp.frf_variance.sel(input=inp, output=outp).values
                    out[f"std_tf_{inp}_{outp}"] = np.sqrt(
                        np.asarray(var, dtype=float)).reshape(-1, 1)
    if not any(k.startswith("f_") for k in out):  # one grid: the seed's variables only
        out = {k: v for k, v in out.items() if not k.startswith("frf_grid_")}
    return out


def ss_struct(sys: ct.StateSpace, *, input_delay_s: Mapping[str, float] | None = None
              ) -> dict[str, Any]:
    """A MATLAB struct (dict) describing a continuous state-space model."""
    delays = input_delay_s or {}
    return {
        "A": np.atleast_2d(np.asarray(sys.A, dtype=float)).reshape(sys.nstates, sys.nstates),
        "B": np.asarray(sys.B, dtype=float).reshape(sys.nstates, sys.ninputs),
        "C": np.asarray(sys.C, dtype=float).reshape(sys.noutputs, sys.nstates),
        "D": np.asarray(sys.D, dtype=float).reshape(sys.noutputs, sys.ninputs),
        "InputName": [str(x) for x in sys.input_labels],
        "OutputName": [str(x) for x in sys.output_labels],
        "StateName": [str(x) for x in sys.state_labels] if sys.nstates else [],
        "InputDelay": np.array([float(delays.get(str(x), 0.0)) for x in sys.input_labels],
                               dtype=float).reshape(-1, 1),
        "Ts": 0.0 if not sys.dt else float(sys.dt),
    }


def plant_variables(plant: PlantModel) -> dict[str, Any]:
    """``sys`` and every block of ``plant`` as structs, plus its provenance."""
    out: dict[str, Any] = {"sys": ss_struct(plant.sys, input_delay_s=plant.input_delay_s)}
    for name, block in plant.blocks.items():
        out[name] = ss_struct(block)
    out["source"] = plant.source
    return out


def write_frf_mat(path: str | Path, responses: Mapping[str, FrequencyResponse]) -> Path:
    """Write ``frf.mat`` (MATLAB v5) atomically."""
    return save_mat(path, frf_variables(responses))


def write_plant_mat(path: str | Path, plant: PlantModel) -> Path:
    """Write ``plant.mat`` (MATLAB v5) atomically."""
    return save_mat(path, plant_variables(plant))


def write_identification_folder(out_dir: str | Path, *, document: Mapping[str, Any],
                                plant: PlantModel | None,
                                frfs: Mapping[str, FrequencyResponse]) -> list[Path]:
    """An identification's folder: ``identification.json``, ``plant.mat``, ``frf.mat``.

    The one writer of the layout ``--bench DIR`` reads (:mod:`fsmbench.ident.load`), for
    the open-loop and the closed-loop identifications. Every file is written atomically.

    Parameters
    ----------
    out_dir : str or Path
        Made if missing.
    document : mapping
        ``identification.json``'s content, stamped here with :data:`IDENTIFICATION_FORMAT`
        (keys sorted, ``format`` and ``format_version`` first).
    plant : PlantModel or None
        ``plant.mat`` (not written when None: nothing was identified).
    frfs : mapping of str to FrequencyResponse
        ``frf.mat``'s measured FRF matrices by name (not written when empty).

    Returns
    -------
    list of Path
        The files written, in that order.
    """

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    name, version = IDENTIFICATION_FORMAT
    paths = [atomic_write_text(out / "identification.json",
                               format_text(stamped(document, format=name, version=version),
                                           sort_keys=True))]
    if plant is not None:
        paths.append(write_plant_mat(out / "plant.mat", plant))
    if frfs:
        paths.append(write_frf_mat(out / "frf.mat", frfs))
    return paths
