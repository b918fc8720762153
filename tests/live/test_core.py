"""The live bench's logic, stepped by hand (no thread, no Tango): deterministic checks."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fsmbench.bench.params import default_bench
from fsmbench.live.arguments import parse_excitation
from fsmbench.live.backend import LiveBlock
from fsmbench.live.core import LiveBench
from fsmbench.live.monitor import LiveMonitor, Ring
from fsmbench.twin.simulate import simulate_bench

BENCH = default_bench()
FS = BENCH.nominal.converter.fs_hz
CONV = BENCH.nominal.converter


@settings(max_examples=40, deadline=None)
@given(capacity=st.integers(1, 50),
       pushes=st.lists(st.integers(0, 120), min_size=1, max_size=8),
       ask=st.integers(0, 60))
def test_ring_keeps_the_last_samples(capacity: int, pushes: list[int], ask: int) -> None:
    ring = Ring(capacity=capacity, channels=("a", "b"))
    everything = np.zeros((0, 2))
    start = 0
    for n in pushes:
        block = np.column_stack([np.arange(start, start + n), -np.arange(start, start + n)])
        start += n
        ring.push(block.astype(float))
        everything = np.vstack([everything, block])
    want = everything[-min(ask, capacity, len(everything)):] if ask and len(everything) else \
        everything[:0]
    np.testing.assert_array_equal(ring.last(ask), want)


def _block(n: int, *, start: int = 0, **signals: np.ndarray | float) -> LiveBlock:
    base = {name: np.zeros(n) for name in ("Uch", "Ucv", "Vph", "Vpv", "Vch", "Vcv", "Va")}
    base.update({k: np.broadcast_to(np.asarray(v, dtype=float), (n,)).copy()
                 for k, v in signals.items()})
    return LiveBlock(start_sample=start, fs_hz=FS, signals=base, source="test")


def _monitor() -> LiveMonitor:
    return LiveMonitor(fs_hz=FS, qd_gain_v_per_rad=(1.0, 1.0), half_range_v=CONV.range_v / 2,
                       lsb_v=CONV.lsb_v)


RAIL = CONV.range_v / 2 - CONV.lsb_v  # the DAC's positive rail, one step below +10 V


@pytest.mark.parametrize(("saturated_ms", "trips"), [(40, False), (50, False), (60, True)])
def test_dac_saturation_rule(saturated_ms: int, trips: bool) -> None:
    mon = _monitor()
    mon.push(_block(1000), loop_closed=True)
    n_sat = round(saturated_ms * 1e-3 * FS)
    uch = np.zeros(1000)
    uch[:n_sat] = RAIL
    trip = mon.push(_block(1000, start=1000, Uch=uch), loop_closed=True)
    assert (trip is not None) is trips
    if trip is not None:
        assert "DAC saturated" in trip.reason and "60 ms" in trip.reason


def test_intermittent_saturation_trips() -> None:
    # An oscillation that clips every other 10 ms: 60 ms of the last 100 ms on a rail.
    mon = _monitor()
    ucv = np.tile(np.r_[np.full(100, -CONV.range_v / 2), np.zeros(60)], 7)[:1000]
    assert mon.push(_block(1000, Ucv=ucv), loop_closed=True) is not None


def test_diverging_beam_and_coil_channels() -> None:
    mon = _monitor()
    # The coil-voltage monitor (60 dB) on its rails is normal in closed loop.
    assert mon.push(_block(500, Vch=RAIL, Vcv=-CONV.range_v / 2), loop_closed=True) is None
    trip = mon.push(_block(500, start=500, Vpv=np.linspace(0, 9.5, 500)), loop_closed=True)
    assert trip is not None and "Vpv" in trip.reason and "diverges" in trip.reason
    # In open loop nothing trips.
    assert _monitor().push(_block(500, Vph=9.9, Uch=RAIL), loop_closed=False) is None


def test_tracking_error_matches_the_batch_twin(tmp_path) -> None:
    live = LiveBench(BENCH, seed=3, output_folder=tmp_path)
    live.advance(5000)
    live.close_loop()
    live.advance(round(2 * FS))  # settle
    readings = []
    for _ in range(60):
        live.advance(round(FS))
        readings.append(live.monitor.tracking_rms_rad())
    measured = np.mean(readings, axis=0)
    # The batch twin, same controller (the seed's, 9.2), loop closed, no excitation.
    run = simulate_bench(BENCH, seed=3, duration_s=63.0, experiments=["data_huddle_test_3"])
    ds = run.recordings["data_huddle_test_3"]
    gd = BENCH.nominal.quad_diode.gain_v_per_rad
    batch = []
    for axis, name in (("h", "Vph"), ("v", "Vpv")):
        e = np.asarray(ds[name].values)[round(2 * FS):] / gd[axis]
        seconds = e[: (e.size // round(FS)) * round(FS)].reshape(-1, round(FS))
        batch.append(np.mean(np.std(seconds, axis=1)))
    # Issue 12's criterion. The 1 s windows scatter by ~15 % (slow noise through the
    # loop): 60 of them put either mean's standard error near 2 %, so 10 % is ~3.5
    # standard errors of the difference, and still a real test of the live statistic.
    np.testing.assert_allclose(measured, batch, rtol=0.10)
    assert live.state == "RUNNING"


def test_close_loop_is_bumpless_and_open_holds(tmp_path) -> None:
    live = LiveBench(BENCH, seed=4, output_folder=tmp_path)
    live.start_excitation(json.dumps({"input": "Unh", "kind": "sine", "amplitude_v": 1.0,
                                      "frequency_hz": 2.0}))
    live.advance(3000)
    live.close_loop()
    live.advance(3000)
    before = live.advance(100).signals
    live.open_loop()
    after = live.advance(100).signals
    for ch in ("Uch", "Ucv"):
        # Opening holds the last command: the first open-loop command is the DAC's
        # rounding of the last closed-loop one.
        assert abs(after[ch][0] - before[ch][-1]) <= 2 * np.max(np.abs(np.diff(before[ch]))) \
            + CONV.lsb_v


@pytest.mark.parametrize(("doc", "message"), [
    ({"input": "Uxx", "kind": "noise", "amplitude_v": 0.1}, "unknown input"),
    ({"input": "Uch", "kind": "chirp", "amplitude_v": 0.1}, "unknown kind"),
    ({"input": "Uch", "kind": "noise", "amplitude_v": 3.0}, "saturate the DAC"),
    ({"input": "Uch", "kind": "sine", "amplitude_v": 11.0, "frequency_hz": 5}, "saturate"),
    ({"input": "Uch", "kind": "sine", "amplitude_v": 1.0}, "frequency_hz"),
    ({"input": "Uch", "kind": "noise", "amplitude_v": -1}, "positive"),
    ({"input": "Uch", "kind": "noise", "amplitude_v": 0.1, "band_hz": [50, 10]}, "band_hz"),
])
def test_bad_excitations_are_refused(doc: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        parse_excitation(json.dumps(doc), start_s=0.0, half_range_v=CONV.range_v / 2, fs_hz=FS)


def test_experiment_restores_the_loop(tmp_path) -> None:
    live = LiveBench(BENCH, seed=5, output_folder=tmp_path)
    live.close_loop()
    path = live.run_experiment("data_huddle_test_1")  # open loop, compensation unit off
    assert live.state == "MOVING" and not live.loop_closed
    with pytest.raises(ValueError, match="Record refused: Experiment data_huddle_test_1 running"):
        live.record(json.dumps({"signals": ["Vph"], "duration_s": 1}))
    while live.state == "MOVING":  # until the file is written (the writer's thread)
        live.advance(5000)
    assert live.loop_closed and live.state == "RUNNING"
    from fsmbench.io.recording import read_recording

    ds = read_recording(path)
    assert ds.attrs["experiment"] == "data_huddle_test_1"
    assert ds.sizes["t"] == round(101.0 * FS)
    assert float(ds["t"][0]) == 0.0  # the seed's layout: time from the record's start
