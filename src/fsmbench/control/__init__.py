"""Plant analysis, controllers (the ESRF study's and fsmbench's), discretisation and export.

Entry point: :func:`design_study` (ESRF study sections 5–10 on a plant model); the
ESRF study's controllers are in :mod:`fsmbench.bench.esrf`. The report's figures
of these results are built in :mod:`fsmbench.report.figures.control`.
"""

from fsmbench.bench.esrf import (
    esrf_decentralised_controller,
    iff_controller,
    newport_controller,
    tustin,
)
from fsmbench.bench.sections import zpk_cascade
from fsmbench.control.study import DesignResult, StudyOptions, design_study

__all__ = [
    "DesignResult",
    "StudyOptions",
    "design_study",
    "esrf_decentralised_controller",
    "iff_controller",
    "newport_controller",
    "tustin",
    "zpk_cascade",
]
