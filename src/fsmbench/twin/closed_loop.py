"""Closed-loop experiments on the twin: an excitation played while the loop runs.

One record per excited command, named after it:

==================  =========================================================================
file                variables
==================  =========================================================================
``data_cl_uch``     ``t``, the excitation (``Xch``: added to ``Uch`` at the controller's
                    output, or ``Xph``: added to the reference of ``Vph``), ``Uch``, ``Ucv``
                    (the commands the DAC gave), ``Vph``, ``Vpv`` (the 4QD), ``Vch``,
                    ``Vcv`` (the coil voltages) [V]
``data_cl_ucv``     the same with ``Xcv`` (or ``Xpv``)
==================  =========================================================================

The protocol: the loop is closed from the first sample with the running
controller (state zero, as the ESRF study's closed-loop records), the bench
settles for ``settle_s``, then the excitation is played (a periodic one repeats
its steady-state periods to the record's end). ``t`` starts at 0 with the loop;
the excitation's variable is zero before it starts, so an estimator finds
where it starts from the record itself.

The engine plays an excitation at the reference by subtracting it from what
the controller reads (:meth:`fsmbench.sim.stream.BenchStream.add_excitation`):
the 4QD channels hold the sensor's reading.

:func:`drifted_bench` moves the Sercalo's resonance (both axes) by a
percentage: the drift ``tune --drift-resonance`` starts from.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import xarray as xr

from fsmbench.bench.params import Bench
from fsmbench.control.controller import Controller
from fsmbench.excite.files import read_excitation
from fsmbench.excite.shaped import beam_bounded_measurement
from fsmbench.io.recording import make_recording
from fsmbench.sim.controller import closed_loop_spectral_radius
from fsmbench.sim.excitation import SampledExcitation, samples_sha256
from fsmbench.sim.plant import ADC_CHANNELS, bench_discrete
from fsmbench.sim.stream import BenchStream
from fsmbench.twin.draws import PARAMETERS, perturbed_bench
from fsmbench.twin.experiments import ExperimentSpec
from fsmbench.twin.simulate import TwinRun
from fsmbench.twin.truth import twin_truth

__all__ = ["CLOSED_LOOP_EXPERIMENTS", "CLOSED_LOOP_SIGNALS", "ClosedLoopPlay",
           "drifted_bench", "excitation_variable", "play_closed_loop", "simulate_closed_loop"]

#: The closed-loop record of each excited command.
CLOSED_LOOP_EXPERIMENTS = {"Uch": "data_cl_uch", "Ucv": "data_cl_ucv"}
#: What every closed-loop record holds besides ``t`` and its excitation.
CLOSED_LOOP_SIGNALS = ("Uch", "Ucv", "Vph", "Vpv", "Vch", "Vcv")
_EXCITATION_VARIABLES = {("Uch", "output"): "Xch", ("Ucv", "output"): "Xcv",
                         ("Uch", "reference"): "Xph", ("Ucv", "reference"): "Xpv"}


def excitation_variable(channel: str, at: str) -> str:
    """The record's name for an excitation of ``channel`` played at ``at`` (``Xch`` …).

    Raises
    ------
    ValueError
        A channel the Sercalo loop does not drive, or an unknown place.
    """
    try:
        return _EXCITATION_VARIABLES[(channel, at)]
    except KeyError:
        raise ValueError(f"a closed-loop excitation drives Uch or Ucv at the output or the "
                         f"reference, not {channel} at {at!r}") from None


@dataclass(frozen=True, eq=False)
class ClosedLoopPlay:
    """One closed-loop experiment.

    Attributes
    ----------
    channel : str
        ``Uch`` or ``Ucv``.
    samples_v : ndarray, shape (n,)
        The excitation [V] at the bench's rate (4QD volts at the reference).
    at : {"output", "reference"}
    loop_from : int or None
        After the last sample: zeros (None) or ``samples_v[loop_from:]`` repeated.
    description : str
        What is played, in words.
    """

    channel: str
    samples_v: np.ndarray
    at: str = "output"
    loop_from: int | None = None
    description: str = "designed excitation"

    @property
    def name(self) -> str:
        """The record's name, ``data_cl_uch`` or ``data_cl_ucv``."""
        if self.channel not in CLOSED_LOOP_EXPERIMENTS:
            raise ValueError(f"a closed-loop experiment excites Uch or Ucv, not {self.channel}")
        return CLOSED_LOOP_EXPERIMENTS[self.channel]


def drifted_bench(bench: Bench, *, resonance_pct: float) -> Bench:
    """``bench`` with the Sercalo's resonance moved by ``resonance_pct`` % on both axes.

    Its static gain is kept (a stiffness and mass change at constant ratio); an
    identified bench moves its identified modes
    (:func:`fsmbench.twin.draws.perturbed_bench`).

    Raises
    ------
    ValueError
        A drift of -100 % or less.
    """
    if not resonance_pct > -100.0:
        raise ValueError(f"a resonance drift must be above -100 %, got {resonance_pct:g} %")
    if resonance_pct == 0.0:
        return bench

    factors = {k: (0.0 if k.endswith("_s") else 1.0) for k in PARAMETERS}
    factors.update({f"resonance_scale.{a}": 1.0 + resonance_pct / 100.0 for a in "hv"})
    moved = perturbed_bench(bench, factors)
    return dataclasses.replace(moved, origin=f"{bench.origin} (resonance {resonance_pct:+g} %)")


def _record(bench: Bench, play: ClosedLoopPlay, out: Any, *, variable: str,
            start_s: float) -> xr.Dataset:
    """The record's variables; the excitation as played, zero before ``start_s``."""
    signals = {name: out.signal(name) for name in CLOSED_LOOP_SIGNALS}
    t = out.t_s()
    start = int(np.searchsorted(t, start_s - 0.5 / out.fs_hz))
    x = np.zeros(out.n)
    x[start:] = _played_samples(play, out.n - start)
    signals[variable] = x
    return make_recording(signals, fs_hz=bench.true.converter.fs_hz,
                          experiment=play.name, source="fsmbench twin (loop closed)")


def _played_samples(play: ClosedLoopPlay, n: int) -> np.ndarray:
    x = np.asarray(play.samples_v, dtype=float)
    if n <= x.size:
        return x[:n]
    out = np.zeros(n)
    out[:x.size] = x
    if play.loop_from is not None:
        span = x.size - play.loop_from
        i = np.arange(n - x.size)
        out[x.size:] = x[play.loop_from + i % span]
    return out


def play_closed_loop(plays: Sequence[ClosedLoopPlay], *, bench: Bench,
                     controller: Controller, seed: int = 0, settle_s: float = 1.0,
                     duration_s: float | None = None,
                     progress: Callable[[str], None] | None = None) -> TwinRun:
    """Run each closed-loop experiment on ``bench`` and return its records and truth.

    Parameters
    ----------
    plays : sequence of ClosedLoopPlay
        At most one per command.
    bench : Bench
        Packaged or identified (its engine plant, :func:`fsmbench.sim.plant.bench_discrete`).
    controller : Controller
        The loop's controller (checked stable on the bench first).
    seed : int
        Noise seed (each experiment's streams named after it).
    settle_s : float
        Loop closed, no excitation, before the excitation starts [s].
    duration_s : float, optional
        Record length [s]; default ``settle_s`` plus every sample played once.

    Raises
    ------
    ValueError
        Two plays of one command, an unstable loop, a record shorter than the
        settling time, an excitation beyond a converter's range.
    """

    names = [p.name for p in plays]
    if len(set(names)) != len(names):
        raise ValueError(f"two excitations for one command ({', '.join(names)}); give one per "
                         "command")
    plant = bench_discrete(bench)
    rho = closed_loop_spectral_radius(plant, controller.feedback, n_adc=len(ADC_CHANNELS))
    if rho >= 1.0:
        raise ValueError(f"{controller.name} does not stabilise {bench.label} (closed-loop "
                         f"spectral radius {rho:.6f} >= 1)")
    fs = bench.true.converter.fs_hz
    recordings: dict[str, xr.Dataset] = {}
    realized: dict[str, dict[str, float]] = {}
    specs = []
    for play in plays:
        n_total = round((duration_s if duration_s is not None
                         else settle_s + play.samples_v.size / fs) * fs)
        if n_total <= round(settle_s * fs):
            raise ValueError(f"{play.name}: a record of {n_total / fs:g} s ends before the "
                             f"excitation starts at {settle_s:g} s")
        variable = excitation_variable(play.channel, play.at)
        ex = SampledExcitation(play.channel, "samples",
                               float(np.sqrt(np.mean(np.square(play.samples_v)))), settle_s,
                               samples_v=play.samples_v, loop_from=play.loop_from)
        stream = BenchStream(bench.true, seed=seed, name=play.name, controller=controller.feedback,
                             plant=plant, specialise=False)
        stream.add_excitation(ex, at=play.at)
        if progress is not None:
            progress(f"playing {play.description} on {play.channel} at the "
                     f"{'controller output' if play.at == 'output' else 'reference'} with the "
                     f"loop closed by {controller.name} ({n_total / fs:g} s)")
        out = stream.run(n_total, block=2**16)
        recordings[play.name] = _record(bench, play, out, variable=variable, start_s=settle_s)
        realized[play.name] = {f"qd_noise_v.{a}": float(np.std(out.noise["qd"][:, i]))
                               for i, a in enumerate("hv")}
        specs.append(ExperimentSpec(
            name=play.name, description=f"{play.description} on {play.channel} "
            f"({'controller output' if play.at == 'output' else 'reference'}, from "
            f"{settle_s:g} s), loop closed by {controller.name}", seed_section="closed loop",
            duration_s=n_total / fs, excitations=(ex,), closed_loop=True,
            compensation_unit=True, shielding=False))
    truth = twin_truth(bench, seed=seed, experiments=tuple(specs), realized=realized,
                       controller_name=controller.name)
    for spec, play in zip(specs, plays, strict=True):
        for item in truth["experiments"][spec.name]["excitations"]:
            item["samples_v"] = {"n_samples": int(play.samples_v.size),
                                 "samples_sha256": samples_sha256(play.samples_v),
                                 "at": play.at}
    truth["closed_loop"] = {"controller": controller.name, "controller_source": controller.source,
                            "settle_s": settle_s,
                            "gd_used_v_per_rad": dict(zip("hv", controller.gd,
                                                          strict=True))}
    return TwinRun(recordings=recordings, truth=truth, seed=seed, experiments=tuple(specs))


def simulate_closed_loop(*, bench: Bench, controller: Controller,
                         sources: Sequence[str] | None = None, at: str = "output",
                         max_error_rad: float = 30e-6, seed: int = 0, settle_s: float = 1.0,
                         duration_s: float | None = None,
                         progress: Callable[[str], None] | None = None) -> TwinRun:
    """``fsmbench simulate --closed-loop CONTROLLER``: the closed-loop records of ``bench``.

    Parameters
    ----------
    bench : Bench
    controller : Controller
        Closes the loop (:func:`fsmbench.control.loaded.running_controller`).
    sources : sequence of str, optional
        ``fsmbench excite`` outputs (folder, ``.json`` or ``.mat``), one per command
        (``Uch``, ``Ucv``); a repeated design repeats its steady-state periods to the
        record's end. Default: the beam-bounded multisines of both commands designed on
        ``bench`` (:func:`fsmbench.excite.shaped.beam_bounded_measurement`, 0.25 Hz,
        6 periods after 2 transient ones).
    at : {"output", "reference"}
    max_error_rad : float
        The bound of the default design [rad].
    seed, settle_s, duration_s
        As :func:`play_closed_loop`.

    Raises
    ------
    ValueError
        A file for a channel the loop does not drive, two for one, or any refusal of
        :func:`play_closed_loop`.
    """
    plays: list[ClosedLoopPlay] = []
    if sources:
        for src in sources:
            design = read_excitation(src)
            if design.input not in CLOSED_LOOP_EXPERIMENTS:
                raise ValueError(f"{src}: excites {design.input}; with the loop closed an "
                                 "excitation drives Uch or Ucv")
            plays.append(ClosedLoopPlay(
                channel=design.input, samples_v=np.asarray(design.samples_v, dtype=float),
                at=at, loop_from=(design.transient_samples if design.after_end == "repeat"
                                  else None),
                description=f"the excitation of {src}"))
    else:
        for ch in ("Uch", "Ucv"):
            m = beam_bounded_measurement(
                bench=bench, params=bench.nominal if bench.model is None else bench.true,
                controller=controller.feedback, channel=ch, max_error_rad=max_error_rad,
                at=at, resolution_hz=0.25, periods=6, transient_periods=2,
                controller_name=controller.name)
            plays.append(ClosedLoopPlay(channel=ch, samples_v=m.design.samples_v, at=at,
                                        description="beam-bounded multisine"))
    return play_closed_loop(plays, bench=bench, controller=controller, seed=seed,
                            settle_s=settle_s, duration_s=duration_s, progress=progress)
