"""MATLAB MAT-files in and out: v4, v5/v7 (scipy.io) and v7.3 (HDF5, h5py).

The format of a file is told from its content, never from its suffix:

* v5/v7: a 128-byte header whose bytes 124..127 hold the version 0x0100 and
  the endian indicator ``IM`` (or ``MI``);
* v7.3: an HDF5 file with a 512-byte userblock that starts with the text
  ``MATLAB 7.3 MAT-file`` and carries version 0x0200 and ``IM`` at 124..127;
* v4: no header; the first int32 is a MOPT type code;
* plain HDF5 (no MATLAB header) is reported as ``"hdf5"``.

MATLAB arrays are column-major and at least 2-D. In a v7.3 file an array of
MATLAB size ``m×n`` is an HDF5 dataset of shape ``(n, m)`` (axes reversed),
tagged with a ``MATLAB_class`` attribute; a column vector of N samples is
therefore stored as ``(1, N)``. :func:`load_mat` undoes that and returns
arrays in MATLAB's shape, the same for every version.

Values returned by :func:`load_mat` (and accepted by :func:`fsmbench.io.matwrite.save_mat`):

==================  ==========================================================
MATLAB              Python
==================  ==========================================================
numeric, logical    ``np.ndarray`` in MATLAB's shape (2-D at least)
complex             complex ``np.ndarray``
char row            ``str``; a char matrix reads as ``list[str]`` (its rows)
cell vector         ``list``; other cells as an object ``np.ndarray``
scalar struct       ``dict``; struct arrays as ``list[dict]``
sparse              ``scipy.sparse`` matrix (v5 only)
==================  ==========================================================

On writing, a 1-D array becomes an N×1 column (``oned_as="column"``), a
``list``/``tuple`` becomes a 1×N cell array, a mapping a struct.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Final, Literal

import h5py
import numpy as np
import scipy.io
import scipy.sparse
from scipy.io import matlab as _matlab

from fsmbench.io.errors import RecordingError
from fsmbench.io.signals import EXPERIMENTS
from fsmbench.io.trailing import HDF5_SIGNATURE, PrefixReader, data_end, warn_trailing

__all__ = [
    "HDF5_SIGNATURE",
    "FileFormat",
    "available_memory_bytes",
    "detect_format",
    "load_mat",
    "other_run_words",
]

#: What :func:`detect_format` can report.
FileFormat = Literal["mat4", "mat5", "mat73", "hdf5"]

_MAT73_TEXT: Final = b"MATLAB 7.3 MAT-file"

#: Fraction of the available memory an HDF5 file's datasets may claim before they are read
#: whole: the reader holds the stored array and the float64 copy the recording is built from.
_MEMORY_FRACTION: Final = 0.5

_DTYPE_OF: Final[dict[str, str]] = {
    "double": "f8", "single": "f4", "int8": "i1", "uint8": "u1", "int16": "i2",
    "uint16": "u2", "int32": "i4", "uint32": "u4", "int64": "i8", "uint64": "u8",
    "logical": "?", "char": "u2",
}


def available_memory_bytes() -> int:
    """Memory the machine can still give [bytes] (Linux ``MemAvailable``; else 4 GiB)."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 4 << 30


# --------------------------------------------------------------------------- format
def _describe(head: bytes) -> str:
    """Say in words what a file that is not a MAT/HDF5 file seems to hold."""
    magic = {
        b"\x89PNG\r\n\x1a\n": "a PNG image", b"%PDF": "a PDF document",
        b"PK\x03\x04": "a ZIP archive", b"\x1f\x8b": "gzip data",
        b"\xff\xd8\xff": "a JPEG image", b"CDF\x01": "a netCDF-3 file",
        b"CDF\x02": "a netCDF-3 file",
    }
    for sig, what in magic.items():
        if head.startswith(sig):
            return what
    try:
        text = head.decode("utf-8")
    except UnicodeDecodeError:
        return f"unrecognised binary data (first bytes {head[:8]!r})"
    if all(c.isprintable() or c in "\r\n\t" for c in text):
        return f"text ({text[:40]!r})"
    return f"unrecognised binary data (first bytes {head[:8]!r})"


def _looks_like_mat4(head: bytes) -> bool:
    """True if ``head`` opens with a plausible MAT v4 matrix header."""
    if len(head) < 20:
        return False
    for order in ("<i4", ">i4"):
        mopt, mrows, ncols, imagf, namlen = np.frombuffer(head[:20], dtype=order)
        m, o, p, t = mopt // 1000, (mopt // 100) % 10, (mopt // 10) % 10, mopt % 10
        # MOPT = 1000*M + 100*O + 10*P + T with M<=4 (machine), O=0, P<=5, T<=2.
        if (0 <= mopt < 5000 and o == 0 and p <= 5 and t <= 2 and m <= 4
                and mrows >= 0 and ncols >= 0 and imagf in (0, 1) and 0 < namlen < 64):
            return True
    return False


def detect_format(path: str | os.PathLike[str]) -> FileFormat:
    """Tell a file's format from its first bytes.

    Parameters
    ----------
    path : str or os.PathLike
        The file; opened read-only.

    Returns
    -------
    {"mat4", "mat5", "mat73", "hdf5"}
        ``"mat5"`` covers MATLAB's v6 and v7 files; ``"hdf5"`` is an HDF5 file
        without a MATLAB header (e.g. a NeXus archive).

    Raises
    ------
    RecordingError
        The file is empty or is neither a MAT-file nor an HDF5 file.
    FileNotFoundError
        The file does not exist.
    """
    p = Path(path)
    size = p.stat().st_size
    if size == 0:
        raise RecordingError(p, "is empty (0 bytes), not a MAT-file or HDF5 file",
                             kind="is empty (0 bytes)")
    with open(p, "rb") as fh:
        head = fh.read(128)
        # The HDF5 superblock sits at 0 or after a userblock of 512 * 2**k bytes.
        offset, sig_at = 0, None
        while offset + 8 <= size:
            fh.seek(offset)
            if fh.read(8) == HDF5_SIGNATURE:
                sig_at = offset
                break
            offset = 512 if offset == 0 else 2 * offset
    if sig_at is not None:
        return "mat73" if sig_at > 0 and head.startswith(_MAT73_TEXT) else "hdf5"
    if len(head) == 128 and (head[124:128] in (b"\x00\x01IM", b"\x01\x00MI")):
        return "mat5"
    if _looks_like_mat4(head):
        return "mat4"
    raise RecordingError(
        p, f"is not a MAT-file (v4, v5/v7, v7.3) or HDF5 file: it holds {_describe(head)}",
        kind="is not a MAT-file (v4, v5/v7, v7.3) or HDF5 file",
    )


# --------------------------------------------------------------------------- reading
def load_mat(
    path: str | os.PathLike[str],
    *,
    variables: list[str] | tuple[str, ...] | None = None,
    skip_unreadable: bool = False,
) -> dict[str, Any]:
    """Read the variables of a MAT-file (any version) or a MATLAB-like HDF5 file.

    Parameters
    ----------
    path : str or os.PathLike
        The file; opened read-only, never modified.
    variables : sequence of str, optional
        Read only these (like MATLAB's ``load(file, 'a', 'b')``); all if None.
    skip_unreadable : bool, default False
        Leave out, with a ``UserWarning``, the variables that only MATLAB can
        read (objects such as ``ss`` or ``timeseries``, function handles)
        instead of raising.

    Returns
    -------
    dict
        Variable name to value, in file order (see the module docstring for
        the types). Units are whatever the file holds; shapes are MATLAB's.

    Raises
    ------
    RecordingError
        Not a MAT/HDF5 file, a corrupt file, a requested variable missing, an
        unreadable variable (unless ``skip_unreadable``), or no variable before
        bytes that end the data (zeros right after the header).

    Warns
    -----
    fsmbench.io.trailing.TrailingBytesWarning
        Bytes follow the data (a zero padding): the variables before them are
        read, the bytes are not (:mod:`fsmbench.io.trailing`).
    """
    p = Path(path)
    fmt = detect_format(p)
    end = data_end(p, fmt)
    if end.trailing and end.end <= (128 if fmt == "mat5" else 0):
        raise RecordingError(p, f"holds no variable: {end.sentence()}")
    warn_trailing(end, stacklevel=2)
    if fmt in ("mat4", "mat5"):
        out = _load_v5(p, fmt, variables, skip_unreadable, end=end.end)
    else:
        out = _load_h5(p, fmt, variables, skip_unreadable)
    if variables is not None:
        missing = [v for v in variables if v not in out]
        if missing:
            raise RecordingError(
                p, f"is missing (the file holds: {', '.join(out) or 'nothing'})"
                + other_run_words(p, out), variable=missing[0],
            )
    return out


def other_run_words(path: Path, held: Mapping[str, Any]) -> str:
    """Words naming the experiment whose variables a file holds instead of its own (a file
    saved under another run's name), empty when none matches."""

    names = set(held)
    own = path.stem
    for name, info in EXPERIMENTS.items():
        if name != own and set(info.required) <= names and not set(
                EXPERIMENTS.get(own, info).required) <= names:
            return (f": it holds {name}'s variables; the files exchanged or misnamed (the "
                    f"other run saved as {path.name}), or the variables renamed: check which "
                    "run this is")
    return ""


class _UnreadableError(Exception):
    """A value only MATLAB can read; carries the reason."""


def _load_v5(
    p: Path, fmt: str, names: list[str] | tuple[str, ...] | None, skip: bool, *, end: int
) -> dict[str, Any]:
    # mat_dtype=True: MATLAB stores integer-valued doubles as small ints; this
    # returns them as the class MATLAB loads (double). But scipy then casts
    # complex arrays to that real class too, dropping the imaginary part
    # (numpy says so with a ComplexWarning): such files are read a second time
    # without mat_dtype and their complex arrays taken from that reading.
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", np.exceptions.ComplexWarning)
        raw = _scipy_loadmat(p, fmt, names, mat_dtype=True, end=end)
    lost_imag = any(issubclass(w.category, np.exceptions.ComplexWarning) for w in caught)
    for w in caught:  # pass on the other warnings unchanged
        if not issubclass(w.category, np.exceptions.ComplexWarning):
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    raw_c = _scipy_loadmat(p, fmt, names, mat_dtype=False, end=end) if lost_imag else {}
    out: dict[str, Any] = {}
    for name, value in raw.items():
        if name.startswith("__"):
            continue
        try:
            out[name] = _from_scipy(value, name)
            if name in raw_c:
                out[name] = _take_complex(out[name], _from_scipy(raw_c[name], name))
        except _UnreadableError as exc:
            _unreadable(p, name, str(exc), skip)
    return out


def _scipy_loadmat(
    p: Path, fmt: str, names: list[str] | tuple[str, ...] | None, *, mat_dtype: bool, end: int
) -> dict[str, Any]:
    try:
        with open(p, "rb") as fh:
            # scipy reads to the end of its stream: the bytes after the data (a padding it
            # would refuse the whole file for) are cut off.
            raw: dict[str, Any] = scipy.io.loadmat(
                PrefixReader(fh, end), variable_names=None if names is None else list(names),
                mat_dtype=mat_dtype, squeeze_me=False, struct_as_record=False,
                chars_as_strings=True,
            )
    except Exception as exc:  # scipy raises many types on a corrupt file
        version = "v4" if fmt == "mat4" else "v5/v7"
        raise RecordingError(p, f"cannot be read as a MATLAB {version} file ({exc})") from exc
    return raw


def _take_complex(real: Any, other: Any) -> Any:
    """``real`` with every complex array taken from ``other`` (same structure)."""
    if isinstance(other, np.ndarray) and other.dtype.kind == "c":
        rdtype = real.dtype if isinstance(real, np.ndarray) else np.dtype(np.float64)
        # class single -> complex64, anything else (double, ints) -> complex128
        return other.astype(np.complex64 if rdtype == np.float32 else np.complex128)
    if isinstance(real, dict) and isinstance(other, dict):
        return {k: _take_complex(v, other[k]) for k, v in real.items()}
    if isinstance(real, list) and isinstance(other, list):
        return [_take_complex(a, b) for a, b in zip(real, other, strict=True)]
    if isinstance(real, np.ndarray) and real.dtype == object:
        out = np.empty(real.shape, dtype=object)
        for idx, v in np.ndenumerate(real):
            out[idx] = _take_complex(v, other[idx])
        return out
    return real


def _unreadable(p: Path, name: str, reason: str, skip: bool) -> None:
    problem = f"{reason}, which only MATLAB can read; save it as arrays, strings or structs"
    if not skip:
        raise RecordingError(p, problem, variable=name)
    warnings.warn(f"{p}: variable '{name}' left out: {problem}", UserWarning, stacklevel=4)


def _is_vector_shape(shape: tuple[int, ...]) -> bool:
    return len(shape) <= 2 and (len(shape) < 2 or min(shape) <= 1)


def _from_scipy(value: Any, where: str) -> Any:
    """Convert one value from scipy.io.loadmat to the types of this module."""
    if isinstance(value, (_matlab.MatlabFunction, _matlab.MatlabOpaque)):
        raise _UnreadableError(f"holds a MATLAB object or function handle ({where})")
    if isinstance(value, _matlab.MatlabObject):
        raise _UnreadableError(f"holds a MATLAB object of class '{value.classname}' ({where})")
    if isinstance(value, _matlab.mat_struct):
        return {f: _from_scipy(getattr(value, f), f"{where}.{f}") for f in value._fieldnames}
    if scipy.sparse.issparse(value) or not isinstance(value, np.ndarray):
        return value
    if value.dtype.kind == "U":
        rows = [str(s) for s in value.ravel()]
        return "" if not rows else rows[0] if len(rows) == 1 else rows
    if value.dtype != object:
        return value
    flat = value.ravel(order="F")  # MATLAB's element order
    if flat.size and all(isinstance(v, _matlab.mat_struct) for v in flat):
        structs = [_from_scipy(v, f"{where}({i + 1})") for i, v in enumerate(flat)]
        return structs[0] if len(structs) == 1 else structs
    items = [_from_scipy(v, f"{where}{{{i + 1}}}") for i, v in enumerate(flat)]
    return _cell(items, value.shape)


def _cell(items: list[Any], shape: tuple[int, ...]) -> list[Any] | np.ndarray:
    """A MATLAB cell as a list (vector) or an object array (matrix)."""
    if _is_vector_shape(shape):
        return items
    arr = np.empty(len(items), dtype=object)
    arr[:] = items
    return arr.reshape(shape, order="F")


def _attr_str(value: Any) -> str | None:
    if value is None:
        return None
    if isinstance(value, np.ndarray):
        value = value.item() if value.size == 1 else b"".join(value.ravel().tolist())
    return value.decode("ascii", "replace") if isinstance(value, bytes) else str(value)


def _load_h5(
    p: Path, fmt: str, names: list[str] | tuple[str, ...] | None, skip: bool
) -> dict[str, Any]:
    try:
        f = h5py.File(p, "r")
    except OSError as exc:
        kind = "MATLAB v7.3" if fmt == "mat73" else "HDF5"
        raise RecordingError(p, f"cannot be read as a {kind} file ({exc})") from exc
    out: dict[str, Any] = {}
    with f:
        keys = [k for k in f if not k.startswith("#")]  # "#refs#", "#subsystem#"
        wanted = keys if names is None else [k for k in keys if k in names]
        _check_claimed_size(p, f, wanted)
        for name in wanted:
            try:
                out[name] = _from_h5(f[name], f, name)
            except _UnreadableError as exc:
                _unreadable(p, name, str(exc), skip)
            except (OSError, KeyError, ValueError) as exc:
                raise RecordingError(p, f"cannot be read ({exc})", variable=name) from exc
    return out


def _claimed_bytes(obj: Any) -> tuple[int, str, tuple[int, ...]]:
    """Bytes the datasets under ``obj`` claim (shape x item size, not what is stored),
    with the largest dataset's name and shape."""
    sizes: list[tuple[int, str, tuple[int, ...]]] = []

    def add(name: str, item: Any) -> None:
        if isinstance(item, h5py.Dataset) and item.shape is not None:
            sizes.append((int(np.prod(item.shape, dtype=object)) * item.dtype.itemsize,
                          item.name, tuple(int(n) for n in item.shape)))

    if isinstance(obj, h5py.Group):
        obj.visititems(add)
    else:
        add(obj.name, obj)
    if not sizes:
        return 0, "", ()
    largest = max(sizes)
    return sum(n for n, _name, _shape in sizes), largest[1], largest[2]


def _check_claimed_size(p: Path, f: h5py.File, names: list[str]) -> None:
    """Refuse, before reading, datasets whose claimed size does not fit in memory.

    An HDF5 header may claim any shape (a damaged file, or chunks never
    written); reading it whole would end in ``MemoryError``.
    """
    total, name, worst = 0, "", 0
    shape: tuple[int, ...] = ()
    for key in names:
        n, big, big_shape = _claimed_bytes(f[key])
        total += n
        if n > worst:
            worst, name, shape = n, big.lstrip("/"), big_shape
    have = available_memory_bytes()
    if total > _MEMORY_FRACTION * have:
        raise RecordingError(p, f"its datasets claim {total / 2**30:.1f} GiB ('{name}' has "
                                f"shape {shape}), more than half of the {have / 2**30:.1f} GiB "
                                "this machine has available, so it is not read whole: a "
                                "damaged file, or a record to read in pieces after fsmbench "
                                f"convert {p} {p.with_suffix('.h5')}")


def _from_h5(obj: Any, f: h5py.File, where: str) -> Any:
    """Read one HDF5 object laid out as MATLAB writes v7.3 files."""
    cls = _attr_str(obj.attrs.get("MATLAB_class"))
    if "MATLAB_object_decode" in obj.attrs or (
        cls is not None and cls not in _DTYPE_OF and cls not in ("cell", "struct")
    ):
        raise _UnreadableError(f"holds a MATLAB object of class '{cls}' ({where})")
    if isinstance(obj, h5py.Group):
        return _group_from_h5(obj, f, where)
    data = obj[()]
    if cls is None:  # plain HDF5 written by another tool: no axis reversal
        if isinstance(data, bytes):
            return data.decode("utf-8")
        return data
    if obj.attrs.get("MATLAB_empty", 0):
        # MATLAB stores an empty array as its dims (MATLAB order) in uint64.
        shape = tuple(int(d) for d in np.ravel(data))
        if cls == "char":
            return ""
        if cls == "cell":
            return [] if _is_vector_shape(shape) else np.empty(shape, dtype=object)
        if cls == "struct":
            return {}
        return np.zeros(shape, dtype=_DTYPE_OF[cls])
    data = np.asarray(data).T  # reverse HDF5's axes back to MATLAB's
    if cls == "cell":
        items = [_from_h5(f[ref], f, f"{where}{{{i + 1}}}")
                 for i, ref in enumerate(data.ravel(order="F"))]
        return _cell(items, data.shape)
    if cls == "char":
        rows = [row.astype("<u2").tobytes().decode("utf-16-le") for row in np.atleast_2d(data)]
        return rows[0] if len(rows) == 1 else rows
    if data.dtype.names is not None and set(data.dtype.names) == {"real", "imag"}:
        ctype = np.result_type(data.dtype["real"], np.complex64)
        out = np.empty(data.shape, dtype=ctype)
        out.real, out.imag = data["real"], data["imag"]
        return out
    if cls == "logical":
        return data.astype(bool)
    return data


def _group_from_h5(g: h5py.Group, f: h5py.File, where: str) -> Any:
    if "MATLAB_sparse" in g.attrs:
        nrows = int(np.ravel(g.attrs["MATLAB_sparse"])[0])
        jc = np.asarray(g["jc"][()]).ravel()
        ir = np.asarray(g["ir"][()]).ravel() if "ir" in g else np.zeros(0, np.int64)
        data = _from_h5(g["data"], f, where).ravel() if "data" in g else np.zeros(0)
        return scipy.sparse.csc_matrix((data, ir, jc), shape=(nrows, jc.size - 1))
    fields_attr = g.attrs.get("MATLAB_fields")
    if fields_attr is not None:
        fields = [b"".join(np.asarray(x).tolist()).decode("ascii") for x in fields_attr]
    else:
        fields = list(g)
    members = [g[k] for k in fields]
    # A struct array stores each field as an array of references with no
    # MATLAB_class (matio: Mat_H5ReadGroupInfo); a scalar struct stores values.
    if members and all(
        isinstance(m, h5py.Dataset) and m.dtype == h5py.ref_dtype
        and "MATLAB_class" not in m.attrs for m in members
    ):
        refs = {k: np.asarray(m[()]).T.ravel(order="F")
                for k, m in zip(fields, members, strict=True)}
        n = refs[fields[0]].size
        return [{k: _from_h5(f[refs[k][i]], f, f"{where}({i + 1}).{k}") for k in fields}
                for i in range(n)]
    return {k: _from_h5(m, f, f"{where}.{k}") for k, m in zip(fields, members, strict=True)}
