"""A folder of recordings in the seed's layout, read as one set.

:func:`load_recordings` reads every seed experiment a folder holds and says,
for every experiment it does not use, why; what a user should know about the
files it did use (saturation, dropped variables …) comes back as
:class:`~fsmbench.checks.Notice` records and plausibility verdicts as
:class:`~fsmbench.checks.Check` records, never as Python warnings.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import xarray as xr

from fsmbench.checks import Check, Notice
from fsmbench.io.errors import RecordingError, SaturationWarning
from fsmbench.io.recording import find_experiments, read_recording
from fsmbench.io.signals import EXPERIMENTS

__all__ = ["RecordingSet", "load_recordings"]


@dataclass(frozen=True, eq=False)
class RecordingSet:
    """The recordings of one folder and what was found about them.

    Attributes
    ----------
    folder : str
    recordings : dict of str to xarray.Dataset
        Experiment name to recording, in the seed's order.
    skipped : dict of str to str
        Experiment name to the reason it is not used (missing file, or the
        problem naming file, variable and problem).
    notices : tuple of Notice
        Non-fatal findings (saturation, dropped variables …).
    checks : tuple of Check
        Plausibility checks run on the recordings.
    """

    folder: str
    recordings: dict[str, xr.Dataset]
    skipped: dict[str, str] = field(default_factory=dict)
    notices: tuple[Notice, ...] = ()
    checks: tuple[Check, ...] = ()

    def to_json(self) -> dict[str, Any]:
        """JSON-ready summary (no arrays)."""
        return {"folder": self.folder, "experiments": list(self.recordings),
                "skipped": dict(self.skipped),
                "notices": [n.to_json() for n in self.notices],
                "checks": [c.to_json() for c in self.checks]}


def _notice_of(w: warnings.WarningMessage, name: str) -> Notice:
    if isinstance(w.message, SaturationWarning):
        return Notice("saturation", f"{name}", str(w.message))
    return Notice("other", name, str(w.message))


def load_recordings(data_dir: Path, *, progress: Callable[[str], None] | None = None
                    ) -> RecordingSet:
    """Read every seed experiment present in ``data_dir``.

    Parameters
    ----------
    data_dir : Path
        Folder of recordings (``data_uch.mat`` …; ``.h5``/``.nxs`` too).
    progress : callable, optional
        Receives one message per file read.
    """
    found = find_experiments(data_dir)
    recordings: dict[str, xr.Dataset] = {}
    skipped: dict[str, str] = {}
    notices: list[Notice] = []
    for name in EXPERIMENTS:
        if name not in found:
            skipped[name] = f"no {name}.mat (or .h5/.nxs) in {data_dir}"
            continue
        if progress is not None:
            progress(f"reading {found[name].name}")
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                recordings[name] = read_recording(found[name], experiment=name)
        except RecordingError as exc:
            skipped[name] = str(exc)
            continue
        notices += [_notice_of(w, name) for w in caught]
    return RecordingSet(folder=str(data_dir), recordings=recordings, skipped=skipped,
                        notices=tuple(notices))
