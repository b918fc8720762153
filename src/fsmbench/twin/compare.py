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

# key -> (kind, tolerance): "rel" relative, "abs" absolute in the key's unit.
TARGETS: dict[str, tuple[str, float]] = {
    **{f"qd_gain_v_per_rad.{a}": ("rel", 0.01) for a in "hv"},
    **{f"current_amp_gain_a_per_v.{a}": ("rel", 0.02) for a in "hv"},
    **{f"sercalo.{a}.resonance_hz": ("rel", 0.005) for a in "hv"},
    **{f"sercalo.{a}.damping_ratio": ("rel", 0.25) for a in "hv"},
    **{f"sercalo.{a}.dc_gain_v_per_a": ("rel", 0.03) for a in "hv"},
    **{f"newport_gain_v_per_v.{a}": ("rel", 0.03) for a in "hv"},
    # The Newport's two real poles are less sharply defined than a resonance: its natural
    # frequency's std is ~0.15 % at the seed's record lengths, 1 % is ~7 of them.
    **{f"newport.{a}.natural_freq_hz": ("rel", 0.01) for a in "hv"},
    **{f"newport.{a}.damping_ratio": ("rel", 0.25) for a in "hv"},
    **{f"newport.{a}.internal_delay_s": ("abs", 1e-4) for a in "hv"},  # one sample
    "delay_s.sercalo": ("abs", 1e-4),  # one sample
    "delay_s.newport": ("abs", 1e-4),
}


@dataclass(frozen=True)
class ComparisonRow:
    """One key: identified, reference, difference and whether the target holds.

    ``reference_kind`` is ``"true"`` (twin) or ``"nominal"``; ``within_target``
    is None against nominal values (the targets are for the twin).
    """

    key: str
    identified: float
    reference: float
    reference_kind: str
    relative_difference: float
    target: str
    within_target: bool | None

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
        rows.append(ComparisonRow(key=key, identified=ours, reference=theirs,
                                  reference_kind=kind, relative_difference=rel, target=target,
                                  within_target=(err <= tol) if reference is not None else None))
    return rows


def compare_with_truth(identified: Mapping[str, Any], *, reference: Mapping[str, Any] | None,
                       bench: Bench) -> list[str]:
    """Printable lines of :func:`comparison_rows` with a header."""
    head = (f"{'key':34s} {'identified':>13s} {'ref':>7s} {'value':>13s} {'diff':>9s}  "
            f"{'target':10s}")
    return [head, *(str(r) for r in comparison_rows(identified, reference=reference,
                                                     bench=bench))]
