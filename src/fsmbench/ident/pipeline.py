"""The seed's section 2 in one call: recordings → identified plant.

:func:`identify` runs each step on the experiments present and records, for
each step it could not run, why:

=====================  ==========================================  ==============
step                   needs                                       seed
=====================  ==========================================  ==============
4QD gains              ``data_cal_pd_h``, ``data_cal_pd_v``        2.1
current amplifier      ``data_uch``, ``data_ucv`` (``Vch``, ``Vcv``)  2.2
Sercalo                ``data_uch``, ``data_ucv`` + current amp    2.3
Newport                ``data_unh``, ``data_unv``                  2.4
full system            all of the above (nominal blocks stand in)  2.5
=====================  ==========================================  ==============

Before a step runs, its recordings pass the plausibility checks of
:func:`fsmbench.io.folder.check_recording` against the bench (rate, data
type, converter range, signals that move); after the 4QD calibration, its r²,
residual and gain against the nominal are checked
(:func:`fsmbench.ident.calibration.qd_checks`). A failed check makes the step
fall back to the nominal block, and ``skipped`` gives the check's name and
sentence as the reason; every check is in ``checks``.

:meth:`Identification.to_json` has the keys of ``twin_truth.json``
(``qd_gain_v_per_rad``, ``current_amp_gain_a_per_v``,
``sercalo.{h,v}.{resonance_hz, damping_ratio, dc_gain_v_per_a}``,
``newport_gain_v_per_v``, ``delay_s``) plus a ``diagnostics`` tree;
:func:`write_identification` puts ``format`` and ``format_version`` first.
"""

from __future__ import annotations

import math
import warnings as pywarnings
from collections.abc import Callable, Mapping
from dataclasses import replace

import control as ct
import numpy as np
import xarray as xr

from fsmbench.bench.blocks import (
    assemble_plant,
    coil_impedance,
    current_amplifier,
    input_delays_s,
    newport,
    quad_diode,
    sercalo,
    voltage_amplifier,
)
from fsmbench.bench.params import Bench
from fsmbench.checks import Check, Finding, Notice, first_failure
from fsmbench.ident.calibration import (
    CurrentAmplifierGain,
    QdCalibration,
    calibrate_current_amplifier,
    calibrate_qd,
    current_amp_checks,
    qd_checks,
)
from fsmbench.ident.compare import compare_records
from fsmbench.ident.consistency import screen_recordings
from fsmbench.ident.crosscheck import (
    NOISE_CHECKS,
    cross_checks,
    floor_checks,
    newport_drive_gains,
)
from fsmbench.ident.delay.sampled import SensorLowpass
from fsmbench.ident.delay.sercalo import with_sensor
from fsmbench.ident.evidence.amplifier import (
    axis_lag_check,
    decide_amplifier,
    with_decided_sensor,
)
from fsmbench.ident.evidence.departures import (
    datasheet_departures,
    departures,
    matching_datasheet,
    matching_params,
    measured_keys,
    merged_findings,
)
from fsmbench.ident.evidence.rate import (
    controller_rate_check,
    current_amplifier_rate_check,
    records_rate,
)
from fsmbench.ident.evidence.recorded_loop import (
    rate_witness,
)
from fsmbench.ident.evidence.sensor_shifts import (
    resolved_sensor,
    sensor_notices,
    unresolved_sensor_shifts,
)
from fsmbench.ident.fit.modes import ModeRefinement, refine_modes
from fsmbench.ident.fit.quality import (
    leakage_corrected,
    quality_warnings,
    sensor_shift_notices,
)
from fsmbench.ident.fit.truncation import TruncationCheck, truncation_checks
from fsmbench.ident.frf.compression import (
    CompressionFactors,
    compression_factors,
    correct_compression,
)
from fsmbench.ident.frf.experiment import OUTPUTS, choose_estimator, experiment_frf
from fsmbench.ident.model_band import model_band
from fsmbench.ident.newport import (
    NewportIdentification,
    identify_newport,
    newport_checks,
    nominal_newport_axis,
)
from fsmbench.ident.noise_model import fit_noise_model
from fsmbench.ident.result import (
    IDENTIFICATION_FORMAT,
    SEED_TRIMS_S,
    Identification,
    IdentifyOptions,
    path_keyed_summary,
    write_identification,
)
from fsmbench.ident.sercalo import (
    SercaloIdentification,
    fit_sercalo,
    refit_with_poles,
    with_frf,
)
from fsmbench.ident.totals import (
    qd_amplifier_lag_s,
    qd_amplifier_lags_by_axis,
    uncertainty_tree,
)
from fsmbench.ident.validate import PathValidation, validate_sercalo
from fsmbench.io.folder import check_recording

__all__ = [
    "IDENTIFICATION_FORMAT",
    "NOISE_EXPERIMENTS",
    "SEED_TRIMS_S",
    "Identification",
    "IdentifyOptions",
    "identify",
    "path_keyed_summary",
    "quality_warnings",
    "write_identification",
]

#: The records the noise model is fitted to (open-loop huddle tests, seed 3).
NOISE_EXPERIMENTS = ("data_huddle_test_1", "data_huddle_test_2", "data_huddle_test_4")

Progress = Callable[[str], None]

_SERCALO_COLUMNS = (("data_uch", "Uch"), ("data_ucv", "Ucv"))
_NEWPORT_COLUMNS = (("data_unh", "Unh"), ("data_unv", "Unv"))


def _gd_block(qd: Mapping[str, QdCalibration]) -> ct.StateSpace:
    return ct.ss([], [], [], np.diag([qd["h"].gain_v_per_rad, qd["v"].gain_v_per_rad]),
                 inputs=["Rh", "Rv"], outputs=["Vph", "Vpv"], name="Gd")


def _gi_block(gi: Mapping[str, CurrentAmplifierGain]) -> ct.StateSpace:
    return ct.ss([], [], [], np.diag([gi["h"].gain_a_per_v, gi["v"].gain_a_per_v]),
                 inputs=["Uch", "Ucv"], outputs=["Ich", "Icv"], name="Gi")


def identify(recordings: Mapping[str, xr.Dataset], *, bench: Bench,
             options: IdentifyOptions | None = None, source: str = "",
             progress: Progress | None = None,
             unusable: Mapping[str, str] | None = None) -> Identification:
    """Run the seed's section 2 on the recordings present.

    Parameters
    ----------
    recordings : mapping of experiment name to Dataset
        As read by :func:`fsmbench.io.read_recording` (or simulated).
    bench : Bench
        Its nominal parameters supply what the seed takes as known (``Ga``,
        ``Zc``, the Newport metrology gain) and stand in for blocks that
        cannot be identified from the data present.
    options : IdentifyOptions, optional
    source : str
        Where the recordings come from (for the report and JSON).
    progress : callable, optional
        Receives one message per step.
    unusable : mapping of experiment name to reason, optional
        Files that were there but could not be read (the loader's reason): a
        step they would feed says so instead of "missing".
    """
    with pywarnings.catch_warnings(record=True) as caught:
        pywarnings.simplefilter("always")
        result = _identify(recordings, bench=bench, opts=options or IdentifyOptions(),
                           source=source, say=progress or (lambda _msg: None),
                           unusable=dict(unusable or {}))
    numeric = [Notice("numeric", "identification", f"{w.category.__name__}: {w.message}")
               for w in caught]
    # The identified values as bench-file keys: the departures from the bench file are
    # findings about the user's bench, and the bench file that matches the records is the
    # file with every measured key set (ident.evidence.departures).
    used = result.params or bench.nominal
    measured = measured_keys(result.to_json(), params=used)
    found = merged_findings(result.findings, departures(
        measured, bench_file=bench.nominal, fs_hz=used.converter.fs_hz))
    result = replace(result, findings=found, matching=replace(
        bench, nominal=matching_params(bench.nominal, measured, result.findings),
        datasheet=matching_datasheet(bench.datasheet, result.findings)))
    if result.plant is not None and result.matching is not None and (
            result.sercalo is not None or result.newport is not None):
        # The model's dynamics against the records (MATLAB's compare) and its Bode band
        # from the parameters' stds (bode(sys, 'sd', 3)): ident.compare, ident.model_band.
        result = replace(result, comparison=compare_records(
            recordings, plant=result.plant, trims_s=result.options.trims_s),
            bode_band=model_band(result.plant, params=result.matching.nominal,
                                 measured=measured, f_hz=np.geomspace(
                                     1.0, 0.5 * used.converter.fs_hz, 300)))
    # Records against each other and against the physical model (ident.crosscheck): a
    # failed one makes the identification untrusted, as a quality warning does.
    crossed = [*cross_checks(result.to_json(), params=used,
                             newport_drive_rad_per_v=newport_drive_gains(recordings, params=used)),
               *floor_checks(recordings, fs_hz=used.converter.fs_hz)]
    failed = [c for c in crossed if not c.passed and c.name not in NOISE_CHECKS]
    noise_failed = [c for c in crossed if not c.passed and c.name in NOISE_CHECKS]
    skipped = dict(result.skipped)
    if noise_failed:
        skipped["noise_model"] = ("the fitted noise contradicts the bench file ("
                                  + "; ".join(f"{c.subject}: {c.advice}" for c in noise_failed)
                                  + "): simulations use the bench file's noise, assumed")
    return replace(result, notices=result.notices + tuple(numeric),
                   checks=result.checks + tuple(crossed), skipped=skipped,
                   noise_model=None if noise_failed else result.noise_model,
                   warnings=result.warnings + tuple(
                       f"{c.subject}: {c.title} failed: {c.advice}" for c in failed))


_ESTIMATOR_WORDS = {"welch": "Welch H1 (the ESRF study's)",
                    "lpm": "the local polynomial method", "periodic": "averaging over periods"}

_QD_CHECKS = ("calibration_r2", "calibration_residual", "qd_gain_vs_nominal")



def _failure_reason(check: Check, fallback: str) -> str:
    return f"{check.sentence()}; {fallback}"


def _identify(recordings: Mapping[str, xr.Dataset], *, bench: Bench, opts: IdentifyOptions,
              source: str, say: Progress, unusable: Mapping[str, str]) -> Identification:
    nom = bench.nominal
    # The records' rate is the bench's (ident.evidence.rate): a bench file that states
    # another is a finding, a record at another rate than the others is named.
    rate = records_rate(recordings, bench_fs_hz=nom.converter.fs_hz)
    if rate.fs_hz != nom.converter.fs_hz:
        nom = replace(nom, converter=replace(nom.converter, fs_hz=rate.fs_hz))
    conv = nom.converter
    # The 4QD amplifier as the bench model knows it (a datasheet value, or unlimited): the
    # joint delay fits keep its lag apart from the paths' delays.
    sensor = SensorLowpass.from_params(nom)
    skipped: dict[str, str] = {}
    checks: list[Check] = [*rate.checks]
    notices: list[Notice] = []
    seen: dict[str, list[Check]] = {}
    rate_findings = rate.findings
    witness = rate_witness(recordings, fs_hz=conv.fs_hz, step_v=conv.lsb_v)
    # Two witnesses of the real rate in the physics the records carry: the controller the
    # closed-loop records ran, and the coil path's analog corners (ident.evidence).
    rate_checks = [c for c in (
        controller_rate_check(witness, rate) if witness is not None else None,
        current_amplifier_rate_check(recordings, params=nom,
                                     trim_s=opts.trims_s.get("data_uch", 1.0)))
        if c is not None]
    checks.extend(rate_checks)
    wrong_rate = next((c for c in rate_checks if not c.passed), None)
    if wrong_rate is not None:
        rate_findings = ()  # t's rate is not the records' rate: nothing to state

    def missing(*names: str) -> list[str]:
        return [n for n in names if n not in recordings]

    def absent_words(names: list[str]) -> str:
        """Why the named records are absent: never "missing" for a file that was there."""
        gone = [n for n in names if n not in unusable]
        words = [f"missing {', '.join(gone)}"] if gone else []
        words += [f"{n} was not used ({unusable[n]}): correct it or record it again"
                  for n in names if n in unusable]
        return "; ".join(words)

    def data_failure(*names: str) -> Check | None:
        """The first failed plausibility check of the named recordings (each checked once)."""
        for n in names:
            if n not in seen:
                found, notes = check_recording(recordings[n], name=n, fs_hz=conv.fs_hz,
                                               adc_range_v=conv.range_v, adc_bits=conv.bits)
                seen[n] = found
                checks.extend(found)
                notices.extend(notes)
        return first_failure(c for n in names for c in seen[n])

    # The records checked against each other (ident.consistency): signs, swapped cables
    # and 4QD offsets across the records. A failed check joins its records' own: each
    # step using them falls back naming it. Huddle tests failing their checks (a jump in
    # Va …) leave the noise model.
    for name, extra in rate.by_experiment.items():
        if name in recordings:
            data_failure(name)
            seen[name] = [*seen[name], *extra]
    if wrong_rate is not None:
        for name in recordings:
            data_failure(name)
            seen[name] = [*seen[name], wrong_rate]
    screen = screen_recordings(recordings, params=nom, trims_s=opts.trims_s,
                               failure=data_failure)
    for name, extra in screen.by_experiment.items():
        if name in recordings:
            data_failure(name)  # a closed-loop record the signs name: its own checks first
        seen[name] = [*seen.get(name, []), *extra]
    checks.extend(screen.checks)
    notices.extend(screen.notices)
    recordings = screen.recordings
    # The bench's own signs, where the records give them, are the model every step works
    # with: the bench file is a prior (ident.evidence).
    if screen.params is not None:
        nom = screen.params

    qd: dict[str, QdCalibration] = {}
    compression: dict[str, CompressionFactors] = {}
    truncation: dict[str, TruncationCheck] = {}
    if gone := missing("data_cal_pd_h", "data_cal_pd_v"):
        skipped["qd"] = absent_words(gone)
    elif bad := data_failure("data_cal_pd_h", "data_cal_pd_v"):
        skipped["qd"] = _failure_reason(bad, "the nominal 4QD gain is used")
    else:
        say("2.1 calibrating the 4QD against the Newport metrology")
        try:
            for axis in "hv":
                qd[axis] = calibrate_qd(
                    recordings[f"data_cal_pd_{axis}"], axis=axis,
                    metrology_gain_rad_per_v=(nom.newport.metrology_gain_rad_per_v
                                              * nom.newport.metrology_sign[axis]),
                    trim_s=opts.trims_s.get(f"data_cal_pd_{axis}", 1.0))
                checks.extend(qd_checks(qd[axis], nominal_v_per_rad=getattr(
                    nom.quad_diode.gain_v_per_rad, axis)))
        except ValueError as exc:
            qd = {}
            skipped["qd"] = f"failed: {exc}"
        if qd and (bad := first_failure(c for c in checks if c.name in _QD_CHECKS)):
            qd = {}
            skipped["qd"] = _failure_reason(bad, "the nominal 4QD gain is used")

    gi: dict[str, CurrentAmplifierGain] = {}
    sercalo_id: SercaloIdentification | None = None
    modes: ModeRefinement | None = None
    unrefined: SercaloIdentification | None = None  # the fit before its modes' refinement
    validation: tuple[PathValidation, ...] = ()
    if gone := missing("data_uch", "data_ucv"):
        skipped["current_amp"] = skipped["sercalo"] = absent_words(gone)
    elif bad := data_failure("data_uch", "data_ucv"):
        skipped["current_amp"] = skipped["sercalo"] = _failure_reason(
            bad, "the nominal current amplifier and Sercalo are used")
    else:
        say("2.2 identifying the current amplifiers")
        amp_estimator = opts.frf if opts.frf != "auto" else choose_estimator(
            recordings, columns=_SERCALO_COLUMNS, trims_s=opts.trims_s)
        try:
            for axis, exp in (("h", "data_uch"), ("v", "data_ucv")):
                gi[axis] = calibrate_current_amplifier(
                    recordings[exp], axis=axis, nominal=nom, trim_s=opts.trims_s.get(exp, 1.0),
                    band_hz=opts.current_amp_band_hz, window_s=opts.window_s,
                    estimator=amp_estimator)
                checks.extend(current_amp_checks(gi[axis]))
        except ValueError as exc:
            gi = {}
            skipped["current_amp"] = f"failed: {exc}"
            skipped["sercalo"] = "needs the current-amplifier gains (2.2), which failed"
        if gi and (bad := first_failure(c for c in checks
                                        if c.name == "current_amp_gain_vs_theoretical")):
            gi = {}
            skipped["current_amp"] = _failure_reason(bad, "the nominal current amplifier is used")
            skipped["sercalo"] = f"needs the current-amplifier gains (2.2): {bad.title} failed"
    if gi:
        say("2.3 Sercalo: FRF matrix, delay, vector fitting")
        try:
            frf = experiment_frf(recordings, columns=_SERCALO_COLUMNS,
                                 trims_s=opts.trims_s, window_s=opts.window_s,
                                 estimator=opts.frf, transient_periods=opts.transient_periods)
            say(f"2.3 Sercalo: FRF by {_ESTIMATOR_WORDS[frf.estimator]}")
            if qd:
                compression["sercalo"] = compression_factors(
                    recordings, columns=_SERCALO_COLUMNS, outputs=OUTPUTS, qd=qd,
                    trims_s=opts.trims_s)
                frf = correct_compression(frf, compression["sercalo"], recordings=recordings,
                                          columns=_SERCALO_COLUMNS, trims_s=opts.trims_s)
            sercalo_id = fit_sercalo(frf, gi_a_per_v={a: g.gain_a_per_v for a, g in gi.items()},
                                     options=replace(opts.sercalo, weights=opts.weights),
                                     sensor=sensor)
            if sercalo_id.options.weights_fallback:
                notices.append(Notice("other", "data_uch.mat, data_ucv.mat",
                                      f"Sercalo fit: {sercalo_id.options.weights_fallback}"))
            if opts.refine_modes and frf.estimator == "periodic":
                # Averaged periods have no leakage to remove: the fit's modes stand, with
                # stds from every line's noise and distortion (ident.fit_std).
                skipped["mode_refinement"] = ("periodic averaging: no leakage to remove; the "
                                              "fit's modes and their stds are used")
            elif opts.refine_modes:
                say("2.3 Sercalo: refining the modes on the time records")
                modes = refine_modes(recordings, sercalo=sercalo_id, trims_s=opts.trims_s)
                unrefined = sercalo_id
                sercalo_id = refit_with_poles(sercalo_id, poles=modes.poles_by_input())
            else:
                skipped["mode_refinement"] = "disabled by option"
            if frf.estimator == "welch":
                say("2.3 Sercalo: the Welch window's leakage near the modes")
                sercalo_id = with_frf(sercalo_id, leakage_corrected(sercalo_id, opts.window_s,
                                                                unrefined=unrefined),
                                      poles=None if modes is None else modes.poles_by_input())
            validation = validate_sercalo(recordings, sercalo=sercalo_id, trims_s=opts.trims_s)
            truncation = truncation_checks(
                sercalo_id, poles=None if modes is None else modes.poles_by_input())
        except ValueError as exc:
            sercalo_id, modes, validation = None, None, ()
            skipped["sercalo"] = f"failed (data_uch, data_ucv): {exc}"

    newport_id: NewportIdentification | None = None
    datasheet_findings: list[Finding] = []
    amplifier_findings: list[Finding] = []
    # One 4QD amplifier feeds both outputs: the two Sercalo runs' lags must agree, or one
    # run's 4QD channels were delayed, and no delay or amplifier is read from them.
    lag_check = axis_lag_check(qd_amplifier_lags_by_axis(sid=sercalo_id, gi=gi, nominal=nom),
                               fs_hz=conv.fs_hz)
    if lag_check is not None:
        checks.append(lag_check)
        if not lag_check.passed:
            skipped["sercalo"] = _failure_reason(lag_check, "the nominal Sercalo is used")
            sercalo_id, modes, validation = None, None, ()
    # Each Newport axis from its own record: one missing or unusable leaves the other
    # identified, and the bench file's model stands in for it (named, not reported).
    newport_usable, newport_fill = [], {}
    for axis, (exp, _inp) in zip("hv", _NEWPORT_COLUMNS, strict=True):
        if exp not in recordings:
            skipped[f"newport_{axis}"] = absent_words([exp])
        elif bad := data_failure(exp):
            skipped[f"newport_{axis}"] = _failure_reason(bad, "the bench file's Newport is "
                                                              f"used for axis {axis}")
        else:
            newport_usable.append((exp, _inp))
            continue
        newport_fill[axis] = nominal_newport_axis(nom, axis, fs_hz=conv.fs_hz)
    newport_columns = tuple(newport_usable)
    if not newport_columns:
        # Both absent read as one phrase; otherwise each axis's own reason, h first.
        gone = missing("data_unh", "data_unv")
        skipped["newport"] = (absent_words(gone) if len(gone) == 2 else
                              "; ".join(skipped[f"newport_{a}"] for a in "hv"))
        skipped.pop("newport_h", None)
        skipped.pop("newport_v", None)
    else:
        say("2.4 Newport: FRF matrix, delay and gains"
            + (f" (axis {', '.join(a for a in 'hv' if a not in newport_fill)} alone)"
               if newport_fill else ""))
        try:
            nfrf = experiment_frf(recordings, columns=newport_columns,
                                  trims_s=opts.trims_s, window_s=opts.window_s,
                                  estimator=opts.frf, transient_periods=opts.transient_periods)
            if qd:
                compression["newport"] = compression_factors(
                    recordings, columns=newport_columns, outputs=OUTPUTS, qd=qd,
                    trims_s=opts.trims_s)
                nfrf = correct_compression(nfrf, compression["newport"],
                                           recordings=recordings, columns=newport_columns,
                                           trims_s=opts.trims_s)
            newport_id = identify_newport(
                nfrf, band_hz=opts.newport_band_hz, dac_delay_samples=conv.dac_delay_samples,
                converter_delay_s=None if sercalo_id is None else sercalo_id.delay_s,
                sensor=sensor, fill=newport_fill)
            lag_s, lag_std_s = qd_amplifier_lag_s(sid=sercalo_id, gi=gi, nominal=nom)
            first_dynamics = newport_id.dynamics
            decision = (None if first_dynamics is None else decide_amplifier(
                nfrf, first_dynamics, lag_s=lag_s, lag_std_s=lag_std_s, model=sensor))
            # Twice at most: a lag read through a pure delay is the band's mean group
            # delay, not the amplifier's; with the decided amplifier in the Sercalo's fit
            # the lag is its own, and a rerun with bench_identified.toml reads the same.
            for again in (False, True):
                if decision is None or decision.sensor is None:
                    break
                # The delays give the amplifier's lag, the lines its order
                # (ident.evidence.amplifier): the Newport fitted with what both decide.
                newport_id = replace(identify_newport(
                    nfrf, band_hz=opts.newport_band_hz,
                    dac_delay_samples=conv.dac_delay_samples,
                    converter_delay_s=None if sercalo_id is None else sercalo_id.delay_s,
                    sensor=decision.sensor, resolve_sensor=False, fill=newport_fill),
                    sensor_shifts=decision.shifts)
                if newport_id.dynamics is not None:
                    newport_id = replace(newport_id, dynamics=with_decided_sensor(
                        newport_id.dynamics, decision, axes=newport_id.identified_axes))
                amplifier_findings = list(decision.findings)
                if not (decision.resolved and sercalo_id is not None
                        and decision.sensor != sensor):
                    break
                say("2.3 Sercalo: the delay again with the 4QD amplifier the records decide")
                sercalo_id = with_sensor(sercalo_id, decision.sensor)
                own_lag_s, own_std_s = qd_amplifier_lag_s(sid=sercalo_id, gi=gi, nominal=nom)
                if (again or first_dynamics is None or not math.isfinite(own_lag_s)
                        or abs(own_lag_s - lag_s) <= 0.1 * lag_std_s):
                    break
                lag_s, lag_std_s = own_lag_s, own_std_s
                redecided = decide_amplifier(nfrf, first_dynamics, lag_s=lag_s,
                                             lag_std_s=lag_std_s, model=sensor)
                if redecided.sensor is None or not redecided.resolved:
                    break  # the first decision stands, with the Sercalo refitted for it
                decision = redecided
            if decision is not None and decision.sensor is not None:
                notices.append(Notice("other", "4QD amplifier", decision.words))
            if (dyn := newport_id.dynamics) is not None and (
                    decision is None or decision.sensor is None):
                notices.extend(sensor_notices(dyn, model=sensor))
                resolved = resolved_sensor(dyn)
                if resolved is not None and sercalo_id is not None:
                    say("2.3 Sercalo: the delay again with the 4QD amplifier the Newport "
                        "resolved")
                    sercalo_id = with_sensor(sercalo_id, resolved)
                # An amplifier neither the bench model nor the lines give: the delays
                # measure its lag, and its shape bounds the Newport's parameters.
                if np.isfinite(lag_s):
                    shifts = unresolved_sensor_shifts(
                        nfrf, dyn, lag_s=max(lag_s, 0.0) + 1.96 * lag_std_s)
                    newport_id = replace(newport_id, sensor_shifts=shifts)
                    notices.extend(sensor_shift_notices(shifts, lag_s=lag_s,
                                                         noise={a: dyn.axes[a].natural_freq_std_hz
                                                                for a in dyn.axes}))
            if (dyn := newport_id.dynamics) is not None:
                ds_np = bench.datasheet.newport
                # The datasheet is a prior: a Newport off it is a finding about this mirror
                # (its tuning, or another unit), with the datasheet key it contradicts.
                found = newport_checks(
                    dyn, amplitude_bandwidth_hz=ds_np.amplitude_bandwidth_hz,
                    phase_bandwidth_hz=ds_np.phase_bandwidth_hz,
                    peaking_max_db=ds_np.peaking_max_db)
                # Only the axes the records gave (an assumed axis is the bench file's model).
                found = [c for c in found
                         if any(f"Newport {a} " in c.subject
                                for a in newport_id.identified_axes)]
                checks.extend(c for c in found if c.passed)
                datasheet_findings = datasheet_departures(found, datasheet=ds_np)
            else:
                skipped["newport_dynamics"] = newport_id.dynamics_skipped
        except ValueError as exc:
            skipped["newport"] = (f"failed ({', '.join(e for e, _ in newport_columns)}): "
                                  f"{exc}")

    warnings = quality_warnings(sercalo=sercalo_id, modes=modes, validation=validation)
    for w in warnings:
        say(f"warning: {w}")

    say("2.5 assembling the identified system")
    blocks = {
        "Gi": ("identified", _gi_block(gi)) if gi else ("nominal", current_amplifier(nom)),
        "Zc": ("nominal", coil_impedance(nom)),
        "Ga": ("nominal", voltage_amplifier(nom)),
        "Gc": (("identified", sercalo_id.gc) if sercalo_id is not None
               else ("nominal", sercalo(nom))),
        "Gn": (("identified", newport_id.gn) if newport_id is not None
               else ("nominal", newport(nom))),
        "Gd": ("identified", _gd_block(qd)) if qd else ("nominal", quad_diode(nom)),
    }
    delays = dict(input_delays_s(nom))  # the model's, replaced by each identified one
    if sercalo_id is not None:
        delays.update(Uch=sercalo_id.delay_s, Ucv=sercalo_id.delay_s)
    if newport_id is not None:
        delays.update(newport_id.input_delays_s())
    plant = assemble_plant(gi=blocks["Gi"][1], zc=blocks["Zc"][1], ga=blocks["Ga"][1],
                           gc=blocks["Gc"][1], gn=blocks["Gn"][1], gd=blocks["Gd"][1],
                           input_delay_s=delays, source=f"identified ({source})")
    noise = None
    if any(n in recordings for n in NOISE_EXPERIMENTS):
        say("noise model of the open-loop huddle tests (the identified bench's noise)")
        try:
            noise = fit_noise_model(recordings, params=nom, qd_gain_v_per_rad=(
                (qd["h"].gain_v_per_rad, qd["v"].gain_v_per_rad) if qd else None))
        except ValueError as exc:
            skipped["noise_model"] = str(exc)
    result = Identification(qd=qd, current_amp=gi, sercalo=sercalo_id, modes=modes,
                            validation=validation, newport=newport_id, plant=plant,
                            plant_blocks={k: v[0] for k, v in blocks.items()}, skipped=skipped,
                            options=opts, source=source, warnings=warnings,
                            checks=tuple(checks), notices=tuple(notices), noise_model=noise,
                            compression=compression, truncation=truncation,
                            findings=(*rate_findings, *screen.findings, *amplifier_findings,
                                      *datasheet_findings),
                            recorded_loop=dict(screen.loops),
                            params=nom)
    return replace(result, uncertainty=uncertainty_tree(
        qd=qd, current_amp=gi, sercalo=sercalo_id, modes=result.sercalo_modes(),
        newport=newport_id, compression=compression, nominal=nom, truncation=truncation))


