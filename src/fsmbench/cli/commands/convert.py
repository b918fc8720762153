"""``fsmbench convert IN OUT``: a recording copied into a chunked NeXus archive.

A MATLAB v5 file cannot be read in parts; converted, it is read lazily with
bounded memory (:mod:`fsmbench.io.lazy`).

OUT is one file, written atomically. It never replaces a file fsmbench did not
write: an existing OUT is replaced only when it is an archive ``convert`` made
from the same IN (its root records IN's absolute path), so a typo such as
``convert data_uch.mat data_ucv.mat`` cannot destroy another recording. OUT
must be named ``.h5`` or ``.nxs`` (what a data folder is read by): the readers
tell formats by content, but a person, MATLAB's ``load`` and the folder reader
go by the name. The archive
has no ``file_time`` unless ``--timestamp`` (a root note says so), so the same
IN gives the same bytes.
"""

from __future__ import annotations

import argparse
import functools
import os
from pathlib import Path
from typing import Any

from fsmbench.cli.args import positive
from fsmbench.cli.options import add_json, add_timestamp
from fsmbench.cli.runfolder import print_files, progress

__all__ = ["NEXUS_SUFFIXES", "register", "run"]

#: Names an archive written by ``convert`` may have: those a data folder is read by
#: (:data:`fsmbench.io.folder._SUFFIXES` less ``.mat``).
NEXUS_SUFFIXES = (".h5", ".nxs")
#: ``created`` of an archive without ``--timestamp``: the epoch, which the NeXus writers
#: take as "no file_time" (:data:`fsmbench.io.nexus_meta.UNSTAMPED_S`), as the twin's files.
_FIXED_CREATED_S = 0.0


def _check_paths(src: Path, dest: Path) -> None:
    """IN readable and UTF-8, OUT a new archive name or an earlier conversion of IN."""
    from fsmbench.io.lazy import converted_from
    from fsmbench.io.outdir import OutputError, check_path_text

    if not src.is_file():
        raise FileNotFoundError(2, "no such recording" if not src.exists()
                                else "is a folder, not a recording", str(src))
    check_path_text("IN", src)  # the archive records IN's path
    if dest.exists() and (dest.resolve() == src.resolve() or os.path.samefile(dest, src)):
        raise OutputError(dest, "is IN itself; the output would replace the input, and inputs "
                                "are never modified: choose another OUT")
    if dest.is_dir():
        raise OutputError(dest, f"is a folder; OUT is the archive to write, e.g. "
                                f"{dest / src.with_suffix('.h5').name}")
    if os.path.lexists(dest) and converted_from(dest) != str(src.resolve()):
        raise OutputError(dest, f"exists and is not an archive fsmbench convert made from "
                                f"{src}; fsmbench never overwrites a file it did not write: "
                                "move it away or choose another OUT")
    if dest.suffix.lower() not in NEXUS_SUFFIXES:
        raise OutputError(dest, f"convert writes a NeXus (HDF5) archive: name OUT "
                                f"{dest.with_suffix('.h5').name} (.h5 or .nxs, the names a data "
                                f"folder is read by), not {dest.suffix or 'without a suffix'}")
    if not dest.parent.is_dir():
        raise FileNotFoundError(2, "output folder does not exist", str(dest.parent))


def register(sub: Any) -> None:
    """Add ``convert`` to the sub-commands ``sub``."""
    p = sub.add_parser("convert", help="copy a recording into a chunked NeXus archive (long "
                                       "records: lazy reading, bounded memory)")
    p.add_argument("source", metavar="IN", help="MATLAB v5/v7.3 or NeXus recording")
    p.add_argument("dest", metavar="OUT",
                   help="the NeXus archive to write (.h5, .nxs); an existing OUT is replaced "
                        "only if convert made it from IN")
    p.add_argument("--format", choices=("nexus",), default="nexus",
                   help="output format (nexus: chunked HDF5, read lazily)")
    p.add_argument("--fs", metavar="HZ", type=functools.partial(positive, unit="Hz"),
                   default=None, dest="fs_hz",
                   help="sampling rate [Hz] (default: from t; when given, it must agree with "
                        "t within 0.1 %%)")
    add_timestamp(p, where="the archive's file_time")
    add_json(p, help="print the archive written as JSON (format fsmbench.files) instead of "
                     "its path")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Convert; the archive's path is the result."""
    from fsmbench.io.lazy import convert_recording

    src, dest = Path(args.source), Path(args.dest)
    _check_paths(src, dest)
    written = convert_recording(src, dest, fs_hz=args.fs_hz, progress=progress(),
                                created=None if args.timestamp else _FIXED_CREATED_S)
    print_files([written], as_json=args.json, command="convert")
    return 0
