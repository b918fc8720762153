"""The digital twin: a 10 kHz discrete-time simulation of the whole bench."""

from fsmbench.sim.controller import feedback_controller
from fsmbench.twin.experiments import ExperimentSpec, seed_experiments
from fsmbench.twin.simulate import TwinRun, simulate_bench, simulate_experiment, write_twin

__all__ = [
    "ExperimentSpec",
    "TwinRun",
    "feedback_controller",
    "seed_experiments",
    "simulate_bench",
    "simulate_experiment",
    "write_twin",
]
