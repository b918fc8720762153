"""The compiled increments' residuals of the Va jump scan against numpy and scipy's
running median (the form the rule is written in), bit for bit."""

from __future__ import annotations

import itertools

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.ndimage import median_filter

from fsmbench.io.va_jumps import MEDIAN_HALF_WIDTH, _increment_residuals, _median9


def _residuals_by_scipy(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    d = np.diff(x)
    steps = np.flatnonzero(d != 0.0)
    dn = d[steps]
    return steps, dn - median_filter(dn, size=2 * MEDIAN_HALF_WIDTH + 1, mode="mirror")


def test_the_network_selects_the_median_of_every_binary_input() -> None:
    # The 0-1 principle: a compare-exchange network that selects the median of every
    # 0/1 input selects it of every input (ties included).
    for bits in itertools.product((0.0, 1.0), repeat=9):
        assert _median9(*bits) == (1.0 if sum(bits) >= 5 else 0.0), bits


# Values on a coarse grid: ties and exactly zero increments (a Va held between updates).
_values = st.one_of(st.floats(-1e-6, 1e-6, allow_nan=False, allow_subnormal=False),
                    st.integers(-3, 3).map(lambda k: k * 0.5))


@settings(max_examples=300, deadline=None)
@given(arrays(np.float64, st.integers(2 * MEDIAN_HALF_WIDTH + 2, 80), elements=_values))
def test_the_residuals_are_scipy_s_bit_for_bit(x: np.ndarray) -> None:
    steps, r = _increment_residuals(x)
    want_steps, want_r = _residuals_by_scipy(x)
    np.testing.assert_array_equal(steps, want_steps, strict=True)
    if want_steps.size >= 2 * MEDIAN_HALF_WIDTH + 1:  # shorter: the scan stops before r
        np.testing.assert_array_equal(r, want_r, strict=True)


def test_a_long_record_s_residuals_are_scipy_s() -> None:
    rng = np.random.default_rng(7)
    va = np.cumsum(rng.normal(0.0, 1e-10, 200_000))
    va[50_000:50_100] = va[50_000]  # a held stretch: its zero increments are left out
    steps, r = _increment_residuals(va)
    want_steps, want_r = _residuals_by_scipy(va)
    np.testing.assert_array_equal(steps, want_steps, strict=True)
    np.testing.assert_array_equal(r, want_r, strict=True)
