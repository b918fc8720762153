"""The twin's ``twin_truth.json``: what the twin really was, when it is there.

A data folder written by ``fsmbench simulate`` holds ``twin_truth.json`` next
to the records; recorded data do not. It is optional, but when present it
must be a complete JSON object: a truncated or edited file is an error that
names the file, not a silent "no truth".
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from fsmbench.io.errors import RecordingError

__all__ = ["TRUTH_FILE", "read_twin_truth"]

#: Name of the twin's truth file in a data folder.
TRUTH_FILE = "twin_truth.json"


def read_twin_truth(path: str | Path) -> dict[str, Any] | None:
    """Read ``twin_truth.json``.

    Parameters
    ----------
    path : str or Path
        The file, or the data folder holding it.

    Returns
    -------
    dict or None
        The truth; None when the file does not exist.

    Raises
    ------
    RecordingError
        The file exists but cannot be read, is not UTF-8, not valid JSON
        (e.g. truncated: the line and column are named) or not a JSON object.
    """
    p = Path(path)
    if p.is_dir():
        p = p / TRUTH_FILE
    if not p.exists():
        return None
    try:
        text = p.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise RecordingError(p, f"is not UTF-8 text ({exc.reason} at byte {exc.start})") from exc
    except OSError as exc:
        raise RecordingError(p, f"cannot be read ({exc.strerror})") from exc
    try:
        payload = json.loads(text)
    except json.JSONDecodeError as exc:
        # Truncated: the error is at the end, or a string runs to the end of the file.
        cut = exc.pos >= len(text.rstrip()) or (exc.msg.startswith("Unterminated string")
                                               and '"' not in text[exc.pos + 1:])
        end = " (the file is truncated)" if cut else ""
        raise RecordingError(p, f"is not valid JSON: {exc.msg} at line {exc.lineno}, column "
                                f"{exc.colno}{end}; restore it from `fsmbench simulate` or "
                                "delete it (it is optional)") from exc
    if not isinstance(payload, dict):
        raise RecordingError(p, f"holds a JSON {type(payload).__name__}, not an object; restore "
                                "it from `fsmbench simulate` or delete it (it is optional)")
    return payload
