"""Writing MATLAB MAT-files: v5/v7 (the ``-v7`` layout MATLAB users load by
default) and v7.3 (HDF5 with MATLAB's userblock and attributes).

The reading side and the value conventions are in :mod:`fsmbench.io.matfile`;
:func:`save_mat` accepts what :func:`~fsmbench.io.matfile.load_mat` returns.
Every file is written atomically (:mod:`fsmbench.atomic`).
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import io
import os
import re
import time
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any, Final, Literal

import h5py
import numpy as np
import scipy.io
import scipy.sparse
from isal import isal_zlib

from fsmbench.atomic import atomic_path
from fsmbench.version import __version__

__all__ = ["FIXED_CREATED_S", "MatVersion", "mat5_header", "mat73_header", "save_mat",
           "wall_clock_headers", "wall_clock_wanted"]

#: Creation time headers carry unless asked otherwise [s since the epoch]: the
#: epoch itself, so that the same variables give a byte-identical file.
FIXED_CREATED_S: Final = 0.0
# Whether headers without an explicit ``created`` carry the wall clock; one
# process-wide switch (``--timestamp``), read by every writer thread.
_wall_clock = [False]


@contextlib.contextmanager
def wall_clock_headers(enabled: bool = True) -> Iterator[None]:
    """Within the block, headers without an explicit ``created`` carry the wall clock.

    Parameters
    ----------
    enabled : bool
        True: the current local time (as MATLAB writes it); False: the fixed
        :data:`FIXED_CREATED_S` (the default outside any block).
    """
    saved = _wall_clock[0]
    _wall_clock[0] = enabled
    try:
        yield
    finally:
        _wall_clock[0] = saved


def wall_clock_wanted() -> bool:
    """True within :func:`wall_clock_headers` (``--timestamp``): files carry the wall clock."""
    return _wall_clock[0]


#: MAT-file versions :func:`save_mat` writes ("5" is MATLAB's ``-v7`` layout).
MatVersion = Literal["5", "7.3"]

_USERBLOCK: Final = 512
# Level of ISA-L's deflate for v5 variables. On the twin's 13 records (314 MB of
# float64) level 2 gave 80 MB in 0.44 CPU-s where zlib's level 1 gave 76 MB in 1.5 s;
# its level 1 gave 87 MB in the same time, its level 3 81 MB in 0.63 s.
_DEFLATE_LEVEL: Final = 2
_MI_COMPRESSED: Final = 15  # MAT v5 data type of a compressed element
_NAME_RE: Final = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,62}")  # MATLAB's namelengthmax = 63

# MATLAB_class of each numpy dtype kind/size MATLAB can hold (complex: same class).
_CLASS_OF: Final[dict[str, str]] = {
    "f8": "double", "f4": "single", "c16": "double", "c8": "single",
    "i1": "int8", "u1": "uint8", "i2": "int16", "u2": "uint16",
    "i4": "int32", "u4": "uint32", "i8": "int64", "u8": "uint64", "b1": "logical",
}
_DAYS: Final = ("Mon", "Tue", "Wed", "Thu", "Fri", "Sat", "Sun")
_MONTHS: Final = ("Jan", "Feb", "Mar", "Apr", "May", "Jun",
                  "Jul", "Aug", "Sep", "Oct", "Nov", "Dec")


def mat73_header(*, platform: str | None = None, created: float | None = None) -> bytes:
    """The 128-byte MAT-file header MATLAB writes in a v7.3 file's userblock.

    Parameters
    ----------
    platform : str, optional
        Text after ``Platform:``; defaults to ``"fsmbench <version>"``.
    created : float, optional
        Creation time, in s since the epoch, written as UTC. Default: the
        fixed :data:`FIXED_CREATED_S` (byte-identical files), or now in local
        time as MATLAB writes it inside :func:`wall_clock_headers`.

    Returns
    -------
    bytes
        128 bytes: the text padded with spaces to 116 bytes, 8 bytes of
        subsystem offset (zeros), version 0x0200 and the endian indicator
        ``IM``.

    Notes
    -----
    Layout followed: the MAT-File Format document (128-byte header: text
    0..115, subsys offset 116..123, version 124..125, endian 126..127) as
    hdf5storage documents it for v7.3 ("Storage Format: MATLAB File Header",
    https://pythonhosted.org/hdf5storage/storage_format.html — "a 116 byte
    string (spaces pad the end) followed by ... 00000000 00000000 0002494D"),
    and matio's/hdf5-pure's ``mat/userblock.rs`` (bytes 124..127 =
    ``00 02 'I' 'M'``, zeros to 512, HDF5 superblock at 512).
    """
    text = (f"MATLAB 7.3 MAT-file, Platform: {_platform(platform)}, "
            f"Created on: {_stamp(created)} HDF5 schema 1.00 .")
    raw = text.encode("ascii", "replace")[:116]
    return raw.ljust(116, b" ") + b"\x00" * 8 + b"\x00\x02" + b"IM"


def mat5_header(*, platform: str | None = None, created: float | None = None) -> bytes:
    """The 128-byte header of a MATLAB v5/v7 MAT-file (little-endian).

    Same text and ``created`` convention as :func:`mat73_header`; bytes
    116..123 are the subsystem offset (zeros), 124..125 the version 0x0100
    and 126..127 the endian indicator ``IM``, as the MAT-File Format
    document specifies and ``scipy.io.savemat`` writes.
    """
    text = f"MATLAB 5.0 MAT-file, Platform: {_platform(platform)}, Created on: {_stamp(created)}"
    raw = text.encode("ascii", "replace")[:116]
    return raw.ljust(116, b" ") + b"\x00" * 8 + b"\x00\x01" + b"IM"


def _platform(platform: str | None) -> str:
    return platform if platform is not None else f"fsmbench {__version__}"


def _stamp(created: float | None) -> str:
    if created is None:
        now = time.localtime() if _wall_clock[0] else time.gmtime(FIXED_CREATED_S)
    else:
        now = time.gmtime(created)
    # English names by hand: strftime's %a/%b follow the locale.
    return (f"{_DAYS[now.tm_wday]} {_MONTHS[now.tm_mon - 1]} {now.tm_mday:02d} "
            f"{now.tm_hour:02d}:{now.tm_min:02d}:{now.tm_sec:02d} {now.tm_year}")




def save_mat(
    path: str | os.PathLike[str],
    variables: Mapping[str, Any],
    *,
    version: MatVersion = "5",
    compress: bool | None = None,
    created: float | None = None,
) -> Path:
    """Write variables to a MAT-file, atomically.

    Parameters
    ----------
    path : str or os.PathLike
        Destination; its folder must exist. Written through a temporary file
        and renamed, so it is either complete or untouched.
    variables : mapping of str to value
        Names must be MATLAB identifiers (letter first, at most 63
        characters). Values: numeric/logical/complex arrays or scalars
        (1-D arrays become N×1 columns), ``str``, lists/tuples (1×N cell
        arrays, e.g. of signal names), mappings (structs, nested allowed);
        v5 also takes ``scipy.sparse`` matrices.
    version : {"5", "7.3"}, default "5"
        ``"5"`` is MATLAB's default ``-v7`` layout (scipy.io.savemat encodes
        each variable); ``"7.3"`` is the HDF5 layout MATLAB writes with
        ``-v7.3``.
    compress : bool, optional
        Compress the data. Default: yes for v5, no for v7.3 (v7.3 is chosen
        for large files, where HDF5's single-threaded deflate dominates).
    created : float, optional
        Creation time for the header [s since the epoch]. Default: the fixed
        :data:`FIXED_CREATED_S`, so that the file is a pure function of the
        variables; the wall clock inside :func:`wall_clock_headers`.

    Returns
    -------
    Path
        The destination.
    """
    dest = Path(path)
    for name in variables:
        _check_name(name, dest)
    if version == "5":
        _save_v5(dest, variables, compress=True if compress is None else compress,
                 header=mat5_header(created=created))
    elif version == "7.3":
        _save_v73(dest, variables, compress=False if compress is None else compress,
                  header=mat73_header(created=created))
    else:
        raise ValueError(f"{dest}: unknown MAT-file version {version!r}; use '5' or '7.3'")
    return dest


def _check_name(name: str, dest: Path) -> None:
    if not isinstance(name, str) or not _NAME_RE.fullmatch(name):
        raise ValueError(
            f"{dest}: {name!r} is not a valid MATLAB variable or field name "
            "(a letter, then letters, digits or '_', at most 63 characters)"
        )


def _to_scipy(value: Any, where: str, dest: Path) -> Any:
    """Convert a value to what scipy.io.savemat writes as the intended class."""
    if isinstance(value, Mapping):
        for k in value:
            _check_name(k, dest)
        return {k: _to_scipy(v, f"{where}.{k}", dest) for k, v in value.items()}
    if isinstance(value, str) or scipy.sparse.issparse(value):
        return value
    if isinstance(value, (list, tuple)):
        cell = np.empty((1, len(value)), dtype=object)  # 1×N cell, as MATLAB's {a, b}
        for i, v in enumerate(value):
            cell[0, i] = _to_scipy(v, f"{where}{{{i + 1}}}", dest)
        return cell
    arr = _as_array(value, where, dest)
    if arr.dtype.kind in "US":
        return str(arr.item()) if arr.ndim == 0 else _to_scipy(arr.tolist(), where, dest)
    if arr.dtype == object:
        out = np.empty(arr.shape, dtype=object)
        for idx, v in np.ndenumerate(arr):
            out[idx] = _to_scipy(v, where, dest)
        return out
    if f"{arr.dtype.kind}{arr.dtype.itemsize}" not in _CLASS_OF:
        raise TypeError(f"{dest}: variable '{where}': cannot store {type(value).__name__} "
                        f"(dtype {arr.dtype}) in a MAT-file")
    return arr


def _as_array(value: Any, where: str, dest: Path) -> np.ndarray:
    """``np.asarray(value)``, refusing objects numpy can only wrap (None, sets, ...)."""
    arr = np.asarray(value)
    if arr.dtype == object and arr.ndim == 0:
        raise TypeError(f"{dest}: variable '{where}': cannot store "
                        f"{type(value).__name__} in a MAT-file")
    return arr


def _deflate(data: bytes) -> bytes:
    """``data`` as a zlib stream (RFC 1950), the compressed form of a v5 variable.

    ISA-L's deflate (``isal``), not zlib's: the same format, which MATLAB, scipy and
    zlib inflate, at 3 to 10 times the speed. It releases the GIL, so the variables of
    a file are compressed side by side.
    """
    return isal_zlib.compress(data, _DEFLATE_LEVEL)


def _worth_compressing(data: bytes) -> bool:
    """Whether deflating shrinks ``data`` by 10 % or more, judged on a 256 KiB sample.

    Noise-like float64 signals barely compress (~0.96 of their size) yet cost
    as much time as any other; they are stored plain (a v5 file may mix plain
    and compressed variables), 16-bit ADC data (~0.42) and ``t`` (~0.3) are not.
    """
    size = 1 << 18
    if len(data) <= 2 * size:
        return True
    start = (len(data) // 2) & ~7
    sample = data[start:start + size]
    return len(_deflate(sample)) < 0.9 * len(sample)


def _v5_element(name: str, value: Any, compress: bool) -> bytes:
    """The data element of one variable, as savemat encodes it."""
    buf = io.BytesIO()
    scipy.io.savemat(buf, {name: value}, format="5", oned_as="column",
                     do_compression=False, long_field_names=True)
    raw = buf.getvalue()
    element = raw[128:]
    if compress and _worth_compressing(element):
        # Same framing as savemat(do_compression=True): an miCOMPRESSED tag
        # around the zlib stream of the miMATRIX element, no padding.
        packed = _deflate(element)
        element = np.array([_MI_COMPRESSED, len(packed)], dtype=np.uint32).tobytes() + packed
    return element


def _save_v5(dest: Path, variables: Mapping[str, Any], *, compress: bool,
             header: bytes) -> None:
    items = [(k, _to_scipy(v, k, dest)) for k, v in variables.items()]
    workers = max(1, min(len(items), os.cpu_count() or 1))
    # Variables are encoded and compressed in threads (the deflate releases the GIL):
    # savemat's own compression is single-threaded zlib, many times slower.
    pool = concurrent.futures.ThreadPoolExecutor(max_workers=workers)
    try:
        with atomic_path(dest) as tmp, open(tmp, "wb") as fh:
            fh.write(header)
            for element in pool.map(lambda kv: _v5_element(kv[0], kv[1], compress), items):
                fh.write(element)
    finally:
        # on failure (Ctrl-C included) drop the variables not started yet
        pool.shutdown(wait=True, cancel_futures=True)


class _H5Writer:
    """Writes Python values into an HDF5 file the way MATLAB lays out v7.3."""

    def __init__(self, f: h5py.File, dest: Path, *, compress: bool) -> None:
        self.f = f
        self.dest = dest
        self.compress = compress
        self._refs: h5py.Group | None = None
        self._count = 0

    def _ref_name(self) -> str:
        # MATLAB names the members of "#refs#" a, b, ..., z, ba, bb, ...
        n, name = self._count, ""
        self._count += 1
        while True:
            n, r = divmod(n, 26)
            name = chr(ord("a") + r) + name
            if n == 0:
                return name

    def write(self, group: h5py.Group, name: str, value: Any, where: str) -> Any:
        if isinstance(value, Mapping):
            return self._struct(group, name, value, where)
        if isinstance(value, str):
            return self._char(group, name, value)
        if isinstance(value, (list, tuple)):
            cell = np.empty((1, len(value)), dtype=object)
            for i, v in enumerate(value):
                cell[0, i] = v
            return self._cell(group, name, cell, where)
        if scipy.sparse.issparse(value):
            raise TypeError(f"{self.dest}: variable '{where}': sparse matrices need version '5'")
        arr = _as_array(value, where, self.dest)
        if arr.dtype.kind in "US":
            if arr.ndim == 0:
                return self._char(group, name, str(arr.item()))
            return self.write(group, name, arr.tolist(), where)
        if arr.ndim == 1:
            arr = arr.reshape(-1, 1)  # oned_as="column", as for v5
        if arr.dtype == object:
            return self._cell(group, name, np.atleast_2d(arr), where)
        key = f"{arr.dtype.kind}{arr.dtype.itemsize}"
        if key not in _CLASS_OF:
            raise TypeError(f"{self.dest}: variable '{where}': cannot store "
                            f"{type(value).__name__} (dtype {arr.dtype}) in a MAT-file")
        return self._numeric(group, name, np.atleast_2d(arr), _CLASS_OF[key])

    def _empty(self, group: h5py.Group, name: str, shape: tuple[int, ...], cls: str) -> Any:
        ds = group.create_dataset(name, data=np.array(shape, dtype=np.uint64),
                                   track_times=False)
        ds.attrs["MATLAB_class"] = np.bytes_(cls)
        ds.attrs["MATLAB_empty"] = np.uint8(1)
        return ds

    def _numeric(self, group: h5py.Group, name: str, arr: np.ndarray, cls: str) -> Any:
        if arr.size == 0:
            return self._empty(group, name, arr.shape, cls)
        data = arr.T  # MATLAB is column-major: HDF5 dims are MATLAB's reversed
        if arr.dtype.kind == "c":
            part = arr.real.dtype
            cdata = np.empty(data.shape, dtype=np.dtype([("real", part), ("imag", part)]))
            cdata["real"], cdata["imag"] = data.real, data.imag
            data = cdata
        elif arr.dtype.kind == "b":
            data = data.astype(np.uint8)
        opts: dict[str, Any] = {}
        if self.compress and data.size > 1:
            opts = {"compression": "gzip", "compression_opts": 1, "chunks": True}
        ds = group.create_dataset(name, data=np.ascontiguousarray(data), track_times=False,
                                   **opts)
        ds.attrs["MATLAB_class"] = np.bytes_(cls)
        if cls == "logical":
            ds.attrs["MATLAB_int_decode"] = np.int32(1)
        return ds

    def _char(self, group: h5py.Group, name: str, text: str) -> Any:
        # MATLAB char data are UTF-16 code units; a 1×L row is stored (L, 1).
        codes = np.frombuffer(text.encode("utf-16-le"), dtype="<u2")
        if codes.size == 0:
            return self._empty(group, name, (0, 0), "char")
        ds = group.create_dataset(name, data=codes.reshape(-1, 1), track_times=False)
        ds.attrs["MATLAB_class"] = np.bytes_("char")
        ds.attrs["MATLAB_int_decode"] = np.int32(2)
        return ds

    def _cell(self, group: h5py.Group, name: str, cell: np.ndarray, where: str) -> Any:
        if cell.size == 0:
            return self._empty(group, name, cell.shape, "cell")
        if self._refs is None:
            self._refs = self.f.require_group("#refs#")
        data = cell.T
        refs = np.empty(data.shape, dtype=h5py.ref_dtype)
        for idx, elem in np.ndenumerate(data):
            obj = self.write(self._refs, self._ref_name(), elem, f"{where}{{{idx}}}")
            refs[idx] = obj.ref
        ds = group.create_dataset(name, data=refs, track_times=False)
        ds.attrs["MATLAB_class"] = np.bytes_("cell")
        return ds

    def _struct(self, group: h5py.Group, name: str, value: Mapping[str, Any], where: str) -> Any:
        g = group.create_group(name)
        g.attrs["MATLAB_class"] = np.bytes_("struct")
        if value:
            # MATLAB_fields: one variable-length array of 1-byte chars per field.
            names = np.empty(len(value), dtype=object)
            for i, k in enumerate(value):
                _check_name(k, self.dest)
                names[i] = np.frombuffer(k.encode("ascii"), dtype="S1")
            g.attrs.create("MATLAB_fields", names, dtype=h5py.vlen_dtype(np.dtype("S1")))
        for k, v in value.items():
            self.write(g, k, v, f"{where}.{k}")
        return g


def _save_v73(dest: Path, variables: Mapping[str, Any], *, compress: bool,
              header: bytes) -> None:
    with atomic_path(dest) as tmp:
        # userblock_size=512: MATLAB's header lives there, the HDF5 superblock at 512.
        with h5py.File(tmp, "w", userblock_size=_USERBLOCK, libver="earliest") as f:
            writer = _H5Writer(f, dest, compress=compress)
            for name, value in variables.items():
                writer.write(f, name, value, name)
        with open(tmp, "r+b") as fh:
            fh.write(header.ljust(_USERBLOCK, b"\x00"))
