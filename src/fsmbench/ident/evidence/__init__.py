"""What the records say about the bench before any model of it is trusted.

The bench file is a prior; the recordings are the evidence. This package reads
the evidence that the identification steps do not: the controller a
closed-loop record ran (:mod:`~fsmbench.ident.evidence.recorded_loop`).
"""

from fsmbench.ident.evidence.recorded_loop import (
    CLOSED_LOOP_RECORDS,
    ControllerFit,
    RecordedController,
    recorded_controllers,
)

__all__ = ["CLOSED_LOOP_RECORDS", "ControllerFit", "RecordedController", "recorded_controllers"]
