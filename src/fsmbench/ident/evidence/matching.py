"""``bench_identified.toml``: the bench file that matches the records.

The user's bench file with every value the records measured set in
``[nominal]`` (:func:`~fsmbench.ident.evidence.departures.matching_params`); a
header lists the keys that departed from the user's file, with the evidence.
A rerun with ``--params bench_identified.toml`` models the bench as the records
describe it, and finds no departure.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import Final

from fsmbench.atomic import atomic_write_text
from fsmbench.bench.params import Bench
from fsmbench.checks import Finding

__all__ = ["MATCHING_BENCH", "matching_toml", "write_matching_bench"]

#: The file's name in an identification's output folder.
MATCHING_BENCH: Final = "bench_identified.toml"


def matching_toml(bench: Bench, *, findings: Iterable[Finding] = ()) -> str:
    """The TOML text: a header with the departures, then the whole bench."""
    found = list(findings)
    lines = ["# The bench file that matches the recordings, written by fsmbench identify.",
             "# [nominal] holds every value the records measured; the rest is the bench file's.",
             "# Rerun with --params bench_identified.toml to model the bench as measured."]
    if found:
        lines.append("# Departures from the bench file given (a finding about the bench, not a "
                     "fault):")
        for f in found:
            unit = "" if f.unit in ("", "1") else f" {f.unit}"
            lines.append(f"#   {f.key}: {f.bench_value:.6g} -> {f.measured:.6g}{unit} "
                         f"({f.subject})")
    else:
        lines.append("# The records agree with the bench file given: no departure.")
    return "\n".join(lines) + "\n" + bench.to_toml()


def write_matching_bench(path: Path, bench: Bench, *, findings: Iterable[Finding] = ()) -> Path:
    """Write :func:`matching_toml` atomically to ``path``; returns the path."""
    return atomic_write_text(Path(path), matching_toml(bench, findings=findings))
