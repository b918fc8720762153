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

__all__ = ["COMPARISON_FORMAT", "TARGETS", "ComparisonRow", "compare_with_truth",
           "comparison_json", "comparison_rows", "quantity", "readable_table"]

#: ``fsmbench identify --json``'s format (2: stamped; each target as numbers,
#: ``target_relative`` / ``target_abs`` / ``target_samples``, and ``within_target_reason``
#: when ``within_target`` is null; version 1, unstamped, had the target as text).
COMPARISON_FORMAT = ("fsmbench.identify_comparison", 2)

#: Why a row against the bench file is not judged.
NOT_JUDGED_NOMINAL = ("no true value: the reference is the bench file's nominal value, and "
                      "the difference is how far this bench is from it, not an error of the "
                      "identification (the accuracy targets hold against the twin's truth)")

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
    is None when it cannot be judged, ``not_judged`` saying why (against nominal
    values: the targets are for the twin); ``tolerance_abs`` is the target in the
    key's unit for absolute targets (sample targets converted at the rate), None for
    relative ones; ``target_relative`` the relative target [1] (None for absolute
    ones); ``target_samples`` a sample target in sampling periods. ``target`` is the
    target as text, for display.
    """

    key: str
    identified: float
    reference: float
    reference_kind: str
    relative_difference: float
    target: str
    within_target: bool | None
    tolerance_abs: float | None = None
    target_relative: float | None = None
    target_samples: float | None = None
    not_judged: str = ""

    def to_json(self) -> dict[str, Any]:
        """Numbers: each target as a number in its unit, the text under ``display``."""
        out = asdict(self)
        del out["target"], out["tolerance_abs"], out["not_judged"]
        out |= {"target_abs": self.tolerance_abs, "within_target_reason": self.not_judged,
                "display": {"target": self.target}}
        return out

    def __str__(self) -> str:
        mark = {True: "ok", False: "MISSED", None: ""}[self.within_target]
        return (f"{self.key:34s} {self.identified:13.6g} {self.reference_kind:>7s} "
                f"{self.reference:13.6g} {self.relative_difference:+9.2%}  "
                f"{self.target:10s} {mark}")


def quantity(key: str) -> tuple[str, str, float]:
    """A comparison key in words: (name with unit, unit, display units per SI unit).

    ``"qd_gain_v_per_rad.h"`` → ``("4QD gain, h [V/rad]", "V/rad", 1.0)``.
    """
    parts = key.split(".")
    if parts[0] == "qd_gain_v_per_rad":
        return f"4QD gain, {parts[1]} [V/rad]", "V/rad", 1.0
    if parts[0] == "current_amp_gain_a_per_v":
        return f"Current-amplifier gain, {parts[1]} [mA/V]", "mA/V", 1e3
    if parts[0] == "newport_gain_v_per_v":
        out, inp = ("Vph", "Unh") if parts[1] == "h" else ("Vpv", "Unv")
        return f"Newport gain {inp} → {out} [V/V]", "V/V", 1.0
    if parts[0] == "delay_s":
        return f"Delay of the {parts[1].capitalize()} path [ms]", "ms", 1e3
    if parts[0] == "newport" and len(parts) == 3:
        axis, what = parts[1], parts[2]
        if what == "natural_freq_hz":
            return f"Newport natural frequency, {axis} [Hz]", "Hz", 1.0
        if what == "damping_ratio":
            return f"Newport damping ratio, {axis} [1]", "", 1.0
        if what == "internal_delay_s":
            return f"Newport internal delay, {axis} [ms]", "ms", 1e3
    if parts[0] == "sercalo" and len(parts) == 3:
        axis, what = parts[1], parts[2]
        if what == "resonance_hz":
            return f"Sercalo resonance, {axis} [Hz]", "Hz", 1.0
        if what == "damping_ratio":
            return f"Sercalo damping ratio, {axis} [1]", "", 1.0
        if what == "dc_gain_v_per_a":
            inp, out = {"h": ("Ich", "Vph"), "v": ("Icv", "Vpv")}[axis]
            return f"Sercalo static gain {inp} → {out} [V/A]", "V/A", 1.0
    return key.replace("_", " ").replace(".", ", "), "", 1.0


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
        samples = tol if tol_kind == "samples" else None
        if tol_kind == "samples":
            fs = _get(ref, "fs_hz") or _get(identified, "fs_hz") or 1e4
            target = f"±{tol:g} sample ({tol / fs:.3g} s)"
            tol = tol / fs
        why = (NOT_JUDGED_NOMINAL if reference is None else
               "the true value is 0: no relative difference" if err != err else "")
        rows.append(ComparisonRow(key=key, identified=ours, reference=theirs,
                                  reference_kind=kind, relative_difference=rel, target=target,
                                  within_target=None if why else bool(err <= tol),
                                  tolerance_abs=None if tol_kind == "rel" else tol,
                                  target_relative=tol if tol_kind == "rel" else None,
                                  target_samples=samples, not_judged=why))
    return rows


def comparison_json(identified: Mapping[str, Any], *, reference: Mapping[str, Any] | None,
                    bench: Bench, **extra: Any) -> dict[str, Any]:
    """``fsmbench identify --json``'s document: :data:`COMPARISON_FORMAT` first, the rows.

    Parameters
    ----------
    identified, reference, bench
        As :func:`comparison_rows`.
    **extra
        More top-level keys (``files``, ``skipped``, ``warnings``).

    Returns
    -------
    dict
        ``format``, ``format_version``, ``reference`` (``"true"`` or ``"nominal"``),
        ``rows`` (:meth:`ComparisonRow.to_json`) and ``extra``.
    """
    rows = comparison_rows(identified, reference=reference, bench=bench)
    name, version = COMPARISON_FORMAT
    return {"format": name, "format_version": version,
            "reference": "true" if reference is not None else "nominal",
            "rows": [r.to_json() for r in rows], **extra}


def readable_table(identified: Mapping[str, Any], *, reference: Mapping[str, Any] | None,
                   bench: Bench) -> list[str]:
    """What ``fsmbench identify`` prints: each quantity in words, engineering units, std.

    Against the twin's truth: the accuracy target and ``ok`` / ``MISSED``; against the
    nominal model (recorded data): the difference, which is how far the bench is from
    its bench file, not an error.
    """
    rows = comparison_rows(identified, reference=reference, bench=bench)
    stds = _stds(identified)
    ref_word = "true value" if reference is not None else "bench file"
    head = ["quantity", "identified", "± std", ref_word, "difference"]
    if reference is not None:
        head += ["target", ""]
    body = []
    for r in rows:
        name, unit, scale = quantity(r.key)
        std = stds.get(r.key)
        diff = (f"{(r.identified - r.reference) * scale:+.3g} {unit}".strip()
                if r.tolerance_abs is not None else f"{100 * r.relative_difference:+.2f} %")
        cells = [name, f"{r.identified * scale:.5g}",
                 "" if std is None else f"{std * scale:.2g}", f"{r.reference * scale:.5g}", diff]
        if reference is not None:
            _kind, tol = TARGETS[r.key]
            target = (f"±{r.tolerance_abs * scale:.3g} {unit}".strip() if r.tolerance_abs
                      is not None else f"±{100 * tol:.3g} %")
            cells += [target, {True: "ok", False: "MISSED", None: ""}[r.within_target]]
        body.append(cells)
    widths = [max(len(str(x)) for x in col) for col in zip(head, *body, strict=True)]
    lines = ["  ".join(str(c).ljust(w) if i == 0 else str(c).rjust(w)
                       for i, (c, w) in enumerate(zip(cells, widths, strict=True))).rstrip()
             for cells in (head, *body)]
    if reference is None:
        lines.append("Against the bench file: the difference is how far this bench is from "
                     "it, not an error of the identification.")
    else:
        met = sum(1 for r in rows if r.within_target)
        lines.append(f"{met} of {len(rows)} values within their accuracy targets.")
    return lines


def _stds(identified: Mapping[str, Any]) -> dict[str, float]:
    """The standard deviations ``identification.json`` reports, by comparison key."""
    out: dict[str, float] = {}
    diag = identified.get("diagnostics") or {}
    for axis, cal in (diag.get("qd") or {}).items():
        if isinstance(cal, Mapping) and cal.get("gain_std_v_per_rad") is not None:
            out[f"qd_gain_v_per_rad.{axis}"] = float(cal["gain_std_v_per_rad"])
    for axis, gi in (diag.get("current_amp") or {}).items():
        if isinstance(gi, Mapping) and gi.get("gain_std_a_per_v") is not None:
            out[f"current_amp_gain_a_per_v.{axis}"] = float(gi["gain_std_a_per_v"])
    for axis, mode in (diag.get("sercalo_modes") or {}).items():
        for key in ("resonance_hz", "damping_ratio"):
            std = mode.get(f"{key}_std") if isinstance(mode, Mapping) else None
            if std is not None:
                out[f"sercalo.{axis}.{key}"] = float(std)
    return out


def compare_with_truth(identified: Mapping[str, Any], *, reference: Mapping[str, Any] | None,
                       bench: Bench) -> list[str]:
    """Printable lines of :func:`comparison_rows` with a header."""
    head = (f"{'key':34s} {'identified':>13s} {'ref':>7s} {'value':>13s} {'diff':>9s}  "
            f"{'target':10s}")
    return [head, *(str(r) for r in comparison_rows(identified, reference=reference,
                                                     bench=bench))]
