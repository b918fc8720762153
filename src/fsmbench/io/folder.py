"""A folder of recordings in the ESRF study's layout, read as one set, and its plausibility checks.

:func:`load_recordings` reads every seed experiment a folder holds and says,
for every experiment it does not use, why; what a user should know about the
files it did use (saturation, dropped variables …) comes back as
:class:`~fsmbench.checks.Notice` records and plausibility verdicts as
:class:`~fsmbench.checks.Check` records, never as Python warnings. A folder
with no usable recording is a :class:`~fsmbench.io.errors.RecordingError`
saying what was looked for, what was found and which file names nearly match
(files failing in the same way named together, in one line). An experiment in
two files (``data_uch.mat`` beside ``data_uch.h5``) is read from the first of
``.mat``, ``.h5``, ``.nxs`` and refused unless the others hold the same samples
(:mod:`fsmbench.io.duplicates`).

:func:`check_recording` (:mod:`fsmbench.io.record_checks`) is the plausibility test of
one recording; the loader runs it on every record it reads.

A name that is there but is not a readable file (a directory, a symbolic link
that loops or points nowhere) is named as what it is, not as missing.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

import h5py
import numpy as np
import xarray as xr

from fsmbench.checks import Check, Notice
from fsmbench.forked import child_share, fork_available, start_forked
from fsmbench.io import matfile
from fsmbench.io.duplicates import compare_files, other_files
from fsmbench.io.errors import RecordingError, SaturationWarning
from fsmbench.io.folder_names import folder_hints, not_a_file
from fsmbench.io.lazy import open_recording, v5_vectors
from fsmbench.io.matfile import detect_format
from fsmbench.io.notes import FILE_CHOICE
from fsmbench.io.record_checks import (
    EXCITATION,
    MAX_VA_RMS_M,
    RATE_TOLERANCE,
    CarriedChecks,
    carried_checks,
    carry_checks,
    check_recording,
)
from fsmbench.io.recording import find_experiments, read_recording, recording_as_read
from fsmbench.io.signals import EXPERIMENTS, TIME
from fsmbench.io.trailing import TrailingBytesWarning, data_end

__all__ = [
    "EXCITATION",
    "MAX_VA_RMS_M",
    "RATE_TOLERANCE",
    "RecordingSet",
    "check_recording",
    "folder_hints",
    "load_recordings",
    "not_a_file",
    "sample_bytes",
]

@dataclass(frozen=True, eq=False)
class RecordingSet:
    """The recordings of one folder and what was found about them.

    Attributes
    ----------
    folder : str
    recordings : dict of str to xarray.Dataset
        Experiment name to recording, in the ESRF study's order (also those that
        fail a check: the stage that needs them skips them, naming the check).
    skipped : dict of str to str
        Experiment name to the reason it is not used (missing file, with
        near-miss hints, or the problem naming file, variable and problem).
    notices : tuple of Notice
        Non-fatal findings (saturation, dropped variables, data types, rates).
    checks : tuple of Check
        Plausibility checks run on the recordings (see :func:`check_recording`).
    """

    folder: str
    recordings: dict[str, xr.Dataset]
    skipped: dict[str, str] = field(default_factory=dict)
    notices: tuple[Notice, ...] = ()
    checks: tuple[Check, ...] = ()

    def unusable(self) -> dict[str, str]:
        """The skipped experiments whose file was there (unreadable, malformed) or nearly
        so (a near-miss name): those a step must not call "missing"."""
        return {name: why for name, why in self.skipped.items()
                if not (why.startswith(f"no {name}.mat") and "; found " not in why)}

    def to_json(self) -> dict[str, Any]:
        """JSON-ready summary (no arrays)."""
        return {"folder": self.folder, "experiments": list(self.recordings),
                "skipped": dict(self.skipped),
                "notices": [n.to_json() for n in self.notices],
                "checks": [c.to_json() for c in self.checks]}


def _notice_of(w: warnings.WarningMessage, label: str) -> Notice | None:
    if isinstance(w.message, (SaturationWarning, TrailingBytesWarning)):
        return None  # check_recording reports them itself (saturation, the recording's notes)
    text = str(w.message)
    if issubclass(w.category, RuntimeWarning):
        return Notice("numeric", label, f"numerical problem while reading: {text}")
    if " left out" in text:
        return Notice("dropped_variable", label, text.split(": ", 1)[-1])
    return Notice("other", label, text)


def _mixed_rates(recordings: dict[str, xr.Dataset], found: dict[str, Path]) -> list[Notice]:
    rates: dict[float, list[str]] = {}
    for name, ds in recordings.items():
        rates.setdefault(float(ds.attrs["fs_hz"]), []).append(found[name].name)
    if len(rates) < 2:
        return []
    text = "; ".join(f"{fs:g} Hz: {', '.join(files)}" for fs, files in rates.items())
    return [Notice("rate", "", f"the recordings have different sampling rates ({text})")]


#: HDF5 recordings (NeXus, MATLAB v7.3) larger than this are read lazily (Dask).
LAZY_BYTES: Final = 512 << 20
#: Samples per Dask chunk of a record read lazily: 8 MiB per signal, so that a day
#: (864 M samples) is 824 chunks per signal, not 13 000 (whose graph alone costs ~0.5 GB).
LAZY_CHUNK_SAMPLES: Final = 1 << 20
#: Experiments whose analyses run out of core; other long records must fit in memory.
OUT_OF_CORE_EXPERIMENTS: Final = frozenset({*(f"data_huddle_test_{i}" for i in range(1, 6)),
                                            "data_rep_h", "data_rep_v"})


#: Peak memory of the analyses of a record read whole, per byte of its float64 samples
#: (the budget on 60 s and 600 s huddle tests: 0.41 and 1.05 GB RSS for 19 and 192 MB of
#: samples, a slope of 3.7; rounded up).
IN_MEMORY_FACTOR: Final = 4.0
#: Files smaller than this are never too large to read whole (their samples are at most
#: ~10x the file, a few hundred MB).
_MEMORY_CHECK_BYTES: Final = 32 << 20


def sample_bytes(path: Path, fmt: str) -> int:
    """The float64 samples a recording holds [bytes], from its headers (nothing read)."""
    if fmt == "mat5":
        return sum(8 * n for _name, n in v5_vectors(path))

    total = 0

    def visit(_name: str, obj: Any) -> None:
        nonlocal total
        if isinstance(obj, h5py.Dataset) and obj.dtype.kind in "fiu":
            total += 8 * int(obj.size)

    with h5py.File(path, "r") as f:
        data = f.get("entry/data")  # NeXus: the samples, not the instrument's numbers
        (data if isinstance(data, h5py.Group) else f).visititems(visit)
    return total


def _refuse_if_too_large(path: Path, name: str, fmt: str, *, out_of_core: bool) -> None:
    """A record whose analysis in memory would not fit: one line, before any allocation."""
    # Read through the module: a test gives the machine less memory by patching it there.
    if path.stat().st_size <= _MEMORY_CHECK_BYTES:
        return
    need = sample_bytes(path, fmt)
    have = matfile.available_memory_bytes()
    if IN_MEMORY_FACTOR * need <= have:
        return
    gib = 2.0**30
    head = (f"is {need / gib:.1f} GiB of samples: analysing it in memory takes about "
            f"{IN_MEMORY_FACTOR * need / gib:.0f} GiB and this machine has {have / gib:.1f} GiB "
            "available")
    if name not in OUT_OF_CORE_EXPERIMENTS:
        raise RecordingError(path, f"{head}; only the huddle tests and the repeatability "
                                   "records run out of core: cut it to the ESRF study's length")
    if fmt == "mat5":
        raise RecordingError(path, f"{head}; a MATLAB v5 file cannot be read in pieces: convert "
                                   f"it once (fsmbench convert {path} {path.with_suffix('.h5')} "
                                   "--format nexus)" + ("" if out_of_core else
                                                        ", with the dask extra installed "
                                                        "(pip install 'fsmbench[dask]')"))
    raise RecordingError(path, f"{head}; install the dask extra (pip install "
                               "'fsmbench[dask]') to analyse it block by block, out of core")


def _read(path: Path, name: str, *, adc_range_v: float, adc_bits: int,
          lazy_bytes: int, written: Mapping[Path, Mapping[str, np.ndarray]]) -> xr.Dataset:
    """The recording, lazily (Dask) when it is a large HDF5 file (see :data:`LAZY_BYTES`).

    Read whole, a record too large to analyse in memory (:data:`IN_MEMORY_FACTOR`) is
    refused in one line before anything is allocated, with the way to analyse it. A
    MAT-file this process wrote (``written``) is taken as read from what was written.
    """

    fmt = detect_format(path)
    wrote = written.get(Path(os.path.abspath(path)))
    if wrote is not None and fmt in ("mat5", "mat73"):
        return recording_as_read(path, wrote, experiment=name,
                                 adc_range_v=adc_range_v, adc_bits=adc_bits)
    try:
        import dask  # noqa: F401
        out_of_core = True
    except ImportError:  # the fsmbench[dask] extra is not installed: read whole, if it fits
        out_of_core = False
    # The data's size, not the file's: zeros after them are not read (fsmbench.io.trailing).
    if data_end(path, fmt).end <= lazy_bytes or fmt not in ("hdf5", "mat73") or not out_of_core:
        _refuse_if_too_large(path, name, fmt, out_of_core=out_of_core)
        return read_recording(path, experiment=name, adc_range_v=adc_range_v, adc_bits=adc_bits)

    # NaN and Inf in the signals are found by check_recording's pass (_signal_stats).
    ds = open_recording(path, check_signals=False, chunk_samples=LAZY_CHUNK_SAMPLES)
    ds.attrs["experiment"] = name
    missing = [v for v in EXPERIMENTS[name].required if v not in ds.variables]
    if missing:
        raise RecordingError(path, f"is missing {', '.join(missing)}", variable=missing[0])
    if name in OUT_OF_CORE_EXPERIMENTS:
        return ds
    need = 8 * ds.sizes[TIME] * (len(ds.data_vars) + 1)
    if need > 0.5 * matfile.available_memory_bytes():
        raise RecordingError(path, f"is {need / 2**30:.1f} GiB of samples: too long to analyse "
                             "in memory, and only the huddle tests and the repeatability "
                             "records run out of core; cut it to the ESRF study's length")
    return ds.compute()


def _read_one(path: Path, name: str, *, fs_hz: float | None, adc_range_v: float,
              adc_bits: int, lazy_bytes: int, written: Mapping[Path, Mapping[str, np.ndarray]]
              ) -> tuple[xr.Dataset, list[Check], list[Notice]]:
    """One experiment's record read and checked: the warnings of reading it as notices,
    other files of the same experiment beside it compared with it (or named in the error)."""
    others = other_files(path, name)

    def read(p: Path, name: str = name) -> xr.Dataset:
        return _read(p, name, adc_range_v=adc_range_v, adc_bits=adc_bits,
                     lazy_bytes=lazy_bytes, written=written)

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            ds = read(path)
        except RecordingError as exc:
            if not others:
                raise
            raise RecordingError(exc.file, f"{exc.problem}; {others[0].name} beside it "
                                 f"holds {name} too: remove or rename the file that is "
                                 "not the record", variable=exc.variable,
                                 kind=exc.kind) from None
        if others:  # which file was read, and the others agree with it (or refused)
            with warnings.catch_warnings(record=True):  # of files not used: dropped
                ds.attrs[FILE_CHOICE] = compare_files(name, path, ds, others, read=read)
        found_checks, found_notices = check_recording(
            ds, name=name, fs_hz=fs_hz, adc_range_v=adc_range_v, adc_bits=adc_bits)
    notices = [n for w in caught if (n := _notice_of(w, path.name)) is not None]
    return ds, list(found_checks), notices + list(found_notices)


@dataclass(frozen=True, eq=False)
class _Read:
    """One record read and checked (:func:`_read_one`), and its checks to carry with it."""

    name: str
    ds: xr.Dataset
    checks: list[Check]
    notices: list[Notice]
    carried: CarriedChecks | None = None


def _read_some(found: Mapping[str, Path], names: Sequence[str], *,
               progress: Callable[[str], None] | None,
               **options: Any) -> dict[str, _Read | RecordingError]:
    """The records of ``names`` read and checked, or the error refusing each."""
    out: dict[str, _Read | RecordingError] = {}
    for name in names:
        if progress is not None:
            progress(f"reading {found[name].name}")
        try:
            ds, checks, notices = _read_one(found[name], name, **options)
        except RecordingError as exc:
            out[name] = exc
            continue
        out[name] = _Read(name, ds, checks, notices, carried_checks(
            ds, name=name, adc_range_v=options["adc_range_v"], adc_bits=options["adc_bits"]))
    return out


def _child_share(found: Mapping[str, Path],
                 written: Mapping[Path, Mapping[str, np.ndarray]]) -> set[str]:
    """The records a forked process reads: about half of the MAT v5 files' bytes (read
    whole, they travel back pickled in milliseconds; a lazy record holds an open file).
    A file this process wrote is not decoded (``written``): the fork would cost more
    than its share of the checks (measured: the same read time, more copy-on-write)."""
    sizes: dict[str, float] = {}
    for name, path in found.items():
        if Path(os.path.abspath(path)) in written:
            continue
        try:
            if detect_format(path) == "mat5":
                sizes[name] = path.stat().st_size
        except (OSError, RecordingError):
            continue  # read here, where its problem is said
    return child_share(sizes)


def _read_all(found: Mapping[str, Path], *, progress: Callable[[str], None] | None,
              parallel: bool, **options: Any) -> dict[str, _Read | RecordingError]:
    """Every record of ``found`` read and checked, or the error refusing it.

    With ``parallel`` a forked process (:mod:`fsmbench.forked`) reads about half of them
    while this one reads the rest: the same datasets, checks and notices, with each
    record's checks kept for the stages that ask for them again.
    """
    share = (_child_share(found, options["written"]) if parallel and fork_available()
             else set())
    job = start_forked(lambda say: _read_some(found, [n for n in found if n in share],
                                              progress=None if progress is None else say,
                                              **options),
                       progress=progress or (lambda _msg: None), parallel=True) if share else None
    try:
        done = _read_some(found, [n for n in found if n not in share], progress=progress,
                          **options)
        theirs = job.result() if job is not None else {}
    finally:
        if job is not None:
            job.cancel()
    for outcome in theirs.values():
        if isinstance(outcome, _Read) and outcome.carried is not None:
            carry_checks(outcome.ds, outcome.carried)
    return {**done, **theirs}


def load_recordings(data_dir: Path, *, fs_hz: float | None = None, adc_range_v: float = 20.0,
                    adc_bits: int = 16, progress: Callable[[str], None] | None = None,
                    lazy_bytes: int = LAZY_BYTES, parallel: bool = False,
                    written: Mapping[Path, Mapping[str, np.ndarray]] | None = None
                    ) -> RecordingSet:
    """Read every seed experiment present in ``data_dir`` and check it.

    Parameters
    ----------
    data_dir : Path
        Folder of recordings (``data_uch.mat`` …; ``.h5``/``.nxs`` too).
    fs_hz : float, optional
        The bench's sampling rate [Hz] (``bench.nominal.converter.fs_hz``);
        each recording's rate must be within 1 % of it (check
        ``sampling_rate``). None accepts any rate.
    adc_range_v, adc_bits : float, int
        Converter span [V] and resolution [bit] (range and saturation).
    progress : callable, optional
        Receives one message per file read.
    lazy_bytes : int
        HDF5 files larger than this [bytes] are read lazily (Dask arrays);
        the huddle tests and the repeatability records stay lazy and are
        analysed out of core, other experiments are loaded into memory if they fit.
    parallel : bool
        Read about half of the MAT v5 files in a forked process (:mod:`fsmbench.forked`,
        where ``fork`` exists and there are two cores) while this one reads the rest:
        the same result.
    written : mapping of Path to mapping of str to numpy.ndarray, optional
        MAT-files of ``data_dir`` this process has just written, each with the
        variables written to it (:func:`~fsmbench.io.recording.mat_variables`): taken
        as read from them, the reader's own checks and notes included, without
        decoding the files again (:func:`~fsmbench.io.recording.recording_as_read`;
        the same datasets, tested).

    Raises
    ------
    RecordingError
        No recording could be read: the message lists what was looked for,
        what the folder holds and the near-miss names, or each file's problem (one
        phrase naming the files that fail in the same way).
    NotADirectoryError
        ``data_dir`` is not a folder.
    """
    found = find_experiments(data_dir)
    hints = folder_hints(data_dir)
    recordings: dict[str, xr.Dataset] = {}
    skipped: dict[str, str] = {}
    notices: list[Notice] = []
    checks: list[Check] = []
    odd = {name: why for name in EXPERIMENTS if name not in found
           and (why := not_a_file(Path(data_dir), name)) is not None}
    failures: dict[str, RecordingError] = {}
    read = _read_all({name: found[name] for name in EXPERIMENTS if name in found},
                     progress=progress, parallel=parallel, fs_hz=fs_hz,
                     adc_range_v=adc_range_v, adc_bits=adc_bits, lazy_bytes=lazy_bytes,
                     written={Path(os.path.abspath(p)): v for p, v in (written or {}).items()})
    for name in EXPERIMENTS:
        if name not in found:
            skipped[name] = odd.get(name) or f"no {name}.mat (or .h5/.nxs) in {data_dir}" + (
                f"; {hints[name]}" if name in hints else "")
            continue
        outcome = read[name]
        if isinstance(outcome, RecordingError):
            skipped[name] = str(outcome)
            failures[name] = outcome
            continue
        recordings[name] = outcome.ds
        checks += outcome.checks
        notices += outcome.notices
    if not recordings:
        raise RecordingError(data_dir, _empty_problem(Path(data_dir), found, skipped, hints,
                                                      odd, failures))
    if fs_hz is None:
        notices += _mixed_rates(recordings, found)
    else:
        notices += [Notice("rate", c.subject, c.sentence()) for c in checks
                    if c.name == "sampling_rate" and not c.passed]
    return RecordingSet(folder=str(data_dir), recordings=recordings, skipped=skipped,
                        notices=tuple(notices), checks=tuple(checks))


def _grouped(names: list[str], found: dict[str, Path], skipped: dict[str, str],
             failures: dict[str, RecordingError]) -> list[str]:
    """Why each experiment was not used, files failing in the same way named together.

    Thirteen files refused for the same reason (a clock's jitter, once) made one line of
    4 KB: such files become one phrase naming them, with the first file's full problem.
    """
    groups: dict[tuple[str | None, str], list[str]] = {}
    for name in names:
        exc = failures.get(name)
        key = (exc.variable, exc.kind) if exc is not None and exc.kind else None
        groups.setdefault(key or (None, name), []).append(name)
    out = []
    for (variable, kind), members in groups.items():
        if len(members) < 2:
            out.append(skipped[members[0]])
            continue
        what = f"variable '{variable}' {kind}" if variable else kind
        first = failures[members[0]]
        out.append(f"{what} in {len(members)} files ({', '.join(found[m].name for m in members)})"
                   f"; the first, {first}")
    return out


def _empty_problem(root: Path, found: dict[str, Path], skipped: dict[str, str],
                   hints: dict[str, str], odd: dict[str, str],
                   failures: dict[str, RecordingError]) -> str:
    names = sorted(p.name for p in root.iterdir()) if root.is_dir() else []
    shown = ", ".join(names[:12]) + (f" … ({len(names)} entries)" if len(names) > 12 else "")
    if found or odd:
        bad = "; ".join(_grouped([n for n in EXPERIMENTS if n in found or n in odd], found,
                                 skipped, failures))
        return f"no recording in this folder can be used: {bad}"
    looked = (f"looked for the ESRF study's recordings ({', '.join(list(EXPERIMENTS)[:2])} … "
              f"{list(EXPERIMENTS)[-1]}, {len(EXPERIMENTS)} names, as .mat, .h5 or .nxs)")
    near = "; ".join(hints.values())
    return (f"holds none of them: {looked}; found {shown or 'nothing (empty folder)'}"
            + (f"; did you mean: {near}" if near else ""))
