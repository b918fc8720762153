"""Shared fixtures: the default bench, its plants, and short twin runs."""

from __future__ import annotations

import pytest

from fsmbench.bench.blocks import PlantModel, physical_plant
from fsmbench.bench.params import Bench, default_bench


@pytest.fixture(scope="session")
def bench() -> Bench:
    """The packaged Sercalo bench."""
    return default_bench()


@pytest.fixture(scope="session")
def true_plant(bench: Bench) -> PlantModel:
    """Physical plant with the twin's true parameters."""
    return physical_plant(bench.true, source="physical (true)")


@pytest.fixture(scope="session")
def nominal_plant(bench: Bench) -> PlantModel:
    """Physical plant with the nominal parameters."""
    return physical_plant(bench.nominal, source="physical (nominal)")
