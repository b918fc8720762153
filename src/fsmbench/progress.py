"""One progress display for every command: stage lines, and bars with time left on long loops.

Every stage takes ``progress: Callable[[str], None]`` and calls it with one line
per step (:data:`Progress`). A loop that knows how far it is calls
:func:`advance` with the task, the work done and the total: on a
:class:`Reporter` (what the CLI gives) that is a tqdm bar with the rate and the
time left when stderr is a terminal, and a plain line at every tenth when it is
not (a log file gets no carriage returns); on any other callable, the same
plain lines. tqdm, not a hand-made meter: its rate smoothing, time-left
estimate and terminal handling are what a hand-made one gets wrong.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import IO, Any

from tqdm import tqdm

__all__ = ["Progress", "Reporter", "advance"]

Progress = Callable[[str], None]


def _amount(x: float, unit: str) -> str:
    return f"{x:.3g} {unit}".strip()


class Reporter:
    """The CLI's progress: ``reporter(msg)`` for a stage line, ``advance`` for a loop.

    Parameters
    ----------
    stream : file, optional
        Where it writes (default stderr).
    rewrite : callable, optional
        Applied to every message (the CLI replaces a run's hidden staging folder by
        the folder the files will be in).
    """

    def __init__(self, *, stream: IO[str] | None = None,
                 rewrite: Callable[[str], str] | None = None) -> None:
        self._stream = sys.stderr if stream is None else stream
        self._rewrite = rewrite or (lambda s: s)
        self._start = time.perf_counter()
        self._tty = bool(getattr(self._stream, "isatty", lambda: False)())
        self._bars: dict[str, Any] = {}
        self._tenths: dict[str, int] = {}

    def __call__(self, msg: str) -> None:
        line = f"[{time.perf_counter() - self._start:6.1f} s] {self._rewrite(msg)}"
        if self._tty and self._bars:
            tqdm.write(line, file=self._stream)
        else:
            print(line, file=self._stream, flush=True)

    @property
    def interactive(self) -> bool:
        """Whether it draws bars (a terminal) rather than plain lines (a log)."""
        return self._tty

    def advance(self, task: str, done: float, total: float, unit: str = "",
                line: str = "") -> None:
        """``task`` has done ``done`` of ``total`` (in ``unit``); closes at the total.

        ``line``: what a log gets for this step instead of the line at each tenth.
        """
        task = self._rewrite(task)
        if not self._tty:
            if line:
                self(line)
            else:
                _tenth_line(self, self._tenths, task, done, total, unit)
            return

        bar = self._bars.get(task)
        if bar is None:
            bar = tqdm(total=total, desc=task, unit=unit or "it", file=self._stream,
                       leave=False, dynamic_ncols=True, unit_scale=True)
            self._bars[task] = bar
        bar.update(max(0.0, done - bar.n))
        if done >= total:
            bar.close()
            del self._bars[task]
            self(f"{task}: done ({_amount(total, unit)})")


def _tenth_line(say: Progress, tenths: dict[str, int], task: str, done: float, total: float,
                unit: str) -> None:
    """One plain line at each tenth of the task (what a log gets)."""
    tenth = int(10 * done / total) if total > 0 else 10
    if tenth > tenths.get(task, 0):
        tenths[task] = tenth
        say(f"{task}: {100 * done / total:.0f} % ({_amount(done, unit)} of "
            f"{_amount(total, unit)})")
    if done >= total:
        tenths.pop(task, None)


_PLAIN_TENTHS: dict[int, dict[str, int]] = {}


def advance(progress: Progress | None, task: str, done: float, total: float,
            unit: str = "", line: str = "") -> None:
    """Report a loop's progress through ``progress`` (see the module notes); None: nothing.

    ``line``: the plain line a log gets for this step (default: one at each tenth).
    """
    if progress is None:
        return
    if isinstance(progress, Reporter):
        progress.advance(task, done, total, unit, line)
        return
    if line:
        progress(line)
        return
    _tenth_line(progress, _PLAIN_TENTHS.setdefault(id(progress), {}), task, done, total, unit)
