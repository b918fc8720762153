"""Atomic file output: a file is either absent, or complete.

Every writer in fsmbench goes through :func:`atomic_path`: it writes into a
temporary file in the destination folder and renames it over the destination
only once the write finished, so an interrupted run (Ctrl-C, crash, full disk)
never leaves a half-written file behind, and an existing file is replaced in
one step.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

__all__ = ["atomic_path", "atomic_write_bytes", "atomic_write_text"]


@contextlib.contextmanager
def atomic_path(destination: str | Path, *, suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path; on success it is renamed to ``destination``.

    Parameters
    ----------
    destination : str or Path
        Final file path. Its folder must exist.
    suffix : str, optional
        Suffix of the temporary file (some writers choose the format by
        suffix); defaults to the destination's suffix.

    Notes
    -----
    On any exception, ``KeyboardInterrupt`` included, the temporary file is
    removed and ``destination`` is left as it was. An ``OSError`` that names
    no file (a failed write, e.g. a full disk) is raised again naming
    ``destination``.
    """
    dest = Path(destination)
    if not dest.parent.is_dir():
        raise FileNotFoundError(f"{dest}: output folder {dest.parent} does not exist")
    fd, tmp_name = tempfile.mkstemp(
        prefix=f".{dest.name}.", suffix=(dest.suffix if suffix is None else suffix) + ".part",
        dir=dest.parent,
    )
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        yield tmp
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        # mkstemp creates 0600; give the file the mode a plain open() would.
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, dest)
    except OSError as exc:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        if exc.filename is None:
            # A failed write (full disk: errno 28) names no file; name the destination.
            raise OSError(exc.errno, exc.strerror or str(exc), str(dest)) from exc
        raise
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        raise


def _umask() -> int:
    # os.umask can only be read by setting it; restore it at once.
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def atomic_write_bytes(destination: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``destination`` atomically and return the path."""
    dest = Path(destination)
    with atomic_path(dest) as tmp:
        tmp.write_bytes(data)
    return dest


def atomic_write_text(destination: str | Path, text: str) -> Path:
    """Write UTF-8 ``text`` to ``destination`` atomically and return the path."""
    return atomic_write_bytes(destination, text.encode("utf-8"))
