"""Recordings of the bench as ``xarray.Dataset``: build, check, read, write.

A recording holds one float64 variable per signal on the dimension ``"t"``:

* coordinate ``t``, in s (attrs ``units="s"``, ``long_name="Time"``);
* each signal: attrs ``units`` and ``long_name`` from
  :data:`fsmbench.io.signals.SIGNALS`; a variable the ESRF study does not know is
  kept with ``units=""`` and a ``note`` saying so;
* dataset attrs ``fs_hz`` (sampling frequency, Hz, float), ``experiment``
  (e.g. ``"data_uch"``) and ``source`` (the file read, or ``""``).

Files are MATLAB v5/v7 or v7.3 MAT-files (what the ESRF study's ``load`` reads) or
the NeXus archive of :mod:`fsmbench.io.nexus`; the format is told from the
content. Every problem is a :class:`~fsmbench.io.errors.RecordingError` that
names the file and the variable.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any, Final, Literal

import numpy as np
import xarray as xr

from fsmbench.io import nexus
from fsmbench.io.dataset import (
    as_vector,
    assemble,
    check_lengths,
    fitted_time_base,
    make_recording,
    note_reading,
    validate_dataset,
    validate_recording,
)
from fsmbench.io.errors import RecordingError
from fsmbench.io.matfile import detect_format, load_mat, other_run_words
from fsmbench.io.matwrite import save_mat
from fsmbench.io.signals import EXPERIMENTS, SIGNALS, TIME
from fsmbench.io.timebase import TimeBase, coarse_double, single_precision
from fsmbench.io.trailing import data_end, warn_trailing

__all__ = [
    "RecordingFormat",
    "find_experiments",
    "make_recording",
    "mat_variables",
    "read_recording",
    "recording_as_read",
    "validate_recording",
    "write_recording",
]

#: Formats :func:`write_recording` writes.
RecordingFormat = Literal["mat5", "mat73", "nexus"]

_SUFFIXES: Final = (".mat", ".h5", ".nxs")  # find_experiments' preference order


def _default_require(*names: str) -> tuple[str, tuple[str, ...]]:
    """(experiment whose load list applies, that list); the first known name wins."""
    for name in names:
        if name in EXPERIMENTS:
            return name, EXPERIMENTS[name].required
    return names[0], (TIME,)


def read_recording(
    path: str | os.PathLike[str],
    *,
    experiment: str | None = None,
    require: Iterable[str] | None = None,
    adc_range_v: float = 20.0,
    adc_bits: int = 16,
) -> xr.Dataset:
    """Read and check a recording from a MAT-file (v4, v5/v7, v7.3) or NeXus archive.

    Parameters
    ----------
    path : str or os.PathLike
        The file; its format is told from its content, not its suffix. It is
        opened read-only and never modified.
    experiment : str, optional
        Experiment name; default the archive's own (NeXus) or the file stem.
    require : iterable of str, optional
        Variables that must be present. Default: the ESRF study's ``load`` list
        (:data:`~fsmbench.io.signals.EXPERIMENTS`) when the experiment or the
        stem is known, else only ``t``.
    adc_range_v : float, default 20.0
        ADC input range, in V, for the saturation check.
    adc_bits : int, default 16
        ADC resolution, in bits.

    Returns
    -------
    xarray.Dataset
        The recording. ``source`` is the absolute path read (NeXus archives
        keep the ``source`` stored in them); ``fs_hz`` comes from ``t``.
        Variables of a MAT-file that are not sampled on ``t`` (scalars,
        strings, structs) are left out with a ``UserWarning``.

    Raises
    ------
    RecordingError
        Any problem of the file or its content (see :func:`validate_recording`).
    """
    p = Path(path)
    fmt = detect_format(p)
    if fmt == "hdf5" and nexus.is_nexus(p):
        return _read_nexus_recording(p, fmt=fmt, experiment=experiment, require=require,
                                     adc_range_v=adc_range_v, adc_bits=adc_bits)
    experiment = p.stem if experiment is None else experiment
    needs, req = _default_require(experiment, p.stem)
    if require is not None:
        needs, req = "the caller", tuple(require)
    raw = load_mat(p, skip_unreadable=True)  # warns of trailing bytes itself
    return _recording_of(p, raw, fmt=fmt, experiment=experiment, needs=needs, req=req,
                         adc_range_v=adc_range_v, adc_bits=adc_bits)


def recording_as_read(
    path: str | os.PathLike[str],
    variables: Mapping[str, np.ndarray],
    *,
    experiment: str,
    adc_range_v: float = 20.0,
    adc_bits: int = 16,
) -> xr.Dataset:
    """The recording :func:`read_recording` gives of a MAT-file this process just wrote,
    from the variables written, without decoding the file again.

    The reader's own steps run on ``variables`` (required variables, lengths, time
    base, checks, notes, ``source``), so the result is identical to reading the file
    back: MAT-files hold float64 columns losslessly (tested).

    Parameters
    ----------
    path : str or os.PathLike
        The MAT-file (v5/v7 or v7.3) :func:`write_recording` wrote ``variables`` to.
    variables : mapping of str to numpy.ndarray
        What was written (:func:`mat_variables`), each shape (N,), float64.
    experiment : str
        Experiment name (``"data_uch"`` …).
    adc_range_v, adc_bits : float, int
        As :func:`read_recording`.

    Raises
    ------
    RecordingError
        As :func:`read_recording`; also a file that is not a MAT-file.
    """
    p = Path(path)
    fmt = detect_format(p)
    if fmt not in ("mat5", "mat73"):
        raise RecordingError(p, f"is a {fmt} file, not the MAT-file its records were "
                                "written to")
    needs, req = _default_require(experiment, p.stem)
    # MATLAB's shapes, as load_mat gives them: N×1 columns.
    raw = {name: np.asarray(v).reshape(-1, 1) for name, v in variables.items()}
    return _recording_of(p, raw, fmt=fmt, experiment=experiment, needs=needs, req=req,
                         adc_range_v=adc_range_v, adc_bits=adc_bits)


def _recording_of(p: Path, raw: Mapping[str, Any], *, fmt: str, experiment: str, needs: str,
                  req: tuple[str, ...], adc_range_v: float, adc_bits: int) -> xr.Dataset:
    """:func:`read_recording` of a MAT-file once its variables are read (``raw``)."""
    origin = os.fspath(p)
    _check_required(p, raw, needs=needs, req=req)
    vectors = _sampled_vectors(raw, origin=origin, req=req)
    check_lengths(vectors, origin)
    t = vectors[TIME]
    base = fitted_time_base(t)
    ds = assemble(vectors, fs_hz=base.fs_hz if base is not None else float("nan"),
                  experiment=experiment, source=os.path.abspath(p))
    for name in vectors:  # what the file held, for the data-type checks (integer counts …)
        stored = np.asarray(raw[name]).dtype
        if stored != np.float64:
            ds[name].attrs["stored_dtype"] = str(stored)
    _validate_mat_recording(ds, t=t, raw_t=raw[TIME], origin=origin, req=req,
                            adc_range_v=adc_range_v, adc_bits=adc_bits, base=base)
    note_reading(ds, base, data_end(p, fmt))
    return ds


def _read_nexus_recording(p: Path, *, fmt: str, experiment: str | None,
                          require: Iterable[str] | None, adc_range_v: float,
                          adc_bits: int) -> xr.Dataset:
    """:func:`read_recording` of a NeXus archive (parameters as there; ``fmt``: "hdf5").

    Its warnings point at :func:`read_recording`'s caller, as the MAT-files' do.
    """
    end = warn_trailing(data_end(p, fmt), stacklevel=3)
    ds = nexus.read_nexus(p)
    if experiment is not None:
        ds.attrs["experiment"] = experiment
    req = (_default_require(ds.attrs["experiment"], p.stem)[1] if require is None
           else tuple(require))
    grid = validate_dataset(ds, origin=os.fspath(p), require=req, adc_range_v=adc_range_v,
                            adc_bits=adc_bits, saturation=True, stacklevel=4)
    note_reading(ds, grid, end)
    return ds


def _check_required(p: Path, raw: Mapping[str, Any], *, needs: str,
                    req: tuple[str, ...]) -> None:
    """Raise a :class:`RecordingError` unless the MAT-file holds ``t`` and all of ``req``.

    ``needs``: who asks for ``req`` (an experiment's name, or "the caller"), for the message.
    """
    origin = os.fspath(p)
    if TIME not in raw:
        present = ", ".join(raw) or "nothing"
        raise RecordingError(origin, "is missing: a recording needs its time vector t, in s "
                             f"(the file holds: {present})", variable=TIME, kind="is missing")
    missing = [r for r in req if r not in raw]
    if missing:
        also = f" (and so are {', '.join(repr(m) for m in missing[1:])})" if missing[1:] else ""
        raise RecordingError(
            origin, f"is missing{also}; {needs} needs {', '.join(req)} "
            f"(the file holds: {', '.join(raw)}){other_run_words(p, raw)}",
            variable=missing[0], kind="is missing",
        )


def _sampled_vectors(raw: Mapping[str, Any], *, origin: str,
                     req: tuple[str, ...]) -> dict[str, np.ndarray]:
    """``t`` and the MAT-file's variables sampled on it, as float64 vectors.

    A known or required variable that is not a vector raises; another one is
    left out with a ``UserWarning`` at :func:`read_recording`'s caller, as is one
    whose length is not ``t``'s.
    """
    vectors = {TIME: as_vector(TIME, raw[TIME], origin)}
    n = vectors[TIME].size
    known = [k for k in raw if k == TIME or k in SIGNALS or k in req]
    for name in [k for k in raw if k != TIME]:
        try:
            v = as_vector(name, raw[name], origin)
        except RecordingError as exc:
            if name in known:
                raise
            warnings.warn(f"{origin}: variable '{name}' left out: {exc.problem}", UserWarning,
                          stacklevel=4)
            continue
        if v.size != n and name not in known:
            values = f"{v.size} value{'s' if v.size != 1 else ''}"
            warnings.warn(f"{origin}: variable '{name}' left out: it has {values} and t has "
                          f"{n}, so it is not sampled on t", UserWarning, stacklevel=4)
            continue
        vectors[name] = v
    return vectors


def _validate_mat_recording(ds: xr.Dataset, *, t: np.ndarray, raw_t: Any, origin: str,
                            req: tuple[str, ...], adc_range_v: float, adc_bits: int,
                            base: TimeBase | None) -> None:
    """:func:`validate_dataset` of a MAT-file's recording (warnings at the reader's caller).

    A problem of ``t`` [s] says, when it is so, that it was stored in single
    precision (``raw_t``: ``t`` as the file held it) or rounded too coarsely.
    """
    try:
        validate_dataset(ds, origin=origin, require=req, adc_range_v=adc_range_v,
                         adc_bits=adc_bits, saturation=True, stacklevel=5, base=base)
    except RecordingError as exc:
        stored = np.asarray(raw_t).dtype
        if exc.variable == TIME and stored.kind == "f" and stored.itemsize < 8:
            raise RecordingError(origin, exc.problem + "; " + single_precision(t, stored),
                                 variable=TIME, kind=exc.kind) from None
        if exc.variable == TIME and (coarse := coarse_double(t)):
            raise RecordingError(origin, exc.problem + "; " + coarse, variable=TIME,
                                 kind=exc.kind) from None
        raise


def write_recording(
    ds: xr.Dataset,
    path: str | os.PathLike[str],
    *,
    format: RecordingFormat = "mat5",
    compress: bool | None = None,
    created: float | None = None,
) -> Path:
    """Write a recording, atomically (complete file or none).

    Parameters
    ----------
    ds : xarray.Dataset
        A valid recording (checked first; nothing is written if it fails).
    path : str or os.PathLike
        Destination; its folder must exist.
    format : {"mat5", "mat73", "nexus"}, default "mat5"
        MATLAB v7 (v5 layout, compressed), MATLAB v7.3 (HDF5), or the NeXus
        archive of :mod:`fsmbench.io.nexus`. MAT-files hold ``t`` and each
        signal as an N×1 double column, which MATLAB's ``load`` reads as the
        seed does; units and attributes are kept by NeXus only.
    compress : bool, optional
        Compress the samples; default: yes for mat5 and nexus (gzip), no for mat73.
    created : float, optional
        Creation time stamped in the file [s since the epoch, UTC]; default
        now. A fixed value makes the file a pure function of ``ds``.

    Returns
    -------
    Path
        The destination.
    """
    dest = Path(path)
    validate_dataset(ds, origin=os.fspath(dest), require=(), adc_range_v=20.0, adc_bits=16,
              saturation=False, stacklevel=3)
    if format == "nexus":
            return nexus.write_nexus(ds, dest, compress=compress is not False, created=created)
    if format not in ("mat5", "mat73"):
        raise ValueError(f"{dest}: unknown recording format {format!r}; "
                         "use 'mat5', 'mat73' or 'nexus'")
    return save_mat(dest, mat_variables(ds), version="5" if format == "mat5" else "7.3",
                    compress=compress, created=created)


def mat_variables(ds: xr.Dataset) -> dict[str, np.ndarray]:
    """The variables :func:`write_recording` stores in a MAT-file: ``t`` [s], then each
    signal, float64 of shape (N,) (written as N×1 columns)."""
    variables = {TIME: np.asarray(ds[TIME].values, dtype=np.float64)}
    for name in ds.data_vars:
        variables[str(name)] = np.asarray(ds[name].values, dtype=np.float64)
    return variables


def find_experiments(folder: str | os.PathLike[str]) -> dict[str, Path]:
    """Which of the ESRF study's experiments a folder holds.

    Parameters
    ----------
    folder : str or os.PathLike
        Folder to look in (not recursively).

    Returns
    -------
    dict of str to Path
        Experiment name to file, for each ``<name>.mat``, ``<name>.h5`` or
        ``<name>.nxs`` found, in :data:`~fsmbench.io.signals.EXPERIMENTS`
        order. When several exist, ``.mat`` (the original) wins over ``.h5``
        over ``.nxs``.

    Raises
    ------
    NotADirectoryError
        ``folder`` is not a folder.
    """
    root = Path(folder)
    if not root.is_dir():
        raise NotADirectoryError(f"{root}: not a folder")
    found: dict[str, Path] = {}
    for name in EXPERIMENTS:
        for suffix in _SUFFIXES:
            candidate = root / f"{name}{suffix}"
            if candidate.is_file():
                found[name] = candidate
                break
    return found
