"""A folder of recordings in the ESRF study's layout, read as one set, and its plausibility checks.

:func:`load_recordings` reads every seed experiment a folder holds and says,
for every experiment it does not use, why; what a user should know about the
files it did use (saturation, dropped variables …) comes back as
:class:`~fsmbench.checks.Notice` records and plausibility verdicts as
:class:`~fsmbench.checks.Check` records, never as Python warnings. A folder
with no usable recording is a :class:`~fsmbench.io.errors.RecordingError`
saying what was looked for, what was found and which file names nearly match
(files failing in the same way named together, in one line). An experiment in
two files (``data_uch.mat`` beside ``data_uch.h5``) is read from the first of
``.mat``, ``.h5``, ``.nxs`` and refused unless the others hold the same samples
(:mod:`fsmbench.io.duplicates`).

:func:`check_recording` is the plausibility test of one recording against
what the bench can produce; the stages run it too, so that a recording that
fails it is skipped *with the check's name as the reason*:

``sampling_rate``     rate from ``t`` within 1 % of the bench's (``t`` in seconds)
``integer_samples``   no signal stored as integers (raw converter counts)
``converter_range``   ADC/DAC signals within the converter's ±range/2
``signal_varies``     measured signals and the excitation are not constant
``va_in_metres``      the Attocube distance varies by ≤ 1 mm rms (it is in m, not nm);
                      the advice names the unit that makes the rms the experiment's own
``va_continuous``     ``Va`` of a huddle or repeatability record has no single-sample step
                      above 10 robust standard deviations of its increments (fringe loss:
                      :mod:`fsmbench.io.va_jumps`), the sample, time and size named
``channels_distinct``, ``signal_clipped``, ``signal_frozen``, ``record_padded``
                      what a channel's own samples say about it: recorded twice,
                      clipped, frozen for a stretch, zeros after the record's end
                      (:mod:`fsmbench.io.channels`)

A name that is there but is not a readable file (a directory, a symbolic link
that loops or points nowhere) is named as what it is, not as missing.
"""

from __future__ import annotations

import math
import os
import warnings
import weakref
from collections.abc import Callable, Collection, Hashable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

import h5py
import numpy as np
import xarray as xr

from fsmbench.checks import Check, Notice
from fsmbench.io import matfile
from fsmbench.io.channels import clipped_signals, copied_channels, frozen_segments
from fsmbench.io.duplicates import compare_files, other_files
from fsmbench.io.errors import RecordingError, SaturationWarning
from fsmbench.io.folder_names import folder_hints, not_a_file
from fsmbench.io.lazy import open_recording, v5_vectors
from fsmbench.io.matfile import detect_format
from fsmbench.io.notes import FILE_CHOICE, READ_NOTES, TIME_JITTER
from fsmbench.io.recording import find_experiments, read_recording
from fsmbench.io.signals import ADC_SIGNALS, DAC_SIGNALS, EXPERIMENTS, MIN_DURATION_S, SIGNALS, TIME
from fsmbench.io.trailing import TrailingBytesWarning, data_end
from fsmbench.io.va_jumps import jump_check, va_unit_hint

__all__ = [
    "EXCITATION",
    "MAX_VA_RMS_M",
    "RATE_TOLERANCE",
    "RecordingSet",
    "check_recording",
    "folder_hints",
    "load_recordings",
    "not_a_file",
    "sample_bytes",
]

#: Relative tolerance of the sampling-rate check: a clock off by more than 1 %
#: is another rate (or ``t`` in another unit), not a crystal's ppm error.
RATE_TOLERANCE: Final = 0.01
#: Largest plausible rms of the Attocube distance variation [m]. The bench's Va
#: moves by nm (huddle) to µm (repeatability steps); 1 mm rms is 1000× the
#: largest motion the bench makes, so a larger value is not metres (nm saved?).
MAX_VA_RMS_M: Final = 1e-3
#: The signal each experiment drives (or sweeps): it must not be constant.
EXCITATION: Final[dict[str, str]] = {
    "data_cal_pd_h": "Vnh", "data_cal_pd_v": "Vnv", "data_uch": "Uch", "data_ucv": "Ucv",
    "data_unh": "Unh", "data_unv": "Unv", "data_rep_h": "Unh", "data_rep_v": "Unv",
}


@dataclass(frozen=True, eq=False)
class RecordingSet:
    """The recordings of one folder and what was found about them.

    Attributes
    ----------
    folder : str
    recordings : dict of str to xarray.Dataset
        Experiment name to recording, in the ESRF study's order (also those that
        fail a check: the stage that needs them skips them, naming the check).
    skipped : dict of str to str
        Experiment name to the reason it is not used (missing file, with
        near-miss hints, or the problem naming file, variable and problem).
    notices : tuple of Notice
        Non-fatal findings (saturation, dropped variables, data types, rates).
    checks : tuple of Check
        Plausibility checks run on the recordings (see :func:`check_recording`).
    """

    folder: str
    recordings: dict[str, xr.Dataset]
    skipped: dict[str, str] = field(default_factory=dict)
    notices: tuple[Notice, ...] = ()
    checks: tuple[Check, ...] = ()

    def unusable(self) -> dict[str, str]:
        """The skipped experiments whose file was there (unreadable, malformed) or nearly
        so (a near-miss name): those a step must not call "missing"."""
        return {name: why for name, why in self.skipped.items()
                if not (why.startswith(f"no {name}.mat") and "; found " not in why)}

    def to_json(self) -> dict[str, Any]:
        """JSON-ready summary (no arrays)."""
        return {"folder": self.folder, "experiments": list(self.recordings),
                "skipped": dict(self.skipped),
                "notices": [n.to_json() for n in self.notices],
                "checks": [c.to_json() for c in self.checks]}


# --------------------------------------------------------------------------- checks
def _label(ds: xr.Dataset, name: str | None) -> str:
    source = str(ds.attrs.get("source", "") or "")
    return os.path.basename(source) if source else (name or str(ds.attrs.get("experiment",
                                                                              "recording")))


def _rate_check(ds: xr.Dataset, label: str, fs_hz: float) -> Check:
    fs = float(ds.attrs.get("fs_hz", math.nan))
    ratio = fs / fs_hz
    ok = math.isfinite(ratio) and abs(ratio - 1.0) <= RATE_TOLERANCE
    advice = ""
    if not ok:
        if abs(ratio * 1e3 - 1.0) <= RATE_TOLERANCE:
            advice = ("t looks like milliseconds (the rate reads 1000× too low): save t in "
                      "seconds (t = t/1000)")
        elif abs(ratio * 1e-3 - 1.0) <= RATE_TOLERANCE:
            advice = "t looks like kiloseconds (1000× too high): save t in seconds"
        elif abs(ratio * 1e6 - 1.0) <= RATE_TOLERANCE:
            advice = "t looks like microseconds: save t in seconds (t = t*1e-6)"
        else:
            advice = (f"the bench runs at {fs_hz:g} Hz; record at that rate, or set "
                      f"converter.fs_hz = {fs:g} in the bench parameters if the bench did "
                      "run at this rate")
    return Check("sampling_rate", ok, fs, f"within {100 * RATE_TOLERANCE:g} % of the bench's "
                 f"{fs_hz:g} Hz", f"{label}: t", advice, unit="Hz")


def _stored_dtype(var: xr.DataArray) -> np.dtype[Any]:
    return np.dtype(var.attrs.get("stored_dtype", var.dtype))


class _NonFiniteError(Exception):
    """A lazily read signal holds NaN or Inf (count, first index)."""


def _signal_stats(x: Any, rail: float) -> tuple[float, int, float, float, float]:
    """(peak |x|, samples at or beyond ±rail, max |x − mean|, rms of x − mean, x[0]).

    In memory as the checks always computed them; out of core (Dask) in one
    pass over the record, memory bounded by a chunk.
    """
    if not type(x).__module__.startswith("dask"):
        x = np.asarray(x, dtype=np.float64)
        with np.errstate(all="ignore"):
            peak = float(np.max(np.abs(x))) if x.size else 0.0
            at_rails = int(np.count_nonzero(np.abs(x) >= rail))
        spread, rms = _finite_rms(x)
        return peak, at_rails, spread, rms, float(x[0]) if x.size else math.nan
    import dask
    import dask.array as da

    # One pass: moments about the first sample (no cancellation for offsets large
    # against the noise), extremes, the samples on the rails and the non-finite ones.
    first = float(x[0].compute())
    y = x - first
    with np.errstate(all="ignore"):
        peak, at_rails, lo, hi, s1, s2, bad = dask.compute(
            da.max(da.abs(x)), da.count_nonzero(da.abs(x) >= rail), da.min(y), da.max(y),
            da.sum(y), da.sum(y * y), da.count_nonzero(~da.isfinite(x)))
    if int(bad):
        index = int(da.argmax(~da.isfinite(x)).compute())
        raise _NonFiniteError(int(bad), index)
    n = int(x.shape[0])
    if not math.isfinite(float(peak)) or float(peak) == 0.0:
        return float(peak), int(at_rails), float(peak), float(peak), first
    mean_y = float(s1) / n
    spread = max(float(hi) - mean_y, mean_y - float(lo))
    rms = math.sqrt(max(float(s2) / n - mean_y * mean_y, 0.0))
    return float(peak), int(at_rails), spread, rms, first


def _finite_rms(x: np.ndarray) -> tuple[float, float]:
    """(max |x − mean|, rms of x − mean) without overflow for huge values."""
    with np.errstate(all="ignore"):
        scale = float(np.max(np.abs(x))) if x.size else 0.0
        if not math.isfinite(scale) or scale == 0.0:
            return scale, scale
        y = x / scale
        y = y - y.mean()
        return scale * float(np.max(np.abs(y))), scale * float(np.sqrt(np.mean(y * y)))


# Checks of records read out of core, by dataset identity: a pass over a day-long
# record takes minutes, and the loader and the budget check the same record.
_LAZY_CHECKED: dict[tuple[Any, ...], tuple[list[Check], list[Notice]]] = {}


def check_recording(ds: xr.Dataset, *, name: str | None = None, fs_hz: float | None = None,
                    adc_range_v: float = 20.0, adc_bits: int = 16
                    ) -> tuple[list[Check], list[Notice]]:
    """Plausibility checks of one recording against what the bench can produce.

    Parameters
    ----------
    ds : xarray.Dataset
        A recording (:func:`~fsmbench.io.recording.read_recording`), N samples.
    name : str, optional
        Experiment name; default the ``experiment`` attribute.
    fs_hz : float, optional
        The bench's sampling rate [Hz]; None accepts any rate (no rate check).
    adc_range_v : float
        Full span of the ADC and DAC [V] (±10 V: 20 V).
    adc_bits : int
        Converter resolution [bit].

    Returns
    -------
    (list of Check, list of Notice)
        Checks in the order of the module docstring (only those that apply),
        and notices: saturation at the ADC rails, single-precision ``t``, and what
        reading the file found (:mod:`fsmbench.io.notes`: bytes after the data, the file
        read of two, ``t``'s clock jitter).
    """
    lazy = any(type(v.data).__module__.startswith("dask") for v in ds.data_vars.values())
    key = (id(ds), name, fs_hz, adc_range_v, adc_bits)
    if lazy and key in _LAZY_CHECKED:
        found, notes = _LAZY_CHECKED[key]
        return list(found), list(notes)
    result = _check_recording(ds, name=name, fs_hz=fs_hz, adc_range_v=adc_range_v,
                              adc_bits=adc_bits)
    if lazy:
        _LAZY_CHECKED[key] = result
        weakref.finalize(ds, _LAZY_CHECKED.pop, key, None)
    return list(result[0]), list(result[1])


def _check_recording(ds: xr.Dataset, *, name: str | None, fs_hz: float | None,
                     adc_range_v: float, adc_bits: int) -> tuple[list[Check], list[Notice]]:
    exp = name or str(ds.attrs.get("experiment", ""))
    label = _label(ds, exp)
    checks: list[Check] = []
    notices: list[Notice] = []
    if fs_hz is not None:
        checks.append(_rate_check(ds, label, float(fs_hz)))
    lsb = adc_range_v / 2**adc_bits
    required = set(EXPERIMENTS[exp].required) if exp in EXPERIMENTS else set(ds.data_vars)
    t_check, t_notice = _time_type_findings(_stored_dtype(ds[TIME]), label)
    if t_check is not None:
        checks.append(t_check)
    if t_notice is not None:
        notices.append(t_notice)
    # A record shorter than its analysis reads: named for its length, before any signal in
    # it is judged (10 samples of a run whose excitation starts at 1 s are not "zero").
    short = _length_check(ds, exp, label)
    if short is not None:
        checks.append(short)
    # What the reader found about the file (fsmbench.io.notes): given by every check of it.
    notices += [Notice(kind, f"{label}: t" if kind == TIME_JITTER else label,
                       str(ds.attrs[kind])) for kind in READ_NOTES if ds.attrs.get(kind)]
    for var in ds.data_vars:
        v = str(var)
        if v not in SIGNALS:
            continue
        found, noted = _signal_findings(ds, v, exp=exp, label=label, required=required,
                                        long_enough=short is None or short.passed,
                                        adc_range_v=adc_range_v, adc_bits=adc_bits)
        checks += found
        notices += noted
    if short is None or short.passed:
        checks += copied_channels(ds, label)
        checks += clipped_signals(ds, exp, label, lsb)
        checks += frozen_segments(ds, label)
    return checks, notices


def _time_type_findings(t_type: np.dtype[Any], label: str) -> tuple[Check | None, Notice | None]:
    """``t`` stored as integers (a failed check) or in single precision (a notice).

    ``t_type``: ``t``'s dtype in the file; ``label``: the record, for the subject.
    """
    if t_type.kind in "iu":
        return Check("integer_samples", False, str(t_type), "floating point, in s",
                     f"{label}: t", f"t holds {t_type} integers (sample numbers?); "
                     "t must be the time in seconds: t = double(k)/fs"), None
    if t_type.itemsize < 8:
        return None, Notice("data_type", f"{label}: t", f"t is stored in single precision "
                            f"({t_type}); it was uniform enough here, but longer records "
                            "will not be: save t in double precision")
    return None, None


def _signal_findings(ds: xr.Dataset, v: str, *, exp: str, label: str,
                     required: Collection[Hashable],
                     long_enough: bool, adc_range_v: float,
                     adc_bits: int) -> tuple[list[Check], list[Notice]]:
    """The checks and notices of one signal ``v`` of :data:`~fsmbench.io.signals.SIGNALS`.

    ``exp``, ``label``: the experiment and the record (for subjects and advice);
    ``required``: the signals its analysis reads; ``long_enough``: the record passed
    its length check (or has none), so ``signal_varies`` is judged; ``adc_range_v``
    [V], ``adc_bits`` [bit]: the converters' span and resolution.
    """
    subject = f"{label}: {v}"
    lsb = adc_range_v / 2**adc_bits
    stored = _stored_dtype(ds[v])
    converter = v in ADC_SIGNALS or v in DAC_SIGNALS
    if stored.kind in "iu":
        return [_integer_samples_check(v, stored, subject=subject, converter=converter,
                                       adc_range_v=adc_range_v, adc_bits=adc_bits)], []
    checks: list[Check] = []
    notices: list[Notice] = []
    rail = adc_range_v / 2 - 1.5 * lsb  # as SaturationWarning: both rails, nothing inside
    try:
        peak, at_rails, spread, rms, first = _signal_stats(ds[v].data, rail)
    except _NonFiniteError as exc:
        count, index = exc.args
        raise RecordingError(str(ds.encoding.get("source", label)),
                             f"holds {count} NaN or Inf value{'s' if count > 1 else ''} "
                             f"(first at index {index})", variable=v) from None
    if converter:
        # Half a span plus 1 LSB: readings rounded to the converter's codes never exceed it.
        limit = adc_range_v / 2 + lsb
        ok = peak <= limit
        checks.append(Check("converter_range", ok, peak, f"≤ {limit:.6g} V (the converter's "
                            f"±{adc_range_v / 2:g} V)", subject,
                            "" if ok else f"{v} exceeds what the converter can deliver: "
                            "it is not in volts (counts, mV?) or not this bench's signal",
                            unit="V"))
        if ok and v in ADC_SIGNALS and at_rails:
            notices.append(Notice("saturation", subject, str(SaturationWarning(
                label, v, at_rails, int(ds[v].shape[0]), rail))))
    measured = v in ADC_SIGNALS or v == "Va"
    if v in required and (measured or EXCITATION.get(exp) == v) and long_enough:
        checks.append(_varies_check(v, exp=exp, subject=subject, spread=spread, peak=peak,
                                    first=first))
    if v == "Va":
        ok = rms <= MAX_VA_RMS_M
        checks.append(Check("va_in_metres", ok, rms, f"≤ {MAX_VA_RMS_M:g} m rms (the bench "
                            "moves by nm to µm)", subject,
                            "" if ok else va_unit_hint(rms, exp), unit="m rms"))
        if ok and v in required:  # jumps in a Va that is not in metres say nothing more
            checks.append(jump_check(ds, subject))
    return checks, notices


def _integer_samples_check(v: str, stored: np.dtype[Any], *, subject: str, converter: bool,
                           adc_range_v: float, adc_bits: int) -> Check:
    """``integer_samples`` failed on signal ``v`` stored as ``stored`` integers.

    A converter's signal (``converter``) is told how to turn counts into volts
    (``adc_range_v`` [V] over ``2^adc_bits`` codes); another, its unit.
    """
    lsb = adc_range_v / 2**adc_bits
    fix = (f"convert before saving: {v} = double({v}) * {adc_range_v:g}/2^{adc_bits} "
           f"(1 count = {1e3 * lsb:.3g} mV)" if converter
           else f"{v} must be in {SIGNALS[v].units}, as double")
    return Check("integer_samples", False, str(stored),
                 f"floating point, in {SIGNALS[v].units}", subject,
                 f"{v} holds {stored} integers: raw converter counts, not "
                 f"{'volts' if converter else SIGNALS[v].units}; {fix}")


def _varies_check(v: str, *, exp: str, subject: str, spread: float, peak: float,
                  first: float) -> Check:
    """``signal_varies`` of signal ``v``: its peak-to-peak ``spread`` is above 0.

    ``peak`` (largest magnitude) and ``first`` (first sample), in ``v``'s unit, say
    whether a constant signal is zero; the experiment's excitation (:data:`EXCITATION`)
    and a measured channel are advised differently.
    """
    ok = spread > 0.0
    unit = SIGNALS[v].units
    if ok:
        why = ""
    elif EXCITATION.get(exp) == v:
        why = (f"{v} is zero throughout: no power in the excitation" if peak == 0
               else f"{v} is constant at {first:.6g} {unit}: no power in the excitation")
        why += "; record it with the excitation on"
    else:
        why = (f"{v} is {'zero' if peak == 0 else f'constant at {first:.6g} {unit}'} "
               "throughout: the channel is dead or not connected")
    return Check("signal_varies", ok, spread, f"> 0 {unit} peak-to-peak",
                 subject, why, unit=unit)


def _length_check(ds: xr.Dataset, exp: str, label: str) -> Check | None:
    """``record_length``: the record against the shortest its analysis reads (None for a
    record that is not one of the study's experiments)."""
    need = MIN_DURATION_S.get(exp)
    if need is None:
        return None
    n = int(ds[TIME].shape[0])
    fs = float(ds.attrs.get("fs_hz", math.nan))
    length = n / fs if fs > 0 else math.nan
    ok = bool(math.isfinite(length) and length >= need)
    words = (f"{length * 1e3:.3g} ms" if length < 1.0 else f"{length:.3g} s")
    return Check("record_length", ok, length, f"≥ {need:g} s (what the ESRF study's analysis of "
                 f"{exp} reads)", f"{label}: t",
                 "" if ok else f"the record is {words} long ({n} samples): too short for its "
                 f"analysis, which needs {need:g} s; nothing in it is judged: record it again at "
                 "its length", unit="s")


# --------------------------------------------------------------------------- folder
def _notice_of(w: warnings.WarningMessage, label: str) -> Notice | None:
    if isinstance(w.message, (SaturationWarning, TrailingBytesWarning)):
        return None  # check_recording reports them itself (saturation, the recording's notes)
    text = str(w.message)
    if issubclass(w.category, RuntimeWarning):
        return Notice("numeric", label, f"numerical problem while reading: {text}")
    if " left out" in text:
        return Notice("dropped_variable", label, text.split(": ", 1)[-1])
    return Notice("other", label, text)


def _mixed_rates(recordings: dict[str, xr.Dataset], found: dict[str, Path]) -> list[Notice]:
    rates: dict[float, list[str]] = {}
    for name, ds in recordings.items():
        rates.setdefault(float(ds.attrs["fs_hz"]), []).append(found[name].name)
    if len(rates) < 2:
        return []
    text = "; ".join(f"{fs:g} Hz: {', '.join(files)}" for fs, files in rates.items())
    return [Notice("rate", "", f"the recordings have different sampling rates ({text})")]


#: HDF5 recordings (NeXus, MATLAB v7.3) larger than this are read lazily (Dask).
LAZY_BYTES: Final = 512 << 20
#: Samples per Dask chunk of a record read lazily: 8 MiB per signal, so that a day
#: (864 M samples) is 824 chunks per signal, not 13 000 (whose graph alone costs ~0.5 GB).
LAZY_CHUNK_SAMPLES: Final = 1 << 20
#: Experiments whose analyses run out of core; other long records must fit in memory.
OUT_OF_CORE_EXPERIMENTS: Final = frozenset({*(f"data_huddle_test_{i}" for i in range(1, 6)),
                                            "data_rep_h", "data_rep_v"})


#: Peak memory of the analyses of a record read whole, per byte of its float64 samples
#: (the budget on 60 s and 600 s huddle tests: 0.41 and 1.05 GB RSS for 19 and 192 MB of
#: samples, a slope of 3.7; rounded up).
IN_MEMORY_FACTOR: Final = 4.0
#: Files smaller than this are never too large to read whole (their samples are at most
#: ~10x the file, a few hundred MB).
_MEMORY_CHECK_BYTES: Final = 32 << 20


def sample_bytes(path: Path, fmt: str) -> int:
    """The float64 samples a recording holds [bytes], from its headers (nothing read)."""
    if fmt == "mat5":
        return sum(8 * n for _name, n in v5_vectors(path))

    total = 0

    def visit(_name: str, obj: Any) -> None:
        nonlocal total
        if isinstance(obj, h5py.Dataset) and obj.dtype.kind in "fiu":
            total += 8 * int(obj.size)

    with h5py.File(path, "r") as f:
        data = f.get("entry/data")  # NeXus: the samples, not the instrument's numbers
        (data if isinstance(data, h5py.Group) else f).visititems(visit)
    return total


def _refuse_if_too_large(path: Path, name: str, fmt: str, *, out_of_core: bool) -> None:
    """A record whose analysis in memory would not fit: one line, before any allocation."""
    # Read through the module: a test gives the machine less memory by patching it there.
    if path.stat().st_size <= _MEMORY_CHECK_BYTES:
        return
    need = sample_bytes(path, fmt)
    have = matfile.available_memory_bytes()
    if IN_MEMORY_FACTOR * need <= have:
        return
    gib = 2.0**30
    head = (f"is {need / gib:.1f} GiB of samples: analysing it in memory takes about "
            f"{IN_MEMORY_FACTOR * need / gib:.0f} GiB and this machine has {have / gib:.1f} GiB "
            "available")
    if name not in OUT_OF_CORE_EXPERIMENTS:
        raise RecordingError(path, f"{head}; only the huddle tests and the repeatability "
                                   "records run out of core: cut it to the ESRF study's length")
    if fmt == "mat5":
        raise RecordingError(path, f"{head}; a MATLAB v5 file cannot be read in pieces: convert "
                                   f"it once (fsmbench convert {path} {path.with_suffix('.h5')} "
                                   "--format nexus)" + ("" if out_of_core else
                                                        ", with the dask extra installed "
                                                        "(pip install 'fsmbench[dask]')"))
    raise RecordingError(path, f"{head}; install the dask extra (pip install "
                               "'fsmbench[dask]') to analyse it block by block, out of core")


def _read(path: Path, name: str, *, adc_range_v: float, adc_bits: int,
          lazy_bytes: int) -> xr.Dataset:
    """The recording, lazily (Dask) when it is a large HDF5 file (see :data:`LAZY_BYTES`).

    Read whole, a record too large to analyse in memory (:data:`IN_MEMORY_FACTOR`) is
    refused in one line before anything is allocated, with the way to analyse it.
    """

    fmt = detect_format(path)
    try:
        import dask  # noqa: F401
        out_of_core = True
    except ImportError:  # the fsmbench[dask] extra is not installed: read whole, if it fits
        out_of_core = False
    # The data's size, not the file's: zeros after them are not read (fsmbench.io.trailing).
    if data_end(path, fmt).end <= lazy_bytes or fmt not in ("hdf5", "mat73") or not out_of_core:
        _refuse_if_too_large(path, name, fmt, out_of_core=out_of_core)
        return read_recording(path, experiment=name, adc_range_v=adc_range_v, adc_bits=adc_bits)

    # NaN and Inf in the signals are found by check_recording's pass (_signal_stats).
    ds = open_recording(path, check_signals=False, chunk_samples=LAZY_CHUNK_SAMPLES)
    ds.attrs["experiment"] = name
    missing = [v for v in EXPERIMENTS[name].required if v not in ds.variables]
    if missing:
        raise RecordingError(path, f"is missing {', '.join(missing)}", variable=missing[0])
    if name in OUT_OF_CORE_EXPERIMENTS:
        return ds
    need = 8 * ds.sizes[TIME] * (len(ds.data_vars) + 1)
    if need > 0.5 * matfile.available_memory_bytes():
        raise RecordingError(path, f"is {need / 2**30:.1f} GiB of samples: too long to analyse "
                             "in memory, and only the huddle tests and the repeatability "
                             "records run out of core; cut it to the ESRF study's length")
    return ds.compute()


def _read_one(path: Path, name: str, *, fs_hz: float | None, adc_range_v: float,
              adc_bits: int, lazy_bytes: int
              ) -> tuple[xr.Dataset, list[Check], list[Notice]]:
    """One experiment's record read and checked: the warnings of reading it as notices,
    other files of the same experiment beside it compared with it (or named in the error)."""
    others = other_files(path, name)

    def read(p: Path, name: str = name) -> xr.Dataset:
        return _read(p, name, adc_range_v=adc_range_v, adc_bits=adc_bits,
                     lazy_bytes=lazy_bytes)

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            ds = read(path)
        except RecordingError as exc:
            if not others:
                raise
            raise RecordingError(exc.file, f"{exc.problem}; {others[0].name} beside it "
                                 f"holds {name} too: remove or rename the file that is "
                                 "not the record", variable=exc.variable,
                                 kind=exc.kind) from None
        if others:  # which file was read, and the others agree with it (or refused)
            with warnings.catch_warnings(record=True):  # of files not used: dropped
                ds.attrs[FILE_CHOICE] = compare_files(name, path, ds, others, read=read)
        found_checks, found_notices = check_recording(
            ds, name=name, fs_hz=fs_hz, adc_range_v=adc_range_v, adc_bits=adc_bits)
    notices = [n for w in caught if (n := _notice_of(w, path.name)) is not None]
    return ds, list(found_checks), notices + list(found_notices)


def load_recordings(data_dir: Path, *, fs_hz: float | None = None, adc_range_v: float = 20.0,
                    adc_bits: int = 16, progress: Callable[[str], None] | None = None,
                    lazy_bytes: int = LAZY_BYTES) -> RecordingSet:
    """Read every seed experiment present in ``data_dir`` and check it.

    Parameters
    ----------
    data_dir : Path
        Folder of recordings (``data_uch.mat`` …; ``.h5``/``.nxs`` too).
    fs_hz : float, optional
        The bench's sampling rate [Hz] (``bench.nominal.converter.fs_hz``);
        each recording's rate must be within 1 % of it (check
        ``sampling_rate``). None accepts any rate.
    adc_range_v, adc_bits : float, int
        Converter span [V] and resolution [bit] (range and saturation).
    progress : callable, optional
        Receives one message per file read.
    lazy_bytes : int
        HDF5 files larger than this [bytes] are read lazily (Dask arrays);
        the huddle tests and the repeatability records stay lazy and are
        analysed out of core, other experiments are loaded into memory if they fit.

    Raises
    ------
    RecordingError
        No recording could be read: the message lists what was looked for,
        what the folder holds and the near-miss names, or each file's problem (one
        phrase naming the files that fail in the same way).
    NotADirectoryError
        ``data_dir`` is not a folder.
    """
    found = find_experiments(data_dir)
    hints = folder_hints(data_dir)
    recordings: dict[str, xr.Dataset] = {}
    skipped: dict[str, str] = {}
    notices: list[Notice] = []
    checks: list[Check] = []
    odd = {name: why for name in EXPERIMENTS if name not in found
           and (why := not_a_file(Path(data_dir), name)) is not None}
    failures: dict[str, RecordingError] = {}
    for name in EXPERIMENTS:
        if name not in found:
            skipped[name] = odd.get(name) or f"no {name}.mat (or .h5/.nxs) in {data_dir}" + (
                f"; {hints[name]}" if name in hints else "")
            continue
        if progress is not None:
            progress(f"reading {found[name].name}")
        try:
            ds, found_checks, found_notices = _read_one(
                found[name], name, fs_hz=fs_hz, adc_range_v=adc_range_v, adc_bits=adc_bits,
                lazy_bytes=lazy_bytes)
        except RecordingError as exc:
            skipped[name] = str(exc)
            failures[name] = exc
            continue
        recordings[name] = ds
        checks += found_checks
        notices += found_notices
    if not recordings:
        raise RecordingError(data_dir, _empty_problem(Path(data_dir), found, skipped, hints,
                                                      odd, failures))
    if fs_hz is None:
        notices += _mixed_rates(recordings, found)
    else:
        notices += [Notice("rate", c.subject, c.sentence()) for c in checks
                    if c.name == "sampling_rate" and not c.passed]
    return RecordingSet(folder=str(data_dir), recordings=recordings, skipped=skipped,
                        notices=tuple(notices), checks=tuple(checks))


def _grouped(names: list[str], found: dict[str, Path], skipped: dict[str, str],
             failures: dict[str, RecordingError]) -> list[str]:
    """Why each experiment was not used, files failing in the same way named together.

    Thirteen files refused for the same reason (a clock's jitter, once) made one line of
    4 KB: such files become one phrase naming them, with the first file's full problem.
    """
    groups: dict[tuple[str | None, str], list[str]] = {}
    for name in names:
        exc = failures.get(name)
        key = (exc.variable, exc.kind) if exc is not None and exc.kind else None
        groups.setdefault(key or (None, name), []).append(name)
    out = []
    for (variable, kind), members in groups.items():
        if len(members) < 2:
            out.append(skipped[members[0]])
            continue
        what = f"variable '{variable}' {kind}" if variable else kind
        first = failures[members[0]]
        out.append(f"{what} in {len(members)} files ({', '.join(found[m].name for m in members)})"
                   f"; the first, {first}")
    return out


def _empty_problem(root: Path, found: dict[str, Path], skipped: dict[str, str],
                   hints: dict[str, str], odd: dict[str, str],
                   failures: dict[str, RecordingError]) -> str:
    names = sorted(p.name for p in root.iterdir()) if root.is_dir() else []
    shown = ", ".join(names[:12]) + (f" … ({len(names)} entries)" if len(names) > 12 else "")
    if found or odd:
        bad = "; ".join(_grouped([n for n in EXPERIMENTS if n in found or n in odd], found,
                                 skipped, failures))
        return f"no recording in this folder can be used: {bad}"
    looked = (f"looked for the ESRF study's recordings ({', '.join(list(EXPERIMENTS)[:2])} … "
              f"{list(EXPERIMENTS)[-1]}, {len(EXPERIMENTS)} names, as .mat, .h5 or .nxs)")
    near = "; ".join(hints.values())
    return (f"holds none of them: {looked}; found {shown or 'nothing (empty folder)'}"
            + (f"; did you mean: {near}" if near else ""))
