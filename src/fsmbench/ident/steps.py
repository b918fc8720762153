"""The steps of ESRF study section 2, each a function of one :class:`StepRun`.

:func:`fsmbench.ident.pipeline.identify` runs them in order: the records' rate and their
screening against each other (:func:`start_run`), the 4QD calibration (2.1,
:func:`qd_step`), the current amplifiers (2.2, :func:`current_amp_step`), the Sercalo
(2.3, :func:`sercalo_step`), the Newport and the 4QD amplifier the records decide (2.4,
:func:`newport_step`), the assembled plant and the noise model (2.5,
:func:`assemble_step`). Each step returns its value, or an empty one with the reason in
``run.skipped`` under its name; its checks and notices join the run's.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace

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
from fsmbench.bench.params import Bench, BenchParams
from fsmbench.checks import Check, Finding, Notice, first_failure
from fsmbench.ident.calibration import (
    CurrentAmplifierGain,
    QdCalibration,
    calibrate_qd,
    current_amp_checks,
    qd_checks,
)
from fsmbench.ident.consistency import screen_recordings
from fsmbench.ident.current_amp import calibrate_current_amplifier
from fsmbench.ident.delay.sampled import SensorLowpass
from fsmbench.ident.delay.sercalo import with_sensor
from fsmbench.ident.evidence.amplifier import (
    AmplifierDecision,
    axis_lag_check,
    decide_amplifier,
    with_decided_sensor,
)
from fsmbench.ident.evidence.departures import datasheet_departures
from fsmbench.ident.evidence.rate import (
    controller_rate_check,
    current_amplifier_rate_check,
    records_rate,
)
from fsmbench.ident.evidence.recorded_loop import RecordedController, rate_witness
from fsmbench.ident.evidence.sensor_shifts import (
    resolved_sensor,
    sensor_notices,
    unresolved_sensor_shifts,
)
from fsmbench.ident.fit.modes import ModeRefinement, refine_modes
from fsmbench.ident.fit.quality import leakage_corrected, quality_warnings, sensor_shift_notices
from fsmbench.ident.fit.truncation import TruncationCheck, truncation_checks
from fsmbench.ident.frf.compression import (
    CompressionFactors,
    compression_factors,
    correct_compression,
)
from fsmbench.ident.frf.experiment import OUTPUTS, choose_estimator, experiment_frf
from fsmbench.ident.frf.response import FrequencyResponse
from fsmbench.ident.newport import (
    NewportAxisFit,
    NewportIdentification,
    identify_newport,
    newport_checks,
    nominal_newport_axis,
)
from fsmbench.ident.noise_model import NoiseModelFit, fit_noise_model
from fsmbench.ident.result import Identification, IdentifyOptions
from fsmbench.ident.sercalo import (
    SercaloIdentification,
    fit_sercalo,
    refit_with_poles,
    with_frf,
)
from fsmbench.ident.totals import qd_amplifier_lag_s, qd_amplifier_lags_by_axis, uncertainty_tree
from fsmbench.ident.validate import PathValidation, validate_sercalo
from fsmbench.io.record_checks import check_recording

__all__ = ["NOISE_EXPERIMENTS", "NoiseStep", "SercaloStep", "StepRun", "assemble_step",
           "current_amp_step", "newport_step", "noise_step", "qd_step", "sercalo_step",
           "start_run"]

#: The records the noise model is fitted to (open-loop huddle tests, seed 3).
NOISE_EXPERIMENTS = ("data_huddle_test_1", "data_huddle_test_2", "data_huddle_test_4")

Progress = Callable[[str], None]

_SERCALO_COLUMNS = (("data_uch", "Uch"), ("data_ucv", "Ucv"))
_NEWPORT_COLUMNS = (("data_unh", "Unh"), ("data_unv", "Unv"))
_ESTIMATOR_WORDS = {"welch": "Welch H1 (the ESRF study's)",
                    "lpm": "the local polynomial method", "periodic": "averaging over periods"}
_QD_CHECKS = ("calibration_r2", "calibration_residual", "qd_gain_vs_nominal")


def _failure_reason(check: Check, fallback: str) -> str:
    return f"{check.sentence()}; {fallback}"


@dataclass(eq=False)
class StepRun:
    """One identification's state as its steps run: the records (screened), the model
    every step works with (the bench file's, with the rate and signs the records give),
    and what the steps found so far (skip reasons by step, checks, notices, findings).

    Mutable on purpose: it is the steps' accumulator, private to one identification;
    :func:`assemble_step` turns it into the frozen :class:`Identification`.
    """

    recordings: Mapping[str, xr.Dataset]
    bench: Bench
    nom: BenchParams
    opts: IdentifyOptions
    say: Progress
    unusable: Mapping[str, str]
    sensor: SensorLowpass
    skipped: dict[str, str] = field(default_factory=dict)
    checks: list[Check] = field(default_factory=list)
    notices: list[Notice] = field(default_factory=list)
    findings: list[Finding] = field(default_factory=list)
    seen: dict[str, list[Check]] = field(default_factory=dict)
    compression: dict[str, CompressionFactors] = field(default_factory=dict)
    loops: dict[str, RecordedController] = field(default_factory=dict)
    parallel: bool = False  # independent fits of a step side by side (fsmbench.forked)

    def missing(self, *names: str) -> list[str]:
        """The named records that are not among the recordings."""
        return [n for n in names if n not in self.recordings]

    def absent_words(self, names: list[str]) -> str:
        """Why the named records are absent: never "missing" for a file that was there."""
        gone = [n for n in names if n not in self.unusable]
        words = [f"missing {', '.join(gone)}"] if gone else []
        words += [f"{n} was not used ({self.unusable[n]}): correct it or record it again"
                  for n in names if n in self.unusable]
        return "; ".join(words)

    def data_failure(self, *names: str) -> Check | None:
        """The first failed plausibility check of the named recordings (each checked once)."""
        conv = self.nom.converter
        for n in names:
            if n not in self.seen:
                found, notes = check_recording(self.recordings[n], name=n, fs_hz=conv.fs_hz,
                                               adc_range_v=conv.range_v, adc_bits=conv.bits)
                self.seen[n] = found
                self.checks.extend(found)
                self.notices.extend(notes)
        return first_failure(c for n in names for c in self.seen[n])


def start_run(recordings: Mapping[str, xr.Dataset], *, bench: Bench, opts: IdentifyOptions,
              say: Progress, unusable: Mapping[str, str], parallel: bool = False) -> StepRun:
    """The records' rate and their screening against each other: the run the steps share
    (``parallel``: independent fits within a step side by side, :mod:`fsmbench.forked`)."""
    nom = bench.nominal
    # The records' rate is the bench's (ident.evidence.rate): a bench file that states
    # another is a finding, a record at another rate than the others is named.
    rate = records_rate(recordings, bench_fs_hz=nom.converter.fs_hz)
    if rate.fs_hz != nom.converter.fs_hz:
        nom = replace(nom, converter=replace(nom.converter, fs_hz=rate.fs_hz))
    conv = nom.converter
    # The 4QD amplifier as the bench model knows it (a datasheet value, or unlimited): the
    # joint delay fits keep its lag apart from the paths' delays.
    run = StepRun(recordings=recordings, bench=bench, nom=nom, opts=opts, say=say,
                  unusable=unusable, sensor=SensorLowpass.from_params(nom),
                  checks=[*rate.checks], parallel=parallel)
    witness = rate_witness(recordings, fs_hz=conv.fs_hz, step_v=conv.lsb_v)
    # Two witnesses of the real rate in the physics the records carry: the controller the
    # closed-loop records ran, and the coil path's analog corners (ident.evidence).
    rate_checks = [c for c in (
        controller_rate_check(witness, rate) if witness is not None else None,
        current_amplifier_rate_check(recordings, params=nom,
                                     trim_s=opts.trims_s.get("data_uch", 1.0)))
        if c is not None]
    run.checks.extend(rate_checks)
    wrong_rate = next((c for c in rate_checks if not c.passed), None)
    # t's rate is not the records' rate: nothing to state about it.
    rate_findings = rate.findings if wrong_rate is None else ()
    # The records checked against each other (ident.consistency): signs, swapped cables
    # and 4QD offsets across the records. A failed check joins its records' own: each
    # step using them falls back naming it. Huddle tests failing their checks (a jump in
    # Va …) leave the noise model.
    for name, extra in rate.by_experiment.items():
        if name in recordings:
            run.data_failure(name)
            run.seen[name] = [*run.seen[name], *extra]
    if wrong_rate is not None:
        for name in recordings:
            run.data_failure(name)
            run.seen[name] = [*run.seen[name], wrong_rate]
    screen = screen_recordings(recordings, params=nom, trims_s=opts.trims_s,
                               failure=run.data_failure)
    for name, extra in screen.by_experiment.items():
        if name in recordings:
            run.data_failure(name)  # a closed-loop record the signs name: its own checks first
        run.seen[name] = [*run.seen.get(name, []), *extra]
    run.checks.extend(screen.checks)
    run.notices.extend(screen.notices)
    run.recordings = screen.recordings
    # The bench's own signs, where the records give them, are the model every step works
    # with: the bench file is a prior (ident.evidence).
    if screen.params is not None:
        run.nom = screen.params
    run.findings.extend([*rate_findings, *screen.findings])
    run.loops = dict(screen.loops)
    return run


def qd_step(run: StepRun) -> dict[str, QdCalibration]:
    """2.1: the 4QD calibrated against the Newport metrology, per axis (empty: skipped)."""
    nom, opts = run.nom, run.opts
    qd: dict[str, QdCalibration] = {}
    if gone := run.missing("data_cal_pd_h", "data_cal_pd_v"):
        run.skipped["qd"] = run.absent_words(gone)
        return qd
    if bad := run.data_failure("data_cal_pd_h", "data_cal_pd_v"):
        run.skipped["qd"] = _failure_reason(bad, "the nominal 4QD gain is used")
        return qd
    run.say("2.1 calibrating the 4QD against the Newport metrology")
    try:
        for axis in "hv":
            qd[axis] = calibrate_qd(
                run.recordings[f"data_cal_pd_{axis}"], axis=axis,
                metrology_gain_rad_per_v=(nom.newport.metrology_gain_rad_per_v
                                          * nom.newport.metrology_sign[axis]),
                trim_s=opts.trims_s.get(f"data_cal_pd_{axis}", 1.0))
            run.checks.extend(qd_checks(qd[axis], nominal_v_per_rad=getattr(
                nom.quad_diode.gain_v_per_rad, axis)))
    except ValueError as exc:
        qd = {}
        run.skipped["qd"] = f"failed: {exc}"
    if qd and (bad := first_failure(c for c in run.checks if c.name in _QD_CHECKS)):
        qd = {}
        run.skipped["qd"] = _failure_reason(bad, "the nominal 4QD gain is used")
    return qd


def current_amp_step(run: StepRun) -> dict[str, CurrentAmplifierGain]:
    """2.2: the current amplifiers' gains, per axis (empty: skipped, with the Sercalo)."""
    opts = run.opts
    gi: dict[str, CurrentAmplifierGain] = {}
    if gone := run.missing("data_uch", "data_ucv"):
        run.skipped["current_amp"] = run.skipped["sercalo"] = run.absent_words(gone)
        return gi
    if bad := run.data_failure("data_uch", "data_ucv"):
        run.skipped["current_amp"] = run.skipped["sercalo"] = _failure_reason(
            bad, "the nominal current amplifier and Sercalo are used")
        return gi
    run.say("2.2 identifying the current amplifiers")
    amp_estimator = opts.frf if opts.frf != "auto" else choose_estimator(
        run.recordings, columns=_SERCALO_COLUMNS, trims_s=opts.trims_s)
    try:
        for axis, exp in (("h", "data_uch"), ("v", "data_ucv")):
            gi[axis] = calibrate_current_amplifier(
                run.recordings[exp], axis=axis, nominal=run.nom,
                trim_s=opts.trims_s.get(exp, 1.0), band_hz=opts.current_amp_band_hz,
                window_s=opts.window_s, estimator=amp_estimator)
            run.checks.extend(current_amp_checks(gi[axis]))
    except ValueError as exc:
        gi = {}
        run.skipped["current_amp"] = f"failed: {exc}"
        run.skipped["sercalo"] = "needs the current-amplifier gains (2.2), which failed"
    if gi and (bad := first_failure(c for c in run.checks
                                    if c.name == "current_amp_gain_vs_theoretical")):
        gi = {}
        run.skipped["current_amp"] = _failure_reason(bad, "the nominal current amplifier is used")
        run.skipped["sercalo"] = f"needs the current-amplifier gains (2.2): {bad.title} failed"
    return gi


@dataclass(frozen=True, eq=False)
class SercaloStep:
    """2.3's result: the fit (None: skipped), its modes refined on the records, the
    paths' validation and the truncation checks."""

    sercalo: SercaloIdentification | None = None
    modes: ModeRefinement | None = None
    validation: tuple[PathValidation, ...] = ()
    truncation: dict[str, TruncationCheck] = field(default_factory=dict)


def sercalo_step(run: StepRun, *, qd: Mapping[str, QdCalibration],
                 gi: Mapping[str, CurrentAmplifierGain]) -> SercaloStep:
    """2.3: the Sercalo's FRF matrix, delay and vector fit, its modes refined on the
    records; then the two runs' 4QD lags checked against each other."""
    step = _sercalo_fit(run, qd=qd, gi=gi) if gi else SercaloStep()
    # One 4QD amplifier feeds both outputs: the two Sercalo runs' lags must agree, or one
    # run's 4QD channels were delayed, and no delay or amplifier is read from them.
    lag_check = axis_lag_check(qd_amplifier_lags_by_axis(sid=step.sercalo, gi=gi,
                                                         nominal=run.nom),
                               fs_hz=run.nom.converter.fs_hz)
    if lag_check is not None:
        run.checks.append(lag_check)
        if not lag_check.passed:
            run.skipped["sercalo"] = _failure_reason(lag_check, "the nominal Sercalo is used")
            return replace(step, sercalo=None, modes=None, validation=())
    return step


def _sercalo_fit(run: StepRun, *, qd: Mapping[str, QdCalibration],
                 gi: Mapping[str, CurrentAmplifierGain]) -> SercaloStep:
    opts, recordings = run.opts, run.recordings
    modes: ModeRefinement | None = None
    unrefined: SercaloIdentification | None = None  # the fit before its modes' refinement
    run.say("2.3 Sercalo: FRF matrix, delay, vector fitting")
    try:
        frf = experiment_frf(recordings, columns=_SERCALO_COLUMNS, trims_s=opts.trims_s,
                             window_s=opts.window_s, estimator=opts.frf,
                             transient_periods=opts.transient_periods)
        run.say(f"2.3 Sercalo: FRF by {_ESTIMATOR_WORDS[frf.estimator]}")
        if qd:
            run.compression["sercalo"] = compression_factors(
                recordings, columns=_SERCALO_COLUMNS, outputs=OUTPUTS, qd=qd,
                trims_s=opts.trims_s)
            frf = correct_compression(frf, run.compression["sercalo"], recordings=recordings,
                                      columns=_SERCALO_COLUMNS, trims_s=opts.trims_s)
        sercalo_id = fit_sercalo(frf, gi_a_per_v={a: g.gain_a_per_v for a, g in gi.items()},
                                 options=replace(opts.sercalo, weights=opts.weights),
                                 sensor=run.sensor)
        if sercalo_id.options.weights_fallback:
            run.notices.append(Notice("other", "data_uch.mat, data_ucv.mat",
                                      f"Sercalo fit: {sercalo_id.options.weights_fallback}"))
        if opts.refine_modes and frf.estimator == "periodic":
            # Averaged periods have no leakage to remove: the fit's modes stand, with
            # stds from every line's noise and distortion (ident.fit_std).
            run.skipped["mode_refinement"] = ("periodic averaging: no leakage to remove; the "
                                              "fit's modes and their stds are used")
        elif opts.refine_modes:
            run.say("2.3 Sercalo: refining the modes on the time records")
            modes = refine_modes(recordings, sercalo=sercalo_id, trims_s=opts.trims_s)
            unrefined = sercalo_id
            sercalo_id = refit_with_poles(sercalo_id, poles=modes.poles_by_input())
        else:
            run.skipped["mode_refinement"] = "disabled by option"
        if frf.estimator == "welch":
            run.say("2.3 Sercalo: the Welch window's leakage near the modes")
            sercalo_id = with_frf(sercalo_id, leakage_corrected(sercalo_id, opts.window_s,
                                                                unrefined=unrefined),
                                  poles=None if modes is None else modes.poles_by_input())
        validation = validate_sercalo(recordings, sercalo=sercalo_id, trims_s=opts.trims_s)
        truncation = truncation_checks(
            sercalo_id, poles=None if modes is None else modes.poles_by_input())
    except ValueError as exc:
        run.skipped["sercalo"] = f"failed (data_uch, data_ucv): {exc}"
        return SercaloStep()
    return SercaloStep(sercalo_id, modes, validation, truncation)


@dataclass(frozen=True, eq=False)
class NewportStep:
    """2.4's result: the Newport (None: skipped) and the Sercalo, refitted when the
    records decided the 4QD amplifier."""

    newport: NewportIdentification | None
    sercalo: SercaloIdentification | None


@dataclass(eq=False)
class _NewportState:
    """2.4 as it goes: a step that fails half-way keeps what it had (as the plant does)."""

    newport: NewportIdentification | None
    sercalo: SercaloIdentification | None
    amplifier_findings: list[Finding] = field(default_factory=list)
    datasheet_findings: list[Finding] = field(default_factory=list)


def newport_step(run: StepRun, *, qd: Mapping[str, QdCalibration],
                 gi: Mapping[str, CurrentAmplifierGain],
                 sercalo_id: SercaloIdentification | None) -> NewportStep:
    """2.4: the Newport's FRF matrix, delay and gains, the 4QD amplifier the records
    decide, and the Newport's dynamics against its datasheet."""
    # Each Newport axis from its own record: one missing or unusable leaves the other
    # identified, and the bench file's model stands in for it (named, not reported).
    newport_usable: list[tuple[str, str]] = []
    newport_fill: dict[str, NewportAxisFit] = {}
    for axis, (exp, inp) in zip("hv", _NEWPORT_COLUMNS, strict=True):
        if exp not in run.recordings:
            run.skipped[f"newport_{axis}"] = run.absent_words([exp])
        elif bad := run.data_failure(exp):
            run.skipped[f"newport_{axis}"] = _failure_reason(
                bad, f"the bench file's Newport is used for axis {axis}")
        else:
            newport_usable.append((exp, inp))
            continue
        newport_fill[axis] = nominal_newport_axis(run.nom, axis, fs_hz=run.nom.converter.fs_hz)
    columns = tuple(newport_usable)
    if not columns:
        # Both absent read as one phrase; otherwise each axis's own reason, h first.
        gone = run.missing("data_unh", "data_unv")
        run.skipped["newport"] = (run.absent_words(gone) if len(gone) == 2 else
                                  "; ".join(run.skipped[f"newport_{a}"] for a in "hv"))
        run.skipped.pop("newport_h", None)
        run.skipped.pop("newport_v", None)
        return NewportStep(None, sercalo_id)
    run.say("2.4 Newport: FRF matrix, delay and gains"
            + (f" (axis {', '.join(a for a in 'hv' if a not in newport_fill)} alone)"
               if newport_fill else ""))
    state = _NewportState(None, sercalo_id)
    try:
        _newport_fit(run, state, columns=columns, fill=newport_fill, qd=qd, gi=gi)
    except ValueError as exc:
        run.skipped["newport"] = f"failed ({', '.join(e for e, _ in columns)}): {exc}"
    run.findings.extend([*state.amplifier_findings, *state.datasheet_findings])
    return NewportStep(state.newport, state.sercalo)


def _newport_fit(run: StepRun, state: _NewportState, *, columns: tuple[tuple[str, str], ...],
                 fill: Mapping[str, NewportAxisFit], qd: Mapping[str, QdCalibration],
                 gi: Mapping[str, CurrentAmplifierGain]) -> None:
    opts, conv = run.opts, run.nom.converter
    nfrf = experiment_frf(run.recordings, columns=columns, trims_s=opts.trims_s,
                          window_s=opts.window_s, estimator=opts.frf,
                          transient_periods=opts.transient_periods)
    if qd:
        run.compression["newport"] = compression_factors(
            run.recordings, columns=columns, outputs=OUTPUTS, qd=qd, trims_s=opts.trims_s)
        nfrf = correct_compression(nfrf, run.compression["newport"], recordings=run.recordings,
                                   columns=columns, trims_s=opts.trims_s)

    def fit(sensor: SensorLowpass, *, resolve: bool = True) -> NewportIdentification:
        sid = state.sercalo
        return identify_newport(
            nfrf, band_hz=opts.newport_band_hz, dac_delay_samples=conv.dac_delay_samples,
            converter_delay_s=None if sid is None else sid.delay_s, sensor=sensor,
            resolve_sensor=resolve, fill=fill, parallel=run.parallel)

    state.newport = fit(run.sensor)
    decision, (lag_s, lag_std_s) = _decide_amplifier(run, state, nfrf, gi=gi, fit=fit)
    newport_id = state.newport
    if decision is not None and decision.sensor is not None:
        run.notices.append(Notice("other", "4QD amplifier", decision.words))
    if (dyn := newport_id.dynamics) is not None and (
            decision is None or decision.sensor is None):
        run.notices.extend(sensor_notices(dyn, model=run.sensor))
        resolved = resolved_sensor(dyn)
        if resolved is not None and state.sercalo is not None:
            run.say("2.3 Sercalo: the delay again with the 4QD amplifier the Newport resolved")
            state.sercalo = with_sensor(state.sercalo, resolved)
        # An amplifier neither the bench model nor the lines give: the delays
        # measure its lag, and its shape bounds the Newport's parameters.
        if np.isfinite(lag_s):
            shifts = unresolved_sensor_shifts(nfrf, dyn,
                                              lag_s=max(lag_s, 0.0) + 1.96 * lag_std_s)
            state.newport = newport_id = replace(newport_id, sensor_shifts=shifts)
            run.notices.extend(sensor_shift_notices(
                shifts, lag_s=lag_s, noise={a: dyn.axes[a].natural_freq_std_hz
                                            for a in dyn.axes}))
    if (dyn := newport_id.dynamics) is not None:
        ds_np = run.bench.datasheet.newport
        # The datasheet is a prior: a Newport off it is a finding about this mirror
        # (its tuning, or another unit), with the datasheet key it contradicts.
        found = newport_checks(dyn, amplitude_bandwidth_hz=ds_np.amplitude_bandwidth_hz,
                               phase_bandwidth_hz=ds_np.phase_bandwidth_hz,
                               peaking_max_db=ds_np.peaking_max_db)
        # Only the axes the records gave (an assumed axis is the bench file's model).
        found = [c for c in found
                 if any(f"Newport {a} " in c.subject for a in newport_id.identified_axes)]
        run.checks.extend(c for c in found if c.passed)
        state.datasheet_findings = datasheet_departures(found, datasheet=ds_np)
    else:
        run.skipped["newport_dynamics"] = newport_id.dynamics_skipped


def _decide_amplifier(run: StepRun, state: _NewportState, nfrf: FrequencyResponse, *,
                      gi: Mapping[str, CurrentAmplifierGain],
                      fit: Callable[..., NewportIdentification],
                      ) -> tuple[AmplifierDecision | None, tuple[float, float]]:
    """The 4QD amplifier the delays (its lag) and the Newport's lines (its order) decide,
    the Newport refitted with it (``state``), the Sercalo's delay again when it changed;
    the decision and the lag it used [s] with its std [s]."""
    nom, sensor = run.nom, run.sensor
    assert state.newport is not None
    lag_s, lag_std_s = qd_amplifier_lag_s(sid=state.sercalo, gi=gi, nominal=nom)
    first_dynamics = state.newport.dynamics
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
        newport_id = replace(fit(decision.sensor, resolve=False),
                             sensor_shifts=decision.shifts)
        if newport_id.dynamics is not None:
            newport_id = replace(newport_id, dynamics=with_decided_sensor(
                newport_id.dynamics, decision, axes=newport_id.identified_axes))
        state.newport = newport_id
        state.amplifier_findings = list(decision.findings)
        if not (decision.resolved and state.sercalo is not None
                and decision.sensor != sensor):
            break
        run.say("2.3 Sercalo: the delay again with the 4QD amplifier the records decide")
        state.sercalo = with_sensor(state.sercalo, decision.sensor)
        own_lag_s, own_std_s = qd_amplifier_lag_s(sid=state.sercalo, gi=gi, nominal=nom)
        if (again or first_dynamics is None or not math.isfinite(own_lag_s)
                or abs(own_lag_s - lag_s) <= 0.1 * lag_std_s):
            break
        lag_s, lag_std_s = own_lag_s, own_std_s
        redecided = decide_amplifier(nfrf, first_dynamics, lag_s=lag_s, lag_std_s=lag_std_s,
                                     model=sensor)
        if redecided.sensor is None or not redecided.resolved:
            break  # the first decision stands, with the Sercalo refitted for it
        decision = redecided
    return decision, (lag_s, lag_std_s)


def _gd_block(qd: Mapping[str, QdCalibration]) -> ct.StateSpace:
    return ct.ss([], [], [], np.diag([qd["h"].gain_v_per_rad, qd["v"].gain_v_per_rad]),
                 inputs=["Rh", "Rv"], outputs=["Vph", "Vpv"], name="Gd")


def _gi_block(gi: Mapping[str, CurrentAmplifierGain]) -> ct.StateSpace:
    return ct.ss([], [], [], np.diag([gi["h"].gain_a_per_v, gi["v"].gain_a_per_v]),
                 inputs=["Uch", "Ucv"], outputs=["Ich", "Icv"], name="Gi")


@dataclass(frozen=True, eq=False)
class NoiseStep:
    """The noise model of the open-loop huddle tests: the fit (None: none), or why not."""

    fit: NoiseModelFit | None = None
    skipped: str = ""


def noise_step(run: StepRun, *, qd: Mapping[str, QdCalibration], say: Progress) -> NoiseStep:
    """The identified bench's noise, fitted to the open-loop huddle tests on the 4QD gains
    2.1 calibrated (the bench file's without them). It changes nothing in ``run``: it
    may run in another process beside the steps 2.2-2.4 (:mod:`fsmbench.forked`)."""
    if not any(n in run.recordings for n in NOISE_EXPERIMENTS):
        return NoiseStep()
    say("noise model of the open-loop huddle tests (the identified bench's noise)")
    try:
        return NoiseStep(fit_noise_model(run.recordings, params=run.nom, qd_gain_v_per_rad=(
            (qd["h"].gain_v_per_rad, qd["v"].gain_v_per_rad) if qd else None)))
    except ValueError as exc:
        return NoiseStep(skipped=str(exc))


def assemble_step(run: StepRun, *, source: str, qd: Mapping[str, QdCalibration],
                  gi: Mapping[str, CurrentAmplifierGain], sercalo_step: SercaloStep,
                  newport_step: NewportStep, noise_step: NoiseStep) -> Identification:
    """2.5: the identified blocks (the bench file's where a step was skipped) assembled
    into the plant, the noise model of the open-loop huddle tests, the uncertainty tree."""
    nom = run.nom
    sercalo_id, newport_id = newport_step.sercalo, newport_step.newport
    modes, validation = sercalo_step.modes, sercalo_step.validation
    warnings = quality_warnings(sercalo=sercalo_id, modes=modes, validation=validation)
    for w in warnings:
        run.say(f"warning: {w}")
    run.say("2.5 assembling the identified system")
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
    noise = noise_step.fit
    if noise_step.skipped:
        run.skipped["noise_model"] = noise_step.skipped
    result = Identification(qd=dict(qd), current_amp=dict(gi), sercalo=sercalo_id,
                            modes=modes, validation=validation, newport=newport_id,
                            plant=plant, plant_blocks={k: v[0] for k, v in blocks.items()},
                            skipped=run.skipped, options=run.opts, source=source,
                            warnings=warnings, checks=tuple(run.checks),
                            notices=tuple(run.notices), noise_model=noise,
                            compression=run.compression, truncation=sercalo_step.truncation,
                            findings=tuple(run.findings), recorded_loop=dict(run.loops),
                            params=nom)
    return replace(result, uncertainty=uncertainty_tree(
        qd=qd, current_amp=gi, sercalo=sercalo_id, modes=result.sercalo_modes(),
        newport=newport_id, compression=run.compression, nominal=nom,
        truncation=sercalo_step.truncation))
