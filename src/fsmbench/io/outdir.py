"""Output folders: where a command may write, and a run as one transaction.

A command never writes into ``--out`` directly. :func:`output_transaction`
first checks ``--out`` (:func:`preflight`: creatable, writable, replaceable,
enough free space, not a user's unrelated folder, not holding or inside the
data), then yields a fresh hidden staging folder beside it (same parent, so
the final swap is a rename on one filesystem). When the command succeeds the
staging folder gets a manifest ``run.json`` and replaces ``--out`` in one
rename; the previous run is removed afterwards. On any error, Ctrl-C or
SIGTERM the staging folder is removed and ``--out`` is left as it was. So
``--out`` always holds either the complete previous run or the complete new
one.

``run.json`` lists every file of the run (relative path, sha256, size), the
command and the fsmbench version; a wall-clock time only when asked.

Inputs are never touched: every path named on the command line (``--params``,
``--bench``, ``--controller``, ``--excitation``, ``--ranges``, DATA, …) is checked
against ``--out`` before anything runs (:func:`check_inputs`), and a previous
run whose files no longer match its ``run.json`` (edited by hand) is not
replaced (:func:`preflight`).
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import hashlib
import json
import os
import shutil
import signal
import tempfile
import threading
import time
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import FrameType
from typing import Any, Final

from fsmbench.atomic import atomic_write_text
from fsmbench.jsonutil import format_text
from fsmbench.version import __version__

__all__ = [
    "MANIFEST",
    "InputPaths",
    "OutputError",
    "RunFolder",
    "check_inputs",
    "check_out_dir",
    "check_path_text",
    "output_transaction",
    "preflight",
    "read_manifest",
]

#: Name of the manifest every run writes into its output folder.
MANIFEST: Final = "run.json"
_FORMAT: Final = "fsmbench.run"
_STAGING_TAG: Final = ".fsmbench-new-"
_OLD_TAG: Final = ".fsmbench-old-"
_RENAME_EXCHANGE: Final = 2  # linux/fs.h


class OutputError(ValueError):
    """The output folder cannot be used; ``str()`` is ``"<file>: <problem>"``.

    Parameters
    ----------
    file : str or os.PathLike
        The folder or file concerned.
    problem : str
        What is wrong and what to do.
    """

    def __init__(self, file: str | os.PathLike[str], problem: str) -> None:
        super().__init__(os.fspath(file), problem)
        self.file = os.fspath(file)
        self.problem = problem

    def __str__(self) -> str:
        return f"{self.file}: {self.problem}"


def check_out_dir(out_dir: Path, data_dir: Path | None, *, out_option: str = "--out") -> None:
    """Refuse an output folder inside the data folder, or one holding it.

    Inputs are never touched: writing inside the data folder would mix
    outputs with recordings, and replacing a folder that holds the data
    (the swap of :func:`output_transaction`) would delete them. ``out_option``:
    how the user gave the output folder (``--out``, or ``simulate``'s ``OUT``).
    """
    if data_dir is None:
        return
    out, data = Path(out_dir).resolve(), Path(data_dir).resolve()
    if out == data or data in out.parents:
        raise OutputError(out_dir, f"{out_option} is inside the data folder {data_dir}; "
                                   "fsmbench never writes into the data folder, choose another "
                                   f"{out_option}")
    if out in data.parents:
        raise OutputError(out_dir, f"{out_option} contains the data folder {data_dir}; a run "
                                   "replaces its output folder as a whole, choose another "
                                   f"{out_option}")


#: The inputs of a command: (option as the user typed it, path) pairs; None paths are skipped.
InputPaths = Iterable[tuple[str, "str | os.PathLike[str] | None"]]


def _shown(raw: str) -> str:
    """A path as text that prints anywhere (bytes that are not UTF-8 as ``\\xff``)."""
    return os.fsencode(raw).decode("utf-8", "backslashreplace")


#: Options that name a file, never a folder: a folder given there is the command's own
#: error ("is a folder; --params needs a TOML file"), not a placement problem.
_FILE_OPTIONS: Final = frozenset({"--params", "--ranges"})


def check_path_text(option: str, path: str | os.PathLike[str]) -> None:
    """Refuse an input path that is not UTF-8 (``OutputError`` naming it and the byte).

    fsmbench records its inputs' paths in its results (JSON, MAT-files, HDF5
    attributes), which hold UTF-8 text; a path with other bytes (Latin-1 names
    on a UTF-8 system) cannot be written there.
    """
    raw = os.fspath(path)
    encoded = os.fsencode(raw)
    try:
        encoded.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise OutputError(_shown(raw), f"the {option} path is not valid UTF-8 (byte "
                                       f"0x{encoded[exc.start]:02x} at position {exc.start}); "
                                       "fsmbench records its inputs' paths in its results "
                                       "(JSON, MAT-files), which are UTF-8: rename it, or link "
                                       "it under a UTF-8 name") from None


def check_inputs(out_dir: str | Path, inputs: InputPaths, *, out_option: str = "--out") -> None:
    """Refuse, before anything runs, an input the run would destroy or write into.

    Parameters
    ----------
    out_dir : str or Path
        The ``--out`` folder (it need not exist).
    inputs : iterable of (str, path or None)
        Every path the command line names as an input, with its option
        (``"--controller"``, ``"DATA"``, ...); a ``FILE::NAME`` controller is
        passed as its file.
    out_option : str
        How the user gave the output folder (``--out``, or ``simulate``'s ``OUT``).

    Raises
    ------
    OutputError
        Naming the input and its option: the input is ``--out`` or inside it
        (the run replaces ``--out`` as a whole, so it would be deleted), or
        ``--out`` is inside an input folder (outputs never go into inputs), or
        the input's path is not UTF-8 (results record their inputs' paths in
        UTF-8 JSON and MAT-files, which cannot hold it).
    """
    out = Path(out_dir).resolve()
    for option, value in inputs:
        if value is None:
            continue
        raw = os.fspath(value)
        check_path_text(option, raw)
        if option in ("DATA", "--data"):  # the data folder's own wording
            check_out_dir(Path(out_dir), Path(raw), out_option=out_option)
            continue
        path = Path(raw).resolve()
        if path == out or out in path.parents:
            where = (f"is the {out_option} folder" if path == out
                     else f"is inside {out_option}")
            raise OutputError(raw, f"{option} {where} {_shown(os.fspath(out_dir))}, which this "
                                   "run replaces as a whole; copy it elsewhere or choose "
                                   f"another {out_option}")
        if path in out.parents and path.is_dir() and option not in _FILE_OPTIONS:
            raise OutputError(out_dir, f"{out_option} is inside the {option} folder {raw}; "
                                       "fsmbench never writes into its inputs' folders, choose "
                                       f"another {out_option}")


def read_manifest(folder: Path) -> dict[str, Any] | None:
    """The ``run.json`` of a previous fsmbench run in ``folder``, or None."""
    path = Path(folder) / MANIFEST
    try:
        payload = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(payload, dict) or payload.get("format") != _FORMAT:
        return None
    return payload


def _human_bytes(n: float) -> str:
    for unit in ("B", "kB", "MB", "GB"):
        if abs(n) < 1000 or unit == "GB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1000
    return f"{n:.1f} GB"  # pragma: no cover - loop always returns


def _first_existing(path: Path) -> Path:
    p = path
    while not os.path.lexists(p) and p != p.parent:
        p = p.parent
    return p


def preflight(out_dir: str | Path, *, data_dir: str | Path | None = None,
              need_bytes: int = 0, out_option: str = "--out") -> Path:
    """Check that ``out_dir`` can take a run, before any computation.

    Parameters
    ----------
    out_dir : str or Path
        The ``--out`` folder; it may not exist yet (its parents are created).
    data_dir : str or Path, optional
        The data folder, which ``out_dir`` must neither be inside nor contain.
    need_bytes : int
        Estimate of what the run writes [bytes]; the filesystem must have at
        least that much free.
    out_option : str
        How the user gave the output folder (``--out``, or ``simulate``'s ``OUT``).

    Returns
    -------
    Path
        ``out_dir`` made absolute (symbolic links resolved).

    Raises
    ------
    OutputError
        With the folder and the problem: a file in the way, a non-empty folder
        that is not a previous fsmbench run (its files are never deleted), a
        previous run with a file changed since it was written (checked
        against the SHA-256 in its ``run.json``), a folder that cannot be
        written (read-only, immutable), too little free space.
    OSError
        The parent folders cannot be created (read-only, no permission).
    """
    out = Path(out_dir).resolve()
    check_out_dir(out, None if data_dir is None else Path(data_dir), out_option=out_option)
    cwd = Path.cwd().resolve()
    if cwd == out or out in cwd.parents:
        raise OutputError(out, "is the current folder or holds it; a run replaces its output "
                               "folder as a whole, so run fsmbench from another folder or "
                               f"choose another {out_option}")
    blocker = _first_existing(out)
    if blocker != out and not blocker.is_dir():
        raise OutputError(blocker, f"is a file, not a folder, so {out_option} {out_dir} cannot "
                                   f"be created under it; choose another {out_option}")
    if out.exists() and not out.is_dir():
        raise OutputError(out, f"exists and is a file, not a folder; choose another {out_option}")
    if out.is_dir():
        _check_replaceable(out, out_option)
    out.parent.mkdir(parents=True, exist_ok=True)
    try:  # writable? (root ignores permission bits: only trying tells)
        os.rmdir(tempfile.mkdtemp(prefix=f".{out.name}{_STAGING_TAG}", dir=out.parent))
    except OSError as exc:
        raise OutputError(out.parent, f"cannot write the output folder here ({exc.strerror}); "
                                      f"choose another {out_option}") from exc
    free = shutil.disk_usage(out.parent).free
    if free < need_bytes:
        raise OutputError(out.parent, f"only {_human_bytes(free)} free on this filesystem but "
                                      f"the run writes about {_human_bytes(need_bytes)}; free "
                                      f"some space or choose another {out_option}")
    return out


def _check_replaceable(out: Path, out_option: str) -> None:
    entries = sorted(p.name for p in out.iterdir())
    if not entries:
        return
    manifest = read_manifest(out)
    if manifest is None:
        raise OutputError(out, f"is not empty ({len(entries)} entries, e.g. {entries[0]}) and "
                               f"holds no fsmbench run ({MANIFEST}); a run replaces its output "
                               f"folder as a whole, so choose a new or empty {out_option}")
    entries_listed = [f for f in manifest.get("files", [])
                      if isinstance(f, dict) and isinstance(f.get("path"), str)]
    listed = {f["path"] for f in entries_listed}
    for path in sorted(out.rglob("*")):
        rel = path.relative_to(out).as_posix()
        if path.is_file() and rel != MANIFEST and rel not in listed:
            raise OutputError(path, f"is not part of the fsmbench run in {out} (not listed in "
                                    f"its {MANIFEST}); move it away or choose another "
                                    f"{out_option}, "
                                    "fsmbench never deletes files it did not write")
    for entry in entries_listed:
        _check_unchanged(out, entry, out_option)


def _check_unchanged(out: Path, entry: dict[str, Any], out_option: str) -> None:
    """Refuse to replace a listed file that was changed since fsmbench wrote it.

    The size is compared first (no read), then the SHA-256. A listed file that
    is gone is no loss. A file edited by hand is the user's work now: the run
    refuses rather than delete it. No ``--force``: moving the one named file
    away is the way out, and an option to skip this check would be one more
    way to lose what it protects.
    """
    path = out / entry["path"]
    if not path.is_file() or out not in path.resolve().parents:
        return
    size, digest = entry.get("size_bytes"), entry.get("sha256")
    changed = ((isinstance(size, int) and path.stat().st_size != size)
               or (isinstance(digest, str) and _sha256(path) != digest))
    if changed:
        raise OutputError(path, f"was changed after fsmbench wrote it (its SHA-256 no longer "
                                f"matches {MANIFEST}); a run replaces {out} as a whole, so move "
                                f"this file away (or delete it) or choose another {out_option}: "
                                "fsmbench never overwrites a file it did not write")


@dataclass(frozen=True)
class RunFolder:
    """The folder a command writes into, and where its files end up.

    Attributes
    ----------
    final : Path
        The ``--out`` folder (absolute).
    staging : Path
        The hidden folder beside ``final`` the command writes into.
    """

    final: Path
    staging: Path

    def final_path(self, path: str | Path) -> Path:
        """Where ``path`` (inside ``staging``) will be once the run is complete."""
        p = Path(path)
        try:
            return self.final / p.relative_to(self.staging)
        except ValueError:
            return p

    def final_text(self, text: str) -> str:
        """``text`` with the staging folder's path replaced by the final one."""
        return text.replace(str(self.staging), str(self.final))


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _write_manifest(staging: Path, *, command: str, arguments: Sequence[str],
                    not_reproducible: Sequence[str], timestamp: bool) -> None:
    files = [{"path": p.relative_to(staging).as_posix(), "sha256": _sha256(p),
              "size_bytes": p.stat().st_size}
             for p in sorted(staging.rglob("*")) if p.is_file()]
    present = {f["path"] for f in files}
    payload: dict[str, Any] = {
        "format": _FORMAT, "format_version": 1, "fsmbench_version": __version__,
        "command": command, "arguments": list(arguments),
        "files": files,
        "not_reproducible": [n for n in not_reproducible if n in present],
    }
    if timestamp:
        payload["created_utc"] = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    atomic_write_text(staging / MANIFEST, format_text(payload, sort_keys=True))


@contextlib.contextmanager
def _signals_deferred() -> Iterator[None]:
    """Hold SIGINT and SIGTERM until the block ends (then deliver them)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pending: list[int] = []

    def hold(signum: int, _frame: FrameType | None) -> None:
        pending.append(signum)

    saved = {int(sig): signal.signal(sig, hold) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for signum, handler in saved.items():
            signal.signal(signum, handler)
        for signum in dict.fromkeys(pending):
            handler = saved[signum]
            if callable(handler):
                handler(signum, None)
            elif handler == signal.SIG_DFL:
                signal.raise_signal(signum)


def _exchange(a: Path, b: Path) -> bool:
    """Swap two paths in one step (Linux renameat2); False when not supported."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        fn = libc.renameat2
    except (OSError, AttributeError):
        return False
    at_fdcwd = -100
    rc = fn(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), _RENAME_EXCHANGE)
    if rc == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.EINVAL, errno.ENOSYS, errno.ENOTSUP):
        return False
    raise OSError(err, os.strerror(err), str(b))


def _mode_for_new_folder() -> int:
    mask = os.umask(0o022)  # os.umask can only be read by setting it; restored at once
    os.umask(mask)
    return 0o777 & ~mask


def _swap_in(staging: Path, out: Path) -> Path | None:
    """Put ``staging`` at ``out``; return where the previous run now is (or None)."""
    os.chmod(staging, _mode_for_new_folder())
    if not out.exists():
        os.rename(staging, out)
        return None
    if _exchange(staging, out):
        return staging  # the old run now sits at the staging path
    old = Path(tempfile.mkdtemp(prefix=f".{out.name}{_OLD_TAG}", dir=out.parent))
    os.rmdir(old)
    os.rename(out, old)
    try:
        os.rename(staging, out)
    except BaseException:
        os.rename(old, out)
        raise
    return old


def _probe_replace(out: Path, out_option: str) -> None:
    """Fail now, not after the computation, if ``out`` cannot be moved (immutable)."""
    if not out.exists():
        return
    probe = Path(tempfile.mkdtemp(prefix=f".{out.name}{_OLD_TAG}", dir=out.parent))
    os.rmdir(probe)
    with _signals_deferred():
        try:
            os.rename(out, probe)
        except OSError as exc:
            raise OutputError(out, f"cannot be replaced ({exc.strerror}); check its permissions "
                                   f"and attributes (lsattr) or choose another {out_option}") \
                from exc
        os.rename(probe, out)


def _remove_stale_staging(out: Path) -> None:
    """Remove staging folders of ``out`` left by runs that were killed (SIGKILL, power loss).

    A staging folder is named ``.<out>.fsmbench-new-<pid>-<random>``; it is stale when no
    process has that pid any more. Folders of live runs, of other users' runs and of
    unknown names are left alone.
    """
    prefix = f".{out.name}{_STAGING_TAG}"
    try:
        siblings = list(out.parent.iterdir())
    except OSError:
        return
    for path in siblings:
        pid_text = path.name[len(prefix):].split("-", 1)[0]
        if not (path.name.startswith(prefix) and pid_text.isdigit() and path.is_dir()):
            continue
        try:
            os.kill(int(pid_text), 0)
        except ProcessLookupError:
            shutil.rmtree(path, ignore_errors=True)
        except OSError:  # a process of another user has that pid: alive
            continue


@contextlib.contextmanager
def output_transaction(out_dir: str | Path, *, command: str, arguments: Sequence[str] = (),
                       data_dir: str | Path | None = None, need_bytes: int = 0,
                       timestamp: bool = False,
                       not_reproducible: Sequence[str] = ("timings.json",),
                       warn: Any = None, inputs: InputPaths = (),
                       out_option: str = "--out") -> Iterator[RunFolder]:
    """Run a command's writes as one transaction on ``out_dir``.

    Parameters
    ----------
    out_dir : str or Path
        The ``--out`` folder: absent, empty, or a previous fsmbench run.
    command : str
        Sub-command name, recorded in ``run.json``.
    arguments : sequence of str
        The command line, recorded in ``run.json`` (pass the output folder as
        ``"."`` so that the manifest does not depend on where the run lives).
    data_dir : str or Path, optional
        The data folder (never inside ``out_dir``, nor containing it).
    need_bytes : int
        Estimate of the run's size [bytes], checked against the free space.
    timestamp : bool
        Record the wall-clock time in ``run.json`` (default: no time, so the
        same inputs give the same manifest).
    not_reproducible : sequence of str
        Files (relative paths) that legitimately differ between identical
        runs, such as ``timings.json``; listed as such in ``run.json``.
    warn : callable, optional
        Receives a one-line message if the previous run cannot be removed
        after the swap (the new run is in place regardless).
    inputs : iterable of (str, path or None)
        Every input the command line names, with its option; checked by
        :func:`check_inputs` before anything else.
    out_option : str
        How the user gave ``out_dir`` (``--out``, or ``simulate``'s ``OUT``), for the messages.

    Yields
    ------
    RunFolder
        ``staging`` to write into, ``final`` and a mapping between them.
    """
    check_inputs(out_dir, inputs, out_option=out_option)
    out = preflight(out_dir, data_dir=data_dir, need_bytes=need_bytes, out_option=out_option)
    _remove_stale_staging(out)
    try:
        # The pid in the name lets a later run tell a killed run's leftovers from a live one.
        staging = Path(tempfile.mkdtemp(prefix=f".{out.name}{_STAGING_TAG}{os.getpid()}-",
                                        dir=out.parent))
    except OSError as exc:
        raise OutputError(out.parent, f"cannot write the output folder here ({exc.strerror}); "
                                      f"choose another {out_option}") from exc
    try:
        _probe_replace(out, out_option)
        yield RunFolder(final=out, staging=staging)
        with _signals_deferred():
            _write_manifest(staging, command=command, arguments=arguments,
                            not_reproducible=not_reproducible, timestamp=timestamp)
            old = _swap_in(staging, out)
            if old is not None:
                try:
                    shutil.rmtree(old)
                except OSError as exc:
                    if warn is not None:
                        warn(f"{old}: the previous run could not be removed ({exc.strerror}); "
                             "delete it by hand")
    except BaseException:
        with _signals_deferred():
            shutil.rmtree(staging, ignore_errors=True)
        raise
