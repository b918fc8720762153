"""The compiled controller recursion of the DAC-noise estimate against scipy's dlsim."""

from __future__ import annotations

import control as ct
import numpy as np
import pytest
from scipy import signal

from fsmbench.budget.huddle import run_controller


@pytest.mark.parametrize("states", [1, 4, 9])
def test_run_controller_equals_dlsim(states: int) -> None:
    rng = np.random.default_rng(states)
    a = rng.standard_normal((states, states))
    a *= 0.95 / max(abs(np.linalg.eigvals(a)))  # stable: the output stays O(1)
    b, c, d = (rng.standard_normal(s) for s in ((states, 2), (2, states), (2, 2)))
    k = ct.ss(a, b, c, d, 1e-4)
    r = rng.standard_normal((2, 5000))
    ours = run_controller(k, r)
    _, ref, _ = signal.dlsim((a, b, c, d, 1e-4), r.T)
    # The same recursion summed in another order: rounding, ~1e-15 of the output per step
    # over a few hundred steps of memory (spectral radius 0.95).
    np.testing.assert_allclose(ours, ref.T, rtol=0, atol=1e-11 * np.abs(ref).max())
