"""One computation run beside the caller's, in a forked process: the study's stages side by side.

Two stages of the study that do not need each other's results (the design, and the
budget of the records) each keep one core busy when one of them runs in a forked
child. A process, not a thread: the stages are NumPy, SciPy and python-control code
that holds the GIL for much of its time, and Python's warnings machinery (which the
stages use to collect numeric notices) is process-wide state that threads would
share.

The child is a fork of the caller, so it reads the caller's objects as they are (the
recordings are not copied or pickled); only its result comes back, pickled. What the
child says on ``progress`` reaches the caller's ``progress`` as it is said (a thread
forwards it); the warnings it raises are raised again in the caller when the result is
taken, so the caller's filters and ``catch_warnings`` blocks see them as if the
computation had run there; an exception it raises is raised again in the caller.

Where ``fork`` is not available, on one core, off the main thread, in a pool's
worker, or with ``parallel`` False, the computation runs in the caller when its result
is taken: the same result, in the order of a serial run.
"""

from __future__ import annotations

import copyreg
import importlib
import io
import mmap
import multiprocessing as mp
import os
import pickle
import secrets
import sys
import threading
import time
import traceback
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any, Generic, TypeVar

from fsmbench.progress import Progress

__all__ = ["ForkedCall", "ForkedError", "ForkedSeries", "child_share", "fork_available",
           "start_forked", "start_forked_series"]

T = TypeVar("T")
K = TypeVar("K")


class ForkedError(RuntimeError):
    """The child failed with an exception that could not be sent back as itself."""


def fork_available() -> bool:
    """Whether a computation can run beside the caller: ``fork`` exists, there are two
    cores or more, and the caller is the main thread of a process that is not a pool's
    worker."""
    # A daemonic process (a worker of a pool) may not have children. Off the main thread
    # (a Tango command, a Dask task, the live device's jobs) the process is a server
    # whose other threads may hold locks at the fork: the work stays in the caller.
    return ("fork" in mp.get_all_start_methods() and (os.cpu_count() or 1) > 1
            and not mp.current_process().daemon
            and threading.current_thread() is threading.main_thread())


def _state_space(a: Any, b: Any, c: Any, d: Any, dt: Any, inputs: list[str],
                 outputs: list[str], states: list[str], name: str) -> Any:
    # python-control is loaded by whoever made the system; here only when one comes back
    # (a core module: the command line's parser imports it and must not load python-control).
    ct = sys.modules.get("control") or importlib.import_module("control")
    return ct.ss(a, b, c, d, dt, inputs=inputs, outputs=outputs, states=states, name=name)


def _reduce_state_space(sys_: Any) -> tuple[Any, tuple[Any, ...]]:
    # python-control's StateSpace holds two lambdas (its update and output functions):
    # it is rebuilt from its matrices, time step and labels, which is all it is.
    return _state_space, (sys_.A, sys_.B, sys_.C, sys_.D, sys_.dt, list(sys_.input_labels),
                          list(sys_.output_labels), list(sys_.state_labels), sys_.name)


def _dispatch_table() -> dict[type, Any]:
    """copyreg's table, with python-control's StateSpace when it is loaded (without it no
    system exists to send)."""
    table: dict[type, Any] = dict(copyreg.dispatch_table)
    ct = sys.modules.get("control")
    if ct is not None:
        table[ct.StateSpace] = _reduce_state_space
    return table


#: Arrays at least this large [bytes] travel beside the pickle, through shared memory.
OUT_OF_BAND_BYTES = 1 << 20
#: Where they are put: a RAM file system, so a record's samples cross without a disk.
_SHM = Path("/dev/shm")


def _dumps(value: Any, out_of_band: list[pickle.PickleBuffer] | None = None) -> bytes:
    buffer = io.BytesIO()

    def in_band(pb: pickle.PickleBuffer) -> bool:
        if out_of_band is None or pb.raw().nbytes < OUT_OF_BAND_BYTES:
            return True
        out_of_band.append(pb)
        return False

    pickler = pickle.Pickler(buffer, protocol=pickle.HIGHEST_PROTOCOL,
                             buffer_callback=in_band)
    # A dispatch table of this pickler only: no process-wide registration.
    pickler.dispatch_table = _dispatch_table()
    pickler.dump(value)
    return buffer.getvalue()


def _stash_path(token: str) -> Path:
    return _SHM / f"fsmbench-forked-{token}.bin"


def _stash(buffers: list[pickle.PickleBuffer], *,
           token: str) -> tuple[str, list[tuple[int, int]]] | None:
    """The large buffers written one after the other to a file in shared memory (its path
    and each one's offset and length), or None where there is no room (they go in-band)."""
    total = sum(b.raw().nbytes for b in buffers)
    path = _stash_path(token)
    try:
        room = os.statvfs(_SHM)
        if room.f_bavail * room.f_frsize < 2 * total:
            return None
        spans = []
        with open(path, "wb") as f:
            for b in buffers:
                raw = b.raw()
                spans.append((f.tell(), raw.nbytes))
                f.write(raw)
    except OSError:
        path.unlink(missing_ok=True)
        return None
    return str(path), spans


def _unstash(where: tuple[str, list[tuple[int, int]]]) -> list[memoryview]:
    """The buffers of :func:`_stash`, mapped copy-on-write (writable, nothing copied); the
    file is removed at once, its pages live as long as the arrays on them."""
    path, spans = where
    try:
        with open(path, "rb") as f:  # never empty: it holds buffers of a MB or more
            view = memoryview(mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_COPY))
    finally:
        Path(path).unlink(missing_ok=True)
    return [view[o:o + n] for o, n in spans]


@dataclass(frozen=True)
class _Caught:
    """A warning raised in the child, to be raised again in the caller."""

    message: str
    category: type[Warning]
    filename: str
    lineno: int

    def raise_again(self) -> None:
        """Raised in the caller as at its place in the code: the module it came from is
        found by its file, so that filters by module and "once per place" apply."""
        module = next((m for m in list(sys.modules.values())
                       if getattr(m, "__file__", None) == self.filename), None)
        registry = (None if module is None
                    else module.__dict__.setdefault("__warningregistry__", {}))
        warnings.warn_explicit(self.message, self.category, self.filename, self.lineno,
                               module=None if module is None else module.__name__,
                               registry=registry)


def _sendable_error(exc: BaseException) -> BaseException:
    try:
        pickle.loads(_dumps(exc))
    except Exception:  # any failure to travel: sent as text
        text = "".join(traceback.format_exception(exc))
        return ForkedError(f"{type(exc).__name__}: {exc}\n{text}")
    return exc


def _run_one(fn: Callable[[Progress], Any], say: Progress) -> tuple[Any, ...]:
    """``fn``'s outcome: (kind, value or error, warnings, its wall time [s])."""
    start = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")  # every one goes back; the caller's filters decide
        try:
            value: Any = ("result", fn(say))
        except BaseException as exc:  # Ctrl-C included: the caller decides
            value = ("error", _sendable_error(exc))
    found = [_Caught(str(w.message), w.category, w.filename, w.lineno) for w in caught]
    return (*value, found, time.perf_counter() - start)


def _send_outcome(conn: Connection, outcome: tuple[Any, ...], *, token: str) -> bool:
    """Send ``outcome`` (:func:`_run_one`'s); True when what was sent is an error (the
    computation's own, or a value that could not travel)."""
    failed = outcome[0] == "error"
    where = None
    try:
        # Large arrays (a record's samples) beside the pickle, in shared memory: a pipe
        # moved 150 MB of records in 0.35 s, the mapped file in a tenth of it.
        large: list[pickle.PickleBuffer] = []
        payload = _dumps(outcome, large)
        where = _stash(large, token=token) if large else None
        if large and where is None:
            payload = _dumps(outcome)
    except Exception as exc:  # a result that cannot travel is an error
        payload = _dumps(("error", ForkedError(f"the result could not be sent back: {exc}"),
                          outcome[2], outcome[3]))
        failed = True
    conn.send_bytes(_dumps(("outcome", where)))
    conn.send_bytes(payload)
    return failed


def _child(fns: Sequence[Callable[[Progress], Any]], conn: Connection, token: str) -> None:
    def say(msg: str) -> None:
        conn.send_bytes(_dumps(("progress", msg)))

    # One after the other, each outcome sent as soon as it is known: the caller takes a
    # value while the next computation runs. After a failure the rest are not run (as in
    # the caller, where the exception would have stopped them).
    for index, fn in enumerate(fns):
        if _send_outcome(conn, _run_one(fn, say), token=f"{token}-{index}"):
            break
    conn.close()


class ForkedSeries:
    """Computations started by :func:`start_forked_series`, run one after the other in one
    child; :meth:`result` waits for one of them.

    ``seconds[i]`` is computation ``i``'s own wall time [s] once its result is taken.
    """

    def __init__(self, fns: Sequence[Callable[[Progress], Any]], *, progress: Progress,
                 parallel: bool) -> None:
        self._fns = list(fns)
        self._progress = progress
        self.seconds = [0.0] * len(self._fns)
        self._taken = [False] * len(self._fns)
        self._outcomes: list[tuple[Any, ...] | None] = [None] * len(self._fns)
        self._ended = False  # the child's pipe closed: no more outcomes
        self._arrived = threading.Condition()
        self._proc: Any = None
        if not (parallel and fork_available()) or not self._fns:
            return
        ctx = mp.get_context("fork")
        recv, send = ctx.Pipe(duplex=False)
        # The shared-memory files' own names: a process id can be another process's by
        # the time the caller cleans up after a child it stopped.
        self._token = f"{os.getpid()}-{secrets.token_hex(8)}"
        self._proc = ctx.Process(target=_child, args=(self._fns, send, self._token),
                                 daemon=True, name="fsmbench-stage")
        self._proc.start()
        send.close()
        self._reader = threading.Thread(target=self._read, args=(recv,), daemon=True,
                                        name="fsmbench-stage-reader")
        self._reader.start()

    def _read(self, conn: Connection) -> None:
        # Progress lines as they come; each outcome in the order of the computations.
        index = 0
        try:
            while index < len(self._fns):
                message = pickle.loads(conn.recv_bytes())
                if message[0] == "progress":
                    self._progress(message[1])
                    continue
                payload = conn.recv_bytes()
                buffers = None if message[1] is None else _unstash(message[1])
                outcome = pickle.loads(payload, buffers=buffers)
                with self._arrived:
                    self._outcomes[index] = outcome
                    self._arrived.notify_all()
                index += 1
        except EOFError:  # the child died without an outcome (killed), or after a failure
            pass
        finally:
            conn.close()
            with self._arrived:
                self._ended = True
                self._arrived.notify_all()

    def _run_here(self, index: int) -> Any:
        # In the caller: every computation before ``index`` not run yet runs first, in order,
        # and keeps its value (or error) for its own result.
        for k in range(index + 1):
            outcome = self._outcomes[k]
            if outcome is None:
                start = time.perf_counter()
                try:
                    outcome = ("result", self._fns[k](self._progress))
                except Exception as exc:
                    outcome = ("error", exc)
                self._outcomes[k] = outcome
                self.seconds[k] = time.perf_counter() - start
            if outcome[0] == "error" and k < index:
                raise ForkedError(f"computation {index} was not run: computation {k} "
                                  "before it failed") from outcome[1]
        assert outcome is not None  # the loop ran at least once: k = index
        kind, value = outcome[:2]
        if kind == "error":
            raise value
        return value

    def result(self, index: int) -> Any:
        """Computation ``index``'s value (its warnings raised here first); its exception if
        it failed. Where it ran in the caller, it runs now (with those before it)."""
        if self._taken[index]:
            raise RuntimeError("the result was already taken")
        self._taken[index] = True
        if self._proc is None:
            return self._run_here(index)
        with self._arrived:
            self._arrived.wait_for(lambda: self._outcomes[index] is not None or self._ended)
            outcome = self._outcomes[index]
        if outcome is None:
            self.cancel()
            earlier = next((k for k, o in enumerate(self._outcomes[:index])
                            if o is not None and o[0] == "error"), None)
            raise ForkedError(f"the stage's process ended with status {self._proc.exitcode} "
                              "and no result" if earlier is None else
                              f"computation {index} was not run: computation {earlier} "
                              "before it failed")
        if all(self._taken) or outcome[0] == "error":
            self.cancel()
        kind, value, caught, self.seconds[index] = outcome
        for w in caught:
            w.raise_again()
        if kind == "error":
            raise value
        return value

    @property
    def forked(self) -> bool:
        """Whether the computations run in a child (False: in the caller, at :meth:`result`)."""
        return self._proc is not None

    def cancel(self) -> None:
        """Stop the child if it still runs (the caller failed or was interrupted), or wait
        for it to end once every result is in."""
        if self._proc is None:
            return
        if self._proc.is_alive() and not all(o is not None for o in self._outcomes):
            self._proc.terminate()
        self._proc.join()
        self._reader.join()
        for index in range(len(self._fns)):  # a child stopped between its stash and its message
            _stash_path(f"{self._token}-{index}").unlink(missing_ok=True)


class ForkedCall(Generic[T]):
    """A computation started by :func:`start_forked`; :meth:`result` waits for it.

    ``seconds`` is the computation's own wall time [s] once the result is taken.
    """

    def __init__(self, fn: Callable[[Progress], T], *, progress: Progress,
                 parallel: bool) -> None:
        self._series = ForkedSeries([fn], progress=progress, parallel=parallel)

    def result(self) -> T:
        """The computation's value (its warnings raised here first); its exception if it
        failed."""
        value: T = self._series.result(0)
        return value

    @property
    def seconds(self) -> float:
        """The computation's own wall time [s] (0 before its result is taken)."""
        return self._series.seconds[0]

    @property
    def forked(self) -> bool:
        """Whether the computation runs in a child (False: in the caller, at :meth:`result`)."""
        return self._series.forked

    def cancel(self) -> None:
        """Stop the child if it still runs (the caller failed or was interrupted)."""
        self._series.cancel()


def child_share(costs: Mapping[K, float]) -> set[K]:
    """The items a forked child takes so that it and the caller carry about half the cost
    each: largest first, each to the lighter side, the caller's on a tie (equal costs
    alternate, the caller first)."""
    here, there, share = 0.0, 0.0, set()
    for key in sorted(costs, key=lambda k: -costs[k]):
        if there < here:
            share.add(key)
            there += costs[key]
        else:
            here += costs[key]
    return share


def start_forked(fn: Callable[[Progress], T], *, progress: Progress,
                 parallel: bool = True) -> ForkedCall[T]:
    """Start ``fn(progress)`` in a forked child and return at once.

    Parameters
    ----------
    fn : callable
        The computation; it receives a progress callable to speak through. Its
        value must pickle (python-control state-space systems do here).
    progress : callable
        Receives ``fn``'s progress lines, from a reader thread, as they are said.
    parallel : bool
        False runs ``fn`` in the caller when the result is taken (also without
        ``fork`` or on one core).

    Returns
    -------
    ForkedCall
        ``.result()`` waits for the value; ``.cancel()`` stops the child. Use it in a
        ``try``/``finally`` that cancels, so that a failure of the caller stops the child.
    """
    return ForkedCall(fn, progress=progress, parallel=parallel)


def start_forked_series(fns: Sequence[Callable[[Progress], Any]], *, progress: Progress,
                        parallel: bool = True) -> ForkedSeries:
    """Start the computations ``fns`` one after the other in one forked child, and return
    at once.

    One child for dependent work beside the caller's: the caller takes the first value
    as soon as it is computed, while the child goes on with the next (one process
    beside the caller's, where a child per computation would crowd two cores).

    Parameters
    ----------
    fns : sequence of callables
        The computations, each as for :func:`start_forked`; after one fails the rest
        are not run.
    progress : callable
        Receives their progress lines, from a reader thread, as they are said.
    parallel : bool
        False runs them in the caller, in order, as their results are taken.

    Returns
    -------
    ForkedSeries
        ``.result(i)`` waits for computation ``i``; ``.cancel()`` stops the child. Use it
        in a ``try``/``finally`` that cancels.
    """
    return ForkedSeries(fns, progress=progress, parallel=parallel)
