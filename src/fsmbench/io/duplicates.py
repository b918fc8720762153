"""One experiment in two files of a folder: ``data_uch.mat`` beside ``data_uch.h5``.

The loader reads one of them (``.mat`` before ``.h5`` before ``.nxs``, as
:func:`~fsmbench.io.recording.find_experiments`); the other may be its faithful
conversion (``fsmbench convert``) or another take of the experiment. Which one was
read is said in a notice, and the experiment is refused, naming both files, unless
they agree. Agreement is checked cheaply first and then exactly: the other file's
variables and their lengths from its headers (a compressed v5 variable's first bytes
inflated, no samples), then its samples,
read as the loader reads them, equal to the first file's (float64, bit for bit: a
conversion copies them exactly; integer or single-precision storage of the same
values compares equal once read).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import xarray as xr

from fsmbench.io.errors import RecordingError
from fsmbench.io.folder_names import SUFFIXES
from fsmbench.io.lazy import _matrix_header, _v5_elements
from fsmbench.io.matfile import detect_format
from fsmbench.io.signals import SIGNALS, TIME

__all__ = ["compare_files", "other_files"]

_KIND = "is in two files that differ"


def other_files(chosen: Path, name: str) -> list[Path]:
    """The other files of experiment ``name`` beside ``chosen`` (``.mat``, ``.h5``, ``.nxs``;
    a link to ``chosen`` itself is not another file)."""
    out = []
    for suffix in SUFFIXES:
        path = chosen.parent / f"{name}{suffix}"
        if path != chosen and path.is_file() and not os.path.samefile(path, chosen):
            out.append(path)
    return out


def compare_files(name: str, chosen: Path, ds: xr.Dataset, others: list[Path], *,
                  read: Callable[[Path], xr.Dataset]) -> str:
    """Check that ``others`` hold what ``chosen`` holds; the notice's sentence if they do.

    Parameters
    ----------
    name : str
        The experiment (``"data_uch"``).
    chosen : Path
        The file read.
    ds : xarray.Dataset
        Its recording.
    others : list of Path
        The other files of the experiment in the same folder.
    read : callable
        Reads a file as ``chosen`` was read (the loader's reader).

    Returns
    -------
    str
        ``"read instead of data_uch.h5, which holds the same 5 variables of 2000
        samples (compared sample by sample)"``, the notice's message (its subject
        is ``chosen``).

    Raises
    ------
    RecordingError
        On the folder, naming both files and the first difference: a variable in one file
        only, a length, the first differing sample (its time and both values), or the other
        file unreadable.
    """
    n = int(ds.sizes[TIME])
    names = [TIME, *map(str, ds.data_vars)]
    for other in others:
        why = _header_difference(chosen, other, names, n) or _sample_difference(
            chosen, ds, other, read)
        if why:
            raise RecordingError(chosen.parent, f"{chosen.name} and {other.name} both hold {name} "
                                 f"but differ: {why}; remove or rename the one that is not the "
                                 "record", kind=f"{_KIND} ({name})")
    held = " and ".join(p.name for p in others)
    return (f"read instead of {held}, which hold{'s' if len(others) == 1 else ''} the same "
            f"{len(names)} variables of {n} samples (compared sample by sample)")


def _header_lengths(path: Path) -> dict[str, int] | None:
    """Variable name to element count, from the headers only (None when not told cheaply)."""
    fmt = detect_format(path)
    if fmt == "mat5":
        out = {}
        for _fh, endian, _start, _size, stream in _v5_elements(path):
            var, _class, count = _matrix_header(stream, endian)
            out[var] = count
        return out
    if fmt not in ("mat73", "hdf5"):
        return None
    with h5py.File(path, "r") as f:
        group: Any = f
        if fmt == "hdf5" and isinstance(f.get("entry/data"), h5py.Group):
            group = f["entry/data"]  # a NeXus archive's signals
        return {k: int(v.size) for k, v in group.items()
                if isinstance(v, h5py.Dataset) and not k.startswith("#")}


def _header_difference(chosen: Path, other: Path, names: list[str], n: int) -> str | None:
    try:
        lengths = _header_lengths(other)
    except (OSError, ValueError, KeyError):
        return None  # the reading says why (next step)
    if lengths is None:
        return None
    for var in names:
        if var not in lengths:
            return f"{var} is in {chosen.name} only"
        if lengths[var] != n:
            return (f"{var} has {n} samples in {chosen.name} and {lengths[var]} in "
                    f"{other.name}")
    extra = [k for k, m in lengths.items() if k in SIGNALS and m == n and k not in names]
    return f"{extra[0]} is in {other.name} only" if extra else None


def _sample_difference(chosen: Path, ds: xr.Dataset, other: Path,
                       read: Callable[[Path], xr.Dataset]) -> str | None:
    try:
        theirs = read(other)
    except RecordingError as exc:
        return f"{other.name} cannot be used ({exc.problem if exc.file == str(other) else exc})"
    mine = [TIME, *map(str, ds.data_vars)]
    if set(mine) != {TIME, *map(str, theirs.data_vars)} or theirs.sizes[TIME] != ds.sizes[TIME]:
        only = sorted(set(map(str, theirs.data_vars)) ^ set(mine[1:]))
        return (f"{only[0]} is in one file only" if only else
                f"t has {ds.sizes[TIME]} samples in {chosen.name} and {theirs.sizes[TIME]} in "
                f"{other.name}")
    for var in mine:
        found = _first_difference(ds[var].data, theirs[var].data)
        if found is not None:
            index, count = found
            unit = "s" if var == TIME else SIGNALS[var].units if var in SIGNALS else ""
            a, b = (f"{float(np.asarray(x[var].data[index])):.10g}{' ' if unit else ''}{unit}"
                    for x in (ds, theirs))
            at = "" if var == TIME else f" (t = {float(np.asarray(ds[TIME].data[index])):.10g} s)"
            return (f"{var} differs first at sample {index}{at}: {a} in {chosen.name}, {b} in "
                    f"{other.name} ({count} sample{'s differ' if count > 1 else ' differs'})")
    return None


def _first_difference(a: Any, b: Any) -> tuple[int, int] | None:
    """(first index, count) where ``a`` and ``b`` differ (NaN equal to NaN), or None."""
    lazy = type(a).__module__.startswith("dask") or type(b).__module__.startswith("dask")
    if not lazy:
        x, y = np.asarray(a), np.asarray(b)
        differ = (x != y) & ~(np.isnan(x) & np.isnan(y))
        count = int(np.count_nonzero(differ))
        return (int(np.argmax(differ)), count) if count else None
    import dask
    import dask.array as da

    differ = (a != b) & ~(da.isnan(a) & da.isnan(b))
    (count,) = dask.compute(differ.sum())
    return (int(da.argmax(differ).compute()), int(count)) if int(count) else None
