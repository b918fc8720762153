"""``fsmbench study``: the whole seed study on recorded data or on the twin.

Stages run left to right (docs/architecture.md): recordings (simulated by
the twin when no data folder is given) → identification → budget → design
(:mod:`fsmbench.stages`) → report. Each stage adds its outputs and a report
section; a stage or part whose experiments are missing is skipped and the
report says why.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from fsmbench import __version__
from fsmbench.bench.params import Bench, default_bench
from fsmbench.io.atomic import atomic_write_text
from fsmbench.io.folder import load_recordings
from fsmbench.io.outdir import check_out_dir
from fsmbench.report.bench_section import bench_section, parameters_section, recordings_section
from fsmbench.report.budget_section import budget_section
from fsmbench.report.design_section import design_section
from fsmbench.report.html import Section, write_report
from fsmbench.report.ident_section import identification_section
from fsmbench.stages import (
    IDENT_EXPERIMENTS,
    budget_stage,
    choose_plant,
    design_stage,
    identify_stage,
)
from fsmbench.twin.simulate import simulate_bench, write_twin

__all__ = ["StageStatus", "StudyResult", "run_study"]

Progress = Callable[[str], None]


@dataclass(frozen=True)
class StageStatus:
    """What one stage did: ran or skipped (with the reason), its outputs, its time."""

    name: str
    ran: bool
    reason: str = ""
    outputs: tuple[str, ...] = ()
    seconds: float = 0.0


@dataclass(frozen=True)
class StudyResult:
    """Outcome of a study: where everything went, and what was skipped."""

    out_dir: str
    data_dir: str
    source: str
    report: str
    stages: tuple[StageStatus, ...]
    experiments: tuple[str, ...]
    skipped_experiments: dict[str, str] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        """JSON-ready dict."""
        return asdict(self)


def run_study(*, out_dir: str | Path, data_dir: str | Path | None = None,
              bench: Bench | None = None, seed: int = 0, duration_s: float | None = None,
              progress: Progress | None = None) -> StudyResult:
    """Run the study and write ``report.html`` (and ``study.json``) into ``out_dir``.

    Parameters
    ----------
    out_dir : path
        Output folder (created; must not be inside ``data_dir``).
    data_dir : path, optional
        Folder of recordings in the seed's layout. Without it the twin
        simulates the bench and its records are written to ``out_dir/twin-data``.
    bench : Bench, optional
        Bench parameters (default: the packaged bench).
    seed : int
        Twin seed.
    duration_s : float, optional
        Twin record length (default: the seed's lengths).
    progress : callable, optional
        Receives progress messages.
    """
    say = progress or (lambda _msg: None)
    bench = default_bench() if bench is None else bench
    out = Path(out_dir)
    data = None if data_dir is None else Path(data_dir)
    check_out_dir(out, data)
    if data is not None and not data.is_dir():
        raise FileNotFoundError(f"data folder {data} does not exist")
    out.mkdir(parents=True, exist_ok=True)
    stages: list[StageStatus] = []

    if data is None:
        t0 = time.perf_counter()
        say("simulating the bench with the digital twin")
        run = simulate_bench(bench, seed=seed, duration_s=duration_s, progress=say)
        data = out / "twin-data"
        say(f"writing the twin's records to {data}")
        written = write_twin(run, data)
        stages.append(StageStatus("simulate", True, outputs=tuple(str(p) for p in written),
                                  seconds=time.perf_counter() - t0))
        source = f"digital twin, seed {seed}"
    else:
        source = f"recorded data in {data}"

    t0 = time.perf_counter()
    loaded = load_recordings(data, progress=say)
    recordings, skipped = loaded.recordings, loaded.skipped
    stages.append(StageStatus("recordings", bool(recordings),
                              reason="" if recordings else "no experiment found",
                              outputs=tuple(recordings), seconds=time.perf_counter() - t0))
    for name, why in skipped.items():
        say(f"skipped {name}: {why}")

    sections: list[Section] = [bench_section(bench), parameters_section(bench)]
    say("drawing the time-domain figures")
    t0 = time.perf_counter()
    sections.append(recordings_section(recordings, bench=bench, skipped=skipped, source=source))
    stages.append(StageStatus("report: experiments", True, seconds=time.perf_counter() - t0))

    truth_path = data / "twin_truth.json"
    truth = json.loads(truth_path.read_text()) if truth_path.is_file() else None
    t0 = time.perf_counter()
    ident = None
    if any(n in recordings for n in IDENT_EXPERIMENTS):
        say("identification (seed section 2)")
        ident, written = identify_stage(recordings, bench=bench, out_dir=out, source=source,
                                        progress=say)
        sections.append(identification_section(ident, recordings=recordings, bench=bench,
                                                truth=truth))
        stages.append(StageStatus(
            "identify", True, outputs=tuple(str(p) for p in written),
            reason="; ".join(f"{k}: {v}" for k, v in ident.skipped.items()),
            seconds=time.perf_counter() - t0))
    else:
        stages.append(StageStatus("identify", False,
                                  reason="none of " + ", ".join(IDENT_EXPERIMENTS) + " present"))
    plant = choose_plant(recordings, bench=bench, identification=ident, progress=say)
    say(f"plant for the budget and the design: {plant.source}")

    t0 = time.perf_counter()
    say("noise and error budget, huddle tests, repeatability (seed sections 3, 4, 11)")
    budget, written = budget_stage(recordings, bench=bench, out_dir=out, plant=plant)
    sections.append(budget_section(budget, recordings=recordings, plant_source=plant.source))
    stages.append(StageStatus("budget", True, outputs=tuple(str(p) for p in written),
                              reason="; ".join(f"{k}: {v}" for k, v in budget.skipped.items()),
                              seconds=time.perf_counter() - t0))

    t0 = time.perf_counter()
    design, written = design_stage(bench=bench, out_dir=out, plant=plant, seed=seed,
                                   progress=say)
    sections.append(design_section(design, plant_source=plant.source))
    stages.append(StageStatus("design", True, outputs=tuple(str(p) for p in written),
                              seconds=time.perf_counter() - t0))

    report_path = out / "report.html"
    meta = (f"fsmbench {__version__}; source: {source}.",
            "Stages: " + "; ".join(f"{s.name} ({'ran' if s.ran else 'skipped: ' + s.reason})"
                                   for s in stages) + ".")
    write_report(report_path, title="Sercalo test bench study (fsmbench)", sections=sections,
                 meta=meta)
    say(f"report written to {report_path}")
    result = StudyResult(out_dir=str(out), data_dir=str(data), source=source,
                         report=str(report_path), stages=tuple(stages),
                         experiments=tuple(recordings), skipped_experiments=dict(skipped))
    atomic_write_text(out / "study.json", json.dumps(result.to_json(), indent=2) + "\n")
    return result
