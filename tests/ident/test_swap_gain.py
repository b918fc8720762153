"""A swap's cross path judged against a direct gain the records measure, not only the
bench file's (a bench far below the bench file's gains still shows its swaps)."""

from __future__ import annotations

import pytest

from fsmbench.ident.consistency import SWAP_GAIN_FACTOR, AxisRatio, with_records_gains


def _run(exp: str, inp: str, direct: float, cross: float, model: float) -> AxisRatio:
    out = ("Vph", "Vpv") if inp.endswith("h") else ("Vpv", "Vph")
    return AxisRatio(exp, inp, out[0], out[1], direct, cross, 50.0, 0.9, 0.9, model)


@pytest.mark.parametrize("scale", [1.0, 1 / 80])
def test_a_swapped_run_is_seen_whatever_the_bench_s_gains(scale: float) -> None:
    """``data_uch`` drives the v axis (its cross output carries Ucv's direct gain); the bench
    file's model expects gains 1/scale times the bench's."""
    g = 0.02 * scale
    axes = {"data_uch": _run("data_uch", "Uch", 0.03 * g, g, model=0.02),
            "data_ucv": _run("data_ucv", "Ucv", g, 0.03 * g, model=0.02)}
    judged = with_records_gains(axes)
    assert not judged["data_uch"].passed  # the other axis moved
    assert judged["data_ucv"].passed
    # Without the records' gain, the bench far below the model hid the swap.
    assert axes["data_uch"].passed is (scale < 1 / SWAP_GAIN_FACTOR)


def test_a_dead_direct_channel_beside_a_coupling_is_not_a_swap() -> None:
    """Vph dead in data_uch: its cross output is a 3 % coupling of the partner's direct gain."""
    g = 0.02 / 80
    axes = {"data_uch": _run("data_uch", "Uch", 0.0, 0.03 * g, model=0.02),
            "data_ucv": _run("data_ucv", "Ucv", g, 0.0, model=0.02)}
    assert with_records_gains(axes)["data_uch"].passed
