"""Twin experiments of any length, streamed to NeXus archives block by block.

The streaming bench (:class:`fsmbench.sim.stream.BenchStream`) gives the
samples of one whole run whatever the block length, so a 24 h huddle test
written in 10 s blocks holds, sample for sample, what one 24 h run would
give, with memory bounded by one block (tens of MB). What the twin injected
(``realized`` in ``twin_truth.json``) is accumulated as running moments.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fsmbench.bench.params import Bench
from fsmbench.io.dataset import ordered_signals
from fsmbench.io.nexus_stream import NexusAppender
from fsmbench.io.signals import EXPERIMENTS
from fsmbench.sim.discretize import DiscretePlant
from fsmbench.sim.engine import DiscreteController
from fsmbench.sim.stream import BenchBlock
from fsmbench.twin.experiments import REALIZED_NOISE, ExperimentSpec, experiment_stream

__all__ = ["RunningMoments", "StreamProgress", "stream_experiment"]


@dataclass
class RunningMoments:
    """Mean and variance of a stream of blocks (Chan et al.'s pairwise update).

    Numerically stable for any number of samples; equal to ``np.mean`` and
    ``np.var`` of the concatenation up to rounding.
    """

    n: int = 0
    mean: float = 0.0
    m2: float = 0.0

    def add(self, x: np.ndarray) -> None:
        """Take the next block (n,)."""
        nb = int(x.size)
        if nb == 0:
            return
        mb = float(np.mean(x))
        m2b = float(np.sum((x - mb) ** 2))
        n = self.n + nb
        delta = mb - self.mean
        self.mean += delta * nb / n
        self.m2 += m2b + delta * delta * self.n * nb / n
        self.n = n

    @property
    def std(self) -> float:
        """Standard deviation (population, as ``np.std``)."""
        return math.sqrt(self.m2 / self.n) if self.n else float("nan")


@dataclass(frozen=True)
class StreamProgress:
    """How far a streamed experiment is.

    Attributes
    ----------
    experiment : str
    samples_done, samples_total : int
    rate_samples_per_s : float
        Simulated samples per wall-clock second so far.
    """

    experiment: str
    samples_done: int
    samples_total: int
    rate_samples_per_s: float

    @property
    def seconds_left(self) -> float:
        """Wall-clock time left at the rate so far [s]."""
        left = self.samples_total - self.samples_done
        return left / self.rate_samples_per_s if self.rate_samples_per_s > 0 else math.inf

    def line(self) -> str:
        """One progress line in words."""
        pct = 100.0 * self.samples_done / max(1, self.samples_total)
        left = self.seconds_left
        eta = f"{left / 60:.1f} min" if left >= 90 else f"{left:.0f} s"
        return (f"{self.experiment}: {self.samples_done:,} of {self.samples_total:,} samples "
                f"({pct:.1f} %), {self.rate_samples_per_s / 1e6:.2f} M samples/s, "
                f"{eta} left")


@dataclass
class _Realized:
    moments: dict[str, RunningMoments] = field(default_factory=dict)

    def add(self, block: BenchBlock) -> None:
        for key, part in REALIZED_NOISE:
            for i, axis in enumerate("hv"):
                self.moments.setdefault(f"{key}.{axis}", RunningMoments()).add(
                    block.noise[part][:, i])
        if block.va is None:  # a record without Va: the Attocube did not run
            return
        for name in ("geometric", "perpendicular", "air", "frame", "noise", "total"):
            self.moments.setdefault(f"va_{name}", RunningMoments()).add(
                getattr(block.va, f"{name}_m"))

    def stds(self) -> dict[str, float]:
        return {k: m.std for k, m in self.moments.items()}


def stream_experiment(bench: Bench, spec: ExperimentSpec, *, seed: int, path: str | Path,
                      block_s: float = 10.0, plant: DiscretePlant | None = None,
                      controller: DiscreteController | None = None,
                      created: float | None = None,
                      progress: Callable[[StreamProgress], None] | None = None,
                      progress_every_s: float = 10.0) -> dict[str, float]:
    """Simulate one experiment into a NeXus archive, block by block.

    Parameters
    ----------
    bench : Bench
    spec : ExperimentSpec
        Any length (``spec.duration_s``).
    seed : int
    path : str or Path
        The archive (written atomically).
    block_s : float
        Bench time per block [s] (memory: ~30 float64 columns of a block).
    plant, controller : optional
        As :func:`fsmbench.twin.simulate.simulate_experiment`.
    created : float, optional
        ``file_time`` of the archive [s since the epoch]; default now;
        :data:`~fsmbench.io.nexus_meta.UNSTAMPED_S`: none (reproducible bytes).
    progress : callable, optional
        Called with a :class:`StreamProgress` at most every ``progress_every_s``
        wall-clock seconds, and at the end.

    Returns
    -------
    dict
        Standard deviation of every injected noise and ``Va`` part over the
        record (the ``realized`` entry of ``twin_truth.json``).
    """
    fs = bench.true.converter.fs_hz
    n_total = round(spec.duration_s * fs)
    stream = experiment_stream(bench, spec, seed=seed, plant=plant, controller=controller)
    # The seed's table order, as make_recording stores in-memory records.
    signals = ordered_signals(s for s in EXPERIMENTS[spec.name].required if s != "t")
    block = max(1, round(block_s * fs))
    realized = _Realized()
    start = last = time.monotonic()
    with NexusAppender(path, signals=signals, fs_hz=fs, created=created, bench=bench,
                       attrs={"experiment": spec.name, "source": "fsmbench twin"},
                       times_unknown="none: simulated by the twin, the samples have no "
                                     "wall-clock time") as nx:
        done = 0
        while done < n_total:
            b = stream.step(min(block, n_total - done))
            nx.append({s: b.signal(s) for s in signals})
            realized.add(b)
            done += b.n
            now = time.monotonic()
            if progress is not None and (now - last >= progress_every_s or done == n_total):
                last = now
                progress(StreamProgress(experiment=spec.name, samples_done=done,
                                        samples_total=n_total,
                                        rate_samples_per_s=done / max(now - start, 1e-9)))
    return realized.stds()
