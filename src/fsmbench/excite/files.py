"""Excitation files: a MAT-file a real-time target plays and a JSON that describes it.

``<stem>.mat`` (MATLAB v5) holds two column vectors at the bench's sampling
rate: ``t`` [s] from 0 and the command under the ESRF study's signal name
(``Uch``, ``Ucv``, ``Unh`` or ``Unv``) [V]; transient periods first, then the
steady-state periods, nothing else. ``<stem>.json`` (format
``fsmbench.excitation`` version 1, :data:`EXCITATION_FORMAT`) says how it was
made and how to play and read it: kind, input, ``fs_hz``, samples per period,
periods and transient periods (an FRF estimator drops the first
``transient_periods``), what a player does after the end (``after_end``:
``zero`` or ``repeat`` the steady-state periods), rms, band, seed, crest
factors, the multisine's lines [Hz] and phases [rad] (and its lines on mains
harmonics, those skipped, the warning), the converter peaks and the 4QD's
beam angle and compression the limit check found, and the SHA-256 of the
samples, which ties the two files together. Both are written atomically.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from fsmbench.atomic import atomic_write_text
from fsmbench.excite.design import CHANNELS, ExcitationDesign
from fsmbench.excite.limits import LimitReport
from fsmbench.excite.mains import mains_hits, mains_warning
from fsmbench.io.errors import RecordingError
from fsmbench.io.matfile import load_mat
from fsmbench.io.matwrite import save_mat
from fsmbench.jsonutil import plain_json, stamped
from fsmbench.sim.excitation import samples_sha256
from fsmbench.version import __version__

__all__ = ["EXCITATION_FORMAT", "ExcitationFileError", "description", "find_description",
           "read_excitation", "write_excitation"]

#: Format name and version of the JSON description.
EXCITATION_FORMAT = ("fsmbench.excitation", 1)

# t is written as k / fs; a reader accepts rounding of a few ulps of the record's length.
_T_RTOL = 1e-12


class ExcitationFileError(ValueError):
    """An excitation file is missing, malformed or inconsistent; one line naming it."""

    def __init__(self, file: str | Path, problem: str) -> None:
        super().__init__(f"{file}: {problem}")


def description(design: ExcitationDesign, *, mat_file: str,
                limits: LimitReport | None = None) -> dict[str, Any]:
    """The JSON description of ``design`` (stamped with :data:`EXCITATION_FORMAT`)."""
    multisine = None
    if design.kind == "multisine":
        resolution = design.fs_hz / design.period_samples
        multisine = {
            "grid": design.grid, "log_grid": design.log_grid,
            "phase_method": design.phase_method, "resolution_hz": resolution,
            "line_amplitude_v": design.line_amplitude_v,
            "harmonics": np.rint(design.lines_hz / resolution).astype(int),
            "lines_hz": design.lines_hz, "phases_rad": design.phases_rad,
            "mains": {
                "mains_hz": design.mains_hz,
                "lines_on_harmonics_hz": design.lines_hz[mains_hits(
                    design.lines_hz, resolution_hz=resolution, mains_hz=design.mains_hz)],
                "skipped_lines_hz": list(design.skipped_lines_hz),
                "warning": mains_warning(design)},
        }
    payload = {
        "input": design.input, "kind": design.kind, "fs_hz": design.fs_hz,
        "n_samples": int(design.samples_v.size), "period_samples": design.period_samples,
        "period_s": design.period_s, "periods": design.periods,
        "transient_periods": design.transient_periods,
        "transient_s": design.transient_samples / design.fs_hz,
        "duration_s": design.duration_s, "after_end": design.after_end,
        "amplitude_rms_v": design.amplitude_rms_v, "band_hz": list(design.band_hz),
        "seed": design.seed, "crest_factor": design.crest_factor,
        "crest_factor_random_phase": design.crest_factor_random_phase,
        "multisine": multisine,
        "chirp": None if design.chirp_method is None else {"method": design.chirp_method},
        "mat_file": mat_file, "signals": {"t": "s", design.input: "V"},
        "samples_sha256": samples_sha256(design.samples_v),
        "limits": None if limits is None else {
            "model": limits.model,
            "slowest_time_constant_s": limits.slowest_time_constant_s,
            "peaks": [{"converter": c.converter, "signal": c.signal, "peak_v": c.peak_v,
                       "limit_v": c.limit_v} for c in limits.peaks],
            "quad_diode": {
                "nonlinearity_pct": limits.qd_nonlinearity_pct,
                "max_compression_pct": 100 * limits.max_qd_compression,
                "summary": limits.qd_line(),
                "channels": [{"signal": q.signal, "peak_v": q.peak_v, "rms_v": q.rms_v,
                              "beam_angle_peak_mrad": 1e3 * q.angle_rad,
                              "full_swing_v": q.full_swing_v,
                              "compression_at_peak_pct": 100 * q.compression,
                              "linear_gain_low_pct": 100 * q.gain_bias}
                             for q in limits.quad_diode]},
            "verdict": limits.verdict()},
        "fsmbench_version": __version__,
    }
    name, version = EXCITATION_FORMAT
    return stamped(plain_json(payload), format=name, version=version)


def write_excitation(design: ExcitationDesign, folder: str | Path, *, stem: str = "excitation",
                     limits: LimitReport | None = None) -> tuple[Path, Path]:
    """Write ``<folder>/<stem>.mat`` and ``<folder>/<stem>.json``; returns both paths.

    Parameters
    ----------
    design : ExcitationDesign
    folder : str or Path
        Existing folder.
    stem : str
        File name without suffix.
    limits : LimitReport, optional
        The converter peaks found, recorded in the JSON.
    """
    folder = Path(folder)
    mat = folder / f"{stem}.mat"
    js = folder / f"{stem}.json"
    n = design.samples_v.size
    save_mat(mat, {"t": np.arange(n) / design.fs_hz, design.input: design.samples_v})
    atomic_write_text(js, json.dumps(description(design, mat_file=mat.name, limits=limits),
                                     indent=2, allow_nan=False) + "\n")
    return mat, js


def find_description(path: str | Path) -> Path:
    """The JSON description for a folder, a ``.json`` or a ``.mat`` path.

    A folder must hold exactly one ``fsmbench.excitation`` JSON; a ``.mat``
    is described by the ``.json`` of the same stem.
    """
    p = Path(path)
    if p.is_dir():
        found = [q for q in sorted(p.glob("*.json")) if _is_description(q)]
        if len(found) != 1:
            raise ExcitationFileError(p, f"holds {len(found)} excitation descriptions "
                                         "(fsmbench.excitation JSON); name the file")
        return found[0]
    if p.suffix.lower() == ".mat":
        p = p.with_suffix(".json")
    if not p.is_file():
        raise ExcitationFileError(p, "no such excitation description")
    return p


def _is_description(p: Path) -> bool:
    try:
        return json.loads(p.read_text("utf-8")).get("format") == EXCITATION_FORMAT[0]
    except (OSError, ValueError, AttributeError):
        return False


def _get(meta: dict[str, Any], key: str, kind: type | tuple[type, ...], js: Path) -> Any:
    if key not in meta:
        raise ExcitationFileError(js, f"has no {key!r}")
    value = meta[key]
    if (isinstance(value, bool) and kind is not bool) or not isinstance(value, kind):
        raise ExcitationFileError(js, f"{key!r} is {value!r}, not a valid value")
    if isinstance(value, float) and not math.isfinite(value):
        raise ExcitationFileError(js, f"{key!r} is not finite")
    return value


def _mains_fields(ms: dict[str, Any], js: Path) -> dict[str, Any]:
    """``mains_hz`` and ``skipped_lines_hz`` of a multisine (absent in older files: none)."""
    mains = ms.get("mains")
    if mains is None:
        return {}
    if not isinstance(mains, dict):
        raise ExcitationFileError(js, f"'mains' is {mains!r}, not a valid value")
    skipped = _get(mains, "skipped_lines_hz", list, js)
    if not all(isinstance(f, (int, float)) and not isinstance(f, bool) for f in skipped):
        raise ExcitationFileError(js, "'skipped_lines_hz' is not a list of frequencies [Hz]")
    return {"mains_hz": float(_get(mains, "mains_hz", (int, float), js)),
            "skipped_lines_hz": tuple(float(f) for f in skipped)}


def _read_description(js: Path) -> dict[str, Any]:
    """The JSON description at ``js``, checked to be an excitation of this format's version."""
    try:
        meta = json.loads(js.read_text("utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ExcitationFileError(js, f"is not a readable JSON file ({exc})") from None
    if not isinstance(meta, dict) or meta.get("format") != EXCITATION_FORMAT[0]:
        raise ExcitationFileError(js, f"is not an excitation description (format "
                                      f"{EXCITATION_FORMAT[0]!r} expected)")
    if meta.get("format_version") != EXCITATION_FORMAT[1]:
        raise ExcitationFileError(js, f"has format version {meta.get('format_version')!r}; "
                                      f"this fsmbench reads version {EXCITATION_FORMAT[1]}")
    return meta


def _read_samples(meta: dict[str, Any], js: Path, *, inp: str, n: int,
                  fs_hz: float) -> np.ndarray:
    """The samples of ``inp`` [V] from the MAT-file the description names, as described.

    Parameters
    ----------
    meta : dict
        The JSON description, read from ``js``.
    js : Path
        Its path (the MAT-file's name is relative to its folder).
    inp : str
        The excited DAC channel.
    n : int
        Number of samples described.
    fs_hz : float
        Sampling rate described [Hz]: ``t`` must be ``k / fs_hz``.
    """
    mat = js.parent / _get(meta, "mat_file", str, js)
    try:
        data = load_mat(mat, variables=["t", inp])
    except (RecordingError, OSError) as exc:
        raise ExcitationFileError(mat, f"cannot be read as the excitation's MAT-file "
                                       f"({exc})") from None
    t = np.asarray(data["t"], dtype=float)
    x = np.asarray(data[inp], dtype=float)
    if t.size != n or x.size != n or max(t.ndim, x.ndim) > 2 or 1 not in x.shape:
        raise ExcitationFileError(mat, f"{inp} and t must be vectors of the {n} samples the "
                                       f"description gives, got shapes {x.shape} and {t.shape}")
    t, x = t.ravel(), x.ravel()
    if not np.allclose(t, np.arange(n) / fs_hz, rtol=0, atol=_T_RTOL * max(n / fs_hz, 1.0)):
        raise ExcitationFileError(mat, f"t is not 0, 1/{fs_hz:g} Hz, ... as described")
    if samples_sha256(x) != meta.get("samples_sha256"):
        raise ExcitationFileError(mat, f"{inp} is not the signal {js.name} describes "
                                       "(SHA-256 differs)")
    return x


def _kind_fields(meta: dict[str, Any], js: Path, *, kind: str) -> dict[str, Any]:
    """The design's fields that depend on its kind, as keyword arguments.

    A multisine's lines [Hz] and phases [rad] (empty for the other kinds),
    grid, phase method, line amplitude [V], mains and random-phase crest
    factor; a chirp's method.
    """
    number = (int, float)
    ms = meta.get("multisine")
    lines = np.zeros(0)
    phases = np.zeros(0)
    extra: dict[str, Any] = {}
    if kind == "multisine":
        if not isinstance(ms, dict):
            raise ExcitationFileError(js, "a multisine needs its 'multisine' lines and phases")
        lines = np.asarray(_get(ms, "lines_hz", list, js), dtype=float)
        phases = np.asarray(_get(ms, "phases_rad", list, js), dtype=float)
        if lines.shape != phases.shape or lines.size == 0:
            raise ExcitationFileError(js, f"{lines.size} lines but {phases.size} phases")
        extra = {"grid": _get(ms, "grid", str, js), "log_grid": _get(ms, "log_grid", bool, js),
                 "phase_method": _get(ms, "phase_method", str, js),
                 "line_amplitude_v": float(_get(ms, "line_amplitude_v", number, js)),
                 **_mains_fields(ms, js),
                 "crest_factor_random_phase": float(_get(meta, "crest_factor_random_phase",
                                                         number, js))}
    chirp = meta.get("chirp")
    if kind == "chirp":
        extra["chirp_method"] = _get(chirp if isinstance(chirp, dict) else {}, "method", str, js)
    return {"lines_hz": lines, "phases_rad": phases, **extra}


def read_excitation(path: str | Path) -> ExcitationDesign:
    """Load and validate an excitation: folder, ``.json`` or ``.mat`` (:func:`find_description`).

    Returns
    -------
    ExcitationDesign
        As designed: the samples from the MAT-file, the rest from the JSON.

    Raises
    ------
    ExcitationFileError
        One line naming the file and the problem: unreadable, wrong format or
        version, missing or invalid keys, a MAT-file without ``t`` or the
        input, lengths or time step not as described, or samples that are not
        the ones described (SHA-256).
    """
    js = find_description(path)
    meta = _read_description(js)
    number = (int, float)
    inp = _get(meta, "input", str, js)
    if inp not in CHANNELS:
        raise ExcitationFileError(js, f"input {inp!r} is not a DAC channel "
                                      f"({', '.join(CHANNELS)})")
    kind = _get(meta, "kind", str, js)
    if kind not in ("multisine", "noise", "chirp"):
        raise ExcitationFileError(js, f"unknown kind {kind!r}")
    fs = float(_get(meta, "fs_hz", number, js))
    n = _get(meta, "n_samples", int, js)
    per = _get(meta, "period_samples", int, js)
    periods = _get(meta, "periods", int, js)
    transient = _get(meta, "transient_periods", int, js)
    if fs <= 0 or per < 1 or periods < 1 or transient < 0 or n != per * (periods + transient):
        raise ExcitationFileError(js, f"{n} samples are not {periods} + {transient} periods of "
                                      f"{per} samples at {fs:g} Hz")
    after_end = _get(meta, "after_end", str, js)
    if after_end not in ("zero", "repeat"):
        raise ExcitationFileError(js, f"after_end {after_end!r} is not 'zero' or 'repeat'")
    x = _read_samples(meta, js, inp=inp, n=n, fs_hz=fs)
    band = _get(meta, "band_hz", list, js)
    if len(band) != 2 or not all(isinstance(b, number) for b in band):
        raise ExcitationFileError(js, f"band_hz {band!r} is not a pair of frequencies [Hz]")
    fields = _kind_fields(meta, js, kind=kind)
    return ExcitationDesign(
        input=inp, kind=kind, fs_hz=fs, samples_v=x, period_samples=per, periods=periods,
        transient_periods=transient,
        amplitude_rms_v=float(_get(meta, "amplitude_rms_v", number, js)),
        band_hz=(float(band[0]), float(band[1])), seed=_get(meta, "seed", int, js),
        crest_factor=float(_get(meta, "crest_factor", number, js)), after_end=after_end,
        **fields)
