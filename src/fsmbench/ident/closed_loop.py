"""The Sercalo identified with the loop closed: records → FRF → the open-loop fit → a plant.

``data_cl_uch`` and ``data_cl_ucv`` (layout: :mod:`fsmbench.twin.closed_loop`)
hold an excitation played while the loop ran, the commands and the 4QD
outputs. :func:`identify_closed_loop`:

1. checks each record as every recording is checked (rate, range, signals that
   move), finds where its excitation starts, and measures the **tracking error
   during the measurement**: the 4QD's beam angle rms while excited, before it
   (the loop's own), and what the excitation added (their quadrature difference),
   against the user's bound when one is given (:mod:`fsmbench.ident.closed_loop_tracking`);
2. estimates the 2×2 FRF matrix ``Uch, Ucv → Vph, Vpv`` by the joint
   input–output method with the excitation as the instrument
   (:mod:`fsmbench.ident.frf.closed_loop`: periodic averaging when the excitation
   repeats, else the LPM), with the variance of every line, and the *direct*
   method on the same lines for its bias;
3. fits it exactly as the open-loop identification fits its FRF
   (:func:`fsmbench.ident.sercalo.fit_sercalo`: the joint delay fit, the vector
   fit weighted by each line's inverse standard deviation, the parameters'
   standard deviations). The time-domain mode refinement of the open-loop records
   does not apply (it treats the command as noise-free and independent of the
   output's noise, which the feedback breaks); the periodic lines need no
   window, so none is needed;
4. the current amplifiers from the coil voltages recorded in the same records
   (``Vch``, ``Vcv``: the feedback does not correlate their noise with the
   command), when present and not clipped;
5. assembles the plant (:func:`fsmbench.bench.blocks.assemble_plant`): ``Gc``
   and ``Gi`` identified here, the 4QD gain ``Gd`` and the Newport ``Gn`` (which
   a closed-loop Sercalo measurement cannot see) from a previous identification
   of the same bench when given (``prior``), else the bench file's, each named.

The result writes ``identification.json`` (format ``fsmbench.identification``
version 4, the keys of ``twin_truth.json`` for what was identified here, the
closed-loop part under ``diagnostics.closed_loop``), ``plant.mat`` and
``frf.mat``: a folder ``--bench DIR`` takes like any identification.
"""

from __future__ import annotations

import dataclasses
import warnings as pywarnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, NamedTuple

import control as ct
import numpy as np
import xarray as xr

from fsmbench.bench.blocks import (
    PlantModel,
    assemble_plant,
    coil_impedance,
    current_amplifier,
    input_delays_s,
    newport,
    quad_diode,
    voltage_amplifier,
)
from fsmbench.bench.params import Bench
from fsmbench.checks import Check, Notice, first_failure
from fsmbench.ident.calibration import current_amp_checks
from fsmbench.ident.closed_loop_tracking import TrackingDuringMeasurement, _tracking
from fsmbench.ident.current_amp import calibrate_current_amplifier
from fsmbench.ident.delay.sampled import SensorLowpass
from fsmbench.ident.export import write_identification_folder
from fsmbench.ident.frf.closed_loop import ClosedLoopFrf, ClosedLoopRecord, closed_loop_frf
from fsmbench.ident.frf.closed_loop_merge import merge_closed_loop_frf
from fsmbench.ident.frf.estimate import FrfEstimate
from fsmbench.ident.pipeline import path_keyed_summary, quality_warnings
from fsmbench.ident.sercalo import SercaloFitOptions, SercaloIdentification, fit_sercalo
from fsmbench.io.errors import RecordingError
from fsmbench.io.record_checks import check_recording
from fsmbench.io.recording import read_recording
from fsmbench.version import __version__

__all__ = ["CLOSED_LOOP_RECORDS", "EXCITATION_VARIABLES", "MODE_ASSIGNMENT_TOLERANCE",
           "ClosedLoopIdentification", "ClosedLoopIdentifyOptions", "TrackingDuringMeasurement",
           "find_closed_loop_records", "identify_closed_loop", "read_closed_loop_records",
           "unassigned_modes", "write_closed_loop_identification"]

#: The closed-loop records, in the order of the FRF matrix's columns.
CLOSED_LOOP_RECORDS = ("data_cl_uch", "data_cl_ucv")
#: The excitation's variable in each record: at the controller's output, or the reference.
EXCITATION_VARIABLES = {"data_cl_uch": ("Xch", "Xph"), "data_cl_ucv": ("Xcv", "Xpv")}
_REQUIRED = ("t", "Uch", "Ucv", "Vph", "Vpv")
_SUFFIXES = (".mat", ".h5", ".nxs")
# The coil-voltage channels: a failure there only leaves the current amplifiers unmeasured.
_COIL = (": Vch", ": Vcv")


@dataclass(frozen=True)
class ClosedLoopIdentifyOptions:
    """Options of :func:`identify_closed_loop`.

    Attributes
    ----------
    frf : {"auto", "periodic", "lpm"}
        Estimator of the joint method (auto: periodic when the excitation repeats).
    transient_periods : int, optional
        Whole periods dropped after the excitation starts (the loop's transient);
        default found on each record
        (:func:`fsmbench.ident.frf.closed_loop.settled_periods`).
    sercalo : SercaloFitOptions
        The fit (inverse-variance weights by default: each line's own variance).
    max_error_rad : float, optional
        The user's bound on the rms beam-angle error the measurement adds [rad],
        to judge the tracking error during it (None: reported only).
    current_amp_band_hz : (float, float)
        Band of the current amplifiers' lines [Hz] (the open-loop identification's).
    fit_min_hz : float
        Lowest line the Sercalo fit takes [Hz]. Below a few hertz the joint estimate
        on the twin falls short of the plant whatever the noise (mean ``G/g`` over 14
        runs: 0.02 at 0.75 Hz, 0.5 at 3.75 Hz, within its standard error of 1 from
        7 Hz; cause not identified), and its variance does not cover that: with two
        stages merged those lines carried the fit off (a mode 4 % off, damping
        ×45). The Sercalo is flat there; its static gain is read from 10-200 Hz.
    """

    frf: Literal["auto", "periodic", "lpm"] = "auto"
    transient_periods: int | None = None
    sercalo: SercaloFitOptions = field(
        default_factory=lambda: SercaloFitOptions(weights="variance"))
    max_error_rad: float | None = None
    current_amp_band_hz: tuple[float, float] = (20.0, 200.0)
    fit_min_hz: float = 10.0

    def to_json(self) -> dict[str, Any]:
        """Plain values."""
        return {"frf": self.frf, "transient_periods": self.transient_periods,
                "sercalo": dict(self.sercalo.__dict__), "max_error_rad": self.max_error_rad,
                "current_amp_band_hz": list(self.current_amp_band_hz),
                "fit_min_hz": self.fit_min_hz}


@dataclass(frozen=True, eq=False)
class ClosedLoopIdentification:
    """What :func:`identify_closed_loop` found (see the module notes).

    Attributes
    ----------
    frf : ClosedLoopFrf
    sercalo : SercaloIdentification or None
        None when the fit failed (``skipped`` says why).
    plant : PlantModel or None
    plant_blocks : dict block -> str
        ``identified`` (here), ``prior`` (the previous identification) or ``nominal``.
    current_amp_a_per_v : dict axis -> float
        The current amplifiers' gains used [A/V].
    tracking : tuple of TrackingDuringMeasurement
    at : {"output", "reference"}
    source, prior_source : str
    skipped : dict step -> reason
    warnings : tuple of str
    checks : tuple of Check
    notices : tuple of Notice
    options : ClosedLoopIdentifyOptions
    """

    frf: ClosedLoopFrf
    sercalo: SercaloIdentification | None
    plant: PlantModel | None
    plant_blocks: dict[str, str]
    current_amp_a_per_v: dict[str, float]
    tracking: tuple[TrackingDuringMeasurement, ...]
    at: str
    source: str
    prior_source: str
    skipped: dict[str, str]
    warnings: tuple[str, ...]
    checks: tuple[Check, ...]
    notices: tuple[Notice, ...]
    options: ClosedLoopIdentifyOptions

    def direct_bias(self, bands_hz: tuple[tuple[float, float], ...] = (
            (0.0, 10.0), (10.0, 100.0), (100.0, 1000.0))) -> dict[str, Any]:
        """Median ``|G_direct / G_joint - 1|`` of the direct paths per band [1]: the direct
        method's departure from the consistent estimate, on the same lines and data."""
        f = self.frf.frequency_hz
        g, d = self.frf.plant.frf, self.frf.direct.frf
        out: dict[str, Any] = {}
        for lo, hi in bands_hz:
            sel = (f > lo) & (f <= hi)
            key = f"band_{lo:g}_{hi:g}_hz"
            out[key] = {path: (float(np.median(np.abs(d[sel, i, i] / g[sel, i, i] - 1.0)))
                               if sel.any() else None)
                        for i, path in enumerate(("Uch_to_Vph", "Ucv_to_Vpv"))}
        return out

    def to_json(self) -> dict[str, Any]:
        """The keys of ``twin_truth.json`` identified here, plus diagnostics."""
        out: dict[str, Any] = {"fsmbench_version": __version__, "source": self.source}
        if self.plant_blocks.get("Gi") == "identified":
            out["current_amp_gain_a_per_v"] = dict(self.current_amp_a_per_v)
        sid = self.sercalo
        modes: dict[str, dict[str, float]] = {}
        if sid is not None:
            dc = sid.dc_gain_v_per_a()
            fitted = sid.fit.modes()
            for axis, inp in (("h", "Uch"), ("v", "Ucv")):
                if inp in sid.resonances_hz and fitted:
                    m = fitted[int(np.argmin([abs(x.resonance_hz - sid.resonances_hz[inp])
                                              for x in fitted]))]
                    modes[axis] = {"resonance_hz": m.resonance_hz,
                                   "damping_ratio": m.damping_ratio,
                                   "resonance_hz_std": m.resonance_hz_std,
                                   "damping_ratio_std": m.damping_ratio_std}
            out["sercalo"] = {a: {"resonance_hz": modes[a]["resonance_hz"],
                                  "damping_ratio": modes[a]["damping_ratio"],
                                  "dc_gain_v_per_a": dc[a]} for a in modes}
            out["delay_s"] = {"sercalo": sid.pure_delay_s}
        out["checks"] = [c.to_json() for c in self.checks]
        out["notices"] = [n.to_json() for n in self.notices]
        summary = None if sid is None else path_keyed_summary(sid.summary())
        out["diagnostics"] = {
            "sercalo": summary,
            "sercalo_modes": modes,
            "frf_estimator": {"sercalo": self.frf.plant.estimator},
            "closed_loop": {
                "method": self.frf.method, "at": self.at, "records": list(CLOSED_LOOP_RECORDS),
                "frf": self.frf.summary(),
                "tracking_during_measurement": [t.to_json() for t in self.tracking],
                "direct_method": {"description": "the direct method (y against u, the "
                                                  "excitation ignored) on the same lines: "
                                                  "median |G_direct / G_joint - 1|",
                                  **self.direct_bias()},
                "prior": self.prior_source},
            "plant_blocks": self.plant_blocks,
            "skipped": self.skipped,
            "warnings": list(self.warnings),
            "options": self.options.to_json(),
        }
        return out


def find_closed_loop_records(folder: str | Path) -> dict[str, Path]:
    """The closed-loop records a folder holds (``data_cl_uch.mat`` … ``.h5``, ``.nxs``)."""
    root = Path(folder)
    found: dict[str, Path] = {}
    for name in CLOSED_LOOP_RECORDS:
        for suffix in _SUFFIXES:
            if (root / f"{name}{suffix}").is_file():
                found[name] = root / f"{name}{suffix}"
                break
    return found


def read_closed_loop_records(folder: str | Path) -> dict[str, xr.Dataset]:
    """Read ``data_cl_uch`` and ``data_cl_ucv`` from ``folder``.

    Raises
    ------
    RecordingError
        A record is missing (named, with what the folder holds) or unreadable.
    """

    found = find_closed_loop_records(folder)
    missing = [n for n in CLOSED_LOOP_RECORDS if n not in found]
    if missing:
        raise RecordingError(folder, f"has no {' and no '.join(missing)} (.mat, .h5 or .nxs): "
                                     "a closed-loop identification needs one record per "
                                     "command (fsmbench simulate --closed-loop, or your "
                                     "target's records in that layout)")
    out = {}
    for name, path in found.items():
        with pywarnings.catch_warnings():
            pywarnings.simplefilter("ignore")
            out[name] = read_recording(path, experiment=name, require=_REQUIRED)
    return out


def _excitation(ds: xr.Dataset, name: str) -> tuple[str, str]:
    """(variable, at) of the record's excitation."""
    out_var, ref_var = EXCITATION_VARIABLES[name]
    have = [v for v in (out_var, ref_var) if v in ds]
    if len(have) != 1:
        raise ValueError(f"{name}: needs its excitation as {out_var} (added at the controller's "
                         f"output) or {ref_var} (added to the reference), exactly one; found "
                         f"{', '.join(have) or 'neither'}")
    return have[0], "output" if have[0] == out_var else "reference"


def identify_closed_loop(recordings: Mapping[str, xr.Dataset], *, bench: Bench,
                         prior: PlantModel | None = None, prior_source: str = "",
                         options: ClosedLoopIdentifyOptions | None = None,
                         source: str = "",
                         merge_with: Sequence[ClosedLoopFrf] = ()) -> ClosedLoopIdentification:
    """Identify the Sercalo from ``data_cl_uch`` and ``data_cl_ucv`` (see the module notes).

    Parameters
    ----------
    recordings : mapping
        At least ``data_cl_uch`` and ``data_cl_ucv``.
    bench : Bench
        The bench file: converters, the nominal blocks (``Zc``, ``Ga``) and what
        ``prior`` does not give; its nominal 4QD gains for the tracking error when
        ``prior`` has none.
    prior : PlantModel, optional
        A previous identification of this bench: its ``Gd``, ``Gn`` (and ``Gi`` when
        the records hold no coil voltages) and the Newport's delays.
    prior_source : str
        Where ``prior`` comes from, in words.
    options : ClosedLoopIdentifyOptions, optional
    source : str
        Where the records come from.
    merge_with : sequence of ClosedLoopFrf
        Earlier measurements of the same plant on the same grid (a previous stage's
        ``frf``): the Sercalo is fitted on the union of their lines and these
        records', shared lines by their inverse-variance mean
        (:func:`fsmbench.ident.frf.closed_loop_merge.merge_closed_loop_frf`).

    Raises
    ------
    ValueError
        A record missing, failing its checks, without its excitation, or an FRF that
        cannot be estimated (named).
    """

    opts = options or ClosedLoopIdentifyOptions()
    missing = [n for n in CLOSED_LOOP_RECORDS if n not in recordings]
    if missing:
        raise ValueError(f"a closed-loop identification needs {', '.join(CLOSED_LOOP_RECORDS)}; "
                         f"{', '.join(missing)} missing")
    skipped: dict[str, str] = {}
    gd_block = prior.blocks["Gd"] if prior is not None else quad_diode(bench.nominal)
    gd = tuple(float(x) for x in np.diag(np.asarray(gd_block.D, dtype=float)))
    excited = _excited_records(recordings, bench=bench, gd_v_per_rad=(gd[0], gd[1]),
                               bound_rad=opts.max_error_rad)
    checks, notices = list(excited.checks), list(excited.notices)
    fit = _fit_records(excited, recordings, bench=bench, prior=prior, options=opts,
                       merge_with=merge_with, checks=checks, notices=notices, skipped=skipped)
    notices += fit.notices
    sid = fit.sercalo
    warnings = quality_warnings(sercalo=sid, modes=None, validation=())
    plant, blocks = _assemble(sid, bench=bench, prior=prior, gi=fit.gi, gi_how=fit.gi_how,
                              source=source)
    return ClosedLoopIdentification(
        frf=fit.frf, sercalo=sid, plant=plant, plant_blocks=blocks, current_amp_a_per_v=fit.gi,
        tracking=tuple(excited.tracking), at=excited.at, source=source,
        prior_source=prior_source or ("the bench file (no previous identification given)"
                                      if prior is None else "a previous identification"),
        skipped=skipped, warnings=warnings, checks=tuple(checks), notices=tuple(notices),
        options=opts)


class _ExcitedRecords(NamedTuple):
    """The closed-loop records checked and cut where their excitation starts.

    Attributes
    ----------
    records : list of ClosedLoopRecord
        What the joint estimator takes, in the order of :data:`CLOSED_LOOP_RECORDS`.
    tracking : list of TrackingDuringMeasurement
    at : {"output", "reference"}
        Where the excitation is added.
    starts : dict record -> int
        The excitation's first sample in each record.
    checks : list of Check
    notices : list of Notice
        What the records' checks found.
    """

    records: list[ClosedLoopRecord]
    tracking: list[TrackingDuringMeasurement]
    at: str
    starts: dict[str, int]
    checks: list[Check]
    notices: list[Notice]


def _excited_records(recordings: Mapping[str, xr.Dataset], *, bench: Bench,
                     gd_v_per_rad: tuple[float, float],
                     bound_rad: float | None) -> _ExcitedRecords:
    """Each record checked, its excitation found and the tracking error measured with the
    4QD gains ``gd_v_per_rad`` [V/rad] against the user's ``bound_rad`` [rad].

    Raises
    ------
    ValueError
        A check failed (the coil voltages' aside), no excitation or one of zeros, or the
        records excite at different places.
    """
    conv = bench.nominal.converter
    checks: list[Check] = []
    notices: list[Notice] = []
    records: list[ClosedLoopRecord] = []
    tracking: list[TrackingDuringMeasurement] = []
    places: set[str] = set()
    starts: dict[str, int] = {}
    for name in CLOSED_LOOP_RECORDS:
        ds = recordings[name]
        found, notes = check_recording(ds, name=name, fs_hz=conv.fs_hz, adc_range_v=conv.range_v,
                                       adc_bits=conv.bits)
        checks += found
        notices += notes
        bad = first_failure(c for c in found if not c.subject.endswith(_COIL))
        if bad is not None:
            raise ValueError(f"{name}: check {bad.name} failed: {bad.sentence()}")
        var, at = _excitation(ds, name)
        places.add(at)
        x = np.asarray(ds[var].values, dtype=float)
        on = np.flatnonzero(x != 0.0)
        if on.size == 0:
            raise ValueError(f"{name}: the excitation {var} is zero throughout")
        start = int(on[0])
        starts[name] = start
        tracking.append(_tracking(ds, name, start, gd_v_per_rad, bound_rad, x[start:]))
        records.append(ClosedLoopRecord(
            excitation=x[start:],
            commands=np.column_stack([ds["Uch"].values, ds["Ucv"].values])[start:],
            outputs=np.column_stack([ds["Vph"].values, ds["Vpv"].values])[start:],
            fs_hz=float(ds.attrs["fs_hz"]), name=name))
    if len(places) != 1:
        raise ValueError("data_cl_uch and data_cl_ucv excite at different places (one at the "
                         "output, one at the reference); play both the same way")
    return _ExcitedRecords(records=records, tracking=tracking, at=places.pop(), starts=starts,
                           checks=checks, notices=notices)


class _RecordsFit(NamedTuple):
    """What the records give: the joint ``frf`` (merged with earlier stages), the
    ``sercalo`` fit (None when it failed), the current amplifiers' gains ``gi`` [A/V] and
    how they were found (``gi_how``), and the numeric warnings meanwhile as ``notices``."""

    frf: ClosedLoopFrf
    sercalo: SercaloIdentification | None
    gi: dict[str, float]
    gi_how: str
    notices: list[Notice]


def _fit_records(excited: _ExcitedRecords, recordings: Mapping[str, xr.Dataset], *,
                 bench: Bench, prior: PlantModel | None, options: ClosedLoopIdentifyOptions,
                 merge_with: Sequence[ClosedLoopFrf], checks: list[Check],
                 notices: list[Notice], skipped: dict[str, str]) -> _RecordsFit:
    """The joint FRF, the current amplifiers and the Sercalo's fit (module notes, steps 2-4).

    The current amplifiers' checks are added to ``checks``, what was not done to
    ``skipped``; the warnings raised are caught and returned as notices.
    """
    nom = bench.nominal
    with pywarnings.catch_warnings(record=True) as caught:
        pywarnings.simplefilter("always")
        frf = closed_loop_frf(excited.records, estimator=options.frf,
                              transient_periods=options.transient_periods)
        if merge_with:
            frf = merge_closed_loop_frf([*merge_with, frf])
        gi, gi_how = _current_amplifiers(recordings, excited.starts, bench=bench, prior=prior,
                                         band_hz=options.current_amp_band_hz, checks=checks,
                                         notices=notices, skipped=skipped,
                                         calibrate=calibrate_current_amplifier)
        sid: SercaloIdentification | None = None
        try:
            sid = fit_sercalo(_from(frf.plant, options.fit_min_hz).to_frequency_response(),
                              gi_a_per_v=gi,
                              options=options.sercalo, sensor=SensorLowpass.from_params(nom))
        except ValueError as exc:
            skipped["sercalo"] = f"failed (data_cl_uch, data_cl_ucv): {exc}"
        if sid is not None and (lost := unassigned_modes(sid)):
            skipped["sercalo"] = f"failed (data_cl_uch, data_cl_ucv): {lost}"
            sid = None
    numeric = [Notice("numeric", "closed-loop identification",
                      f"{w.category.__name__}: {w.message}") for w in caught]
    return _RecordsFit(frf=frf, sercalo=sid, gi=gi, gi_how=gi_how, notices=numeric)


#: A fitted mode is an axis's when it lies within this fraction of the axis's peak (the
#: detected resonance): the lines are 0.25 Hz apart and a drift is a few per cent.
MODE_ASSIGNMENT_TOLERANCE = 0.05


def unassigned_modes(sid: SercaloIdentification) -> str:
    """Why an axis has no fitted mode near its own peak, in words ('' when each has one).

    The closed-loop fit once kept a single pole pair, the v mode's, with the h axis's peak
    at 411.25 Hz (twin seed 8, the refined stage alone: its sparse lines gave a phase-only
    delay 7 samples off): reporting the nearest mode would have put the h resonance at
    251 Hz (-39 %).
    """
    fitted = sid.fit.modes()
    problems = []
    for axis, inp in (("h", "Uch"), ("v", "Ucv")):
        peak = sid.resonances_hz.get(inp)
        if peak is None:
            continue
        near = min((m.resonance_hz for m in fitted), key=lambda f: abs(f - peak), default=None)
        if near is None or abs(near / peak - 1.0) > MODE_ASSIGNMENT_TOLERANCE:
            found = "no mode" if near is None else f"its nearest mode at {near:.2f} Hz"
            problems.append(f"the {axis} axis's peak is at {peak:.2f} Hz but the fit kept "
                            f"{found} (more than {100 * MODE_ASSIGNMENT_TOLERANCE:g} % away)")
    return "; ".join(problems)


def _from(est: FrfEstimate, f_min_hz: float) -> FrfEstimate:
    """``est`` on its lines at or above ``f_min_hz``."""
    keep = est.frequency_hz >= f_min_hz
    if keep.all():
        return est

    def cut(x: Any) -> Any:
        return None if x is None else x[keep]

    return dataclasses.replace(
        est, frequency_hz=est.frequency_hz[keep], frf=est.frf[keep],
        frf_variance=est.frf_variance[keep], output_noise_psd=est.output_noise_psd[keep],
        input_psd=est.input_psd[keep], snr=est.snr[keep], transient=cut(est.transient),
        distortion_variance=cut(est.distortion_variance))


def _current_amplifiers(recordings: Mapping[str, xr.Dataset], starts: Mapping[str, int], *,
                        bench: Bench, prior: PlantModel | None, band_hz: tuple[float, float],
                        checks: list[Check], notices: list[Notice], skipped: dict[str, str],
                        calibrate: Any) -> tuple[dict[str, float], str]:
    """``Gi`` per axis from the records' coil voltages, else the prior's, else nominal."""

    pairs = (("h", "data_cl_uch", "Vch"), ("v", "data_cl_ucv", "Vcv"))
    why = ""
    if all(sig in recordings[rec] for _a, rec, sig in pairs):
        failed = [c.sentence() for c in checks if not c.passed and c.subject.endswith(_COIL)]
        failed += [n.sentence() for n in notices
                   if n.kind == "saturation" and n.subject.endswith(_COIL)]
        if failed:
            why = failed[0]
        else:
            try:
                out = {}
                for axis, rec, _sig in pairs:
                    ds = recordings[rec]
                    t0 = float(ds["t"].values[starts[rec]])
                    g = calibrate(ds, axis=axis, nominal=bench.nominal, trim_s=t0,
                                  band_hz=band_hz)
                    found = current_amp_checks(g)
                    checks.extend(found)
                    if (bad := first_failure(found)) is not None:
                        raise ValueError(f"check {bad.name} failed: {bad.sentence()}")
                    out[axis] = float(g.gain_a_per_v)
                return out, "identified"
            except ValueError as exc:
                why = str(exc)
    else:
        why = "the records hold no coil voltages (Vch, Vcv)"
    if prior is not None:
        d = np.diag(np.asarray(prior.blocks["Gi"].D, dtype=float))
        skipped["current_amp"] = f"{why}: the previous identification's gains are used"
        return {"h": float(d[0]), "v": float(d[1])}, "prior"
    gi = bench.nominal.current_amp_gain_a_per_v()
    skipped["current_amp"] = f"{why}: the bench file's gains are used"
    return {"h": float(gi.h), "v": float(gi.v)}, "nominal"


def _assemble(sid: SercaloIdentification | None, *, bench: Bench, prior: PlantModel | None,
              gi: Mapping[str, float], gi_how: str, source: str
              ) -> tuple[PlantModel | None, dict[str, str]]:
    """The plant: ``Gc`` (and ``Gi``) from here, the rest from ``prior`` or the bench file."""
    if sid is None:
        return None, {}
    nom = bench.nominal
    gi_block = ct.ss([], [], [], np.diag([gi["h"], gi["v"]]), inputs=["Uch", "Ucv"],
                     outputs=["Ich", "Icv"], name="Gi") if gi_how != "nominal" \
        else current_amplifier(nom)
    blocks = {"Gi": gi_how, "Gc": "identified", "Zc": "nominal", "Ga": "nominal",
              "Gn": "prior" if prior is not None else "nominal",
              "Gd": "prior" if prior is not None else "nominal"}
    delays = dict(input_delays_s(nom) if prior is None else prior.input_delay_s)
    delays.update(Uch=sid.delay_s, Ucv=sid.delay_s)
    plant = assemble_plant(
        gi=gi_block, zc=coil_impedance(nom), ga=voltage_amplifier(nom), gc=sid.gc,
        gn=prior.blocks["Gn"] if prior is not None else newport(nom),
        gd=prior.blocks["Gd"] if prior is not None else quad_diode(nom),
        input_delay_s=delays, source=f"identified in closed loop ({source})")
    return plant, blocks


def write_closed_loop_identification(result: ClosedLoopIdentification,
                                     out_dir: str | Path) -> list[Path]:
    """Write ``identification.json``, ``plant.mat`` (when a plant was found) and ``frf.mat``
    (:func:`fsmbench.ident.export.write_identification_folder`)."""

    return write_identification_folder(
        out_dir, document=result.to_json(), plant=result.plant,
        frfs={"sercalo": result.frf.plant.to_frequency_response()})
