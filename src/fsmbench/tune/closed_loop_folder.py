"""``fsmbench identify DATA`` on closed-loop records: detection, identification, what is printed.

A folder holding ``data_cl_uch`` and ``data_cl_ucv`` (:mod:`fsmbench.twin.closed_loop`'s
layout) and neither open-loop Sercalo record (``data_uch``, ``data_ucv``) is identified
with the loop closed (:func:`fsmbench.ident.closed_loop.identify_closed_loop`); the
output says so, and ``identification.json`` records it under
``diagnostics.closed_loop``. A folder with both kinds is identified in open loop as
before (the open-loop records carry more of the plant: the 4QD, the Newport).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fsmbench.ident.closed_loop import (
    ClosedLoopIdentifyOptions,
    find_closed_loop_records,
    identify_closed_loop,
    read_closed_loop_records,
    write_closed_loop_identification,
)

if TYPE_CHECKING:  # the identification is imported when a command runs, not with the CLI
    from fsmbench.bench.params import Bench
    from fsmbench.ident.closed_loop import ClosedLoopIdentification

__all__ = ["check_closed_loop_folder", "identify_closed_loop_folder", "is_closed_loop_folder",
           "summary_lines"]

_OPEN_LOOP_SERCALO = ("data_uch", "data_ucv")
_SUFFIXES = (".mat", ".h5", ".nxs")


def is_closed_loop_folder(folder: str | Path) -> bool:
    """Both closed-loop records and neither open-loop Sercalo record."""

    root = Path(folder)
    if not root.is_dir() or len(find_closed_loop_records(root)) < 2:
        return False
    return not any((root / f"{n}{s}").is_file() for n in _OPEN_LOOP_SERCALO for s in _SUFFIXES)


def check_closed_loop_folder(folder: str | Path) -> None:
    """Nothing if ``folder`` holds a closed-loop record (``identify --closed-loop``).

    Raises
    ------
    ValueError
        One line: the folder holds no ``data_cl_*`` record (what it holds instead).
    """

    root = Path(folder)
    if root.is_dir() and find_closed_loop_records(root):
        return
    held = sorted(p.name for p in root.iterdir() if p.suffix in _SUFFIXES) \
        if root.is_dir() else []
    what = (f"it holds {', '.join(held[:6])}{' ...' if len(held) > 6 else ''}" if held
            else "it holds no recording" if root.is_dir() else "it is not a folder")
    raise ValueError(f"{folder}: --closed-loop needs the closed-loop records data_cl_uch and "
                     f"data_cl_ucv (.mat, .h5 or .nxs; fsmbench simulate --closed-loop writes "
                     f"them); {what}")


def identify_closed_loop_folder(folder: str | Path, *, bench: Bench, out_dir: Path,
                                progress: Callable[[str], None] | None = None,
                                asked: bool = False
                                ) -> tuple[ClosedLoopIdentification, list[Path]]:
    """Identify the records of ``folder`` with the loop closed and write the results.

    ``asked``: ``identify --closed-loop`` (else detected: no open-loop Sercalo record).

    Raises
    ------
    RecordingError, ValueError
        A record missing, unreadable or failing its checks (named).
    """

    say = progress or (lambda _m: None)
    why = ("identify --closed-loop" if asked
           else "no open-loop Sercalo record")
    say(f"closed-loop records in {folder} (data_cl_uch, data_cl_ucv), {why}: identifying the "
        "Sercalo with the loop closed (joint input-output method)")
    recordings = read_closed_loop_records(folder)
    result = identify_closed_loop(recordings, bench=bench, options=ClosedLoopIdentifyOptions(),
                                  source=str(folder))
    return result, write_closed_loop_identification(result, out_dir)


def _pct(value: float, truth: float | None) -> str:
    if truth is None or truth == 0 or not math.isfinite(value):
        return ""
    return f" ({100 * (value / truth - 1):+.2f} % from the twin's truth {truth:.4g})"


def summary_lines(result: ClosedLoopIdentification,
                  truth: Mapping[str, Any] | None = None) -> list[str]:
    """What ``identify`` prints for a closed-loop identification, in words with units."""
    frf = result.frf
    where = ("the controller's output" if result.at == "output" else "the loop's reference")
    lines = [f"identified with the loop closed: {frf.method} (G = S_yr S_ur^-1, the "
             f"excitation at {where} as the instrument), {frf.frequency_hz.size} lines"]
    js = result.to_json()
    true_s = (truth or {}).get("sercalo") or {}
    for axis, words in (("h", "horizontal"), ("v", "vertical")):
        found = (js.get("sercalo") or {}).get(axis)
        if found is None:
            continue
        t = true_s.get(axis) or {}
        lines.append(f"Sercalo {words}: resonance {found['resonance_hz']:.3f} Hz"
                     f"{_pct(found['resonance_hz'], t.get('resonance_hz'))}, damping ratio "
                     f"{found['damping_ratio']:.3g}"
                     f"{_pct(found['damping_ratio'], t.get('damping_ratio'))}"
                     f", static gain {found['dc_gain_v_per_a']:.4g} V/A"
                     f"{_pct(found['dc_gain_v_per_a'], t.get('dc_gain_v_per_a'))}")
    delay = (js.get("delay_s") or {}).get("sercalo")
    if delay is not None:
        t_delay = ((truth or {}).get("delay_s") or {}).get("sercalo")
        extra = ("" if t_delay is None
                 else f" (twin's truth {1e6 * t_delay:.1f} µs, "
                      f"{(delay - t_delay) * frf.plant.fs_hz:+.2f} samples)")
        lines.append(f"Sercalo delay: {1e6 * delay:.1f} µs{extra}")
    for t in result.tracking:
        added = ", ".join(f"{a} {1e6 * v:.3g} µrad" for a, v in t.added_rms_rad.items())
        bound = ("" if t.bound_rad is None
                 else f" (bound {1e6 * t.bound_rad:.3g} µrad: "
                      f"{'within' if t.within_bound else 'exceeded'})")
        lines.append(f"beam error the excitation added during {t.record}: {added} rms{bound}")
    bias = result.direct_bias()
    low = bias.get("band_0_10_hz") or {}
    if low:
        lines.append("the direct method (y against u, as in open loop) on the same lines departs "
                     "from it by " + ", ".join(f"{100 * v:.0f} %" for v in low.values()
                                              if v is not None)
                     + " below 10 Hz (median, h and v): the feedback's bias")
    for step, why in result.skipped.items():
        lines.append(f"not identified: {step.replace('_', ' ')}: {why}")
    return lines
