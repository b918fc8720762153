"""The streaming bench: blocks equal one run bit for bit; controller swaps without a bump."""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fsmbench.bench.esrf import esrf_decentralised_controller
from fsmbench.bench.params import default_bench
from fsmbench.sim.controller import feedback_controller
from fsmbench.sim.excitation import Excitation
from fsmbench.sim.plant import DAC_CHANNELS, twin_discrete
from fsmbench.sim.stream import BenchBlock, BenchStream, concatenate_blocks

BENCH = default_bench()
P = BENCH.true
PLANT = twin_discrete(P)
N = 3000


def _controller(gain: float = 1.0, name: str = "seed K (9.2)"):
    k = esrf_decentralised_controller() * gain
    k = type(k)(k.A, k.B, k.C, k.D, inputs=["Rh", "Rv"], outputs=["Uch", "Ucv"])
    return feedback_controller(k, gd_v_per_rad=BENCH.nominal.quad_diode.gain_v_per_rad,
                               ts_s=P.converter.ts_s, name=name)


def _stream(*, closed: bool, excitations=()) -> BenchStream:
    return BenchStream(P, seed=7, name="test", plant=PLANT,
                       controller=_controller() if closed else None, excitations=excitations)


EXCITATIONS = (
    Excitation("Uch", "noise", 0.02, 0.01),
    Excitation("Unv", "sine", 0.5, 0.05, freq_hz=3.0),
    Excitation("Ucv", "noise", 0.01, 0.0, band_hz=(10.0, 500.0)),
    Excitation("Unh", "multisine", 0.05, 0.02, band_hz=(1.0, 300.0), period_s=0.1),
)


def _same(a: BenchBlock, b: BenchBlock) -> None:
    # Bit for bit: the stream promises identical samples, not close ones.
    for field in ("dac", "adc", "internal"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field), err_msg=field)
    for field in dataclasses.fields(a.va):
        np.testing.assert_array_equal(getattr(a.va, field.name), getattr(b.va, field.name),
                                      err_msg=field.name)
    for key in a.noise:
        np.testing.assert_array_equal(a.noise[key], b.noise[key], err_msg=key)


@pytest.fixture(scope="module", params=[False, True], ids=["open", "closed"])
def whole(request) -> tuple[bool, BenchBlock]:
    closed = request.param
    return closed, _stream(closed=closed, excitations=EXCITATIONS).step(N)


@settings(max_examples=8, deadline=None)
@given(cuts=st.lists(st.integers(min_value=0, max_value=N), min_size=1, max_size=6))
def test_blocks_equal_one_run(whole, cuts) -> None:
    closed, reference = whole
    stream = _stream(closed=closed, excitations=EXCITATIONS)
    edges = [0, *sorted(cuts), N]
    blocks = [stream.step(b - a) for a, b in itertools.pairwise(edges)]

    _same(concatenate_blocks(blocks), reference)
    assert stream.samples_done == N


def test_fixed_blocks_of_100(whole) -> None:
    closed, reference = whole
    _same(_stream(closed=closed, excitations=EXCITATIONS).run(N, block=100), reference)


@pytest.mark.parametrize("cut", [0, 1234])
def test_without_the_attocube_every_other_signal_is_the_same(whole, cut: int) -> None:
    """A record that holds no Va runs the bench without its Attocube: the Attocube reads the
    loop, never acts on it, and its noises have their own generators."""
    closed, reference = whole
    stream = BenchStream(P, seed=7, name="test", plant=PLANT,
                         controller=_controller() if closed else None,
                         excitations=EXCITATIONS, distance=False)
    stream.set_environment(compensation_unit=False, shielding=True)  # nothing to switch
    blocks = [stream.step(cut), stream.step(N - cut)]
    without = concatenate_blocks(blocks)
    assert without.va is None
    for field in ("dac", "adc", "internal"):
        np.testing.assert_array_equal(getattr(without, field), getattr(reference, field))
    for key in reference.noise:
        np.testing.assert_array_equal(without.noise[key], reference.noise[key])
    with pytest.raises(KeyError, match="without the Attocube"):
        without.signal("Va")


def test_generic_loop_equals_specialised() -> None:
    a = BenchStream(P, seed=1, name="x", plant=PLANT, controller=_controller(),
                    excitations=EXCITATIONS, specialise=False).step(500)
    b = BenchStream(P, seed=1, name="x", plant=PLANT, controller=_controller(),
                    excitations=EXCITATIONS).step(500)
    _same(a, b)


def _quiet_stream(**kw) -> BenchStream:
    """The bench with ideal converters (no quantisation, no rails)."""
    conv = dataclasses.replace(P.converter, bits=0)
    quiet = dataclasses.replace(P, converter=conv)
    return BenchStream(quiet, seed=0, name="quiet", plant=PLANT, **kw)


def test_closing_and_swapping_is_bumpless() -> None:
    s = BenchStream(P, seed=2, name="swap", plant=PLANT,
                    excitations=(Excitation("Unh", "sine", 1.0, 0.0, freq_hz=5.0),))
    s.step(2000)
    closing = s.set_controller(_controller())
    # Closing from an open loop with nothing held: the first command is the held zero.
    np.testing.assert_allclose(closing.command_after_v, closing.command_before_v, atol=1e-12)
    s.step(2000)
    swap = s.set_controller(_controller(gain=0.5, name="half gain"))
    # Least-norm state solve: rounding of a small least-squares problem only.
    assert swap.bump_v <= 1e-9 * max(1.0, float(np.max(np.abs(swap.command_before_v))))
    assert np.max(np.abs(swap.command_before_v)) > 1e-4  # the controller was really working
    s.step(100)
    opening = s.set_controller(None, hold=True)
    np.testing.assert_allclose(opening.command_after_v, opening.command_before_v, atol=1e-12)
    held = s.held_command_v
    block = s.step(10)
    uc = [DAC_CHANNELS.index("Uch"), DAC_CHANNELS.index("Ucv")]
    lsb = P.converter.lsb_v
    # The DAC rounds the held command to its step.
    np.testing.assert_allclose(block.dac[:, uc], np.broadcast_to(held[uc], (10, 2)),
                               atol=lsb / 2 + 1e-15)


def test_first_command_after_swap_is_continuous_in_the_samples() -> None:
    # The command the DAC outputs right after the swap continues the one before it:
    # its jump is no larger than the sample-to-sample steps the controller made anyway.
    s = _quiet_stream(controller=_controller(),
                      excitations=(Excitation("Unv", "sine", 1.0, 0.0, freq_hz=2.0),))
    before = s.step(3000)
    s.set_controller(_controller(gain=0.5, name="half"))
    after = s.step(3)
    uc = [DAC_CHANNELS.index("Uch"), DAC_CHANNELS.index("Ucv")]
    steps = np.abs(np.diff(before.dac[-50:, uc], axis=0)).max(axis=0)
    jump = np.abs(after.dac[0, uc] - before.dac[-1, uc])
    assert np.all(jump <= 3 * steps + 1e-12)


def test_opening_without_hold_returns_to_zero() -> None:
    s = _stream(closed=True, excitations=(Excitation("Unh", "sine", 1.0, 0.0, freq_hz=1.0),))
    s.step(3000)
    trip = s.set_controller(None, hold=False)
    np.testing.assert_array_equal(trip.command_after_v, np.zeros(4))
    assert s.controller is None
    np.testing.assert_array_equal(s.held_command_v, np.zeros(4))


@pytest.mark.parametrize("bad", [
    Excitation("Xyz", "noise", 0.1, 0.0),
    Excitation("Uch", "sine", 20.0, 0.0, freq_hz=1.0),
])
def test_bad_excitation_refused(bad: Excitation) -> None:
    with pytest.raises(ValueError, match=r"channel|range"):
        _stream(closed=False).add_excitation(bad)


def test_multisine_rms_and_lines() -> None:
    s = _quiet_stream(excitations=(Excitation("Unh", "multisine", 0.1, 0.0, band_hz=(5.0, 95.0),
                                              period_s=0.1),))
    u = s.step(1000).dac[:, DAC_CHANNELS.index("Unh")]
    # Whole periods of equal-amplitude lines: the rms is exact (float rounding only).
    assert np.sqrt(np.mean(u**2)) == pytest.approx(0.1, rel=1e-9)
    spectrum = np.abs(np.fft.rfft(u)) / u.size
    f = np.fft.rfftfreq(u.size, 1 / s.fs_hz)
    lines = f[spectrum > 1e-6]
    np.testing.assert_allclose(lines, np.arange(10.0, 91.0, 10.0))


def test_identification_does_not_import_the_twin() -> None:
    import subprocess
    import sys

    code = ("import sys, fsmbench.ident.pipeline, fsmbench.ident.validate; "
            "print(sorted(m for m in sys.modules if m.startswith('fsmbench.twin')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
