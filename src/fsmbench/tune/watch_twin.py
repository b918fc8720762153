"""The watch on the twin: a loop running while its Sercalo resonance drifts.

:func:`watch_twin` runs the twin with a controller loaded, moves the Sercalo's
resonance (both axes) linearly in time, ``drift_pct_per_h`` per hour, updating
the plant every ``update_s`` (:meth:`fsmbench.sim.stream.BenchStream.set_plant`,
the state carried over), and feeds the tracking error to a
:class:`~fsmbench.tune.watch.LoopWatch` whose prediction is the loaded
controller's on the bench *before* the drift (the model the controller was
tuned on, with the twin's noise), calibrated on the first windows before the
drift starts (as right after a ``tune``): what ``--drift-resonance PCT/h`` does.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from fsmbench.bench.blocks import physical_plant
from fsmbench.bench.params import Bench
from fsmbench.control.controller import Controller
from fsmbench.control.validation import tracking_error_spectra
from fsmbench.sim.plant import ADC_CHANNELS, bench_discrete
from fsmbench.sim.stream import BenchStream
from fsmbench.tune.watch import LoopWatch, WatchEvent, WatchOptions
from fsmbench.twin.closed_loop import drifted_bench

__all__ = ["WatchRun", "watch_twin"]

_QD = (ADC_CHANNELS.index("Vph"), ADC_CHANNELS.index("Vpv"))


@dataclass(frozen=True, eq=False)
class WatchRun:
    """What the watch saw.

    Attributes
    ----------
    events : tuple of WatchEvent
    watch : LoopWatch
        Its band history (every window's checks).
    drift_pct_per_h : float
    duration_s : float
    first_warning_s : float or None
        Time of the first WARNING from the watch's start [s] (None: none).
    drift_start_s : float
        When the drift started [s].
    drift_at_warning_pct : float or None
        The resonance's drift then [%].
    """

    events: tuple[WatchEvent, ...]
    watch: LoopWatch
    drift_pct_per_h: float
    duration_s: float
    first_warning_s: float | None
    drift_at_warning_pct: float | None
    drift_start_s: float = 0.0


def watch_twin(*, bench: Bench, loop: Controller, drift_pct_per_h: float, duration_s: float,
               options: WatchOptions | None = None, seed: int = 0, update_s: float = 1.0,
               settle_s: float = 5.0, drift_start_s: float | None = None,
               progress: Callable[[str], None] | None = None) -> WatchRun:
    """Run ``loop`` on the twin while the resonance drifts, watched (see the module notes).

    Parameters
    ----------
    bench : Bench
        The packaged bench (its ``true`` parameters are the twin before the drift).
    loop : Controller
        The loaded controller.
    drift_pct_per_h : float
        Resonance drift rate [%/h] (both axes).
    duration_s : float
        Watched time, after ``settle_s`` of the loop closing [s].
    options : WatchOptions, optional
    seed : int
    update_s : float
        The plant is moved every this many seconds [s].
    settle_s : float
        The loop closes this long before the watch starts [s].
    drift_start_s : float, optional
        The drift starts this long into the watch [s]; default when the watch's
        baseline is taken (``baseline_windows`` windows), as after a ``tune``.
    """

    opts = options or WatchOptions()
    start = opts.baseline_windows * opts.window_s if drift_start_s is None else drift_start_s
    fs = bench.true.converter.fs_hz
    f = np.linspace(0.05, fs / 2, 50_000)
    spectra = tracking_error_spectra(physical_plant(bench.true, source="the twin before the "
                                                                       "drift"),
                                     loop.continuous, params=bench.true,
                                     gd_used_v_per_rad=loop.gd, f_hz=f)
    lines = {float(fl): np.asarray(spectra.line_power[i], dtype=float)
             for i, fl in enumerate(spectra.line_freqs_hz)}
    res = [float(bench.true.sercalo.resonance_hz[a]) for a in ("h", "v")]
    watch = LoopWatch(f_hz=f, predicted_psd=spectra.total, fs_hz=fs, resonances_hz=res,
                      line_power=lines, options=opts)
    stream = BenchStream(bench.true, seed=seed, name="watch", controller=loop.feedback,
                         plant=bench_discrete(bench), specialise=False)
    stream.step(round(settle_s * fs))
    gd = np.asarray(loop.gd, dtype=float)
    n_upd = round(update_s * fs)
    t = 0.0
    events: list[WatchEvent] = []
    while t < duration_s - 1e-9:
        drift = drift_pct_per_h * max(0.0, t - start) / 3600.0
        if drift != 0.0:
            stream.set_plant(bench_discrete(drifted_bench(bench, resonance_pct=drift)))
        block = stream.step(min(n_upd, round((duration_s - t) * fs)))
        t += block.adc.shape[0] / fs
        new = watch.feed(block.adc[:, _QD] / gd)
        for ev in new:
            if progress is not None:
                progress(f"{ev.time_s:.0f} s (resonance {drift:+.3g} %): {ev.level}: {ev.cause}")
        events += new
    first = next((e.time_s for e in events if e.level == "WARNING"), None)
    return WatchRun(events=tuple(events), watch=watch, drift_pct_per_h=drift_pct_per_h,
                    duration_s=duration_s, first_warning_s=first, drift_start_s=start,
                    drift_at_warning_pct=None if first is None
                    else drift_pct_per_h * max(0.0, first - start) / 3600.0)
