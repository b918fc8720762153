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

import json
import warnings as pywarnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal

import control as ct
import numpy as np
import xarray as xr

from fsmbench import __version__
from fsmbench.bench.blocks import (
    PlantModel,
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
    calibrate_current_amplifier,
    calibrate_qd,
    current_amp_checks,
    qd_checks,
)
from fsmbench.ident.consistency import screen_recordings
from fsmbench.ident.crosscheck import (
    NOISE_CHECKS,
    cross_checks,
    floor_checks,
    newport_drive_gains,
)
from fsmbench.ident.delay.sampled import SensorLowpass
from fsmbench.ident.delay.sercalo import with_sensor
from fsmbench.ident.evidence.amplifier import axis_lag_check, decide_amplifier
from fsmbench.ident.evidence.departures import (
    datasheet_departures,
    departures,
    matching_datasheet,
    matching_params,
    measured_keys,
)
from fsmbench.ident.evidence.matching import MATCHING_BENCH, write_matching_bench
from fsmbench.ident.evidence.rate import (
    RateEvidence,
    current_amplifier_rate_check,
    records_rate,
)
from fsmbench.ident.evidence.recorded_loop import (
    RateWitness,
    RecordedController,
    rate_witness,
)
from fsmbench.ident.export import write_frf_mat, write_plant_mat
from fsmbench.ident.fit.modes import ModeRefinement, refine_modes
from fsmbench.ident.fit.truncation import TruncationCheck, truncation_checks
from fsmbench.ident.frf.compression import (
    CompressionFactors,
    compression_factors,
    correct_compression,
)
from fsmbench.ident.frf.leakage import welch_leakage_bias
from fsmbench.ident.frf.response import FrequencyResponse, with_variance_part
from fsmbench.ident.frf.welch import hanning
from fsmbench.ident.newport import (
    NewportIdentification,
    SensorShift,
    identify_newport,
    newport_checks,
    nominal_newport_axis,
    resolved_sensor,
    sensor_notices,
    unresolved_sensor_shifts,
)
from fsmbench.ident.noise_model import NoiseModelFit, fit_noise_model
from fsmbench.ident.sercalo import (
    OUTPUTS,
    SercaloFitOptions,
    SercaloIdentification,
    choose_estimator,
    experiment_frf,
    fit_sercalo,
    refit_with_poles,
    with_frf,
)
from fsmbench.ident.totals import (
    qd_amplifier_lag_s,
    qd_amplifier_lags_by_axis,
    uncertainty_tree,
)
from fsmbench.ident.uncertainty import Uncertain
from fsmbench.ident.validate import PathValidation, validate_sercalo
from fsmbench.io.atomic import atomic_write_text
from fsmbench.io.folder import check_recording
from fsmbench.jsonutil import plain_json, stamped

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

# The seed's t0 for each experiment (2.1: 1 s, 2.3: 1 s, 2.4: 3 s and 1.5 s).
#: The records the noise model is fitted to (open-loop huddle tests, seed 3).
NOISE_EXPERIMENTS = ("data_huddle_test_1", "data_huddle_test_2", "data_huddle_test_4")

SEED_TRIMS_S = {"data_cal_pd_h": 1.0, "data_cal_pd_v": 1.0, "data_uch": 1.0, "data_ucv": 1.0,
                "data_unh": 3.0, "data_unv": 1.5}

Progress = Callable[[str], None]

#: ``identification.json``'s format and version (docs/results.md); 2: the keys of
#: ``diagnostics.sercalo.fit_error_rms_relative`` are ``Uch_to_Vph``, not ``Vph/Uch``;
#: 3: ``noise_model``, the noise fitted to the open-loop huddle tests; 4: ``uncertainty``,
#: every value with its total std and parts (issue 20), ``effective_delay_s`` and
#: ``qd_diode_gain_v_per_rad``; ``delay_s.sercalo`` measured on ``Uc → Vc``.
IDENTIFICATION_FORMAT = ("fsmbench.identification", 4)

_SERCALO_COLUMNS = (("data_uch", "Uch"), ("data_ucv", "Ucv"))
_NEWPORT_COLUMNS = (("data_unh", "Unh"), ("data_unv", "Unv"))


@dataclass(frozen=True)
class IdentifyOptions:
    """Options of :func:`identify`.

    Attributes
    ----------
    window_s : float
        Hann window of every Welch estimate [s] (seed: 1 s).
    trims_s : mapping
        Seconds removed at the start of each experiment (seed's values).
    sercalo : SercaloFitOptions
        Weights and order of the rational fit.
    newport_band_hz, current_amp_band_hz : (float, float)
        Averaging bands [Hz] (seed: 10–100 Hz and 20–200 Hz).
    refine_modes : bool
        Re-estimate each Sercalo mode's frequency and damping from the time
        records (:mod:`fsmbench.ident.fit.modes`), which the 1 s window smears.
    frf : {"auto", "welch", "lpm", "periodic"}
        FRF estimator of the Sercalo and Newport matrices
        (:func:`fsmbench.ident.sercalo.experiment_frf`). ``"auto"``: periodic
        averaging when every experiment's input repeats with a period (three
        whole periods at least), else Welch, the seed's estimator
        (:func:`fsmbench.ident.sercalo.choose_estimator`).
    weights : {"seed", "variance"}
        Vector-fit weights: the seed's coherence recipe, or the inverse
        standard deviation of every line (:mod:`fsmbench.ident.fit.parameter_std`; the
        parameters' standard deviations come with either). Overrides
        ``sercalo.weights``.
    transient_periods : mapping of experiment name to int
        The transient periods of each played excitation (``excitation.json``'s
        ``transient_periods``, :func:`fsmbench.ident.load.excitation_transients`):
        periodic averaging drops at least these, more when the data show a
        transient (default: at least 1).
    """

    window_s: float = 1.0
    trims_s: Mapping[str, float] = field(default_factory=lambda: dict(SEED_TRIMS_S))
    sercalo: SercaloFitOptions = field(default_factory=SercaloFitOptions)
    newport_band_hz: tuple[float, float] = (10.0, 100.0)
    current_amp_band_hz: tuple[float, float] = (20.0, 200.0)
    refine_modes: bool = True
    frf: Literal["auto", "welch", "lpm", "periodic"] = "auto"
    weights: Literal["seed", "variance"] = "seed"
    transient_periods: Mapping[str, int] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.frf not in ("auto", "welch", "lpm", "periodic"):
            raise ValueError(f"frf must be auto, welch, lpm or periodic, got {self.frf!r}")
        if self.weights not in ("seed", "variance"):
            raise ValueError(f"weights must be 'seed' (the ESRF study's coherence recipe) or "
                             f"'variance', got {self.weights!r}")

    def to_json(self) -> dict[str, Any]:
        """Plain values."""
        return {"window_s": self.window_s, "trims_s": dict(self.trims_s),
                "sercalo": {**self.sercalo.__dict__, "weights": self.weights},
                "newport_band_hz": list(self.newport_band_hz),
                "current_amp_band_hz": list(self.current_amp_band_hz),
                "refine_modes": self.refine_modes, "frf": self.frf, "weights": self.weights,
                "transient_periods": dict(self.transient_periods)}


@dataclass(frozen=True, eq=False)
class Identification:
    """Everything section 2 identified, with what it skipped.

    Attributes
    ----------
    qd : dict axis -> QdCalibration
    current_amp : dict axis -> CurrentAmplifierGain
    sercalo : SercaloIdentification or None
    modes : ModeRefinement or None
        Refined modal parameters (None when not run).
    validation : tuple of PathValidation
        Time-domain check of the fitted Sercalo model.
    newport : NewportIdentification or None
    plant : PlantModel or None
        The assembled system (2.5); blocks not identified are nominal, see
        ``plant_blocks``.
    plant_blocks : dict block -> "identified" | "nominal"
    skipped : dict step -> reason
        Steps not run (missing data) or failed (the error message).
    options : IdentifyOptions
    source : str
    warnings : tuple of str
        Why the results should not be trusted (bad fit, low coherence, no
        convergence); empty when all quality checks pass.
    checks : tuple of Check
        Plausibility checks of the recordings used and of the calibrations;
        a failed one made its step fall back to the nominal block, and
        ``skipped`` names it.
    notices : tuple of Notice
        Non-fatal findings (saturation, numerical warnings while computing).
    noise_model : NoiseModelFit or None
    compression : dict {"sercalo", "newport"} -> CompressionFactors
        The 4QD's compression each FRF was corrected for.
    truncation : dict axis -> TruncationCheck
        The Sercalo's static gains over half the band (:mod:`fsmbench.ident.fit.truncation`).
    uncertainty : dict key -> Uncertain
        Every identified value with its total std and its parts, keyed as
        ``twin_truth.json`` (:mod:`fsmbench.ident.totals`).
    findings : tuple of Finding
        Where the records measured the bench other than its bench file states
        (:mod:`fsmbench.ident.evidence`), each with its bench-file key.
    recorded_loop : dict axis -> RecordedController
        The controller the closed-loop records ran.
    params : BenchParams or None
        The nominal parameters the steps modelled the bench with: the bench
        file's, with the signs the records gave.
    matching : Bench or None
        The bench file with every value the records measured: what
        ``bench_identified.toml`` holds.
    """

    qd: dict[str, QdCalibration]
    current_amp: dict[str, CurrentAmplifierGain]
    sercalo: SercaloIdentification | None
    modes: ModeRefinement | None
    validation: tuple[PathValidation, ...]
    newport: NewportIdentification | None
    plant: PlantModel | None
    plant_blocks: dict[str, str]
    skipped: dict[str, str]
    options: IdentifyOptions
    source: str
    warnings: tuple[str, ...] = ()
    checks: tuple[Check, ...] = ()
    notices: tuple[Notice, ...] = ()
    noise_model: NoiseModelFit | None = None
    compression: dict[str, CompressionFactors] = field(default_factory=dict)
    truncation: dict[str, TruncationCheck] = field(default_factory=dict)
    uncertainty: dict[str, Uncertain] = field(default_factory=dict)
    findings: tuple[Finding, ...] = ()
    recorded_loop: dict[str, RecordedController] = field(default_factory=dict)
    params: BenchParams | None = None
    matching: Bench | None = None

    def uncertain(self, key: str) -> Uncertain | None:
        """The value of ``key`` (``"sercalo.h.dc_gain_v_per_a"``) with its std and parts."""
        return self.uncertainty.get(key)

    def largest_part(self, key: str) -> str:
        """The largest part of the uncertainty of ``key`` ("" when not identified)."""
        u = self.uncertainty.get(key)
        return "" if u is None else u.largest_part

    def sercalo_modes(self) -> dict[str, dict[str, float]]:
        """Resonance and damping per axis: refined when available, else from the fit."""
        out: dict[str, dict[str, float]] = {}
        if self.modes is not None:
            for axis, est in self.modes.by_axis().items():
                out[axis] = {"resonance_hz": est.resonance_hz,
                             "damping_ratio": est.damping_ratio,
                             "resonance_hz_std": est.resonance_hz_std,
                             "damping_ratio_std": est.damping_ratio_std}
            return out
        if self.sercalo is not None:
            modes = self.sercalo.fit.modes()
            res = self.sercalo.resonances_hz
            pstd = self.sercalo.parameter_std
            for axis, inp in (("h", "Uch"), ("v", "Ucv")):
                if inp in res and modes:
                    fr = res[inp]
                    m = modes[int(np.argmin([abs(x.resonance_hz - fr) for x in modes]))]
                    out[axis] = {"resonance_hz": m.resonance_hz,
                                 "damping_ratio": m.damping_ratio,
                                 "resonance_hz_std": m.resonance_hz_std,
                                 "damping_ratio_std": m.damping_ratio_std}
                    if pstd is not None and not pstd.fixed_poles and axis in pstd.std:
                        # The lines' own variances (noise, distortion), propagated.
                        out[axis].update(resonance_hz_std=pstd.std[axis]["resonance_hz"],
                                         damping_ratio_std=pstd.std[axis]["damping_ratio"])
        return out

    def to_json(self) -> dict[str, Any]:
        """``twin_truth.json``'s keys for what was identified, plus diagnostics."""
        out: dict[str, Any] = {"fsmbench_version": __version__, "source": self.source}
        if self.qd:
            out["qd_gain_v_per_rad"] = {a: c.gain_v_per_rad for a, c in self.qd.items()}
        if self.current_amp:
            out["current_amp_gain_a_per_v"] = {a: g.gain_a_per_v
                                               for a, g in self.current_amp.items()}
        if self.sercalo is not None:
            dc = self.sercalo.dc_gain_v_per_a()
            modes = self.sercalo_modes()
            out["sercalo"] = {a: {"resonance_hz": modes[a]["resonance_hz"],
                                  "damping_ratio": modes[a]["damping_ratio"],
                                  "dc_gain_v_per_a": dc[a]} for a in modes}
        if self.newport is not None:
            known = self.newport.identified_axes
            out["newport_gain_v_per_v"] = {a: g for a, g in self.newport.gain_v_per_v.items()
                                           if a in known}
            dyn = self.newport.dynamics
            if dyn is not None:
                out["newport"] = {a: {"natural_freq_hz": dyn.axes[a].natural_freq_hz,
                                      "damping_ratio": dyn.axes[a].damping_ratio,
                                      "internal_delay_s": dyn.internal_delay_s(a)}
                                  for a in known}
        delays = {}
        if self.sercalo is not None:
            delays["sercalo"] = self.sercalo.pure_delay_s
        if self.newport is not None:
            delays["newport"] = self.newport.delay_s
        if delays:
            out["delay_s"] = delays
        if self.noise_model is not None:
            out["noise_model"] = self.noise_model.to_json()
        # Values the uncertainty tree holds are its own (one value per key, with its std),
        # nested as the values are (JSON keys are ids: no dots).
        tree: dict[str, Any] = {}
        for key, u in sorted(self.uncertainty.items()):
            node, branch = out, tree
            *stems, leaf = key.split(".")
            for stem in stems:
                node = node.setdefault(stem, {})
                branch = branch.setdefault(stem, {})
            node[leaf] = u.value
            branch[leaf] = u.to_json()
        out["uncertainty"] = tree
        out["checks"] = [c.to_json() for c in self.checks]
        out["notices"] = [n.to_json() for n in self.notices]
        out["findings"] = [f.to_json() for f in self.findings]
        out["diagnostics"] = {
            "qd": {a: c.to_json() for a, c in self.qd.items()},
            "current_amp": {a: g.to_json() for a, g in self.current_amp.items()},
            "sercalo": None if self.sercalo is None else path_keyed_summary(self.sercalo.summary()),
            "sercalo_modes": self.sercalo_modes(),
            "mode_refinement": None if self.modes is None else self.modes.to_json(),
            "validation": [v.to_json() for v in self.validation],
            "newport": None if self.newport is None else self.newport.summary(),
            "frf_estimator": {name: part.frf.estimator
                              for name, part in (("sercalo", self.sercalo),
                                                 ("newport", self.newport)) if part is not None},
            "frf_columns": {name: {k: dict(v) for k, v in part.frf.column_options.items()}
                            for name, part in (("sercalo", self.sercalo),
                                               ("newport", self.newport)) if part is not None},
            "compression": {k: c.summary() for k, c in self.compression.items()},
            "sercalo_truncation": {k: c.to_json() for k, c in self.truncation.items()},
            "plant_blocks": self.plant_blocks,
            "recorded_loop": {a: r.to_json() for a, r in self.recorded_loop.items()},
            "skipped": self.skipped,
            "warnings": list(self.warnings),
            "options": self.options.to_json(),
        }
        return out


def path_keyed_summary(summary: dict[str, Any]) -> dict[str, Any]:
    """``fit_error_rms_relative`` keyed ``Uch_to_Vph`` (input ``_to_`` output), not ``Vph/Uch``:
    JSON keys are ids, without punctuation."""
    errors = summary.get("fit_error_rms_relative")
    if not isinstance(errors, Mapping):
        return summary
    renamed = {}
    for key, value in errors.items():
        out, slash, inp = str(key).partition("/")
        renamed[f"{inp}_to_{out}" if slash else str(key)] = value
    return {**summary, "fit_error_rms_relative": renamed}


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
    found = _merged_findings(result.findings, departures(
        measured, bench_file=bench.nominal, fs_hz=used.converter.fs_hz))
    result = replace(result, findings=found, matching=replace(
        bench, nominal=matching_params(bench.nominal, measured, result.findings),
        datasheet=matching_datasheet(bench.datasheet, result.findings)))
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


def _rate_check(witness: RateWitness, rate: RateEvidence) -> Check:
    """``rate_vs_controller``: the rate at which the ESRF study's controller explains the
    closed-loop commands against the rate ``t`` gives (ident.evidence.recorded_loop)."""
    left = {f: max(1.0 - e, 1e-12) for f, e in witness.explained.items()}
    own = left[witness.labelled_fs_hz]
    subject = f"{witness.record}.mat: t, {witness.command}"
    limit = (f"the ESRF study's controller explains {witness.command} best at t's "
             f"{witness.labelled_fs_hz:g} Hz")
    if not witness.contradicts:
        return Check("rate_vs_controller", True, witness.fs_hz, limit, subject, unit="Hz")
    factor = witness.fs_hz / witness.labelled_fs_hz
    others = len(rate.by_record) - 1
    return Check(
        "rate_vs_controller", False, witness.fs_hz, limit, subject,
        f"the controller discretised at {witness.fs_hz:g} Hz leaves {own / left[witness.fs_hz]:.3g}"
        f"× less of {witness.command} unexplained than at {witness.labelled_fs_hz:g} Hz: the "
        f"records were sampled at {witness.fs_hz:g} Hz and t was saved with the step of "
        f"{witness.labelled_fs_hz:g} Hz (×{factor:g} off"
        + (f", in this record and the {others} others that share its step" if others else "")
        + "), or the loop ran another controller than the ESRF study's, tuned an octave away; "
        "every frequency and delay would be off by that factor: check the rate the target "
        "recorded at, and save t = k / fs with it", unit="Hz")


def _merged_findings(signs: tuple[Finding, ...], values: list[Finding]) -> tuple[Finding, ...]:
    """One finding per key: a value's departure on a key whose sign the records also gave
    keeps the sign's words and alternatives."""
    by_key = {f.key: f for f in signs}
    for f in values:
        sign = by_key.get(f.key)
        by_key[f.key] = f if sign is None else replace(
            f, message=f"{sign.message}; {f.message}", alternatives=sign.alternatives)
    return tuple(by_key.values())


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
        _rate_check(witness, rate) if witness is not None else None,
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

    # ---- issue 21 (ident.consistency): signs, swapped cables and 4QD offsets across the
    # records. A failed check joins its records' own: each step using them falls back
    # naming it. Huddle tests failing their checks (a jump in Va …) leave the noise model.
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
    # ---- end of issue 21

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
                sercalo_id = with_frf(sercalo_id, _with_leakage(sercalo_id, opts.window_s,
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
        gone = missing("data_unh", "data_unv")
        skipped["newport"] = (absent_words(gone) if gone else
                              "; ".join(skipped.pop(f"newport_{a}") for a in "hv"))
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
            decision = (None if newport_id.dynamics is None else decide_amplifier(
                nfrf, newport_id.dynamics, lag_s=lag_s, lag_std_s=lag_std_s, model=sensor))
            if decision is not None and decision.sensor is not None:
                # The delays give the amplifier's lag, the lines its order
                # (ident.evidence.amplifier): the Newport fitted with what both decide.
                newport_id = replace(identify_newport(
                    nfrf, band_hz=opts.newport_band_hz,
                    dac_delay_samples=conv.dac_delay_samples,
                    converter_delay_s=None if sercalo_id is None else sercalo_id.delay_s,
                    sensor=decision.sensor, resolve_sensor=False, fill=newport_fill),
                    sensor_shifts=decision.shifts)
                notices.append(Notice("other", "4QD amplifier", decision.words))
                amplifier_findings = list(decision.findings)
                if decision.resolved and sercalo_id is not None and decision.sensor != sensor:
                    say("2.3 Sercalo: the delay again with the 4QD amplifier the records "
                        "decide")
                    sercalo_id = with_sensor(sercalo_id, decision.sensor)
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
                    notices.extend(_sensor_shift_notices(shifts, lag_s=lag_s,
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


def _leakage_bias(sid: SercaloIdentification, window_s: float) -> np.ndarray:
    """``E[Ĥ] − H`` of the Welch estimate on ``sid.frf``'s lines for ``sid``'s model and
    delay (:func:`~fsmbench.ident.frf.leakage.welch_leakage_bias`), shape (F, p, m)."""
    frf = sid.frf
    delay = sid.delay_s

    def model(f_hz: np.ndarray) -> np.ndarray:
        return sid.fit.response(f_hz) * np.exp(-2j * np.pi * f_hz * delay)[:, None, None]

    f = frf.frequency_hz
    bias = np.zeros(frf.frf.shape, dtype=complex)
    sel = f > 0
    fit_out = list(sid.fit.output_names)
    fit_in = list(sid.fit.input_names)
    b = welch_leakage_bias(model, f[sel], fs_hz=frf.fs_hz,
                           window=hanning(int(np.ceil(window_s * frf.fs_hz))))
    rows = [fit_out.index(o) for o in frf.output_names]
    cols = [fit_in.index(i) for i in frf.input_names]
    bias[sel] = b[:, rows][:, :, cols]
    return bias


def _with_leakage(sid: SercaloIdentification, window_s: float, *,
                  unrefined: SercaloIdentification | None) -> FrequencyResponse:
    """The Sercalo's Welch FRF with its leakage bias near the modes removed, and the
    correction's uncertainty as a variance part (:mod:`fsmbench.ident.frf.leakage`).

    The bias is the fitted model's (its modes refined on the time records) with its delay.
    Removed, because a bias only widened still pulls the fit: the lines a few Hz from the
    vertical mode moved its static gain by +0.7 of its std on every seed (issue 20, 100
    twin seeds); subtracted, +0.04. The correction's own error is that of the model's
    modes: bounded by how much the bias changes from the fit's modes before the refinement
    (the FRF's, leakage-biased: 5-10 % in damping) to the refined ones; without a
    refinement, by the bias itself."""
    bias = _leakage_bias(sid, window_s)
    spread = bias if unrefined is None else bias - _leakage_bias(unrefined, window_s)
    frf = sid.frf
    corrected = replace(frf, frf=frf.frf.copy(data=np.asarray(frf.frf.values) - bias))
    return with_variance_part(corrected, "leakage", np.abs(spread) ** 2)


def _sensor_shift_notices(shifts: Mapping[str, SensorShift], *, lag_s: float,
                          noise: Mapping[str, float]) -> list[Notice]:
    """Advice where the amplifier's unknown order outweighs the noise on the Newport's
    natural frequency: the bench file can state it."""
    out = []
    for axis, shift in shifts.items():
        width = shift.half_width["natural_freq_hz"]
        if width <= noise[axis]:
            continue
        out.append(Notice(
            "other", f"Newport {axis}",
            f"the delays measure a 4QD amplifier lag of {lag_s * 1e6:.3g} µs that the bench "
            f"model lacks and the Newport's lines do not resolve; its order moves the "
            f"Newport's natural frequency by up to {width:.3g} Hz (noise {noise[axis]:.2g} "
            f"Hz): state quad_diode.bandwidth_hz and bandwidth_order in the bench file's "
            f"[nominal] to remove it"))
    return out


_ESTIMATOR_WORDS = {"welch": "Welch H1 (the ESRF study's)",
                    "lpm": "the local polynomial method", "periodic": "averaging over periods"}

_QD_CHECKS = ("calibration_r2", "calibration_residual", "qd_gain_vs_nominal")


# Quality limits: the identification issue's 5 % fit target on direct paths;
# a direct path whose model explains < 90 % of the recorded variance, or a
# modal fit that did not converge, is not a model to design a controller on.
MAX_DIRECT_FIT_ERROR = 0.05
MIN_DIRECT_VAF = 0.9


def quality_warnings(*, sercalo: SercaloIdentification | None, modes: ModeRefinement | None,
                     validation: tuple[PathValidation, ...]) -> tuple[str, ...]:
    """Why a Sercalo model should not be trusted, one sentence each (empty when good)."""
    out: list[str] = []
    if sercalo is None:
        return ()
    if not sercalo.fit.converged:
        out.append(f"vector fitting did not converge in {sercalo.fit.iterations} iterations; "
                   "the poles may be wrong — check the weights and the excitation")
    for path in ("Vph/Uch", "Vpv/Ucv"):
        err = sercalo.fit_error.get(path, float("nan"))
        if not np.isfinite(err):
            out.append(f"{path}: no bin with coherence > 0.9 between 10 Hz and 1 kHz; the "
                       "excitation is too weak for this path — raise its level or lengthen "
                       "the record")
        elif err > MAX_DIRECT_FIT_ERROR:
            out.append(f"{path}: the fit misses the measured FRF by {err:.1%} rms "
                       f"(limit {MAX_DIRECT_FIT_ERROR:.0%}); more poles or other weights needed")
    for v in validation:
        if v.output[-1] == v.input[-1] and v.vaf < MIN_DIRECT_VAF:
            out.append(f"{v.experiment}: the model explains {v.vaf:.1%} of {v.output}'s "
                       f"variance (limit {MIN_DIRECT_VAF:.0%})")
    if modes is not None:
        for axis, est in modes.estimates.items():
            if not est.converged:
                out.append(f"modal estimate of axis {axis} did not converge; its damping is "
                           "unreliable")
    return tuple(out)


def write_identification(result: Identification, out_dir: str | Path) -> list[Path]:
    """Write ``identification.json``, ``plant.mat`` and ``frf.mat`` into ``out_dir``.

    Every file is written atomically. ``frf.mat`` holds the measured FRF
    matrices present (Sercalo and/or Newport); it is not written when none is.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    name, version = IDENTIFICATION_FORMAT
    payload = stamped(result.to_json(), format=name, version=version)
    paths = [atomic_write_text(out / "identification.json",
                               json.dumps(plain_json(payload), indent=2, sort_keys=True) + "\n")]
    if result.plant is not None:
        paths.append(write_plant_mat(out / "plant.mat", result.plant))
    frfs = {name: part.frf for name, part in (("sercalo", result.sercalo),
                                                ("newport", result.newport)) if part is not None}
    if frfs:
        paths.append(write_frf_mat(out / "frf.mat", frfs))
    if result.matching is not None:
        paths.append(write_matching_bench(out / MATCHING_BENCH, result.matching,
                                          findings=result.findings))
    return paths

