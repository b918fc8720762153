"""Recordings and experiments written to disk as they run, off the bench loop.

A job's samples go from the loop to a bounded queue and from there, in the
job's own writer thread, into a NeXus file with the chunked writer long
records use (:class:`fsmbench.io.nexus_stream.NexusAppender`): memory is a
few blocks whatever the duration, and a slow or failing disk ends the job
with a sentence, never the loop. A ``.mat`` file (the seed's layout) is made
from the streamed file when the job ends, so its size is bounded
(:data:`MAT_MAX_BYTES`); longer records are NeXus.

Before a job starts, :func:`plan_job` checks what the filesystem will say at
the end: the folder can be created and written, the name fits, no file is
overwritten unless asked, and the disk has room for it.
"""

from __future__ import annotations

import contextlib
import os
import queue
import shutil
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fsmbench.io.nexus_meta import iso_time
from fsmbench.io.nexus_stream import NexusAppender
from fsmbench.io.recording import read_recording, write_recording
from fsmbench.live.states import Refused

if TYPE_CHECKING:
    from fsmbench.bench.params import Bench

__all__ = ["BATCH_SAMPLES", "DISK_RESERVE_BYTES", "MAT_MAX_BYTES", "QUEUE_BLOCKS", "JobOutcome",
           "JobPlan", "JobWriter", "plan_job"]

#: Largest .mat job (samples of every column, t included) [bytes]: the file is built
#: in memory at the end. The study's longest experiment needs 48 MB.
MAT_MAX_BYTES = 64 * 2**20
#: Free space a job leaves on the disk [bytes].
DISK_RESERVE_BYTES = 64 * 2**20
#: Blocks the loop may be ahead of the writer (50 ms blocks: 12.8 s of bench time).
QUEUE_BLOCKS = 256
#: Samples the writer appends at once, at most (one HDF5 chunk).
BATCH_SAMPLES = 1 << 16


@dataclass(frozen=True)
class JobPlan:
    """A recording or an experiment, checked and ready to write.

    Attributes
    ----------
    kind : {"record", "experiment"}
    name : str
    path : Path
        The file the job makes.
    format : {"mat", "nexus"}
    signals : tuple of str
    n_samples : int
    start_sample : int
        Bench sample of the first sample.
    t0_s : float
        ``t`` of the first sample in the file [s] (bench time for a record,
        0 for an experiment: the seed's layout).
    fs_hz : float
    source : str
        The file's ``source`` attribute.
    bench : Bench or None
        The bench served, described in the file's NXinstrument (None: the packaged one).
    """

    kind: str
    name: str
    path: Path
    format: str
    signals: tuple[str, ...]
    n_samples: int
    start_sample: int
    t0_s: float
    fs_hz: float
    source: str
    bench: Bench | None = None

    @property
    def duration_s(self) -> float:
        """Bench time the job covers [s]."""
        return self.n_samples / self.fs_hz

    @property
    def stream_path(self) -> Path:
        """Where the samples are streamed (the file itself for NeXus; hidden for .mat)."""
        if self.format == "nexus":
            return self.path
        return self.path.with_name(f".{self.path.stem}.stream.h5")


def _size(n_bytes: float) -> str:
    return f"{n_bytes / 2**30:.2f} GB" if n_bytes >= 2**30 else f"{n_bytes / 2**20:.0f} MB"


def plan_job(*, kind: str, name: str, folder: Path, fmt: str, signals: tuple[str, ...],
             n_samples: int, start_sample: int, t0_s: float, fs_hz: float, source: str,
             overwrite: bool) -> JobPlan:
    """Check a job against the filesystem and the disk; the plan, or :class:`Refused`.

    Raises
    ------
    Refused
        ``FSM_Output``: the folder cannot be made or written, the file exists
        (and ``overwrite`` is false), a .mat job is larger than
        :data:`MAT_MAX_BYTES`, or the disk lacks room (with
        :data:`DISK_RESERVE_BYTES` kept free).
    """
    command = "Record" if kind == "record" else "RunExperiment"
    suffix = ".mat" if fmt == "mat" else ".h5"
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise Refused("FSM_Output", f"{command} refused: the output folder {folder} cannot be "
                                    f"created ({exc.strerror or exc})") from None
    if not folder.is_dir() or not os.access(folder, os.W_OK | os.X_OK):
        raise Refused("FSM_Output", f"{command} refused: the output folder {folder} is not a "
                                    "folder this server can write")
    path = folder / f"{name}{suffix}"
    try:
        name_max = os.pathconf(folder, "PC_NAME_MAX")
    except (OSError, ValueError):
        name_max = 255
    staging = len(f"..{name}.stream.h5.") + 16  # the writers' temporary names
    if max(len(path.name), staging) > name_max:
        raise Refused("FSM_Output", f"{command} refused: the name {name!r} is too long for "
                                    f"this filesystem ({name_max} bytes per file name)")
    if path.exists() and not overwrite:
        raise Refused("FSM_Output", f"{command} refused: {path} exists; fsmbench does not "
                                    "overwrite a file unless asked (\"overwrite\": true), move "
                                    "it or choose another name or OutputFolder")
    columns = len(signals) + 1
    data_bytes = n_samples * columns * 8
    if fmt == "mat" and data_bytes > MAT_MAX_BYTES:
        longest = MAT_MAX_BYTES / (columns * 8 * fs_hz)
        raise Refused("FSM_Output", f"{command} refused: a .mat file is built in memory at the "
                                    f"end; {_size(data_bytes)} for {n_samples / fs_hz:g} s of "
                                    f"{len(signals)} signals is more than "
                                    f"{_size(MAT_MAX_BYTES)} (at most {longest:.0f} s); ask "
                                    "\"format\": \"nexus\", streamed to disk")
    need = data_bytes * (2 if fmt == "mat" else 1) * 1.05  # HDF5 overhead: a few percent
    free = shutil.disk_usage(folder).free
    if need + DISK_RESERVE_BYTES > free:
        raise Refused("FSM_Output", f"{command} refused: {_size(need)} needed for "
                                    f"{n_samples / fs_hz:g} s of {len(signals)} signals, "
                                    f"{_size(free)} free in {folder} (keeping "
                                    f"{_size(DISK_RESERVE_BYTES)})")
    return JobPlan(kind=kind, name=name, path=path, format=fmt, signals=signals,
                   n_samples=n_samples, start_sample=start_sample, t0_s=t0_s, fs_hz=fs_hz,
                   source=source)


@dataclass(frozen=True)
class JobOutcome:
    """How a job ended.

    Attributes
    ----------
    plan : JobPlan
    n_samples : int
        Samples written.
    path : Path or None
        The file made (None: none).
    error : str
        Why it failed ("" when it did not).
    aborted : str
        What stopped it early ("" when it ran to its end).
    """

    plan: JobPlan
    n_samples: int
    path: Path | None
    error: str = ""
    aborted: str = ""

    @property
    def sentence(self) -> str:
        """The outcome in words."""
        p = self.plan
        what = f"{p.kind.capitalize()} {p.name}"
        seconds = f"{self.n_samples / p.fs_hz:.1f} of {p.duration_s:.1f} s"
        if self.error:
            kept = f" (the samples are kept in {self.path})" if self.path else ""
            return f"{what} failed after {seconds}: {self.error}{kept}."
        if self.aborted:
            if self.path is None:
                return f"{what} stopped by {self.aborted} before any sample: no file."
            return f"{what} stopped by {self.aborted} after {seconds}: kept in {self.path}."
        return f"Last file: {self.path}."


class JobWriter:
    """The writer thread of one job (see the module notes).

    Parameters
    ----------
    plan : JobPlan
    on_done : callable
        Called once, in the writer thread, with the :class:`JobOutcome`.
    thread_init : callable, optional
        Context manager factory entered in the thread (Tango's omni thread).
    """

    def __init__(self, plan: JobPlan, *, on_done: Callable[[JobOutcome], None],
                 thread_init: Callable[[], Any] | None = None) -> None:
        self.plan = plan
        self._on_done = on_done
        self._queue: queue.Queue[dict[str, np.ndarray]] = queue.Queue(QUEUE_BLOCKS)
        self._finished = threading.Event()
        self.taken = 0  # samples handed over by the loop
        # Wall clock [s since the epoch] of the first and the last hand-over: when the
        # samples were taken, to one loop block.
        self._first_put_s: float | None = None
        self._last_put_s: float | None = None
        #: Why the writer stopped early ("" while it writes): the loop ends the job on it.
        self.failed = ""
        self._aborted = ""
        self._error = ""
        self._thread = threading.Thread(target=self._run, args=(thread_init,),
                                        name=f"fsmbench-job-{plan.name}", daemon=True)
        self._thread.start()

    def put(self, samples: dict[str, np.ndarray]) -> bool:
        """Hand over samples (copies); False when the writer is too far behind."""
        try:
            self._queue.put_nowait(samples)
        except queue.Full:
            return False
        self.taken += len(next(iter(samples.values())))
        self._last_put_s = time.time()
        if self._first_put_s is None:
            self._first_put_s = self._last_put_s
        return True

    def finish(self, *, aborted: str = "", error: str = "") -> None:
        """No more samples: write the file (``aborted``/``error`` say why it ends early).

        Never blocks: the loop calls it.
        """
        self._aborted, self._error = aborted, error
        self._finished.set()

    def join(self, timeout_s: float | None = None) -> None:
        """Wait for the writer thread to end."""
        self._thread.join(timeout_s)

    def _run(self, thread_init: Callable[[], Any] | None) -> None:
        ctx = thread_init() if thread_init is not None else contextlib.nullcontext()
        with ctx:
            self._on_done(self._write())

    def _next(self) -> dict[str, np.ndarray] | None:
        """The next block, or None once the job is finished and every block written."""
        while True:
            try:
                return self._queue.get(timeout=0.05)
            except queue.Empty:
                if self._finished.is_set():
                    # Every put came before finish(): one last look, then done.
                    try:
                        return self._queue.get_nowait()
                    except queue.Empty:
                        return None

    def _batch(self, first: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """``first`` and the blocks queued behind it, up to :data:`BATCH_SAMPLES`, as one
        (an HDF5 append costs the same for 100 samples as for 65536)."""
        parts = [first]
        n = len(next(iter(first.values())))
        while n < BATCH_SAMPLES:
            try:
                block = self._queue.get_nowait()
            except queue.Empty:
                break
            parts.append(block)
            n += len(next(iter(block.values())))
        if len(parts) == 1:
            return first
        return {s: np.concatenate([p[s] for p in parts]) for s in first}

    def _write(self) -> JobOutcome:
        p = self.plan
        written = 0
        try:
            with NexusAppender(p.stream_path, signals=p.signals, fs_hz=p.fs_hz, t0_s=p.t0_s,
                               attrs={"experiment": p.name, "source": p.source},
                               bench=p.bench) as app:
                while (block := self._next()) is not None:
                    app.append(self._batch(block))
                    written = app.n_samples
                if written == 0:
                    # NexusAppender refuses an empty file; leave none, say so below.
                    raise _NoSamplesError
                # How it ended, in the file: a record cut short says so and by what.
                if self._first_put_s is not None and self._last_put_s is not None:
                    app.set_times(start=iso_time(self._first_put_s),
                                  end=iso_time(self._last_put_s))
                app.note(planned_duration_s=p.duration_s, recorded_duration_s=written / p.fs_hz,
                         ended=(f"stopped by {self._aborted}" if self._aborted else
                                f"ended early: {self._error}" if self._error else "complete"))
        except _NoSamplesError:
            return JobOutcome(p, 0, None, error=self._error, aborted=self._aborted)
        except Exception as exc:
            self.failed = _reason(exc)
            return JobOutcome(p, written, None, error=self.failed)
        if p.format == "mat":
            try:
                ds = read_recording(p.stream_path, require=())
                write_recording(ds, p.path, format="mat5")
            except Exception as exc:
                return JobOutcome(p, written, p.stream_path,
                                  error=f"the .mat file could not be written ({_reason(exc)})")
            with contextlib.suppress(OSError):
                p.stream_path.unlink()
        return JobOutcome(p, written, p.path, error=self._error, aborted=self._aborted)


class _NoSamplesError(Exception):
    pass


def _reason(exc: BaseException) -> str:
    if isinstance(exc, OSError) and exc.strerror:
        where = f"{exc.filename}: " if exc.filename else ""
        return f"{where}{exc.strerror}"
    return str(exc) or type(exc).__name__
