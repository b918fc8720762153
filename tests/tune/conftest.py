"""Shared fixtures of the ``tune`` tests through the live Tango device.

``device``: a twin device of its own (PyTango's ``DeviceTestContext``, no database, in this
process) at 50x real time with the loop closed by the ESRF study's controller.
``invalid_reads``: makes the device answer chosen attribute reads with quality INVALID
(PyTango's value None), as it does when it cannot take its bench's lock within 0.5 s.
``fsmbench_loop``: fsmbench's controller designed on the bench file (``--running
fsmbench``), a candidate the guards load on the device.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from fsmbench.bench.params import Bench


@pytest.fixture()
def device(tmp_path: Path) -> Iterator[tuple[Any, str]]:
    """(proxy, address) of a twin device at 50x with the loop closed by the seed."""
    tango = pytest.importorskip("tango")
    from tango.test_context import DeviceTestContext

    from fsmbench.live.device import FsmBench

    ctx = DeviceTestContext(FsmBench, device_name="fsmbench/bench/1", process=False,
                            properties={"Speed": 50.0, "OutputFolder": str(tmp_path / "live")})
    with ctx as proxy:
        proxy.set_source(tango.DevSource.DEV)
        proxy.CloseLoop()
        yield proxy, ctx.get_device_access()


class InvalidReads:
    """How many more reads of each attribute the device answers INVALID, and how many it did.

    Only attributes that no device thread reads (no polling, no events read through the
    attribute: ``LoopClosed``, ``Controller``, ``SpeedFactor``, ``Task``) count client reads
    alone.
    """

    def __init__(self) -> None:
        self.left: dict[str, float] = {}
        self.served: dict[str, int] = {}

    def arm(self, name: str, count: float) -> None:
        """The next ``count`` reads of ``name`` are INVALID (``math.inf``: all of them)."""
        self.left[name] = count

    def forever(self, name: str) -> None:
        """Every read of ``name`` from now on is INVALID."""
        self.arm(name, math.inf)


@pytest.fixture()
def invalid_reads(monkeypatch: pytest.MonkeyPatch) -> InvalidReads:
    """The device's attribute reads, INVALID on demand (:class:`InvalidReads`)."""
    pytest.importorskip("tango")
    from tango import AttrQuality

    from fsmbench.live.device import EMPTY_TEXT, FsmBench

    reads = InvalidReads()
    original = FsmBench._read

    def read(self: Any, spec: Any) -> tuple[Any, float, Any]:
        if reads.left.get(spec.name, 0) > 0:
            reads.left[spec.name] -= 1
            reads.served[spec.name] = reads.served.get(spec.name, 0) + 1
            return EMPTY_TEXT[spec.kind], time.time(), AttrQuality.ATTR_INVALID
        return original(self, spec)

    monkeypatch.setattr(FsmBench, "_read", read)
    return reads


@pytest.fixture(scope="session")
def fsmbench_loop(bench: Bench) -> Any:
    """fsmbench's controller designed on the bench file, as ``tune --running fsmbench``."""
    from fsmbench.tune.running import running_loop

    return running_loop("fsmbench", bench)
