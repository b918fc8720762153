"""Recordings checked against each other and against the physical model, after identification.

Each identification step checks its own records (r², coherence, ranges). Data
that read fine but are wrong (a 4QD gain changed between runs, a channel scaled
×40 and clipped, a unit slip on one file) pass those checks and give absurd
numbers. These checks compare what different records say about the same
quantity, and what was identified against the bench file's physics:

``qd_gain_newport_vs_calibration``
    Records against records. The Newport run sees the 4QD through
    ``Gn(0) = Gd · Mn · gn``: with the calibration's ``Gd`` (data_cal_pd_*), the
    bench's beam factor ``Mn`` (2, the two reflections) and the Newport's drive
    gain ``gn`` *measured* in ``data_rep_h/v`` (its metrology ``Vn`` against its
    command ``Un`` in the 1 Hz sine, :func:`newport_drive_gains`), the ratio
    ``Gn(0) / (Gd Mn gn)`` is 1. Accepted 0.8–1.25: the gains' own errors are ~1 %
    each, and a gain or unit change between runs (×10 → 10) is far outside.
    Without ``data_rep`` there is no second measurement of ``gn``: the Newport's
    gain is then a finding against the bench file, not a check.
``sercalo_gain_vs_model`` / ``newport_gain_vs_model``
    The static gains against the bench file's physical model (``Gc(0) = Gd · 4 ·
    g0`` with the datasheet's ``g0`` and the *calibrated* ``Gd``, so that each device
    is judged on its own; ``Gn(0)`` likewise), within a factor 10 in
    magnitude and of the model's sign (the model carries the signs the records
    gave, ident.evidence): the bench file is a prior, a mirror or a Newport a few
    times off it is a bench (a finding, ident.evidence.departures); a clipped ×40
    channel (2989 V/A for 80 V/A) is beyond a plausible bench.
``noise_floor_across_files``
    The same sensor's white floor (the 4QD outputs' PSD, median over 2–4.5 kHz,
    where the loop and the slow motions leave only noise) in every record that
    does not excite that channel, against the median of the records: within a
    factor 3 in amplitude (≈ 10 dB). On the twin of four benches every record
    is within 2 % of the median (the Newport runs' driven channel 1.5–1.9×, so
    driven channels are left out); one sensor's floor cannot move 10 dB between
    runs of a session unless its gain or its unit did.
``qd_noise_vs_model``, ``newport_noise_vs_datasheet``, ``attocube_noise_vs_model``
    The noise model fitted to the huddle tests against the bench file's levels,
    within a factor 10 (20 dB): an amplifier a few times noisier than its
    datasheet is a bench, a factor 10 is a unit or a wrong channel.

A failed gain check is also a *warning* of the identification, so its plant is
not trusted (``stages.choose_plant`` falls back, the verdict's control rows are
not verified) and its values are not reported as found. A failed noise check
drops the noise model (:data:`NOISE_CHECKS`): simulations use the bench file's
noise, marked assumed.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import replace
from typing import Any

import numpy as np
from scipy.signal import welch

from fsmbench.bench.blocks import newport_beam_matrix, physical_plant
from fsmbench.bench.params import BenchParams
from fsmbench.checks import Check

__all__ = ["FLOOR_FACTOR", "GAIN_FACTOR", "NEWPORT_CALIBRATION_BAND", "NOISE_CHECKS",
           "NOISE_FACTOR", "cross_checks", "floor_checks", "newport_drive_gains"]

#: The identified static gains against the bench file's model: a factor 10, same sign (the
#: bench file is a prior: within it, a departure is a finding, ident.evidence.departures).
GAIN_FACTOR = 10.0
#: ``Gn(0) / (Gd Mn gn)``, the Newport run's 4QD gain against the calibration's.
NEWPORT_CALIBRATION_BAND = (0.8, 1.25)
#: The fitted noise levels against the bench file's.
NOISE_FACTOR = 10.0
#: One sensor's white floor across the records, in amplitude.
FLOOR_FACTOR = 3.0
#: Band of the floor [Hz] (at 10 kHz; scaled with the rate): above the loop's crossovers
#: and the Newport's motion, below the Nyquist bin.
_FLOOR_BAND = (0.2, 0.45)
#: The channel each excitation experiment drives (its floor may be the excitation's).
_DRIVEN = {"data_uch": "Vph", "data_ucv": "Vpv", "data_unh": "Vph", "data_unv": "Vpv"}

#: The checks of the noise model (a failed one drops it, not the plant).
NOISE_CHECKS = ("qd_noise_vs_model", "newport_noise_vs_datasheet", "attocube_noise_vs_model")

_NEWPORT_RUN = {"h": ("data_unh", "Vph"), "v": ("data_unv", "Vpv")}
_SERCALO_RUN = {"h": ("data_uch", "Vph"), "v": ("data_ucv", "Vpv")}


def _cause(ratio: float, *, between: str) -> str:
    """Every cause that fits a ratio, in words (``between``: what the ratio compares).

    A round factor (10, 1000, 10⁶) fits a gain or unit slip, and as well a device
    or a noise that much larger: the ratio alone never separates them, so both are
    named and no change of the data is advised.
    """
    if not np.isfinite(ratio) or ratio == 0:
        return ("either a missing or dead channel, or a noise hidden under a wrong reference "
                f"({between})")
    if ratio < 0:
        return (f"either a sign of the channel or its cable, or of the device itself "
                f"({between})")
    for factor, words in ((1e3, "a unit (mV for V, or mm for m)"),
                          (1e6, "a unit (µV for V, or µm for m)"),
                          (10.0, "a gain changed by 10 (an amplifier range)")):
        for f, way in ((factor, "larger"), (1 / factor, "smaller")):
            if abs(np.log10(ratio / f)) < 0.1:  # within 26 % of the round factor
                return (f"either {words}, or a device or a noise that much {way} than the "
                        f"reference ({between}); the ratio alone cannot tell which")
    return f"a gain or a channel that changed, or a device not the bench file's ({between})"


def _ratio_check(name: str, ratio: float, band: tuple[float, float], subject: str,
                 what: str, *, between: str) -> Check:
    ok = bool(np.isfinite(ratio) and band[0] <= ratio <= band[1])
    advice = "" if ok else f"{what} (ratio {ratio:.3g}): {_cause(ratio, between=between)}"
    return Check(name, ok, float(ratio), f"{band[0]:g} to {band[1]:g}", subject, advice,
                 unit="×")


def newport_drive_gains(recordings: Mapping[str, Any], *, params: BenchParams
                        ) -> dict[str, float]:
    """The Newport's drive gain ``gn`` [rad/V] per axis measured in ``data_rep_h/v``.

    The repeatability runs drive the Newport with a 1 Hz sine on ``Un`` and record its
    metrology ``Vn``: at 1 Hz, three decades under its ~1 kHz bandwidth, the slope of
    ``Vn`` on ``Un`` times the metrology gain (and its sign) is the static drive gain.
    An axis whose record is absent, or whose ``Vn`` does not follow ``Un`` (r² < 0.9),
    is left out.
    """
    out = {}
    for axis in "hv":
        ds = recordings.get(f"data_rep_{axis}")
        un, vn = f"Un{axis}", f"Vn{axis}"
        if ds is None or un not in ds or vn not in ds:
            continue
        u = np.asarray(ds[un].values, dtype=float)
        v = np.asarray(ds[vn].values, dtype=float)
        if u.size != v.size or u.size < 3 or np.ptp(u) == 0 or np.ptp(v) == 0:
            continue
        r = np.corrcoef(u, v)[0, 1]
        if not np.isfinite(r) or r * r < 0.9:
            continue
        slope = float(np.polyfit(u, v, 1)[0])
        out[axis] = (slope * params.newport.metrology_gain_rad_per_v
                     * params.newport.metrology_sign[axis])
    return out


def cross_checks(js: Mapping[str, Any], *, params: BenchParams,
                 newport_drive_rad_per_v: Mapping[str, float] | None = None) -> list[Check]:
    """The cross-checks of one identification (see the module notes).

    Parameters
    ----------
    js : mapping
        ``Identification.to_json()``: ``qd_gain_v_per_rad``, ``sercalo``,
        ``newport_gain_v_per_v`` where identified.
    params : BenchParams
        The bench file's nominal parameters (with the signs the records gave).
    newport_drive_rad_per_v : mapping of axis to float, optional
        The Newport's drive gain measured in ``data_rep_h/v``
        (:func:`newport_drive_gains`); without it the Newport run is not checked
        against the calibration.

    Returns
    -------
    list of Check
        Only the checks whose inputs were identified.
    """
    out: list[Check] = []
    nominal = physical_plant(params, source="nominal")
    qd = js.get("qd_gain_v_per_rad") or {}
    mn = newport_beam_matrix(params)
    for i, axis in enumerate("hv"):
        gn = js.get("newport_gain_v_per_v", {}).get(axis)
        exp, vp = _NEWPORT_RUN[axis]
        drive = (newport_drive_rad_per_v or {}).get(axis)
        if gn is not None and axis in qd and drive is not None:
            expected = qd[axis] * mn[i, i] * drive
            ratio = gn / expected
            out.append(_ratio_check(
                "qd_gain_newport_vs_calibration", ratio, NEWPORT_CALIBRATION_BAND,
                f"{exp}.mat: {vp}",
                f"the Newport run gives {gn:.4g} V/V where the calibration's 4QD gain "
                f"({qd[axis]:.4g} V/rad, data_cal_pd_{axis}) and the Newport's drive gain "
                f"measured in data_rep_{axis} ({drive:.4g} rad/V) predict {expected:.4g} V/V",
                between="the Newport run against the calibration and the repeatability run"))
        # Each device against the bench file on its own: the path's gain over the 4QD gain
        # the calibration measured (a 4QD 5x the bench file's is its own finding, not the
        # Newport's or the Sercalo's).
        gd_model = params.quad_diode.gain_v_per_rad[axis]
        per_gd = (qd[axis] / gd_model) if axis in qd else 1.0
        if gn is not None:
            model = nominal.dc_gain(output=vp, input=exp.split("_")[1].capitalize())
            out.append(_ratio_check(
                "newport_gain_vs_model", gn / model / per_gd, (1 / GAIN_FACTOR, GAIN_FACTOR),
                f"{exp}.mat: {vp}",
                f"the Newport's static gain {gn:.4g} V/V against the bench file's model "
                f"{model * per_gd:.4g} V/V (with the calibrated 4QD gain)",
                between="the Newport run against the bench file"))
        ser = (js.get("sercalo") or {}).get(axis)
        if ser is not None:
            exp, vp = _SERCALO_RUN[axis]
            model = float(np.real(nominal.blocks["Gc"].dcgain()[i, i])) * per_gd
            gain = float(ser["dc_gain_v_per_a"])
            out.append(_ratio_check(
                "sercalo_gain_vs_model", gain / model, (1 / GAIN_FACTOR, GAIN_FACTOR),
                f"{exp}.mat: {vp}",
                f"the Sercalo's static gain {gain:.4g} V/A against the bench file's model "
                f"{model:.4g} V/A (with the calibrated 4QD gain)",
                between="the Sercalo run against the bench file"))
    out += _noise_checks(js.get("noise_model"), params)
    return out


def _noise_checks(noise: Any, params: BenchParams) -> list[Check]:
    if not isinstance(noise, Mapping) or not noise.get("tests"):
        return []
    band = (1 / NOISE_FACTOR, NOISE_FACTOR)
    tests = ", ".join(noise["tests"])
    out = []
    sig = noise.get("newport_noise_rad") or {}
    # A Newport angle noise measured far above its datasheet through the 4QD–Va
    # cross-spectrum takes the 4QD's own noise with it: the slip is then Va's scale
    # (mm for m …), not the 4QD; say so where the 4QD's fitted noise collapses.
    newport_ratio = (float(sig["value"]) / params.newport.angle_noise_rms_rad
                     if sig.get("significant") and params.newport.angle_noise_rms_rad > 0
                     else 1.0)
    for axis, vp in (("h", "Vph"), ("v", "Vpv")):
        if not noise["noise_rms_v"][axis].get("significant", True):
            continue  # not separated from the Newport's noise: no value to check
        fitted = float(noise["noise_rms_v"][axis]["value"])
        model = params.quad_diode.noise_rms_v[axis]
        check = _ratio_check(
            "qd_noise_vs_model", fitted / model, band, f"{tests}: {vp}",
            f"the 4QD's fitted white noise {fitted * 1e3:.4g} mV rms against the bench file's "
            f"{model * 1e3:.3g} mV", between="the huddle tests against the bench file")
        if not check.passed and fitted < model / NOISE_FACTOR and newport_ratio > NOISE_FACTOR:
            check = replace(check, advice=(
                f"{check.advice.split(': ')[0]}: the Newport's angle noise measured through "
                f"Va is {newport_ratio:.3g}× its datasheet's and leaves the 4QD none of its "
                "own: either Va's unit (mm or µm for m), or an interferometer and a Newport "
                "that much noisier; the records cannot tell which"))
        out.append(check)
    if sig.get("significant"):
        value, model = float(sig["value"]), params.newport.angle_noise_rms_rad
        out.append(_ratio_check(
            "newport_noise_vs_datasheet", value / model, band, f"{tests}: Vph, Vpv, Va",
            f"the Newport angle noise from the 4QD–Va cross-spectrum, {value * 1e6:.4g} µrad "
            f"rms, against the datasheet's {model * 1e6:.3g} µrad",
            between="the huddle tests against the datasheet"))
    att = (noise.get("attocube_noise_rms_m") or {}).get("value")
    if att and params.attocube.noise_rms_m > 0:
        out.append(_ratio_check(
            "attocube_noise_vs_model", float(att) / params.attocube.noise_rms_m, band,
            f"{tests}: Va", f"the Attocube's fitted floor {float(att) * 1e9:.4g} nm rms against "
            f"the bench file's {params.attocube.noise_rms_m * 1e9:.3g} nm",
            between="the huddle tests against the bench file"))
    return out


def floor_checks(recordings: Mapping[str, Any], *, fs_hz: float) -> list[Check]:
    """``noise_floor_across_files``: each 4QD channel's floor against the records' median.

    Parameters
    ----------
    recordings : mapping of str to xarray.Dataset
        Every record read (``Vph``, ``Vpv`` where present); the first 10 s of each
        after 1 s are used.
    fs_hz : float
        The bench's sampling rate [Hz].
    """
    n_fs = round(fs_hz)
    floors: dict[str, dict[str, float]] = {"Vph": {}, "Vpv": {}}
    for name, ds in recordings.items():
        for ch in floors:
            if ch not in ds or _DRIVEN.get(name) == ch:
                continue
            x = np.asarray(ds[ch].values[n_fs:11 * n_fs], dtype=float)
            if x.size < n_fs or not np.all(np.isfinite(x)) or np.ptp(x) == 0:
                continue
            f, p = welch(x - x.mean(), fs=fs_hz, nperseg=n_fs)
            band = (f >= _FLOOR_BAND[0] * fs_hz) & (f <= _FLOOR_BAND[1] * fs_hz)
            floors[ch][name] = float(np.sqrt(np.median(p[band])))
    out: list[Check] = []
    for ch, by_file in floors.items():
        if len(by_file) < 3:  # a median of fewer records is no reference
            continue
        ref = float(np.median(list(by_file.values())))
        for name, value in by_file.items():
            ratio = value / ref if ref > 0 else math.inf
            out.append(_ratio_check(
                "noise_floor_across_files", ratio, (1 / FLOOR_FACTOR, FLOOR_FACTOR),
                f"{name}.mat: {ch}",
                f"its white floor {value * 1e6:.3g} µV/√Hz against {ref * 1e6:.3g} µV/√Hz, the "
                f"median of the {len(by_file)} records with {ch}",
                between=f"{name} against the other records"))
    return out
