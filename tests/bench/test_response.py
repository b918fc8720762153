"""Responses at many points evaluated in blocks: each point's value is that of the
whole-array evaluation, bit for bit, on either side of a block's edge."""

from __future__ import annotations

import control as ct
import numpy as np
import pytest

from fsmbench.bench import response
from fsmbench.bench.blocks import PlantModel


def _whole(monkeypatch: pytest.MonkeyPatch, fn, *args):  # type: ignore[no-untyped-def]
    with monkeypatch.context() as m:
        m.setattr(response, "BLOCK_POINTS", 10**9)
        return fn(*args)


@pytest.mark.parametrize("n_points", [1, response.BLOCK_POINTS, response.BLOCK_POINTS + 1,
                                      3 * response.BLOCK_POINTS + 17])
def test_blocks_change_no_bit(nominal_plant: PlantModel, monkeypatch: pytest.MonkeyPatch,
                              n_points: int) -> None:
    sub = nominal_plant.subsystem(outputs=["Vph", "Vpv"], inputs=["Uch", "Ucv"])
    f = np.geomspace(0.01, 5000.0, n_points)
    s = 2j * np.pi * f
    abcd = [np.asarray(x, dtype=float) for x in (sub.A, sub.B, sub.C, sub.D)]
    evaluator = response.ResponseEvaluator(sub, check_points=s[:: max(1, n_points // 50)])
    for fn, args in ((response.ss_frequency_response, (sub, f)),
                     (response.solve_response, (*abcd, s)),
                     (evaluator, (s,))):
        blocked = fn(*args)
        assert blocked.shape == (n_points, 2, 2)
        np.testing.assert_array_equal(blocked, _whole(monkeypatch, fn, *args), strict=True)


def test_the_blocked_modal_sum_matches_the_solve() -> None:
    # A lightly damped pair and a real pole: the modal sum (kept only where it matches the
    # solve to 1e-10 relative at its check points) against the solve everywhere.
    sys = ct.ss(ct.tf([1.0, 3.0], [1.0, 2.0, 4e4]) * ct.tf([10.0], [1.0, 10.0]))
    f = np.linspace(0.0, 3000.0, 2 * response.BLOCK_POINTS + 5)
    abcd = [np.asarray(x, dtype=float) for x in (sys.A, sys.B, sys.C, sys.D)]
    modal = response.ss_frequency_response(sys, f)
    direct = response.solve_response(*abcd, 2j * np.pi * f)
    # cond(V) of a 0.5 %-damped pair and the sum's cancellation: 1e-10 relative is the
    # agreement the modal sum is kept for.
    np.testing.assert_allclose(modal, direct, rtol=1e-10, atol=0.0)
