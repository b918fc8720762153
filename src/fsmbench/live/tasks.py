"""Work that runs off the client's call: designing an excitation.

A :class:`Task` runs one function in its own thread and shows its progress
(0 to 1) and what it does; ``Abort`` cancels it at its next progress step.
The client's command returns at once (a full-band multisine once held the
call ~5 s, timed clients out and stalled every other client of the device).

:func:`design_multisine` is the live device's multisine: equal lines every
``1/period_s`` in the band, Schroeder's phases, then clipping iterations
that lower the crest factor (a lower peak for the same rms), one period
played again and again.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable
from typing import Any

import numpy as np

from fsmbench.excite.design import crest_factor, multisine_period, schroeder_phases
from fsmbench.sim.excitation import Excitation, SampledExcitation

__all__ = ["CLIP_ITERATIONS", "Cancelled", "Task", "TaskControl", "design_multisine"]

#: Clipping iterations of the multisine design (each: two FFTs of one period).
CLIP_ITERATIONS = 60


class Cancelled(Exception):  # noqa: N818
    """The task was aborted."""


class TaskControl:
    """What a task's function sees: report progress, stop when cancelled."""

    def __init__(self) -> None:
        self.fraction = 0.0
        self._cancel = threading.Event()

    def progress(self, fraction: float) -> None:
        """Report progress (0 to 1); raises :class:`Cancelled` once the task is aborted."""
        self.fraction = min(1.0, max(self.fraction, float(fraction)))
        if self._cancel.is_set():
            raise Cancelled

    def cancel(self) -> None:
        """Ask the task to stop at its next progress report."""
        self._cancel.set()

    @property
    def cancelled(self) -> bool:
        """Abort was asked."""
        return self._cancel.is_set()


class Task:
    """One piece of work in its own thread.

    Parameters
    ----------
    what : str
        In words, for ``Status`` and the ``Task`` attribute.
    work : callable
        ``work(control) -> result``; calls ``control.progress`` now and then.
    on_done : callable
        Called in the task's thread with the task when it ends (``result``,
        ``error`` or ``cancelled`` set).
    thread_init : callable, optional
        Context manager factory entered in the thread (Tango's omni thread).
    """

    def __init__(self, what: str, work: Callable[[TaskControl], Any], *,
                 on_done: Callable[[Task], None],
                 thread_init: Callable[[], Any] | None = None) -> None:
        self.what = what
        self.control = TaskControl()
        self.result: Any = None
        self.error = ""
        self.done = False
        self._work = work
        self._on_done = on_done
        self._thread = threading.Thread(target=self._run, args=(thread_init,),
                                        name="fsmbench-task", daemon=True)
        self._thread.start()

    @property
    def progress(self) -> float:
        """Fraction done, 0 to 1."""
        return 1.0 if self.done else self.control.fraction

    @property
    def cancelled(self) -> bool:
        """Abort was asked."""
        return self.control.cancelled

    def cancel(self) -> None:
        """Stop at the next progress step (the result is then dropped)."""
        self.control.cancel()

    def join(self, timeout_s: float | None = None) -> None:
        """Wait for the thread."""
        self._thread.join(timeout_s)

    def _run(self, thread_init: Callable[[], Any] | None) -> None:
        ctx = thread_init() if thread_init is not None else contextlib.nullcontext()
        with ctx:
            try:
                self.result = self._work(self.control)
            except Cancelled:
                pass
            except Exception as exc:
                self.error = str(exc) or type(exc).__name__
            self.done = True
            self._on_done(self)


def design_multisine(ex: Excitation, *, fs_hz: float, half_range_v: float,
                     control: TaskControl) -> tuple[SampledExcitation, float]:
    """The multisine ``ex`` asks for, with a lowered crest factor (see the module notes).

    Parameters
    ----------
    ex : Excitation
        Kind ``multisine``: ``amplitude_v`` rms [V], ``band_hz`` (default:
        ``1/period_s`` to Nyquist), ``period_s`` [s], ``start_s`` (replaced by
        the caller when the design is done).
    fs_hz : float
        Bench sampling rate [Hz].
    half_range_v : float
        The DAC's half range [V]: a design that peaks beyond it is refused.
    control : TaskControl

    Returns
    -------
    (SampledExcitation, float)
        One period played for ever (``loop_from=0``), and its crest factor [1].

    Raises
    ------
    ValueError
        The lowest peak found still exceeds the DAC's range (the sentence gives
        the largest rms that fits).
    """
    n = round(ex.period_s * fs_hz)
    lo, hi = ex.band_hz if ex.band_hz is not None else (0.0, fs_hz / 2)
    k = np.arange(max(1, int(np.ceil(lo * ex.period_s - 1e-9))),
                  int(np.floor(hi * ex.period_s + 1e-9)) + 1)
    k = k[k < n / 2]  # strictly below Nyquist
    a = ex.amplitude_v * np.sqrt(2.0 / k.size)  # equal lines of total rms amplitude_v
    phases = schroeder_phases(k.size)
    best, best_cf = phases, np.inf
    for i, step in enumerate(np.geomspace(0.1, 0.01, CLIP_ITERATIONS if k.size > 1 else 1)):
        control.progress(i / CLIP_ITERATIONS)
        x = multisine_period(harmonics=k, phases_rad=phases, n_samples=n, amplitude_v=1.0)
        c = crest_factor(x)
        if c < best_cf:
            best, best_cf = phases, c
        level = (1.0 - step) * np.max(np.abs(x))
        phases = np.angle(np.fft.rfft(np.clip(x, -level, level))[k])
    period = multisine_period(harmonics=k, phases_rad=best, n_samples=n, amplitude_v=float(a))
    peak = float(np.max(np.abs(period)))
    if peak > half_range_v:
        fits = ex.amplitude_v * half_range_v / peak
        raise ValueError(f"the multisine of {ex.amplitude_v:g} V rms on {ex.channel} peaks at "
                         f"{peak:.3g} V (crest factor {best_cf:.2f}), beyond the DAC's "
                         f"+/-{half_range_v:g} V; at most {fits:.3g} V rms fits")
    control.progress(1.0)
    sampled = SampledExcitation(channel=ex.channel, kind="samples", amplitude_v=ex.amplitude_v,
                                start_s=ex.start_s, samples_v=period, loop_from=0)
    return sampled, float(best_cf)
