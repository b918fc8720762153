"""``signal_clipped`` on signals of few converter codes (a weak bench's 4QD outputs)."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from fsmbench.io.channels import CLIPPED_MIN_STEPS, clipped_signals

LSB = 20.0 / 2**16


def _run(vph: np.ndarray) -> xr.Dataset:
    return xr.Dataset({"Vph": ("t", vph)})


def _noise(codes: int, n: int = 66_000, seed: int = 0) -> np.ndarray:
    """Gaussian noise on the converter's grid spanning about ``codes`` steps (±4.3 sigma)."""
    rng = np.random.default_rng(seed)
    return np.round(rng.standard_normal(n) * codes / 8.6) * LSB


@pytest.mark.parametrize("codes", [4, 11, 30, 55])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_noise_of_few_codes_is_not_called_clipped(codes: int, seed: int) -> None:
    """A tail thins outwards however few its codes: 3 to 55 codes of noise pass."""
    (check,) = clipped_signals(_run(_noise(codes, seed=seed)), "data_unh", "data_unh.mat",
                               LSB)
    assert check.passed, check.sentence()


@pytest.mark.parametrize("codes", [11, 30, 55])
def test_few_codes_clipped_at_30_percent_are_named(codes: int) -> None:
    """The corpus's weak bench: Vph of 55 codes clipped at 30 % of its peak holds ~10 % of
    its samples on each extreme code and nothing of the tail its own Gaussian puts beyond
    them; 11 and 30 codes alike."""
    x = _noise(codes)
    peak = float(np.max(np.abs(x)))
    level = np.round(0.3 * peak / LSB) * LSB  # the clip lands on a code, as a converter's
    (check,) = clipped_signals(_run(np.clip(x, -level, level)), "data_unh", "data_unh.mat",
                               LSB)
    assert not check.passed and "clipped" in check.advice
    assert (2 * level / LSB) < CLIPPED_MIN_STEPS  # judged by the missing tail as well


def test_sub_step_noise_on_three_codes_is_not_called_clipped() -> None:
    """A channel whose noise is a third of a step sits on three codes, its outer two on
    ~5 % of the samples each: its own Gaussian puts no sample beyond them."""
    rng = np.random.default_rng(3)
    x = np.round(rng.standard_normal(50_000) * 0.3) * LSB
    assert np.unique(x).size == 3
    (check,) = clipped_signals(_run(x), "data_unh", "data_unh.mat", LSB)
    assert check.passed, check.sentence()
