"""ESRF study sections 3, 4 and 11 on whatever recordings are present: :func:`budget_study`.

What always runs (it needs no data): the geometry of 4.1–4.2, the noise
closed forms of 1.6/4.5, the air and frame terms of 4.3–4.4 and the error
budget of the operating configuration (closed loop, compensation unit,
aluminium shielding: the repeatability measurement's). What the recordings
add: the huddle analysis (3) and from it the measured 4QD noise (open-loop
tests) and the Sercalo DAC's quantisation error (closed-loop tests), which
replace the nominal/white models in the budget; the budget's prediction for
every huddle configuration present; the repeatability analysis (11) and its
comparison with the huddle noise (Fig. 50). Everything left out is listed in
``skipped`` with the reason.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Mapping
from dataclasses import replace
from typing import Any

import control as ct
import numpy as np
import xarray as xr

from fsmbench.bench.blocks import PlantModel, newport_beam_matrix, physical_plant
from fsmbench.bench.esrf import esrf_decentralised_controller, tustin
from fsmbench.bench.params import Bench, BenchParams, PerAxis
from fsmbench.budget.environment import air_budget, frame_budget
from fsmbench.budget.huddle import (
    HUDDLE_CONFIGS,
    HuddleAnalysis,
    QdNoiseEstimate,
    analyse_huddle,
    check_trim,
    estimate_dac_noise,
    huddle_number,
)
from fsmbench.budget.huddle_screen import screen_huddles
from fsmbench.budget.long_record import LongRecordSummary, summarise_long_record
from fsmbench.budget.optics import geometry_budget
from fsmbench.budget.quantisation import noise_sources
from fsmbench.budget.repeatability import (
    RepeatabilityRecord,
    analyse_repeatability,
    huddle_window,
)
from fsmbench.budget.result import BudgetResult, ControllerBudget, NonRepeatability
from fsmbench.budget.signals import is_lazy
from fsmbench.budget.stability import DRIFT_BINS, StabilityRecord, analyse_stability
from fsmbench.budget.table import AngleSources, angle_sources, budget_table
from fsmbench.checks import Check, Notice, first_failure
from fsmbench.io.record_checks import check_recording

# The result types live in fsmbench.budget.result; named here too, where they were first.
__all__ = ["BudgetResult", "ControllerBudget", "NonRepeatability", "budget_study",
           "with_recommended"]

_HUDDLE = tuple(f"data_huddle_test_{i}" for i in HUDDLE_CONFIGS)
_REP = {"data_rep_h": "h", "data_rep_v": "v"}



def _plausible(recordings: Mapping[str, xr.Dataset], *, bench: Bench,
               skipped: dict[str, str], checks: list[Check],
               notices: list[Notice]) -> dict[str, xr.Dataset]:
    """The huddle and repeatability records that pass their plausibility checks."""
    conv = bench.nominal.converter
    passed = {}
    for name in (*_HUDDLE, *_REP):
        if name not in recordings:
            continue
        found, notes = check_recording(recordings[name], name=name, fs_hz=conv.fs_hz,
                                       adc_range_v=conv.range_v, adc_bits=conv.bits)
        checks.extend(found)
        notices.extend(notes)
        if (bad := first_failure(found)) is not None:
            skipped[name] = (f"{bad.sentence()}; the record is left "
                             "out of the analysis and of every comparison")
            continue
        passed[name] = recordings[name]
    return passed


def _valid_huddles(recordings: Mapping[str, xr.Dataset],
                   skipped: dict[str, str]) -> dict[str, xr.Dataset]:
    valid = {}
    for name in _HUDDLE:
        if name in skipped:
            continue
        if name not in recordings:
            skipped[name] = "not in the recordings (ESRF study 3)"
            continue
        try:
            check_trim(recordings[name], name=name)
        except ValueError as exc:
            skipped[name] = str(exc)
            continue
        valid[name] = recordings[name]
    return valid


def budget_study(recordings: Mapping[str, xr.Dataset], *, bench: Bench,
                 plant: PlantModel | None = None, controller: ct.StateSpace | None = None,
                 window_s: float = 100.0, df_hz: float = 0.1,
                 progress: Callable[[str], None] | None = None,
                 recommended: ct.StateSpace | None = None,
                 recommended_name: str = "fsmbench's controller",
                 noise_model: Any = None, controller_name: str = "") -> BudgetResult:
    """ESRF study sections 3, 4 and 11 on the recordings present.

    Parameters
    ----------
    recordings : mapping of str to xarray.Dataset
        Records by experiment name (``data_huddle_test_1..5``, ``data_rep_h``,
        ``data_rep_v``; others are ignored).
    bench : Bench
        ``bench.nominal`` supplies every model number (what is known without
        the twin's truth).
    plant : PlantModel, optional
        Plant with outputs ``Rh, Rv`` (e.g. the identified one); default
        ``physical_plant(bench.nominal)``.
    controller : control.StateSpace, optional
        Loop controller ``Rh, Rv → Uch, Ucv`` (``U = −K R``); default the ESRF study's
        9.2 controller discretised as its 9.3 (Tustin at ``1/fs``).
    controller_name : str
        ``controller`` in words (default its ``name``).
    window_s : float
        Record length of the budget's rms [s] (the huddle tests' 100 s).
    df_hz : float
        Frequency step of the propagation grid [Hz].
    progress : callable, optional
        Receives the progress of the reads of huddle tests analysed out of core.
    recommended : control.StateSpace, optional
        The controller a verdict recommends (continuous, Tustin at ``1/fs`` as the
        target runs it, or discrete): its budget of the operating configuration
        is computed beside the recorded one, with the Sercalo DAC's error as white
        ``q²/12`` (the huddle tests measured it behind the controller that ran).
    recommended_name : str
        Its name in words.
    noise_model : NoiseModelFit, optional
        The noise the identification fitted to the huddle tests
        (:mod:`fsmbench.ident.noise_model`): the Newport's angle noise and the
        Attocube's floor it measured replace the bench file's (their rows become
        *measured*).
    """
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = _budget_study(recordings, bench=bench, plant=plant, controller=controller,
                               window_s=window_s, df_hz=df_hz, progress=progress,
                               recommended=recommended, recommended_name=recommended_name,
                               noise_model=noise_model, controller_name=controller_name)
    numeric = tuple(Notice("numeric", "budget", f"{w.category.__name__}: {w.message}")
                    for w in caught)
    return replace(result, notices=result.notices + numeric) if numeric else result


def _usable_records(recordings: Mapping[str, xr.Dataset], *, bench: Bench,
                    params: BenchParams, plant: PlantModel, skipped: dict[str, str],
                    checks: list[Check], notices: list[Notice]
                    ) -> tuple[dict[str, xr.Dataset], dict[str, xr.Dataset]]:
    """The plausible records, and the huddle tests among them that can be compared; what is
    left out is named in ``skipped``, ``checks`` and ``notices``."""
    usable = _plausible(recordings, bench=bench, skipped=skipped, checks=checks,
                        notices=notices)
    # Copies, a closed-loop test whose loop was not closed, an open-loop test recorded with
    # the loop closed: named, and left out of every comparison (budget.huddle_screen).
    # The plant from the commands to the 4QD, flat in the 1–10 Hz band (its value at 5 Hz):
    # the closed-loop tests then measure how much of that band their loop removed.
    uc_to_vp = np.real(plant.frequency_response(
        np.array([5.0]), outputs=("Vph", "Vpv"), inputs=("Uch", "Ucv")).values[0])
    screen = screen_huddles(usable, fs_hz=params.converter.fs_hz,
                            step_v=params.converter.lsb_v, uc_to_vp=uc_to_vp)
    checks.extend(screen.checks)
    notices.extend(Notice("other", "data_huddle_test_1, 2, 4: Vph, Vpv", n)
                   for n in screen.notes)
    for name, why in screen.excluded.items():
        skipped[name] = f"{why}; the record is left out of the analysis and of every comparison"
        usable.pop(name, None)
    return usable, _valid_huddles(usable, skipped)


def _huddle_predictions(huddle: HuddleAnalysis, *, params: BenchParams, bench: Bench,
                        plant: PlantModel, controller: ct.StateSpace,
                        angles: Callable[[bool], AngleSources], df_hz: float,
                        checks: list[Check]) -> dict[int, float]:
    """Each huddle test's Va rms as the budget predicts it [m]; its cross-checks against the
    bench file's own prediction added to ``checks``."""
    predicted: dict[int, float] = {}
    for n, rec in huddle.records.items():
        closed, comp, alu = HUDDLE_CONFIGS[n]
        predicted[n] = budget_table(params, angles(closed), compensation_unit=comp,
                                    shielding=alu, window_s=rec.duration_s).total_rms_m
    # The cross-check's reference is the bench file alone: a measured input (the 4QD's
    # noise, the DAC's error) that is itself wrong must not hide, or fake, a wrong Va.
    nominal = bench.nominal
    reference: dict[int, float] = {}
    cache_ref: dict[bool, AngleSources] = {}
    for n, rec in huddle.records.items():
        closed, comp, alu = HUDDLE_CONFIGS[n]
        if closed not in cache_ref:
            cache_ref[closed] = angle_sources(nominal, plant=plant, controller=controller,
                                              closed_loop=closed, df_hz=df_hz)
        reference[n] = budget_table(nominal, cache_ref[closed], compensation_unit=comp,
                                    shielding=alu, window_s=rec.duration_s).total_rms_m
    checks.extend(huddle_cross_checks(huddle, predicted_va_rms_m=reference, params=nominal))
    return predicted


def _repeatability(usable: Mapping[str, xr.Dataset], *, params: BenchParams,
                   skipped: dict[str, str],
                   progress: Callable[[str], None] | None) -> dict[str, RepeatabilityRecord]:
    """ESRF study 11: each repeatability record analysed, by direction (what cannot be,
    named in ``skipped``)."""
    say = progress or (lambda _msg: None)
    reps: dict[str, RepeatabilityRecord] = {}
    for name, direction in _REP.items():
        if name in skipped:
            continue
        if name not in usable:
            skipped[name] = "not in the recordings (ESRF study 11)"
            continue
        say(f"repeatability: {name} (ESRF study 11)")
        try:
            reps[direction] = analyse_repeatability(usable[name], params=params, name=name,
                                                    progress=progress)
        except ValueError as exc:
            skipped[name] = str(exc)
    return reps


def _nonrepeatability(reps: Mapping[str, RepeatabilityRecord], *, huddle: HuddleAnalysis | None,
                      usable: Mapping[str, xr.Dataset], params: BenchParams,
                      angles: Callable[[bool], AngleSources],
                      notices: list[Notice]) -> dict[str, NonRepeatability]:
    """Each direction's non-repeatability against the huddle test's Va and the budget's
    prediction over the same length (Fig. 50)."""
    nonrep: dict[str, NonRepeatability] = {}
    ref = None
    if huddle is not None:
        ref = huddle.records.get(5) or huddle.records[max(huddle.records)]
    window = None
    if ref is not None and reps and ref.name in usable:
        # Fig. 50's last panel: the huddle test over the longest record's aligned length.
        longest = max(r.n_periods * r.period_samples for r in reps.values())
        try:
            window = huddle_window(usable[ref.name], name=ref.name, n_max=longest)
        except ValueError as exc:
            notices.append(Notice("other", f"{ref.name}: Va", str(exc)))
    for d, r in reps.items():
        pred = budget_table(params, angles(True), window_s=r.n_periods * r.period_s)
        nonrep[d] = NonRepeatability(
            direction=d, va_nonrep_rms_m=r.nonrep_rms_m,
            va_nonrep_unbiased_m=r.nonrep_rms_unbiased_m,
            tracking_nonrep_rms_m=r.tracking_distance_nonrep_rms_m,
            huddle_test=None if ref is None else ref.name,
            huddle_va_rms_m=None if ref is None else ref.va_rms_m,
            predicted_rms_m=pred.total_rms_m, huddle_window=window)
    return nonrep


def _budget_study(recordings: Mapping[str, xr.Dataset], *, bench: Bench,
                  plant: PlantModel | None, controller: ct.StateSpace | None,
                  window_s: float, df_hz: float,
                  progress: Callable[[str], None] | None,
                  recommended: ct.StateSpace | None = None,
                  recommended_name: str = "", noise_model: Any = None,
                  controller_name: str = "") -> BudgetResult:
    params, measured = _measured_params(bench.nominal, noise_model)
    plant = physical_plant(params, source="physical (nominal)") if plant is None else plant
    params = _with_plant_qd_gain(params, plant)
    if controller is None:
        controller = tustin(esrf_decentralised_controller(), ts_s=params.converter.ts_s)
        controller_name = "ESRF study 9.2 K, Tustin at 1/fs (9.3)"
    else:
        controller_name = controller_name or str(controller.name or "given controller")
    skipped: dict[str, str] = {}
    checks: list[Check] = []
    notices: list[Notice] = []
    usable, valid = _usable_records(recordings, bench=bench, params=params, plant=plant,
                                    skipped=skipped, checks=checks, notices=notices)
    # Records out of core are read twice, in blocks, for everything below (huddle and stability).
    summaries = {name: summarise_long_record(ds, name=name, n_bins=DRIFT_BINS, progress=progress)
                 for name, ds in valid.items() if is_lazy(ds["Va"].data)}
    say = progress or (lambda _msg: None)
    if valid:
        say(f"huddle tests: spectra and rms of {', '.join(sorted(valid))} (ESRF study 3)")
    huddle = analyse_huddle(valid, params=params, summaries=summaries) if valid else None
    if valid:
        say("huddle tests: drift and Allan deviation over each whole record")
    stability = _stability(valid, params=params, summaries=summaries)
    qd = None if huddle is None else huddle.qd_noise
    if qd is None:
        skipped["4QD noise from huddle data"] = ("no open-loop huddle test (1, 2, 4): the "
                                                 "nominal white noise is used")
    dac, dac_skipped = estimate_dac_noise(valid, controller=controller, params=params)
    skipped.update({f"{k} (DAC noise)": v for k, v in dac_skipped.items()})
    if dac is None:
        skipped["Sercalo DAC noise from huddle data"] = (
            "no usable closed-loop huddle test (3, 5) with Uch, Ucv: the white q²/(12 fs) "
            "model is used")
    cache: dict[bool, AngleSources] = {}

    def angles(closed: bool) -> AngleSources:
        if closed not in cache:
            a = angle_sources(params, plant=plant, controller=controller, closed_loop=closed,
                              qd_noise=qd, dac_noise=dac, df_hz=df_hz)
            cache[closed] = replace(a, spectra_origin={**a.spectra_origin, **measured})
        return cache[closed]

    say(f"error budget: every source through the plant and the loop with {controller_name} "
        "(ESRF study 4)")
    budget = budget_table(params, angles(True), window_s=window_s)
    stationary = budget_table(params, angles(True), window_s=None).total_rms_m
    rec_budget = None
    if recommended is not None:
        say(f"error budget: the same with {recommended_name}")
        rec_budget = _recommended_budget(params, plant=plant, qd=qd, measured=measured,
                                         recommended=recommended, name=recommended_name,
                                         df_hz=df_hz, window_s=window_s)
    predicted = {} if huddle is None else _huddle_predictions(
        huddle, params=params, bench=bench, plant=plant, controller=controller, angles=angles,
        df_hz=df_hz, checks=checks)
    reps = _repeatability(usable, params=params, skipped=skipped, progress=progress)
    nonrep = _nonrepeatability(reps, huddle=huddle, usable=usable, params=params,
                               angles=angles, notices=notices)
    return BudgetResult(
        plant_source=plant.source, controller=controller_name,
        noise=noise_sources(params, plant=plant,
                            qd_noise_v=None if qd is None else qd.rms_v),
        geometry=geometry_budget(params), air=air_budget(params, window_s=window_s),
        frame=frame_budget(params, window_s=window_s), budget=budget, huddle=huddle,
        dac_noise=dac, predicted_huddle_va_rms_m=predicted, repeatability=reps,
        nonrep=nonrep, skipped=skipped, checks=tuple(checks), notices=tuple(notices),
        stability=stability, stationary_total_rms_m=stationary, recommended=rec_budget)


def _recommended_budget(params: BenchParams, *, plant: PlantModel, qd: QdNoiseEstimate | None,
                        measured: Mapping[str, str], recommended: ct.StateSpace, name: str,
                        df_hz: float, window_s: float) -> ControllerBudget:
    """The budget of the operating configuration with ``recommended`` in the loop (the
    Sercalo DAC's error white, ``q²/12``: the huddle tests measured it behind another
    controller)."""
    k_rec = recommended if recommended.dt else tustin(recommended, ts_s=params.converter.ts_s)
    rec_angles = angle_sources(params, plant=plant, controller=k_rec, closed_loop=True,
                               qd_noise=qd, dac_noise=None, df_hz=df_hz)
    rec_angles = replace(rec_angles, spectra_origin={**rec_angles.spectra_origin, **measured})
    return ControllerBudget(name, budget_table(params, rec_angles, window_s=window_s),
                            budget_table(params, rec_angles, window_s=None).total_rms_m)


def with_recommended(result: BudgetResult, *, bench: Bench, plant: PlantModel | None = None,
                     recommended: ct.StateSpace,
                     recommended_name: str = "fsmbench's controller",
                     noise_model: Any = None, window_s: float = 100.0,
                     df_hz: float = 0.1) -> BudgetResult:
    """``result`` (a :func:`budget_study` without ``recommended``) with the budget of the
    controller a verdict recommends added, as :func:`budget_study` computes it.

    The same ``bench``, ``plant``, ``noise_model``, ``window_s`` and ``df_hz`` as the
    study's: the budget of the records and the recommended one can then be computed at
    different times (the study computes the records' beside the design).
    """
    params, measured = _measured_params(bench.nominal, noise_model)
    plant = physical_plant(params, source="physical (nominal)") if plant is None else plant
    params = _with_plant_qd_gain(params, plant)
    qd = None if result.huddle is None else result.huddle.qd_noise
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        rec = _recommended_budget(params, plant=plant, qd=qd, measured=measured,
                                  recommended=recommended, name=recommended_name,
                                  df_hz=df_hz, window_s=window_s)
    numeric = tuple(Notice("numeric", "budget", f"{w.category.__name__}: {w.message}")
                    for w in caught)
    return replace(result, recommended=rec, notices=result.notices + numeric)


#: Measured huddle Va rms against the budget's prediction for the same configuration: the
#: budget's environment terms are the bench file's assumptions (room drifts, sensor errors),
#: good to a factor ~2; a factor 5 (14 dB) apart is a unit, a jump or a wrong channel.
HUDDLE_VA_BAND = (0.2, 5.0)
#: Measured open-loop 4QD rms against the bench file's noise model: a 4QD amplifier a few
#: times noisier than its datasheet is a bench; a factor 10 (20 dB) is a unit or a channel.
HUDDLE_QD_BAND = (0.1, 10.0)


def _unit_cause(ratio: float, *, unit: str, device: str) -> str:
    """A ratio near a power of a thousand: the unit slip, beside ``device`` that much off
    (the ratio alone cannot tell them: dividing by 1000 on a guess would fake a pass);
    empty otherwise."""
    for power, prefix in ((1, "m"), (2, "µ"), (3, "n")):
        factor = 1e3**power
        if abs(math.log10(ratio / factor)) < 0.15:  # within 40 % of the round factor
            return (f"either a unit (the record in {prefix}{unit}, not {unit}), or {device} "
                    f"{factor:g}× the bench file's; the records cannot tell which: check the "
                    "channel's unit before anything is rescaled")
        if abs(math.log10(ratio * factor)) < 0.15:
            return (f"either a unit (the record {factor:g}× too small: a scaling applied "
                    f"twice?), or {device} {factor:g}× below the bench file's; the records "
                    "cannot tell which")
    return ""


def _line_share(f_hz: np.ndarray, psd: np.ndarray) -> tuple[float, float]:
    """(share of the power in the strongest mains line family, its frequency [Hz]): a line at
    50 or 60 Hz and its first harmonics, ±1 Hz each, over the whole PSD."""
    df = float(f_hz[1] - f_hz[0]) if f_hz.size > 1 else 1.0
    total = float(np.sum(psd)) * df
    best = (0.0, 0.0)
    for mains in (50.0, 60.0):
        near = np.zeros(f_hz.size, dtype=bool)
        for k in range(1, 6):
            near |= np.abs(f_hz - k * mains) <= 1.0
        share = float(np.sum(psd[near])) * df / total if total > 0 else 0.0
        best = max(best, (share, mains))
    return best


def huddle_cross_checks(huddle: HuddleAnalysis, *, predicted_va_rms_m: Mapping[int, float],
                        params: BenchParams) -> list[Check]:
    """The huddle tests' measured rms against what the bench file predicts for them.

    ``huddle_va_vs_prediction`` (each test: measured ``Va`` rms over the budget of its
    configuration from the bench file alone, :data:`HUDDLE_VA_BAND`) and
    ``huddle_qd_vs_model`` (each open-loop
    test: the 4QD outputs' rms over the bench file's 4QD, Newport and ADC noise,
    :data:`HUDDLE_QD_BAND`). A failed one names the file, the signal, both numbers and
    the likely cause; the verdict's distance requirement is then not verified.
    """
    out: list[Check] = []
    conv = params.converter
    gd = params.quad_diode.gain_v_per_rad.as_array()
    newport = gd**2 * (newport_beam_matrix(params) ** 2).sum(axis=1) \
        * params.newport.angle_noise_rms_rad**2
    for n, rec in huddle.records.items():
        pred = predicted_va_rms_m.get(n)
        if pred is not None and pred > 0:
            ratio = rec.va_rms_m / pred
            ok = bool(math.isfinite(ratio) and HUDDLE_VA_BAND[0] <= ratio <= HUDDLE_VA_BAND[1])
            cause = _unit_cause(ratio, unit="m", device="an interferometer noise") or (
                "a jump in Va (the interferometer lost count) or an environment far from the "
                "bench file's" if ratio > 1 else "Va not the beam path's distance")
            out.append(Check(
                "huddle_va_vs_prediction", ok, float(ratio),
                f"{HUDDLE_VA_BAND[0]:g} to {HUDDLE_VA_BAND[1]:g} times the budget's prediction",
                f"{rec.name}.mat: Va", "" if ok else
                f"measured {rec.va_rms_m * 1e9:.4g} nm rms where the budget predicts "
                f"{pred * 1e9:.3g} nm for this configuration: {cause}", unit="×"))
        if rec.closed_loop:
            continue
        for i, (vp, rms) in enumerate((("Vph", rec.vph_rms_v), ("Vpv", rec.vpv_rms_v))):
            model = math.sqrt(params.quad_diode.noise_rms_v.as_array()[i] ** 2 + newport[i]
                              + conv.lsb_v**2 / 12.0)
            ratio = rms / model
            ok = bool(math.isfinite(ratio) and HUDDLE_QD_BAND[0] <= ratio <= HUDDLE_QD_BAND[1])
            share, mains = _line_share(rec.f_hz, rec.psd_vph_v2_per_hz if i == 0
                                       else rec.psd_vpv_v2_per_hz)
            cause = (f"mains pickup: the {mains:g} Hz line and its harmonics carry "
                     f"{100 * share:.0f} % of the power (an earth loop, a cable near a supply)"
                     if share > 0.5 else
                     _unit_cause(ratio, unit="V", device="a 4QD noise") or
                     "either a wrong channel, or a 4QD amplifier noisier than the bench file's")
            out.append(Check(
                "huddle_qd_vs_model", ok, float(ratio),
                f"{HUDDLE_QD_BAND[0]:g} to {HUDDLE_QD_BAND[1]:g} times the bench file's noise",
                f"{rec.name}.mat: {vp}", "" if ok else
                f"measured {rms * 1e3:.4g} mV rms with nothing moving where the bench file's 4QD, "
                f"Newport and ADC noise give {model * 1e3:.3g} mV: {cause}", unit="×"))
    return out


def _with_plant_qd_gain(params: BenchParams, plant: PlantModel) -> BenchParams:
    """``params`` with the 4QD gain of the plant the budget runs on (its ``Gd``).

    Volts become radians with one gain everywhere: the huddle tests' Newport share and the
    4QD noise in radians with the plant's own (an identified 4QD five times the bench
    file's once read the Newport's share 5× low and the 4QD's noise 35 % high)."""
    if "Gd" not in plant.blocks:
        return params
    gd = np.diag(np.asarray(plant.blocks["Gd"].D, dtype=float))
    if gd.shape != (2,) or not np.all(np.isfinite(gd)) or np.any(gd == 0):
        return params
    return replace(params, quad_diode=replace(
        params.quad_diode, gain_v_per_rad=PerAxis(h=float(gd[0]), v=float(gd[1]))))


def _measured_params(params: BenchParams, noise_model: Any) -> tuple[BenchParams, dict[str, str]]:
    """The bench file's values with what the noise model measured, and where each came from."""
    measured: dict[str, str] = {}
    if noise_model is None:
        return params, measured
    tests = ", ".join(noise_model.tests)
    if noise_model.newport_noise_rad.significant:
        params = replace(params, newport=replace(
            params.newport, angle_noise_rms_rad=noise_model.newport_noise_rad.value))
        measured["newport_angle"] = (f"measured: the 4QD–Va cross-spectrum of {tests} "
                                     f"({noise_model.newport_noise_rad.value * 1e6:.3g} µrad rms)")
    if str(noise_model.provenance.get("attocube.noise_rms_m", "")).startswith("measured"):
        params = replace(params, attocube=replace(
            params.attocube, noise_rms_m=noise_model.attocube_noise_rms_m.value))
        measured["attocube"] = (f"measured: the Va floor of {tests} "
                                f"({noise_model.attocube_noise_rms_m.value * 1e9:.3g} nm rms)")
    return params, measured


def _stability(valid: Mapping[str, xr.Dataset], *, params: BenchParams,
               summaries: Mapping[str, LongRecordSummary]) -> dict[int, StabilityRecord]:
    """Drift and Allan deviation of every valid huddle test (out of core for lazy records)."""
    gd = params.quad_diode.gain_v_per_rad
    return {huddle_number(name): analyse_stability(ds, name=name, qd_gain_v_per_rad=(gd.h, gd.v),
                                                   summary=summaries.get(name))
            for name, ds in valid.items()}
