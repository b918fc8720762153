"""Fixtures of the spectral estimators' tests."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture
def rng() -> np.random.Generator:
    """Fixed-seed generator: tolerances hold for any seed; the seed makes runs repeatable."""
    return np.random.default_rng(20240611)
