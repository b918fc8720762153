"""Long recordings read lazily: xarray over Dask arrays, chunked along time.

HDF5 files — NeXus archives and MATLAB v7.3 — can be read in pieces: each
signal becomes a Dask array whose chunks read their own slice of the file
when computed (the file is opened per chunk, so the graph pickles to
``dask.distributed`` workers). MATLAB v5 files cannot be read in pieces
(each variable is one zlib stream); :func:`open_recording` loads them whole
when they fit in memory and otherwise says to convert them with
``fsmbench convert IN OUT --format nexus``, which streams a v5 file's
compressed variables one by one (:func:`convert_recording`) with memory
bounded by one chunk.

Dask is the ``fsmbench[dask]`` extra: this module imports it lazily.
"""

from __future__ import annotations

import functools
import math
import os
import struct
import zlib
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, NamedTuple

import h5py
import numpy as np
import xarray as xr

from fsmbench.io.dataset import ordered_signals, signal_attrs
from fsmbench.io.errors import RecordingError
from fsmbench.io.matfile import available_memory_bytes, detect_format
from fsmbench.io.nexus import _plain, is_nexus
from fsmbench.io.nexus_meta import FILE_ATTRS, read_times
from fsmbench.io.nexus_stream import DEFAULT_CHUNK_SAMPLES, NexusAppender
from fsmbench.io.notes import READ_NOTES, TIME_JITTER, TRAILING_BYTES, clear_notes
from fsmbench.io.recording import read_recording
from fsmbench.io.signals import TIME
from fsmbench.io.timebase import (
    EXACT_TOLERANCE,
    irregular,
    not_increasing,
    sum_k_squared,
    time_base,
)
from fsmbench.io.trailing import data_end, warn_trailing

__all__ = [
    "CONVERTED_FROM",
    "available_memory_bytes",
    "convert_recording",
    "converted_from",
    "open_recording",
    "v5_stream_variable",
    "v5_vectors",
]

_READ_BLOCK = 1 << 20  # samples per piece when streaming a conversion (8 MiB of float64)


class _H5Vector:
    """A float64 vector inside an HDF5 file, read slice by slice (a Dask source)."""

    def __init__(self, path: Path, name: str, *, length: int, matlab: bool) -> None:
        self.path = path
        self.name = name
        self.shape = (length,)
        self.dtype = np.dtype(np.float64)
        self.ndim = 1
        self._matlab = matlab

    def __getitem__(self, key: Any) -> np.ndarray:
        if isinstance(key, tuple):  # Dask asks with one index per dimension
            (key,) = key
        with h5py.File(self.path, "r") as f:
            dset = f[self.name]
            if self._matlab and dset.ndim == 2:
                # MATLAB stores an N x 1 column as HDF5 shape (1, N).
                values = dset[0, key] if dset.shape[0] == 1 else dset[key, 0]
            else:
                values = dset[key]
        return np.asarray(values, dtype=np.float64)


def _vector_length(path: Path, dset: h5py.Dataset, name: str, matlab: bool) -> int:
    shape = dset.shape
    if matlab and len(shape) == 2 and 1 in shape:
        return int(max(shape))
    if len(shape) == 1:
        return int(shape[0])
    raise RecordingError(path, f"is not a vector (HDF5 shape {shape})", variable=name)


def _lazy_dataset(path: Path, names: list[str], lengths: dict[str, int],
                  attrs_of: dict[str, dict[str, Any]], attrs: dict[str, Any], *, matlab: bool,
                  chunk_samples: int, prefix: str = "") -> xr.Dataset:
    import dask.array as da

    n = lengths[TIME]
    uneven = sorted({k for k, v in lengths.items() if v != n})
    if uneven:
        raise RecordingError(path, f"signals of unequal lengths: {TIME} has {n} samples, "
                             + ", ".join(f"{k} {lengths[k]}" for k in uneven))

    def lazy(name: str) -> Any:
        src = _H5Vector(path, prefix + name, length=n, matlab=matlab)
        # A stable name: the same file and signal give the same graph keys.
        token = f"fsmbench-{path.name}-{name}-{os.stat(path).st_mtime_ns}"
        return da.from_array(src, chunks=(chunk_samples,), name=token, lock=False,
                             asarray=True, meta=np.zeros(0))

    # No index on t: xarray would load an index coordinate into memory (7 GB for a day).
    coords = xr.Coordinates({TIME: xr.Variable(TIME, lazy(TIME), attrs_of.get(TIME, {}))},
                            indexes={})
    return xr.Dataset({name: (TIME, lazy(name), attrs_of.get(name, {})) for name in names},
                      coords=coords, attrs=attrs)


def _open_nexus(path: Path, chunk_samples: int) -> xr.Dataset:
    with h5py.File(path, "r") as f:
        entry = f["entry"]
        data = entry["data"]
        signal = _plain(data.attrs.get("signal"))
        aux = _plain(data.attrs.get("auxiliary_signals", []))
        order = ([signal] if signal else []) + ([aux] if isinstance(aux, str) else list(aux))
        order += [k for k in data if k not in order and k != TIME]
        if TIME not in data:
            raise RecordingError(path, "is missing from /entry/data", variable=TIME)
        lengths = {k: _vector_length(path, data[k], k, False) for k in [TIME, *order]}
        attrs_of = {k: {a: _plain(v) for a, v in data[k].attrs.items()} for k in [TIME, *order]}
        attrs = {k: _plain(v) for k, v in entry.attrs.items() if k not in FILE_ATTRS}
        attrs.update(read_times(entry))
    return _lazy_dataset(path, order, lengths, attrs_of, attrs, matlab=False,
                         chunk_samples=chunk_samples, prefix="entry/data/")


def _open_mat73(path: Path, chunk_samples: int, fs_hz: float | None) -> xr.Dataset:
    with h5py.File(path, "r") as f:
        names = [k for k in f if not k.startswith("#") and isinstance(f[k], h5py.Dataset)
                 and _plain(f[k].attrs.get("MATLAB_class")) == "double"]
        if TIME not in names:
            raise RecordingError(path, "has no time vector", variable=TIME)
        lengths = {k: _vector_length(path, f[k], k, True) for k in names}
    signals = [k for k in names if k != TIME]

    ds = _lazy_dataset(path, ordered_signals(signals), lengths,
                       {k: signal_attrs(k) for k in signals}, {}, matlab=True,
                       chunk_samples=chunk_samples)
    t = ds[TIME].data
    if fs_hz is None:
        head = np.asarray(t[: min(1001, t.shape[0])].compute())
        fs_hz = float((head.size - 1) / (head[-1] - head[0])) if head.size > 1 else float("nan")
    ds.attrs.update({"fs_hz": float(fs_hz), "experiment": path.stem, "source": path.name})
    return ds


def open_recording(path: str | os.PathLike[str], *, chunk_samples: int = DEFAULT_CHUNK_SAMPLES,
                   memory_fraction: float = 0.5, check_signals: bool = True) -> xr.Dataset:
    """A recording as an xarray Dataset: lazy (Dask) for HDF5 files, in memory for v5.

    Parameters
    ----------
    path : str or os.PathLike
        NeXus archive, MATLAB v7.3 or v5 file in the ESRF study's layout.
    chunk_samples : int
        Dask chunk length along time (samples).
    memory_fraction : float
        A v5 file is refused when its samples would take more than this
        fraction of the memory available now.
    check_signals : bool
        Check every signal for NaN and Inf while opening (one pass over the
        file); the folder loader leaves it to its own checks, which read
        each signal once anyway (a day-long file is read at ~100 MB/s).

    Raises
    ------
    RecordingError
        Unreadable file, or a v5 file too large for memory (with the command
        that converts it).
    """
    p = Path(path)
    fmt = detect_format(p)
    if fmt == "hdf5" and is_nexus(p):
        return _validated(_open_nexus(p, chunk_samples), p, check_signals=check_signals)
    if fmt == "mat73":
        return _validated(_open_mat73(p, chunk_samples, None), p, check_signals=check_signals)
    if fmt == "mat5":
        need = sum(8 * n for _name, n in v5_vectors(p))
        have = available_memory_bytes()
        if need > memory_fraction * have:
            raise RecordingError(p, f"holds {need / 2**30:.1f} GiB of samples in MATLAB v5, "
                                 "which cannot be read in pieces, and this machine has "
                                 f"{have / 2**30:.1f} GiB available: convert it once with "
                                 f"fsmbench convert {p} {p.with_suffix('.h5')} --format nexus")

    return read_recording(p)


def _validated(ds: xr.Dataset, path: Path, *, check_signals: bool) -> xr.Dataset:
    """The checks :func:`~fsmbench.io.recording.read_recording` makes, out of core.

    Every signal finite (the first bad sample named), ``t`` increasing and on a uniform
    grid but for clock jitter (:mod:`fsmbench.io.timebase`), ``fs_hz`` fitted to the whole
    of ``t``. One pass over ``t`` (and the signals); a second over ``t`` only when it strays
    from the line through its ends by more than float64 rounding.
    """
    import dask
    import dask.array as da

    t = ds[TIME].data
    n = int(t.shape[0])
    names = [TIME, *map(str, ds.data_vars)] if check_signals else [TIME]
    bad = [~da.isfinite(ds[k].data) for k in names]
    t_first, t_last = (float(v) for v in dask.compute(t[0], t[-1]))
    steps = da.diff(t)
    period_ends = (t_last - t_first) / (n - 1) if n > 1 else 1.0
    k = da.arange(n, chunks=t.chunks, dtype=np.float64)
    u = t - t_first  # t far from 0 keeps its resolution in the differences
    off_ends = u - k * period_ends  # distance from the line through the first and last sample
    out = dask.compute(*[b.sum() for b in bad], steps.min(), ((k - 0.5 * (n - 1)) * u).sum(),
                       u.sum(), abs(off_ends).max())
    counts, (dt_min, sum_ku, sum_u, ends_max) = out[:len(names)], out[len(names):]
    base = None
    for name, count, mask in zip(names, counts, bad, strict=True):
        if int(count):
            first = int(da.argmax(mask).compute())
            raise RecordingError(path, f"holds {int(count)} NaN or Inf value"
                                 f"{'s' if int(count) > 1 else ''} (first at index {first})",
                                 variable=name)
    if n > 1:
        if not float(dt_min) > 0:
            i = int(da.argmax(~(steps > 0)).compute())
            raise not_increasing(str(path), i + 1, *(float(v) for v in t[i:i + 2].compute()))
        period = float(sum_ku) / sum_k_squared(n)
        # A line fitted to values within m of zero stays within 2.5 m over the fitted range, so
        # the residuals stay within 3.5 m: no second pass when that is float64 rounding.
        if 3.5 * float(ends_max) <= EXACT_TOLERANCE * period:
            deviation, at = float(ends_max), 0
        else:
            residual = abs(u - float(sum_u) / n - period * (k - 0.5 * (n - 1)))
            at = int(da.argmax(residual).compute())
            deviation = float(residual[at].compute())
        base = time_base(n=n, span_s=t_last - t_first, period_s=period, deviation_s=deviation,
                         at_index=at)
        if base is None:
            i = int(da.argmax(abs(steps - period)).compute())
            before, after = (float(v) for v in t[i:i + 2].compute())
            raise irregular(str(path), index=i + 1, t_before=before, t_after=after,
                            step_s=period, step_words="the period fitted to t",
                            deviation_s=deviation, period_s=period)
        ds.attrs["fs_hz"] = base.fs_hz
    ds.encoding["source"] = str(path)  # xarray's convention: the file a dataset came from
    # As read_recording: the attributes stored in the file win, but for the notes of a reading.
    ds.attrs.setdefault("experiment", path.stem)
    ds.attrs.setdefault("source", str(path))
    clear_notes(ds)
    end = warn_trailing(data_end(path, detect_format(path)), stacklevel=3)
    if end.trailing:
        ds.attrs[TRAILING_BYTES] = end.sentence()
    if base is not None and base.jittered:
        ds.attrs[TIME_JITTER] = base.jitter_sentence()
    return ds


# --------------------------------------------------------------------- MATLAB v5, streamed

_MI_INT8, _MI_UINT32, _MI_INT32, _MI_DOUBLE, _MI_MATRIX, _MI_COMPRESSED = 1, 6, 5, 9, 14, 15
_MX_DOUBLE = 6
_MI_BYTES = {1: 1, 2: 1, 3: 2, 4: 2, 5: 4, 6: 4, 7: 4, 9: 8, 12: 8, 13: 8}
_MI_DTYPE = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 9: "f8",
             12: "i8", 13: "u8"}


class _Stream:
    """Bytes of one v5 data element: raw file bytes, or a zlib stream inflated on demand."""

    def __init__(self, fh: Any, size: int, *, compressed: bool) -> None:
        self._fh = fh
        self._left = size
        self._z = zlib.decompressobj() if compressed else None
        self._buf = b""

    def read(self, n: int) -> bytes:
        while len(self._buf) < n:
            if self._left <= 0:
                if self._z is not None and self._z.unconsumed_tail:
                    self._buf += self._z.decompress(self._z.unconsumed_tail, 1 << 24)
                    continue
                raise EOFError
            raw = self._fh.read(min(self._left, 1 << 20))
            self._left -= len(raw)
            self._buf += self._z.decompress(raw) if self._z is not None else raw
        out, self._buf = self._buf[:n], self._buf[n:]
        return out


def _tag(s: _Stream, endian: str) -> tuple[int, int, bytes]:
    """(type, size, small data) of the next tag; small elements pack data into the tag."""
    head = s.read(8)
    word = struct.unpack(endian + "I", head[:4])[0]
    if word >> 16:
        return word & 0xFFFF, word >> 16, head[4:4 + (word >> 16)]
    return word, struct.unpack(endian + "I", head[4:])[0], b""


def _skip_padded(s: _Stream, size: int) -> bytes:
    data = s.read(size)
    if size % 8:
        s.read(8 - size % 8)
    return data


def _matrix_header(s: _Stream, endian: str) -> tuple[str, int, int]:
    """Name, class and element count of a miMATRIX (flags, dims, name read)."""
    _t, size, small = _tag(s, endian)
    flags = small or _skip_padded(s, size)
    mx_class = struct.unpack(endian + "I", flags[:4])[0] & 0xFF
    t, size, small = _tag(s, endian)
    dims_raw = small or _skip_padded(s, size)
    dims = np.frombuffer(dims_raw, dtype=endian + _MI_DTYPE[t])
    t, size, small = _tag(s, endian)
    name = (small or _skip_padded(s, size)).decode("latin-1")
    return name, mx_class, int(np.prod(dims)) if dims.size else 0


def _v5_elements(path: Path) -> Iterator[tuple[Any, str, int, int, _Stream]]:
    with open(path, "rb") as fh:
        header = fh.read(128)
        endian = "<" if header[126:128] == b"IM" else ">"
        while True:
            head = fh.read(8)
            if len(head) < 8:
                return
            outer, size = struct.unpack(endian + "II", head)
            if outer == 0 or size == 0:  # no variable: the data end (fsmbench.io.trailing)
                return
            start = fh.tell()
            s = _Stream(fh, size, compressed=outer == _MI_COMPRESSED)
            kind = outer
            if outer == _MI_COMPRESSED:
                kind, _inner_size = struct.unpack(endian + "II", s.read(8))
            if kind == _MI_MATRIX:
                yield fh, endian, start, size, s
            # Uncompressed elements are padded to 8 bytes; compressed ones are not.
            fh.seek(start + size + (-size % 8 if outer != _MI_COMPRESSED else 0))


def v5_vectors(path: Path) -> list[tuple[str, int]]:
    """(name, samples) of every real double vector of a v5 file (headers only)."""
    out = []
    for _fh, endian, _start, _size, s in _v5_elements(path):
        name, mx_class, count = _matrix_header(s, endian)
        if mx_class == _MX_DOUBLE:
            out.append((name, count))
    return out


def v5_stream_variable(path: Path, wanted: str,
                        block: int = _READ_BLOCK) -> Iterator[np.ndarray]:
    """The samples of one real double vector of a v5 file, ``block`` at a time."""
    for _fh, endian, _start, _size, s in _v5_elements(path):
        name, mx_class, _count = _matrix_header(s, endian)
        if name != wanted:
            continue
        if mx_class != _MX_DOUBLE:
            raise RecordingError(path, "is not a real double vector", variable=name)
        t, size, small = _tag(s, endian)
        if small:
            yield np.frombuffer(small, dtype=endian + _MI_DTYPE[t]).astype(np.float64)
            return
        width = _MI_BYTES[t]
        left = size // width
        while left > 0:
            n = min(block, left)
            yield np.frombuffer(s.read(n * width), dtype=endian + _MI_DTYPE[t]).astype(
                np.float64)
            left -= n
        return
    raise RecordingError(path, "is not in the file", variable=wanted)


#: Root attribute of an archive ``fsmbench convert`` wrote: the absolute path of its input.
CONVERTED_FROM = "converted_from"
#: How far ``--fs`` may be from the rate of ``t``: the readers' tolerance on the time step
#: (:data:`fsmbench.io.dataset._STEP_TOLERANCE`, 0.1 %), so what is written reads back.
_FS_TOLERANCE = 1e-3


def _streamed_rate(pieces: Callable[[], Iterator[np.ndarray]], n: int) -> float:
    """The rate [Hz] :func:`~fsmbench.io.timebase.time_base` gives ``t``, ``t`` read block by
    block twice (the least-squares period, then the distances from it); nan when ``t`` has
    fewer than 2 samples or no span."""
    if n < 2:
        return math.nan
    centre, t0, t_last, sum_ku, sum_u = 0.5 * (n - 1), math.nan, math.nan, 0.0, 0.0
    start = 0
    for block in pieces():
        if start == 0:
            t0 = float(block[0])
        k = np.arange(start, start + block.size, dtype=np.float64) - centre
        sum_ku += float(np.sum(k * (block - t0)))
        sum_u += float(np.sum(block - t0))
        start, t_last = start + block.size, float(block[-1])
    period = sum_ku / sum_k_squared(n)
    if not period > 0:
        return math.nan
    start, deviation = 0, 0.0
    for block in pieces():
        k = np.arange(start, start + block.size, dtype=np.float64) - centre
        deviation = max(deviation, float(np.max(np.abs(block - t0 - sum_u / n - period * k))))
        start += block.size
    base = time_base(n=n, span_s=t_last - t0, period_s=period, deviation_s=deviation,
                     at_index=0)
    # Irregular t is copied as it is: reading the archive says what is wrong with it.
    return base.fs_hz if base is not None else float(f"{1.0 / period:.12g}")


def converted_from(path: str | os.PathLike[str]) -> str | None:
    """The input ``fsmbench convert`` made the archive ``path`` from (absolute), or None
    when ``path`` is not such an archive (another file, another tool's, unreadable)."""
    try:
        with h5py.File(path, "r") as f:
            value = _plain(f.attrs.get(CONVERTED_FROM))
            creator = str(_plain(f.attrs.get("creator", "")))
    except (OSError, ValueError):
        return None
    return value if isinstance(value, str) and creator.startswith("fsmbench") else None


def convert_recording(source: str | os.PathLike[str], dest: str | os.PathLike[str], *,
                      fs_hz: float | None = None,
                      progress: Callable[[str], None] | None = None,
                      created: float | None = None) -> Path:
    """Copy a recording into a chunked NeXus archive, with memory bounded by one block.

    Parameters
    ----------
    source : str or os.PathLike
        MATLAB v5 (compressed or not), v7.3, or NeXus, in the ESRF study's layout
        (real double column vectors, ``t`` among them).
    dest : str or os.PathLike
        The NeXus archive to write (atomically). Its root records the source's
        absolute path (attribute :data:`CONVERTED_FROM`).
    fs_hz : float, optional
        Sampling rate [Hz]; default: the rate fitted to the whole of ``t`` by least
        squares (a v5 file's ``t`` is inflated once more for it; the first step alone
        is off by twice the stamps' jitter). When ``t`` has two samples or more, it must
        agree with that rate within 0.1 % (``t`` is copied as it is, so another rate
        would contradict it).
    progress : callable, optional
        Called with a line per signal.
    created : float, optional
        ``file_time`` of the archive [s since the epoch]; default now;
        :data:`~fsmbench.io.nexus_meta.UNSTAMPED_S`: none. The recording's own
        ``start_time`` and ``end_time`` are copied from a NeXus source, never
        taken from the clock.

    Raises
    ------
    RecordingError
        Unreadable input, no usable time base, or ``fs_hz`` contradicting ``t``.
    """

    src, out = Path(source), Path(dest)
    fmt = detect_format(src)
    say = progress or (lambda _msg: None)
    if fmt == "mat5":
        got = _v5_input(src)
    elif fmt in ("mat73", "hdf5"):
        got = _hdf5_input(open_recording(src))
    else:
        raise RecordingError(src, "cannot be converted: MATLAB v4 files are small, read them "
                             "directly")
    rate = _conversion_rate(src, fs_hz=fs_hz, from_t=got.from_t)
    signals, n, pieces, first_t = got.signals, got.n, got.pieces, got.first_t
    # One pass per signal keeps memory at one block: the archive is written column by
    # column (HDF5 datasets grow independently), time first.
    with NexusAppender(out, signals=signals, fs_hz=rate, attrs=got.attrs,
                       t0_s=float(first_t[0]) if first_t.size else 0.0, created=created,
                       root_attrs={CONVERTED_FROM: str(src.resolve())},
                       times_unknown=f"not known: {src.name} does not say when it was "
                                     "taken") as nx:
        nx.write_columns({TIME: pieces(TIME), **{name: pieces(name) for name in signals}},
                         n_samples=n)
        say(f"{src.name}: {n} samples of {', '.join(signals)} into {out}")
    return out


class _ConversionInput(NamedTuple):
    """What :func:`convert_recording` copies from its source.

    Attributes
    ----------
    signals : list of str
        The signals besides ``t``, in the order written.
    n : int
        Samples per signal.
    pieces : callable
        A signal's name to its samples, block after block (a new iterator per call).
    first_t : ndarray
        ``t``'s first two samples [s] (fewer for a shorter ``t``).
    from_t : float
        The rate fitted to the whole of ``t`` [Hz] (nan when there is none).
    attrs : dict
        The archive's recording attributes.
    """

    signals: list[str]
    n: int
    pieces: Callable[[str], Iterator[np.ndarray]]
    first_t: np.ndarray
    from_t: float
    attrs: dict[str, Any]


def _v5_input(src: Path) -> _ConversionInput:
    """A MATLAB v5 file's variables, streamed one by one (``t`` inflated once more for its rate).

    Raises
    ------
    RecordingError
        No ``t``, or signals of another length than ``t``.
    """
    vectors = dict(v5_vectors(src))
    if TIME not in vectors:
        raise RecordingError(src, "has no time vector", variable=TIME)

    def pieces(name: str) -> Iterator[np.ndarray]:
        return v5_stream_variable(src, name)
    n = vectors[TIME]
    signals = ordered_signals([k for k in vectors if k != TIME])
    uneven = [k for k in signals if vectors[k] != n]
    if uneven:
        raise RecordingError(src, f"signals of unequal lengths ({', '.join(uneven)} vs "
                             f"{TIME})")
    first_t = next(pieces(TIME))[:2]
    from_t = _streamed_rate(functools.partial(pieces, TIME), n)
    attrs = {"experiment": src.stem, "source": str(src)}
    return _ConversionInput(signals=signals, n=n, pieces=pieces, first_t=first_t,
                            from_t=from_t, attrs=attrs)


def _hdf5_input(ds: xr.Dataset) -> _ConversionInput:
    """A v7.3 or NeXus recording opened lazily (:func:`open_recording`), read in blocks."""
    signals = [str(k) for k in ds.data_vars]
    n = ds.sizes[TIME]

    def pieces(name: str) -> Iterator[np.ndarray]:
        arr = ds[name].data
        for k in range(0, n, _READ_BLOCK):
            yield np.asarray(arr[k:k + _READ_BLOCK].compute())
    first_t = np.asarray(ds[TIME].data[:2].compute())
    from_t = float(ds.attrs.get("fs_hz", math.nan))  # fitted to the whole of t (_validated)
    attrs = {k: v for k, v in ds.attrs.items() if k != "fs_hz" and k not in READ_NOTES}
    return _ConversionInput(signals=signals, n=n, pieces=pieces, first_t=first_t,
                            from_t=from_t, attrs=attrs)


def _conversion_rate(src: Path, *, fs_hz: float | None, from_t: float) -> float:
    """The archive's rate [Hz]: ``fs_hz`` if given (within 0.1 % of ``from_t``), else ``from_t``.

    Raises
    ------
    RecordingError
        ``fs_hz`` contradicts the rate fitted to ``t``, or there is no usable rate.
    """
    if fs_hz is not None and np.isfinite(from_t) and from_t > 0 \
            and abs(fs_hz - from_t) > _FS_TOLERANCE * from_t:
        raise RecordingError(src, f"is sampled at {from_t:.6g} Hz (the rate fitted to t) but "
                             f"--fs is {fs_hz:g} Hz; t is "
                             "copied as it is, so leave --fs out (the rate comes from t) or "
                             "fix t", variable=TIME)
    rate = fs_hz if fs_hz is not None else from_t
    if not np.isfinite(rate) or rate <= 0:
        raise RecordingError(src, "has no usable time base to take the sampling rate from; "
                             "give --fs", variable=TIME)
    return rate
