"""Long recordings written as they are produced: NeXus with chunked, growing datasets.

:class:`NexusAppender` writes the layout of :func:`fsmbench.io.nexus.write_nexus`
(so :func:`~fsmbench.io.nexus.read_nexus` and the lazy reader read it) block
by block: every signal is an HDF5 dataset of unlimited length, chunked
along time and gzip-compressed (:mod:`fsmbench.io.nexus_meta`), extended at
each :meth:`~NexusAppender.append`. Memory is one block, whatever the record's
length. The file appears under its name only
when :meth:`~NexusAppender.close` completes (a temporary file is renamed),
so a failed or interrupted run leaves no partial record.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any

import h5py
import numpy as np

from fsmbench.atomic import atomic_path
from fsmbench.bench.params import default_bench
from fsmbench.io.dataset import signal_attrs
from fsmbench.io.nexus_meta import (
    END_TIME,
    START_TIME,
    check_time,
    compression_options,
    write_instrument,
    write_root,
    write_times,
)
from fsmbench.io.signals import TIME

if TYPE_CHECKING:
    from fsmbench.bench.params import Bench

__all__ = ["DEFAULT_CHUNK_SAMPLES", "NexusAppender"]

#: Samples per HDF5 chunk: 512 KiB of float64, large enough for fast sequential
#: reads, small enough that a lazy reader's tasks stay light.
DEFAULT_CHUNK_SAMPLES = 1 << 16


class NexusAppender:
    """Write a recording to a NeXus file block by block (see the module notes).

    Parameters
    ----------
    path : str or os.PathLike
        Destination; its folder must exist.
    signals : sequence of str
        Signal names, in the order they are stored (ESRF study names: units and
        long names come from :mod:`fsmbench.io.signals`).
    fs_hz : float
        Sampling rate [Hz]; the time axis is ``k / fs_hz`` [s] from ``t0_s``.
    attrs : mapping
        Recording attributes (``experiment``, ``source``, ...); ``fs_hz`` is added.
        ``start_time`` and ``end_time`` (ISO 8601 with a UTC offset), when given,
        are the NXentry's fields (a copied recording keeps them).
    t0_s : float
        Time of the first sample [s].
    chunk_samples : int
        HDF5 chunk length along time.
    created : float, optional
        ``file_time`` [s since the epoch]; default now;
        :data:`~fsmbench.io.nexus_meta.UNSTAMPED_S`: none (reproducible bytes).
    root_attrs : mapping, optional
        More attributes of the file's root (``/``), such as the provenance
        ``fsmbench convert`` records.
    bench : Bench, optional
        The bench the samples come from (``/entry/instrument``); default the
        packaged bench, marked ``@assumed``.
    times_unknown : str
        Why the samples have no wall-clock time (``@start_time_note``), when
        neither ``attrs`` nor :meth:`set_times` gives one.
    compress : bool, default True
        gzip level 1 with shuffling.

    Notes
    -----
    The times are never taken from the clock here: a conversion or a simulation
    runs at another time than its samples. A live recording says when its
    samples were taken through :meth:`set_times`.
    """

    def __init__(self, path: str | os.PathLike[str], *, signals: Sequence[str], fs_hz: float,
                 attrs: Mapping[str, Any], t0_s: float = 0.0,
                 chunk_samples: int = DEFAULT_CHUNK_SAMPLES,
                 created: float | None = None,
                 root_attrs: Mapping[str, Any] | None = None, bench: Bench | None = None,
                 times_unknown: str = "", compress: bool = True) -> None:
        if not signals:
            raise ValueError(f"{path}: a recording needs at least one signal")
        self.path = Path(path)
        self.signals = tuple(signals)
        self.fs_hz = float(fs_hz)
        self.t0_s = float(t0_s)
        self.n_samples = 0
        attrs = dict(attrs)
        self._times: dict[str, str | None] = {}
        self.set_times(start=attrs.pop(START_TIME, None), end=attrs.pop(END_TIME, None))
        self._attrs = {**attrs, "fs_hz": self.fs_hz}
        self._bench = bench
        self._times_unknown = times_unknown
        self._compress = compress
        self._chunk = int(chunk_samples)
        self._created = created
        self._root_attrs = dict(root_attrs or {})
        self._stack = contextlib.ExitStack()
        self._file: h5py.File | None = None
        self._data: h5py.Group | None = None
        self._entry: h5py.Group | None = None

    def __enter__(self) -> NexusAppender:
        tmp = self._stack.enter_context(atomic_path(self.path))
        f = self._stack.enter_context(h5py.File(tmp, "w"))
        self._file = f
        write_root(f, created=self._created, extra=self._root_attrs)
        entry = f.create_group("entry")
        entry.attrs["NX_class"] = "NXentry"
        entry.attrs["default"] = "data"
        for key, value in self._attrs.items():
            entry.attrs[key] = value
        write_instrument(entry, default_bench() if self._bench is None else self._bench)
        if self._bench is None:
            entry["instrument"].attrs["assumed"] = ("the packaged bench: the writer was not "
                                                    "told which bench took the samples")
        self._entry = entry
        data = entry.create_group("data")
        data.attrs["NX_class"] = "NXdata"
        data.attrs["axes"] = TIME
        data.attrs[f"{TIME}_indices"] = np.int32(0)
        data.attrs["signal"] = self.signals[0]
        if len(self.signals) > 1:
            data.attrs["auxiliary_signals"] = list(self.signals[1:])
        opts = compression_options(None, chunk_samples=self._chunk, compress=self._compress)
        for name in (TIME, *self.signals):
            dset = data.create_dataset(name, shape=(0,), maxshape=(None,), dtype=np.float64,
                                       track_times=False, **opts)
            attrs = {"units": "s", "long_name": "Time"} if name == TIME else signal_attrs(name)
            for key, value in attrs.items():
                dset.attrs[key] = value
        self._data = data
        return self

    def set_times(self, *, start: str | None, end: str | None) -> None:
        """When the first and the last sample were taken (ISO 8601 with a UTC offset).

        Written when the file is closed; replaces times given in ``attrs``.

        Raises
        ------
        ValueError
            Not ISO 8601 or without an offset.
        """
        self._times = {name: None if value is None else check_time(value, name)
                       for name, value in ((START_TIME, start), (END_TIME, end))}

    def note(self, **attrs: Any) -> None:
        """More attributes of the entry, written now (e.g. how a record ended)."""
        if self._entry is None:
            raise RuntimeError("NexusAppender.note outside its with-block")
        for key, value in attrs.items():
            self._entry.attrs[key] = value

    def append(self, block: Mapping[str, np.ndarray]) -> None:
        """Append the next samples: every signal, arrays of equal length (n,)."""
        if self._data is None:
            raise RuntimeError("NexusAppender.append outside its with-block")
        missing = [s for s in self.signals if s not in block]
        if missing:
            raise ValueError(f"{self.path}: block lacks {', '.join(missing)}")
        lengths = {np.shape(block[s])[0] for s in self.signals}
        if len(lengths) != 1:
            raise ValueError(f"{self.path}: signals of unequal lengths {sorted(lengths)} in a "
                             "block")
        n = lengths.pop()
        if n == 0:
            return
        k0 = self.n_samples
        t = self.t0_s + np.arange(k0, k0 + n, dtype=np.float64) / self.fs_hz
        for name, values in ((TIME, t), *((s, block[s]) for s in self.signals)):
            dset = self._data[name]
            dset.resize((k0 + n,))
            dset[k0:k0 + n] = np.asarray(values, dtype=np.float64)
        self.n_samples = k0 + n

    def write_columns(self, columns: Mapping[str, Iterable[np.ndarray]], *,
                      n_samples: int) -> None:
        """Write whole signals one after the other, each from an iterator of pieces.

        For copying a record whose columns can only be read one at a time
        (a MATLAB v5 file); ``columns`` holds ``t`` [s] and every signal, each
        ``n_samples`` long in all. Memory is one piece.
        """
        if self._data is None:
            raise RuntimeError("NexusAppender.write_columns outside its with-block")
        if self.n_samples:
            raise RuntimeError(f"{self.path}: write_columns on a file already appended to")
        for name in (TIME, *self.signals):
            if name not in columns:
                raise ValueError(f"{self.path}: no column {name}")
            dset = self._data[name]
            dset.resize((n_samples,))
            k = 0
            for piece in columns[name]:
                piece = np.asarray(piece, dtype=np.float64).ravel()
                if k + piece.size > n_samples:
                    raise ValueError(f"{self.path}: {name} has more than {n_samples} samples")
                dset[k:k + piece.size] = piece
                k += piece.size
            if k != n_samples:
                raise ValueError(f"{self.path}: {name} has {k} samples, not {n_samples}")
        self.n_samples = n_samples

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        if exc is None and self.n_samples == 0:
            try:
                raise ValueError(f"{self.path}: no samples were written")
            except ValueError as err:
                self._stack.__exit__(type(err), err, err.__traceback__)
                raise
        if exc is None and self._entry is not None:
            write_times(self._entry, start=self._times[START_TIME], end=self._times[END_TIME],
                        unknown=self._times_unknown)
        self._data = None
        self._entry = None
        self._file = None
        self._stack.__exit__(exc_type, exc, tb)

