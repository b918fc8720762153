"""The native archive of a recording: HDF5 in the NeXus layout.

Layout (NeXus: NXentry holding an NXdata group, https://manual.nexusformat.org)::

    /                   attrs default="entry", creator, format="fsmbench.nexus_recording",
                        format_version=2, file_time (or file_time_note), HDF5_Version
    /entry              NX_class="NXentry", default="data",
                        experiment, fs_hz (Hz), source, and any other dataset attrs;
                        start_time, end_time (ISO 8601 with offset) when the recording
                        has them, else @start_time_note
    /entry/instrument   NXinstrument: converters and bench parts with units
                        (:func:`fsmbench.io.nexus_meta.write_instrument`)
    /entry/data         NX_class="NXdata", signal=<first signal>, axes="t",
                        t_indices=0, auxiliary_signals=[<other signals>]
    /entry/data/t       float64 (N,), units="s", long_name="Time"
    /entry/data/<name>  float64 (N,), units, long_name (and note) as in the Dataset

The samples are chunked and gzip-compressed (see :mod:`fsmbench.io.nexus_meta`
for why gzip). Every attribute of the Dataset, of ``t`` and of each signal is
stored and read back (``start_time`` and ``end_time`` as NXentry fields), so
``read_nexus(write_nexus(ds, path))`` is identical to ``ds``, samples bit for
bit and variables in the same order.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

import h5py
import numpy as np
import xarray as xr

from fsmbench.atomic import atomic_path
from fsmbench.bench.params import default_bench
from fsmbench.io.dataset import as_vector, check_lengths, validate_dataset
from fsmbench.io.errors import RecordingError
from fsmbench.io.nexus_meta import (
    END_TIME,
    FILE_ATTRS,
    START_TIME,
    compression_options,
    read_times,
    write_instrument,
    write_root,
    write_times,
)
from fsmbench.io.notes import READ_NOTES
from fsmbench.io.signals import TIME

if TYPE_CHECKING:
    from fsmbench.bench.params import Bench

__all__ = ["is_nexus", "read_nexus", "write_nexus"]

_ENTRY: Final = "entry"
_DATA: Final = "data"
# Attributes that describe the NeXus layout itself, not the recording.
_LAYOUT_ATTRS: Final = FILE_ATTRS | {"signal", "axes", "auxiliary_signals", f"{TIME}_indices"}
#: Samples per chunk of a compressed dataset: 512 KiB of float64, as the streaming writer.
_CHUNK_SAMPLES: Final = 1 << 16


def _plain(value: Any) -> Any:
    """An HDF5 attribute value as the Python type it was written from."""
    if isinstance(value, bytes):
        return value.decode("utf-8")
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray) and value.dtype == object:
        return [_plain(v) for v in value.tolist()]
    return value


def is_nexus(path: str | os.PathLike[str]) -> bool:
    """True if ``path`` is an HDF5 file with an NXentry group ``/entry``.

    Parameters
    ----------
    path : str or os.PathLike
        The file; opened read-only.

    Returns
    -------
    bool
        False as well for files that are not HDF5 at all.
    """
    try:
        with h5py.File(path, "r") as f:
            entry = f.get(_ENTRY)
            return isinstance(entry, h5py.Group) and _plain(entry.attrs.get("NX_class")) == (
                "NXentry"
            )
    except OSError:
        return False


def write_nexus(ds: xr.Dataset, path: str | os.PathLike[str], *, compress: bool = True,
                created: float | None = None, bench: Bench | None = None) -> Path:
    """Write a recording as a NeXus archive, atomically.

    Parameters
    ----------
    ds : xarray.Dataset
        A valid recording (see :mod:`fsmbench.io.recording`), N samples.
        Checked first; nothing is written if it fails. Attributes ``start_time``
        and ``end_time`` (ISO 8601 with a UTC offset), when present, become the
        NXentry's fields; without ``start_time`` the file says it is not known.
    path : str or os.PathLike
        Destination (``.nxs`` by convention); its folder must exist.
    compress : bool, default True
        gzip (level 1) with byte shuffling, chunks of 65536 samples: about half
        the size for 16-bit ADC data. False: contiguous, raw.
    created : float, optional
        ``file_time`` [s since the epoch]; default now.
        :data:`~fsmbench.io.nexus_meta.UNSTAMPED_S` (the epoch): none, so the
        file is a pure function of ``ds``.
    bench : Bench, optional
        The bench the samples come from, described in ``/entry/instrument``;
        default the packaged bench (``@assumed`` says so).

    Returns
    -------
    Path
        The destination.

    Raises
    ------
    ValueError
        ``start_time`` or ``end_time`` not ISO 8601 with a UTC offset.
    """

    dest = Path(path)
    validate_dataset(ds, origin=os.fspath(dest), require=(), adc_range_v=20.0, adc_bits=16,
              saturation=False, stacklevel=3)
    names = [str(n) for n in ds.data_vars]
    opts = compression_options(ds.sizes[TIME], chunk_samples=_CHUNK_SAMPLES, compress=compress)
    times = {START_TIME: ds.attrs.get(START_TIME), END_TIME: ds.attrs.get(END_TIME)}
    with atomic_path(dest) as tmp, h5py.File(tmp, "w") as f:
        write_root(f, created=created)
        entry = f.create_group(_ENTRY)
        entry.attrs["NX_class"] = "NXentry"
        entry.attrs["default"] = _DATA
        for key, value in ds.attrs.items():
            # READ_NOTES describe the file read, not this one; the times are fields.
            if key not in READ_NOTES and key not in times:
                entry.attrs[key] = value
        write_times(entry, start=times[START_TIME], end=times[END_TIME],
                    unknown="not known: the recording does not say when it was taken")
        write_instrument(entry, default_bench() if bench is None else bench)
        if bench is None:
            entry["instrument"].attrs["assumed"] = ("the packaged bench: the writer was not "
                                                    "told which bench took the samples")
        data = entry.create_group(_DATA)
        data.attrs["NX_class"] = "NXdata"
        data.attrs["axes"] = TIME
        data.attrs[f"{TIME}_indices"] = np.int32(0)
        if names:
            data.attrs["signal"] = names[0]
        if len(names) > 1:
            data.attrs["auxiliary_signals"] = names[1:]
        for name in [TIME, *names]:
            values = np.ascontiguousarray(ds[name].values, dtype=np.float64)
            dset = data.create_dataset(name, data=values, track_times=False, **opts)
            for key, value in ds[name].attrs.items():
                dset.attrs[key] = value
    return dest


def read_nexus(path: str | os.PathLike[str]) -> xr.Dataset:
    """Read a NeXus archive written by :func:`write_nexus`, as it was written.

    Parameters
    ----------
    path : str or os.PathLike
        The archive; opened read-only, never modified.

    Returns
    -------
    xarray.Dataset
        The stored recording: every attribute, variable order and sample
        (float64, shape (N,)) as written. Samples are not checked here
        (NaN, time base, saturation): :func:`~fsmbench.io.recording.read_recording`
        does that.

    Raises
    ------
    RecordingError
        Not an HDF5 file, no NXentry ``/entry`` or NXdata ``/entry/data``, ``t``
        missing, a variable that is not a numeric vector, unequal lengths.
    """
    p = Path(path)
    origin = os.fspath(p)
    try:
        f = h5py.File(p, "r")
    except OSError as exc:
        raise RecordingError(origin, f"cannot be read as an HDF5 file ({exc})") from exc
    with f:
        entry = f.get(_ENTRY)
        if not isinstance(entry, h5py.Group) or _plain(entry.attrs.get("NX_class")) != "NXentry":
            raise RecordingError(origin, "is not a NeXus archive: no NXentry group /entry")
        data = entry.get(_DATA)
        if not isinstance(data, h5py.Group) or _plain(data.attrs.get("NX_class")) != "NXdata":
            raise RecordingError(origin, "is not a recording archive: no NXdata group "
                                 "/entry/data")
        axis = _plain(data.attrs.get("axes", TIME))
        if axis != TIME or TIME not in data:
            present = ", ".join(data) or "nothing"
            raise RecordingError(origin, f"is missing from /entry/data (axes = {axis!r}; "
                                 f"present: {present})", variable=TIME)
        signal = _plain(data.attrs.get("signal"))
        aux = _plain(data.attrs.get("auxiliary_signals", []))
        order = ([signal] if signal else []) + ([aux] if isinstance(aux, str) else list(aux))
        order += [k for k in data if k not in order and k != TIME]
        missing = [k for k in order if k not in data]
        if missing:
            raise RecordingError(origin, "is named by /entry/data's signal attributes but "
                                 "is not in the archive", variable=missing[0])
        vectors: dict[str, np.ndarray] = {}
        var_attrs: dict[str, dict[str, Any]] = {}
        for name in [TIME, *order]:
            dset = data[name]
            if not isinstance(dset, h5py.Dataset):
                raise RecordingError(origin, "is a group, not samples", variable=name)
            vectors[name] = as_vector(name, dset[()], origin)
            var_attrs[name] = {k: _plain(v) for k, v in dset.attrs.items()}
        attrs = {k: _plain(v) for k, v in entry.attrs.items() if k not in _LAYOUT_ATTRS}
        attrs.update(read_times(entry))
    check_lengths(vectors, origin)
    return xr.Dataset(
        {name: (TIME, vectors[name], var_attrs[name]) for name in order},
        coords={TIME: (TIME, vectors[TIME], var_attrs[TIME])},
        attrs=attrs,
    )
