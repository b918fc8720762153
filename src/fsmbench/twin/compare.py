"""Identified values against a reference: the twin's truth or the nominal model.

Lives beside the twin, not in :mod:`fsmbench.ident`: identification knows
nothing of the twin; the commands that print a comparison (``fsmbench
identify``, the study) bring the two together.

The identification issue's accuracy targets are attached to each key, so a
comparison says at a glance whether the identification met them (on the
twin) or how far the bench is from its datasheet (on recorded data).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import Any

from fsmbench.bench.params import Bench
from fsmbench.twin.truth import model_values

__all__ = ["TARGETS", "ComparisonRow", "compare_with_truth", "comparison_rows"]

# key -> (kind, tolerance): "rel" relative, "abs" absolute in the key's unit, "samples"
# absolute in sampling periods of the reference's (or the identification's) fs_hz.
TARGETS: dict[str, tuple[str, float]] = {
    **{f"qd_gain_v_per_rad.{a}": ("rel", 0.01) for a in "hv"},
    **{f"current_amp_gain_a_per_v.{a}": ("rel", 0.02) for a in "hv"},
    **{f"sercalo.{a}.resonance_hz": ("rel", 0.005) for a in "hv"},
    **{f"sercalo.{a}.damping_ratio": ("rel", 0.25) for a in "hv"},
    **{f"sercalo.{a}.dc_gain_v_per_a": ("rel", 0.03) for a in "hv"},
    **{f"newport_gain_v_per_v.{a}": ("rel", 0.03) for a in "hv"},
    # The Newport's two real poles have no sharp feature: its natural frequency is read from
    # the curvature of the roll-off. Its std is 0.15-0.3 % at 10 kHz and 0.7 % at 5 kHz (band
    # up to 2 kHz) on 10 s records with every real-bench feature on: 2 % is ~3 of the latter.
    **{f"newport.{a}.natural_freq_hz": ("rel", 0.02) for a in "hv"},
    **{f"newport.{a}.damping_ratio": ("rel", 0.25) for a in "hv"},
    **{f"newport.{a}.internal_delay_s": ("samples", 1.0) for a in "hv"},
    "delay_s.sercalo": ("samples", 1.0),  # one sample of the converter's rate
    "delay_s.newport": ("samples", 1.0),
}


@dataclass(frozen=True)
class ComparisonRow:
    """One key: identified, reference, difference and whether the target holds.

    ``reference_kind`` is ``"true"`` (twin) or ``"nominal"``; ``within_target``
    is None against nominal values (the targets are for the twin);
    ``tolerance_abs`` is the target in the key's unit for absolute targets
    (sample targets converted at the rate), None for relative ones.
    """

    key: str
    identified: float
    reference: float
    reference_kind: str
    relative_difference: float
    target: str
    within_target: bool | None
    tolerance_abs: float | None = None

    def to_json(self) -> dict[str, Any]:
        """Plain values."""
        return asdict(self)

    def __str__(self) -> str:
        mark = {True: "ok", False: "MISSED", None: ""}[self.within_target]
        return (f"{self.key:34s} {self.identified:13.6g} {self.reference_kind:>7s} "
                f"{self.reference:13.6g} {self.relative_difference:+9.2%}  "
                f"{self.target:10s} {mark}")


def _get(tree: Mapping[str, Any], key: str) -> float | None:
    node: Any = tree
    for part in key.split("."):
        if not isinstance(node, Mapping) or part not in node:
            return None
        node = node[part]
    return float(node) if isinstance(node, (int, float)) else None


def comparison_rows(identified: Mapping[str, Any], *, reference: Mapping[str, Any] | None,
                    bench: Bench) -> list[ComparisonRow]:
    """Rows for every target key present in ``identified``.

    ``reference`` is a ``twin_truth.json`` dict; without it the nominal model
    of ``bench`` is the reference. Only the keys of :data:`TARGETS` are
    compared: ``format``, ``format_version`` and every other key of either
    file are ignored.
    """
    kind = "true" if reference is not None else "nominal"
    ref = reference if reference is not None else model_values(bench.nominal)
    rows = []
    for key, (tol_kind, tol) in TARGETS.items():
        ours, theirs = _get(identified, key), _get(ref, key)
        if ours is None or theirs is None:
            continue
        rel = ours / theirs - 1 if theirs != 0 else float("nan")
        err = abs(rel) if tol_kind == "rel" else abs(ours - theirs)
        target = f"±{tol:.3g}" if tol_kind == "abs" else f"±{tol:.1%}"
        if tol_kind == "samples":
            fs = _get(ref, "fs_hz") or _get(identified, "fs_hz") or 1e4
            target = f"±{tol:g} sample ({tol / fs:.3g} s)"
            tol = tol / fs
        rows.append(ComparisonRow(key=key, identified=ours, reference=theirs,
                                  reference_kind=kind, relative_difference=rel, target=target,
                                  within_target=(err <= tol) if reference is not None else None,
                                  tolerance_abs=None if tol_kind == "rel" else tol))
    return rows


def compare_with_truth(identified: Mapping[str, Any], *, reference: Mapping[str, Any] | None,
                       bench: Bench) -> list[str]:
    """Printable lines of :func:`comparison_rows` with a header."""
    head = (f"{'key':34s} {'identified':>13s} {'ref':>7s} {'value':>13s} {'diff':>9s}  "
            f"{'target':10s}")
    return [head, *(str(r) for r in comparison_rows(identified, reference=reference,
                                                     bench=bench))]
