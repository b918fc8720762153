"""Identified values against a reference."""

from __future__ import annotations

import pytest

from fsmbench.bench.params import Bench
from fsmbench.jsonutil import stamped
from fsmbench.twin.compare import compare_with_truth, comparison_rows
from fsmbench.twin.truth import model_values


def test_against_truth_marks_targets(bench: Bench) -> None:
    truth = model_values(bench.true)
    ident = model_values(bench.true)
    ident["sercalo"]["h"]["resonance_hz"] *= 1.004  # inside ±0.5 %
    ident["sercalo"]["v"]["resonance_hz"] *= 1.006  # outside
    ident["delay_s"]["sercalo"] += 1.5e-4  # 1.5 samples: outside one sample
    rows = {r.key: r for r in comparison_rows(ident, reference=truth, bench=bench)}
    assert rows["sercalo.h.resonance_hz"].within_target is True
    assert rows["sercalo.v.resonance_hz"].within_target is False
    assert rows["delay_s.sercalo"].within_target is False
    assert rows["qd_gain_v_per_rad.h"].relative_difference == 0.0


def test_against_nominal_has_no_verdict(bench: Bench) -> None:
    rows = comparison_rows(model_values(bench.true), reference=None, bench=bench)
    assert all(r.reference_kind == "nominal" and r.within_target is None for r in rows)
    gi = next(r for r in rows if r.key == "current_amp_gain_a_per_v.h")
    # The seed's 2.2 observation, in the packaged bench: true Gi is 64 % of 1/(R+Rc).
    assert gi.relative_difference == pytest.approx(0.01275 / (1 / 50.3) - 1, rel=1e-3)


def test_missing_keys_are_left_out(bench: Bench) -> None:
    lines = compare_with_truth({"qd_gain_v_per_rad": {"h": -31.0}}, reference=None, bench=bench)
    assert len(lines) == 2 and lines[1].startswith("qd_gain_v_per_rad.h")


def test_format_stamps_are_not_compared(bench: Bench) -> None:
    """The files' ``format`` keys differ (identification vs twin_truth): no row, same rows."""
    truth, ident = model_values(bench.true), model_values(bench.nominal)
    plain = comparison_rows(ident, reference=truth, bench=bench)
    rows = comparison_rows(stamped(ident, format="fsmbench.identification", version=2),
                           reference=stamped(truth, format="fsmbench.twin_truth", version=2),
                           bench=bench)
    assert rows == plain and len(rows) == 20  # 9 (h, v) pairs + 2 delays
    assert not any(r.key.startswith("format") for r in rows)
