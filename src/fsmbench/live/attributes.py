"""The live bench's attributes as one protocol-neutral table: Tango and EPICS read it alike.

Each :class:`AttributeSpec` says what a value is (its reader on
:class:`~fsmbench.live.core.LiveBench`, in SI), how it is shown (display
unit and scale, format), when it is WARNING or ALARM (:class:`Limits`, with
a hysteresis), and when it is sent (:class:`Events`: change and archive
criteria, polling). The Tango device turns a row into an attribute
(``unit``, ``format``, ``min_alarm``…, ``abs_change``, ``archive_period``…),
the EPICS IOC into a record (``EGU``, ``PREC``, ``HOPR``/``LOPR``,
``HIHI``/``HIGH``/``LOW``/``LOLO`` with ``HYST``, ``MDEL``/``ADEL``), so the
limits and units are the same on both.

Quality (:func:`evaluate`): INVALID when the value is not current (the loop
stalled or died, the lock was not free) or not finite; ALARM/WARNING from
the limits, entered at the limit and left only ``hysteresis`` inside it;
VALID otherwise.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from fsmbench.live.core import LiveBench

__all__ = ["ATTRIBUTES", "PUSHED", "QUALITIES", "AttributeSpec", "Events", "Limits",
           "QualityLatch", "by_name", "ca_units", "evaluate", "precision", "readme_table"]

QUALITIES = ("VALID", "WARNING", "ALARM", "INVALID")
#: Views the bench pushes itself when they change (LiveBench.on_change), with State and
#: Status; the others are polled.
PUSHED = ("LoopClosed", "Controller", "Excitation", "SpeedFactor", "Task", "WatchVerdict",
          "WatchCause")
#: Points of the ASD and FRF spectra at 10 kHz with a 1 s window (nfft 16384).
MAX_SPECTRUM = 100_000


@dataclass(frozen=True)
class Limits:
    """Warning and alarm limits in display units (None: no such limit).

    Attributes
    ----------
    low_alarm, low_warning, high_warning, high_alarm : float or None
    hysteresis : float
        How far inside a limit a value must come back to leave it [display unit].
    """

    low_alarm: float | None = None
    low_warning: float | None = None
    high_warning: float | None = None
    high_alarm: float | None = None
    hysteresis: float = 0.0

    def level(self, value: float, *, margin: float = 0.0) -> int:
        """0 valid, 1 warning, 2 alarm; ``margin`` moves every limit inward."""
        def beyond(low: float | None, high: float | None) -> bool:
            return (low is not None and value < low + margin) or \
                (high is not None and value > high - margin)

        if beyond(self.low_alarm, self.high_alarm):
            return 2
        if beyond(self.low_warning, self.high_warning):
            return 1
        return 0


@dataclass(frozen=True)
class Events:
    """When an attribute is sent (display units; None: no such criterion).

    Attributes
    ----------
    abs_change, rel_change : float or None
        Change event when the value moves this much (rel: in %).
    archive_abs_change, archive_rel_change : float or None
        Archive event (HDB++; EPICS ``ADEL``) when it moves this much.
    archive_period_ms : int or None
        Archive event at least this often [ms].
    polling_ms : int or None
        Tango polling period [ms] (None: pushed by the bench, :data:`PUSHED`).
    period_ms : int
        Periodic event period [ms].
    """

    abs_change: float | None = None
    rel_change: float | None = None
    archive_abs_change: float | None = None
    archive_rel_change: float | None = None
    archive_period_ms: int | None = 60_000
    polling_ms: int | None = 1000
    period_ms: int = 1000


@dataclass(frozen=True)
class AttributeSpec:
    """One attribute (Tango) / PV (EPICS) of the live bench.

    Attributes
    ----------
    name : str
        Tango attribute name, and the PV name after ``PREFIX:``.
    kind : {"float", "int", "bool", "str", "spectrum", "image"}
    read : callable
        ``read(bench)``: the value in SI (run under the bench's lock).
    doc : str
    unit : str
        Display unit (Tango ``unit``; Latin-1).
    egu : str
        The same in ASCII (EPICS ``EGU``).
    scale : float
        Display value = SI value × scale.
    fmt : str
        printf format of the display value.
    limits : Limits
    events : Events
    display : tuple of float, optional
        Display range (EPICS ``LOPR``, ``HOPR``).
    writable : bool
    min_value, max_value : float, optional
        Write limits (display units).
    rows : tuple of str
        Row names of an image (EPICS: one waveform per row, ``<name><row>``).
    """

    name: str
    kind: str
    read: Callable[[LiveBench], Any] = field(repr=False, compare=False)
    doc: str
    unit: str = ""
    egu: str = ""
    scale: float = 1.0
    fmt: str = ""
    limits: Limits = Limits()
    events: Events = Events()
    display: tuple[float, float] | None = None
    writable: bool = False
    min_value: float | None = None
    max_value: float | None = None
    rows: tuple[str, ...] = ()

    @property
    def standard_unit(self) -> str:
        """SI per display unit (Tango ``standard_unit``), e.g. ``1e-06`` for µrad."""
        return f"{1.0 / self.scale:g}"


def precision(fmt: str) -> int:
    """Digits after the point of a printf format (EPICS ``PREC``; 0 without one)."""
    m = re.search(r"\.(\d+)[efg]", fmt)
    return int(m.group(1)) if m else 0


def _frf(what: str) -> Callable[[LiveBench], Any]:
    def read(b: LiveBench) -> np.ndarray:
        snap = b.frf()
        if snap is None:
            return np.zeros(0) if what == "frequency" else np.zeros((0, 0))
        if what == "magnitude":
            return np.abs(snap.h1)
        if what == "phase":
            return np.degrees(np.angle(snap.h1))
        if what == "frequency":
            return np.asarray(snap.frequency_hz)
        return np.asarray(snap.coherence)
    return read


_ANGLE = Limits(low_alarm=-150_000.0, low_warning=-50_000.0, high_warning=50_000.0,
                high_alarm=150_000.0, hysteresis=5_000.0)
_ANGLE_EVENTS = Events(abs_change=1.0, archive_abs_change=10.0)
_TRACKING = Limits(high_warning=100.0, high_alarm=1000.0, hysteresis=10.0)
_TRACKING_EVENTS = Events(abs_change=1.0, rel_change=5.0, archive_abs_change=5.0,
                          archive_rel_change=20.0)
_SPECTRUM = Events(polling_ms=None)

ATTRIBUTES: tuple[AttributeSpec, ...] = (
    AttributeSpec("BeamAngleH", "float", lambda b: b.monitor.beam_angle_rad()[0],
                  "horizontal beam angle on the 4QD (its voltage over the calibrated gain), "
                  "mean over the last 0.1 s", "µrad", "urad", 1e6, "%.3f", _ANGLE,
                  _ANGLE_EVENTS, (-300_000.0, 300_000.0)),
    AttributeSpec("BeamAngleV", "float", lambda b: b.monitor.beam_angle_rad()[1],
                  "vertical beam angle on the 4QD, mean over the last 0.1 s", "µrad", "urad",
                  1e6, "%.3f", _ANGLE, _ANGLE_EVENTS, (-300_000.0, 300_000.0)),
    AttributeSpec("Distance", "float", lambda b: b.monitor.distance_m(),
                  "Attocube distance Va, mean over the last 0.1 s (INVALID when the played "
                  "file has no Va)", "nm", "nm", 1e9, "%.3f",
                  events=Events(abs_change=1.0, archive_abs_change=10.0),
                  display=(-1000.0, 1000.0)),
    AttributeSpec("TrackingErrorRmsH", "float", lambda b: b.monitor.tracking_rms_rad()[0],
                  "rms of the horizontal beam angle about its mean over the last 1 s", "µrad",
                  "urad", 1e6, "%.3f", _TRACKING, _TRACKING_EVENTS, (0.0, 2000.0)),
    AttributeSpec("TrackingErrorRmsV", "float", lambda b: b.monitor.tracking_rms_rad()[1],
                  "rms of the vertical beam angle about its mean over the last 1 s", "µrad",
                  "urad", 1e6, "%.3f", _TRACKING, _TRACKING_EVENTS, (0.0, 2000.0)),
    AttributeSpec("DacSaturation", "float", lambda b: b.monitor.dac_saturation(),
                  "share of the last 1 s with Uch or Ucv on a DAC rail", "%", "%", 100.0,
                  "%.1f", Limits(high_warning=1.0, high_alarm=10.0, hysteresis=0.5),
                  Events(abs_change=0.1, archive_abs_change=1.0), (0.0, 100.0)),
    AttributeSpec("BenchTime", "float", lambda b: b.bench_time_s,
                  "bench time since the server started (INVALID when the loop stalls)", "s",
                  "s", 1.0, "%.3f",
                  events=Events(abs_change=1.0, archive_abs_change=60.0)),
    AttributeSpec("Heartbeat", "int", lambda b: b.heartbeat,
                  "blocks the bench loop has run (it stops when the loop stalls)", "", "",
                  1.0, "%d", events=Events(abs_change=1.0, archive_abs_change=1000.0)),
    AttributeSpec("LoopLag", "float", lambda b: b.loop_lag_s,
                  "wall-clock time since the bench loop last advanced (the watchdog's FAULT "
                  "at its limit, 5 s by default)", "s", "s", 1.0, "%.2f",
                  Limits(high_warning=1.0, high_alarm=5.0, hysteresis=0.2),
                  Events(abs_change=0.5, archive_abs_change=1.0), (0.0, 10.0)),
    AttributeSpec("Progress", "float", lambda b: b.progress_percent / 100.0,
                  "progress of the running recording, experiment or task (100 when idle)",
                  "%", "%", 100.0, "%.0f", events=Events(abs_change=1.0,
                                                         archive_abs_change=25.0),
                  display=(0.0, 100.0)),
    AttributeSpec("SpeedFactor", "float", lambda b: b.speed,
                  "bench seconds per wall-clock second (1: real time)", "", "", 1.0, "%.3g",
                  events=Events(abs_change=1e-6, archive_abs_change=1e-6, polling_ms=None),
                  display=(0.01, 100.0), writable=True, min_value=0.01, max_value=100.0),
    AttributeSpec("SpeedReached", "float", lambda b: b.speed_reached,
                  "bench seconds per wall-clock second the loop ran over the last 2 s (below "
                  "90 % of SpeedFactor, a busy machine: a WARNING in the log; INVALID until "
                  "1 s has run)", "", "", 1.0, "%.3g",
                  events=Events(abs_change=0.05, archive_abs_change=0.5),
                  display=(0.0, 100.0)),
    AttributeSpec("LoopClosed", "bool", lambda b: b.loop_closed, "the Sercalo loop is closed",
                  events=Events(polling_ms=None)),
    AttributeSpec("Controller", "str", lambda b: b.controller_name,
                  "controller in the loop, or loaded for the next CloseLoop",
                  events=Events(polling_ms=None)),
    AttributeSpec("Excitation", "str", lambda b: b.excitation_text,
                  "the running excitation as JSON ({} when none)",
                  events=Events(polling_ms=None)),
    AttributeSpec("Task", "str", lambda b: b.task_text,
                  "work running off the client's call (designing an excitation); empty when "
                  "none", events=Events(polling_ms=None)),
    AttributeSpec("ControllersPath", "str", lambda b: str(b.controllers_folder),
                  "the only folder LoadController reads controller files from (absolute; a "
                  "relative path is taken inside it)", events=Events(polling_ms=None)),
    AttributeSpec("WatchVerdict", "str", lambda b: b.watch_view.verdict,
                  "the loop watching itself: off (loop open), waiting, calibrating, within the "
                  "prediction, or WARNING since a bench time (State ALARM; hysteresis: 3 "
                  "windows of 10 s to raise, 3 to clear)", events=Events(polling_ms=None)),
    AttributeSpec("WatchCause", "str", lambda b: b.watch_view.cause,
                  "the warning's likely cause (a resonance moved, a new line, the noise "
                  "floor), with what to do (fsmbench tune); empty without a warning",
                  events=Events(polling_ms=None)),
    AttributeSpec("WatchDeparture", "float", lambda b: b.watch_view.departure_sigma,
                  "largest departure of the last 10 s window's tracking error from the "
                  "loaded controller's prediction, in units of its statistical scatter "
                  "(INVALID until a window is judged)", "sigma", "sigma", 1.0, "%.2f",
                  events=Events(abs_change=0.5, archive_abs_change=2.0),
                  display=(-10.0, 50.0)),
    AttributeSpec("AsdFrequency", "spectrum", lambda b: b.asd_frequency(),
                  "frequencies of AsdVph, AsdVpv and AsdVa", "Hz", "Hz", 1.0, "%.2f",
                  events=_SPECTRUM),
    AttributeSpec("AsdVph", "spectrum", lambda b: b.asd("Vph"),
                  "ASD of Vph, Welch 1 s Hann over the last 10 s, updated every second",
                  "V/sqrt(Hz)", "V/sqrt(Hz)", 1.0, "%.3e", events=_SPECTRUM),
    AttributeSpec("AsdVpv", "spectrum", lambda b: b.asd("Vpv"),
                  "ASD of Vpv, Welch 1 s Hann over the last 10 s, updated every second",
                  "V/sqrt(Hz)", "V/sqrt(Hz)", 1.0, "%.3e", events=_SPECTRUM),
    AttributeSpec("AsdVa", "spectrum", lambda b: b.asd("Va"),
                  "ASD of Va, Welch 1 s Hann over the last 10 s, updated every second",
                  "nm/sqrt(Hz)", "nm/sqrt(Hz)", 1e9, "%.3e", events=_SPECTRUM),
    AttributeSpec("FrfFrequency", "spectrum", _frf("frequency"),
                  "frequencies of the live FRF", "Hz", "Hz", 1.0, "%.2f", events=_SPECTRUM),
    AttributeSpec("FrfMagnitude", "image", _frf("magnitude"),
                  "|H1| from the excited input to Vph (row 0) and Vpv (row 1)", "V/V", "V/V",
                  1.0, "%.3e", events=_SPECTRUM, rows=("Vph", "Vpv")),
    AttributeSpec("FrfPhase", "image", _frf("phase"),
                  "phase of H1 from the excited input to Vph (row 0) and Vpv (row 1)", "deg",
                  "deg", 1.0, "%.1f", events=_SPECTRUM, rows=("Vph", "Vpv")),
    AttributeSpec("FrfCoherence", "image", _frf("coherence"),
                  "magnitude-squared coherence, excited input to Vph (row 0) and Vpv (row 1)",
                  "", "", 1.0, "%.3f", events=_SPECTRUM, rows=("Vph", "Vpv")),
)


def by_name(name: str) -> AttributeSpec:
    """The row of ``name``."""
    for spec in ATTRIBUTES:
        if spec.name == name:
            return spec
    raise KeyError(name)


class QualityLatch:
    """The quality each attribute had, for the hysteresis (one per device or IOC)."""

    def __init__(self) -> None:
        self._level: dict[str, int] = {}

    def next(self, spec: AttributeSpec, value: float) -> str:
        """VALID, WARNING or ALARM for ``value`` (display units), with hysteresis."""
        raw = spec.limits.level(value)
        held = min(self._level.get(spec.name, 0),
                   spec.limits.level(value, margin=spec.limits.hysteresis))
        level = max(raw, held)
        self._level[spec.name] = level
        return QUALITIES[level]


def evaluate(spec: AttributeSpec, bench: LiveBench, latch: QualityLatch) -> tuple[Any, str]:
    """``(display value, quality)`` of one attribute now (see the module notes).

    The value is None when INVALID for want of a current reading.
    """
    value, current = bench.read(spec.read)
    if value is None:
        return None, "INVALID"
    if spec.kind in ("spectrum", "image"):
        arr = np.asarray(value, dtype=float) * spec.scale
        return arr, "VALID" if current else "INVALID"
    if spec.kind in ("bool", "str"):
        return value, "VALID"
    x = float(value) * spec.scale
    if not current or not math.isfinite(x):
        return x, "INVALID"
    return (int(value) if spec.kind == "int" else x), latch.next(spec, x)


def _num(x: float | None) -> str:
    return "–" if x is None else f"{x:g}"


def ca_units(egu: str) -> str:
    """``egu`` as Channel Access carries it: at most 7 characters (``MAX_UNITS_SIZE`` of a
    DBR_CTRL reply is 8 with its NUL; ``V/sqrt(Hz)`` reached clients as ``V/sqrt(``)."""
    short = egu.replace("sqrt(Hz)", "rtHz")
    if len(short) > 7:
        raise ValueError(f"unit {egu!r} has no Channel Access form of 7 characters")
    return short


def readme_table() -> str:
    """The attribute configuration table of the README (Markdown), from :data:`ATTRIBUTES`."""
    lines = ["| attribute / PV | type | unit (EPICS EGU) | format | warning | alarm | "
             "change event | archive event | meaning |",
             "|---|---|---|---|---|---|---|---|---|"]
    for s in ATTRIBUTES:
        lim, ev = s.limits, s.events
        warn = alarm = "–"
        if lim.high_warning is not None or lim.low_warning is not None:
            warn = f"< {_num(lim.low_warning)} or > {_num(lim.high_warning)}" \
                if lim.low_warning is not None else f"> {_num(lim.high_warning)}"
        if lim.high_alarm is not None or lim.low_alarm is not None:
            alarm = f"< {_num(lim.low_alarm)} or > {_num(lim.high_alarm)}" \
                if lim.low_alarm is not None else f"> {_num(lim.high_alarm)}"
        u = f" {s.unit}" if s.unit else ""
        warn += u if warn != "–" else ""
        if alarm != "–":
            alarm += u + (f" (hysteresis {lim.hysteresis:g}{u})" if lim.hysteresis else "")
        if s.kind in ("spectrum", "image"):
            change = archive = "– (read)"
        elif ev.polling_ms is None:
            change, archive = "pushed on change", "pushed on change"
        else:
            parts = [f"±{ev.abs_change:g}{u}" if ev.abs_change is not None else "",
                     f"±{ev.rel_change:g} %" if ev.rel_change is not None else ""]
            change = " or ".join(p for p in parts if p) + f", polled {ev.polling_ms} ms"
            parts = [f"±{ev.archive_abs_change:g}{u}" if ev.archive_abs_change is not None
                     else "", f"±{ev.archive_rel_change:g} %" if ev.archive_rel_change
                     is not None else ""]
            archive = " or ".join(p for p in parts if p) + \
                f", every {(ev.archive_period_ms or 0) / 1000:g} s"
        kind = {"float": "double", "int": "long", "bool": "boolean", "str": "string",
                "spectrum": "spectrum (waveform)", "image": f"image, rows {', '.join(s.rows)} "
                                                            "(a waveform per row)"}[s.kind]
        if s.writable:
            kind += f", writable {s.min_value:g}–{s.max_value:g}"
        unit = s.unit or "–"
        if s.egu and ca_units(s.egu) != s.unit:
            unit += f" ({ca_units(s.egu)})"
        fmt = f"`{s.fmt}`" if s.fmt else "–"
        doc = s.doc.replace("|", "\\|")  # |H1| would end the cell
        lines.append(f"| `{s.name}` | {kind} | {unit} | {fmt} | {warn} | {alarm} "
                     f"| {change} | {archive} | {doc} |")
    return "\n".join(lines)
