"""The lines' correlation taken from the residual (Newey-West), against closed forms."""

from __future__ import annotations

import numpy as np
import pytest

from fsmbench.ident.delay.joint import hac_factors

N = 8000  # lines
LAGS = 10  # ceil(4 x 2.5), the nominal correlation of a zero-padded Hann window


def _factor(x: np.ndarray) -> float:
    """The factor of a mean over the lines (influence 1 on every real part, 0 on imaginary)."""
    influence = np.concatenate([np.ones((1, N)), np.zeros((1, N))], axis=1)
    residual = np.concatenate([x, np.zeros(N)])
    return float(hac_factors(influence, residual, 2.5)[0])


@pytest.mark.parametrize("theta", [0.0, -0.3, 0.5])
def test_moving_average_long_run_variance(theta: float, rng: np.random.Generator) -> None:
    e = rng.standard_normal(N + 1)
    x = e[1:] + theta * e[:-1]
    # MA(1): ρ₁ = θ / (1 + θ²), no longer lags; the long-run variance over the variance is
    # 1 + 2 ρ₁ = (1 + θ)² / (1 + θ²), and Bartlett's weights expect 1 + 2 (1 − 1/11) ρ₁.
    # Its relative std over 8000 lines is sqrt(4 L / 3 N) = 4 %: 15 % is 3.7 of it.
    rho = theta / (1 + theta**2)
    expected = min(max(1 + 2 * (1 - 1 / (LAGS + 1)) * rho, 1 / 2.5), 2.5)
    assert _factor(x) == pytest.approx(expected, rel=0.15)


@pytest.mark.parametrize("theta", [0.0, -0.5, -0.8, 0.5])
def test_current_amplifier_factor_is_t_scaled_newey_west(theta: float,
                                                         rng: np.random.Generator) -> None:
    """The current amplifier's factor (50 Bartlett lags at a nominal 2.5): an MA(1)'s long-run
    variance over its variance, (1 + θ)² / (1 + θ²), clipped to [1/2.5, 2.5], times the
    (t₀.₉₇₅(ν)/1.96)² of ν = 3N/(2L) degrees of freedom."""
    from scipy import stats

    from fsmbench.ident.current_amp import HAC_LAGS_PER_LINE, hac_factor

    e = rng.standard_normal(N + 1)
    x = e[1:] + theta * e[:-1]
    lags = int(np.ceil(HAC_LAGS_PER_LINE * 2.5))
    rho = theta / (1 + theta**2)
    t_scale = (stats.t.ppf(0.975, 3 * N / (2 * lags)) / stats.norm.ppf(0.975)) ** 2
    expected = min(max(1 + 2 * (1 - 1 / (lags + 1)) * rho, 1 / 2.5), 2.5) * t_scale
    got = hac_factor((x, np.zeros(N)), (np.ones(N), np.zeros(N)), 2.5)
    # Bartlett's estimate over 50 lags and 8000 lines has a relative std sqrt(4 L / 3 N),
    # 9 %: 3.5 of it.
    assert got == pytest.approx(expected, rel=3.5 * np.sqrt(4 * lags / (3 * N)))
