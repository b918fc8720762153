"""The huddle screen's open-loop test: judged where the band decides, and only there.

Synthetic records of known band power (white noise: the 1–10 Hz PSD is 2σ²/fs), so the
expected ratios are closed forms. The closed-loop tests' controller fits are given (they
are tested on recorded loops in ``tests/ident/evidence/test_evidence.py``); what is tested here is
the decision taken from them.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal
import xarray as xr

from fsmbench.budget import huddle_screen
from fsmbench.budget.huddle_screen import CLOSED_LIKE_FACTOR, MAX_INJECTION, screen_huddles
from fsmbench.ident.evidence.recorded_loop import ControllerFit, RecordedController

FS_HZ = 1000.0
N = 20_000  # 20 s: four 4 s windows twice over, the band's PSD to ~±10 % (36 lines × 9)
PLANT = np.diag([2.0, -3.0])  # Uc -> Vp in the band [V/V], one axis inverting


def _record(rng: np.random.Generator, *, vp_std: float, removed_std: float | None
            ) -> xr.Dataset:
    """White ``Vph``, ``Vpv`` of ``vp_std``; with ``removed_std``, closed-loop commands
    such that ``Vp − P Uc`` carries white motion of that std on top of ``Vp``."""
    vp = rng.standard_normal((2, N)) * vp_std
    data = {"Vph": ("t", vp[0]), "Vpv": ("t", vp[1]), "Va": ("t", rng.standard_normal(N))}
    if removed_std is not None:
        removed = rng.standard_normal((2, N)) * removed_std
        uc = -np.linalg.solve(PLANT, removed)
        data |= {"Uch": ("t", uc[0]), "Ucv": ("t", uc[1])}
    return xr.Dataset(data, coords={"t": np.arange(N) / FS_HZ}, attrs={"fs_hz": FS_HZ})


@pytest.fixture
def ran_the_controller(monkeypatch: pytest.MonkeyPatch) -> None:
    def fits(recordings: dict[str, xr.Dataset], **_: float) -> dict[str, RecordedController]:
        return {a: RecordedController(a, f"Uc{a}", f"Vp{a}", tuple(
            ControllerFit(n, 1e-3, 5.0, 30.0, 0.1, 0.99, 1) for n in recordings), 30.0, 0.1)
            for a in "hv"}
    monkeypatch.setattr(huddle_screen, "recorded_controllers", fits)


def _tests(*, open_std: float, closed_std: float, removed_std: float,
           test2_std: float) -> dict[str, xr.Dataset]:
    rng = np.random.default_rng(5)
    out = {f"data_huddle_test_{i}": _record(rng, vp_std=open_std, removed_std=None)
           for i in (1, 4)}
    out["data_huddle_test_2"] = _record(rng, vp_std=test2_std, removed_std=None)
    for i in (3, 5):
        out[f"data_huddle_test_{i}"] = _record(rng, vp_std=closed_std, removed_std=removed_std)
    return out


@pytest.mark.usefixtures("ran_the_controller")
def test_an_open_test_recorded_with_the_loop_closed_is_named() -> None:
    # The loop removed the open tests' motion (faced 1.01× it) and left 1 % of its power:
    # test 2, at the closed tests' level, is 1× them, the open ones 100×.
    recs = _tests(open_std=1.0, closed_std=0.1, removed_std=1.0, test2_std=0.1)
    screen = screen_huddles(recs, fs_hz=FS_HZ, step_v=1e-4, uc_to_vp=PLANT)
    judged = {c.subject.split(".mat")[0]: c for c in screen.checks
              if c.name == "huddle_loop_open"}
    assert set(judged) == {"data_huddle_test_1", "data_huddle_test_2", "data_huddle_test_4"}
    assert not judged["data_huddle_test_2"].passed
    # 1× within the PSD's ±10 % scatter per record (a ratio of two: ±20 %).
    assert judged["data_huddle_test_2"].value == pytest.approx(1.0, rel=0.2)
    assert judged["data_huddle_test_1"].passed and judged["data_huddle_test_4"].passed
    assert judged["data_huddle_test_1"].value == pytest.approx(100.0, rel=0.2)
    assert set(screen.excluded) == {"data_huddle_test_2"} and not screen.notes


@pytest.mark.usefixtures("ran_the_controller")
def test_a_loop_set_by_what_it_injects_leaves_the_open_tests_unjudged() -> None:
    # The closed loop faced 2500× the open tests' motion (its DAC limit-cycling) and left
    # 4× their power: an open record and a closed one are both within 4× of it, so the
    # band cannot say which test 2 is: no check, a note with the measured factor.
    recs = _tests(open_std=1.0, closed_std=2.0, removed_std=50.0, test2_std=2.0)
    screen = screen_huddles(recs, fs_hz=FS_HZ, step_v=1e-4, uc_to_vp=PLANT)
    assert not [c for c in screen.checks if c.name == "huddle_loop_open"]
    assert not screen.excluded
    (note,) = screen.notes
    assert "cannot tell an open loop from a closed one" in note
    faced = float(note.split("faced ")[1].split("×")[0])
    assert faced == pytest.approx(2500.0 / 4.0, rel=0.2)  # over the largest open test (2)
    assert faced >= MAX_INJECTION


@pytest.mark.usefixtures("ran_the_controller")
def test_without_the_plant_the_screen_judges_on_the_band_alone() -> None:
    recs = _tests(open_std=1.0, closed_std=2.0, removed_std=50.0, test2_std=2.0)
    screen = screen_huddles(recs, fs_hz=FS_HZ, step_v=1e-4)
    judged = [c for c in screen.checks if c.name == "huddle_loop_open"]
    assert len(judged) == 3 and not any(c.passed for c in judged)
    assert all(c.value < CLOSED_LIKE_FACTOR for c in judged)


@pytest.mark.parametrize(("explained", "named"), [(0.99, "data_huddle_test_1"),
                                                  (0.0, "data_huddle_test_3")])
def test_shared_samples_name_the_test_whose_name_they_do_not_fit(
        monkeypatch: pytest.MonkeyPatch, explained: float, named: str) -> None:
    """Test 1 and test 3 hold the same Vph, Vpv, Va. When the ESRF study's controller
    explains test 3's commands from them, they are a closed-loop record: test 1 is named
    (the loop closed while it was recorded) and test 3 kept. When it does not, test 3's
    samples are not its own: test 3 is the copy (its commands left from another record)."""
    def fits(recordings: dict[str, xr.Dataset], **_: float) -> dict[str, RecordedController]:
        return {a: RecordedController(a, f"Uc{a}", f"Vp{a}", tuple(
            ControllerFit(n, 1e-3, 5.0, 30.0, 0.1, explained, 1) for n in recordings),
            30.0, 0.1) for a in "hv"}
    monkeypatch.setattr(huddle_screen, "recorded_controllers", fits)
    recs = _tests(open_std=1.0, closed_std=0.1, removed_std=1.0, test2_std=1.0)
    closed = recs["data_huddle_test_3"]
    recs["data_huddle_test_1"] = closed[["Vph", "Vpv", "Va"]]
    screen = screen_huddles(recs, fs_hz=FS_HZ, step_v=1e-4, uc_to_vp=PLANT)
    (copy,) = [c for c in screen.checks if c.name == "huddle_distinct"]
    assert copy.subject == f"{named}.mat" and named in screen.excluded
    other = ({"data_huddle_test_1", "data_huddle_test_3"} - {named}).pop()
    assert other not in screen.excluded
    if named == "data_huddle_test_1":
        assert "the loop was closed when data_huddle_test_1 was recorded" in copy.advice


@pytest.mark.parametrize("n", [2, 3, 40_000])
def test_the_projection_detrend_is_scipys_linear_detrend(n: int) -> None:
    rng = np.random.default_rng(n)
    ramp = np.arange(n) * 3e-4 - 2.0  # a large trend: what there is to remove
    segments = rng.standard_normal((3, n)) + ramp
    ours = huddle_screen._linear_detrend(n)(segments)
    theirs = scipy.signal.detrend(segments, axis=-1, type="linear")
    # Both remove the least-squares line; they differ in rounding only (a few ulp of the
    # segment's size, which the residual carries).
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-13 * np.max(np.abs(segments)))
