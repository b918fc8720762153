"""The identification records against each other and the bench file, before any step runs.

Each step of :mod:`fsmbench.ident.pipeline` checks its own records (rate, range,
r², coherence). A flipped sign, a swapped cable or a beam off the 4QD's centre
pass those checks and give a wrong or no result with the wrong advice. This
module reads the six identification records once, each along its own
excitation (``data_cal_pd_h``: ``Vnh``; ``data_uch``: ``Uch`` …), and compares
what they say with the bench file's nominal model and with each other:

``excited_axis``
    The excitation moves its own axis: the direct output (``Vph`` for
    ``Uch``, ``Unh``, ``Vnh``) responds more than the cross one, and for a
    Sercalo run with both coil voltages recorded, its own coil's. The cross
    paths are couplings of a few % (the twin's direct paths are 26–76× its
    cross ones), so a cross output that moves more than the direct one,
    coherently and with a direct path's gain (:data:`SWAP_GAIN_FACTOR`; the
    bench file's or, when smaller, the partner run's as measured: a bench far
    below the bench file's gains is a finding, not a reason to miss a swap),
    means the other axis was driven: a swapped DAC cable, or the other run
    saved under this name. A dead direct channel beside a coupling is not a
    swap: the steps' own checks name it.
``signs_across_records``
    Each direct path's sign against the bench file's model, from its response
    in :data:`SIGN_BAND_HZ` projected on the model's phase (``ρ``, the cosine of
    the phase between them weighted by magnitude: +1 agrees, −1 is reversed),
    with the metrology against the Newport's drive in ``data_rep_h/v`` and the
    sign of the controller each closed-loop record ran
    (:mod:`fsmbench.ident.evidence.recorded_loop`). The signs are then
    explained (:mod:`fsmbench.ident.evidence.signs`) by the bench's own signs (a
    finding with its bench-file key: the identification models the bench with
    it) or by a record's flipped signal; only when every explanation flips a
    record do the records contradict each other, and the check fails on them.

A failed check is attached to the records it concerns
(:attr:`Screening.by_experiment`): every step that uses them falls back
naming it. 4QD offsets are notices: a mean beyond the bench file's linear
span of the 4QD (``quad_diode.nonlinearity_full_swing_rad``) is named, and
the estimators remove it (the calibration's intercept, the mean removed
before every FRF estimate). The open-loop huddle tests whose own checks
(:func:`fsmbench.io.folder.check_recording`) fail are left out of the
recordings the noise model sees.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import Final

import numpy as np
import scipy.fft
import scipy.signal
import xarray as xr

from fsmbench.bench.blocks import PlantModel, newport_beam_matrix, physical_plant
from fsmbench.bench.params import BenchParams
from fsmbench.checks import Check, Finding, Notice, first_failure
from fsmbench.ident.calibration import trim_recording
from fsmbench.ident.evidence.bench_signs import diagnose_signs
from fsmbench.ident.evidence.observations import (
    closed_loop_runs,
    loop_observations,
    rep_observations,
)
from fsmbench.ident.evidence.recorded_loop import RecordedController, recorded_controllers
from fsmbench.ident.evidence.signs import SignDiagnosis, SignObservation
from fsmbench.io.record_checks import check_recording

__all__ = [
    "AXIS_RATIO_MIN",
    "MIN_COHERENCE",
    "OFFSET_SPAN_FACTOR",
    "SIGN_AGREEMENT",
    "SIGN_BAND_HZ",
    "SWAP_GAIN_FACTOR",
    "AxisRatio",
    "PathSign",
    "Screening",
    "screen_recordings",
    "with_records_gains",
]

#: Band of the sign estimates [Hz]: below the Sercalo's modes (≥ 250 Hz) and the
#: Newport's 600 Hz bandwidth, where every direct path is near its static gain and the
#: model's phase (delays, poles) is known to a few degrees; the seed's Newport band.
SIGN_BAND_HZ: Final = (10.0, 100.0)
#: A Welch bin is excited when its input PSD is above this fraction of the band's median
#: (30 dB: a Hann window's leakage from a line two bins away is 1/6 of it in amplitude).
_EXCITED_OF_TOP: Final = 1e-3
#: ``|ρ|`` at which a path's sign is judged: cos 60°. The model's phase is within a few
#: degrees in the band and a reversed sign is 180° off (ρ ≈ −1); noise or a dead path
#: leaves ρ near 0 and no verdict.
SIGN_AGREEMENT: Final = 0.5
#: Direct over cross response below which the other axis moved: the cross paths are
#: couplings of a few % (on the twin's records the direct paths are 26–76× the cross ones;
#: the bench file's model has none), so below 1 the excitation drove the other axis.
AXIS_RATIO_MIN: Final = 1.0
#: A path is coherent when the excitation explains at least half of its output in the band
#: (median γ² ≥ 0.5; the calibration: r² ≥ 0.5): its gain is the path's, not noise. Only
#: a coherent cross path can show that the other axis moved (a dead direct channel is the
#: steps' own finding, not a swap).
MIN_COHERENCE: Final = 0.5
#: A swapped run's cross output carries a direct gain (the other axis's: 0.6–1.2× the
#: model's direct gain on the twin), a coupling only a few % of it: the cross path must
#: reach the model's direct gain divided by this (a factor 2 for a gain against its
#: nominal, as the steps allow, times 2 between the bench's axes) to show a swap, and not
#: a dead direct channel beside a coupling.
SWAP_GAIN_FACTOR: Final = 4.0
#: Notice a 4QD offset beyond this many times the bench file's linear span of the 4QD.
OFFSET_SPAN_FACTOR: Final = 1.0

_CAL = ("data_cal_pd_h", "data_cal_pd_v")


@dataclass(frozen=True)
class _Run:
    experiment: str
    axis: int  # 0: h, 1: v
    command: str  # the excitation (Uch, Unh) or the calibration's regressor (Vnh)
    direct: str
    cross: str
    coil: str | None = None
    other_coil: str | None = None


_RUNS: Final = (
    _Run("data_cal_pd_h", 0, "Vnh", "Vph", "Vpv"),
    _Run("data_cal_pd_v", 1, "Vnv", "Vpv", "Vph"),
    _Run("data_uch", 0, "Uch", "Vph", "Vpv", "Vch", "Vcv"),
    _Run("data_ucv", 1, "Ucv", "Vpv", "Vph", "Vcv", "Vch"),
    _Run("data_unh", 0, "Unh", "Vph", "Vpv"),
    _Run("data_unv", 1, "Unv", "Vpv", "Vph"),
)
_NOISE_RUNS: Final = ("data_huddle_test_1", "data_huddle_test_2", "data_huddle_test_4")


@dataclass(frozen=True)
class PathSign:
    """One direct path's gain against the model's.

    Attributes
    ----------
    experiment, input, output : str
    measured : float
        The response in :data:`SIGN_BAND_HZ` in phase with the model's static
        sign [output unit / input unit] (the calibration: its slope).
    model : float
        The model's, signed, same unit.
    agreement : float
        ρ in [−1, 1]: +1 the model's sign, −1 reversed.
    """

    experiment: str
    input: str
    output: str
    measured: float
    model: float
    agreement: float

    @property
    def verdict(self) -> int:
        """+1 agrees, −1 reversed, 0 not judged (``|ρ| < SIGN_AGREEMENT``)."""
        return 1 if self.agreement >= SIGN_AGREEMENT else (
            -1 if self.agreement <= -SIGN_AGREEMENT else 0)

    def words(self) -> str:
        """``Uch → Vph −0.96 V/V (model +0.96)``."""
        unit = "V/V"
        return f"{self.input} → {self.output} {self.measured:+.3g} {unit} (model {self.model:+.3g})"


@dataclass(frozen=True)
class AxisRatio:
    """How much more the excitation moves its own axis than the other.

    Attributes
    ----------
    experiment, input, direct, cross : str
    direct_gain, cross_gain : float
        Rms response magnitudes [V/V] in the band (the calibration: slopes).
    model_ratio : float
        The model's direct over cross (inf without a cross path).
    direct_coherence, cross_coherence : float
        Median γ² in the band (the calibration: r²).
    model_direct_gain : float
        The model's direct gain, same measure as ``direct_gain`` [V/V].
    coil : tuple of (str, float, str, float) or None
        Own coil voltage and gain, other coil and gain, when both were recorded.
    own_coil_coherence : float
        Median γ² of the run's own coil monitor (``Uch → Vch``) in the band: the DAC
        drove this axis's coil when it is coherent (NaN without a coil monitor).
    mode_hz : float
        The Sercalo mode the run excites (the largest response between 50 Hz and
        1 kHz on either 4QD output) [Hz]; NaN for a run without a coil.
    records_direct_gain : float
        A direct path's gain as the records measure it: the larger of the partner
        run's two responses (``data_ucv``'s for ``data_uch`` …), same measure [V/V];
        NaN without a coherent partner run.
    """

    experiment: str
    input: str
    direct: str
    cross: str
    direct_gain: float
    cross_gain: float
    model_ratio: float
    direct_coherence: float
    cross_coherence: float
    model_direct_gain: float
    coil: tuple[str, float, str, float] | None = None
    own_coil_coherence: float = float("nan")
    mode_hz: float = float("nan")
    records_direct_gain: float = float("nan")

    @property
    def swap_gain(self) -> float:
        """The gain a cross path must reach to show that the other axis moved [V/V]: a
        direct path's, the bench file's model's or the records' (the smaller: a bench
        whose gains are all below the bench file's is a finding, not a reason to miss a
        swap), over :data:`SWAP_GAIN_FACTOR`."""
        direct = (min(self.model_direct_gain, self.records_direct_gain)
                  if np.isfinite(self.records_direct_gain) else self.model_direct_gain)
        return direct / SWAP_GAIN_FACTOR

    @property
    def judged(self) -> bool:
        """At least one of the two paths is coherent (:data:`MIN_COHERENCE`)."""
        return max(self.direct_coherence, self.cross_coherence) >= MIN_COHERENCE

    @property
    def ratio(self) -> float:
        """Direct over cross (inf for a cross path that does not move)."""
        return self.direct_gain / self.cross_gain if self.cross_gain > 0 else float("inf")

    @property
    def passed(self) -> bool:
        """Not shown to have moved the other axis: the own coil moved more than the other,
        and the cross output did not move more than the direct one with a direct path's gain
        (coherent, at least :attr:`swap_gain`)."""
        coil_ok = self.coil is None or self.coil[1] > self.coil[3]
        other_moved = (self.ratio <= AXIS_RATIO_MIN and self.cross_coherence >= MIN_COHERENCE
                       and self.cross_gain >= self.swap_gain)
        return bool(coil_ok and not other_moved)


@dataclass(frozen=True, eq=False)
class Screening:
    """What :func:`screen_recordings` found.

    Attributes
    ----------
    checks : tuple of Check
        Every check, once, in order.
    by_experiment : dict of str to tuple of Check
        The checks each record answers for (a failed one makes every step
        that uses the record fall back, naming it).
    notices : tuple of Notice
        4QD offsets removed; huddle tests left out of the noise model.
    recordings : mapping of str to Dataset
        The recordings less the open-loop huddle tests whose own checks failed.
    findings : tuple of Finding
        The bench's own signs where the bench file states others.
    params : BenchParams or None
        The bench file's nominal parameters with those signs (what the steps model).
    loops : dict of axis to RecordedController
        The controller the closed-loop records ran.
    signs : tuple of SignDiagnosis
        The explanations of each axis's path signs.
    """

    checks: tuple[Check, ...]
    by_experiment: dict[str, tuple[Check, ...]]
    notices: tuple[Notice, ...]
    recordings: Mapping[str, xr.Dataset] = field(default_factory=dict)
    findings: tuple[Finding, ...] = ()
    params: BenchParams | None = None
    loops: Mapping[str, RecordedController] = field(default_factory=dict)
    signs: tuple[SignDiagnosis, ...] = ()


def _values(ds: xr.Dataset, name: str) -> np.ndarray:
    return np.asarray(ds[name].values, dtype=np.float64)


def _welch_h1(u: np.ndarray, ys: list[np.ndarray], fs: float
              ) -> tuple[np.ndarray, list[np.ndarray], list[np.ndarray], np.ndarray]:
    """Frequencies [Hz], the H1 estimate and γ² of each output (1 s Hann, means removed),
    and the bins the input excites (its PSD within 30 dB of its band median's; a multisine
    on a coarser grid than 1 Hz leaves bins with round-off for input, whose ratio means
    nothing).

    scipy's ``welch`` and ``csd`` (periodic Hann, half overlap, each segment less its
    mean, one-sided density), every segment of every signal in one FFT: scipy detrends
    and transforms them one by one (0.21 s against 0.03 s for the six Sercalo and Newport
    runs; the tests compare the two to 1e-12).
    """
    n = min(round(fs), u.size // 2)
    window = scipy.signal.get_window("hann", n)
    hop = n - n // 2
    signals = np.stack([u, *ys])
    segments = np.lib.stride_tricks.sliding_window_view(signals, n, axis=1)[:, ::hop]
    spectra = scipy.fft.rfft((segments - segments.mean(axis=-1, keepdims=True)) * window,
                             axis=-1)  # (signal, segment, bin)
    scale = np.full(spectra.shape[-1], 2.0 / (fs * float(np.sum(window**2))))
    scale[0] /= 2.0
    if n % 2 == 0:
        scale[-1] /= 2.0
    f = scipy.fft.rfftfreq(n, 1.0 / fs)
    puu = np.mean(spectra[0].real ** 2 + spectra[0].imag ** 2, axis=0) * scale
    band = (f >= SIGN_BAND_HZ[0]) & (f <= SIGN_BAND_HZ[1])
    typical = float(np.median(puu[band])) if band.any() else 0.0
    top = float(np.max(puu[band])) if band.any() else 0.0
    # A flat (noise) input: every bin; lines of a multisine: the bins at and beside them.
    excited = puu > _EXCITED_OF_TOP * max(typical, top * _EXCITED_OF_TOP)
    puu = np.where(puu > 0, puu, np.inf)
    h, coh = [], []
    for y in spectra[1:]:
        puy = np.mean(spectra[0].conj() * y, axis=0) * scale
        pyy = np.mean(y.real ** 2 + y.imag ** 2, axis=0) * scale
        h.append(puy / puu)
        coh.append(np.abs(puy) ** 2 / (puu * np.where(pyy > 0, pyy, np.inf)))
    return f, h, coh, excited


def _projection(h: np.ndarray, model: np.ndarray, sign: float) -> tuple[float, float, float]:
    """(measured in phase with the model, model, ρ) over the band's lines."""
    phase = model / np.abs(model) * sign  # the model's phase less its static sign
    measured = float(np.mean(np.real(h * np.conj(phase))))
    norm = float(np.linalg.norm(model) * np.linalg.norm(h))
    rho = float(np.real(np.vdot(model, h))) / norm if norm > 0 else 0.0
    return measured, float(np.mean(np.abs(model))) * sign, rho


def _measure_dynamic(run: _Run, ds: xr.Dataset, plant: PlantModel
                     ) -> tuple[list[PathSign], AxisRatio, dict[str, float]]:
    fs = float(ds.attrs["fs_hz"])
    outs = [run.direct, run.cross]
    coils = [c for c in (run.coil, run.other_coil) if c is not None and c in ds]
    f, hs, cs, excited = _welch_h1(_values(ds, run.command),
                                   [_values(ds, o) for o in outs + coils], fs)
    band = (f >= SIGN_BAND_HZ[0]) & (f <= SIGN_BAND_HZ[1]) & excited
    h = dict(zip(outs + coils, (x[band] for x in hs), strict=True))
    coherence = {o: float(np.median(c[band])) for o, c in zip(outs + coils, cs, strict=True)}
    names = outs + coils
    model = plant.frequency_response(f[band], outputs=names, inputs=[run.command])
    signs = []
    for out in [run.coil, run.direct]:
        if out is None or out not in h:
            continue
        hn = model.sel(output=out, input=run.command).values
        sign = float(np.sign(plant.dc_gain(output=out, input=run.command)) or 1.0)
        measured, m, rho = _projection(h[out], hn, sign)
        signs.append(PathSign(run.experiment, run.command, out, measured, m, rho))
    rms = {k: float(np.sqrt(np.mean(np.abs(v) ** 2))) for k, v in h.items()}
    mod = {k: float(np.sqrt(np.mean(np.abs(model.sel(output=k).values) ** 2))) for k in names}
    coil = None
    if run.coil in rms and run.other_coil in rms and run.coil and run.other_coil:
        coil = (run.coil, rms[run.coil], run.other_coil, rms[run.other_coil])
    # The Sercalo mode the run excites: its own axis's (a mirror turned against the 4QD) or
    # the other's (the other axis's run), on whichever output carries it.
    peak = float("nan")
    if run.coil is not None:
        search = (f >= 50.0) & (f <= min(1000.0, 0.4 * fs))
        if search.any():
            both = np.abs(hs[0][search]) + np.abs(hs[1][search])
            peak = float(f[search][int(np.argmax(both))])
    axis = AxisRatio(run.experiment, run.command, run.direct, run.cross, rms[run.direct],
                     rms[run.cross], mod[run.direct] / mod[run.cross] if mod[run.cross] > 0
                     else float("inf"), coherence[run.direct], coherence[run.cross],
                     mod[run.direct], coil,
                     coherence.get(run.coil, float("nan")) if run.coil else float("nan"),
                     peak)
    offsets = {o: float(np.mean(_values(ds, o))) for o in outs}
    return signs, axis, offsets


def _measure_calibration(run: _Run, ds: xr.Dataset, params: BenchParams
                         ) -> tuple[list[PathSign], AxisRatio, dict[str, float]]:
    x = _values(ds, run.command)
    x = x - x.mean()
    gd = params.quad_diode.gain_v_per_rad.as_array()
    mn = newport_beam_matrix(params)
    gn0 = params.newport.metrology_gain_rad_per_v
    model = {run.direct: gd[run.axis] * mn[run.axis, run.axis] * gn0,
             run.cross: gd[1 - run.axis] * mn[1 - run.axis, run.axis] * gn0}
    sxx = float(x @ x)
    raw_mean = float(np.mean(_values(ds, run.command)))
    slopes, offsets, corr = {}, {}, {}
    for out in (run.direct, run.cross):
        y = _values(ds, out)
        yc = y - y.mean()
        slopes[out] = float(x @ yc) / sxx if sxx > 0 else 0.0
        # The 4QD's offset where the metrology reads 0: the line's intercept.
        offsets[out] = float(y.mean()) - slopes[out] * raw_mean
        sy = float(np.linalg.norm(yc))
        corr[out] = float(x @ yc) / (np.sqrt(sxx) * sy) if sxx > 0 and sy > 0 else 0.0
    rho = corr[run.direct] * float(np.sign(model[run.direct]) or 1.0)
    sign = PathSign(run.experiment, run.command, run.direct, slopes[run.direct],
                    model[run.direct], rho)
    cross_model = abs(model[run.cross])
    axis = AxisRatio(run.experiment, run.command, run.direct, run.cross,
                     abs(slopes[run.direct]), abs(slopes[run.cross]),
                     abs(model[run.direct]) / cross_model if cross_model > 0 else float("inf"),
                     corr[run.direct] ** 2, corr[run.cross] ** 2, abs(model[run.direct]))
    return [sign], axis, offsets


_BY_NAME: Final = {r.experiment: r for r in _RUNS}


def with_records_gains(axes: Mapping[str, AxisRatio]) -> dict[str, AxisRatio]:
    """Each run with its partner's larger coherent response (:attr:`AxisRatio.swap_gain`).

    A swapped run's cross output carries the other axis's direct gain, which the partner
    run measures (as its direct response, or as its cross one when both runs are
    swapped); a dead direct channel beside a coupling leaves the cross output a few % of
    it. On a bench far below the bench file's gains (the corpus's ``weak``: the Sercalo
    path at 1/80 of the model's) the model's gain alone hid every swap.
    """
    out = dict(axes)
    for exp, a in axes.items():
        partner = axes.get(_PARTNER[exp])
        if partner is None or not partner.judged:
            continue
        gains = [g for g, c in ((partner.direct_gain, partner.direct_coherence),
                                (partner.cross_gain, partner.cross_coherence))
                 if c >= MIN_COHERENCE and np.isfinite(g)]
        if gains:
            out[exp] = replace(a, records_direct_gain=float(max(gains)))
    return out
_PARTNER: Final = {"data_cal_pd_h": "data_cal_pd_v", "data_cal_pd_v": "data_cal_pd_h",
                   "data_uch": "data_ucv", "data_ucv": "data_uch",
                   "data_unh": "data_unv", "data_unv": "data_unh"}


def _band_words() -> str:
    return f"{SIGN_BAND_HZ[0]:g}–{SIGN_BAND_HZ[1]:g} Hz"


def _ratio_words(r: float) -> str:
    return "no cross path" if not np.isfinite(r) else f"{r:.3g}×"


def _axis_check(a: AxisRatio, axes: Mapping[str, AxisRatio],
                resonances_hz: Mapping[str, float] | None = None) -> Check:
    subject = f"{a.experiment}.mat: {a.input}"
    limit = (f"> {AXIS_RATIO_MIN:g} ({a.direct} over {a.cross}) if {a.cross} moves with a "
             f"direct path's gain (≥ {a.swap_gain:.3g} V/V); the bench "
             f"file's model: {_ratio_words(a.model_ratio)}")
    if a.passed:
        return Check("excited_axis", True, a.ratio, limit, subject, unit="×")
    moved = [f"{a.input} moves {a.cross} ({a.cross_gain:.3g} V/V) more than {a.direct} "
             f"({a.direct_gain:.3g} V/V)"]
    if a.coil is not None and a.coil[3] >= a.coil[1]:
        moved.append(f"the {a.coil[2]} coil ({a.coil[3]:.3g} V/V) more than its own {a.coil[0]} "
                     f"({a.coil[1]:.3g} V/V)")
    return Check("excited_axis", False, a.ratio, limit, subject,
                 f"{' and '.join(moved)} ({_band_words()}), where the bench file's model "
                 + (f"moves only {a.direct}" if not np.isfinite(a.model_ratio) else
                    f"has {a.direct} {a.model_ratio:.3g}× above {a.cross}")
                 + f"; {_swap_cause(a, axes, resonances_hz)}; this file's identification "
                 "steps use the nominal model", unit="×")


def _kind(exp: str) -> str:
    return "cal" if exp in _CAL else ("uc" if _BY_NAME[exp].coil is not None else "un")


def _swap_cause(a: AxisRatio, axes: Mapping[str, AxisRatio],
                resonances_hz: Mapping[str, float] | None = None) -> str:
    """Every cause that moves the other axis in the records that show it, across the runs:
    the pattern over the calibrations, the Sercalo and the Newport runs separates the 4QD's
    outputs crossed (every run, the coil monitors following their own commands) from the
    DAC cables swapped (the Sercalo's runs only, the monitors not following)."""
    judged = {e: r for e, r in axes.items() if r.judged}
    other = {e for e, r in judged.items() if not r.passed}
    kinds = {_kind(e) for e in judged}
    crossed_kinds = {_kind(e) for e in other}
    coils = [r.own_coil_coherence for e, r in judged.items()
             if _kind(e) == "uc" and np.isfinite(r.own_coil_coherence)]
    coils_follow = bool(coils) and min(coils) >= MIN_COHERENCE
    if other == set(judged) and len(kinds) >= 2:
        separated = [w for k, w in (
            ("cal", "the calibrations, where the metrology reads the Newport's own axis"),
            ("uc", "the Sercalo's runs, whose coil monitors follow their own commands"
                   if coils_follow else "the Sercalo's runs"),
            ("un", "the Newport's runs")) if k in kinds]
        return ("one cause explains every record: the 4QD's outputs are crossed (Vph reads the "
                "vertical beam angle and Vpv the horizontal: their cables exchanged, or the "
                "detector turned by 90°), as " + ", ".join(separated) + " show alike; not the "
                "DAC cables" + (", whose commands reach their own coils" if coils_follow else "")
                + ": exchange Vph and Vpv (the cables, or the variables of the files)")
    partner_name = _PARTNER[a.experiment]
    partner = axes.get(partner_name)
    both = partner is not None and partner.judged and not partner.passed
    if _kind(a.experiment) == "uc":
        axis = _BY_NAME[a.experiment].axis
        res = resonances_hz or {}
        own, far = res.get("hv"[axis]), res.get("hv"[1 - axis])
        other_mode = (own is not None and far is not None and np.isfinite(a.mode_hz)
                      and abs(a.mode_hz - far) < abs(a.mode_hz - own))
        if both and coils_follow and other_mode:
            # The records are self-consistent either way: exchanging files when the coils
            # were crossed would hide a wiring fault, so no data-changing advice.
            return (f"the two runs hold each other's axis: {a.experiment}.mat excites the "
                    f"{a.mode_hz:.0f} Hz mode, the bench file's {'hv'[1 - axis]} mode, and its "
                    "coil monitor follows its command: either the amplifiers drive each "
                    "other's axis (the cables from the current amplifiers to the coils "
                    "swapped for these runs), or the two files exchanged with their variables "
                    "renamed; not the DAC's cables, which would leave this file's coil monitor "
                    "still; the records cannot tell the two: check which coil each amplifier "
                    "drives before changing any file")
        if both and coils_follow:
            return ("the Sercalo's two runs move each other's 4QD axis while their coil "
                    "monitors follow their own commands and each excites its own axis's mode: "
                    "the Sercalo's axes are turned against the 4QD's (the mirror turned by "
                    "90°, or its coil pairs exchanged after the monitors); not the DAC cables "
                    "nor the files; check the mirror's mounting and its coils' wiring")
        if both and partner is not None:
            return (f"the two runs drive each other's axis: the {a.input} and {partner.input} "
                    f"DAC cables swapped, or the two files exchanged ({a.experiment}.mat holds "
                    f"{partner_name}'s run); the records cannot tell the two: check the cables "
                    "and the files' names")
        return (f"the excitation drove the other axis in this run only: a DAC cable swapped "
                f"for it, or the other axis's run saved as {a.experiment}.mat; the records "
                "cannot tell the two")
    if _kind(a.experiment) == "cal":
        return ("the Newport swept the other axis in the calibration: the metrology cables "
                "(Vnh, Vnv), the Newport's drive cables, or the two calibration files exchanged"
                + ("" if crossed_kinds == {"cal"} else " (other runs show it too)")
                + "; the records cannot tell which")
    return ("the Newport's command drove its other axis: the drive cables (Unh, Unv) "
            "exchanged, or the two files; the records cannot tell which")


#: The bench signs (:data:`~fsmbench.ident.evidence.signs.BENCH_SIGNS`) along each measured
#: path, by record kind and whether the output is the run's coil monitor.
def _bench_letters(run: _Run, output: str) -> tuple[str, ...]:
    if run.experiment in _CAL:
        return ("q", "r")
    if run.coil is not None:
        return ("c", "i") if output == run.coil else ("q", "m", "i")
    return ("q", "n")


def _path_observations(judged: Mapping[str, list[PathSign]]) -> list[SignObservation]:
    return [SignObservation(exp, p.input, p.output, _bench_letters(_BY_NAME[exp], p.output),
                            p.verdict, p.words())
            for exp, paths in judged.items() for p in paths if p.verdict != 0]


def _offset_notices(offsets: Mapping[str, Mapping[str, float]], params: BenchParams
                    ) -> list[Notice]:
    qd = params.quad_diode
    out = []
    for axis, vp in enumerate(("Vph", "Vpv")):
        span = abs(qd.gain_v_per_rad.as_array()[axis]) * qd.nonlinearity_full_swing_rad
        far = {exp: off[vp] for exp, off in offsets.items()
               if vp in off and abs(off[vp]) > OFFSET_SPAN_FACTOR * span}
        if not far or span <= 0:
            continue
        gain = qd.gain_v_per_rad.as_array()[axis]
        worst = max(far.values(), key=abs)
        same = max(far.values()) - min(far.values()) <= 0.1 * abs(worst)  # one offset, 10 %
        values = (f"{worst:+.3g} V in {'each of the ' if len(far) > 1 else ''}"
                  f"{len(far)} file{'s' if len(far) > 1 else ''}" if same
                  else ", ".join(f"{v:+.3g} V ({e}.mat)" for e, v in far.items()))
        out.append(Notice(
            "other", f"{', '.join(f'{e}.mat' for e in far)}: {vp}",
            f"4QD offset: {vp} is centred at {values}, beyond the 4QD's linear span of "
            f"±{span:.3g} V (±{1e3 * qd.nonlinearity_full_swing_rad:.3g} mrad at {gain:+.4g} "
            f"V/rad in the bench file): the beam is {1e3 * abs(worst / gain):.3g} mrad off the "
            "detector's centre. Removed: the calibration fits its intercept and every FRF "
            "estimate works on the signals less their means; but off centre the 4QD's gain is "
            "not the calibrated one: centre the beam on the 4QD"))
    return out


def screen_recordings(recordings: Mapping[str, xr.Dataset], *, params: BenchParams,
                      trims_s: Mapping[str, float],
                      failure: Callable[[str], Check | None]) -> Screening:
    """Check the identification records against each other and the bench file.

    Parameters
    ----------
    recordings : mapping of str to Dataset
        The records by experiment name; those of the six identification runs
        present are read (``t`` [s], signals [V]).
    params : BenchParams
        The bench file's nominal parameters (the model the signs and axes are
        compared with; the 4QD's linear span for the offsets).
    trims_s : mapping of str to float
        Seconds removed at the start of each run (the steps' own).
    failure : callable
        The first failed plausibility check of a record, or None
        (``check_recording``'s): a record that fails one is not read here.

    Returns
    -------
    Screening
        The checks (each once), the experiments they answer for, the offset
        notices and the recordings for the noise model.
    """
    plant = physical_plant(params, source="nominal")
    signs: dict[str, list[PathSign]] = {}
    axes: dict[str, AxisRatio] = {}
    offsets: dict[str, dict[str, float]] = {}
    for run in _RUNS:
        if run.experiment not in recordings or failure(run.experiment) is not None:
            continue
        try:
            ds = trim_recording(recordings[run.experiment],
                                t0_s=trims_s.get(run.experiment, 0.0))
            if any(v not in ds for v in (run.command, run.direct, run.cross)):
                continue
            found = (_measure_calibration(run, ds, params) if run.experiment in _CAL
                     else _measure_dynamic(run, ds, plant))
        except ValueError:
            continue  # too short to read: the step says so itself
        signs[run.experiment], axes[run.experiment], offsets[run.experiment] = found
    axes = with_records_gains(axes)
    res = {a: params.sercalo.resonance_hz[a] for a in "hv"}
    pairs = [(_axis_check(a, axes, res), [exp]) for exp, a in axes.items() if a.judged]
    pairs += closed_loop_runs(recordings, params)
    judged = {exp: [p for p in signs[exp] if p.verdict != 0] for exp in signs
              if axes[exp].passed}
    # In this process: forking the four fits cost more than it saved (the copy-on-write of
    # the caller's heap; docs/architecture.md, Processes).
    loops = recorded_controllers(recordings, fs_hz=params.converter.fs_hz,
                                 step_v=params.converter.lsb_v)
    outcome = diagnose_signs([*_path_observations(judged),
                              *rep_observations(recordings, params),
                              *loop_observations(loops, plant)], params=params)
    by_experiment: dict[str, tuple[Check, ...]] = {}
    for check, exps in pairs:
        for exp in exps:
            by_experiment[exp] = (*by_experiment.get(exp, ()), check)
    for exp, sign_checks in outcome.by_experiment.items():
        by_experiment[exp] = (*by_experiment.get(exp, ()), *sign_checks)
    notices = [*_offset_notices(offsets, params), *outcome.notices]
    checks = [c for c, _ in pairs] + list(outcome.checks)
    kept = dict(recordings)
    conv = params.converter
    for name in _NOISE_RUNS:
        if name not in recordings:
            continue
        found_checks, _ = check_recording(recordings[name], name=name, fs_hz=conv.fs_hz,
                                          adc_range_v=conv.range_v, adc_bits=conv.bits)
        bad = first_failure(found_checks)
        if bad is not None:
            del kept[name]
            checks += [c for c in found_checks if not c.passed]
            notices.append(Notice("other", f"{name}.mat", f"left out of the noise model: "
                                  f"{bad.sentence()}"))
    return Screening(checks=tuple(checks), by_experiment=by_experiment,
                     notices=tuple(notices), recordings=kept, findings=outcome.findings,
                     params=outcome.params, loops=loops, signs=outcome.diagnoses)
