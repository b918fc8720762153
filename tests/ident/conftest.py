"""Shared fixtures for the identification tests: seeded noise, known filters, seed-like data."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
import scipy.signal as ss

FS_HZ = 1e4  # the seed's sampling frequency


def _resonance(f0_hz: float, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Second-order digital resonance with unit DC gain (poles radius*exp(+-j 2 pi f0/fs))."""
    theta = 2.0 * np.pi * f0_hz / FS_HZ
    a = np.array([1.0, -2.0 * radius * np.cos(theta), radius**2])
    return np.array([a.sum()]), a


def pytest_configure(config: pytest.Config) -> None:
    """The ``slow`` mark: minutes-long Monte Carlo runs (tests/ident/test_coverage.py)."""
    config.addinivalue_line("markers", "slow: a Monte Carlo run of minutes (-m 'not slow' skips)")


FILTERS = {
    "first-order low-pass": (np.array([0.1]), np.array([1.0, -0.9])),
    "second-order resonance": _resonance(411.0, 0.95),
}


@pytest.fixture
def rng() -> np.random.Generator:
    """Fixed-seed generator: tolerances hold for any seed; the seed makes runs repeatable."""
    return np.random.default_rng(20240611)


@pytest.fixture(params=sorted(FILTERS))
def digital_filter(request: pytest.FixtureRequest) -> tuple[str, np.ndarray, np.ndarray]:
    """(name, b, a) of a known digital filter with a smooth, well-resolved response."""
    b, a = FILTERS[request.param]
    return request.param, b, a


@pytest.fixture
def resonance_ba() -> tuple[np.ndarray, np.ndarray]:
    """The seed's lightly damped mode near 411 Hz (digital, fs = 10 kHz)."""
    return FILTERS["second-order resonance"]


@dataclass(frozen=True)
class Experiment:
    """One single-input identification run: excitation column, two measured outputs."""

    input_name: str
    inputs: np.ndarray  # (N, 1)
    outputs: np.ndarray  # (N, 2), columns Vph, Vpv


@pytest.fixture
def esrf_experiments(
    rng: np.random.Generator, resonance_ba: tuple[np.ndarray, np.ndarray]
) -> dict[str, Experiment]:
    """data_uch / data_ucv look-alikes: 6 s at 10 kHz, white excitation, coupled outputs."""
    b, a = resonance_ba
    n = int(6 * FS_HZ)
    gains = {"Uch": (1.0, 0.2), "Ucv": (0.1, 0.8)}  # (Vph, Vpv) gain of each excitation
    out = {}
    for name, (g_h, g_v) in gains.items():
        u = rng.standard_normal(n + 2000)
        y = ss.lfilter(b, a, u)
        outputs = np.column_stack([g_h * y, g_v * y])[2000:] + 0.01 * rng.standard_normal((n, 2))
        out[name] = Experiment(name, u[2000:, None], outputs)
    return out
