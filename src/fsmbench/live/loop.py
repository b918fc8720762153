"""The bench loop's thread, paced to the wall clock, and the watchdog that watches it.

:class:`PacedLoop` calls ``step()`` (one block of the bench) again and again,
sleeping so that bench time runs ``speed`` times the wall clock. It sleeps in
short slices, so a new speed acts at once (a ``SpeedFactor`` of 1e-6 once
put the loop to sleep for ~10^4 s). Each step is a heartbeat.

The loop measures the speed it reaches (:attr:`PacedLoop.reached_speed`): bench
time over wall clock across the last :data:`REACHED_WINDOW_S`; a busy machine
runs slower than asked, and a client must be able to see it.

The watchdog is a second thread: when no heartbeat came for
:meth:`PacedLoop.stall_limit_s` of wall clock, or the loop thread died, it
reports it once (``on_stall``, ``on_death``); the bench then says FAULT with
the reason, never ON or RUNNING.
"""

from __future__ import annotations

import contextlib
import math
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any

__all__ = ["PacedLoop"]

#: Longest single sleep of the loop [s]: how fast a new speed or a stop acts.
_SLICE_S = 0.05
#: Pause after a block when the loop is behind [s] (hands the lock to waiting readers).
_YIELD_S = 0.001
#: How often the watchdog looks [s].
_WATCH_S = 0.1
#: Wall clock over which the speed reached is measured [s] (blocks of 10 ms of bench time
#: at 1x come 100 a second: a few hundred pairs).
REACHED_WINDOW_S = 2.0


class PacedLoop:
    """A paced loop thread with a heartbeat and a watchdog (see the module notes).

    Parameters
    ----------
    step : callable
        Runs one block; returns the bench time after it [s].
    speed : callable
        Bench seconds per wall-clock second, read before every sleep.
    block_s : callable
        Bench time of the next block [s] (the stall limit grows with it at low speeds).
    watchdog_s : float
        Wall-clock time without a heartbeat that counts as a stall [s] (at least).
    on_stall : callable
        ``on_stall(lag_s)`` once per stall, from the watchdog thread.
    on_death : callable
        ``on_death(exc)`` when ``step`` raised, from the loop thread.
    thread_init : callable, optional
        Context manager factory entered in both threads (Tango's omni thread).
    """

    def __init__(self, *, step: Callable[[], float], speed: Callable[[], float],
                 block_s: Callable[[], float], watchdog_s: float,
                 on_stall: Callable[[float], None], on_death: Callable[[BaseException], None],
                 thread_init: Callable[[], Any] | None = None) -> None:
        self._step = step
        self._speed = speed
        self._block_s = block_s
        self.watchdog_s = float(watchdog_s)
        self._on_stall = on_stall
        self._on_death = on_death
        self._thread_init = thread_init
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._watchdog: threading.Thread | None = None
        self.heartbeat = 0
        self.last_beat = time.monotonic()
        self.error: BaseException | None = None
        self._stalled = False
        self._paces: deque[tuple[float, float]] = deque()  # (wall, bench) since the speed

    # -- views ---------------------------------------------------------------------

    @property
    def reached_speed(self) -> float:
        """Bench seconds per wall-clock second over the last :data:`REACHED_WINDOW_S` (NaN
        until half of it has run at the present speed)."""
        try:  # the window's two ends (a deque's ends are O(1); a reset may empty it)
            (wall0, bench0), (wall1, bench1) = self._paces[0], self._paces[-1]
        except IndexError:
            return math.nan
        if wall1 - wall0 < 0.5 * REACHED_WINDOW_S:
            return math.nan
        return (bench1 - bench0) / (wall1 - wall0)

    def _paced(self, wall: float, bench: float, *, reset: bool) -> None:
        if reset:
            self._paces.clear()
        self._paces.append((wall, bench))
        while self._paces and wall - self._paces[0][0] > REACHED_WINDOW_S:
            self._paces.popleft()

    @property
    def running(self) -> bool:
        """The loop thread is alive."""
        return self._thread is not None and self._thread.is_alive()

    @property
    def dead(self) -> bool:
        """The loop thread ended on an error (``error``)."""
        return self.error is not None

    @property
    def started(self) -> bool:
        """:meth:`start` was called (and not :meth:`stop`)."""
        return self._thread is not None and not self._stop.is_set()

    @property
    def lag_s(self) -> float:
        """Wall-clock time since the last heartbeat [s]."""
        return time.monotonic() - self.last_beat

    def stall_limit_s(self) -> float:
        """Lag that counts as a stall [s]: ``watchdog_s``, or 4 blocks at a low speed."""
        return max(self.watchdog_s, 4.0 * self._block_s() / self._speed())

    @property
    def stalled(self) -> bool:
        """Started, and no heartbeat for longer than the stall limit (or the thread died)."""
        if not self.started:
            return False
        return self.dead or not self.running or self.lag_s > self.stall_limit_s()

    # -- life cycle ----------------------------------------------------------------

    def beat(self) -> None:
        """One heartbeat (the bench calls it after every block, threads or not)."""
        self.heartbeat += 1
        self.last_beat = time.monotonic()
        self._stalled = False

    def start(self) -> None:
        """Start (or restart, after a death) the loop thread and the watchdog."""
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(5.0)  # a dying thread may still be reporting its death
        self._stop.clear()
        self.error = None
        self.last_beat = time.monotonic()
        self._stalled = False
        self._thread = threading.Thread(target=self._run, name="fsmbench-live", daemon=True)
        self._thread.start()
        if self._watchdog is None or not self._watchdog.is_alive():
            self._watchdog = threading.Thread(target=self._watch, name="fsmbench-watchdog",
                                              daemon=True)
            self._watchdog.start()

    def stop(self, timeout_s: float = 10.0) -> None:
        """Stop both threads (waits up to ``timeout_s`` each)."""
        self._stop.set()
        for thread in (self._thread, self._watchdog):
            if thread is not None and thread is not threading.current_thread():
                thread.join(timeout_s)

    def _context(self) -> Any:
        return self._thread_init() if self._thread_init is not None \
            else contextlib.nullcontext()

    def _run(self) -> None:
        with self._context():
            wall0, bench0, speed = time.monotonic(), None, self._speed()
            try:
                while not self._stop.is_set():
                    now_bench = self._step()  # beats (the bench calls beat())
                    if bench0 is None or self._speed() != speed:
                        speed = self._speed()
                        wall0, bench0 = time.monotonic(), now_bench
                        self._paced(wall0, now_bench, reset=True)
                        continue
                    self._paced(time.monotonic(), now_bench, reset=False)
                    ahead = wall0 + (now_bench - bench0) / speed - time.monotonic()
                    while ahead > 0 and not self._stop.is_set() and self._speed() == speed:
                        self._stop.wait(min(ahead, _SLICE_S))
                        ahead = wall0 + (now_bench - bench0) / speed - time.monotonic()
                    if ahead <= 0:
                        # Behind: no sleep above, so let the threads waiting for the bench's
                        # lock (clients' reads) in; a lock is not fair, a sleep hands it over.
                        time.sleep(_YIELD_S)
                    if ahead < -1.0:
                        # Slower than asked (a loaded machine): do not try to catch up.
                        wall0, bench0 = time.monotonic(), now_bench
            except BaseException as exc:
                self.error = exc
                self._on_death(exc)

    def _watch(self) -> None:
        with self._context():
            while not self._stop.wait(_WATCH_S):
                if not self.running:
                    continue  # a death is reported by the loop thread itself
                lag = self.lag_s
                if lag > self.stall_limit_s() and not self._stalled:
                    self._stalled = True
                    self._on_stall(lag)
