"""Shared fixtures: the default bench, its plants, and short twin runs."""

from __future__ import annotations

import pytest

from fsmbench.bench.blocks import PlantModel, physical_plant
from fsmbench.bench.params import Bench, default_bench
from fsmbench.twin import TwinRun, simulate_bench


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


@pytest.fixture(scope="session")
def short_twin() -> TwinRun:
    """All thirteen experiments, 5 s each (the shortest every protocol accepts)."""
    return simulate_bench(seed=1, duration_s=5.0)


@pytest.fixture(scope="session")
def ident_twin() -> TwinRun:
    """The six identification experiments at the seed's lengths (11–33 s)."""
    return simulate_bench(seed=0, experiments=["data_cal_pd_h", "data_cal_pd_v", "data_uch",
                                               "data_ucv", "data_unh", "data_unv"])
