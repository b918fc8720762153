"""Long recordings written as they are produced: NeXus with chunked, growing datasets.

:class:`NexusAppender` writes the layout of :func:`fsmbench.io.nexus.write_nexus`
(so :func:`~fsmbench.io.nexus.read_nexus` and the lazy reader read it) block
by block: every signal is an HDF5 dataset of unlimited length, chunked
along time, extended at each :meth:`~NexusAppender.append`. Memory is one
block, whatever the record's length. The file appears under its name only
when :meth:`~NexusAppender.close` completes (a temporary file is renamed),
so a failed or interrupted run leaves no partial record.
"""

from __future__ import annotations

import contextlib
import datetime
import os
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from types import TracebackType
from typing import Any

import h5py
import numpy as np

from fsmbench.io.atomic import atomic_path
from fsmbench.io.recording import _signal_attrs
from fsmbench.io.signals import TIME

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
    t0_s : float
        Time of the first sample [s].
    chunk_samples : int
        HDF5 chunk length along time.
    created : float, optional
        ``file_time`` [s since the epoch]; default now.
    root_attrs : mapping, optional
        More attributes of the file's root (``/``), such as the provenance
        ``fsmbench convert`` records.
    """

    def __init__(self, path: str | os.PathLike[str], *, signals: Sequence[str], fs_hz: float,
                 attrs: Mapping[str, Any], t0_s: float = 0.0,
                 chunk_samples: int = DEFAULT_CHUNK_SAMPLES,
                 created: float | None = None,
                 root_attrs: Mapping[str, Any] | None = None) -> None:
        if not signals:
            raise ValueError(f"{path}: a recording needs at least one signal")
        self.path = Path(path)
        self.signals = tuple(signals)
        self.fs_hz = float(fs_hz)
        self.t0_s = float(t0_s)
        self.n_samples = 0
        self._attrs = {**dict(attrs), "fs_hz": self.fs_hz}
        self._chunk = int(chunk_samples)
        self._created = created
        self._root_attrs = dict(root_attrs or {})
        self._stack = contextlib.ExitStack()
        self._file: h5py.File | None = None
        self._data: h5py.Group | None = None
        self._entry: h5py.Group | None = None

    def __enter__(self) -> NexusAppender:
        from fsmbench import __version__

        tmp = self._stack.enter_context(atomic_path(self.path))
        f = self._stack.enter_context(h5py.File(tmp, "w"))
        self._file = f
        f.attrs["default"] = "entry"
        f.attrs["creator"] = f"fsmbench {__version__}"
        f.attrs["file_time"] = (
            datetime.datetime.now().astimezone() if self._created is None
            else datetime.datetime.fromtimestamp(self._created, tz=datetime.UTC)).isoformat()
        f.attrs["HDF5_Version"] = h5py.version.hdf5_version
        for key, value in self._root_attrs.items():
            f.attrs[key] = value
        entry = f.create_group("entry")
        entry.attrs["NX_class"] = "NXentry"
        entry.attrs["default"] = "data"
        for key, value in self._attrs.items():
            entry.attrs[key] = value
        # NXentry's own fields: the wall clock of the first and (at the end) the last sample.
        entry.create_dataset("start_time", data=self._time_iso())
        self._entry = entry
        data = entry.create_group("data")
        data.attrs["NX_class"] = "NXdata"
        data.attrs["axes"] = TIME
        data.attrs[f"{TIME}_indices"] = np.int32(0)
        data.attrs["signal"] = self.signals[0]
        if len(self.signals) > 1:
            data.attrs["auxiliary_signals"] = list(self.signals[1:])
        for name in (TIME, *self.signals):
            dset = data.create_dataset(name, shape=(0,), maxshape=(None,), dtype=np.float64,
                                       chunks=(self._chunk,), track_times=False)
            attrs = {"units": "s", "long_name": "Time"} if name == TIME else _signal_attrs(name)
            for key, value in attrs.items():
                dset.attrs[key] = value
        self._data = data
        return self

    def _time_iso(self) -> str:
        """The wall clock now, or ``created`` when the caller fixed the file's time (a
        reproducible run's files are byte-identical: its start and end time are that one)."""
        if self._created is not None:
            return datetime.datetime.fromtimestamp(self._created, tz=datetime.UTC).isoformat()
        return _now_iso()

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
            self._entry.create_dataset("end_time", data=self._time_iso())
        self._data = None
        self._entry = None
        self._file = None
        self._stack.__exit__(exc_type, exc, tb)


def _now_iso() -> str:
    """The wall clock now, ISO 8601 with its UTC offset (NeXus ``NX_DATE_TIME``)."""
    return datetime.datetime.now().astimezone().isoformat()
