"""The live device watching its own loop: :class:`~fsmbench.tune.watch.LoopWatch` on the bench.

:class:`LiveWatch` feeds the running tracking error (the 4QD readings over the
calibrated gains, both axes) to a :class:`~fsmbench.tune.watch.LoopWatch` whose
prediction is the controller in the loop on the bench model
(:func:`fsmbench.control.validation.tracking_error_spectra`, the controller as the
bench runs it):

* the prediction is computed off the bench's loop (a thread, ~1 s) each time the
  loop closes or its controller changes; the watch then starts afresh (its
  baseline is taken again: each controller is judged against itself);
* only a *quiet* loop is judged: closed, no excitation, no experiment. Anything
  else drops the window being filled and waits ``settle_s`` of bench time after it
  ends (the notched resonance rings for ~0.75 s), so ``fsmbench tune``'s
  measurement never raises the warning it may be answering;
* the verdict is what the device shows: ``off`` (loop open), ``waiting``
  (prediction or settling), ``calibrating`` (the baseline windows), ``within the
  prediction`` or ``WARNING`` with the watch's cause sentence (which names the
  likely cause and suggests ``fsmbench tune``). The warning's hysteresis is the
  watch's own (windows to raise and to clear).

The device's state is ALARM while the warning stands and the loop runs
(:mod:`fsmbench.live.states`); commands are allowed as in RUNNING.
"""

from __future__ import annotations

import contextlib
import math
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import control as ct
import numpy as np

from fsmbench.bench.blocks import physical_plant
from fsmbench.bench.params import Bench
from fsmbench.control.validation import tracking_error_spectra
from fsmbench.sim.engine import DiscreteController
from fsmbench.tune.watch import LoopWatch, WatchEvent, WatchOptions

__all__ = ["LiveWatch", "WatchView", "prediction_of"]

#: Bench time the loop settles after a switch or an excitation before it is judged [s].
SETTLE_S = 5.0
#: Points of the prediction's grid up to Nyquist (0.1 Hz apart at 10 kHz: a 0.1 %-damped
#: resonance is ~0.5 Hz wide).
_N_FREQ = 50_000
_CHUNK = 1_000


@dataclass(frozen=True)
class WatchView:
    """What the device shows of the watch.

    Attributes
    ----------
    verdict : str
        ``off (loop open)``, ``waiting ...``, ``calibrating ...``, ``within the
        prediction`` or ``WARNING ...``, with bench times [s].
    cause : str
        The warning's cause and what to do ("" when there is no warning).
    departure_sigma : float
        Largest departure of the last judged window from the prediction, in units
        of its statistical scatter [1] (NaN before the first judged window).
    warning : bool
    """

    verdict: str
    cause: str
    departure_sigma: float
    warning: bool


def prediction_of(bench: Bench, controller: DiscreteController, *,
                  qd_gain_v_per_rad: tuple[float, float],
                  options: WatchOptions | None = None,
                  cancelled: Callable[[], bool] | None = None) -> LoopWatch | None:
    """A fresh :class:`LoopWatch` predicting ``controller`` as the bench runs it.

    ``controller`` reads the 4QD volts (its ``b``, ``d`` include the division by the
    gains it was loaded with) and its output is added to the DAC commands (the
    feedback sign included): ``K = -(c, d)`` from volts, so the prediction is made
    with unit "used gains" (:func:`~fsmbench.control.validation.tracking_error_spectra`
    multiplies by the plant's own 4QD gains). The measured error the watch is fed is
    the 4QD reading over ``qd_gain_v_per_rad``; the watch's baseline calibrates the
    ratio of the two. ``cancelled()`` is asked between chunks of the frequency grid:
    when it says so, None is returned (a new controller, or the bench stopping).
    """

    p = bench.true
    fs = p.converter.fs_hz
    k_volts = ct.ss(controller.a, controller.b, -np.asarray(controller.c),
                    -np.asarray(controller.d), 1.0 / fs)
    f = np.linspace(fs / 2 / _N_FREQ, fs / 2, _N_FREQ)
    plant = physical_plant(p, source="the device's bench model")
    # In chunks: the loop's responses over the whole grid at once are ~40 MB of temporaries
    # in the device's process (a Record's memory bound is 25 MB).
    total, spectra = [], None
    for part in np.array_split(f, _N_FREQ // _CHUNK):
        if cancelled is not None and cancelled():
            return None  # another controller took over, or the bench stopped
        spectra = tracking_error_spectra(plant, k_volts, params=p,
                                         gd_used_v_per_rad=(1.0, 1.0), f_hz=part)
        total.append(spectra.total)
    assert spectra is not None
    gd = p.quad_diode.gain_v_per_rad
    # The prediction is in the plant's radians; the device measures over its calibrated gains.
    ratio = np.array([(float(gd.h) / qd_gain_v_per_rad[0]) ** 2,
                      (float(gd.v) / qd_gain_v_per_rad[1]) ** 2])
    lines = {float(fl): np.asarray(spectra.line_power[i], dtype=float) * ratio
             for i, fl in enumerate(spectra.line_freqs_hz)}
    res = [float(p.sercalo.resonance_hz[a]) for a in ("h", "v")]
    return LoopWatch(f_hz=f, predicted_psd=np.vstack(total) * ratio[None, :], fs_hz=fs,
                     resonances_hz=res, line_power=lines, options=options or WatchOptions())


class LiveWatch:
    """The watch of one live bench (see the module notes).

    Parameters
    ----------
    bench : Bench
        The bench model the prediction is made on.
    qd_gain_v_per_rad : (float, float)
        The calibrated 4QD gains the measured error is computed with [V/rad].
    options : WatchOptions, optional
    log : callable, optional
        ``log(level, message)``.
    thread_init : callable, optional
        Context manager factory entered in the prediction's thread.
    """

    def __init__(self, bench: Bench, *, qd_gain_v_per_rad: tuple[float, float],
                 options: WatchOptions | None = None,
                 log: Callable[[str, str], None] | None = None,
                 thread_init: Callable[[], Any] | None = None) -> None:
        self.bench = bench
        self.gd = np.asarray(qd_gain_v_per_rad, dtype=float)
        self.options = options or WatchOptions()
        self._log = log or (lambda _level, _msg: None)
        self._thread_init = thread_init
        self._controller: DiscreteController | None = None
        self._watch: LoopWatch | None = None
        self._pending: DiscreteController | None = None  # prediction being computed
        self._generation = 0
        self._quiet_from_s = math.inf
        self._warning_since_s: float | None = None
        self._cause = ""
        self._last_z = math.nan
        self._error = ""
        self._lock = threading.Lock()
        self._threads: list[threading.Thread] = []

    # -- from the bench's loop -----------------------------------------------------

    def push(self, *, controller: DiscreteController | None, quiet: bool, vph: np.ndarray | None,
             vpv: np.ndarray | None, end_s: float) -> list[WatchEvent]:
        """One block of the bench (the loop's thread, outside the bench's lock).

        Parameters
        ----------
        controller : DiscreteController or None
            The controller in the loop (None: open).
        quiet : bool
            No excitation, no experiment.
        vph, vpv : ndarray (n,) or None
            The 4QD readings of the block [V].
        end_s : float
            Bench time at the end of the block [s].

        Returns
        -------
        list of WatchEvent
            The warnings raised and cleared by the windows this block completed.
        """
        with self._lock:
            if controller is not self._controller:
                self._restart(controller, end_s)
            watch = self._watch
            if controller is None or watch is None:
                return []
            if not quiet or vph is None or vpv is None:
                self._quiet_from_s = end_s + SETTLE_S
                watch.discard()
                return []
            n = vph.size
            start_s = end_s - n / watch.fs_hz
            if start_s < self._quiet_from_s - 1e-9:
                return []
            e = np.column_stack([vph, vpv]) / self.gd
            if not np.all(np.isfinite(e)):
                self._quiet_from_s = end_s + SETTLE_S
                watch.discard()
                return []
        events = watch.feed(e)  # only the loop's thread feeds: outside the small lock
        with self._lock:
            if watch is not self._watch:
                return []
            if len(watch.history) > watch.options.baseline_windows:  # judged, not calibrating
                self._last_z = max((c.z for c in watch.history[-1][1]), default=math.nan)
            for ev in events:
                if ev.level == "WARNING":
                    self._warning_since_s = end_s
                    self._cause = ev.cause
                else:
                    self._warning_since_s = None
                    self._cause = ""
        return events

    def _restart(self, controller: DiscreteController | None, now_s: float) -> None:
        """A new controller (or none): drop the watch, predict the new one off the loop."""
        self._controller = controller
        self._watch = None
        self._warning_since_s = None
        self._cause = ""
        self._last_z = math.nan
        self._error = ""
        self._generation += 1
        if controller is None:
            self._pending = None
            return
        self._pending = controller
        generation = self._generation

        def predict() -> None:
            ctx = self._thread_init() if self._thread_init is not None \
                else contextlib.nullcontext()
            with ctx:
                try:
                    watch: LoopWatch | None = prediction_of(
                        self.bench, controller,
                        qd_gain_v_per_rad=(float(self.gd[0]), float(self.gd[1])),
                        options=self.options,
                        cancelled=lambda: generation != self._generation)
                    error = ""
                except Exception as exc:  # a controller the model cannot predict: say so
                    watch, error = None, f"{type(exc).__name__}: {exc}"
                with self._lock:
                    if generation != self._generation:
                        return  # another controller took over meanwhile
                    self._pending = None
                    self._watch = watch
                    self._error = error
                if error:
                    self._log("WARNING", f"the loop's watch cannot predict {controller.name}: "
                                         f"{error}; not watched")

        self._quiet_from_s = now_s + SETTLE_S
        thread = threading.Thread(target=predict, name="fsmbench-watch", daemon=True)
        self._threads = [t for t in self._threads if t.is_alive()] + [thread]
        thread.start()

    def stop(self, *, timeout_s: float = 10.0) -> None:
        """Stop watching (the bench stops): a prediction being computed ends at its next
        chunk, and is waited for (at most ``timeout_s`` [s]) so that no thread of a stopped
        device goes on computing (or importing) beside what runs next in the process."""
        with self._lock:
            self._generation += 1
            self._controller = None
            self._watch = None
            threads, self._threads = self._threads, []
        for thread in threads:
            if thread is not threading.current_thread():
                thread.join(timeout_s)

    # -- views ---------------------------------------------------------------------

    @property
    def warning(self) -> bool:
        """The warning stands (the loop runs and departs from its prediction)."""
        return self._warning_since_s is not None

    def view(self, controller: DiscreteController | None) -> WatchView:
        """What the device shows now, ``controller`` in the loop (None: open).

        A controller the watch has not seen yet (the loop switched since the last
        block) is shown waiting for its prediction, never with the last one's verdict.
        """
        with self._lock:
            watch, ctrl = self._watch, self._controller
            if controller is None:
                return WatchView("off (loop open)", "", math.nan, False)
            if controller is not ctrl:
                return WatchView(f"waiting for the prediction of {controller.name}", "",
                                 math.nan, False)
            if ctrl is None:
                return WatchView("off (loop open)", "", math.nan, False)
            if self._error:
                return WatchView(f"off: {ctrl.name} cannot be predicted ({self._error})", "",
                                 math.nan, False)
            if watch is None:
                return WatchView(f"waiting for the prediction of {ctrl.name}", "", math.nan,
                                 False)
            if self._warning_since_s is not None:
                return WatchView(f"WARNING since bench time {self._warning_since_s:.1f} s",
                                 self._cause, self._last_z, True)
            opts = watch.options
            done = len(watch.history)
            if done < opts.baseline_windows:
                return WatchView(f"calibrating on the running loop: {done} of "
                                 f"{opts.baseline_windows} windows of {opts.window_s:g} s "
                                 "(quiet: no excitation, no experiment)", "", self._last_z,
                                 False)
            return WatchView("within the prediction", "", self._last_z, False)
