"""``fsmbench study``: the whole ESRF study on recorded data or on the twin.

Stages run left to right (docs/architecture.md): recordings (simulated by
the twin when no data folder is given) → identification → budget → design
(:mod:`fsmbench.stages`) → summary and report. A stage or part whose
experiments are missing or fail their checks is skipped or falls back, and
the summary at the top of the report says so.

Outputs (all atomic): ``report.html``, ``summary.json`` (the verdict),
``study.json`` (what ran; paths relative to the output folder, so the file
is the same wherever the folder goes), ``timings.json`` (wall time per
stage, the design's beside the budget's and the validation's: the one output that differs
between two identical runs), plus each
stage's files and, with ``figures``, ``figures/<key>.png|pdf``.

Called, ``fsmbench.study(out_dir=...)`` is the public :func:`fsmbench.api.study`.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any, Generic, TypeVar

from threadpoolctl import threadpool_limits

from fsmbench.atomic import atomic_write_text
from fsmbench.bench.blocks import PlantModel
from fsmbench.bench.params import Bench, default_bench
from fsmbench.entry import callable_module
from fsmbench.forked import ForkedSeries, start_forked_series
from fsmbench.ident.pipeline import Identification, IdentifyOptions
from fsmbench.io.folder import RecordingSet, load_recordings
from fsmbench.io.outdir import check_out_dir
from fsmbench.io.signals import EXPERIMENTS
from fsmbench.io.truth import read_twin_truth
from fsmbench.jsonutil import plain_json
from fsmbench.report.figures.static import export_figures
from fsmbench.report.html import EncodedFigures, Section, encode_figures, iter_figures, write_report
from fsmbench.report.sections.study import study_chapters, with_recorded_loop_check
from fsmbench.report.summary import (
    PartSkipped,
    Specification,
    StudyEvidence,
    Summary,
    build_summary,
)
from fsmbench.report.verdict import verdict_html
from fsmbench.stages import (
    IDENT_EXPERIMENTS,
    BudgetStage,
    DesignStage,
    PlantChoice,
    SimulationBench,
    ValidationStage,
    choose_plant,
    design_stage,
    finish_budget,
    identify_stage,
    recorded_loop,
    simulation_bench,
    start_budget,
    validation_stage,
)
from fsmbench.twin.compare import comparison_rows
from fsmbench.twin.simulate import simulate_bench
from fsmbench.version import __version__

__all__ = ["FIGURE_FORMATS", "StageStatus", "StudyResult", "run_study"]

Progress = Callable[[str], None]
FIGURE_FORMATS = ("png", "pdf")
STUDY_FORMAT = ("fsmbench.study", 1)

@dataclass(frozen=True)
class StageStatus:
    """What one stage did: ran or skipped (with the reason), its outputs (relative paths)."""

    name: str
    ran: bool
    reason: str = ""
    outputs: tuple[str, ...] = ()


@dataclass(frozen=True)
class StudyResult:
    """Outcome of a study: where everything went, what was skipped, the verdict."""

    out_dir: str
    data_dir: str
    source: str
    report: str
    stages: tuple[StageStatus, ...]
    experiments: tuple[str, ...]
    skipped_experiments: dict[str, str] = field(default_factory=dict)
    summary: Summary | None = None
    timings_s: dict[str, float] = field(default_factory=dict)
    figures: tuple[str, ...] = ()
    sections: tuple[Section, ...] = field(default=(), repr=False, compare=False)
    design: DesignStage | None = field(default=None, repr=False, compare=False)
    plant: PlantModel | None = field(default=None, repr=False, compare=False)

    def to_json(self) -> dict[str, Any]:
        """``study.json``: what ran, relative paths, no timings (they are in timings.json)."""
        out = Path(self.out_dir)

        def rel(p: str) -> str:
            path = Path(p)
            return str(path.relative_to(out)) if path.is_relative_to(out) else str(path)

        return {
            "format": STUDY_FORMAT[0], "format_version": STUDY_FORMAT[1],
            "fsmbench_version": __version__, "source": self.source,
            "data_dir": rel(self.data_dir), "report": rel(self.report),
            "stages": [{**asdict(s), "outputs": [rel(o) for o in s.outputs]}
                       for s in self.stages],
            "experiments": list(self.experiments),
            "skipped_experiments": dict(self.skipped_experiments),
            "figures": [rel(f) for f in self.figures],
            "meets_specifications": None if self.summary is None
            else self.summary.meets_specifications,
            # What a user must know about the data, as in summary.json: failed
            # plausibility checks and notices (saturation, dropped variables …).
            "failed_checks": [] if self.summary is None
            else [c.to_json() for c in self.summary.failed_checks],
            "notices": [] if self.summary is None
            else [n.to_json() for n in self.summary.notices],
        }


def _identification_headline(ident: Identification, truth: Mapping[str, Any] | None,
                             bench: Bench) -> str:
    """One line: the main identified values, and how they compare with the twin's truth."""
    js = ident.to_json()
    parts = []
    qd = js.get("qd_gain_v_per_rad") or {}
    if qd.get("h") is not None and qd.get("v") is not None:
        parts.append(f"4QD gain {qd['h']:.4g} / {qd['v']:.4g} V/rad")
    modes = ident.sercalo_modes() if ident.sercalo is not None else {}
    if modes:
        parts.append("Sercalo modes " + " / ".join(f"{m['resonance_hz']:.1f} Hz"
                                                    for m in modes.values()))
    if truth is not None:
        rows = comparison_rows(js, reference=truth, bench=bench)
        within = sum(1 for r in rows if r.within_target)
        parts.append(f"{within} of {len(rows)} values within their targets against the twin's "
                     "truth")
    return "; ".join(parts) or "ran"


# The blocks the Sercalo loop's numbers rest on, and the records that identify each.
_LOOP_BLOCKS = {"Gd": "the 4QD calibration (data_cal_pd_h, data_cal_pd_v)",
                "Gi": "the current amplifier (data_uch, data_ucv)",
                "Gc": "the Sercalo (data_uch, data_ucv)"}


#: Blocks the distance budget, the closed-loop simulation and the model's check use beyond
#: the loop's: the Newport drives the repeatability runs' motion and its DAC's noise.
_DISTURBANCE_BLOCKS = {"Gn": "Newport (data_unh, data_unv)"}


def _disturbance_blocks_missing(ident: Identification | None) -> str:
    """The disturbance's blocks an identification left to the bench file, in words."""
    if ident is None:
        return ""
    gone = [f"{words}: {ident.skipped.get('newport', 'not identified')}"
            for block, words in _DISTURBANCE_BLOCKS.items()
            if ident.plant_blocks.get(block) != "identified"]
    if not gone and ident.newport is not None:
        gone = [f"Newport {a} (data_un{a}): {ident.skipped.get(f'newport_{a}', 'not identified')}"
                for a in ident.newport.assumed_axes]
    return "; ".join(gone)


def _loop_blocks_missing(ident: Identification | None) -> str:
    """The loop's blocks an identification left nominal, in words (empty when none)."""
    if ident is None:
        return ""
    gone = [words for block, words in _LOOP_BLOCKS.items()
            if ident.plant_blocks.get(block) != "identified"]
    return ("identified " + ", ".join(gone) + " (the plant used the bench file's)"
            if gone else "")


@dataclass(eq=False)
class _StudyRun:
    """One study as its stages run: where it writes, what each stage did, their times.

    Mutable on purpose: the stages' accumulator, private to one :func:`run_study`.
    """

    out: Path
    say: Progress
    stages: list[StageStatus] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)
    clock: float = field(default_factory=time.perf_counter)

    def lap(self, name: str) -> None:
        """The wall time since the last lap, added to stage ``name``'s [s]."""
        now = time.perf_counter()
        self.timings[name] = round(self.timings.get(name, 0.0) + now - self.clock, 3)
        self.clock = now


@dataclass(frozen=True, eq=False)
class _Recorded:
    """The recordings the study analyses and where they came from."""

    data: Path
    source: str
    is_twin: bool
    loaded: RecordingSet
    truth: Mapping[str, Any] | None


@dataclass(frozen=True, eq=False)
class _Identified:
    """Section 2's outcome: the identification (None: not run), the bench as the records
    describe it, the plant the later stages use, the bench the predictions simulate."""

    ident: Identification | None
    bench: Bench
    plant: PlantChoice
    identified: SimulationBench
    simulated: SimulationBench


def _recordings_step(run: _StudyRun, *, data: Path | None, bench: Bench, seed: int,
                     duration_s: float | None, parallel: bool) -> _Recorded:
    """The twin's records simulated and written (no ``data``), then every record read."""
    is_twin = data is None
    written = None
    if data is None:
        data = run.out / "twin-data"
        run.say(f"simulating the bench with the digital twin, writing its records to {data}")
        simulated = simulate_bench(bench, seed=seed, duration_s=duration_s, progress=run.say,
                                   write_dir=data)
        run.stages.append(StageStatus("simulate", True,
                                      outputs=tuple(str(p) for p in simulated.files)))
        source = f"digital twin, random seed {seed}"
        # Read as written: decoding the files just compressed gives the same records.
        written = simulated.written()
        run.lap("simulate")
    else:
        source = f"recorded data in {data}"
    conv = bench.nominal.converter
    # The records' rate is judged against each other and then the bench file, by the
    # identification (ident.evidence.rate): the loader does not hold t to the bench file.
    loaded = load_recordings(data, progress=run.say, fs_hz=None, adc_range_v=conv.range_v,
                             adc_bits=conv.bits, parallel=parallel, written=written)
    run.stages.append(StageStatus("recordings", True, outputs=tuple(loaded.recordings)))
    truth = read_twin_truth(data / "twin_truth.json")
    run.lap("recordings")
    return _Recorded(data, source, is_twin, loaded, truth)


def _identification_step(run: _StudyRun, rec: _Recorded, *, bench: Bench,
                         options: IdentifyOptions | None, parallel: bool) -> _Identified:
    """Section 2 when its experiments are there; the plant and the benches that follow."""
    recordings = rec.loaded.recordings
    ident = None
    if any(n in recordings for n in IDENT_EXPERIMENTS):
        run.say("identification (ESRF study section 2)")
        stage = identify_stage(recordings, bench=bench, out_dir=run.out, source=rec.source,
                               progress=run.say, options=options,
                               unusable=rec.loaded.unusable(), parallel=parallel)
        ident = stage.result
        run.stages.append(StageStatus(
            "identify", True, outputs=tuple(str(p) for p in stage.files),
            reason="; ".join(f"{k}: {v}" for k, v in ident.skipped.items())))
    else:
        run.stages.append(StageStatus("identify", False, reason="none of " + ", ".join(
            IDENT_EXPERIMENTS) + " present"))
    if ident is not None and ident.params is not None and ident.params != bench.nominal:
        # The bench as the records describe its structure (their rate, its signs): every
        # later stage models and simulates it so (ident.evidence).
        bench = replace(bench, nominal=ident.params)
    plant = choose_plant(recordings, bench=bench, identification=ident, progress=run.say)
    run.say(f"plant for the budget and the design: {plant.source}")
    run.lap("identify")
    # Every prediction runs on the bench the recordings came from: the packaged twin for
    # twin data, the bench identified from them otherwise (never the packaged one).
    identified = simulation_bench(bench=bench, is_twin=False,
                                  identification_dir=run.out if ident is not None else None,
                                  identification=ident,
                                  label=("the bench identified from the twin's records"
                                         if rec.is_twin else
                                         f"the bench identified from the recordings in "
                                         f"{rec.data}"))
    simulated = SimulationBench(bench) if rec.is_twin else identified
    return _Identified(ident, bench, plant, identified, simulated)


_T = TypeVar("_T")


@dataclass(frozen=True, eq=False)
class _Timed(Generic[_T]):
    """What a forked process computed, and its own wall time [s]."""

    value: _T
    seconds: float


def _timed(compute: Callable[[], _T]) -> _Timed[_T]:
    start = time.perf_counter()
    value = compute()
    return _Timed(value, round(time.perf_counter() - start, 3))


def _design(run: _StudyRun, found: _Identified, *, seed: int,
            say: Progress) -> _Timed[DesignStage]:
    """Sections 5-10 (they need no budget)."""
    return _timed(lambda: design_stage(bench=found.bench, out_dir=run.out, plant=found.plant,
                                       seed=seed, progress=say, simulated=found.simulated))


def _validation(run: _StudyRun, rec: _Recorded, found: _Identified, *, seed: int,
                say: Progress) -> _Timed[ValidationStage]:
    """The model's check on the recorded loop (it needs neither the design nor the budget)."""
    identified = found.identified
    return _timed(lambda: validation_stage(
        rec.loaded.recordings, bench=found.bench, simulated=identified.bench,
        plant=None if identified.bench is None else found.plant.plant, out_dir=run.out,
        seed=seed, progress=say, loop=recorded_loop(found.ident, bench=found.bench)))


def _waited_for(run: _StudyRun, later: ForkedSeries, index: int, *, lap: str) -> Any:
    """``later``'s value ``index``. The computation keeps its own time; what this process
    waited for it is the line ``lap`` (run here, the wait was the computation itself)."""
    value = later.result(index)
    if later.forked:
        run.lap(lap)
    else:
        run.clock = time.perf_counter()
    return value


@dataclass(frozen=True, eq=False)
class _Later:
    """The stages after the identification, and the report's chapters drafted from all
    but the validation (:func:`~fsmbench.report.sections.study.study_chapters`), their
    figures encoded."""

    design: DesignStage
    budget: BudgetStage
    validation: ValidationStage
    chapters: list[Section]
    encoded: EncodedFigures


def _later_stages(run: _StudyRun, rec: _Recorded, found: _Identified, *, seed: int,
                  parallel: bool) -> _Later:
    """Sections 5-10 (design), 3, 4, 11 (budget, with fsmbench's controller the design
    recommends) and the model's check on the recorded loop; the report's chapters that
    need no validation.

    The design and the validation need no budget, and the budget of the records no
    controller: one forked process (:mod:`fsmbench.forked`) runs the design, then the
    validation, while this one runs the budget of the records; the budget gets the
    recommended controller's part as soon as the design is done, then the report's
    chapters are drafted, beside the validation. Two processes on two cores: a third
    (the design and the validation each in its own) measured 0.7 s slower, the three
    crowding the cores.
    """
    recordings, bench, plant = rec.loaded.recordings, found.bench, found.plant
    later = start_forked_series(
        [lambda say: _design(run, found, seed=seed, say=say),
         lambda say: _validation(run, rec, found, seed=seed, say=say)],
        progress=run.say, parallel=parallel)
    try:
        run.say("noise and error budget, huddle tests, repeatability (ESRF study sections 3, "
                "4, 11)")
        # The recorded loop's budget (the ESRF study's controller ran in the huddle tests),
        # then the one the verdict recommends (fsmbench's).
        draft = start_budget(recordings, bench=bench, plant=plant, progress=run.say)
        run.lap("budget")
        designed: _Timed[DesignStage] = _waited_for(run, later, 0, lap="design_wait")
        design = designed.value
        budgeted = finish_budget(draft, bench=bench, out_dir=run.out, plant=plant,
                                 progress=run.say,
                                 recommended=design.result.controllers["fsmbench_controller"])
        run.lap("budget")
        run.say("writing the report's chapters")
        chapters = study_chapters(
            bench=found.bench, recordings=rec.loaded.recordings, skipped=rec.loaded.skipped,
            source=rec.source, is_twin=rec.is_twin, ident=found.ident, truth=rec.truth,
            budget=budgeted.result, design=design.result, twin_check=design.twin_check,
            design_skipped=design.skipped, plant_source=found.plant.source)
        encoded = encode_figures(chapters)
        run.lap("report")
        validated: _Timed[ValidationStage] = _waited_for(run, later, 1,
                                                         lap="validation_wait")
    finally:
        later.cancel()
    run.timings.update({"design": designed.seconds, "validation": validated.seconds})
    validation = validated.value
    run.stages.append(StageStatus("design", True, outputs=tuple(str(p) for p in design.files),
                                  reason=design.skipped))
    run.stages.append(StageStatus(
        "budget", True, outputs=tuple(str(p) for p in budgeted.files),
        reason="; ".join(f"{k}: {v}" for k, v in budgeted.result.skipped.items())))
    run.stages.append(StageStatus("validation", validation.result is not None,
                                  outputs=tuple(str(p) for p in validation.files),
                                  reason=validation.skipped or found.identified.reason))
    return _Later(design, budgeted, validation, chapters, encoded)


def _evidence(rec: _Recorded, found: _Identified, *, design: DesignStage,
              budget: BudgetStage, validation: ValidationStage,
              montecarlo: Mapping[str, Any] | None) -> StudyEvidence:
    """What the stages found, for the verdict."""
    loaded, ident, plant, bench = rec.loaded, found.ident, found.plant, found.bench
    # A check can be run by several stages on the same record: list each verdict once.
    checks = list(dict.fromkeys([*loaded.checks, *(ident.checks if ident is not None else ()),
                                 *budget.result.checks, *design.result.checks,
                                 *(() if validation.result is None
                                   else (validation.result.check,))]))
    notices = list(dict.fromkeys([*loaded.notices,
                                  *(ident.notices if ident is not None else ()),
                                  *budget.result.notices]))
    # What a stage left out of a record it had (a record the loader skipped, or one that
    # is simply absent, is already in loaded.skipped; a part refused by a check is in the
    # failed checks).
    parts = [PartSkipped(stage, part, why)
             for stage, skips in (("identification", ident.skipped if ident else {}),
                                  ("budget", budget.result.skipped))
             for part, why in skips.items()
             if part not in loaded.skipped
             and not why.startswith(("not in the recordings", "missing", "check "))]
    simulated = found.simulated
    return StudyEvidence(
        source=rec.source, is_twin=rec.is_twin, skipped=loaded.skipped, parts_skipped=parts,
        n_experiments=len(EXPERIMENTS), n_read=len(loaded.recordings), checks=checks,
        notices=notices,
        identification=None if ident is None else {
            "ran": True, "warnings": list(ident.warnings), "skipped": dict(ident.skipped)},
        identification_headline=("" if ident is None
                                 else _identification_headline(ident, rec.truth, bench)),
        plant_source=plant.source,
        plant_identified=(plant.identification is not None
                          and plant.source.startswith("identified")),
        plant_missing=_loop_blocks_missing(plant.identification),
        disturbance_missing=_disturbance_blocks_missing(plant.identification),
        budget=budget.result, design=design.payload, validation=validation.result,
        validation_skipped=validation.skipped or found.identified.reason,
        simulated_bench="" if simulated.bench is None else simulated.bench.label,
        montecarlo=montecarlo)


def run_study(*, out_dir: str | Path, data_dir: str | Path | None = None,
              bench: Bench | None = None, seed: int = 0, duration_s: float | None = None,
              progress: Progress | None = None, figures: Sequence[str] = (),
              spec: Specification | None = None,
              identify_options: IdentifyOptions | None = None,
              montecarlo: Mapping[str, Any] | None = None,
              parallel: bool = True) -> StudyResult:
    """Run the study and write its report and results into ``out_dir``.

    Parameters
    ----------
    out_dir : path
        Output folder (created; must not be inside ``data_dir``).
    data_dir : path, optional
        Folder of recordings in the ESRF study's layout. Without it the twin
        simulates the bench and its records are written to ``out_dir/twin-data``.
    bench : Bench, optional
        Bench parameters (default: the packaged bench).
    seed : int
        Random seed of the twin's noise.
    duration_s : float, optional
        Twin record length in s (default: the ESRF study's lengths).
    progress : callable, optional
        Receives progress messages.
    figures : sequence of {"png", "pdf"}
        Also write every figure to ``out_dir/figures`` in these formats.
    spec : Specification, optional
        The requirements of the verdict (default: the ESRF study's, 5 nm distance error).
    identify_options : IdentifyOptions, optional
        FRF estimator and fit weights of the identification (default: ``auto``, the ESRF study's).
    montecarlo : mapping, optional
        A ``montecarlo.json``'s content (:func:`fsmbench.scale.montecarlo_run.read_montecarlo`):
        chapter 11 lists its draws that break a requirement, and the robustness row names
        a requirement ≥ 5 % of them break.
    parallel : bool
        Decode half of the recorded files, run the design then the validation beside the
        budget, the noise model beside the identification's other steps, the Newport's two
        fits and the report's figures two by two, in forked processes
        (:mod:`fsmbench.forked`; where ``fork`` exists and there are two cores). False runs everything in this
        process, one after the other: the same results.
    """
    bench = default_bench() if bench is None else bench
    spec = Specification() if spec is None else spec
    bad = [f for f in figures if f not in FIGURE_FORMATS]
    if bad:
        raise ValueError(f"--figures {','.join(bad)}: unknown format; use png and/or pdf")
    out = Path(out_dir)
    data = None if data_dir is None else Path(data_dir)
    check_out_dir(out, data)
    if data is not None and not data.is_dir():
        raise FileNotFoundError(f"data folder {data} does not exist")
    out.mkdir(parents=True, exist_ok=True)
    run = _StudyRun(out, progress or (lambda _msg: None))
    # One BLAS thread for the study (restored after): its matrices are small, and BLAS
    # threads spinning beside the twin's threads and the forked stages slow all of them.
    with threadpool_limits(limits=1, user_api="blas"):
        rec = _recordings_step(run, data=data, bench=bench, seed=seed, duration_s=duration_s,
                               parallel=parallel)
        found = _identification_step(run, rec, bench=bench, options=identify_options,
                                     parallel=parallel)
        later = _later_stages(run, rec, found, seed=seed, parallel=parallel)
        summary = build_summary(_evidence(rec, found, design=later.design, budget=later.budget,
                                          validation=later.validation, montecarlo=montecarlo),
                                spec=spec)
        return _write_outputs(run, rec, found, summary=summary, later=later, figures=figures,
                              montecarlo=montecarlo, parallel=parallel)


def _write_outputs(run: _StudyRun, rec: _Recorded, found: _Identified, *, summary: Summary,
                   later: _Later, figures: Sequence[str], montecarlo: Mapping[str, Any] | None,
                   parallel: bool) -> StudyResult:
    """The report, summary.json, the figures asked for, study.json and timings.json."""
    out, say, source = run.out, run.say, rec.source
    say("writing the report")
    validation = later.validation
    sections = with_recorded_loop_check(
        later.chapters, validation=validation.result,
        skipped=validation.skipped or found.identified.reason, montecarlo=montecarlo)
    summary_json = summary.to_json()
    report_path = write_report(
        out / "report.html", title="Sercalo test bench study", sections=sections,
        verdict_html=verdict_html(summary), summary=summary_json,
        meta=(f"fsmbench {__version__}. Data: {source}. The chapters follow the ESRF Sercalo "
              "test bench study (ESRF, 2020), called \"the ESRF study\" below; its sections, "
              "figures and tables are cited as (ESRF study 2.1), (ESRF study Fig. 8).",),
        parallel=parallel, encoded=later.encoded)
    atomic_write_text(out / "summary.json",
                      json.dumps(summary_json, indent=2, allow_nan=False) + "\n")
    run.lap("report")
    exported: list[Path] = []
    if figures:
        say(f"writing every figure as {', '.join(figures)} to {out / 'figures'}")
        exported = export_figures(iter_figures(sections), out / "figures", formats=figures)
        run.lap("figures")
    say("report written")
    result = StudyResult(out_dir=str(out), data_dir=str(rec.data), source=source,
                         report=str(report_path), stages=tuple(run.stages),
                         experiments=tuple(rec.loaded.recordings),
                         skipped_experiments=dict(rec.loaded.skipped), summary=summary,
                         timings_s=run.timings, figures=tuple(str(p) for p in exported),
                         sections=tuple(sections), design=later.design, plant=found.plant.plant)
    atomic_write_text(out / "study.json", json.dumps(plain_json(result.to_json()), indent=2)
                      + "\n")
    atomic_write_text(out / "timings.json", json.dumps(
        {"format": "fsmbench.timings", "format_version": 1, "seconds": run.timings}, indent=2)
        + "\n")
    return result


# fsmbench.study is also the API's study(): importing this module rebinds the name.
callable_module(__name__)
