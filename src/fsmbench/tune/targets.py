"""The twin as :func:`fsmbench.tune.guarded.tune_guarded`'s target.

:class:`TwinTarget` runs one :class:`~fsmbench.sim.stream.BenchStream` of the
(possibly drifted) twin with the running controller and the Newport's 1 Hz sine on
both axes (the ESRF study's repeatability motion, the disturbance the 6.1 objective
is about); controllers are swapped in it bumplessly. Its closed-loop measurements
are :func:`fsmbench.twin.closed_loop.play_closed_loop` on the same twin. The live
device is the other target (:mod:`fsmbench.tune.device`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from fsmbench.bench.params import Bench
from fsmbench.control.controller import Controller
from fsmbench.sim.excitation import Excitation
from fsmbench.sim.plant import ADC_CHANNELS, bench_discrete
from fsmbench.sim.stream import BenchStream
from fsmbench.twin.closed_loop import ClosedLoopPlay, play_closed_loop
from fsmbench.twin.experiments import REP_FREQ_HZ
from fsmbench.twin.simulate import TwinRun

__all__ = ["TwinTarget"]

_QD = (ADC_CHANNELS.index("Vph"), ADC_CHANNELS.index("Vpv"))
_BLOCK = 2**14


class TwinTarget:
    """The running twin (see the module notes).

    Parameters
    ----------
    true_bench : Bench
        What the twin simulates (the bench file, drifted or identified).
    loop : Controller
        The controller running at the start.
    seed : int
    amplitude_v : float
        The Newport's 1 Hz sine on both axes during the watches [V].
    drift_pct : float
        How far ``true_bench``'s resonance was moved from the bench file [%] (reported).
    """

    def __init__(self, true_bench: Bench, loop: Controller, *, seed: int, amplitude_v: float,
                 drift_pct: float = 0.0) -> None:
        sines = tuple(Excitation(ch, "sine", amplitude_v, 0.0, REP_FREQ_HZ)
                      for ch in ("Unh", "Unv"))
        self.true_bench = true_bench
        self.stream = BenchStream(true_bench.true, seed=seed, name="tune",
                                  controller=loop.feedback, excitations=sines,
                                  plant=bench_discrete(true_bench), specialise=False)
        self.fs_hz = self.stream.fs_hz
        self.gd = loop.gd
        self.label = true_bench.label
        self.drift_pct = float(drift_pct)

    def run(self, duration_s: float, *, settle_s: float) -> np.ndarray:
        """The 4QD tracking error after ``settle_s`` of ``duration_s`` [rad], (n, 2)."""
        n = round(duration_s * self.fs_hz)
        parts, done = [], 0
        while done < n:
            block = self.stream.step(min(_BLOCK, n - done))
            parts.append(block.adc[:, _QD] / np.asarray(self.gd))
            done += block.adc.shape[0]
        e = np.vstack(parts)[round(settle_s * self.fs_hz):]
        return e - e.mean(axis=0)

    def load(self, loop: Controller) -> dict[str, Any]:
        """Swap ``loop`` in bumplessly; the switch (sample, names, commands around it [V])."""
        sw = self.stream.set_controller(loop.feedback)
        self.gd = loop.gd
        return {"sample": int(sw.sample), "from": sw.previous, "to": sw.current,
                "command_before_v": [float(x) for x in sw.command_before_v],
                "command_after_v": [float(x) for x in sw.command_after_v]}

    def roll_back(self, loop: Controller, *, force: bool = False) -> dict[str, Any]:
        """Swap ``loop`` (the controller that ran before) back in bumplessly: :meth:`load`
        (always: the twin's reading is exact, ``force`` changes nothing)."""
        return self.load(loop)

    def running_controller(self) -> str:
        """The name of the controller in the twin's loop."""
        k = self.stream.controller
        return "none (loop open)" if k is None else str(k.name)

    def checkpoint(self, loop: Controller) -> dict[str, Any]:
        """``loop`` as the record names it (the twin swaps the same controller back)."""
        return {"name": loop.name, "device": self.label, "noun": "The twin",
                "checked": "running when tune started", "restore_with": []}

    def play(self, plays: Sequence[ClosedLoopPlay], *, controller: Controller,
             settle_s: float, seed: int,
             progress: Callable[[str], None] | None) -> TwinRun:
        """The closed-loop records on the twin (each from a fresh loop, as the ESRF study's)."""
        return play_closed_loop(plays, bench=self.true_bench, controller=controller, seed=seed,
                                settle_s=settle_s, progress=progress)
