"""Where a MAT-file's data end, and the bytes after them.

A file of valid variables can be followed by bytes that belong to no variable:
zeros from a copy that preallocated its destination, a disk image's slack, a
transfer padded to a block size. scipy reads such a v5 file up to the first
empty element and then gives up on the whole file (``Did not read any bytes``),
and walking the padding element by element took minutes per GiB. This module
finds the end of the data from the elements' own headers, so that reading
costs the same whatever the padding's size and never touches the padding:

* MAT v5/v7: the elements after the 128-byte header, each a tag (type, size)
  and its data, are stepped over by their sizes; a tag of type 0, which the
  format does not define (8 zero bytes in a zero padding), or of 0 bytes (a
  variable holds at least its flags, dimensions and name) is the end;
* MAT v4: the matrices, each a 20-byte header and its data, are stepped over;
  a header with no name (``namlen`` 0, 20 zero bytes in a zero padding) is the
  end, since every v4 matrix stores its name and the name's terminating NUL;
* HDF5 and MAT v7.3: the superblock's end-of-file address, which the HDF5
  library stores counting the userblock (a v7.3 file's 512-byte MAT header) and
  checks against the file's size when it opens it.

Anything else the walk meets (a tag or size that runs past the end of the
file, an unknown layout) ends the walk with the whole file as data: the
reader then reports the damage as it always did.
"""

from __future__ import annotations

import contextlib
import os
import struct
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO, Final

__all__ = ["HDF5_SIGNATURE", "DataEnd", "PrefixReader", "TrailingBytesWarning", "data_end",
           "warn_trailing"]

#: The 8 bytes that open an HDF5 superblock (HDF5 File Format Specification).
HDF5_SIGNATURE: Final = b"\x89HDF\r\n\x1a\n"

_V5_HEADER: Final = 128
_MI_COMPRESSED: Final = 15
#: Bytes per element of a v4 matrix by its precision digit P (MOPT = 1000 M + 100 O + 10 P + T).
_V4_BYTES: Final = {0: 8, 1: 4, 2: 4, 3: 2, 4: 2, 5: 1}


@dataclass(frozen=True)
class DataEnd:
    """Where the data of a file end.

    Attributes
    ----------
    file : str
        The file.
    end : int
        Offset of the first byte after the data [bytes]; ``size`` when nothing
        follows them.
    size : int
        The file's size [bytes].
    marker : str
        Where the data end, in words that follow ``"byte N, "`` (``"where an element
        of type 0 begins (zeros, not a variable)"``, ``"the end-of-file address in
        the HDF5 superblock"``); empty when nothing follows them.
    """

    file: str
    end: int
    size: int
    marker: str = ""

    @property
    def trailing(self) -> int:
        """Bytes after the data [bytes], never read."""
        return self.size - self.end

    def sentence(self) -> str:
        """One line without the file name: how many bytes were ignored, from where, and why."""
        return (f"its data end at byte {self.end}, {self.marker}: the "
                f"{_bytes_text(self.trailing)} after them were ignored, not read")


def _bytes_text(n: int) -> str:
    if n < 1 << 20:
        return f"{n} bytes"
    unit, scale = ("GiB", 1 << 30) if n >= 1 << 30 else ("MiB", 1 << 20)
    return f"{n / scale:.4g} {unit} ({n} bytes)"


class TrailingBytesWarning(UserWarning):
    """Bytes after a file's data were ignored; the variables before them were read.

    Parameters
    ----------
    end : DataEnd
        Where the data end (``trailing`` > 0).
    """

    def __init__(self, end: DataEnd) -> None:
        super().__init__(end)
        self.end = end

    def __str__(self) -> str:
        return f"{self.end.file}: {self.end.sentence()}"


def warn_trailing(end: DataEnd, *, stacklevel: int = 2) -> DataEnd:
    """Warn (:class:`TrailingBytesWarning`) when bytes follow the data; return ``end``."""
    if end.trailing:
        warnings.warn(TrailingBytesWarning(end), stacklevel=stacklevel + 1)
    return end


class PrefixReader:
    """A read-only file whose end is ``end``: what scipy.io.loadmat reads instead of the file.

    scipy stops at the end of its stream (``read`` returns ``b""``), so the variables before
    the padding are read and the padding is not.

    Parameters
    ----------
    fh : binary file
        Open for reading; not closed here.
    end : int
        Offset of the first byte not to read [bytes].
    """

    def __init__(self, fh: BinaryIO, end: int) -> None:
        self._fh = fh
        self._end = end

    def read(self, n: int = -1) -> bytes:
        left = max(self._end - self._fh.tell(), 0)
        return self._fh.read(left if n is None or n < 0 or n > left else n)

    def seek(self, offset: int, whence: int = os.SEEK_SET) -> int:
        if whence == os.SEEK_END:
            return self._fh.seek(self._end + offset)
        return self._fh.seek(offset, whence)

    def tell(self) -> int:
        return self._fh.tell()

    def readable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return True


def _v5_end(fh: BinaryIO, size: int) -> tuple[int, str]:
    fh.seek(126)
    endian = "<" if fh.read(2) == b"IM" else ">"
    pos = _V5_HEADER
    while pos + 8 <= size:
        fh.seek(pos)
        kind, length = struct.unpack(endian + "II", fh.read(8))
        if kind == 0:
            return pos, "where an element of type 0 begins (zeros, not a variable)"
        if length == 0:  # a variable is never empty (flags, dimensions, name): scipy stops here
            return pos, f"where an element of type {kind} and 0 bytes begins (not a variable)"
        if kind >> 16:  # a small data element: never a variable, so not a walkable layout
            break
        # Uncompressed elements are padded to 8 bytes; compressed ones are not.
        pos += 8 + length + (-length % 8 if kind != _MI_COMPRESSED else 0)
    return _short_zeros(fh, pos, size, 8)


def _v4_end(fh: BinaryIO, size: int) -> tuple[int, str]:
    fh.seek(0)
    first = fh.read(4)
    # As scipy: the byte order whose MOPT reads as a small number.
    endian = "<" if 0 <= struct.unpack("<i", first)[0] < 5000 else ">"
    pos = 0
    while pos + 20 <= size:
        fh.seek(pos)
        mopt, mrows, ncols, imagf, namlen = struct.unpack(endian + "5i", fh.read(20))
        if namlen == 0:
            return pos, "where a matrix header with no name begins (zeros, not a variable)"
        width = _V4_BYTES.get((mopt // 10) % 10)
        if width is None or min(mrows, ncols, namlen) < 0 or imagf not in (0, 1):
            break
        pos += 20 + namlen + mrows * ncols * width * (1 + imagf)
    return _short_zeros(fh, pos, size, 20)


def _short_zeros(fh: BinaryIO, pos: int, size: int, header: int) -> tuple[int, str]:
    """The end at ``pos`` when fewer zeros than a header follow it there; else the file's."""
    if 0 < size - pos < header:
        fh.seek(pos)
        if not any(fh.read(header)):
            return pos, "where zeros too short for a header begin"
    return size, ""


def _hdf5_end(fh: BinaryIO, size: int, sig_at: int) -> tuple[int, str]:
    fh.seek(sig_at + 8)
    head = fh.read(64)
    if len(head) < 24:
        return size, ""
    version = head[0]
    if version in (0, 1):
        width = head[5]  # size of offsets
        at = 16 + (4 if version == 1 else 0)  # base, free space, end of file, driver
        index = 2
    elif version in (2, 3):
        width = head[1]
        at, index = 4, 2  # base, superblock extension, end of file, root
    else:
        return size, ""
    if width not in (2, 4, 8) or at + (index + 1) * width > len(head):
        return size, ""
    raw = head[at + index * width: at + (index + 1) * width]
    eof = int.from_bytes(raw, "little")
    # Stored counting the userblock (H5Fsuper.c compares it with the file's size); an
    # address past the file's end is a truncated file, which h5py reports itself.
    if sig_at < eof < size:
        return eof, "the end-of-file address in the HDF5 superblock"
    return size, ""


def data_end(path: str | os.PathLike[str], fmt: str, *, fh: Any = None) -> DataEnd:
    """Where the data of a MAT or HDF5 file end, from its headers alone.

    Parameters
    ----------
    path : str or os.PathLike
        The file; opened read-only.
    fmt : {"mat4", "mat5", "mat73", "hdf5"}
        Its format (:func:`fsmbench.io.matfile.detect_format`).
    fh : binary file, optional
        The file already open for reading (its position is changed).

    Returns
    -------
    DataEnd
        ``end`` is the offset after the last element (v4, v5) or the HDF5
        end-of-file address; equal to ``size`` when nothing follows the data.
        Reads one tag per variable (8 or 20 bytes), or 72 bytes of an HDF5
        superblock: the cost does not grow with what follows the data.
    """
    p = Path(path)
    size = p.stat().st_size
    with open(p, "rb") if fh is None else contextlib.nullcontext(fh) as f:
        if fmt == "mat5":
            end, marker = _v5_end(f, size)
        elif fmt == "mat4":
            end, marker = _v4_end(f, size)
        else:
            end, marker = _hdf5_end(f, size, _hdf5_signature_at(f, size))
    return DataEnd(os.fspath(p), end, size, marker)


def _hdf5_signature_at(fh: BinaryIO, size: int) -> int:
    offset = 0
    while offset + 8 <= size:  # at 0, or after a userblock of 512 * 2**k bytes
        fh.seek(offset)
        if fh.read(8) == HDF5_SIGNATURE:
            return offset
        offset = 512 if offset == 0 else 2 * offset
    return 0
