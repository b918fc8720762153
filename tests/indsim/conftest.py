"""indsim's tests: ``tests/`` on ``sys.path`` and short simulated benches."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

_TESTS = str(Path(__file__).resolve().parents[1])
if _TESTS not in sys.path:
    sys.path.append(_TESTS)  # last: its folders must shadow no installed package

from indsim import BenchRun, corpus, simulate_bench  # noqa: E402

SHORT = 0.05  # duration scale of the test runs: 3-5 s per record


@pytest.fixture(scope="session")
def benches() -> dict:
    """The corpus, ``name -> IndBench``."""
    return corpus()


@pytest.fixture(scope="session")
def plain_run(benches: dict) -> BenchRun:
    """The plain bench, every record at a tenth of the study's length."""
    return simulate_bench(benches["plain"], seed=3, duration_scale=SHORT)


@pytest.fixture(scope="session")
def runs(benches: dict, plain_run: BenchRun) -> dict[str, BenchRun]:
    """A few benches that differ in signs, gains, amplifier and rate, short records."""
    names = ["sercalo_h_flipped", "all_flipped", "weak", "hot", "qd_amp1_2k",
             "rotated_modes", "fs5k", "fs20k", "real_like", "back_emf"]
    out = {n: simulate_bench(benches[n], seed=5, duration_scale=SHORT) for n in names}
    out["plain"] = plain_run
    return out
