"""The names in a data folder: near misses of the ESRF study's file names, and entries that
are there but are not files to read.

:func:`folder_hints` says, for each experiment the folder lacks, which file nearly
matches and how to rename it; :func:`not_a_file` names an entry that has the right
name but is a directory, a dangling or looping link, a pipe …; both are
used by :func:`fsmbench.io.folder.load_recordings`, which re-exports them.
"""

from __future__ import annotations

import contextlib
import difflib
import errno
import os
import re
import stat
from collections.abc import Iterable
from pathlib import Path
from typing import Final

from fsmbench.io.signals import EXPERIMENTS

__all__ = ["SUFFIXES", "folder_hints", "not_a_file"]

#: The suffixes of the files a folder's experiments are read from, in order of preference.
SUFFIXES: Final = (".mat", ".h5", ".nxs")
_COPY_TAIL = re.compile(r"(\s*\(\d+\)|\s*-\s*copy(\s*\d+)?|\s+copy|_copy|\s*\[\d+\])$",
                        re.IGNORECASE)


def _norm_stem(path: Path) -> str:
    """Lower-case stem without extensions and copy marks: ``DATA_UCH (1).MAT`` → ``data_uch``."""
    stem = path.name[: -len(path.suffix)] if path.suffix else path.name
    for suffix in SUFFIXES:
        if stem.lower().endswith(suffix):
            stem = stem[: -len(suffix)]
    stem = _COPY_TAIL.sub("", stem.strip()).strip()
    return stem.lower().replace(" ", "_").replace("-", "_")


def folder_hints(folder: str | os.PathLike[str],
                 names: Iterable[str] = tuple(EXPERIMENTS)) -> dict[str, str]:
    """For each experiment absent from ``folder``, the file that nearly matches and the fix.

    Parameters
    ----------
    folder : str or os.PathLike
        The data folder (read, not recursed).
    names : iterable of str
        Experiment names to look for.

    Returns
    -------
    dict of str to str
        Experiment name to a sentence such as ``"found DATA_UCH.mat: rename it
        data_uch.mat (file names are case-sensitive)"``; only for the
        experiments with a near miss.
    """
    root = Path(folder)
    files = sorted(p for p in root.iterdir() if p.is_file()) if root.is_dir() else []
    wanted = list(names)
    hints: dict[str, str] = {}
    for p in files:
        if p.name in {f"{n}{s}" for n in wanted for s in SUFFIXES}:
            continue
        stem = _norm_stem(p)
        exp = stem if stem in wanted else next(iter(difflib.get_close_matches(
            stem, wanted, n=1, cutoff=0.9)), None)
        if exp is None or exp in hints or any((root / f"{exp}{s}").is_file()
                                              for s in SUFFIXES):
            continue
        suffix = p.suffix.lower()
        if suffix not in SUFFIXES:
            hints[exp] = (f"found {p.name}, a {p.suffix or 'suffix-less'} file: the study reads "
                          f"MAT-files (MATLAB: save('{exp}.mat', ...)) or NeXus (.h5, .nxs)")
            continue
        if stem != exp:
            why = "a similar name; the study reads only the exact name"
        elif p.suffix != suffix:
            why = "the extension must be lower case"
        elif p.stem.lower() == exp:
            why = "file names are case-sensitive"
        else:
            why = "a copy's name; the study reads only the exact name"
        hints[exp] = f"found {p.name}: rename it {exp}{suffix} ({why})"
    return hints


def not_a_file(folder: Path, name: str) -> str | None:
    """Why ``folder/name.mat`` (or ``.h5``, ``.nxs``) is there but is not a file to read.

    Parameters
    ----------
    folder : Path
        The data folder.
    name : str
        An experiment name (``"data_uch"``).

    Returns
    -------
    str or None
        ``"data_uch.mat in DIR is a directory, not a recording file …"``, a
        symbolic link that loops or points to nothing, a named pipe …; None
        when no entry of that name exists (or it is a file).
    """
    for suffix in SUFFIXES:
        path = folder / f"{name}{suffix}"
        if not os.path.lexists(path):
            continue
        head = f"{path.name} in {folder} is"
        if path.is_symlink():
            target = os.readlink(path)
            try:
                mode = os.stat(path).st_mode
            except OSError as exc:
                if exc.errno == errno.ELOOP:
                    return (f"{head} a symbolic link that loops ({path.name} → {target} → …, "
                            "never reaching a file): point it at the recording")
                return (f"{head} a symbolic link to {target}, which does not exist (a dangling "
                        "link: the file was moved or deleted): point it at the recording")
            if stat.S_ISREG(mode):
                continue
            what = f"a symbolic link to {target}, " + _kind(mode)
        else:
            try:
                mode = os.lstat(path).st_mode
            except OSError as exc:
                return f"{head} not readable ({exc.strerror})"
            if stat.S_ISREG(mode):
                continue
            what = _kind(mode)
        inside = ""
        if stat.S_ISDIR(mode):
            with contextlib.suppress(OSError):
                held = sorted(p.name for p in path.iterdir())
                inside = (f" holding {', '.join(held[:5])}{' …' if len(held) > 5 else ''}"
                          if held else " (empty)")
        return (f"{head} {what}{inside}, not a recording file: the study reads {name}.mat as "
                "a MAT-file (or .h5/.nxs)")
    return None


def _kind(mode: int) -> str:
    for test, words in ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a named pipe (FIFO)"),
                        (stat.S_ISSOCK, "a socket"), (stat.S_ISCHR, "a character device"),
                        (stat.S_ISBLK, "a block device")):
        if test(mode):
            return words
    return "not a regular file"
