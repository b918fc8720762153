"""The bench simulation engine: one discrete-time bench, advanced block by block.

Everything that simulates the bench runs on it: the twin's experiments
(:mod:`fsmbench.twin`), the identification's time-domain validation, the
design's verification on the twin and the live device (:mod:`fsmbench.live`).
"""

from fsmbench.sim.engine import DiscreteController, Quantiser, run_loop
from fsmbench.sim.excitation import Excitation
from fsmbench.sim.stream import BenchBlock, BenchStream, ControllerSwitch

__all__ = [
    "BenchBlock",
    "BenchStream",
    "ControllerSwitch",
    "DiscreteController",
    "Excitation",
    "Quantiser",
    "run_loop",
]
