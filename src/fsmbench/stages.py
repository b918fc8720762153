"""The study's later stages, shared by their sub-commands and ``fsmbench study``.

Each stage is a function of the recordings (and the bench) that writes its
files atomically into an output folder and returns its result:

``identify_stage``  seed section 2 → ``identification.json``, ``plant.mat``, ``frf.mat``
``budget_stage``    sections 3, 4, 11 → ``budget.json``
``design_stage``    sections 5–10 → ``design.json``, ``controllers.mat``,
                    ``controllers_sos.json``; fsmbench's controller is then run on the
                    twin (the repeatability experiment, 10 kHz, quantisation and noise)

The plant a stage uses is the identified one when the identification
experiments are present and pass their checks, the nominal physical model
otherwise; the result says which and why (the missing files, or the failed
check or step by name). ``identification.json`` and ``budget.json`` carry
``checks`` and ``notices`` lists. Every file's format name and version are
its first keys (``docs/results.md``).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import xarray as xr

from fsmbench.bench.blocks import PlantModel, physical_plant
from fsmbench.bench.params import Bench
from fsmbench.ident.pipeline import (
    Identification,
    IdentifyOptions,
    identify,
    write_identification,
)
from fsmbench.io.atomic import atomic_write_text
from fsmbench.jsonutil import plain_json, stamped

__all__ = [
    "BUDGET_FORMAT",
    "DESIGN_FORMAT",
    "IDENT_EXPERIMENTS",
    "DesignStage",
    "PlantChoice",
    "budget_stage",
    "choose_plant",
    "design_stage",
    "identify_stage",
]

Progress = Callable[[str], None]

IDENT_EXPERIMENTS = ("data_cal_pd_h", "data_cal_pd_v", "data_uch", "data_ucv", "data_unh",
                     "data_unv")


#: ``budget.json``'s format and version (2: no duplicated total/rows/limiting at the top,
#: ids for keys, (h, v) pairs as ``{"h", "v"}``, huddle bands as a list).
BUDGET_FORMAT = ("fsmbench.budget", 3)
#: ``design.json``'s format and version.
DESIGN_FORMAT = ("fsmbench.design", 1)


def _quiet(_msg: str) -> None:
    return None


@dataclass(frozen=True, eq=False)
class PlantChoice:
    """The plant a stage works on and where it comes from."""

    plant: PlantModel
    source: str
    identification: Identification | None


def identify_stage(recordings: Mapping[str, xr.Dataset], *, bench: Bench, out_dir: Path,
                   source: str, progress: Progress | None = None,
                   options: IdentifyOptions | None = None
                   ) -> tuple[Identification, list[Path]]:
    """Run seed section 2 and write its files (``options``: the estimator and weights)."""
    result = identify(recordings, bench=bench, options=options, source=source,
                      progress=progress)
    return result, write_identification(result, out_dir)


def choose_plant(recordings: Mapping[str, xr.Dataset], *, bench: Bench,
                 identification: Identification | None = None,
                 progress: Progress | None = None) -> PlantChoice:
    """The identified plant if the Sercalo could be identified, else the nominal model.

    ``source`` says which and why: the missing experiments, or the failed
    check or step of the identification (never "missing" when the file was
    there). Blocks that fell back to nominal inside an identified plant are
    named with their reason too.
    """
    say = progress or _quiet
    ident = identification
    if ident is None and all(n in recordings for n in ("data_uch", "data_ucv")):
        say("identifying the plant first (seed section 2)")
        ident = identify(recordings, bench=bench, progress=say)
    if ident is not None and ident.plant is not None and ident.sercalo is not None \
            and not ident.warnings:
        parts = []
        for block, how in ident.plant_blocks.items():
            step = _BLOCK_STEP.get(block)
            why = ident.skipped.get(step, "") if step else ""
            parts.append(f"{block}: {how}" + (f" — {why}" if how == "nominal" and why else ""))
        return PlantChoice(ident.plant, "identified (" + ", ".join(parts) + ")", ident)
    return PlantChoice(physical_plant(bench.nominal, source="physical (nominal)"),
                       f"nominal physical model ({_why_nominal(recordings, ident)})", ident)


# The identification step whose failure leaves each plant block nominal.
_BLOCK_STEP = {"Gi": "current_amp", "Gc": "sercalo", "Gn": "newport", "Gd": "qd"}


def _why_nominal(recordings: Mapping[str, xr.Dataset], ident: Identification | None) -> str:
    gone = [n for n in ("data_uch", "data_ucv") if n not in recordings]
    if gone:
        return f"{' and '.join(gone)} missing"
    if ident is None:
        return "the Sercalo was not identified"
    if ident.warnings:
        return "the identification raised warnings: " + "; ".join(ident.warnings)
    for step in ("current_amp", "sercalo"):
        if step in ident.skipped:
            return f"Sercalo identification: {ident.skipped[step]}"
    return "the Sercalo was not identified"


def _write_json(path: Path, payload: Mapping[str, Any]) -> Path:
    return atomic_write_text(path, json.dumps(plain_json(payload), indent=2, sort_keys=True,
                                              allow_nan=False) + "\n")


def budget_stage(recordings: Mapping[str, xr.Dataset], *, bench: Bench, out_dir: Path,
                 plant: PlantChoice, progress: Callable[[str], None] | None = None
                 ) -> tuple[Any, list[Path]]:
    """Seed sections 3, 4, 11: ``budget.json`` (``progress`` hears of long records' reads)."""
    from fsmbench.budget.study import budget_study

    result = budget_study(recordings, bench=bench, plant=plant.plant, progress=progress)
    # The stage's plant source (which blocks were identified, or why nominal) replaces the
    # plant model's own shorter one.
    payload = {**result.to_json(), "plant_source": plant.source}
    if plant.identification is not None:  # the plant's own verdicts travel with it
        payload["plant_checks"] = [c.to_json() for c in plant.identification.checks]
    name, version = BUDGET_FORMAT
    return result, [_write_json(out_dir / "budget.json",
                                stamped(payload, format=name, version=version))]


@dataclass(frozen=True, eq=False)
class DesignStage:
    """The design study and the twin's verdict on fsmbench's controller."""

    result: Any
    twin_check: Any
    payload: dict[str, Any]


def design_stage(*, bench: Bench, out_dir: Path, plant: PlantChoice, seed: int = 0,
                 progress: Progress | None = None) -> tuple[DesignStage, list[Path]]:
    """Seed sections 5–10 and the closed-loop proof on the twin."""
    from fsmbench.control.study import design_study
    from fsmbench.twin.verify import verify_on_twin

    say = progress or _quiet
    say("designing and verifying the controllers (seed sections 5–10)")
    result = design_study(plant.plant, bench=bench)
    paths = result.write(out_dir)
    say("running fsmbench's controller on the twin (repeatability experiment)")
    check = verify_on_twin(result.controllers["fsmbench_controller"], bench=bench,
                           plant=plant.plant, name="fsmbench controller", seed=seed)
    payload = {**result.to_json(), "plant_source": plant.source,
               "closed_loop_twin": {
                   "tracking_error_rms_rad": check.measured_rms_rad,
                   "predicted_rms_rad": check.predicted_rms_rad,
                   "measured_over_predicted": check.ratio,
                   "predicted_parts_rad": check.predicted_parts_rad,
                   "duration_s": check.duration_s, "settle_s": check.settle_s,
                   "seed": check.seed}}
    name, version = DESIGN_FORMAT
    paths.insert(0, _write_json(out_dir / "design.json",
                                stamped(payload, format=name, version=version)))
    return DesignStage(result=result, twin_check=check, payload=payload), paths
