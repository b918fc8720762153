"""Shared fixtures: the default bench, its plants, and short twin runs."""

from __future__ import annotations

import numpy as np
import pytest

from fsmbench.bench.blocks import PlantModel, physical_plant
from fsmbench.bench.params import Bench, default_bench
from fsmbench.io.matwrite import save_mat
from fsmbench.study import StudyResult, run_study
from fsmbench.twin import TwinRun, simulate_bench, write_twin


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
    """The six identification experiments at the ESRF study's lengths (11–33 s)."""
    return simulate_bench(seed=0, experiments=["data_cal_pd_h", "data_cal_pd_v", "data_uch",
                                               "data_ucv", "data_unh", "data_unv"])


@pytest.fixture(scope="session")
def twin_study(tmp_path_factory: pytest.TempPathFactory) -> StudyResult:
    """The whole study on the twin, 5 s records: report, summary and every stage's files."""
    return run_study(out_dir=tmp_path_factory.mktemp("twin-study"), duration_s=5.0)


@pytest.fixture(scope="session")
def broken_study(short_twin: TwinRun, tmp_path_factory: pytest.TempPathFactory) -> StudyResult:
    """The study on recorded data where ``data_unh.mat`` holds a NaN in ``Vph``."""
    data = tmp_path_factory.mktemp("broken-data")
    write_twin(TwinRun(recordings={k: v for k, v in short_twin.recordings.items()
                                   if k != "data_unh"},
                       truth=short_twin.truth, seed=short_twin.seed,
                       experiments=short_twin.experiments), data)
    (data / "twin_truth.json").unlink()  # recorded data: no truth beside it
    ds = short_twin.recordings["data_unh"]
    bad = {"t": ds["t"].values, **{str(k): ds[k].values.copy() for k in ds.data_vars}}
    bad["Vph"][123] = np.nan
    save_mat(data / "data_unh.mat", bad)
    return run_study(out_dir=tmp_path_factory.mktemp("broken-study"), data_dir=data)
