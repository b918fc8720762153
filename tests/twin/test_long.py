"""Experiments streamed to NeXus equal the in-memory twin, sample for sample."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fsmbench.bench.params import default_bench
from fsmbench.io.nexus import read_nexus
from fsmbench.twin.experiments import esrf_experiments
from fsmbench.twin.long import RunningMoments, StreamProgress, stream_experiment
from fsmbench.twin.simulate import simulate_bench, stream_bench

BENCH = default_bench()


def test_stream_bench_equals_simulate_bench(tmp_path: Path) -> None:
    names = ["data_uch", "data_huddle_test_5"]
    lines: list[str] = []
    paths = stream_bench(BENCH, out_dir=tmp_path, seed=4, duration_s=6.0, experiments=names,
                         progress=lines.append)
    run = simulate_bench(BENCH, seed=4, duration_s=6.0, experiments=names)
    for name in names:
        streamed = read_nexus(tmp_path / f"{name}.h5")
        whole = run.recordings[name]
        assert list(streamed.data_vars) == list(whole.data_vars)
        for v in ("t", *whole.data_vars):
            # Bit for bit: the stream's blocks are the whole run's samples (tests/sim).
            np.testing.assert_array_equal(streamed[v].values, whole[v].values, err_msg=v)
    assert paths[-1].name == "twin_truth.json"
    assert any("data_uch: 60,000 of 60,000 samples (100.0 %)" in line for line in lines)


def test_blocks_and_realized_noise(tmp_path: Path) -> None:
    spec = next(s for s in esrf_experiments(duration_s=5.0) if s.name == "data_huddle_test_1")
    seen: list[StreamProgress] = []
    realized = stream_experiment(BENCH, spec, seed=2, path=tmp_path / "a.h5", block_s=0.37,
                                 progress=seen.append, progress_every_s=0.0)
    run = simulate_bench(BENCH, seed=2, duration_s=5.0, experiments=["data_huddle_test_1"])
    whole = run.truth["realized"]["data_huddle_test_1"]
    # Running moments over 0.37 s blocks against np.std of the whole: rounding only.
    assert realized["qd_noise_v.h"] == pytest.approx(whole["qd_noise_v"]["h"], rel=1e-12)
    assert realized["va_total"] == pytest.approx(whole["va_total"], rel=1e-12)
    assert seen[-1].samples_done == seen[-1].samples_total == 50_000
    assert len(seen) == 14  # ceil(5 / 0.37) blocks, one report each


@pytest.mark.parametrize("sizes", [[1], [3, 1, 7], [1000, 1, 1, 2500]])
def test_running_moments(sizes: list[int]) -> None:
    rng = np.random.default_rng(0)
    blocks = [1e3 + rng.normal(size=n) for n in sizes]
    m = RunningMoments()
    for b in blocks:
        m.add(b)
    x = np.concatenate(blocks)
    # A 1e3 offset on unit noise: the pairwise update keeps ~1e-13 where naive sums lose 1e-10.
    assert m.mean == pytest.approx(x.mean(), rel=1e-14)
    assert m.std == pytest.approx(x.std(), rel=1e-10, abs=1e-12)
