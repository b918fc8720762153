"""The bench: parameters, physics blocks, geometry and the assembled plant model."""

from fsmbench.bench.params import (
    Bench,
    BenchParams,
    ParamsError,
    PerAxis,
    default_bench,
    load_bench,
    param_rows,
    real_bench,
    save_bench,
)

__all__ = [
    "Bench",
    "BenchParams",
    "ParamsError",
    "PerAxis",
    "default_bench",
    "load_bench",
    "param_rows",
    "real_bench",
    "save_bench",
]
