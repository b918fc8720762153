"""The plausibility checks of one recording against what the bench can produce.

:func:`check_recording` is the plausibility test of one recording; the folder's loader
(:func:`fsmbench.io.folder.load_recordings`) and the stages run it, so that a recording that
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
"""

from __future__ import annotations

import math
import os
import weakref
from collections.abc import Collection, Hashable
from dataclasses import dataclass
from typing import Any, Final

import numpy as np
import xarray as xr

from fsmbench.checks import Check, Notice
from fsmbench.io.channels import clipped_signals, copied_channels, frozen_segments
from fsmbench.io.errors import RecordingError, SaturationWarning
from fsmbench.io.notes import READ_NOTES, TIME_JITTER
from fsmbench.io.signals import ADC_SIGNALS, DAC_SIGNALS, EXPERIMENTS, MIN_DURATION_S, SIGNALS, TIME
from fsmbench.io.va_jumps import jump_check, va_unit_hint

__all__ = ["EXCITATION", "MAX_VA_RMS_M", "RATE_TOLERANCE", "CarriedChecks", "carried_checks",
           "carry_checks", "check_recording"]

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


# The checks that do not depend on the rate asked, by dataset identity: the loader, the
# identification and the budget check the same record (a pass over a day-long record read
# out of core takes minutes; over the study's in-memory records, a second of its wall).
# A dataset is never modified in place (inputs are not), and its entry goes with it.
_CHECKED: dict[tuple[Any, ...], tuple[list[Check], list[Notice]]] = {}


@dataclass(frozen=True, eq=False)
class CarriedChecks:
    """A record's rate-free checks as :func:`check_recording` keeps them, to travel with a
    copy of the record to another process (:func:`carried_checks`, :func:`carry_checks`)."""

    name: str | None
    adc_range_v: float
    adc_bits: int
    checks: tuple[Check, ...]
    notices: tuple[Notice, ...]


def carried_checks(ds: xr.Dataset, *, name: str | None, adc_range_v: float,
                   adc_bits: int) -> CarriedChecks | None:
    """What :func:`check_recording` keeps for ``ds`` (None: not checked yet)."""
    found = _CHECKED.get((id(ds), name, adc_range_v, adc_bits))
    return None if found is None else CarriedChecks(name, adc_range_v, adc_bits,
                                                     tuple(found[0]), tuple(found[1]))


def carry_checks(ds: xr.Dataset, carried: CarriedChecks) -> None:
    """Keep ``carried`` as ``ds``'s checks: ``ds`` is a copy of the record they were made on
    (read in a forked process and sent back), so they are not made again."""
    key = (id(ds), carried.name, carried.adc_range_v, carried.adc_bits)
    if key not in _CHECKED:
        _CHECKED[key] = (list(carried.checks), list(carried.notices))
        weakref.finalize(ds, _CHECKED.pop, key, None)


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
    key = (id(ds), name, adc_range_v, adc_bits)
    found = _CHECKED.get(key)
    if found is None:
        found = _check_recording(ds, name=name, adc_range_v=adc_range_v, adc_bits=adc_bits)
        _CHECKED[key] = found
        weakref.finalize(ds, _CHECKED.pop, key, None)
    checks, notices = list(found[0]), list(found[1])
    if fs_hz is not None:  # the first check of the docstring's order
        checks.insert(0, _rate_check(ds, _label(ds, name or str(ds.attrs.get("experiment", ""))),
                                     float(fs_hz)))
    return checks, notices


def _check_recording(ds: xr.Dataset, *, name: str | None, adc_range_v: float,
                     adc_bits: int) -> tuple[list[Check], list[Notice]]:
    """Every check but the rate's, and the notices (whatever the rate asked)."""
    exp = name or str(ds.attrs.get("experiment", ""))
    label = _label(ds, exp)
    checks: list[Check] = []
    notices: list[Notice] = []
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
