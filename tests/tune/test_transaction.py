"""The loop change's transaction (:mod:`fsmbench.tune.transaction`) on a scripted target:
the record before the load, and a roll-back that fails said plainly with what to do."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from fsmbench.tune.guarded import ControllerFigures, TuneOptions
from fsmbench.tune.transaction import LoopChangeError, load_and_watch

AXES2 = {"h": 1.0, "v": 1.0}


def _figures(name: str) -> ControllerFigures:
    return ControllerFigures(name=name, sensitivity_at_1hz=AXES2, gain_margin_db=AXES2,
                             phase_margin_deg=AXES2, modulus_margin=AXES2, stable=True,
                             robust_stable=True, predicted_rms_rad={"h": 1e-6, "v": 1e-6})


class Scripted:
    """A target whose load, watch and roll-back do what the test says."""

    label, fs_hz, drift_pct = "a scripted bench", 1000.0, 0.0

    def __init__(self, *, on_load: BaseException | None, roll_back: BaseException | None,
                 journal: list[Any]) -> None:
        self.on_load, self.fail_back, self.journal = on_load, roll_back, journal
        self.now = "before"
        self.seen_at_load: list[str] = []
        self.forced: list[bool] = []

    def load(self, loop: Any) -> dict[str, Any]:
        self.seen_at_load.append(self.journal[-1].decision)
        self.now = loop.name
        if self.on_load is not None:
            raise self.on_load
        return {"from": "before", "to": loop.name}

    def roll_back(self, loop: Any, *, force: bool = False) -> dict[str, Any]:
        self.forced.append(force)
        if self.fail_back is not None:
            raise self.fail_back
        self.now = loop.name
        return {"from": "candidate", "to": loop.name, "request": "seed"}

    def running_controller(self) -> str:
        return self.now

    def checkpoint(self, loop: Any) -> dict[str, Any]:
        return {"name": loop.name, "noun": "The device", "restore_with": ["seed", "last-good"]}

    def play(self, *args: Any, **kw: Any) -> Any:
        raise AssertionError("the transaction plays nothing")

    def run(self, duration_s: float, *, settle_s: float) -> np.ndarray:
        return np.zeros((100, 2))  # never reached: the load is cut short


def _change(target: Scripted, journal: list[Any]) -> Any:
    def make(decision: str, reason: str, **kw: Any) -> Any:
        return SimpleNamespace(decision=decision, reason=reason, **kw)

    running: Any = SimpleNamespace(name="before")  # the transaction reads only the names
    candidate: Any = SimpleNamespace(name="candidate")
    return load_and_watch(target=target, running=running, candidate=candidate,
                          before=_figures("before"), candidate_figures=_figures("candidate"),
                          options=TuneOptions(watch_s=2.0, settle_s=1.0), why="better",
                          make=make, journal=journal.append, say=lambda _m: None)


def test_a_failed_roll_back_is_said_plainly_with_what_to_do() -> None:
    journal: list[Any] = []
    target = Scripted(on_load=KeyboardInterrupt(), roll_back=ValueError("refused: FAULT"),
                      journal=journal)
    with pytest.raises(KeyboardInterrupt):
        _change(target, journal)
    assert target.seen_at_load == ["loading"]  # the decision was recorded before the load
    last = journal[-1]
    assert last.decision == "interrupted"
    tx = last.transaction
    assert tx["rollback"] == {"needed": True, "done": False, "error": "ValueError: refused: "
                                                                       "FAULT"}
    assert tx["left_on"] == "candidate"
    assert "FAILED" in tx["sentence"] and "the device is left on candidate" in tx["sentence"]
    assert "LoadController 'seed' or LoadController 'last-good'" in tx["sentence"]


def test_an_error_after_the_load_rolls_back_and_says_where_the_device_is() -> None:
    journal: list[Any] = []
    target = Scripted(on_load=RuntimeError("connection lost"), roll_back=None, journal=journal)
    with pytest.raises(LoopChangeError) as err:
        _change(target, journal)
    assert target.now == "before"
    assert err.value.sentence == ("The device is left on before, the controller it ran before "
                                  "tune, loaded back by LoadController 'seed' (checked by the "
                                  "device).")
    assert "RuntimeError: connection lost" in str(err.value)
    assert [r.decision for r in journal] == ["loading", "interrupted"]


class Lagging(Scripted):
    """A device that loads the candidate but whose Controller still reads the old name (an
    IOC whose updates had stopped: a soak's run)."""

    def load(self, loop: Any) -> dict[str, Any]:
        self.seen_at_load.append(self.journal[-1].decision)
        self.loaded = loop.name  # in the loop; the reading below lags
        raise ValueError("LoadController of candidate is not confirmed")

    def running_controller(self) -> str:
        return "before"

    def roll_back(self, loop: Any, *, force: bool = False) -> dict[str, Any]:
        self.forced.append(force)
        self.loaded = loop.name
        return {"from": "candidate", "to": loop.name, "request": "seed"}


def test_once_a_load_started_the_roll_back_is_made_whatever_the_device_reads() -> None:
    journal: list[Any] = []
    target = Lagging(on_load=None, roll_back=None, journal=journal)
    with pytest.raises(LoopChangeError) as err:
        _change(target, journal)
    assert target.forced == [True] and target.loaded == "before"
    assert journal[-1].transaction["rollback"]["done"] is True
    assert "loaded back by LoadController 'seed'" in err.value.sentence


def test_a_measurement_that_identifies_nothing_is_made_once_again(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Twice nothing: tune stops before any design or load, having measured twice (new
    noise the second time) and said so."""
    import fsmbench.tune.guarded as guarded
    from fsmbench.bench.params import default_bench

    seeds: list[int] = []

    def measure(**kw: Any) -> Any:
        seeds.append(kw["seed"])
        ident = SimpleNamespace(plant=None, skipped={"sercalo": "no mode near the peaks"})
        return SimpleNamespace(identification=ident)

    monkeypatch.setattr(guarded, "measure_closed_loop", measure)
    target: Any = SimpleNamespace(label="a scripted bench", fs_hz=1000.0, drift_pct=0.0,
                                  play=None, run=lambda *_a, **_k: np.zeros((100, 2)))
    running: Any = SimpleNamespace(name="before", feedback=None, gd_v_per_rad=(1.0, 1.0))
    said: list[str] = []
    with pytest.raises(ValueError, match="could not be identified in closed loop"):
        guarded.tune_guarded(target=target, bench=default_bench(), running=running,
                             options=TuneOptions(watch_s=2.0, settle_s=1.0), seed=5,
                             progress=said.append)
    assert seeds == [105, 305]
    assert any(s.endswith("measured once again") for s in said)
