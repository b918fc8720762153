"""Plan stubs for the live bench: a command, a computation off the RunEngine's loop, the
waits on the device's state, bench time and excitation, and the stand-down after a plan
(:mod:`fsmbench.live.plans` builds its plans from them)."""

from __future__ import annotations

import asyncio
import contextlib
import json
import time
from collections.abc import Callable, Generator
from typing import Any

import bluesky.plan_stubs as bps

from fsmbench.live.ophyd import BenchCommand, BenchState, CommandRefusedError, FsmBenchDevice

__all__ = ["STALL_S", "Plan", "excitation_start", "execute", "in_thread", "stand_down",
           "wait_bench_time", "wait_until_done"]

#: Longest wall-clock time the bench may stand still while a plan waits on it [s]: a
#: stalled bench fails the plan, a slow one does not.
STALL_S = 60.0
_POLL_S = 0.05

Plan = Generator[Any, Any, Any]


def execute(command: BenchCommand, *args: str) -> Plan:
    """Run ``command`` on the device; the device's reply (a plan stub).

    Raises
    ------
    fsmbench.live.ophyd.CommandRefusedError
        The device refused it (its reason code and sentence).
    """

    async def run() -> str:
        return str(await command.execute(*args))

    (task,) = yield from bps.wait_for([run])
    return task.result()


def in_thread(fn: Callable[[], Any]) -> Plan:
    """``fn()`` off the RunEngine's loop (a computation of seconds), its result."""

    async def run() -> Any:
        return await asyncio.to_thread(fn)

    (task,) = yield from bps.wait_for([run])
    return task.result()


def wait_until_done(bench: FsmBenchDevice, what: str) -> Plan:
    """Wait while the device is MOVING (its experiment or record runs); its state after.

    Fails when the bench time stands still for :data:`STALL_S` of wall clock, or the
    device ends in FAULT (its status named).
    """
    last = yield from bps.rd(bench.bench_time)
    moved = time.monotonic()
    while (state := (yield from bps.rd(bench.state))) == BenchState.MOVING:
        yield from bps.sleep(_POLL_S)
        now = yield from bps.rd(bench.bench_time)
        if now != last:
            last, moved = now, time.monotonic()
        elif time.monotonic() - moved > STALL_S:
            status = yield from bps.rd(bench.status)
            raise TimeoutError(f"{bench.address}: the bench time stood still for {STALL_S:g} s "
                               f"(wall clock) during {what}: {status}")
    if state == BenchState.FAULT:
        status = yield from bps.rd(bench.status)
        raise RuntimeError(f"{bench.address}: FAULT during {what}: {status}")
    return state


def stand_down(bench: FsmBenchDevice, *, open_loop: bool) -> Plan:
    """After a plan, whether it ended or failed: its experiment or record aborted, its
    excitation stopped and (``open_loop``) the loop it closed opened; a refusal (nothing to
    stop, a FAULT) is no error here."""
    if (yield from bps.rd(bench.state)) == BenchState.MOVING:
        with contextlib.suppress(CommandRefusedError):
            yield from execute(bench.abort)
    with contextlib.suppress(CommandRefusedError):
        yield from execute(bench.stop_excitation)
    if open_loop:
        with contextlib.suppress(CommandRefusedError):
            yield from execute(bench.open_loop)


def wait_bench_time(bench: FsmBenchDevice, until_s: float) -> Plan:
    """Wait until the device's bench time reaches ``until_s`` [s]."""
    while (yield from bps.rd(bench.bench_time)) < until_s:
        yield from bps.sleep(_POLL_S)


def excitation_start(bench: FsmBenchDevice, sha: str) -> Plan:
    """The bench time the excitation of samples ``sha`` started [s] (the device's
    ``Excitation``, once it names them: the IOC refreshes it 10 times a second)."""
    moved = time.monotonic()
    while True:
        text = yield from bps.rd(bench.excitation)
        try:
            doc = json.loads(str(text) or "{}")
        except ValueError:
            doc = {}
        if isinstance(doc, dict) and doc.get("samples_sha256") == sha:
            return float(doc["start_time_s"])
        if time.monotonic() - moved > STALL_S:
            raise TimeoutError(f"{bench.address}: Excitation never named the samples played: "
                               f"{text}")
        yield from bps.sleep(_POLL_S)
