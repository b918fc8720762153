"""A computation in a forked child: its value, progress, warnings and errors reach the caller
as if it had run there."""

from __future__ import annotations

import os
import threading
import time
import warnings
from pathlib import Path

import control as ct
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from fsmbench import forked
from fsmbench.forked import ForkedError, fork_available, start_forked, start_forked_series
from fsmbench.progress import Progress

needs_fork = pytest.mark.skipif(not fork_available(), reason="fork and two cores needed")


class _UnpicklableError(Exception):
    def __init__(self) -> None:
        super().__init__("refused")
        self.handle = lambda: None  # a lambda does not pickle


def _system(say: Progress) -> ct.StateSpace:
    say("building")
    say("built")
    return ct.ss([[-1.0, 2.0], [0.0, -3.0]], [[1.0], [0.5]], [[1.0, 0.0]], [[0.25]], 1e-4,
                 inputs=["Uch"], outputs=["Vph"], states=["x1", "x2"], name="K")


@needs_fork
def test_a_state_space_comes_back_as_itself_with_the_progress_in_order() -> None:
    said: list[str] = []
    call = start_forked(_system, progress=said.append)
    got = call.result()
    assert call.forked and said == ["building", "built"]
    want = _system(lambda _msg: None)
    for name in ("A", "B", "C", "D"):  # pickled float64: bit for bit
        assert np.array_equal(getattr(got, name), getattr(want, name))
    assert (got.dt, got.name, got.input_labels, got.output_labels, got.state_labels) == (
        want.dt, want.name, want.input_labels, want.output_labels, want.state_labels)


@needs_fork
def test_it_runs_in_another_process_beside_the_caller() -> None:
    call = start_forked(lambda _say: (os.getpid(), time.sleep(0.5))[0], progress=print)
    assert call.forked  # start_forked returned while the child sleeps
    assert call.result() != os.getpid()
    assert call.seconds >= 0.5  # the computation's own time


def _warns(_say: Progress) -> int:
    warnings.warn("ill-conditioned", RuntimeWarning, stacklevel=1)
    return 3


@pytest.mark.parametrize("parallel", [True, False])
def test_the_child_s_warnings_are_raised_in_the_caller(parallel: bool) -> None:
    call = start_forked(_warns, progress=print, parallel=parallel)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert call.result() == 3
    assert [(w.category, str(w.message), w.filename) for w in caught] == [
        (RuntimeWarning, "ill-conditioned", __file__)]


def _fails(_say: Progress) -> None:
    raise ValueError("data_uch.mat: Vph is missing")


def _fails_unpicklable(_say: Progress) -> None:
    raise _UnpicklableError


@pytest.mark.parametrize("parallel", [True, False])
def test_the_child_s_error_is_raised_in_the_caller(parallel: bool) -> None:
    with pytest.raises(ValueError, match=r"data_uch\.mat: Vph is missing"):
        start_forked(_fails, progress=print, parallel=parallel).result()


@needs_fork
def test_an_error_that_cannot_travel_comes_back_as_its_text() -> None:
    with pytest.raises(ForkedError, match="_UnpicklableError: refused"):
        start_forked(_fails_unpicklable, progress=print).result()


@needs_fork
def test_a_result_that_cannot_travel_is_an_error_not_a_hang() -> None:
    with pytest.raises(ForkedError, match="could not be sent back"):
        start_forked(lambda _say: (lambda: None), progress=print).result()


@needs_fork
def test_cancel_stops_the_child() -> None:
    call = start_forked(lambda _say: time.sleep(60), progress=print)
    call.cancel()  # the caller failed: the child must not outlive it
    with pytest.raises(ForkedError, match="no result"):
        call.result()


def test_serial_runs_in_the_caller_when_the_result_is_taken() -> None:
    said: list[str] = []
    call = start_forked(lambda say: (say("now"), os.getpid())[1], progress=said.append,
                        parallel=False)
    assert not call.forked and said == []  # nothing has run yet
    assert call.result() == os.getpid() and said == ["now"]
    with pytest.raises(RuntimeError, match="already taken"):
        call.result()


def test_off_the_main_thread_it_runs_in_the_caller() -> None:
    """A server's command thread (Tango, Dask, the live device's jobs) never forks."""
    got: list[int] = []
    thread = threading.Thread(target=lambda: got.append(
        start_forked(lambda _say: os.getpid(), progress=print).result()))
    thread.start()
    thread.join()
    assert got == [os.getpid()]


def _large(_say: Progress) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(5)
    return {"record": rng.standard_normal((3, 400_000)),  # 9.6 MB: beside the pickle
            "small": np.arange(10.0)}  # in it


@needs_fork
@pytest.mark.parametrize("shared_memory", [True, False])
def test_large_arrays_come_back_whole_and_writable(shared_memory: bool,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """Through a file in shared memory, removed once mapped; without room there, in the
    pipe: the same arrays either way, writable as the caller's own."""
    if not shared_memory:
        monkeypatch.setattr(forked, "_SHM", forked.Path("/nonexistent-shm"))
    before = set(os.listdir("/dev/shm")) if os.path.isdir("/dev/shm") else set()
    got = start_forked(_large, progress=print).result()
    want = _large(print)
    for key, value in want.items():
        np.testing.assert_array_equal(got[key], value, strict=True)
        got[key][0] = -1.0  # the caller may change its copy
    after = set(os.listdir("/dev/shm")) if os.path.isdir("/dev/shm") else set()
    assert after <= before  # nothing left behind


@given(st.dictionaries(st.integers(0, 50), st.floats(0.0, 1e6), max_size=20))
def test_the_child_s_share_leaves_the_two_loads_within_one_item(costs: dict[int, float]) -> None:
    # Largest first, each to the lighter side: the loads never differ by more than the
    # largest item (the greedy rule's bound), and every item is on one side.
    share = forked.child_share(costs)
    assert share <= set(costs)
    theirs = sum(costs[k] for k in share)
    mine = sum(v for k, v in costs.items() if k not in share)
    assert abs(mine - theirs) <= max(costs.values(), default=0.0) * (1 + 1e-12)


def test_equal_costs_alternate_the_caller_first() -> None:
    assert forked.child_share(dict.fromkeys("abcde", 1.0)) == {"b", "d"}


# --------------------------------------------------------------------------- series
def _wait_for(path: Path) -> str:
    for _ in range(3000):  # 30 s at most: a hang would fail the test, not block it
        if path.exists():
            return "the caller had the first value"
        time.sleep(0.01)
    return "timed out"


@needs_fork
def test_a_series_hands_each_value_over_while_the_next_runs(tmp_path: Path) -> None:
    """The second computation waits for a file the caller writes only once it holds the
    first value: the first came back before the second ended, from the same child."""
    flag = tmp_path / "first-taken"
    series = start_forked_series([lambda _say: os.getpid(), lambda _say: (
        os.getpid(), _wait_for(flag))], progress=print)
    try:
        first = series.result(0)
        flag.touch()
        second = series.result(1)
    finally:
        series.cancel()
    assert series.forked and first != os.getpid()
    assert second == (first, "the caller had the first value")


@pytest.mark.parametrize("parallel", [True, False])
def test_a_series_after_a_failure_runs_nothing_more(parallel: bool) -> None:
    ran: list[int] = []  # in the caller only: a child's list is its own
    series = start_forked_series([_fails, lambda _say: ran.append(1)], progress=print,
                                 parallel=parallel)
    with pytest.raises(ValueError, match="Vph is missing"):
        series.result(0)
    with pytest.raises(ForkedError, match="computation 1 was not run: computation 0"):
        series.result(1)
    assert ran == []


@needs_fork
def test_a_series_stops_when_a_value_cannot_travel() -> None:
    series = start_forked_series([lambda _say: (lambda: None), lambda _say: 2], progress=print)
    with pytest.raises(ForkedError, match="could not be sent back"):
        series.result(0)
    with pytest.raises(ForkedError, match="computation 1 was not run: computation 0"):
        series.result(1)


@pytest.mark.parametrize("parallel", [True, False])
def test_a_series_raises_each_computation_s_warnings_with_its_value(parallel: bool) -> None:
    series = start_forked_series([_warns, lambda _say: 4], progress=print, parallel=parallel)
    with warnings.catch_warnings(record=True) as second:
        warnings.simplefilter("always")
        if not parallel:  # run here, in order: the first one's warning is said now
            with warnings.catch_warnings(record=True) as first:
                warnings.simplefilter("always")
                assert series.result(0) == 3
            assert series.result(1) == 4
        else:
            assert series.result(1) == 4
            with warnings.catch_warnings(record=True) as first:
                warnings.simplefilter("always")
                assert series.result(0) == 3
    assert [str(w.message) for w in first] == ["ill-conditioned"]
    assert second == []


def test_a_serial_series_runs_each_computation_once_in_order() -> None:
    calls: list[str] = []
    series = start_forked_series([lambda _say: calls.append("a") or "a",
                                  lambda _say: calls.append("b") or "b"], progress=print,
                                 parallel=False)
    assert not series.forked and calls == []
    assert series.result(1) == "b" and calls == ["a", "b"]  # the first ran before it
    assert series.result(0) == "a" and calls == ["a", "b"]  # and is not run again
    with pytest.raises(RuntimeError, match="already taken"):
        series.result(0)


@needs_fork
def test_cancelling_a_series_stops_its_child() -> None:
    series = start_forked_series([lambda _say: 1, lambda _say: time.sleep(60)],
                                 progress=print)
    assert series.result(0) == 1
    series.cancel()  # the caller failed while the second ran
    with pytest.raises(ForkedError, match="no result"):
        series.result(1)
