"""The Sercalo measured with the loop closed, in two stages, within a beam-error bound.

A closed-loop measurement's precision on a line is the ratio of the command the
excitation makes to the noise entering with it (the coils' own noise, which the
Sercalo's resonance filters as it filters the command): the joint estimate
``G = S_yr S_ur^-1`` is unbiased, but its variance near a 0.1 %-damped
resonance is that ratio, and the beam-error bound caps the command there,
where the beam moves most. Spreading the resonance band's share over every line
of ±5 % (where a drifted resonance may be) leaves each line too little: the
damping comes out to ±30 % on the twin. So :func:`measure_closed_loop`:

1. **locates**: a beam-bounded shaped multisine
   (:func:`fsmbench.excite.shaped.beam_bounded_measurement`) on each command,
   its resonance band ±5 % around the model's resonance, shaped over the
   design's robust set; the record is identified
   (:func:`fsmbench.ident.closed_loop.identify_closed_loop`);
2. **refines**: the same design around the *located* resonance
   (:func:`located_bench`), its band and robust set narrowed to ``refine_width``
   (±0.2 % by default, ten times the located frequency's standard deviation),
   so that the band's share of the budget falls on the few lines that carry the
   mode; the plant is fitted on both stages' lines (the union, a line both
   measured by its inverse-variance mean:
   :func:`fsmbench.ident.frf.closed_loop_merge.merge_closed_loop_frf`). Stage 2
   alone starves the lines far from the modes (its fit failed on coherence once
   in 6 ``real_bench.toml`` runs, and put the h mode at the v mode's frequency
   once in 8 twin runs) and throws away half the measurement time; merged, the
   damping came within 25 % on 12 / 12 ``real_bench.toml`` axis-runs (10 / 12
   from stage 2 alone).

Both stages' records and their tracking errors are kept; the measurement time is
their sum.
"""

from __future__ import annotations

import dataclasses
import math
import tempfile
from collections.abc import Callable, Generator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fsmbench.bench.axes import PerAxis
from fsmbench.bench.params import Bench
from fsmbench.control.controller import Controller
from fsmbench.excite.closed_loop import robust_loops
from fsmbench.excite.shaped import BoundedMeasurement, beam_bounded_measurement
from fsmbench.ident.closed_loop import (
    ClosedLoopIdentification,
    ClosedLoopIdentifyOptions,
    identify_closed_loop,
    write_closed_loop_identification,
)
from fsmbench.ident.frf.closed_loop import ClosedLoopFrf
from fsmbench.ident.load import load_identified_plant, read_identification_json
from fsmbench.twin.closed_loop import CLOSED_LOOP_EXPERIMENTS, ClosedLoopPlay, play_closed_loop
from fsmbench.twin.draws import PARAMETERS, perturbed_bench
from fsmbench.twin.identified import bench_from_identification
from fsmbench.twin.simulate import TwinRun

__all__ = [
    "ClosedLoopMeasurement",
    "MeasurementOptions",
    "MeasurementSteps",
    "Player",
    "RecordsRejectedError",
    "StageRequest",
    "identified_model",
    "located_bench",
    "measure_closed_loop",
    "measurement_steps",
    "model_excess",
    "not_located",
]


#: ``play(plays, controller=, settle_s=, seed=, progress=)``: the closed-loop records.
Player = Callable[..., TwinRun]


@dataclass(frozen=True)
class MeasurementOptions:
    """How the closed-loop measurement is made.

    Attributes
    ----------
    max_error_rad : float
        The bound on the rms beam error the measurement adds [rad].
    resolution_hz : float
        Multisine resolution [Hz] (odd lines: twice that apart).
    periods : int
        Steady-state periods of each stage.
    transient_periods : int
        Periods played first and dropped (the slowest closed-loop mode, the
        notched resonance, has a ~0.75 s time constant: 2 periods of 4 s leave
        ``exp(-8/0.75)`` of it).
    refine : bool
        Run the second stage.
    refine_width : float
        Half-width of the refined resonance band, relative [1] (±0.5 Hz at 251 Hz:
        ten times stage 1's frequency standard deviation on the twin, ~0.05 Hz).
    fill : float
        Fraction of the bound stage 2 uses (the rest is margin), in (0, 1]; less
        when stage 1 measured more beam error than its design predicted
        (:func:`model_excess`: stage 2 divides by that ratio).
    first_fill : float
        Fraction of the bound stage 1 uses, designed on a model not yet checked
        against the bench: on ``real_bench.toml`` (seed 5) the bench file's
        model under-predicted the vertical beam's response to ``Uch`` by 12 %
        (the cross-axis response), and 0.9 of the bound measured 30.4 µrad
        against 30; 0.75 lost stage 1's precision (seed 7's vertical damping
        +1300 %, and stage 2 refined around the wrong frequency). 0.85: every
        tolerance met and at most 28.8 µrad added on seeds 1-20 of
        ``real_bench.toml`` and 1-16 of the twin.
    at : {"output", "reference"}
    settle_s : float
        Loop closed, nothing played, before each stage's excitation [s].
    """

    max_error_rad: float = 30e-6
    resolution_hz: float = 0.25
    periods: int = 6
    transient_periods: int = 2
    refine: bool = True
    refine_width: float = 0.002
    fill: float = 0.9
    first_fill: float = 0.85
    at: str = "output"
    settle_s: float = 1.0

    def to_json(self) -> dict[str, Any]:
        """Plain values."""
        return dataclasses.asdict(self)


@dataclass(frozen=True, eq=False)
class ClosedLoopMeasurement:
    """Both stages of a closed-loop measurement.

    Attributes
    ----------
    identification : ClosedLoopIdentification
        From the last stage's records (stage 1's when stage 2's could not be fitted).
    stages : tuple of (ClosedLoopIdentification, TwinRun, tuple of BoundedMeasurement)
        Each stage's identification, records and designs (a stage 1 that located no
        resonance and was measured again first, its records counted in the duration).
    duration_s : float
        Measurement time, both stages and both commands [s].
    options : MeasurementOptions
    note : str
        Why stage 1 was measured again, and why the identification is not the last
        stage's ('' when neither).
    model_excess : float
        Stage 1's measured over predicted beam error (≥ 1; stage 2's fill was
        divided by it).
    """

    identification: ClosedLoopIdentification
    stages: tuple[tuple[ClosedLoopIdentification, TwinRun, tuple[BoundedMeasurement, ...]], ...]
    duration_s: float
    options: MeasurementOptions
    note: str = ""
    model_excess: float = 1.0

    def tracking_added_rad(self) -> dict[str, float]:
        """Largest rms beam error the measurement added per axis, over stages and records [rad]."""
        out = {"h": 0.0, "v": 0.0}
        for ident, _run, _designs in self.stages:
            for t in ident.tracking:
                for axis, value in t.added_rms_rad.items():
                    if value == value:  # NaN: not measurable
                        out[axis] = max(out[axis], float(value))
        return out

    def to_json(self) -> dict[str, Any]:
        """Per stage: the designs' predicted beam error, the tracking measured, the duration."""
        stages = []
        for ident, run, designs in self.stages:
            stages.append({
                "duration_s": float(sum(s.duration_s for s in run.experiments)),
                "designs": [{"input": d.design.input, "amplitude_rms_v": d.design.amplitude_rms_v,
                             "lines": int(d.design.lines_hz.size),
                             "worst_model_beam_rms_rad": d.worst_beam_rms_rad,
                             "limits": d.report.to_json()} for d in designs],
                "tracking_during_measurement": [t.to_json() for t in ident.tracking]})
        return {"options": self.options.to_json(), "duration_s": self.duration_s,
                "note": self.note, "model_excess": self.model_excess,
                "added_beam_error_rms_rad": self.tracking_added_rad(), "stages": stages}


def identified_model(ident: ClosedLoopIdentification, *, bench: Bench,
                     label: str = "") -> Bench:
    """The bench the identification describes, as every simulation and design takes it.

    Raises
    ------
    ValueError
        The Sercalo was not identified (the reason named).
    """

    if ident.plant is None:
        raise ValueError(f"the Sercalo was not identified in closed loop: "
                         f"{ident.skipped.get('sercalo', 'no plant')}")
    with tempfile.TemporaryDirectory(prefix="fsmbench-cl-") as tmp:
        write_closed_loop_identification(ident, tmp)
        path, js = read_identification_json(tmp)
        plant = load_identified_plant(Path(tmp)).plant
        return bench_from_identification(js, plant=plant, bench=bench, path=path,
                                         label=label or "the bench identified in closed loop")


def located_bench(model: Bench, ident: ClosedLoopIdentification) -> Bench:
    """``model`` with its Sercalo resonances moved to where ``ident`` found them.

    Only the resonances: stage 2 needs where the modes are, not a whole
    identified plant (which may carry a fit warning that stage 2 removes).

    Raises
    ------
    ValueError
        ``ident`` found no resonance on an axis (named).
    """

    if (why := not_located(ident)):
        raise ValueError(f"stage 1 found {why}")
    found = ident.to_json()["sercalo"]
    f_hz = {a: float(found[a]["resonance_hz"]) for a in ("h", "v")}
    if model.model is not None:
        values = model.model.values.get("sercalo") or {}
        factors = {k: (0.0 if k.endswith("_s") else 1.0) for k in PARAMETERS}
        factors.update({f"resonance_scale.{a}": f_hz[a] / float(values[a]["resonance_hz"])
                        for a in ("h", "v")})
        return perturbed_bench(model, factors)
    res = PerAxis(h=f_hz["h"], v=f_hz["v"])
    return dataclasses.replace(
        model,
        nominal=dataclasses.replace(model.nominal, sercalo=dataclasses.replace(
            model.nominal.sercalo, resonance_hz=res)),
        true=dataclasses.replace(model.true, sercalo=dataclasses.replace(
            model.true.sercalo, resonance_hz=res)),
        origin=f"{model.origin} (resonances located in closed loop)")


def model_excess(ident: ClosedLoopIdentification,
                 designs: Sequence[BoundedMeasurement]) -> float:
    """How much more beam error a stage's records show than its designs predicted (≥ 1).

    Per command, the largest added rms over the two beam axes (the synchronous
    average, :class:`fsmbench.ident.closed_loop.TrackingDuringMeasurement`)
    over the design's worst model's rms; the largest over the commands, at
    least 1. Not measurable (NaN) counts as 1.
    """

    ratio = 1.0
    tracking = {t.record: t for t in ident.tracking}
    for d in designs:
        t = tracking.get(CLOSED_LOOP_EXPERIMENTS.get(d.design.input, ""))
        if t is None or not d.worst_beam_rms_rad > 0:
            continue
        added = [v for v in t.added_rms_rad.values() if math.isfinite(v)]
        if added:
            ratio = max(ratio, max(added) / d.worst_beam_rms_rad)
    return ratio


@dataclass(frozen=True, eq=False)
class StageRequest:
    """One stage's excitations, for whatever plays them (the twin, the device, a plan).

    Attributes
    ----------
    plays : tuple of ClosedLoopPlay
        One per command, each its whole design (transient periods first).
    designs : tuple of BoundedMeasurement
        The designs the plays come from (period, periods, predicted beam error).
    settle_s : float
        Loop closed, nothing played, before each excitation [s].
    seed : int
        The stage's noise seed (the twin's; a device ignores it).
    label : str
        The stage, in words (``stage 1``, ``stage 1 again``, ``stage 2``).
    """

    plays: tuple[ClosedLoopPlay, ...]
    designs: tuple[BoundedMeasurement, ...]
    settle_s: float
    seed: int
    label: str


#: The two-stage protocol (:func:`measurement_steps`): yields each stage's request,
#: is sent its records, returns the measurement.
MeasurementSteps = Generator[StageRequest, TwinRun, ClosedLoopMeasurement]
_Stage = tuple[ClosedLoopIdentification, TwinRun, tuple[BoundedMeasurement, ...]]


def _stage_request(*, model: Bench, controller: Controller, options: MeasurementOptions,
                   dense_width: float, seed: int, prior_label: str, label: str) -> StageRequest:
    scales = (1.0 - dense_width, 1.0, 1.0 + dense_width)
    loops = robust_loops(model, controller.feedback, frequency_scales=scales)
    designs = tuple(beam_bounded_measurement(
        bench=model, params=model.nominal if model.model is None else model.true,
        controller=controller.feedback, channel=ch, max_error_rad=options.max_error_rad,
        at=options.at, resolution_hz=options.resolution_hz,
        periods=options.periods,
        transient_periods=options.transient_periods, dense_width=dense_width,
        fill=options.fill, loops=loops, controller_name=controller.name, model=prior_label)
        for ch in ("Uch", "Ucv"))
    plays = tuple(ClosedLoopPlay(channel=d.design.input, samples_v=d.design.samples_v,
                                 at=options.at,
                                 description=f"beam-bounded multisine ({prior_label})")
                  for d in designs)
    return StageRequest(plays=plays, designs=designs, settle_s=options.settle_s, seed=seed,
                        label=label)


def _stage(*, model: Bench, controller: Controller, options: MeasurementOptions,
           dense_width: float, seed: int, prior_label: str, ident_bench: Bench, label: str,
           merge_with: Sequence[ClosedLoopFrf] = ()) -> Generator[StageRequest, TwinRun, _Stage]:
    request = _stage_request(model=model, controller=controller, options=options,
                             dense_width=dense_width, seed=seed, prior_label=prior_label,
                             label=label)
    run = yield request
    try:
        ident = identify_closed_loop(
            run.recordings, bench=ident_bench,
            options=ClosedLoopIdentifyOptions(transient_periods=options.transient_periods,
                                              max_error_rad=options.max_error_rad),
            source=f"closed-loop measurement ({prior_label})", merge_with=merge_with)
    except ValueError as exc:
        raise RecordsRejectedError(str(exc)) from exc
    return ident, run, request.designs


class RecordsRejectedError(ValueError):
    """A stage's records failed their checks: the identification could not start."""


def _stage_one(*, model: Bench, controller: Controller, options: MeasurementOptions,
               seed: int, say: Callable[[str], None]
               ) -> Generator[StageRequest, TwinRun, tuple[list[_Stage], _Stage, str]]:
    """Stage 1 (the resonances located in ±5 % bands), measured once again when its records
    locate nothing; the stages before the one kept, the one kept, and what was repeated
    (in words, "" if nothing)."""

    def locate(stage_seed: int, label: str) -> Generator[StageRequest, TwinRun, _Stage]:
        return _stage(model=model, controller=controller,
                      options=dataclasses.replace(options, fill=options.first_fill),
                      dense_width=0.05, seed=stage_seed, prior_label="the bench model",
                      ident_bench=model, label=label)

    stages: list[_Stage] = []
    repeated = ""
    attempt: _Stage | None
    try:
        attempt = yield from locate(seed, "stage 1")
        why = not_located(attempt[0])
    except RecordsRejectedError as exc:  # not the device's errors: those stop tune
        attempt, why = None, str(exc)
    if not why and attempt is not None:
        first = attempt
    else:
        # A stage 1 whose records locate no resonance on an axis (before the resonance
        # search ignored isolated noisy lines, a live stage 1 kept one mode for both axes)
        # is measured again before tune gives up.
        repeated = f"stage 1 was measured again: its first records located nothing ({why})"
        say(repeated)
        if attempt is not None:
            stages.append(attempt)
        first = yield from locate(seed + 2, "stage 1 again")
        if (again := not_located(first[0])):
            raise ValueError(f"stage 1 found no Sercalo resonance in two measurements: {why}; "
                             f"then {again}")
    return stages, first, repeated


def measurement_steps(*, model: Bench, controller: Controller,
                      options: MeasurementOptions | None = None, seed: int = 0,
                      progress: Callable[[str], None] | None = None) -> MeasurementSteps:
    """The two-stage measurement as a protocol: what to play, then what was recorded.

    A generator: each ``next``/``send`` designs a stage and yields its
    :class:`StageRequest`; the caller plays it and sends the records back (a
    :class:`fsmbench.twin.simulate.TwinRun`: ``recordings`` ``data_cl_uch`` and
    ``data_cl_ucv``, and ``experiments`` for their durations). The generator's return
    value (``StopIteration.value``) is the :class:`ClosedLoopMeasurement`.
    :func:`measure_closed_loop` drives it with a blocking player;
    :func:`fsmbench.live.plans.closed_loop_identification` from a Bluesky plan.

    Parameters
    ----------
    model, controller, options, seed, progress
        As :func:`measure_closed_loop`.

    Raises
    ------
    ValueError
        (From a ``send``) stage 1 located no resonance in two measurements (named).
    """
    opts = options or MeasurementOptions()
    say = progress or (lambda _m: None)
    say("closed-loop measurement, stage 1: locating the resonances (±5 % bands)")

    stages, first, repeated = yield from _stage_one(model=model, controller=controller,
                                                    options=opts, seed=seed, say=say)
    stages.append(first)
    excess = model_excess(first[0], first[2])
    if opts.refine:
        located = located_bench(model, first[0])
        say("closed-loop measurement, stage 2: the located resonances "
            f"(±{100 * opts.refine_width:g} % bands)")
        if excess > 1.0:
            say(f"stage 1 added {excess:.3g}x the beam error its model predicted: stage 2 "
                f"uses {opts.fill / excess:.2g} of the bound")
        stages.append((yield from _stage(
            model=located, controller=controller,
            options=dataclasses.replace(opts, fill=opts.fill / excess),
            dense_width=opts.refine_width, seed=seed + 1,
            prior_label="the resonances located in stage 1", ident_bench=model,
            label="stage 2", merge_with=(first[0].frf,))))
    duration = float(sum(s.duration_s for _i, run, _d in stages for s in run.experiments))
    final, note = stages[-1][0], ""
    if final.plant is None and first[0].plant is not None:
        # The refined records starve the lines far from the modes; when they do not carry
        # the whole band (the fit names why), stage 1's identification stands.
        note = (f"stage 2 did not identify the Sercalo "
                f"({final.skipped.get('sercalo', 'no plant')}); stage 1's identification is kept")
        say(note)
        final = first[0]
    return ClosedLoopMeasurement(identification=final, stages=tuple(stages),
                                 duration_s=duration, options=opts,
                                 note="; ".join(n for n in (repeated, note) if n),
                                 model_excess=excess)


def measure_closed_loop(*, model: Bench, controller: Controller,
                        true_bench: Bench | None = None, play: Player | None = None,
                        options: MeasurementOptions | None = None, seed: int = 0,
                        progress: Callable[[str], None] | None = None) -> ClosedLoopMeasurement:
    """Measure and identify the Sercalo on ``true_bench`` with the loop closed (module notes).

    Parameters
    ----------
    true_bench : Bench, optional
        The twin played on (possibly drifted), when ``play`` is not given.
    play : callable, optional
        ``play(plays, controller=, settle_s=, seed=, progress=)`` returning the records
        (:meth:`fsmbench.tune.guarded.TuneTarget.play`: the twin's or the live device's).
    model : Bench
        What the excitation is designed on (the bench file, or an identified bench).
    controller : Controller
        The loop's running controller.
    options : MeasurementOptions, optional
    seed : int
        Noise seed of the first stage (the second uses ``seed + 1``).

    Raises
    ------
    ValueError
        The Sercalo could not be identified in the first stage (named).
    """
    if play is None:
        if true_bench is None:
            raise ValueError("measure_closed_loop needs the twin (true_bench) or a player")
        twin = true_bench

        def play(plays: Sequence[ClosedLoopPlay], *, controller: Controller,
                 settle_s: float, seed: int,
                 progress: Callable[[str], None] | None) -> TwinRun:
            return play_closed_loop(plays, bench=twin, controller=controller, seed=seed,
                                    settle_s=settle_s, progress=progress)

    steps = measurement_steps(model=model, controller=controller, options=options, seed=seed,
                              progress=progress)
    request = next(steps)
    while True:
        run = play(list(request.plays), controller=controller, settle_s=request.settle_s,
                   seed=request.seed, progress=progress)
        try:
            request = steps.send(run)
        except StopIteration as done:
            measurement: ClosedLoopMeasurement = done.value
            return measurement


def not_located(ident: ClosedLoopIdentification) -> str:
    """Why ``ident`` gives no resonance on an axis, in words ('' when it gives both)."""
    found = (ident.to_json().get("sercalo") or {})
    missing = [a for a in ("h", "v") if a not in found]
    if not missing:
        return ""
    return (f"no Sercalo resonance on axis {', '.join(missing)}: "
            f"{ident.skipped.get('sercalo', 'the fit kept no mode there')}")
