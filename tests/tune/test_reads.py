"""``read_valid``: what tune reads from a device is a value, or a clear error in bounded time.

PyTango's ``DevFailed`` carries its errors (each with a ``reason``) in ``args``; the fakes
below are shaped the same way, and the real one is checked when PyTango is installed.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import pytest

from fsmbench.tune.reads import DeviceReadError, read_valid


@dataclass
class _Error:
    reason: str
    desc: str = ""


class _DevFailedError(Exception):
    """PyTango's shape: ``args`` is the tuple of DevErrors."""


@dataclass
class _Reading:
    value: Any
    quality: str = "ATTR_VALID"


class _Proxy:
    """Answers each read from a script: an exception to raise, or a reading."""

    def __init__(self, script: list[Any]) -> None:
        self.script, self.reads = script, 0

    def read_attribute(self, name: str) -> _Reading:
        step = self.script[min(self.reads, len(self.script) - 1)]
        self.reads += 1
        if isinstance(step, Exception):
            raise step
        return step


@pytest.mark.parametrize("reason", ["API_CommandTimedOut", "API_DeviceTimedOut"])
def test_a_busy_device_is_read_again(reason: str) -> None:
    # Seen on two loaded cores: the device's serialization monitor held past the client's
    # 3 s by another thread; the device answers the next read.
    busy = _DevFailedError(_Error(reason), _Error("API_AttributeFailed"))
    proxy = _Proxy([busy, busy, _Reading(None, "ATTR_INVALID"), _Reading("tuned")])
    assert read_valid(proxy, "Controller", device="fake", poll_s=0.0) == "tuned"
    assert proxy.reads == 4


def test_a_device_busy_beyond_the_wait_is_named() -> None:
    proxy = _Proxy([_DevFailedError(_Error("API_CommandTimedOut"))])
    with pytest.raises(DeviceReadError, match="Controller") as raised:
        read_valid(proxy, "Controller", device="fake", wait_s=0.05, poll_s=0.0)
    assert raised.value.device == "fake"


def test_any_other_failure_is_not_retried() -> None:
    gone = _DevFailedError(_Error("API_DeviceNotExported"))
    proxy = _Proxy([gone, _Reading(1.0)])
    with pytest.raises(_DevFailedError):
        read_valid(proxy, "BenchTime", device="fake", poll_s=0.0)
    assert proxy.reads == 1


def test_pytango_s_own_timeout_is_read_as_busy() -> None:
    tango = pytest.importorskip("tango")
    error = tango.DevError()
    error.reason, error.desc = "API_CommandTimedOut", "monitor held"
    proxy = _Proxy([tango.DevFailed(error), _Reading(7.5)])
    assert read_valid(proxy, "BenchTime", device="fake", poll_s=0.0) == 7.5
