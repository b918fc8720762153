"""One JSON convention for every result: plain Python numbers, NaN and ±inf as null."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

__all__ = ["plain_json"]


def plain_json(value: Any) -> Any:
    """JSON-safe copy: numpy scalars and arrays to Python numbers and lists, NaN and ±inf to
    None, tuples to lists, complex numbers to ``{"re": …, "im": …}``."""
    if isinstance(value, Mapping):
        return {str(k): plain_json(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [plain_json(v) for v in value]
    if isinstance(value, np.ndarray):
        return plain_json(value.tolist())
    if isinstance(value, bool | np.bool_):
        return bool(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, complex | np.complexfloating):
        return {"re": plain_json(value.real), "im": plain_json(value.imag)}
    return value
