"""Run the seed's experiments on the twin and write them in the seed's layout.

>>> run = simulate_bench(seed=1, duration_s=5.0)          # doctest: +SKIP
>>> write_twin(run, "twin-data")                          # doctest: +SKIP

writes ``data_cal_pd_h.mat`` ... ``data_rep_v.mat`` (MATLAB v5, column
vectors, the seed's variable names) and ``twin_truth.json``.

>>> run = simulate_excitation("excite-out/excitation.json")  # doctest: +SKIP

plays a designed excitation (``fsmbench excite``) in the experiment of its
input (``data_uch`` for ``Uch`` ...) instead of the seed's noise: from the
seed's start time, every sample once, then zeros (or, for a file whose
``after_end`` is ``repeat``, its steady-state periods again when the record
is longer).
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from fsmbench.atomic import atomic_write_text
from fsmbench.bench.params import Bench, default_bench
from fsmbench.excite.files import ExcitationFileError, find_description, read_excitation
from fsmbench.io.recording import (
    RecordingFormat,
    make_recording,
    mat_variables,
    write_recording,
)
from fsmbench.io.signals import EXPERIMENTS
from fsmbench.jsonutil import format_text, stamped
from fsmbench.progress import advance
from fsmbench.sim.codegen import specialised_kernel
from fsmbench.sim.controller import closed_loop_spectral_radius
from fsmbench.sim.discretize import DiscretePlant
from fsmbench.sim.engine import DiscreteController
from fsmbench.sim.excitation import samples_sha256
from fsmbench.sim.plant import ADC_CHANNELS, bench_discrete
from fsmbench.twin.experiments import (
    REALIZED_NOISE,
    ExperimentSpec,
    esrf_experiments,
    esrf_feedback,
    experiment_stream,
    played_experiment,
    with_duration,
)
from fsmbench.twin.long import stream_experiment
from fsmbench.twin.truth import TRUTH_FORMAT, twin_truth

__all__ = [
    "ExperimentResult",
    "TwinRun",
    "play_excitation",
    "simulate_bench",
    "simulate_excitation",
    "simulate_experiment",
    "stream_bench",
    "write_twin",
]


@dataclass(frozen=True)
class ExperimentResult:
    """One simulated record and what the twin injected into it.

    Attributes
    ----------
    recording : xarray.Dataset
        The seed's signals (see :mod:`fsmbench.io.recording`).
    realized : dict
        Standard deviation of every injected noise and of each ``Va``
        component in this record, SI units.
    """

    recording: xr.Dataset
    realized: dict[str, float]


@dataclass(frozen=True)
class TwinRun:
    """All records of one twin run, the truth to compare identifications with."""

    recordings: Mapping[str, xr.Dataset]
    truth: Mapping[str, Any]
    seed: int
    experiments: tuple[ExperimentSpec, ...] = field(default=())
    #: The files written as the records were simulated (``simulate_bench(write_dir=...)``):
    #: each record's, then ``twin_truth.json``; empty when nothing was written.
    files: tuple[Path, ...] = field(default=())

    def written(self) -> dict[Path, dict[str, np.ndarray]]:
        """Each MAT-file written and the variables in it (``load_recordings(written=)``);
        empty when nothing was written or the files are NeXus archives."""
        return {path: mat_variables(self.recordings[path.stem]) for path in self.files
                if path.suffix == ".mat" and path.stem in self.recordings}


def simulate_experiment(bench: Bench, spec: ExperimentSpec, *, seed: int,
                        plant: DiscretePlant | None = None,
                        controller: DiscreteController | None = None,
                        block: int | None = None) -> ExperimentResult:
    """Simulate one experiment on the twin (the bench's ``true`` parameters).

    Parameters
    ----------
    bench : Bench
    spec : ExperimentSpec
    seed : int
        Run seed; each noise source derives its own stream from it.
    plant : DiscretePlant, optional
        Pre-computed :func:`~fsmbench.sim.plant.bench_discrete` of ``bench`` (saves time over
        many runs).
    controller : DiscreteController, optional
        Used when ``spec.closed_loop``; default: the seed's decentralised
        controller of 9.2, Tustin at the converter rate.
    block : int, optional
        Run the streaming bench in blocks of this many samples (default: one
        block); the record is the same bit for bit.
    """
    fs = bench.true.converter.fs_hz
    n = round(spec.duration_s * fs)
    stream = experiment_stream(bench, spec, seed=seed, plant=plant, controller=controller)
    out = stream.run(n, block=block)
    # A file holds what the seed loads from it. The other channels are not
    # recorded: e.g. in closed loop the 60 dB coil-voltage amplifier (Vch,
    # Vcv) sits on the ADC rails, which the real bench's files would show as
    # clipped data nobody uses.
    signals = {name: out.signal(name) for name in EXPERIMENTS[spec.name].required if name != "t"}
    recording = make_recording(signals, fs_hz=fs, experiment=spec.name, source="fsmbench twin")
    realized = {
        f"{key}.{a}": float(np.std(out.noise[part][:, i]))
        for key, part in REALIZED_NOISE
        for i, a in enumerate("hv")
    }
    if out.va is not None:  # the Attocube runs for the records that hold Va
        realized.update({f"va_{k}": v for k, v in out.va.std_m().items()})
    return ExperimentResult(recording=recording, realized=realized)


def _prepare_run(bench: Bench, *, duration_s: float | None, experiments: Sequence[str] | None,
                 controller: DiscreteController | None
                 ) -> tuple[tuple[ExperimentSpec, ...], DiscretePlant, DiscreteController | None]:
    """The experiments asked for, the twin's plant and a controller checked stable."""
    specs = esrf_experiments()
    if experiments is not None:
        unknown = sorted(set(experiments) - {s.name for s in specs})
        if unknown:
            raise ValueError(f"unknown experiment(s) {unknown}; known: {[s.name for s in specs]}")
        specs = tuple(s for s in specs if s.name in set(experiments))
    if duration_s is not None:
        specs = with_duration(specs, duration_s=duration_s)
    plant = bench_discrete(bench)
    if controller is None and any(s.closed_loop for s in specs):
        controller = esrf_feedback(bench)
    if controller is not None:
        rho = closed_loop_spectral_radius(plant, controller, n_adc=len(ADC_CHANNELS))
        if rho >= 1.0:
            raise ValueError(f"controller '{controller.name}' does not stabilise "
                             f"{bench.label} (closed-loop spectral radius {rho:.6f} >= 1)")
    return specs, plant, controller


def stream_bench(bench: Bench | None = None, *, out_dir: str | Path, seed: int = 0,
                 duration_s: float | None = None, experiments: Sequence[str] | None = None,
                 controller: DiscreteController | None = None,
                 progress: Callable[[str], None] | None = None) -> list[Path]:
    """Run the seed's experiments on the twin straight into NeXus archives (any length).

    Each experiment streams block by block (:func:`fsmbench.twin.long.stream_experiment`),
    so memory does not grow with ``duration_s``; the samples are those
    :func:`simulate_bench` gives for the same seed, bit for bit. Writes
    ``<name>.h5`` and ``twin_truth.json`` into ``out_dir``; returns the paths.
    """

    bench = default_bench() if bench is None else bench
    specs, plant, controller = _prepare_run(bench, duration_s=duration_s,
                                            experiments=experiments, controller=controller)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    specialised_kernel(plant)

    def one(spec: ExperimentSpec) -> dict[str, float]:
        return stream_experiment(bench, spec, seed=seed, path=out / f"{spec.name}.h5",
                                 plant=plant, controller=controller, created=TWIN_CREATED_S,
                                 progress=None if progress is None
                                 else (lambda sp: advance(
                                     progress, f"simulating {sp.experiment}", sp.samples_done,
                                     sp.samples_total, "samples", line=sp.line())))

    with ThreadPoolExecutor(max_workers=max(1, min(len(specs), os.cpu_count() or 1))) as pool:
        realized = dict(zip((s.name for s in specs), pool.map(one, specs), strict=True))
    truth = twin_truth(bench, seed=seed, experiments=specs, realized=realized,
                       controller_name=None if controller is None else controller.name)
    truth_path = out / "twin_truth.json"
    name, version = TRUTH_FORMAT
    atomic_write_text(truth_path, format_text(stamped(truth, format=name, version=version),
                                              sort_keys=True))
    return [*(out / f"{s.name}.h5" for s in specs), truth_path]


def simulate_bench(bench: Bench | None = None, *, seed: int = 0, duration_s: float | None = None,
                   experiments: Sequence[str] | None = None,
                   controller: DiscreteController | None = None,
                   progress: Callable[[str], None] | None = None,
                   write_dir: str | Path | None = None,
                   format: RecordingFormat = "mat5") -> TwinRun:
    """Run the seed's experiments on the twin.

    Parameters
    ----------
    bench : Bench, optional
        Default: the packaged bench.
    seed : int
        Same seed, same records, bit for bit.
    duration_s : float, optional
        Length of every record [s]; default: the seed's lengths.
    experiments : sequence of str, optional
        Names to run (default: all thirteen).
    controller : DiscreteController, optional
        Closed-loop controller; default the seed's of 9.2 (checked stable).
    progress : callable, optional
        Called with a short message before each experiment.
    write_dir : path, optional
        Also write each record there as soon as it is simulated (the files of
        :func:`write_twin`, in ``format``, and ``twin_truth.json`` last); the paths are
        the run's ``files``. Writing beside the next simulations keeps every core busy.
    format : {"mat5", "mat73", "nexus"}
        The files' format when ``write_dir`` is given (see :func:`write_twin`).
    """
    bench = default_bench() if bench is None else bench
    specs, plant, controller = _prepare_run(bench, duration_s=duration_s,
                                            experiments=experiments, controller=controller)
    out = None if write_dir is None else Path(write_dir)
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)

    def one(spec: ExperimentSpec) -> ExperimentResult:
        result = simulate_experiment(bench, spec, seed=seed, plant=plant, controller=controller)
        if out is not None:  # zlib and the file's write release the GIL
            write_recording(result.recording, out / f"{spec.name}{_suffix(format)}",
                            format=format, created=TWIN_CREATED_S)
        return result

    # The experiments are independent (each noise source has its own stream, keyed by
    # experiment and source), so they run on every core; the compiled loop, the random
    # generators and most numpy work release the GIL. The result does not depend on the
    # number of threads.
    specialised_kernel(plant)  # load (or build) the loop once, before the threads use it
    with ThreadPoolExecutor(max_workers=max(1, min(len(specs), os.cpu_count() or 1))) as pool:
        # Longest first: the last ones to end are short, so no thread idles long at the end
        # while the other finishes a 100 s record.
        futures = {pool.submit(one, spec): spec for spec in sorted(
            specs, key=lambda s: -s.duration_s)}
        for i, future in enumerate(as_completed(futures), start=1):
            spec = futures[future]
            future.result()  # its exception now, and the pool stops at the block's end
            advance(progress, "simulating the experiments", i, len(specs), "experiments",
                    line=f"[{i}/{len(specs)}] simulated {spec.name} ({spec.duration_s:g} s)")
        by_name = {futures[f].name: f.result() for f in futures}
    results = [by_name[s.name] for s in specs]
    recordings: dict[str, xr.Dataset] = {s.name: r.recording for s, r in zip(specs, results,
                                                                             strict=True)}
    realized: dict[str, dict[str, float]] = {s.name: r.realized for s, r in zip(specs, results,
                                                                               strict=True)}
    truth = twin_truth(bench, seed=seed, experiments=specs, realized=realized,
                       controller_name=None if controller is None else controller.name)
    run = TwinRun(recordings=recordings, truth=truth, seed=seed, experiments=specs)
    if out is None:
        return run
    files = (*(out / f"{s.name}{_suffix(format)}" for s in specs), _write_truth(run, out))
    return replace(run, files=files)


def simulate_excitation(source: str | Path, bench: Bench | None = None, *, seed: int = 0,
                        duration_s: float | None = None,
                        progress: Callable[[str], None] | None = None) -> TwinRun:
    """Play a designed excitation on the twin in the experiment of its input.

    Parameters
    ----------
    source : str or Path
        The excitation: its folder, JSON description or MAT-file
        (:func:`fsmbench.excite.files.read_excitation`, validated).
    bench : Bench, optional
        Default: the packaged bench; its sampling rate must be the file's.
    seed : int
        Run seed (the bench's own noise; the excitation is the file's).
    duration_s : float, optional
        Record length [s]; default: the seed's start time plus the file, so
        every sample is played once (see the module notes for after the end).
    progress : callable, optional
        Called with a short message.

    Returns
    -------
    TwinRun
        One record (``data_uch`` ... ``data_unv``) and its truth; the truth's
        experiment names the file and the samples' SHA-256 instead of the samples.

    Raises
    ------
    ValueError
        The file is invalid (one line naming it), sampled at another rate than
        the bench, or ``duration_s`` is too short for the experiment.
    """

    bench = default_bench() if bench is None else bench
    described = find_description(source)
    design = read_excitation(described)
    fs = bench.true.converter.fs_hz
    if abs(design.fs_hz - fs) > 1e-9 * fs:
        raise ExcitationFileError(described, f"is sampled at {design.fs_hz:g} Hz; the twin's "
                                             f"bench runs at {fs:g} Hz")
    spec = played_experiment(
        channel=design.input, samples_v=design.samples_v, fs_hz=fs, duration_s=duration_s,
        loop_from=design.transient_samples if design.after_end == "repeat" else None,
        description=f"{design.kind} of {described.name}")
    if progress is not None:
        progress(f"playing {described.name} ({design.kind}, {design.duration_s:g} s) in "
                 f"{spec.name} ({spec.duration_s:g} s)")
    result = simulate_experiment(bench, spec, seed=seed, plant=bench_discrete(bench))
    truth = twin_truth(bench, seed=seed, experiments=(spec,),
                       realized={spec.name: result.realized}, controller_name=None)
    for ex in truth["experiments"][spec.name]["excitations"]:
        ex["samples_v"] = {"file": described.name, "n_samples": int(design.samples_v.size)}
    truth["excitation_file"] = {"description": described.name, "input": design.input,
                                "kind": design.kind,
                                "samples_sha256": samples_sha256(design.samples_v)}
    return TwinRun(recordings={spec.name: result.recording}, truth=truth, seed=seed,
                   experiments=(spec,))


# Files stamp this creation time (the epoch, UTC), not the wall clock, so the
# same seed gives byte-identical files.
TWIN_CREATED_S = 0.0


def write_twin(run: TwinRun, out_dir: str | Path, *,
               format: RecordingFormat = "mat5") -> list[Path]:
    """Write every record as ``<name>.mat`` (or ``.h5`` for NeXus) and ``twin_truth.json``.

    ``twin_truth.json`` is ``run.truth`` with its ``format`` and ``format_version``
    (:data:`fsmbench.twin.truth.TRUTH_FORMAT`). Each file is written atomically;
    returns the paths written.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, ds in run.recordings.items():
        path = out / f"{name}{_suffix(format)}"
        write_recording(ds, path, format=format, created=TWIN_CREATED_S)
        paths.append(path)
    paths.append(_write_truth(run, out))
    return paths


def _suffix(format: RecordingFormat) -> str:
    """A record's file suffix in ``format``."""
    return ".h5" if format == "nexus" else ".mat"


def _write_truth(run: TwinRun, out: Path) -> Path:
    """``out/twin_truth.json``: ``run.truth`` with its format and version."""
    truth_path = out / "twin_truth.json"
    name, version = TRUTH_FORMAT
    atomic_write_text(truth_path, format_text(stamped(run.truth, format=name, version=version),
                                              sort_keys=True))
    return truth_path


def play_excitation(sources: str | Path | Sequence[str | Path], bench: Bench | None = None, *,
                    out_dir: str | Path, seed: int = 0, duration_s: float | None = None,
                    experiments: Sequence[str] | None = None,
                    format: RecordingFormat = "mat5",
                    progress: Callable[[str], None] | None = None) -> list[Path]:
    """``fsmbench simulate --excitation FILE… [--experiments NAME…]``, written to ``out_dir``.

    Each designed excitation is played in its input's experiment
    (:func:`simulate_excitation`); ``experiments`` adds the seed's own
    experiments (those not played from a file), so one folder can hold a whole
    identification set. Two files for the same input are refused. Beside the
    records, each played excitation's description is written as
    ``excitation_<input>.json`` (its samples are in the record), so that
    ``identify`` finds the transient periods to drop, as it does in a folder of
    real recordings with ``fsmbench excite``'s JSON beside them. Returns the paths
    written.
    """

    items = [sources] if isinstance(sources, (str, Path)) else list(sources)
    played = [simulate_excitation(src, bench, seed=seed, duration_s=duration_s,
                                  progress=progress) for src in items]
    names = [next(iter(r.recordings)) for r in played]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise ValueError(f"two excitation files play {', '.join(twice)}; give one per input")
    runs = list(played)
    rest = [e for e in (experiments or ()) if e not in names]
    if rest:
        runs.append(simulate_bench(bench, seed=seed, duration_s=duration_s, experiments=rest,
                                   progress=progress))
    truth = dict(runs[-1].truth)
    truth["experiments"] = {k: v for r in runs for k, v in r.truth["experiments"].items()}
    truth["realized"] = {k: v for r in runs for k, v in r.truth["realized"].items()}
    files = [r.truth["excitation_file"] for r in played]
    truth.pop("excitation_file", None)
    if len(files) == 1:
        truth["excitation_file"] = files[0]
    truth["excitation_files"] = files
    merged = TwinRun(recordings={k: v for r in runs for k, v in r.recordings.items()},
                     truth=truth, seed=seed,
                     experiments=tuple(e for r in runs for e in r.experiments))
    paths = write_twin(merged, out_dir, format=format)
    for src in items:
        meta = json.loads(find_description(src).read_text("utf-8"))
        meta["played_as"] = ("the description of the excitation played; its samples are "
                             f"{meta['input']} in the record")
        paths.append(atomic_write_text(Path(out_dir) / f"excitation_{meta['input'].lower()}.json",
                                       json.dumps(meta, indent=2) + "\n"))
    return paths
