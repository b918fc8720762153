"""What :func:`fsmbench.ident.pipeline.identify` returns, its options and its files.

:class:`Identification` holds every step's result with its options, checks, findings
and uncertainties; :meth:`Identification.to_json` has the keys of ``twin_truth.json``
plus a ``diagnostics`` tree, and :func:`write_identification` writes it (format and
version first) with ``plant.mat``, ``frf.mat`` and ``bench_identified.toml``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from fsmbench.bench.blocks import PlantModel
from fsmbench.bench.params import Bench, BenchParams
from fsmbench.checks import Check, Finding, Notice
from fsmbench.ident.calibration import CurrentAmplifierGain, QdCalibration
from fsmbench.ident.compare import ModelComparison
from fsmbench.ident.evidence.matching import MATCHING_BENCH, write_matching_bench
from fsmbench.ident.evidence.recorded_loop import RecordedController
from fsmbench.ident.export import IDENTIFICATION_FORMAT, write_identification_folder
from fsmbench.ident.fit.modes import ModeRefinement
from fsmbench.ident.fit.truncation import TruncationCheck
from fsmbench.ident.frf.compression import CompressionFactors
from fsmbench.ident.model_band import ModelBand
from fsmbench.ident.newport import NewportIdentification
from fsmbench.ident.noise_model import NoiseModelFit
from fsmbench.ident.sercalo import SercaloFitOptions, SercaloIdentification
from fsmbench.ident.uncertainty import Uncertain
from fsmbench.ident.validate import PathValidation
from fsmbench.version import __version__

__all__ = [
    "ESRF_TRIMS_S",
    "IDENTIFICATION_FORMAT",
    "Identification",
    "IdentifyOptions",
    "PlantChoice",
    "SavedIdentification",
    "path_keyed_summary",
    "write_identification",
]

# The seed's t0 for each experiment (2.1: 1 s, 2.3: 1 s, 2.4: 3 s and 1.5 s).
ESRF_TRIMS_S = {"data_cal_pd_h": 1.0, "data_cal_pd_v": 1.0, "data_uch": 1.0, "data_ucv": 1.0,
                "data_unh": 3.0, "data_unv": 1.5}

#: ``identification.json``'s format and version (docs/results.md); 2: the keys of
#: ``diagnostics.sercalo.fit_error_rms_relative`` are ``Uch_to_Vph``, not ``Vph/Uch``;
#: 3: ``noise_model``, the noise fitted to the open-loop huddle tests; 4: ``uncertainty``,
#: every value with its total std and parts, ``effective_delay_s`` and
#: ``qd_diode_gain_v_per_rad``; ``delay_s.sercalo`` measured on ``Uc → Vc``.


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
        (:func:`fsmbench.ident.frf.experiment.experiment_frf`). ``"auto"``: periodic
        averaging when every experiment's input repeats with a period (three
        whole periods at least), else Welch, the seed's estimator
        (:func:`fsmbench.ident.frf.experiment.choose_estimator`).
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
    trims_s: Mapping[str, float] = field(default_factory=lambda: dict(ESRF_TRIMS_S))
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
    comparison : ModelComparison or None
        The identified model against each open-loop identification record, with its
        NRMSE fit (:mod:`fsmbench.ident.compare`, MATLAB's ``compare``).
    bode_band : ModelBand or None
        The identified model's response on its direct paths with the std its parameters'
        total stds give (:mod:`fsmbench.ident.model_band`, MATLAB's ``bode(sys, 'sd')``).
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
    comparison: ModelComparison | None = None
    bode_band: ModelBand | None = None

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
            "model_fit": None if self.comparison is None else self.comparison.to_json(),
            "bode_band": None if self.bode_band is None else self.bode_band.to_json(),
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


def write_identification(result: Identification, out_dir: str | Path) -> list[Path]:
    """Write ``identification.json``, ``plant.mat`` and ``frf.mat`` into ``out_dir``.

    Every file is written atomically. ``frf.mat`` holds the measured FRF
    matrices present (Sercalo and/or Newport); it is not written when none is.
    """
    frfs = {name: part.frf for name, part in (("sercalo", result.sercalo),
                                                ("newport", result.newport)) if part is not None}
    paths = write_identification_folder(out_dir, document=result.to_json(), plant=result.plant,
                                        frfs=frfs)
    out = Path(out_dir)
    if result.matching is not None:
        paths.append(write_matching_bench(out / MATCHING_BENCH, result.matching,
                                          findings=result.findings))
    return paths


@dataclass(frozen=True)
class SavedIdentification:
    """What the budget reads of an identification besides its plant, read back from a
    previous run's ``identification.json`` (``--bench DIR``).

    Attributes
    ----------
    path : str
        The ``identification.json`` read.
    noise_model : NoiseModelFit or None
        The noise its open-loop huddle tests fitted (None: none was fitted).
    recorded_loops : mapping
        ``diagnostics.recorded_loop``: per axis ``{"verdict", "gd_used_v_per_rad",
        "gd_used_std_v_per_rad", …}``, the 4QD gains [V/rad] the closed-loop records ran.
    checks : tuple of dict
        Its plausibility checks, as written.
    """

    path: str
    noise_model: Any = None
    recorded_loops: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    checks: tuple[Mapping[str, Any], ...] = ()


@dataclass(frozen=True, eq=False)
class PlantChoice:
    """The plant a stage works on and where it comes from.

    ``saved``: with no ``identification`` in memory, what a previous run's
    ``identification.json`` adds to its plant (the measured noise and the recorded loop's
    gains), so that ``budget --bench DIR`` computes the budget the study computes.
    """

    plant: PlantModel
    source: str
    identification: Identification | None
    saved: SavedIdentification | None = None
