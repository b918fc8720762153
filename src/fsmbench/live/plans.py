"""Bluesky plans for the live bench: the study's identification experiments, in open and
closed loop, through a RunEngine, and the identification of their files.

- :func:`identification_experiments`: the six open-loop experiments of the ESRF study's
  identification (section 2: ``data_cal_pd_h``/``_v``, ``data_uch``/``_ucv``,
  ``data_unh``/``_unv``), each by the device's ``RunExperiment`` with the study's
  protocol; the files (the study's ``.mat`` layout) gathered into a folder;
- :func:`closed_loop_experiments`: with the loop closed, a beam-bounded multisine on each
  Sercalo command (:func:`fsmbench.excite.shaped.beam_bounded_measurement`, as ``fsmbench
  simulate --closed-loop``) played by ``StartExcitation`` and recorded by ``Record``;
  written as ``data_cl_uch.mat`` and ``data_cl_ucv.mat``, the layout
  :func:`fsmbench.ident.closed_loop.identify_closed_loop` reads;
- :func:`closed_loop_identification`: ``fsmbench tune``'s two-stage closed-loop
  measurement (locate the resonances, then refine around them) played the same way, each
  stage identified between the records off the RunEngine's loop; the identification's
  files written (a folder ``--bench`` takes);
- :func:`identify_records`: the follow-up call, the folder's records to
  :func:`fsmbench.api.identify` (open loop) or to the closed-loop identification.

Each plan is one Bluesky run (start, an event of the bench's readings after each
experiment, stop) and returns :class:`BenchRecords` (``RE(plan).plan_result`` with
``RunEngine(call_returns_result=True)``). A refused command fails the plan with the
device's :class:`~fsmbench.live.ophyd.CommandRefusedError`.

The device writes its files in its own output folder (``fsmbench serve --out``); the
plans read them from there, so the folder must be reachable from where the RunEngine runs
(the same host, or a shared file system), and the closed-loop excitation files the plan
writes in ``folder`` must be readable by the device.
"""

from __future__ import annotations

import functools
import json
import shutil
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import bluesky.plan_stubs as bps
import bluesky.preprocessors as bpp
import numpy as np

from fsmbench import api
from fsmbench.atomic import atomic_write_text
from fsmbench.bench.params import default_bench
from fsmbench.control.loaded import running_controller
from fsmbench.excite.shaped import beam_bounded_measurement
from fsmbench.ident.closed_loop import (
    identify_closed_loop,
    read_closed_loop_records,
    write_closed_loop_identification,
)
from fsmbench.io.recording import make_recording, read_recording, write_recording
from fsmbench.jsonutil import format_text, stamped
from fsmbench.live.ophyd import FsmBenchDevice
from fsmbench.live.plan_stubs import (
    Plan,
    excitation_start,
    execute,
    in_thread,
    stand_down,
    wait_bench_time,
    wait_until_done,
)
from fsmbench.sim.excitation import SampledExcitation, samples_sha256
from fsmbench.tune.measure import MeasurementOptions, StageRequest, measurement_steps
from fsmbench.twin.closed_loop import (
    CLOSED_LOOP_EXPERIMENTS,
    CLOSED_LOOP_SIGNALS,
    excitation_variable,
)
from fsmbench.twin.experiments import ExperimentSpec
from fsmbench.twin.simulate import TwinRun

if TYPE_CHECKING:
    from fsmbench.bench.params import Bench
    from fsmbench.tune.measure import (
        ClosedLoopMeasurement,
        MeasurementOptions,
        MeasurementSteps,
        StageRequest,
    )
    from fsmbench.twin.simulate import TwinRun

__all__ = ["IDENTIFICATION_EXPERIMENTS", "BenchRecords", "ClosedLoopIdentificationRun",
           "closed_loop_experiments", "closed_loop_identification", "design_excitations",
           "execute", "identification_experiments", "identify_records", "wait_until_done"]

#: The ESRF study's identification experiments (section 2), as the twin plays them.
IDENTIFICATION_EXPERIMENTS = ("data_cal_pd_h", "data_cal_pd_v", "data_uch", "data_ucv",
                              "data_unh", "data_unv")
_SETTLE_S = 4.0  # least bench time between the excitation's start and its record [s]


@dataclass(frozen=True)
class BenchRecords:
    """What a plan recorded.

    Attributes
    ----------
    folder : Path
        Where the records are (``<experiment>.mat``).
    files : dict of str to Path
        Each experiment's file in ``folder``.
    kind : {"open loop", "closed loop"}
    address : str
        The device.
    controller : str
        The device's controller during the records (closed loop) or as found.
    bench_s : float
        Bench time the plan took [s].
    excitations : dict of str to Path
        The closed-loop excitations played (``excitation_Uch.npy`` …; open loop: none).
    """

    folder: Path
    files: dict[str, Path]
    kind: str
    address: str
    controller: str
    bench_s: float
    excitations: dict[str, Path] = field(default_factory=dict)


def _gather(path: Path, folder: Path, name: str) -> Path:
    """The device's file copied into ``folder`` as ``name.mat`` (unless it is there)."""
    if not path.is_file():
        raise FileNotFoundError(f"the device's file {path} is not readable here: run the "
                                "plan where the device's output folder is reachable")
    target = folder / f"{name}{path.suffix}"
    if target.resolve() != path.resolve():
        shutil.copyfile(path, target)
    return target


def identification_experiments(bench: FsmBenchDevice, folder: str | Path, *,
                               experiments: Sequence[str] = IDENTIFICATION_EXPERIMENTS,
                               md: Mapping[str, Any] | None = None) -> Plan:
    """The ESRF study's open-loop identification experiments on the live bench (a plan).

    Parameters
    ----------
    bench : FsmBenchDevice
        Connected (:func:`fsmbench.live.ophyd.bench_device`).
    folder : str or Path
        Where the records are gathered (made if missing).
    experiments : sequence of str
        The experiments, each by the device's ``RunExperiment`` (the study's protocol:
        excitation, length, environment; the loop as the experiment needs, then restored).
    md : mapping, optional
        Added to the run's start document.

    Returns
    -------
    BenchRecords
        As the plan's result; identify them with :func:`identify_records`.

    Examples
    --------
    >>> from bluesky import RunEngine                                    # doctest: +SKIP
    >>> from ophyd_async.plan_stubs import ensure_connected              # doctest: +SKIP
    >>> RE = RunEngine(call_returns_result=True)                         # doctest: +SKIP
    >>> bench = bench_device("ca://BL1")                                 # doctest: +SKIP
    >>> RE(ensure_connected(bench))                                      # doctest: +SKIP
    >>> records = RE(identification_experiments(bench, "ident")).plan_result  # doctest: +SKIP
    >>> result = identify_records(records)                               # doctest: +SKIP
    """
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    controller = yield from bps.rd(bench.controller)
    t0 = yield from bps.rd(bench.bench_time)
    files: dict[str, Path] = {}

    def body() -> Plan:
        for name in experiments:
            path = yield from execute(bench.run_experiment,
                                      json.dumps({"name": name, "overwrite": True}))
            yield from wait_until_done(bench, f"RunExperiment {name}")
            files[name] = _gather(Path(path), out, name)
            yield from bps.trigger_and_read([bench], name="experiments")

    yield from bpp.finalize_wrapper(
        bpp.run_wrapper(body(), md={"plan_name": "fsmbench_identification_experiments",
                                    "experiments": list(experiments), "folder": str(out),
                                    "device": bench.address, **(md or {})}),
        functools.partial(stand_down, bench, open_loop=False))
    t1 = yield from bps.rd(bench.bench_time)
    return BenchRecords(folder=out, files=files, kind="open loop", address=bench.address,
                        controller=str(controller), bench_s=float(t1 - t0))


def design_excitations(*, model: Any = None, controller: str | Path | None = None,
                       max_error_rad: float = 30e-6,
                       resolution_hz: float = 0.25) -> dict[str, np.ndarray]:
    """One period of the beam-bounded multisine on each Sercalo command, for
    :func:`closed_loop_experiments` (a computation of seconds: design once, play often).

    Parameters
    ----------
    model : Bench, optional
        The bench model the excitation is designed on (default: the packaged bench).
    controller : str or Path, optional
        The loop's controller, as ``fsmbench simulate --closed-loop`` takes it (default:
        the ESRF study's, which the device closes with when it has none loaded).
    max_error_rad : float
        The bound on the rms beam error the excitation adds, on the model [rad].
    resolution_hz : float
        The line spacing [Hz]: the period is ``1 / resolution_hz``.

    Returns
    -------
    dict of str to ndarray
        ``Uch`` and ``Ucv``: one period of commands [V] at the bench's rate
        (:func:`fsmbench.excite.shaped.beam_bounded_measurement`).
    """

    bench_model = model if model is not None else default_bench()
    k = running_controller(None if controller is None else str(controller), bench=bench_model)
    out = {}
    for ch in CLOSED_LOOP_EXPERIMENTS:
        m = beam_bounded_measurement(
            bench=bench_model,
            params=bench_model.nominal if bench_model.model is None else bench_model.true,
            controller=k.feedback, channel=ch, max_error_rad=max_error_rad,
            resolution_hz=resolution_hz, periods=1, transient_periods=0,
            controller_name=k.name)
        out[ch] = np.asarray(m.design.samples_v, dtype=float)
    return out


def _record_closed_loop(bench: FsmBenchDevice, npy: Path, x: np.ndarray, *, periods: int,
                        fs_hz: float, channel: str, source: str) -> Plan:
    """One period ``x`` [V] played on ``channel``, repeated, with the loop closed; after a
    period of bench time (at least :data:`_SETTLE_S`) ``periods`` whole periods recorded and
    written next to ``npy`` as ``data_cl_<ch>.mat`` with the excitation as it was played
    (placed by the bench time the device's ``Excitation`` says it started); its path."""

    name = CLOSED_LOOP_EXPERIMENTS[channel]
    np.save(npy, x)
    yield from execute(bench.start_excitation, json.dumps(
        {"input": channel, "kind": "samples", "path": str(npy.resolve()), "loop_from": 0}))
    e0 = yield from excitation_start(bench, samples_sha256(x))
    # The loop's transient decays before the record: the Sercalo's modes (time constant
    # 1 / (zeta w) ~0.6 s at 251 Hz, 0.1 %) ring for seconds; a whole period (4 s at the
    # default 0.25 Hz) and at least _SETTLE_S.
    yield from wait_bench_time(bench, e0 + max(_SETTLE_S, x.size / fs_hz))
    n = periods * x.size
    path = yield from execute(bench.record, json.dumps(
        {"signals": list(CLOSED_LOOP_SIGNALS), "name": f"bluesky_{name}",
         "duration_s": n / fs_hz, "overwrite": True}))
    yield from wait_until_done(bench, f"the record of {name}")
    yield from execute(bench.stop_excitation)
    rec = read_recording(path, require=())
    if rec.sizes["t"] != n:
        status = yield from bps.rd(bench.status)
        raise RuntimeError(f"{bench.address}: the record of {name} holds {rec.sizes['t']} "
                           f"samples of {n} (cut short): {status}")
    r0 = round(float(rec["t"].values[0]) * fs_hz)
    # The sample of the (repeated) excitation each recorded sample was played with.
    played = x[(r0 - round(e0 * fs_hz) + np.arange(n)) % x.size]
    signals = {s: np.asarray(rec[s].values, dtype=float) for s in CLOSED_LOOP_SIGNALS}
    signals[excitation_variable(channel, "output")] = played
    ds = make_recording(signals, fs_hz=fs_hz, experiment=name, source=source)
    return write_recording(ds, npy.parent / f"{name}.mat")


def _checked_excitations(excitations: Mapping[str, np.ndarray] | None,
                         design: Mapping[str, Any]) -> Plan:
    """The closed-loop excitations given, else designed off the RunEngine's loop
    (:func:`design_excitations` with ``design``); one for each Sercalo command."""
    if excitations is None:
        excitations = yield from in_thread(functools.partial(design_excitations, **design))
    missing = [ch for ch in CLOSED_LOOP_EXPERIMENTS if ch not in excitations]
    if missing:
        raise ValueError(f"closed_loop_experiments needs an excitation for {', '.join(missing)}")
    return excitations


def _closed_loop_run(bench: FsmBenchDevice, play: Callable[[str], Plan], *,
                     md: dict[str, Any]) -> Plan:
    """One Bluesky run with the loop closed; the device's controller and the bench time the
    run took [s].

    ``CloseLoop`` when the loop is open, then ``play`` with the name of the device's
    controller; the bench stood down at the end, whatever happened (``OpenLoop`` when the
    run closed the loop). ``md`` is the run's start document.
    """
    t0 = yield from bps.rd(bench.bench_time)
    closes = not (yield from bps.rd(bench.loop_closed))
    running: list[str] = []

    def body() -> Plan:
        if closes:
            yield from execute(bench.close_loop)
        running.append(str((yield from bps.rd(bench.controller))))
        yield from play(running[0])

    yield from bpp.finalize_wrapper(bpp.run_wrapper(body(), md=md),
                                    functools.partial(stand_down, bench, open_loop=closes))
    t1 = yield from bps.rd(bench.bench_time)
    return running[0], float(t1 - t0)


def closed_loop_experiments(bench: FsmBenchDevice, folder: str | Path, *,
                            excitations: Mapping[str, np.ndarray] | None = None,
                            periods: int = 6, md: Mapping[str, Any] | None = None,
                            **design: Any) -> Plan:
    """A closed-loop identification's records on the live bench (a plan).

    With the loop closed (``CloseLoop`` when it is open, ``OpenLoop`` at the end), for each
    command ``Uch`` and
    ``Ucv``: one period of excitation (``excitations``, or the beam-bounded multisine of
    :func:`design_excitations`) is written to ``folder/excitation_<ch>.npy`` and played by
    ``StartExcitation`` as a ``samples`` excitation repeated from its first sample; after
    a period of bench time (at least :data:`_SETTLE_S`: the loop's transient) ``Record``
    takes ``periods`` whole periods of the loop's signals; ``StopExcitation``. The record
    and the excitation as it was played during it (placed by the bench time the device's
    ``Excitation`` says it started) are written as ``data_cl_uch.mat`` /
    ``data_cl_ucv.mat`` (``t``, ``Xch``/``Xcv``, ``Uch``, ``Ucv``, ``Vph``, ``Vpv``,
    ``Vch``, ``Vcv``: the layout of ``fsmbench simulate --closed-loop``). The excitation
    is in steady state from the record's first sample (the record holds no loop before
    it), so the latency between the plan and the device never shifts it.

    Parameters
    ----------
    bench : FsmBenchDevice
    folder : str or Path
    excitations : mapping of str to ndarray, optional
        ``Uch`` and ``Ucv``: one period of commands each [V] at the bench's rate.
    periods : int
        Whole periods recorded per command.
    md : mapping, optional
        Added to the run's start document.
    **design
        :func:`design_excitations`'s options when ``excitations`` is not given.

    Returns
    -------
    BenchRecords

    Notes
    -----
    One stage at the default bound gives the resonances, the Sercalo's static gains, the
    current amplifiers and the delay within the open-loop identification's targets, and
    the h damping within 19 % (17 runs on the twin); the v damping, whose excitation the
    bound keeps at half the h one, came out 2.8, 5.8 and 10 times the true value in 3 of
    them. ``fsmbench tune``'s two-stage measurement (locate the resonances, then refine
    around them, :func:`fsmbench.tune.measure.measure_closed_loop`) is what brings the
    damping within its target.
    """

    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    fs = float((design.get("model") or default_bench()).true.converter.fs_hz)
    played = yield from _checked_excitations(excitations, design)
    files: dict[str, Path] = {}
    npys: dict[str, Path] = {}

    def play(controller: str) -> Plan:
        for ch, name in CLOSED_LOOP_EXPERIMENTS.items():
            x = np.asarray(played[ch], dtype=float)
            npys[ch] = out / f"excitation_{ch}.npy"
            files[name] = yield from _record_closed_loop(
                bench, npys[ch], x, periods=periods, fs_hz=fs, channel=ch,
                source=f"fsmbench Bluesky plan through {bench.address} (loop closed by "
                       f"{controller})")
            yield from bps.trigger_and_read([bench], name="experiments")

    controller, bench_s = yield from _closed_loop_run(
        bench, play, md={"plan_name": "fsmbench_closed_loop_experiments", "folder": str(out),
                         "device": bench.address, "periods": periods, **(md or {})})
    return BenchRecords(folder=out, files=files, kind="closed loop", address=bench.address,
                        controller=controller, bench_s=bench_s, excitations=npys)


@dataclass(frozen=True, eq=False)
class ClosedLoopIdentificationRun:
    """What :func:`closed_loop_identification` measured and identified.

    Attributes
    ----------
    folder : Path
        ``identification.json``, ``plant.mat``, ``frf.mat`` (the identification, a folder
        ``--bench`` takes) and ``measurement.json`` (each stage's designs and tracking).
    stage_folders : tuple of Path
        Each stage's records (``data_cl_uch.mat``, ``data_cl_ucv.mat``) and excitations.
    measurement : fsmbench.tune.measure.ClosedLoopMeasurement
        Both stages and the identification from them (``.identification``).
    files : tuple of Path
        The files written in ``folder``.
    address, controller : str
        The device, and its controller during the records.
    bench_s : float
        Bench time the plan took [s].
    """

    folder: Path
    stage_folders: tuple[Path, ...]
    measurement: ClosedLoopMeasurement
    files: tuple[Path, ...]
    address: str
    controller: str
    bench_s: float


def _advance(steps: MeasurementSteps, records: TwinRun | None
             ) -> StageRequest | ClosedLoopMeasurement:
    """The protocol's next stage request, or its result once it returns."""
    try:
        return next(steps) if records is None else steps.send(records)
    except StopIteration as done:
        return done.value


def _play_stage(bench: FsmBenchDevice, folder: Path, request: StageRequest, *, fs_hz: float,
                controller: str) -> Plan:
    """One stage's designs played through the device (:func:`_record_closed_loop`: the
    steady-state period repeated, ``transient + steady`` periods recorded); its records as
    :func:`fsmbench.tune.measure.measurement_steps` takes them."""

    folder.mkdir(parents=True, exist_ok=True)
    specs = []
    for play, measured in zip(request.plays, request.designs, strict=True):
        d = measured.design
        x = np.asarray(d.samples_v[-d.period_samples:], dtype=float)
        periods = d.periods + d.transient_periods
        yield from _record_closed_loop(
            bench, folder / f"excitation_{play.channel}.npy", x, periods=periods, fs_hz=fs_hz,
            channel=play.channel, source=f"fsmbench Bluesky plan through {bench.address}, "
            f"{request.label} (loop closed by {controller})")
        specs.append(ExperimentSpec(
            name=play.name, description=f"{play.description} on {play.channel} (controller "
            f"output, in steady state), loop closed by {controller}, through {bench.address}",
            seed_section="closed loop", duration_s=periods * x.size / fs_hz,
            excitations=(SampledExcitation(play.channel, "samples",
                                           float(np.sqrt(np.mean(x**2))), 0.0, samples_v=x,
                                           loop_from=0),),
            closed_loop=True, compensation_unit=True, shielding=True))
    yield from bps.trigger_and_read([bench], name="experiments")
    recordings = yield from in_thread(functools.partial(read_closed_loop_records, folder))
    return TwinRun(recordings=recordings, truth={"source": bench.address}, seed=request.seed,
                   experiments=tuple(specs))


def _measure_in_stages(bench: FsmBenchDevice, out: Path, steps: MeasurementSteps, *,
                       fs_hz: float, controller: str, stages: list[Path]) -> Plan:
    """Each stage the protocol asks for played into ``out/stage_<n>`` (appended to
    ``stages``) and identified off the RunEngine's loop; the measurement once it returns.

    Parameters
    ----------
    steps : MeasurementSteps
        The protocol (:func:`fsmbench.tune.measure.measurement_steps`), not started.
    fs_hz : float
        The bench's sampling rate [Hz].
    controller : str
        The device's controller, for the records' source.
    """
    step = yield from in_thread(functools.partial(_advance, steps, None))
    while isinstance(step, StageRequest):
        stages.append(out / f"stage_{len(stages) + 1}")
        run = yield from _play_stage(bench, stages[-1], step, fs_hz=fs_hz,
                                     controller=controller)
        step = yield from in_thread(functools.partial(_advance, steps, run))
    return step


def _write_measurement(measurement: ClosedLoopMeasurement, out: Path, *, address: str,
                       controller: str) -> list[Path]:
    """The identification's files and ``measurement.json`` (each stage's designs and
    tracking, with the device and its controller) written in ``out``; their paths."""
    files = write_closed_loop_identification(measurement.identification, out)
    files.append(atomic_write_text(out / "measurement.json", format_text(stamped(
        {"device": address, "controller": controller, **measurement.to_json()},
        format="fsmbench.closed_loop_measurement", version=1))))
    return files


def closed_loop_identification(bench: FsmBenchDevice, folder: str | Path, *,
                               model: Bench | None = None,
                               controller: str | Path | None = None,
                               options: MeasurementOptions | None = None, seed: int = 0,
                               md: Mapping[str, Any] | None = None) -> Plan:
    """The Sercalo measured and identified with the loop closed, in two stages (a plan).

    ``fsmbench tune``'s measurement (:func:`fsmbench.tune.measure.measurement_steps`, one
    protocol for the twin, the device and this plan): stage 1 locates the resonances with
    a beam-bounded multisine on each command (±5 % bands, 0.85 of the bound, designed on
    ``model``); stage 2 refines around the located ones (±0.2 %), the plant fitted on both
    stages' lines. Each stage is played as :func:`closed_loop_experiments` plays its
    excitations (its steady-state period repeated, recorded whole periods after a period
    of settling) and identified between the stages off the RunEngine's loop. One stage
    leaves the dampings short of their targets (the v damping 2.8 to 10 times, the h one
    +63 % once in 9 runs on the twin); the two stages bring them within.

    Parameters
    ----------
    bench : FsmBenchDevice
    folder : str or Path
        Where the stages' records and the identification go (made if missing).
    model : Bench, optional
        The bench file the excitations are designed on and the 4QD gains and Newport come
        from (default: the packaged bench).
    controller : str or Path, optional
        The controller the device runs, as ``fsmbench simulate --closed-loop`` takes it
        (default: the ESRF study's, which the device closes with when it has none
        loaded); the plan fails when the device's ``Controller`` names another.
    options : fsmbench.tune.measure.MeasurementOptions, optional
        The bound (``max_error_rad``, 30 µrad), resolution, periods, stages.
    seed : int
        The stages' seeds, as ``tune`` numbers them (the device ignores them).
    md : mapping, optional
        Added to the run's start document.

    Returns
    -------
    ClosedLoopIdentificationRun
    """

    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    bench_model = model if model is not None else default_bench()
    opts = options or MeasurementOptions()
    if opts.at != "output":
        raise ValueError("the device adds an excitation at the controller's output, not at "
                         "the reference: MeasurementOptions(at='output')")
    fs = float(bench_model.true.converter.fs_hz)
    k = yield from in_thread(functools.partial(
        running_controller, None if controller is None else str(controller), bench=bench_model))
    stages: list[Path] = []
    done: list[ClosedLoopMeasurement] = []

    def play(running: str) -> Plan:
        if running != k.name:
            raise ValueError(f"{bench.address} runs {running}; the excitations would be "
                             f"designed on {k.name} and their beam bound would not hold: "
                             "give controller= the file of the device's controller")
        steps = measurement_steps(model=bench_model, controller=k, options=opts, seed=seed)
        done.append((yield from _measure_in_stages(bench, out, steps, fs_hz=fs,
                                                   controller=running, stages=stages)))

    running, bench_s = yield from _closed_loop_run(
        bench, play, md={"plan_name": "fsmbench_closed_loop_identification",
                         "folder": str(out), "device": bench.address,
                         "max_error_rad": opts.max_error_rad, **(md or {})})
    measurement = done[0]
    files = _write_measurement(measurement, out, address=bench.address, controller=running)
    return ClosedLoopIdentificationRun(
        folder=out, stage_folders=tuple(stages), measurement=measurement, files=tuple(files),
        address=bench.address, controller=running, bench_s=bench_s)


def identify_records(records: BenchRecords, *, model: Any = None,
                     out_dir: str | Path | None = None) -> Any:
    """Identify the plant from a plan's records (the follow-up call).

    Parameters
    ----------
    records : BenchRecords
        From :func:`identification_experiments` (open loop: :func:`fsmbench.api.identify`
        on the folder's records) or :func:`closed_loop_experiments`
        (:func:`fsmbench.ident.closed_loop.identify_closed_loop`, the bench's 4QD gains
        from ``model``).
    model : Bench, optional
        The bench file (default: the packaged bench).
    out_dir : str or Path, optional
        Also write the identification's files there (open loop: ``identification.json``,
        ``plant.mat``, ``frf.mat``; closed loop: its JSON and plant).

    Returns
    -------
    Identification or ClosedLoopIdentification
    """

    bench = model if model is not None else default_bench()
    if records.kind == "closed loop":
        result = identify_closed_loop(read_closed_loop_records(records.folder), bench=bench,
                                      source=f"{records.folder} ({records.address})")
        if out_dir is not None:
            write_closed_loop_identification(result, Path(out_dir))
        return result

    loaded = api.load_recordings(records.folder, bench=bench)
    recordings = {k: v for k, v in loaded.recordings.items() if k in records.files}
    return api.identify(recordings, bench=bench, out_dir=out_dir)
