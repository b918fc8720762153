"""The device's JSON command arguments, checked: one line saying what is wrong, or a value."""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

import numpy as np

from fsmbench.live.backend import LIVE_SIGNALS
from fsmbench.sim.excitation import Excitation
from fsmbench.sim.plant import DAC_CHANNELS

__all__ = ["RecordRequest", "parse_excitation", "parse_record"]


def _json(argument: str, command: str, example: str) -> dict[str, Any]:
    try:
        doc = json.loads(argument)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{command}: the argument is not valid JSON ({exc})") from None
    if not isinstance(doc, dict):
        raise ValueError(f"{command}: give {example}")
    return doc


@dataclass(frozen=True)
class RecordRequest:
    """What ``Record`` was asked for.

    Attributes
    ----------
    signals : tuple of str
    duration_s : float
        [s]
    name : str
        File stem.
    suffix : str
        ``.mat`` (MATLAB v7) or ``.h5`` (NeXus).
    """

    signals: tuple[str, ...]
    duration_s: float
    name: str
    suffix: str


def parse_record(argument: str) -> RecordRequest:
    """``{"signals": [...], "duration_s": s, "name": ..., "format": "mat"|"nexus"}``."""
    doc = _json(argument, "Record", '{"signals": [...], "duration_s": seconds}')
    signals = doc.get("signals", list(LIVE_SIGNALS))
    if not isinstance(signals, list) or not signals:
        raise ValueError("Record: signals must be a non-empty list of names")
    unknown = [s for s in signals if s not in LIVE_SIGNALS]
    if unknown:
        raise ValueError(f"Record: unknown signal(s) {', '.join(map(str, unknown))}; known: "
                         f"{', '.join(LIVE_SIGNALS)}")
    duration = doc.get("duration_s")
    if not isinstance(duration, (int, float)) or not 0 < duration <= 3600:
        raise ValueError(f"Record: duration_s must be a number of seconds in (0, 3600], "
                         f"got {duration!r}")
    fmt = doc.get("format", "mat")
    if fmt not in ("mat", "nexus"):
        raise ValueError(f"Record: format must be 'mat' or 'nexus', got {fmt!r}")
    name = str(doc.get("name", "record"))
    if not name.replace("_", "").replace("-", "").isalnum():
        raise ValueError(f"Record: name {name!r} must be letters, digits, - and _")
    return RecordRequest(signals=tuple(str(s) for s in signals), duration_s=float(duration),
                         name=name, suffix=".mat" if fmt == "mat" else ".h5")


_KINDS = ("noise", "sine", "multisine")


def parse_excitation(argument: str, *, start_s: float, half_range_v: float) -> Excitation:
    """An :class:`~fsmbench.sim.excitation.Excitation` from the device's JSON argument.

    ``{"input": "Uch", "kind": "noise"|"sine"|"multisine", "amplitude_v": V,
    "band_hz": [low, high], "frequency_hz": f, "period_s": T}``: ``amplitude_v``
    is the standard deviation (noise), the amplitude (sine) or the rms
    (multisine); ``band_hz`` limits noise and multisines; ``frequency_hz`` is
    the sine's; ``period_s`` the multisine's (default 1 s).
    """
    doc = _json(argument, "StartExcitation",
                '{"input": "Uch", "kind": "noise", "amplitude_v": 0.02}')
    channel = doc.get("input")
    if channel not in DAC_CHANNELS:
        raise ValueError(f"StartExcitation: unknown input {channel!r}; the DAC drives "
                         f"{', '.join(DAC_CHANNELS)}")
    kind = doc.get("kind", "noise")
    if kind not in _KINDS:
        raise ValueError(f"StartExcitation: unknown kind {kind!r}; known: {', '.join(_KINDS)}")
    amp = doc.get("amplitude_v")
    if not isinstance(amp, (int, float)) or not np.isfinite(amp) or amp <= 0:
        raise ValueError(f"StartExcitation: amplitude_v must be a positive number of volts, "
                         f"got {amp!r}")
    band = doc.get("band_hz")
    if band is not None:
        numbers = isinstance(band, list) and len(band) == 2 \
            and all(isinstance(b, (int, float)) for b in band)
        if not numbers or not 0 <= band[0] < band[1]:
            raise ValueError(f"StartExcitation: band_hz must be [low, high] in Hz with "
                             f"0 <= low < high, got {band!r}")
        band = (float(band[0]), float(band[1]))
    freq = float(doc.get("frequency_hz", 0.0))
    if kind == "sine" and not freq > 0:
        raise ValueError("StartExcitation: a sine needs frequency_hz > 0")
    ex = Excitation(channel=str(channel), kind=kind, amplitude_v=float(amp), start_s=start_s,
                    freq_hz=freq, band_hz=band, period_s=float(doc.get("period_s", 1.0)))
    if ex.kind != "multisine" and ex.peak_v() > half_range_v:
        what = "4.5 standard deviations" if kind == "noise" else "the amplitude"
        raise ValueError(f"StartExcitation: {what} of {ex.peak_v():.3g} V would saturate the "
                         f"DAC (+/-{half_range_v:g} V) on {channel}")
    return ex
