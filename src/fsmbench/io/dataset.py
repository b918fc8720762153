"""A recording as an ``xarray.Dataset``: built from named vectors and checked.

The layout (:mod:`fsmbench.io.recording`'s notes): one float64 variable per signal on
``"t"``, units and long names from :data:`fsmbench.io.signals.SIGNALS`, dataset attrs
``fs_hz``, ``experiment`` and ``source``. What builds and checks it, apart from the
readers and writers of files (:mod:`fsmbench.io.recording`, :mod:`fsmbench.io.nexus`),
which both build on it.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Iterable, Mapping
from typing import Any, Final

import numpy as np
import scipy.sparse
import xarray as xr

from fsmbench.io.errors import RecordingError, SaturationWarning
from fsmbench.io.notes import TIME_JITTER, TRAILING_BYTES, clear_notes
from fsmbench.io.signals import ADC_SIGNALS, SIGNALS, TIME
from fsmbench.io.timebase import TimeBase, fit_time_base
from fsmbench.io.trailing import DataEnd

__all__ = [
    "as_vector",
    "assemble",
    "check_lengths",
    "fitted_time_base",
    "make_recording",
    "note_reading",
    "ordered_signals",
    "signal_attrs",
    "validate_dataset",
    "validate_recording",
]

# How far a file's fs_hz may be from the rate fitted to its t (relative): far above the
# fit's error, far below another rate.
_STEP_TOLERANCE: Final = 1e-3
_UNKNOWN_NOTE: Final = "not in the ESRF study's signal table (fsmbench.io.signals.SIGNALS)"


# --------------------------------------------------------------------------- helpers
def _shape_text(shape: tuple[int, ...]) -> str:
    return "x".join(str(d) for d in shape)


def as_vector(name: str, value: Any, origin: str) -> np.ndarray:
    """``value`` as a new 1-D float64 array, or a RecordingError saying why not.

    N×1, 1×N and 1-D arrays are vectors (MATLAB saves both orientations).
    """
    if isinstance(value, str):
        raise RecordingError(origin, f"holds text ({value[:30]!r}), not samples", variable=name)
    if isinstance(value, Mapping):
        fields = ", ".join(map(str, value)) or "none"
        raise RecordingError(origin, f"holds a struct (fields: {fields}), not samples",
                             variable=name)
    if isinstance(value, list):
        raise RecordingError(origin, f"holds a cell array of {len(value)} elements, "
                             "not samples", variable=name)
    if scipy.sparse.issparse(value):
        raise RecordingError(origin, "holds a sparse matrix, not samples", variable=name)
    arr = np.asarray(value)
    kind = arr.dtype.kind
    if kind == "c":
        raise RecordingError(origin, f"holds complex values (dtype {arr.dtype}); a signal "
                             "must be real", variable=name)
    if kind == "b":
        raise RecordingError(origin, "holds logical (true/false) values, not numbers",
                             variable=name)
    if kind not in "iuf":
        raise RecordingError(origin, f"is not numeric (dtype {arr.dtype})", variable=name)
    if arr.ndim > 2 or (arr.ndim == 2 and min(arr.shape) > 1):
        what = "matrix" if arr.ndim == 2 else "array"
        raise RecordingError(
            origin, f"is a {_shape_text(arr.shape)} {what}, not a vector (N x 1 or 1 x N)",
            variable=name,
        )
    # np.array copies: the caller's arrays are never aliased nor modified.
    return np.array(arr.reshape(-1), dtype=np.float64, copy=True)


def check_lengths(vectors: Mapping[str, np.ndarray], origin: str) -> int:
    """Common length of ``vectors`` (``t`` first if present), else an error."""
    ref = TIME if TIME in vectors else next(iter(vectors))
    n = vectors[ref].size
    for name, v in vectors.items():
        if v.size != n:
            raise RecordingError(
                origin, f"has {v.size} samples but variable '{ref}' has {n}", variable=name
            )
    return n


def _nonfinite_problem(v: np.ndarray, t: np.ndarray | None) -> str | None:
    bad = ~np.isfinite(v)
    if not bad.any():
        return None
    n_nan = int(np.count_nonzero(np.isnan(v)))
    n_inf = int(np.count_nonzero(bad)) - n_nan
    counts = [f"{c} {kind}" for c, kind in ((n_nan, "NaN"), (n_inf, "Inf")) if c]
    total = n_nan + n_inf
    first = int(np.argmax(bad))
    where = f"first at index {first}"
    if t is not None:
        where += f", t = {t[first]:.10g} s"
    return f"holds {' and '.join(counts)} value{'s' if total > 1 else ''} ({where})"


def _check_time(t: np.ndarray, origin: str) -> TimeBase:
    """Check that ``t`` (s) is finite, increasing and on a uniform grid but for clock jitter
    (:mod:`fsmbench.io.timebase`); return the grid fitted to it."""
    problem = _nonfinite_problem(t, None)
    if problem:
        raise RecordingError(origin, problem, variable=TIME, kind="holds NaN or Inf values")
    return fit_time_base(t, origin)


def signal_attrs(name: str) -> dict[str, str]:
    info = SIGNALS.get(name)
    if info is None:
        return {"units": "", "long_name": name, "note": _UNKNOWN_NOTE}
    return {"units": info.units, "long_name": info.long_name}


def ordered_signals(names: Iterable[str]) -> list[str]:
    """Signals in the ESRF study's table order, then the others as given."""
    names = [n for n in names if n != TIME]
    return [n for n in SIGNALS if n in names] + [n for n in names if n not in SIGNALS]


def assemble(
    vectors: Mapping[str, np.ndarray], *, fs_hz: float, experiment: str, source: str
) -> xr.Dataset:
    t = vectors[TIME]
    data_vars = {n: (TIME, vectors[n], signal_attrs(n)) for n in ordered_signals(vectors)}
    return xr.Dataset(
        data_vars,
        coords={TIME: (TIME, t, {"units": "s", "long_name": "Time"})},
        attrs={"fs_hz": float(fs_hz), "experiment": str(experiment), "source": str(source)},
    )


def _check_saturation(
    ds: xr.Dataset, origin: str, adc_range_v: float, adc_bits: int, stacklevel: int
) -> None:
    lsb = adc_range_v / 2**adc_bits
    # A bipolar converter's codes span -range/2 .. range/2 - 1 LSB: the upper
    # rail is one LSB below range/2. Allowing half an LSB more for the rounding
    # of a reading stored as volts catches both rails and nothing inside them.
    limit = adc_range_v / 2 - 1.5 * lsb
    for name in ADC_SIGNALS:
        if name in ds.data_vars:
            v = ds[name].values
            count = int(np.count_nonzero(np.abs(v) >= limit))
            if count:
                warnings.warn(SaturationWarning(origin, name, count, v.size, limit),
                              stacklevel=stacklevel)


def validate_dataset(
    ds: xr.Dataset,
    *,
    origin: str,
    require: Iterable[str],
    adc_range_v: float,
    adc_bits: int,
    saturation: bool,
    stacklevel: int,
    base: TimeBase | None = None,
) -> TimeBase:
    """Raise on the first problem of ``ds``; return the grid fitted to its ``t`` (``base``:
    already fitted to it by the caller, so ``t`` is not fitted twice)."""
    if TIME not in ds.coords and TIME not in ds.variables:
        present = ", ".join(map(str, ds.data_vars)) or "nothing"
        raise RecordingError(origin, "is missing: a recording needs its time vector t, in s "
                             f"(present: {present})", variable=TIME)
    missing = [r for r in require if r not in ds.variables]
    if missing:
        present = ", ".join([TIME, *map(str, ds.data_vars)])
        also = f" (and so are {', '.join(repr(m) for m in missing[1:])})" if missing[1:] else ""
        raise RecordingError(origin, f"is missing{also}; present: {present}",
                             variable=missing[0])
    for name, var in ds.variables.items():
        if var.dims != (TIME,):
            raise RecordingError(origin, f"has dims {var.dims}, expected ('t',)",
                                 variable=str(name))
        if var.dtype.kind not in "iuf":
            raise RecordingError(origin, f"is not real numeric (dtype {var.dtype})",
                                 variable=str(name))
    t = np.asarray(ds[TIME].values, dtype=np.float64)
    if t.size < 2:
        raise RecordingError(origin, f"holds {t.size} sample{'s' if t.size != 1 else ''}; "
                             "a recording needs at least 2", variable=TIME)
    base = base or _check_time(t, origin)
    for name in ds.data_vars:
        problem = _nonfinite_problem(np.asarray(ds[name].values), t)
        if problem:
            raise RecordingError(origin, problem, variable=str(name),
                                 kind="holds NaN or Inf values")
    fs = ds.attrs.get("fs_hz")
    if not isinstance(fs, (int, float, np.floating, np.integer)) or not np.isfinite(fs) or fs <= 0:
        raise RecordingError(origin, f"attribute 'fs_hz' is {fs!r}; it must be the sampling "
                             "frequency in Hz, a positive number")
    if abs(float(fs) / base.fs_hz - 1.0) > _STEP_TOLERANCE:
        raise RecordingError(origin, f"attribute 'fs_hz' = {float(fs):.10g} Hz disagrees with "
                             f"t, whose rate is {base.fs_hz:.10g} Hz")
    if saturation:
        _check_saturation(ds, origin, adc_range_v, adc_bits, stacklevel + 1)
    return base


def fitted_time_base(t: np.ndarray) -> TimeBase | None:
    """The grid fitted to ``t``, or None when it has none (the validation then says why)."""
    if t.size < 2 or not np.isfinite(t).all():
        return None
    try:
        return fit_time_base(t, "")
    except RecordingError:
        return None


def note_reading(ds: xr.Dataset, base: TimeBase | None, end: DataEnd | None = None) -> None:
    """Say in the recording what reading it found (:mod:`fsmbench.io.notes`): bytes ignored
    after the data, ``t`` jittering; every check of it then gives the notice."""
    clear_notes(ds)  # the notes an archive kept from an earlier reading
    if end is not None and end.trailing:
        ds.attrs[TRAILING_BYTES] = end.sentence()
    if base is not None and base.jittered:
        ds.attrs[TIME_JITTER] = base.jitter_sentence()


# --------------------------------------------------------------------------- public API
def validate_recording(
    ds: xr.Dataset,
    *,
    origin: str | os.PathLike[str],
    require: Iterable[str] = (),
    adc_range_v: float = 20.0,
    adc_bits: int = 16,
) -> None:
    """Check a recording; raise on the first problem, warn on ADC saturation.

    Parameters
    ----------
    ds : xarray.Dataset
        The recording (see the module docstring), N samples on ``"t"``.
    origin : str or os.PathLike
        File (or label) named in the messages.
    require : iterable of str, default ()
        Variables that must be present (``t`` always is).
    adc_range_v : float, default 20.0
        Full input range ΔV of the ADC, in V (±10 V: 20 V, ESRF study section 1.6).
    adc_bits : int, default 16
        ADC resolution n, in bits.

    Raises
    ------
    RecordingError
        ``t`` or a required variable missing, a variable not 1-D on ``t`` or
        not real numeric, fewer than 2 samples, ``t`` not finite, not
        increasing or not uniform (straying from the grid fitted to it by more
        than 0.1 % of a period: :mod:`fsmbench.io.timebase`), NaN/Inf in a
        signal, ``fs_hz`` missing or off ``t``.

    Warns
    -----
    SaturationWarning
        For each of :data:`~fsmbench.io.signals.ADC_SIGNALS` with samples at
        the converter rails, ``|v| >= adc_range_v/2 - 1.5 LSB`` with
        ``LSB = adc_range_v / 2**adc_bits``.
    """
    validate_dataset(ds, origin=os.fspath(origin), require=require, adc_range_v=adc_range_v,
              adc_bits=adc_bits, saturation=True, stacklevel=3)


def make_recording(
    signals: Mapping[str, np.ndarray],
    *,
    t: np.ndarray | None = None,
    fs_hz: float | None = None,
    experiment: str,
    source: str = "",
    adc_range_v: float = 20.0,
    adc_bits: int = 16,
) -> xr.Dataset:
    """Build a checked recording from arrays.

    Parameters
    ----------
    signals : mapping of str to array_like
        Signal name to samples, each of shape (N,), (N, 1) or (1, N), real,
        in the unit of :data:`~fsmbench.io.signals.SIGNALS` (V, or m for
        ``Va``). May hold ``"t"`` instead of the ``t`` argument. Copied,
        never modified.
    t : array_like, optional
        Sample times, in s, shape (N,). Default ``arange(N) / fs_hz``.
    fs_hz : float, optional
        Sampling frequency, in Hz. Default: from ``t``. At least one of
        ``t`` and ``fs_hz`` is needed; given both, they must agree.
    experiment : str
        Experiment name, e.g. ``"data_uch"``.
    source : str, default ""
        File the samples came from; also names the recording in messages.
    adc_range_v, adc_bits : float, int
        ADC range (V) and resolution (bits) for the saturation check.

    Returns
    -------
    xarray.Dataset
        The recording; signals in the ESRF study's table order, then the others.

    Raises
    ------
    RecordingError
        As :func:`validate_recording`, plus wrong shapes, types and lengths.
    ValueError
        Neither ``t`` nor ``fs_hz``, or ``t`` given twice.
    """
    origin = source or f"recording '{experiment}'"
    if TIME in signals and t is not None:
        raise ValueError(f"{origin}: t is given both in signals and as the t argument")
    raw: dict[str, Any] = dict(signals)
    if t is not None:
        raw[TIME] = t
    vectors = {name: as_vector(name, value, origin) for name, value in raw.items()}
    if TIME not in vectors:
        if fs_hz is None:
            raise ValueError(f"{origin}: give t (s) or fs_hz (Hz)")
        if not vectors:
            raise ValueError(f"{origin}: no signals and no t")
        n = check_lengths(vectors, origin)
        vectors[TIME] = np.arange(n, dtype=np.float64) / float(fs_hz)
    check_lengths(vectors, origin)
    base = fitted_time_base(vectors[TIME])
    if fs_hz is None:
        fs_hz = base.fs_hz if base is not None else float("nan")
    ds = assemble(vectors, fs_hz=float(fs_hz), experiment=experiment, source=source)
    validate_dataset(ds, origin=origin, require=(), adc_range_v=adc_range_v, adc_bits=adc_bits,
              saturation=True, stacklevel=3, base=base)
    note_reading(ds, base)
    return ds


