"""The study's later stages, shared by their sub-commands and ``fsmbench study``.

Each stage is a function of the recordings (and the bench) that writes its
files atomically into an output folder and returns its result:

``identify_stage``  ESRF study section 2 → ``identification.json``, ``plant.mat``, ``frf.mat``
``budget_stage``    sections 3, 4, 11 → ``budget.json``
``design_stage``    sections 5–10 → ``design.json``, ``controllers.mat``,
                    ``controllers_sos.json``; fsmbench's controller is then run on the
                    simulated bench (the repeatability experiment, quantisation and
                    noise): the packaged twin on twin data, the bench identified from
                    the recordings otherwise (:func:`simulation_bench`)
``validation_stage`` the model checked on the recorded closed loop (``data_rep_h/v``
                    against the same experiments simulated on the identified bench)
                    → ``validation.json``

The plant a stage uses is the identified one when the identification
experiments are present and pass their checks, the nominal physical model
otherwise; the result says which and why (the missing files, or the failed
check or step by name). ``identification.json`` and ``budget.json`` carry
``checks`` and ``notices`` lists. Every file's format name and version are
its first keys (``docs/results.md``).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import control as ct
import numpy as np
import xarray as xr

from fsmbench.atomic import atomic_write_text
from fsmbench.bench.axes import PerAxis
from fsmbench.bench.blocks import PlantModel, physical_plant
from fsmbench.bench.esrf import esrf_decentralised_controller, tustin
from fsmbench.bench.params import Bench
from fsmbench.budget.result import BudgetResult
from fsmbench.budget.study import budget_study, with_recommended
from fsmbench.control.study import DesignResult, design_study
from fsmbench.control.validation import ClosedLoopValidation, validate_closed_loop
from fsmbench.ident.pipeline import (
    Identification,
    IdentifyOptions,
    identify,
    write_identification,
)
from fsmbench.ident.result import PlantChoice, SavedIdentification
from fsmbench.io.errors import RecordingError
from fsmbench.io.signals import MIN_DURATION_S
from fsmbench.jsonutil import format_text, stamped
from fsmbench.sim.controller import feedback_controller
from fsmbench.twin.identified import bench_from_identification
from fsmbench.twin.simulate import simulate_bench
from fsmbench.twin.verify import TrackingCheck, verify_on_twin

__all__ = [
    "BUDGET_FORMAT",
    "DESIGN_FORMAT",
    "IDENT_EXPERIMENTS",
    "RECOMMENDED_SKIPPED",
    "VALIDATION_FORMAT",
    "BudgetDraft",
    "BudgetStage",
    "DesignStage",
    "IdentifyStage",
    "PlantChoice",
    "RecordedLoop",
    "SavedIdentification",
    "SimulationBench",
    "ValidationStage",
    "budget_stage",
    "choose_plant",
    "design_stage",
    "finish_budget",
    "identify_stage",
    "recorded_loop",
    "simulation_bench",
    "start_budget",
    "validation_stage",
]

Progress = Callable[[str], None]

IDENT_EXPERIMENTS = ("data_cal_pd_h", "data_cal_pd_v", "data_uch", "data_ucv", "data_unh",
                     "data_unv")


#: ``budget.json``'s format and version (2: no duplicated total/rows/limiting at the top,
#: ids for keys, (h, v) pairs as ``{"h", "v"}``, huddle bands as a list; 4: each row's
#: provenance, ``stationary_total_rms_m``, ``recommended``: fsmbench's controller's budget).
BUDGET_FORMAT = ("fsmbench.budget", 4)
#: ``budget.json``'s ``recommended_skipped`` when no controller was designed in the run.
RECOMMENDED_SKIPPED = (
    "no controller was designed in this run, so there is no budget with fsmbench's "
    "controller: budget.total_rms_m is the recorded loop's (the ESRF study's controller as "
    "the closed-loop records ran it), the same number the study's budget.json has on the "
    "same recordings and identification; the study's verdict quotes recommended (fsmbench's "
    "controller), which fsmbench study writes")
#: ``design.json``'s format and version (2: ``closed_loop_twin`` names the bench it ran on,
#: ``bench``/``bench_kind``, and is null with ``closed_loop_skipped`` when there was none).
DESIGN_FORMAT = ("fsmbench.design", 2)
#: ``validation.json``'s format and version.
VALIDATION_FORMAT = ("fsmbench.validation", 1)


def _quiet(_msg: str) -> None:
    return None


@dataclass(frozen=True, eq=False)
class IdentifyStage:
    """ESRF study section 2's result and the files written of it."""

    result: Identification
    files: tuple[Path, ...]


def identify_stage(recordings: Mapping[str, xr.Dataset], *, bench: Bench, out_dir: Path,
                   source: str, progress: Progress | None = None,
                   options: IdentifyOptions | None = None,
                   unusable: Mapping[str, str] | None = None,
                   parallel: bool = True) -> IdentifyStage:
    """Run ESRF study section 2 and write its files (``options``: the estimator and weights;
    ``unusable``: files present but unreadable, by experiment, with the loader's reason;
    ``parallel``: the noise model fitted beside the other steps, :func:`identify`)."""
    result = identify(recordings, bench=bench, options=options, source=source,
                      progress=progress, unusable=unusable, parallel=parallel)
    return IdentifyStage(result, tuple(write_identification(result, out_dir)))


def choose_plant(recordings: Mapping[str, xr.Dataset], *, bench: Bench,
                 identification: Identification | None = None,
                 progress: Progress | None = None, source: str = "") -> PlantChoice:
    """The identified plant if the Sercalo could be identified, else the nominal model.

    ``source`` says which and why: the missing experiments, or the failed
    check or step of the identification (never "missing" when the file was
    there). Blocks that fell back to nominal inside an identified plant are
    named with their reason too. ``source``: where the recordings are (named in the
    identified plant's source when it is identified here).
    """
    say = progress or _quiet
    ident = identification
    if ident is None and all(n in recordings for n in ("data_uch", "data_ucv")):
        say("identifying the plant first (ESRF study section 2)")
        ident = identify(recordings, bench=bench, progress=say, source=source or "recordings")
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
    # The identification's own reason first: it tells a file that was there but could not
    # be read ("unusable") from one that is missing.
    for step in ("current_amp", "sercalo"):
        if ident is not None and step in ident.skipped:
            return f"Sercalo identification: {ident.skipped[step]}"
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


@dataclass(frozen=True)
class RecordedLoop:
    """The 4QD gains the recorded closed loop divided by, and where they come from.

    ``gd_used_v_per_rad`` per axis (h, v) [V/rad], signed; ``measured`` per axis:
    read from the closed-loop records (:mod:`fsmbench.ident.evidence.recorded_loop`),
    else the bench file's (assumed, as the ESRF study's real-time code used).
    """

    gd_used_v_per_rad: tuple[float, float]
    measured: tuple[bool, bool]

    def words(self) -> str:
        """Where the gains come from, in words."""
        parts = []
        for axis, gd, m in zip("hv", self.gd_used_v_per_rad, self.measured, strict=True):
            how = "measured from the closed-loop records" if m else "assumed: the bench file's"
            parts.append(f"{axis} {gd:+.4g} V/rad ({how})")
        return ", ".join(parts)


def recorded_loop(ident: Identification | Mapping[str, Mapping[str, Any]] | None, *,
                  bench: Bench) -> RecordedLoop:
    """The recorded loop's 4QD gains: measured where the records ran the ESRF study's
    controller, the bench file's otherwise. A measured gain within 3 of its standard
    deviations (or 0.1 %) of the bench file's is the bench file's: the records confirm it,
    and a simulation of the loop does not change with the fit's last digits.

    ``ident``: the identification, or its ``diagnostics.recorded_loop`` as written (per
    axis ``verdict``, ``gd_used_v_per_rad``, ``gd_used_std_v_per_rad``)."""
    gd = bench.nominal.quad_diode.gain_v_per_rad
    found: Mapping[str, Any] = ({} if ident is None else ident if isinstance(ident, Mapping)
                                else {a: r.to_json() for a, r in ident.recorded_loop.items()})
    values, measured = [], []
    for axis in "hv":
        loop = found.get(axis)
        ok = loop is not None and loop.get("verdict") == "seed"
        value = gd[axis]
        if ok and loop is not None:
            value = float(loop["gd_used_v_per_rad"])
            close = max(3.0 * float(loop["gd_used_std_v_per_rad"]), 1e-3 * abs(gd[axis]))
            if abs(value - gd[axis]) <= close:
                value = gd[axis]
        values.append(value)
        measured.append(ok)
    return RecordedLoop((values[0], values[1]), (measured[0], measured[1]))


def _write_json(path: Path, payload: Mapping[str, Any]) -> Path:
    return atomic_write_text(path, format_text(payload, sort_keys=True))


@dataclass(frozen=True, eq=False)
class BudgetStage:
    """ESRF study sections 3, 4 and 11's result and the file written of it."""

    result: BudgetResult
    files: tuple[Path, ...]


@dataclass(frozen=True, eq=False)
class BudgetDraft:
    """The budget of the records (:func:`start_budget`), before the recommended controller's.

    ``noise_model``: the measured noise it used (None: the bench file's); the
    recommended budget uses the same.
    """

    result: BudgetResult
    noise_model: Any = None


def start_budget(recordings: Mapping[str, xr.Dataset], *, bench: Bench, plant: PlantChoice,
                 progress: Callable[[str], None] | None = None) -> BudgetDraft:
    """ESRF study sections 3, 4, 11 on the records, with the loop they ran (the ESRF study's
    controller of 9.2, on the 4QD gains the closed-loop records show it divided by:
    :func:`recorded_loop`); ``progress`` hears of long records' reads. Nothing is written:
    :func:`finish_budget` adds the recommended controller's budget and writes the file."""
    ident, saved = plant.identification, plant.saved
    if ident is not None:
        # The measured noise replaces the bench file's only from a trusted identification.
        trusted = not ident.warnings and plant.plant is ident.plant
        noise_model = ident.noise_model if trusted else None
        loop = recorded_loop(ident, bench=bench)
    else:
        # A saved identification (--bench DIR) with warnings was refused when it was read:
        # what it measured is used as the study uses it in memory.
        noise_model = None if saved is None else saved.noise_model
        loop = recorded_loop(None if saved is None else saved.recorded_loops, bench=bench)
    result = budget_study(recordings, bench=bench, plant=plant.plant, progress=progress,
                          controller=_recorded_seed_controller(plant.plant, bench=bench,
                                                               loop=loop),
                          controller_name=("ESRF study 9.2 K, Tustin at 1/fs (9.3), on the 4QD "
                                           f"gains the records ran ({loop.words()})"
                                           if any(loop.measured) else ""),
                          noise_model=noise_model)
    return BudgetDraft(result, noise_model)


def finish_budget(draft: BudgetDraft, *, bench: Bench, out_dir: Path, plant: PlantChoice,
                  progress: Callable[[str], None] | None = None,
                  recommended: ct.StateSpace | None = None) -> BudgetStage:
    """The budget of :func:`start_budget` with fsmbench's controller's (``recommended``,
    continuous) beside the recorded loop's; ``budget.json`` written."""
    result = draft.result
    if recommended is not None:
        (progress or _quiet)("error budget: the same with fsmbench's controller")
        result = with_recommended(result, bench=bench, plant=plant.plant,
                                  recommended=recommended, noise_model=draft.noise_model)
    # The stage's plant source (which blocks were identified, or why nominal) replaces the
    # plant model's own shorter one.
    payload = {**result.to_json(), "plant_source": plant.source}
    if recommended is None:
        # The study quotes the recommended budget in its verdict; say why this one has none.
        payload["recommended_skipped"] = RECOMMENDED_SKIPPED
    if plant.identification is not None:  # the plant's own verdicts travel with it
        payload["plant_checks"] = [c.to_json() for c in plant.identification.checks]
    elif plant.saved is not None:
        payload["plant_checks"] = [dict(c) for c in plant.saved.checks]
    name, version = BUDGET_FORMAT
    return BudgetStage(result, (_write_json(out_dir / "budget.json",
                                            stamped(payload, format=name, version=version)),))


def budget_stage(recordings: Mapping[str, xr.Dataset], *, bench: Bench, out_dir: Path,
                 plant: PlantChoice, progress: Callable[[str], None] | None = None,
                 recommended: ct.StateSpace | None = None) -> BudgetStage:
    """ESRF study sections 3, 4, 11: ``budget.json`` (``progress`` hears of long records' reads).

    ``recommended``: fsmbench's controller (continuous), whose budget is computed
    beside the recorded loop's (the ESRF study's controller of 9.2, on the 4QD gains
    the closed-loop records show it divided by: :func:`recorded_loop`).
    """
    draft = start_budget(recordings, bench=bench, plant=plant, progress=progress)
    return finish_budget(draft, bench=bench, out_dir=out_dir, plant=plant, progress=progress,
                         recommended=recommended)


def _recorded_seed_controller(plant: PlantModel, *, bench: Bench,
                              loop: RecordedLoop) -> ct.StateSpace | None:
    """The ESRF study's controller as the records ran it on this plant's beam angles:
    ``K diag(Gd / g_used)`` (Tustin at 1/fs, ESRF study 9.3), or None (the budget's
    default, K on the beam angle) when the records measured no loop."""
    if not any(loop.measured) or "Gd" not in plant.blocks:
        return None
    scale = (np.diag(np.asarray(plant.blocks["Gd"].D, dtype=float))
             / np.asarray(loop.gd_used_v_per_rad, dtype=float))
    k = tustin(esrf_decentralised_controller(), ts_s=bench.nominal.converter.ts_s)
    return ct.ss(k.A, k.B @ np.diag(scale), k.C, np.asarray(k.D) @ np.diag(scale), k.dt,
                 inputs=["Rh", "Rv"], outputs=["Uch", "Ucv"], name="Krecorded")


@dataclass(frozen=True, eq=False)
class SimulationBench:
    """The bench every prediction of a study simulates, or why there is none.

    ``bench`` is the packaged twin on twin data (it is the truth of the data),
    the bench identified from the recordings on recorded data; None when the
    recordings could not be identified (``reason`` says why): then nothing is
    predicted on a bench that is not the user's.
    """

    bench: Bench | None
    reason: str = ""


def simulation_bench(*, bench: Bench, is_twin: bool, identification: Identification | None,
                     identification_dir: Path | None = None,
                     label: str = "") -> SimulationBench:
    """The bench the study's simulations run (see :class:`SimulationBench`).

    ``identification_dir``: where the identification was written (named as the
    bench's folder); ``label`` names the identified bench in words.
    """
    if is_twin:
        return SimulationBench(bench)
    if identification is None:
        return SimulationBench(None, "no identification ran: none of its experiments is "
                                     "usable")
    if identification.sercalo is None or identification.plant is None:
        why = identification.skipped.get("sercalo") or identification.skipped.get(
            "current_amp") or "the Sercalo was not identified"
        return SimulationBench(None, f"the Sercalo was not identified ({why})")
    if identification.warnings:
        return SimulationBench(None, "the identification raised warnings: "
                                     + "; ".join(identification.warnings))
    try:
        folder = Path(".") if identification_dir is None else identification_dir
        return SimulationBench(bench_from_identification(
            identification.to_json(), plant=identification.plant, bench=bench,
            path=folder / "identification.json", label=label))
    except (RecordingError, ValueError) as exc:
        return SimulationBench(None, f"the identified bench cannot be built: {exc}")


@dataclass(frozen=True, eq=False)
class DesignStage:
    """The design study and the simulated bench's verdict on fsmbench's controller.

    ``twin_check`` is None when there was no bench to simulate (``skipped`` says why);
    ``payload`` is ``design.json``'s content; ``files`` the files written.
    """

    result: DesignResult
    twin_check: TrackingCheck | None
    payload: dict[str, Any]
    skipped: str = ""
    files: tuple[Path, ...] = ()


def design_stage(*, bench: Bench, out_dir: Path, plant: PlantChoice, seed: int = 0,
                 progress: Progress | None = None,
                 simulated: SimulationBench | None = None) -> DesignStage:
    """ESRF study sections 5–10 and the closed-loop proof on the simulated bench.

    ``simulated``: the bench fsmbench's controller is run on (default: ``bench``
    itself, the packaged twin).
    """
    say = progress or _quiet
    sim = SimulationBench(bench) if simulated is None else simulated
    say("designing and verifying the controllers (ESRF study sections 5–10)")
    result = design_study(plant.plant, bench=bench)
    paths = result.write(out_dir)
    check = None
    closed: dict[str, Any] | None = None
    if sim.bench is not None:
        say(f"running fsmbench's controller on {sim.bench.label} (repeatability experiment)")
        check = verify_on_twin(result.controllers["fsmbench_controller"], bench=sim.bench,
                               plant=plant.plant, name="fsmbench controller", seed=seed)
        closed = {"tracking_error_rms_rad": check.measured_rms_rad,
                  "predicted_rms_rad": check.predicted_rms_rad,
                  "measured_over_predicted": check.ratio,
                  "predicted_parts_rad": check.predicted_parts_rad,
                  "duration_s": check.duration_s, "settle_s": check.settle_s,
                  "seed": check.seed, "bench": check.bench, "bench_kind": check.bench_kind}
    payload = {**result.to_json(), "plant_source": plant.source, "closed_loop_twin": closed,
               "closed_loop_skipped": sim.reason if sim.bench is None else ""}
    name, version = DESIGN_FORMAT
    paths.insert(0, _write_json(out_dir / "design.json",
                                stamped(payload, format=name, version=version)))
    return DesignStage(result=result, twin_check=check, payload=payload,
                       skipped=sim.reason, files=tuple(paths))


@dataclass(frozen=True, eq=False)
class ValidationStage:
    """The model's check on the recorded closed loop, or why it did not run; the file
    written of it."""

    result: ClosedLoopValidation | None
    skipped: str = ""
    files: tuple[Path, ...] = ()


def validation_stage(recordings: Mapping[str, xr.Dataset], *, bench: Bench,
                     simulated: Bench | None, plant: PlantModel | None, out_dir: Path,
                     seed: int = 0, progress: Progress | None = None,
                     loop: RecordedLoop | None = None) -> ValidationStage:
    """``data_rep_h/v`` as recorded against the same experiments simulated on ``simulated``.

    Parameters
    ----------
    recordings : mapping
        The study's records (``data_rep_h``, ``data_rep_v``).
    bench : Bench
        The bench file: the 4QD gains the recorded loop divided by (assumed: its
        nominal ones, as the ESRF study's real-time code used).
    simulated : Bench or None
        The identified bench (or the twin); None: not run.
    plant : PlantModel or None
        The model's plant (the identified one).
    loop : RecordedLoop, optional
        The 4QD gains the recorded loop divided by (default: the bench file's,
        assumed).
    """
    say = progress or _quiet
    present = [n for n in ("data_rep_h", "data_rep_v") if n in recordings]
    # A record shorter than its analysis reads is named by its record_length check: it
    # is not simulated (the twin refuses a duration under the protocol's minimum).
    names = [n for n in present if recordings[n]["t"].size
             / float(recordings[n].attrs.get("fs_hz", bench.nominal.converter.fs_hz))
             >= MIN_DURATION_S[n]]
    if not names:
        return ValidationStage(None, "neither data_rep_h nor data_rep_v was recorded" if not
                               present else f"{' and '.join(present)} too short to compare "
                               f"(at least {MIN_DURATION_S[present[0]]:g} s)")
    if simulated is None or plant is None:
        return ValidationStage(None, "no identified bench to predict the recorded loop on")
    say(f"predicting the recorded closed loop ({', '.join(names)}) on {simulated.label}")
    used = (loop or recorded_loop(None, bench=bench)).gd_used_v_per_rad
    runs: dict[str, xr.Dataset] = {}
    for name in names:
        t = recordings[name]["t"].values
        duration = float(t[-1] - t[0]) + 1.0 / bench.nominal.converter.fs_hz
        # The recorded loop ran the seed's controller on the 4QD gains it divided by.
        controller = feedback_controller(esrf_decentralised_controller(),
                                         gd_v_per_rad=PerAxis(h=used[0], v=used[1]),
                                         ts_s=simulated.true.converter.ts_s, name="seed K (9.2)")
        try:
            run = simulate_bench(simulated, seed=seed, duration_s=duration,
                                 experiments=[name], controller=controller)
        except ValueError as exc:
            # The records ran stable: a model on which their loop is unstable is
            # contradicted by them, and the study goes on without this check.
            return ValidationStage(None, (
                f"{exc}, yet {name} ran stable: its signals contradict the identified "
                "model (a signal of it recorded with its sign flipped or its gain changed, "
                "or a loop that divided by other 4QD gains than the other closed-loop "
                "records show); the records cannot tell which, and the model's check on "
                "the closed loop is not made"))
        runs[name] = run.recordings[name]
    k = tustin(esrf_decentralised_controller(), ts_s=bench.nominal.converter.ts_s)
    try:
        result = validate_closed_loop(recordings, simulated=runs, plant=plant,
                                      params=simulated.true, controller=k,
                                      controller_name="the ESRF study's controller (9.2)",
                                      gd_used_v_per_rad=used,
                                      bench_label=simulated.label)
    except ValueError as exc:
        return ValidationStage(None, str(exc))
    name, version = VALIDATION_FORMAT
    path = _write_json(out_dir / "validation.json",
                       stamped(result.to_json(), format=name, version=version))
    return ValidationStage(result, files=(path,))
