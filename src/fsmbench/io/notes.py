"""What a reader found about the file it read, kept in the recording, one sentence each.

A reader sets these dataset attributes; :func:`fsmbench.io.folder.check_recording`
turns each into a :class:`~fsmbench.checks.Notice` of the same kind, so that the
loader's results, ``identification.json`` and the study say the same line, whether
the stage was given the folder or the recordings. A reader removes the ones an
archive kept from an earlier reading (they describe the file read then, not this one).
"""

from __future__ import annotations

from typing import Final

import xarray as xr

__all__ = ["FILE_CHOICE", "READ_NOTES", "TIME_JITTER", "TRAILING_BYTES", "clear_notes"]

#: Bytes after the data were ignored (:mod:`fsmbench.io.trailing`).
TRAILING_BYTES: Final = "trailing_bytes"
#: The experiment is in several files of the folder; which was read, and that they agree.
FILE_CHOICE: Final = "file_choice"
#: ``t`` strays from a uniform grid by clock jitter (:mod:`fsmbench.io.timebase`).
TIME_JITTER: Final = "time_jitter"
#: Every note, in the order the notices are given.
READ_NOTES: Final = (TRAILING_BYTES, FILE_CHOICE, TIME_JITTER)


def clear_notes(ds: xr.Dataset) -> None:
    """Remove the notes a dataset's attributes hold (an archive written from a reading)."""
    for key in READ_NOTES:
        ds.attrs.pop(key, None)
