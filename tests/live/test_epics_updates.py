"""The IOC's record updates while the bench cannot be read (a stalled loop, a busy machine).

No IOC here: softioc creates records once per process, and the update logic needs none.
The fake records keep the one rule of softioc's that matters: a ``longIn`` takes only an
int (``builder.longIn(...).set(0.0)`` raises ``TypeError: 'float' object cannot be
interpreted as an integer``, seen on softioc 4.7 and in a soak's serve log).
"""

from __future__ import annotations

import threading
from typing import Any

import pytest

pytest.importorskip("softioc")

from fsmbench.live.attributes import ATTRIBUTES, QualityLatch
from fsmbench.live.epics import BenchIoc


class FakeRecord:
    def __init__(self, kind: str) -> None:
        self.kind = kind
        self.values: list[tuple[Any, dict[str, Any]]] = []

    def set(self, value: Any, **alarm: Any) -> None:
        if self.kind == "int" and not isinstance(value, int):
            raise TypeError(f"'{type(value).__name__}' object cannot be interpreted as an "
                            "integer")
        self.values.append((value, alarm))


class StalledBench:
    """Numbers not current (the bench lock not taken in time); texts readable."""

    state = "RUNNING"
    status = "Loop closed with tuned (controllers_sos.json)."

    def __init__(self) -> None:
        self.by_reader = {id(s.read): s for s in ATTRIBUTES}
        self.logged: list[tuple[str, str]] = []

    def read(self, reader: Any) -> tuple[Any, bool]:
        spec = self.by_reader[id(reader)]
        if spec.name == "Controller":
            return "tuned (controllers_sos.json)", True
        if spec.kind == "str":
            return "", True
        if spec.kind == "bool":
            return True, True
        if spec.kind in ("spectrum", "image"):
            return None, False
        return None, False  # no current reading: INVALID

    def log(self, level: str, text: str) -> None:
        self.logged.append((level, text))


def _ioc(bench: StalledBench) -> tuple[BenchIoc, dict[str, FakeRecord]]:
    ioc = BenchIoc.__new__(BenchIoc)  # the update logic without softioc's records
    records = {s.name: FakeRecord(s.kind) for s in ATTRIBUTES}
    records["State"] = FakeRecord("int")
    records["Status"] = FakeRecord("str")
    ioc.bench = bench  # type: ignore[assignment]
    ioc.prefix = "TEST"
    ioc._latch = QualityLatch()
    ioc._records = records  # type: ignore[assignment]
    ioc._last_arrays = {}
    ioc._posted = {}
    ioc._refused = set()
    ioc._lengths = {}
    ioc._state_lock = threading.Lock()
    return ioc, records  # type: ignore[return-value]


def test_an_invalid_count_is_posted_as_an_int_and_the_controller_still_updates() -> None:
    bench = StalledBench()
    ioc, records = _ioc(bench)
    ioc.update()
    ints = [s.name for s in ATTRIBUTES if s.kind == "int"]
    assert ints, "the table has a count (Heartbeat)"
    for name in ints:
        value, alarm = records[name].values[-1]
        assert value == 0 and isinstance(value, int), (name, value)
        assert alarm["severity"] != 0, "INVALID: the record says so by its severity"
    # The records after the count, the ones a client acts on, carry the bench's state.
    assert records["Controller"].values[-1][0] == "tuned (controllers_sos.json)"
    assert records["Status"].values[-1][0] == StalledBench.status
    assert not bench.logged


def test_one_record_refusing_does_not_stop_the_others() -> None:
    bench = StalledBench()
    ioc, records = _ioc(bench)
    first = next(s.name for s in ATTRIBUTES if s.kind == "float" and not s.writable)

    def refuse(value: Any, **alarm: Any) -> None:
        raise ValueError("refused by the record")

    records[first].set = refuse  # type: ignore[method-assign]
    ioc.update()
    ioc.update()
    assert records["Controller"].values[-1][0] == "tuned (controllers_sos.json)"
    assert records["State"].values, "State still updated"
    warnings = [text for level, text in bench.logged if level == "WARNING"]
    assert len(warnings) == 1 and f"TEST:{first}" in warnings[0], warnings  # logged once
