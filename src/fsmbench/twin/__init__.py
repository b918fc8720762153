"""The digital twin: a 10 kHz discrete-time simulation of the whole bench."""

from fsmbench.sim.controller import feedback_controller
from fsmbench.twin.experiments import ExperimentSpec, esrf_experiments
from fsmbench.twin.simulate import TwinRun, simulate_bench, simulate_experiment, write_twin

__all__ = [
    "ExperimentSpec",
    "TwinRun",
    "esrf_experiments",
    "feedback_controller",
    "simulate_bench",
    "simulate_experiment",
    "write_twin",
]
