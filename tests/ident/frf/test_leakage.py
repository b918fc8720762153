"""The Welch leakage bias (ident.frf.leakage) against a closed form and its exact sum."""

from __future__ import annotations

import numpy as np
import pytest

from fsmbench.ident.frf.leakage import welch_leakage_bias
from fsmbench.signal.welch import hanning

FS_HZ = 10_000.0
WINDOW = hanning(10_000)  # 1 s: 1 Hz bins, the ESRF study's


def _two_modes(f_hz: np.ndarray) -> np.ndarray:
    """Two lightly damped modes (the twin's Sercalo: 0.5 and 1 Hz half-power bandwidths)
    behind a 150 µs delay, as a (F, 2, 1) response."""
    s = 2j * np.pi * f_hz
    out = []
    for fn, zeta in ((251.2, 1e-3), (411.5, 1.2e-3)):
        wn = 2 * np.pi * fn
        out.append(wn**2 / (s**2 + 2 * zeta * wn * s + wn**2))
    h = np.stack(out, axis=1)[:, :, None]
    return h * np.exp(-s * 150e-6)[:, None, None]


def test_a_quadratic_response_is_biased_by_the_kernels_second_moment() -> None:
    # Parseval: ∫ν²|W|² / ∫|W|² = ∫|w'|² / (4π² ∫w²) = 1/(3 L²) for a continuous Hann,
    # i.e. 1/3 bin²; the sampled window's moment is 2e-4 smaller and the kernel cut at
    # ±8 bins drops 1.3e-4 more (measured with wider cuts): 1e-3.
    c = 2.0e-3  # per Hz²
    f = np.array([50.0, 1000.0, 3000.5])
    bias = welch_leakage_bias(lambda x: (1.0 + 0.1 * x + c * x**2).astype(complex), f,
                              fs_hz=FS_HZ, window=WINDOW)
    assert bias == pytest.approx(np.full(3, c / 3.0), rel=1e-3)


def test_the_fast_sum_equals_the_exact_one_near_and_far_from_the_modes() -> None:
    f = np.arange(1.0, 2000.0, 0.25)
    fast = welch_leakage_bias(_two_modes, f, fs_hz=FS_HZ, window=WINDOW)
    exact = welch_leakage_bias(_two_modes, f, fs_hz=FS_HZ, window=WINDOW, exact=True)
    h = np.abs(_two_modes(f))
    # the tolerances of the fast path's switch (1e-3 of the bias, 1e-9 of |H|), with a
    # factor 10 for the degree-6 sum's own remainder
    assert np.all(np.abs(fast - exact) <= 1e-2 * np.abs(exact) + 1e-8 * h)
    # the bias near the modes is what the module is for: the peaks are smeared
    peak = np.argmin(np.abs(f - 251.2))
    assert abs(exact[peak, 0, 0]) > 0.3 * h[peak, 0, 0]
