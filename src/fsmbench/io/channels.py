"""What a channel's own samples say about the channel: recorded twice, clipped, frozen, padded.

Each check reads one record's samples and nothing else, so it holds on any bench:

``channels_distinct``
    Two measured channels of one record holding the same samples: noise is never
    recorded twice.
``signal_clipped``
    A measured signal of a noise run flat at its extremes (a share of its samples at
    its largest or smallest value that Gaussian noise never gives).
``signal_frozen``
    A measured signal that holds one value for a stretch where, everywhere else, it
    changes on most samples: its noise (several converter steps) makes a run of
    ``L`` equal samples as likely as ``(1 − p)^L`` per sample, ``p`` the share of
    samples on which it changes elsewhere; a run that chance gives less than once in
    a billion records is a channel that froze (a dead input, a stalled acquisition, a
    buffer repeated). A run that opens the record is left to the lag checks: a channel
    shifted late starts on its fill value.
``record_padded``
    Every signal exactly zero from one sample to the end while ``t`` runs on: zeros
    appended after the record's end (a preallocated buffer the acquisition never
    filled). Named once for the record, not as each signal frozen.

Dask-backed (out-of-core) signals are not read here.
"""

from __future__ import annotations

import math
from typing import Any, Final

import numpy as np
import xarray as xr

from fsmbench.checks import Check
from fsmbench.io.signals import ADC_SIGNALS, DAC_SIGNALS, TIME

__all__ = ["CLIPPED_MIN_STEPS", "CLIPPED_SHARE", "CLIPPED_TAIL_SAMPLES", "FROZEN_MIN_CHANGE",
           "FROZEN_ODDS", "clipped_signals", "copied_channels", "frozen_segments"]

#: The noise runs: their excitation is random, so a measured signal that passes it on is
#: never flat at its extremes (a sine spends a share of its samples at its top code).
_NOISE_RUNS: Final = ("data_uch", "data_ucv", "data_unh", "data_unv")
#: A signal with at least this share of its samples at its largest (or smallest) value is
#: clipped: Gaussian noise of 10^5 samples puts 1 there, a record clipped at 30 % of its
#: peak ~30 % (its gain then reads 16 % low).
CLIPPED_SHARE: Final = 0.005
#: Signals spanning fewer converter steps than this are judged by their missing tail
#: (:data:`CLIPPED_TAIL_SAMPLES`) as well: a few codes are each visited often, clipped
#: or not.
CLIPPED_MIN_STEPS: Final = 64
#: On a signal of few codes (3 to :data:`CLIPPED_MIN_STEPS`), a share at an extreme code
#: above :data:`CLIPPED_SHARE` is a clip when a Gaussian of the signal's own mean and std
#: puts at least this many samples beyond that code (past its rounding edge), where the
#: record has none. Beyond a noise record's own maximum it puts about one (10 or more:
#: a chance of e^-10); the corpus's ``weak`` bench, Vph of 55 codes clipped at 30 % of
#: its peak, misses hundreds. The std of the clipped record is smaller than the true one,
#: so the count is a lower bound.
CLIPPED_TAIL_SAMPLES: Final = 10.0
#: A signal is judged for a frozen stretch only where it changes on at least this share
#: of its samples elsewhere: noise of a converter step or more. A quieter channel (a coil
#: monitor without command, sub-step noise) sits on one code by itself.
FROZEN_MIN_CHANGE: Final = 0.5
#: A run of equal samples is frozen when chance gives it less often than this per record
#: (``n (1 − p)^L``, the run's odds at each of the record's ``n`` samples).
FROZEN_ODDS: Final = 1e-9
#: Fewest equal samples named: a few repeated samples (a converter's missed conversion)
#: change no estimate.
_FROZEN_MIN_SAMPLES: Final = 20


def _in_memory(x: Any) -> bool:
    return not type(x).__module__.startswith("dask")


def copied_channels(ds: xr.Dataset, label: str) -> list[Check]:
    """``channels_distinct``: two measured channels of one record holding the same samples."""
    names = [str(v) for v in ds.data_vars if str(v) in ADC_SIGNALS and _in_memory(ds[v].data)]
    out = []
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            x, y = np.asarray(ds[a].values), np.asarray(ds[b].values)
            if x.shape == y.shape and np.ptp(x) > 0 and np.array_equal(x, y):
                out.append(Check(
                    "channels_distinct", False, "the same samples", "two channels, two signals",
                    f"{label}: {a}, {b}",
                    f"{b} holds the same samples as {a}: one channel recorded twice (a cable "
                    f"split to both inputs, or the save writing {a} twice); the records "
                    f"cannot tell which: record it again with {a} and {b} on their own channels"))
    return out


def clipped_signals(ds: xr.Dataset, exp: str, label: str, lsb: float) -> list[Check]:
    """``signal_clipped``: a measured signal of a noise run flat at its extremes.

    Parameters
    ----------
    ds : xarray.Dataset
        One record.
    exp : str
        Its experiment (only the noise runs are judged).
    label : str
        The file in words, for the check's subject.
    lsb : float
        One converter step [V].
    """
    if exp not in _NOISE_RUNS:
        return []
    out = []
    for var in ds.data_vars:
        v = str(var)
        if v not in ADC_SIGNALS or not _in_memory(ds[v].data):
            continue
        x = np.asarray(ds[v].values, dtype=float)
        lo, hi = float(np.min(x)), float(np.max(x))
        if x.size == 0 or (hi - lo) < 2.0 * lsb:  # no code between the extremes
            continue
        share = max(float(np.mean(x >= hi)), float(np.mean(x <= lo)))
        ok = share < CLIPPED_SHARE
        if not ok and (hi - lo) < CLIPPED_MIN_STEPS * lsb:
            ok = not _tail_missing(x, lo=lo, hi=hi, lsb=lsb)
        out.append(Check(
            "signal_clipped", ok, share, f"< {CLIPPED_SHARE:g} of the samples at its largest or "
            "smallest value (a noise run's signal is never flat at its extremes)",
            f"{label}: {v}",
            "" if ok else f"{v} sits at {hi:+.4g} V or {lo:+.4g} V on {100 * share:.3g} % of its "
            "samples: clipped below the converter's range (an amplifier's or a channel's "
            "limit, or a saturation in the target); its gains would read low: record it "
            "again within the limit", unit="×"))
    return out


def _tail_missing(x: np.ndarray, *, lo: float, hi: float, lsb: float) -> bool:
    """An extreme code holding at least :data:`CLIPPED_SHARE` of the record beyond which a
    Gaussian of the record's mean and std puts :data:`CLIPPED_TAIL_SAMPLES` samples."""
    mean, std = float(np.mean(x)), float(np.std(x))
    if not std > 0:
        return False
    for share, beyond in ((float(np.mean(x >= hi)), hi + 0.5 * lsb - mean),
                          (float(np.mean(x <= lo)), mean - (lo - 0.5 * lsb))):
        expected = x.size * 0.5 * math.erfc(beyond / (std * math.sqrt(2.0)))
        if share >= CLIPPED_SHARE and expected >= CLIPPED_TAIL_SAMPLES:
            return True
    return False


def _longest_run(x: np.ndarray) -> tuple[int, int, float]:
    """``(start, length, p)``: the longest run of equal samples and the share of the other
    samples on which the signal changes."""
    n = x.size
    changes = np.flatnonzero(np.diff(x) != 0)
    starts = np.concatenate(([0], changes + 1))
    lengths = np.diff(np.concatenate((starts, [n])))
    k = int(np.argmax(lengths))
    length = int(lengths[k])
    elsewhere = n - length
    return int(starts[k]), length, (changes.size / elsewhere if elsewhere > 0 else 0.0)


def _trailing_zeros(x: np.ndarray) -> int:
    nonzero = np.flatnonzero(x != 0)
    return x.size if nonzero.size == 0 else x.size - 1 - int(nonzero[-1])


def _when(t: np.ndarray, i: int) -> str:
    return f"{float(t[i] - t[0]):.4g} s" if 0 <= i < t.size else "the end"


def frozen_segments(ds: xr.Dataset, label: str) -> list[Check]:
    """``record_padded`` and ``signal_frozen`` (see the module notes).

    Only signals that change on at least :data:`FROZEN_MIN_CHANGE` of their samples are
    judged; a signal constant throughout is ``signal_varies``'s, one flat at its extremes
    ``signal_clipped``'s.
    """
    names = [str(v) for v in ds.data_vars
             if (str(v) in ADC_SIGNALS or str(v) in DAC_SIGNALS or str(v) == "Va")
             and _in_memory(ds[v].data)]
    if not names or TIME not in ds:
        return []
    t = np.asarray(ds[TIME].values, dtype=float)
    x = {v: np.asarray(ds[v].values, dtype=float) for v in names}
    n = t.size
    runs = {v: _longest_run(s) for v, s in x.items() if s.size == n and n > 1}
    noisy = [v for v, (_s, _l, p) in runs.items() if p >= FROZEN_MIN_CHANGE
             and v not in DAC_SIGNALS]
    out: list[Check] = []
    padded = min((_trailing_zeros(s) for s in x.values()), default=0)
    if noisy and padded >= _FROZEN_MIN_SAMPLES and padded < n and len(x) >= 2:
        i0 = n - padded
        out.append(Check(
            "record_padded", False, f"{padded} samples", "no run of zeros on every signal at "
            "the record's end", f"{label}: {', '.join(names)}",
            f"every signal is exactly zero for its last {padded} samples ({100 * padded / n:.3g} "
            f"% of the record, from {_when(t, i0)}) while t runs on, where "
            f"{', '.join(noisy)} change{'s' if len(noisy) == 1 else ''} on most samples before: "
            "zeros padded after the record's end (a preallocated buffer the acquisition never "
            f"filled); cut the record at t = {_when(t, i0)} or record it again"))
        return out
    for v in noisy:
        start, length, p = runs[v]
        s = x[v]
        value = float(s[start])
        if value in (float(np.min(s)), float(np.max(s))):
            continue  # flat at an extreme: signal_clipped's
        if start == 0:
            continue  # a channel that started late (delayed): the lag checks judge it
        odds = math.log10(n) + length * math.log10(max(1.0 - p, 1e-300))
        if length < _FROZEN_MIN_SAMPLES or odds >= math.log10(FROZEN_ODDS):
            continue
        unit = "m" if v == "Va" else "V"
        out.append(Check(
            "signal_frozen", False, float(length), f"a run of equal samples chance gives in "
            f"fewer than 1 record in {1 / FROZEN_ODDS:.0e}", f"{label}: {v}",
            f"{v} holds one value ({value:.6g} {unit}) for {length} samples "
            f"({100 * length / n:.3g} % of the record, from {_when(t, start)} to "
            f"{_when(t, start + length)}) where it changes on {100 * p:.0f} % of its samples "
            "elsewhere: the channel was stuck (a dead input, a stalled acquisition or a "
            "buffer repeated); every estimate through it would be biased: record it again",
            unit="samples"))
    return out
