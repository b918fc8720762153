"""Attribute reads ``tune --device`` relies on, each one valid or a clear error.

The live device answers a read with quality INVALID (and PyTango gives ``None`` for the
value) whenever it cannot take the bench's lock within 0.5 s of wall clock, which happens
on a busy machine (:meth:`fsmbench.live.core.LiveBench.read`), or when the loop has
stalled. A client that took such a value as a number crashed (``float(None)``) after it
had loaded a controller. :func:`read_valid` is the one way :mod:`fsmbench.tune.device`
reads an attribute: an INVALID reading is read again, every :data:`POLL_S`, for a bounded
wall-clock time; one still INVALID then is a :class:`DeviceReadError` naming the attribute
and the device, never a ``TypeError``.

A read that PyTango gives up on because the device is busy (``API_CommandTimedOut``: its
serialization monitor held past the client's timeout by another call, seen on two cores
each running a busy process) is read again the same way: the device is there and will
answer; only the wait is bounded.
"""

from __future__ import annotations

import time
from typing import Any

__all__ = ["INVALID_WAIT_S", "POLL_S", "DeviceReadError", "read_valid"]

#: Wall-clock time an attribute may stay INVALID before tune gives up on it [s]: twenty of
#: the device's 0.5 s lock waits, far beyond a busy machine's occasional miss, short of
#: its 5 s watchdog (a stalled loop turns the device to FAULT well within it).
INVALID_WAIT_S = 10.0
#: Wall clock between two reads of an INVALID attribute [s].
POLL_S = 0.05


class DeviceReadError(ValueError):
    """An attribute stayed INVALID (or without a value, or the device busy) for the whole
    wait.

    Parameters
    ----------
    attribute : str
    device : str
        The device in words (its address).
    waited_s : float
        Wall clock spent reading it [s].
    reads : int
        How many readings were INVALID.
    """

    def __init__(self, attribute: str, device: str, waited_s: float, reads: int) -> None:
        self.attribute, self.device = attribute, device
        super().__init__(f"{device}: the attribute {attribute} stayed INVALID for "
                         f"{waited_s:.1f} s of wall clock ({reads} reads; the device gives no "
                         "value when it cannot take its bench's lock, a busy machine, or when "
                         "its loop stalls): tune acts on no value it was not given")


#: PyTango's reasons for a read the device was too busy to serve in the client's timeout.
_BUSY_REASONS = frozenset({"API_CommandTimedOut", "API_DeviceTimedOut"})


def _busy(exc: Exception) -> bool:
    """True for a ``tango.DevFailed`` whose errors say the device was busy (no import of
    PyTango: its errors are read by their ``reason``)."""
    errors = exc.args[0] if exc.args and isinstance(exc.args[0], (tuple, list)) else exc.args
    return any(getattr(e, "reason", None) in _BUSY_REASONS for e in errors)


def _invalid(reading: Any) -> bool:
    """True for a PyTango ``DeviceAttribute`` of quality INVALID or without a value."""
    return reading.value is None or str(reading.quality).endswith("ATTR_INVALID")


def read_valid(proxy: Any, attribute: str, *, device: str,
               wait_s: float = INVALID_WAIT_S, poll_s: float = POLL_S) -> Any:
    """The value of ``attribute`` once the device gives it with a quality other than INVALID.

    Parameters
    ----------
    proxy : tango.DeviceProxy
        Or anything with ``read_attribute(name)`` returning ``.value`` and ``.quality``
        (:class:`fsmbench.tune.ca_device.CaDevice`: quality ``ATTR_INVALID`` for SEVR
        INVALID).
    attribute : str
        The attribute's name (``SpeedFactor``, ``BenchTime``, ``Controller``, ...).
    device : str
        The device in words, for the error.
    wait_s : float
        Wall-clock time INVALID readings are read again for [s]; at least one read is made.
    poll_s : float
        Wall clock between two reads [s].

    Returns
    -------
    Any
        The value (a float, bool or str as PyTango gives it).

    Raises
    ------
    DeviceReadError
        Still INVALID (or busy) after ``wait_s``, naming ``attribute`` and ``device``.
    tango.DevFailed or fsmbench.tune.device_errors.DeviceLost
        The read itself failed (the device gone, the connection lost): not retried.
    """
    t0 = time.monotonic()
    reads = 0
    while True:
        try:
            reading = proxy.read_attribute(attribute)
        except Exception as exc:
            if not _busy(exc):
                raise
            reading = None
        if reading is not None and not _invalid(reading):
            return reading.value
        reads += 1
        waited = time.monotonic() - t0
        if waited >= wait_s:
            raise DeviceReadError(attribute, device, waited, reads)
        time.sleep(min(poll_s, max(wait_s - waited, 0.0)))
