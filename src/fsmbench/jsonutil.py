"""One JSON convention for every result: plain Python numbers, NaN and ±inf as null.

Every JSON file fsmbench writes starts with ``format`` (``"fsmbench.<name>"``)
and ``format_version`` (an int, bumped when a key is renamed, moved or changes
shape); ``docs/results.md`` describes each. A pair of values for the two axes
is always ``{"h": …, "v": …}`` (:func:`hv`), never a 2-element list.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

__all__ = ["format_text", "hv", "nested", "plain_json", "stamped"]


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


def hv(pair: Sequence[Any] | np.ndarray) -> dict[str, Any]:
    """An (h, v) pair as ``{"h": pair[0], "v": pair[1]}``.

    Parameters
    ----------
    pair : sequence or array, shape (2,)
        The horizontal then the vertical axis's value.

    Raises
    ------
    ValueError
        ``pair`` does not hold exactly two values.
    """
    if len(pair) != 2:
        raise ValueError(f"an (h, v) pair needs 2 values, got {len(pair)}")
    return {"h": pair[0], "v": pair[1]}


def stamped(payload: Mapping[str, Any], *, format: str, version: int) -> dict[str, Any]:
    """``payload`` with ``format`` and ``format_version`` first (they win over its own keys).

    Parameters
    ----------
    payload : mapping
        The file's content.
    format : str
        ``"fsmbench.<name>"``, as documented in ``docs/results.md``.
    version : int
        The format's version, ≥ 1.
    """
    if not format.startswith("fsmbench.") or version < 1:
        raise ValueError(f"format must be 'fsmbench.<name>' with a version >= 1, "
                         f"got {format!r} v{version}")
    rest = {k: v for k, v in payload.items() if k not in ("format", "format_version")}
    return {"format": format, "format_version": int(version), **rest}


def _sorted(value: Any) -> Any:
    """``value`` with every mapping's keys in sorted order, at every depth."""
    if isinstance(value, Mapping):
        return {k: _sorted(value[k]) for k in sorted(value)}
    if isinstance(value, list):
        return [_sorted(v) for v in value]
    return value


def format_text(payload: Mapping[str, Any], *, sort_keys: bool = False,
                indent: int | None = 2) -> str:
    """A format's file content: ``format`` and ``format_version`` its first two keys.

    ``json.dumps(..., sort_keys=True)`` would file them among the other keys in
    alphabetical order; here the rest is sorted (at every depth) behind them.

    Parameters
    ----------
    payload : mapping
        The file's content, holding ``format`` and ``format_version``
        (:func:`stamped`); made plain with :func:`plain_json` (NaN to null).
    sort_keys : bool
        Sort every other key, at every depth (reproducible files).
    indent : int or None
        As :func:`json.dumps`.

    Returns
    -------
    str
        Strict JSON text, ending with a newline.

    Raises
    ------
    ValueError
        When ``payload`` has no ``format`` or ``format_version``.
    """
    if "format" not in payload or "format_version" not in payload:
        raise ValueError(f"a result file needs 'format' and 'format_version', got keys "
                         f"{sorted(payload)[:8]}")
    plain = plain_json(payload)
    body = _sorted(plain) if sort_keys else plain
    ordered = stamped(body, format=str(plain["format"]), version=int(plain["format_version"]))
    return json.dumps(ordered, indent=indent, allow_nan=False, ensure_ascii=True) + "\n"


def nested(flat: Mapping[str, Any]) -> dict[str, Any]:
    """``{"a.h": 1, "a.v": 2, "b": 3}`` → ``{"a": {"h": 1, "v": 2}, "b": 3}`` (keys are ids)."""
    out: dict[str, Any] = {}
    for key, value in flat.items():
        *parents, last = key.split(".")
        node = out
        for part in parents:
            node = node.setdefault(part, {})
        node[last] = value
    return out
