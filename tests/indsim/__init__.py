"""indsim: a second, independent simulator of the Sercalo beam-stabilisation bench.

Written from the physics of the ESRF study (no code shared with fsmbench):
:class:`IndBench` holds a bench's parameters (frames and signs in
:mod:`indsim.bench`), :func:`simulate_bench` runs the study's thirteen
recordings on it and :func:`write_bench` writes them with ``truth.json``;
:func:`corpus` names the benches, ``python -m indsim OUT`` writes them.
"""

from .bench import HV, IndBench
from .corpus import corpus
from .model import BenchModel, bench_model
from .write import BenchRun, simulate_bench, write_bench

__all__ = ["HV", "BenchModel", "BenchRun", "IndBench", "bench_model", "corpus",
           "simulate_bench", "write_bench"]
