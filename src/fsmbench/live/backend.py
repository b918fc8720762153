"""What the live device runs on: the twin's streaming bench, or a folder played back.

Both give the device blocks of named signals at the bench's rate
(:class:`LiveBlock`). The twin acts (loop, excitations, experiments); the
playback only replays what was recorded, sample for sample, and refuses to
act with a message that says so.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fsmbench.bench.params import Bench
from fsmbench.io.folder import load_recordings
from fsmbench.live.states import MAX_DRIFT_PCT_PER_H
from fsmbench.sim.engine import DiscreteController
from fsmbench.sim.excitation import Excitation
from fsmbench.sim.plant import ADC_CHANNELS, DAC_CHANNELS, bench_discrete
from fsmbench.sim.stream import BenchStream, ControllerSwitch
from fsmbench.twin.closed_loop import drifted_bench

__all__ = ["DRIFT_STEP_PCT", "LIVE_SIGNALS", "MAX_DRIFT_PCT_PER_H", "LiveBlock",
           "PlaybackBackend", "TwinBackend"]

#: A drifting resonance moves in steps of this much [%] (a fifth of the 0.25 % a
#: 10 s window locates a 0.1 %-damped peak to), every 1 to 30 s of bench time (a new
#: plant costs ~70 ms: every second at 50x real time would slow the bench).
DRIFT_STEP_PCT = 0.05
#: Largest drift rate of the twin's resonance [%/h].

#: Signals a live block may carry, in the seed's names.
LIVE_SIGNALS = (*DAC_CHANNELS, *ADC_CHANNELS, "Va")


@dataclass(frozen=True)
class LiveBlock:
    """Consecutive samples of the live bench.

    Attributes
    ----------
    start_sample : int
        Index of the first sample since the backend started.
    fs_hz : float
    signals : dict of str to array (n,)
        Seed names (:data:`LIVE_SIGNALS`); DAC/ADC in V, ``Va`` in m. A
        playback carries only what its current file recorded.
    source : str
        ``twin`` or the file the samples were played from.
    """

    start_sample: int
    fs_hz: float
    signals: dict[str, np.ndarray] = field(repr=False)
    source: str

    @property
    def n(self) -> int:
        """Number of samples."""
        return len(next(iter(self.signals.values()))) if self.signals else 0


class TwinBackend:
    """The twin's bench, live: one :class:`~fsmbench.sim.stream.BenchStream` run for ever.

    Parameters
    ----------
    bench : Bench
        ``bench.true`` is simulated; ``bench.nominal`` gives the calibrated 4QD gains.
    seed : int
    drift_pct_per_h : float
        The Sercalo's resonance (both axes) drifts this fast from ``drift_start_s`` [%/h]: the
        plant is moved in steps of :data:`DRIFT_STEP_PCT`, its state carried over
        (:meth:`~fsmbench.sim.stream.BenchStream.set_plant`).
    drift_start_s : float
        Bench time the drift starts [s].
    """

    kind = "twin"
    acts = True

    def __init__(self, bench: Bench, *, seed: int, drift_pct_per_h: float = 0.0,
                 drift_start_s: float = 0.0) -> None:
        if not (math.isfinite(drift_pct_per_h) and abs(drift_pct_per_h) <= MAX_DRIFT_PCT_PER_H):
            raise ValueError(f"a drift rate of {drift_pct_per_h!r} %/h is not within "
                             f"+/-{MAX_DRIFT_PCT_PER_H:g} %/h")
        self.bench = bench
        self.stream = BenchStream(bench.true, seed=seed, name="live",
                                  plant=bench_discrete(bench))
        self.fs_hz = self.stream.fs_hz
        self.converter_half_range_v = bench.true.converter.range_v / 2
        self.drift_pct_per_h = float(drift_pct_per_h)
        self._drift_every_s = (min(30.0, max(1.0, DRIFT_STEP_PCT / abs(drift_pct_per_h) * 3600))
                               if drift_pct_per_h else math.inf)
        self.drift_start_s = max(0.0, float(drift_start_s))
        self._next_drift_s = self.drift_start_s + self._drift_every_s

    @property
    def drift_pct(self) -> float:
        """How far the resonance has drifted now [%]."""
        return self.drift_pct_per_h * max(0.0, self.time_s - self.drift_start_s) / 3600.0

    @property
    def controller(self) -> DiscreteController | None:
        """Controller in the loop (None: open)."""
        return self.stream.controller

    def set_controller(self, controller: DiscreteController | None, *,
                       hold: bool) -> ControllerSwitch:
        """Close, swap or open (bumpless; see :meth:`BenchStream.set_controller`)."""
        return self.stream.set_controller(controller, hold=hold)

    def start_excitation(self, excitation: Excitation) -> float:
        """Play ``excitation`` (its ``start_s`` in bench time); returns its peak [V]."""
        return self.stream.add_excitation(excitation)

    def stop_excitation(self) -> None:
        """Stop every excitation."""
        self.stream.clear_excitations()

    def set_environment(self, *, compensation_unit: bool, shielding: bool) -> None:
        """Switch the Attocube's compensation unit and the beam path's shielding."""
        self.stream.set_environment(compensation_unit=compensation_unit, shielding=shielding)

    @property
    def time_s(self) -> float:
        """Bench time of the next sample [s]."""
        return self.stream.time_s

    def step(self, n: int) -> LiveBlock:
        """The next ``n`` samples."""
        if self.drift_pct_per_h and self.time_s >= self._next_drift_s:
            self.stream.set_plant(bench_discrete(drifted_bench(self.bench,
                                                               resonance_pct=self.drift_pct)))
            self._next_drift_s = self.time_s + self._drift_every_s
        b = self.stream.step(n)
        signals = {name: b.dac[:, i] for i, name in enumerate(DAC_CHANNELS)}
        signals.update({name: b.adc[:, i] for i, name in enumerate(ADC_CHANNELS)})
        signals["Va"] = b.signal("Va")  # the live bench's stream runs its Attocube
        return LiveBlock(start_sample=b.start_sample, fs_hz=b.fs_hz, signals=signals,
                         source="twin")


class PlaybackBackend:
    """A folder of recordings replayed as if live, one file after the other, then again.

    Parameters
    ----------
    folder : str or Path
        Recordings in the seed's layout (``data_*.mat`` or NeXus).
    fs_hz, adc_range_v, adc_bits : float, float, int
        What the folder was recorded with (the checks of
        :func:`fsmbench.io.folder.load_recordings`).

    Raises
    ------
    ValueError
        No readable recording in the folder (each skipped file and why).
    """

    kind = "playback"
    acts = False
    controller = None

    def __init__(self, folder: str | Path, *, fs_hz: float, adc_range_v: float,
                 adc_bits: int) -> None:
        loaded = load_recordings(Path(folder), fs_hz=fs_hz, adc_range_v=adc_range_v,
                                 adc_bits=adc_bits)
        if not loaded.recordings:
            why = "; ".join(f"{name}: {reason}" for name, reason in loaded.skipped.items()) \
                or "no recordings of the ESRF study's experiments"
            raise ValueError(f"{folder}: nothing to play back ({why})")
        self.fs_hz = float(fs_hz)
        self.converter_half_range_v = adc_range_v / 2
        self._files: list[tuple[str, dict[str, np.ndarray]]] = []
        for name, ds in loaded.recordings.items():
            self._files.append((name, {v: np.asarray(ds[v].values, dtype=float)
                                       for v in ds.data_vars if v in LIVE_SIGNALS}))
        self._file = 0
        self._pos = 0
        self._k = 0

    @property
    def files(self) -> tuple[str, ...]:
        """Experiment names in playing order."""
        return tuple(name for name, _ in self._files)

    @property
    def time_s(self) -> float:
        """Bench time of the next sample [s] (since the playback started)."""
        return self._k / self.fs_hz

    @property
    def current(self) -> str:
        """The experiment playing now."""
        return self._files[self._file][0]

    def step(self, n: int) -> LiveBlock:
        """The next ``n`` samples of the current file (fewer at its end)."""
        name, signals = self._files[self._file]
        length = len(next(iter(signals.values())))
        take = min(n, length - self._pos)
        block = LiveBlock(start_sample=self._k, fs_hz=self.fs_hz,
                          signals={k: v[self._pos:self._pos + take].copy()
                                   for k, v in signals.items()},
                          source=name)
        self._pos += take
        self._k += take
        if self._pos >= length:
            self._pos = 0
            self._file = (self._file + 1) % len(self._files)
        return block

    def _refuse(self, what: str) -> None:
        raise ValueError(f"{what} is not possible on a playback: the bench replays "
                         f"recorded files ({', '.join(self.files)})")

    def set_controller(self, controller: DiscreteController | None, *,
                       hold: bool) -> ControllerSwitch:
        """Refused: a recording cannot be controlled."""
        self._refuse("closing or opening the loop")
        raise AssertionError  # pragma: no cover - _refuse always raises

    def start_excitation(self, excitation: Excitation) -> float:
        """Refused: a recording cannot be excited."""
        self._refuse("an excitation")
        raise AssertionError  # pragma: no cover

    def stop_excitation(self) -> None:
        """Nothing plays on a recording: nothing to stop."""

    def set_environment(self, *, compensation_unit: bool, shielding: bool) -> None:
        """Refused: a recording's environment is what it was."""
        self._refuse("changing the environment")
