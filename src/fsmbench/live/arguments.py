"""The device's command arguments, checked against the bench: one sentence, or a value.

Every number is bounded before it reaches the loop: frequencies below
Nyquist, finite positive periods of a whole number of samples, durations
and names the disk and the filesystem can take (the disk itself is checked
when the file is planned, :mod:`fsmbench.live.jobs`). Unknown keys are
refused, so a misspelt key is never silently ignored.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from typing import Any

import numpy as np

from fsmbench.live.backend import LIVE_SIGNALS
from fsmbench.live.states import Refused
from fsmbench.sim.excitation import Excitation, SampledExcitation
from fsmbench.sim.plant import DAC_CHANNELS

__all__ = ["MAX_NAME_CHARS", "MAX_PERIOD_S", "MAX_RECORD_S", "MAX_SAMPLES", "MIN_PERIOD_S",
           "ExperimentRequest",
           "RecordRequest", "check_name", "parse_excitation", "parse_experiment",
           "parse_record"]

#: Longest Record duration [s] (an hour: with streaming, bounded by the disk, not memory).
MAX_RECORD_S = 3600.0
#: Multisine periods [s]: at least 100 samples at 10 kHz, at most 10^6 samples
#: (8 MB per design array; 10^5 s took the device to 15 GB).
MIN_PERIOD_S = 0.01
MAX_PERIOD_S = 100.0
#: Longest file stem: far below every filesystem's 255-byte limit with the suffix and
#: the staging prefix.
MAX_NAME_CHARS = 100
_NAME = re.compile(r"[A-Za-z0-9_-]+")


def _bad(command: str, text: str) -> Refused:
    return Refused("FSM_BadArgument", f"{command} refused: {text}")


def _json(argument: str, command: str, example: str, keys: tuple[str, ...]) -> dict[str, Any]:
    try:
        doc = json.loads(argument)
    except json.JSONDecodeError as exc:
        raise _bad(command, f"the argument is not valid JSON ({exc}); give {example}") from None
    except RecursionError:  # "[[[[…]]]]" thousands deep: the parser's stack, not a bug
        raise _bad(command, f"the argument's JSON nests too deeply; give {example}") from None
    if not isinstance(doc, dict):
        raise _bad(command, f"give {example}")
    unknown = sorted(set(doc) - set(keys))
    if unknown:
        raise _bad(command, f"unknown key(s) {', '.join(map(repr, unknown))}; known: "
                            f"{', '.join(keys)}")
    return doc


def _number(doc: dict[str, Any], key: str) -> float | None:
    """A JSON number as float (None when absent); booleans and NaN are not numbers."""
    value = doc.get(key)
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or \
            not math.isfinite(value):
        return math.nan
    return float(value)


def check_name(command: str, name: object) -> str:
    """A file stem: ASCII letters, digits, ``-`` and ``_``, 1 to :data:`MAX_NAME_CHARS` long."""
    if not isinstance(name, str) or not _NAME.fullmatch(name):
        raise _bad(command, f"name {name!a} must be ASCII letters, digits, - and _ (no "
                            "spaces, accents or path separators)")
    if len(name) > MAX_NAME_CHARS:
        raise _bad(command, f"name of {len(name)} characters is too long for a file name "
                            f"(at most {MAX_NAME_CHARS})")
    return name


@dataclass(frozen=True)
class RecordRequest:
    """What ``Record`` was asked for.

    Attributes
    ----------
    signals : tuple of str
    duration_s : float
        [s] of bench time.
    name : str
        File stem.
    format : {"mat", "nexus"}
        MATLAB v7 (``.mat``, written at the end from the streamed NeXus) or
        NeXus (``.h5``, streamed as it runs).
    overwrite : bool
        Replace an existing file of that name.
    """

    signals: tuple[str, ...]
    duration_s: float
    name: str
    format: str
    overwrite: bool = False

    @property
    def suffix(self) -> str:
        """``.mat`` or ``.h5``."""
        return ".mat" if self.format == "mat" else ".h5"


def parse_record(argument: str, *, fs_hz: float) -> RecordRequest:
    """``{"signals": [...], "duration_s": s, "name": ..., "format": "mat"|"nexus",
    "overwrite": false}``."""
    doc = _json(argument, "Record", '{"signals": [...], "duration_s": seconds}',
                ("signals", "duration_s", "name", "format", "overwrite"))
    signals = doc.get("signals", list(LIVE_SIGNALS))
    if not isinstance(signals, list) or not signals or \
            not all(isinstance(s, str) for s in signals):
        raise _bad("Record", "signals must be a non-empty list of names")
    unknown = [s for s in signals if s not in LIVE_SIGNALS]
    if unknown:
        raise _bad("Record", f"unknown signal(s) {', '.join(map(str, unknown))}; known: "
                             f"{', '.join(LIVE_SIGNALS)}")
    if len(set(signals)) != len(signals):
        raise _bad("Record", "a signal is listed twice")
    duration = _number(doc, "duration_s")
    if duration is None or not 0 < duration <= MAX_RECORD_S or round(duration * fs_hz) < 1:
        raise _bad("Record", f"duration_s must be a number of seconds in (0, "
                             f"{MAX_RECORD_S:g}] of at least one sample, got "
                             f"{doc.get('duration_s')!r}")
    fmt = doc.get("format", "mat")
    if fmt not in ("mat", "nexus"):
        raise _bad("Record", f"format must be 'mat' or 'nexus', got {fmt!r}")
    overwrite = doc.get("overwrite", False)
    if not isinstance(overwrite, bool):
        raise _bad("Record", f"overwrite must be true or false, got {overwrite!r}")
    return RecordRequest(signals=tuple(signals), duration_s=duration,
                         name=check_name("Record", doc.get("name", "record")), format=fmt,
                         overwrite=overwrite)


@dataclass(frozen=True)
class ExperimentRequest:
    """What ``RunExperiment`` was asked for: the experiment and whether to replace its file.

    Attributes
    ----------
    name : str
    overwrite : bool
    """

    name: str
    overwrite: bool = False


def parse_experiment(argument: str, known: tuple[str, ...]) -> ExperimentRequest:
    """``data_uch`` or ``{"name": "data_uch", "overwrite": true}``."""
    text = argument.strip()
    if text.startswith("{"):
        doc = _json(text, "RunExperiment", '{"name": "data_uch"}', ("name", "overwrite"))
        name, overwrite = doc.get("name"), doc.get("overwrite", False)
        if not isinstance(overwrite, bool):
            raise _bad("RunExperiment", f"overwrite must be true or false, got {overwrite!r}")
    else:
        name, overwrite = text, False
    if name not in known:
        raise _bad("RunExperiment", f"unknown experiment {name!r}; known: {', '.join(known)}")
    return ExperimentRequest(name=str(name), overwrite=overwrite)


_KINDS = ("noise", "sine", "multisine", "samples")
#: Most samples a ``samples`` excitation may hold (1000 s at 10 kHz, 80 MB).
MAX_SAMPLES = 10_000_000


def _samples(doc: dict[str, Any], channel: str, start_s: float,
             half_range_v: float) -> SampledExcitation:
    """A ``samples`` excitation: a 1-D ``.npy`` of float commands [V] at the bench's rate."""
    cmd = "StartExcitation"
    path = doc.get("path")
    if not isinstance(path, str) or not path.endswith(".npy"):
        raise _bad(cmd, f"a samples excitation needs path, a .npy file of commands in V, got "
                        f"{path!r}")
    for key in ("amplitude_v", "band_hz", "frequency_hz", "period_s"):
        if key in doc:
            raise _bad(cmd, f"{key} is not for a samples excitation (the file holds the "
                            "commands)")
    try:
        x = np.load(path, allow_pickle=False, mmap_mode="r")
    except (OSError, ValueError) as exc:
        raise _bad(cmd, f"{path}: not a readable .npy file ({exc})") from None
    if x.ndim != 1 or not 0 < x.size <= MAX_SAMPLES or x.dtype.kind != "f":
        raise _bad(cmd, f"{path}: holds {x.dtype} of shape {x.shape}; give 1 to "
                        f"{MAX_SAMPLES} float commands in V")
    x = np.array(x, dtype=float)
    if not np.all(np.isfinite(x)):
        raise _bad(cmd, f"{path}: holds commands that are not finite")
    peak = float(np.max(np.abs(x)))
    if peak > half_range_v:
        raise _bad(cmd, f"{path}: its commands reach {peak:.3g} V, beyond the DAC's "
                        f"+/-{half_range_v:g} V")
    loop_from = doc.get("loop_from")
    if loop_from is not None and (isinstance(loop_from, bool) or not isinstance(loop_from, int)
                                  or not 0 <= loop_from < x.size):
        raise _bad(cmd, f"loop_from must be a sample index in [0, {x.size}) (the samples "
                        f"repeated from there after the end), got {loop_from!r}")
    return SampledExcitation(channel=channel, kind="samples",
                             amplitude_v=float(np.sqrt(np.mean(x**2))), start_s=start_s,
                             samples_v=x, loop_from=loop_from)


def _band(doc: dict[str, Any], cmd: str, *, kind: str,
          fs_hz: float) -> tuple[float, float] | None:
    """``band_hz`` checked: [low, high] in Hz, below Nyquist, not for a sine."""
    nyquist = fs_hz / 2
    band = doc.get("band_hz")
    if band is not None:
        if kind == "sine":
            raise _bad(cmd, "a sine has frequency_hz, not band_hz")
        numbers = isinstance(band, list) and len(band) == 2 and all(
            not isinstance(b, bool) and isinstance(b, (int, float)) and math.isfinite(b)
            for b in band)
        if not numbers or not 0 <= band[0] < band[1]:
            raise _bad(cmd, f"band_hz must be [low, high] in Hz with 0 <= low < high, got "
                            f"{band!r}")
        if band[1] > nyquist:
            raise _bad(cmd, f"band_hz {band!r} goes above Nyquist ({nyquist:g} Hz at "
                            f"{fs_hz:g} Hz sampling)")
        band = (float(band[0]), float(band[1]))
    return band


def _period(doc: dict[str, Any], cmd: str, *, kind: str,
            band: tuple[float, float] | None, amp: float, fs_hz: float,
            half_range_v: float) -> float | None:
    """A multisine's ``period_s`` checked (default 1 s): a whole number of samples, a line
    in the band, a peak within the DAC's range; None for another kind."""
    nyquist = fs_hz / 2
    period = _number(doc, "period_s")
    if kind == "multisine":
        period = 1.0 if period is None else period
        if not MIN_PERIOD_S <= period <= MAX_PERIOD_S:
            raise _bad(cmd, f"period_s must be a number of seconds in [{MIN_PERIOD_S:g}, "
                            f"{MAX_PERIOD_S:g}], got {doc.get('period_s')!r}")
        n = period * fs_hz
        if abs(n - round(n)) > 1e-6 * n:
            raise _bad(cmd, f"period_s {period:g} s is not a whole number of samples at "
                            f"{fs_hz:g} Hz")
        lo, hi = band if band is not None else (0.0, nyquist)
        if math.floor(min(hi, nyquist * (1 - 1e-9)) * period) < max(1, math.ceil(lo * period)):
            raise _bad(cmd, f"no multisine line (multiples of 1/period_s = {1 / period:g} Hz) "
                            f"falls in the band [{lo:g}, {hi:g}] Hz")
        # No phases give a multisine a crest factor below sqrt(2) (one line: a sine).
        if amp * math.sqrt(2) > half_range_v:
            raise _bad(cmd, f"a multisine of {amp:g} V rms peaks at least at "
                            f"{amp * math.sqrt(2):.3g} V, beyond the DAC's +/-{half_range_v:g} V")
    elif period is not None:
        raise _bad(cmd, f"period_s is for a multisine, not a {kind}")
    return period


def parse_excitation(argument: str, *, start_s: float, half_range_v: float,
                     fs_hz: float) -> Excitation:
    """An :class:`~fsmbench.sim.excitation.Excitation` from the device's JSON argument.

    ``{"input": "Uch", "kind": "noise"|"sine"|"multisine", "amplitude_v": V,
    "band_hz": [low, high], "frequency_hz": f, "period_s": T}``: ``amplitude_v``
    is the standard deviation (noise), the amplitude (sine) or the rms
    (multisine); ``band_hz`` limits noise and multisines (up to Nyquist);
    ``frequency_hz`` is the sine's (below Nyquist); ``period_s`` the
    multisine's (default 1 s, a whole number of samples in
    [:data:`MIN_PERIOD_S`, :data:`MAX_PERIOD_S`]).

    ``{"input": "Uch", "kind": "samples", "path": "x.npy", "loop_from": i}``: the
    commands of a 1-D ``.npy`` file [V] one per sample from now, then
    ``samples[i:]`` repeated (zeros without ``loop_from``): a designed excitation,
    e.g. ``fsmbench tune``'s beam-bounded multisines with the loop closed.
    """
    cmd = "StartExcitation"
    doc = _json(argument, cmd, '{"input": "Uch", "kind": "noise", "amplitude_v": 0.02}',
                ("input", "kind", "amplitude_v", "band_hz", "frequency_hz", "period_s", "path",
                 "loop_from"))
    nyquist = fs_hz / 2
    channel = doc.get("input")
    if channel not in DAC_CHANNELS:
        raise _bad(cmd, f"unknown input {channel!r}; the DAC drives {', '.join(DAC_CHANNELS)}")
    kind = doc.get("kind", "noise")
    if kind not in _KINDS:
        raise _bad(cmd, f"unknown kind {kind!r}; known: {', '.join(_KINDS)}")
    if kind == "samples":
        return _samples(doc, str(channel), start_s, half_range_v)
    for key in ("path", "loop_from"):
        if key in doc:
            raise _bad(cmd, f"{key} is for a samples excitation, not a {kind}")
    amp = _number(doc, "amplitude_v")
    if amp is None or not amp > 0:
        raise _bad(cmd, f"amplitude_v must be a positive number of volts, got "
                        f"{doc.get('amplitude_v')!r}")
    band = _band(doc, cmd, kind=kind, fs_hz=fs_hz)
    freq = _number(doc, "frequency_hz")
    if kind == "sine":
        if freq is None or not 0 < freq < nyquist:
            raise _bad(cmd, f"a sine needs frequency_hz in (0, {nyquist:g}) Hz (below "
                            f"Nyquist), got {doc.get('frequency_hz')!r}")
    elif freq is not None:
        raise _bad(cmd, f"frequency_hz is for a sine, not a {kind}")
    period = _period(doc, cmd, kind=kind, band=band, amp=amp, fs_hz=fs_hz,
                     half_range_v=half_range_v)
    ex = Excitation(channel=str(channel), kind=kind, amplitude_v=amp, start_s=start_s,
                    freq_hz=freq or 0.0, band_hz=band, period_s=period or 1.0)
    if ex.kind != "multisine" and ex.peak_v() > half_range_v:
        what = "4.5 standard deviations" if kind == "noise" else "the amplitude"
        raise _bad(cmd, f"{what} of {ex.peak_v():.3g} V would saturate the DAC "
                        f"(+/-{half_range_v:g} V) on {channel}")
    return ex
