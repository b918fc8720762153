"""Noise, error budget, huddle tests and repeatability (ESRF study sections 3, 4 and 11).

Entry point: :func:`budget_study` (everything on the recordings present). The
numerics draw nothing: the report's figures are built in
:mod:`fsmbench.report.figures.budget` and :mod:`fsmbench.report.figures.repeatability`.
Called, ``fsmbench.budget(recordings, ...)`` is the public :func:`fsmbench.api.budget`.
"""

from fsmbench.budget.environment import (
    AirBudget,
    FrameBudget,
    air_budget,
    frame_budget,
    ou_window_factor,
)
from fsmbench.budget.huddle import (
    HUDDLE_CONFIGS,
    ConfigComparison,
    DacNoiseEstimate,
    HuddleAnalysis,
    HuddleRecord,
    QdNoiseEstimate,
    analyse_huddle,
    analyse_huddle_record,
    estimate_dac_noise,
    estimate_qd_noise,
    trim_huddle,
)
from fsmbench.budget.optics import GeometryBudget, geometry_budget
from fsmbench.budget.propagation import (
    LoopResponse,
    NoiseInput,
    PropagatedSource,
    QuadraticDistance,
    budget_grid,
    distance_coefficients,
    loop_response,
    propagate,
    quadratic_distance,
)
from fsmbench.budget.quantisation import NoiseSources, noise_sources
from fsmbench.budget.repeatability import (
    RepeatabilityRecord,
    align_periods,
    analyse_repeatability,
)
from fsmbench.budget.result import BudgetResult, NonRepeatability
from fsmbench.budget.spectra import cumulative_power, esrf_welch, first_order_lowpass
from fsmbench.budget.study import budget_study
from fsmbench.budget.table import BudgetRow, ErrorBudget, error_budget

__all__ = [
    "HUDDLE_CONFIGS",
    "AirBudget",
    "BudgetResult",
    "BudgetRow",
    "ConfigComparison",
    "DacNoiseEstimate",
    "ErrorBudget",
    "FrameBudget",
    "GeometryBudget",
    "HuddleAnalysis",
    "HuddleRecord",
    "LoopResponse",
    "NoiseInput",
    "NoiseSources",
    "NonRepeatability",
    "PropagatedSource",
    "QdNoiseEstimate",
    "QuadraticDistance",
    "RepeatabilityRecord",
    "air_budget",
    "align_periods",
    "analyse_huddle",
    "analyse_huddle_record",
    "analyse_repeatability",
    "budget_grid",
    "budget_study",
    "cumulative_power",
    "distance_coefficients",
    "error_budget",
    "esrf_welch",
    "estimate_dac_noise",
    "estimate_qd_noise",
    "first_order_lowpass",
    "frame_budget",
    "geometry_budget",
    "loop_response",
    "noise_sources",
    "ou_window_factor",
    "propagate",
    "quadratic_distance",
    "trim_huddle",
]

# fsmbench.budget is also the API's budget(): importing this package rebinds the name.
from fsmbench.entry import callable_module as _callable

_callable(__name__)
