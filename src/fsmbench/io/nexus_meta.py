"""What a NeXus archive says besides its samples: format, times, instrument, compression.

Shared by :func:`fsmbench.io.nexus.write_nexus` (a recording in memory) and
:class:`fsmbench.io.nexus_stream.NexusAppender` (written block by block), so both
write the same layout (https://manual.nexusformat.org)::

    /                     attrs default, creator, format, format_version, HDF5_Version,
                          file_time (when the file was written) or file_time_note
    /entry                NXentry; start_time, end_time (NX_DATE_TIME: ISO 8601 with
                          its UTC offset) when known, else @start_time_note
    /entry/instrument     NXinstrument: the bench file's converters and components,
                          every field with @units (see :func:`write_instrument`)

Strings written as datasets are fixed-length ASCII: GNU Octave's HDF5 ``load``
(Octave has no ``h5read``) fails on a whole file at the first variable-length
string dataset; h5py, MATLAB and the NeXus tools read both kinds.
"""

from __future__ import annotations

import dataclasses
import datetime
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, Final

import h5py
import numpy as np

from fsmbench.io.matwrite import wall_clock_wanted
from fsmbench.version import __version__

if TYPE_CHECKING:
    from fsmbench.bench.params import Bench

__all__ = ["END_TIME", "FILE_ATTRS", "NEXUS_FORMAT", "START_TIME", "UNSTAMPED_S", "check_time",
           "compression_options", "iso_time", "read_times", "write_instrument", "write_root",
           "write_times"]

#: Root attributes ``format``, ``format_version``. Version 2: NXinstrument,
#: start/end times or a note saying they are unknown, gzip, no 1970 file_time.
#: Files before it carry no version.
NEXUS_FORMAT: Final = ("fsmbench.nexus_recording", 2)
#: NXentry fields: the wall clock of the first and the last sample. A recording
#: (xarray) keeps them as attributes of these names.
START_TIME: Final = "start_time"
END_TIME: Final = "end_time"
#: ``created`` that asks for no wall clock in the file: the epoch, which the
#: reproducible writers pass (:data:`fsmbench.io.matwrite.FIXED_CREATED_S`, the twin,
#: ``fsmbench convert``) so that the same inputs give the same bytes. A NeXus file
#: then says it carries no file_time rather than show a 1970 date.
UNSTAMPED_S: Final = 0.0
#: Entry attributes that describe the file, not the recording: readers leave them out.
FILE_ATTRS: Final = frozenset({"NX_class", "default", "start_time_note"})

# gzip (deflate) is built into the HDF5 library itself, so MATLAB's h5read, Octave's
# load -hdf5, h5py and every NeXus tool read it; lzf ships only inside h5py and would
# leave the file unreadable to MATLAB. Level 1 with byte shuffling: 16-bit ADC codes
# as float64 shrink to about half at a small cost in write speed (higher levels gain
# little more on such data).
_GZIP: Final = {"compression": "gzip", "compression_opts": 1, "shuffle": True}


def compression_options(n_samples: int | None, *, chunk_samples: int,
                        compress: bool = True) -> dict[str, Any]:
    """``create_dataset`` keywords for a signal of ``n_samples`` (None: growing).

    Parameters
    ----------
    n_samples : int or None
        Length of the dataset [samples]; None for one extended block by block.
    chunk_samples : int
        Longest chunk along time [samples].
    compress : bool, default True
        gzip level 1 with shuffling; False: chunked (if growing) but raw.

    Returns
    -------
    dict
        ``chunks`` (only when compressed or growing: HDF5 needs chunks for both)
        and the filter keywords.
    """
    opts: dict[str, Any] = dict(_GZIP) if compress else {}
    if compress or n_samples is None:
        opts["chunks"] = (max(1, min(chunk_samples, n_samples or chunk_samples)),)
    return opts


def iso_time(seconds: float | None = None) -> str:
    """A time as NeXus ``NX_DATE_TIME``: ISO 8601 with the local UTC offset.

    Parameters
    ----------
    seconds : float, optional
        Seconds since the epoch; default now.
    """
    when = (datetime.datetime.now() if seconds is None
            else datetime.datetime.fromtimestamp(seconds))
    return when.astimezone().isoformat()


def _text(value: str) -> np.bytes_:
    """A string for a dataset: fixed-length ASCII (see the module notes)."""
    return np.bytes_(value.encode("ascii", "replace"))


def write_root(f: h5py.File, *, created: float | None,
               extra: Mapping[str, Any] | None = None) -> None:
    """The root group's attributes.

    Parameters
    ----------
    f : h5py.File
        Open for writing.
    created : float or None
        ``file_time`` [s since the epoch]; None: now; :data:`UNSTAMPED_S`: none (the
        attribute ``file_time_note`` says why), or now within
        :func:`~fsmbench.io.matwrite.wall_clock_headers` (``--timestamp``).
    extra : mapping, optional
        More root attributes (``fsmbench convert``'s provenance).
    """

    f.attrs["default"] = "entry"
    f.attrs["creator"] = f"fsmbench {__version__}"
    f.attrs["format"], f.attrs["format_version"] = NEXUS_FORMAT[0], np.int32(NEXUS_FORMAT[1])
    if created == UNSTAMPED_S and not wall_clock_wanted():
        f.attrs["file_time_note"] = ("no file_time: a reproducible output (the same inputs "
                                     "give the same bytes); the commands' --timestamp "
                                     "records it")
    else:
        f.attrs["file_time"] = iso_time(None if created == UNSTAMPED_S else created)
    f.attrs["HDF5_Version"] = h5py.version.hdf5_version
    for key, value in (extra or {}).items():
        f.attrs[key] = value


def check_time(value: Any, what: str) -> str:
    """``value`` as NeXus ``NX_DATE_TIME`` text, checked.

    Raises
    ------
    ValueError
        Not ISO 8601, or without a UTC offset.
    """
    text = str(value)
    stamp = datetime.datetime.fromisoformat(text)  # ValueError: not ISO 8601
    if stamp.tzinfo is None:
        raise ValueError(f"{what} {text!r} has no UTC offset (NeXus NX_DATE_TIME needs one)")
    return text


def write_times(entry: h5py.Group, *, start: str | None, end: str | None,
                unknown: str = "") -> None:
    """NXentry ``start_time`` and ``end_time``, or a note that they are not known.

    Parameters
    ----------
    entry : h5py.Group
        The NXentry.
    start, end : str or None
        ISO 8601 with a UTC offset; None: not known (never invented).
    unknown : str
        Why, when ``start`` is None (attribute ``start_time_note``).

    Raises
    ------
    ValueError
        A time that is not ISO 8601 or has no UTC offset.
    """
    for name, value in ((START_TIME, start), (END_TIME, end)):
        if value is not None:
            entry.create_dataset(name, data=_text(check_time(value, name)))
    if start is None:
        entry.attrs["start_time_note"] = (unknown or "not known: the writer was not told when "
                                          "the samples were taken")


def read_times(entry: h5py.Group) -> dict[str, str]:
    """``start_time`` and ``end_time`` of an NXentry, those present, as text."""
    out = {}
    for name in (START_TIME, END_TIME):
        node = entry.get(name)
        if isinstance(node, h5py.Dataset):
            value = node[()]
            out[name] = value.decode("utf-8") if isinstance(value, bytes) else str(value)
    return out


# What each part of the bench is in NeXus terms. No base class describes an ADC or an
# amplifier: NXcollection (fields with units) holds them.
_PARTS: Final = (
    ("quad_diode", "NXdetector", "4-quadrant photodiode: beam angle to Vph, Vpv"),
    ("attocube", "NXdetector", "Attocube interferometer: displacement Va"),
    ("sercalo", "NXpositioner", "Sercalo fast-steering mirror, driven by Uch, Ucv"),
    ("newport", "NXpositioner", "Newport FSM-300: the perturbation mirror, driven by Unh, "
                                "Unv"),
    ("current_amplifier", "NXcollection", "current amplifiers of the Sercalo coils"),
    ("voltage_amplifier", "NXcollection", "voltage amplifiers of the Sercalo coils (Vch, Vcv)"),
)


def _units(unit: str) -> tuple[str, str]:
    """A bench file's unit as a NeXus ``units`` value and what it leaves out ("rms")."""
    value, _, qualifier = unit.partition(" ")
    return value, qualifier


def _field(group: h5py.Group, name: str, value: Any, *, unit: str, doc: str,
           source: str = "") -> None:
    if isinstance(value, str):
        group.create_dataset(name, data=_text(value))
        return
    axes = dataclasses.is_dataclass(value)  # PerAxis: h, v
    data = np.asarray([value.h, value.v] if axes else value)
    dset = group.create_dataset(name, data=data)
    units, qualifier = _units(unit)
    dset.attrs["units"] = units
    dset.attrs["long_name"] = f"{doc} ({qualifier})" if qualifier else doc
    if source:
        dset.attrs["source"] = source
    if axes:
        dset.attrs["axes_order"] = "h, v"


def write_instrument(entry: h5py.Group, bench: Bench) -> None:
    """``/entry/instrument`` (NXinstrument): the bench file's description of the bench.

    ``adc`` and ``dac`` (NXcollection): ``sampling_rate`` [Hz], ``range`` [V, full
    span], ``bits`` [bit], ``lsb`` [V]; the DAC's ``delay`` [s]. Then one group per
    part (4QD and Attocube as NXdetector, Sercalo and Newport as NXpositioner,
    amplifiers as NXcollection), each parameter of the bench file's ``[nominal]``
    model under its bench-file key with ``units``, ``long_name`` and ``source``
    (``fsmbench params`` prints the same).

    Parameters
    ----------
    entry : h5py.Group
        The NXentry.
    bench : Bench
        The bench the samples come from.
    """
    p = bench.nominal
    inst = entry.create_group("instrument")
    inst.attrs["NX_class"] = "NXinstrument"
    inst.create_dataset("name", data=_text("fast-steering-mirror bench"))
    inst.attrs["bench_file"] = bench.origin or "default_bench.toml"
    inst.attrs["label"] = bench.label
    inst.attrs["values"] = "the bench file's [nominal] model (fsmbench params: every source)"
    conv = p.converter
    lsb = conv.range_v / 2**conv.bits
    for name, what, span in (("adc", "analog-to-digital converters (every recorded V signal)",
                              "input"),
                             ("dac", "digital-to-analog converters (Uch, Ucv, Unh, Unv)",
                              "output")):
        g = inst.create_group(name)
        g.attrs["NX_class"] = "NXcollection"
        g.create_dataset("description", data=_text(what))
        _field(g, "sampling_rate", conv.fs_hz, unit="Hz", doc="sampling rate")
        _field(g, "range", conv.range_v, unit="V",
               doc=f"full {span} span ({-conv.range_v / 2:g} V to {conv.range_v / 2:g} V)")
        _field(g, "bits", np.int32(conv.bits), unit="bit", doc="resolution")
        _field(g, "lsb", lsb, unit="V", doc="one code step: range / 2**bits")
    delay = conv.dac_delay_samples / conv.fs_hz + conv.dac_extra_delay_s
    _field(inst["dac"], "delay", delay, unit="s", doc="DAC transport delay")
    for name, nx_class, what in _PARTS:
        params = getattr(p, name)
        g = inst.create_group(name)
        g.attrs["NX_class"] = nx_class
        g.create_dataset("description", data=_text(what))
        for f in dataclasses.fields(params):
            value = getattr(params, f.name)
            if isinstance(value, tuple) and not value:
                continue  # a real-bench feature that is off (mains lines): nothing to say
            _field(g, f.name, value, unit=f.metadata["unit"], doc=f.metadata["doc"],
                   source=f.metadata["source"])
