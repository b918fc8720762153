"""A given sample array played on a DAC channel: blocks equal one run, bit for bit."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fsmbench.bench.params import default_bench
from fsmbench.sim.excitation import Excitation, ExcitationStream, SampledExcitation
from fsmbench.sim.plant import DAC_CHANNELS, twin_discrete
from fsmbench.sim.stream import BenchStream, concatenate_blocks

P = default_bench().true
PLANT = twin_discrete(P)
FS = P.converter.fs_hz
N = 3000
SAMPLES = 0.05 * np.sin(2 * np.pi * 37.0 * np.arange(700) / FS) + 0.01 * np.random.default_rng(
    5).standard_normal(700)


def _played(loop_from: int | None) -> SampledExcitation:
    return SampledExcitation("Ucv", "samples", 0.03, 0.01235, samples_v=SAMPLES,
                             loop_from=loop_from)


@settings(max_examples=10, deadline=None)
@given(n1=st.integers(min_value=0, max_value=N), n2=st.integers(min_value=0, max_value=N),
       loop_from=st.sampled_from([None, 0, 100]))
def test_step_n1_then_n2_equals_step_n1_plus_n2(n1: int, n2: int, loop_from: int | None) -> None:
    ex = _played(loop_from)
    whole = BenchStream(P, seed=3, name="s", plant=PLANT, excitations=(ex,)).step(n1 + n2)
    s = BenchStream(P, seed=3, name="s", plant=PLANT, excitations=(ex,))
    parts = concatenate_blocks([s.step(n1), s.step(n2)])
    # Bit for bit: the stream promises identical samples, not close ones.
    for field in ("dac", "adc", "internal"):
        np.testing.assert_array_equal(getattr(parts, field), getattr(whole, field))


@pytest.mark.parametrize("loop_from", [None, 0, 100])
def test_samples_start_on_time_then_zero_or_repeat(loop_from: int | None) -> None:
    ex = _played(loop_from)
    stream = ExcitationStream(ex, fs_hz=FS, rng=np.random.default_rng(0))
    cuts = [0, 17, 140, 900, 1500, 2600]
    x = np.concatenate([stream.next(a, b - a) for a, b in itertools.pairwise(cuts)])
    start = 124  # first k with k / 10 kHz >= 12.35 ms
    assert np.all(x[:start] == 0.0)
    np.testing.assert_array_equal(x[start:start + SAMPLES.size], SAMPLES)
    after = x[start + SAMPLES.size:]
    if loop_from is None:
        assert np.all(after == 0.0)
    else:
        span = SAMPLES[loop_from:]
        reps = np.tile(span, after.size // span.size + 1)[:after.size]
        np.testing.assert_array_equal(after, reps)
    assert stream.peak_v() == np.max(np.abs(SAMPLES))


def test_dac_plays_the_samples_quantised() -> None:
    block = BenchStream(P, seed=0, name="d", plant=PLANT, excitations=(_played(None),)).step(N)
    dac = block.dac[:, DAC_CHANNELS.index("Ucv")]
    expected = np.zeros(N)
    expected[124:124 + SAMPLES.size] = SAMPLES
    # The DAC rounds to its step: half an LSB.
    np.testing.assert_allclose(dac, expected, atol=P.converter.lsb_v / 2 + 1e-15)


def test_sampled_excitation_checks_and_compares_by_samples() -> None:
    a, b = _played(None), _played(None)
    assert a == b and a.samples_sha256 == b.samples_sha256
    assert a != SampledExcitation("Ucv", "samples", 0.03, 0.01235, samples_v=SAMPLES * 2)
    assert not a.samples_v.flags.writeable
    with pytest.raises(ValueError, match="kind 'samples'"):
        SampledExcitation("Ucv", "noise", 0.03, 0.0, samples_v=SAMPLES)
    with pytest.raises(ValueError, match="finite 1-D"):
        SampledExcitation("Ucv", "samples", 0.03, 0.0, samples_v=np.array([1.0, np.nan]))
    with pytest.raises(ValueError, match="loop start 700"):
        SampledExcitation("Ucv", "samples", 0.03, 0.0, samples_v=SAMPLES, loop_from=700)
    with pytest.raises(ValueError, match="must be a SampledExcitation"):
        ExcitationStream(Excitation("Ucv", "samples", 0.03, 0.0), fs_hz=FS,
                         rng=np.random.default_rng(0))
    with pytest.raises(ValueError, match="peaks at"):
        BenchStream(P, seed=0, name="x", plant=PLANT, excitations=(
            SampledExcitation("Ucv", "samples", 20.0, 0.0, samples_v=np.array([0.0, 11.0])),))
