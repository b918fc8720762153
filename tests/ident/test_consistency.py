"""The screening's Welch H1 (every segment in one FFT) against scipy's welch and csd, the
estimator it stands for."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal

from fsmbench.ident.consistency import _EXCITED_OF_TOP, SIGN_BAND_HZ, _welch_h1


def _by_scipy(u: np.ndarray, ys: list[np.ndarray], fs: float
              ) -> tuple[np.ndarray, list[np.ndarray], list[np.ndarray], np.ndarray]:
    n = min(round(fs), u.size // 2)
    kw = {"fs": fs, "window": "hann", "nperseg": n, "noverlap": n // 2, "detrend": "constant"}
    f, puu = scipy.signal.welch(u, **kw)
    band = (f >= SIGN_BAND_HZ[0]) & (f <= SIGN_BAND_HZ[1])
    typical = float(np.median(puu[band])) if band.any() else 0.0
    top = float(np.max(puu[band])) if band.any() else 0.0
    excited = puu > _EXCITED_OF_TOP * max(typical, top * _EXCITED_OF_TOP)
    puu = np.where(puu > 0, puu, np.inf)
    h, coh = [], []
    for y in ys:
        _, puy = scipy.signal.csd(u, y, **kw)
        _, pyy = scipy.signal.welch(y, **kw)
        h.append(puy / puu)
        coh.append(np.abs(puy) ** 2 / (puu * np.where(pyy > 0, pyy, np.inf)))
    return f, h, coh, excited


@pytest.mark.parametrize(("n_samples", "fs_hz"), [(310_000, 1e4), (310_001, 1e4), (12_345, 1e4),
                                                  (40_000, 5e3), (999, 1e3)])
def test_the_h1_and_coherence_are_scipy_s(n_samples: int, fs_hz: float) -> None:
    rng = np.random.default_rng(n_samples)
    u = rng.normal(size=n_samples) + 3.0  # offsets: each segment's mean is removed
    ys = [np.convolve(u, [0.5, 0.3, -0.1], "same") + 0.1 * rng.normal(size=n_samples) + 1.0,
          rng.normal(size=n_samples)]  # one coherent output, one not
    f, h, coh, excited = _welch_h1(u, ys, fs_hz)
    want_f, want_h, want_coh, want_excited = _by_scipy(u, ys, fs_hz)
    np.testing.assert_array_equal(f, want_f)
    np.testing.assert_array_equal(excited, want_excited)
    # The same sums in another order: a few ulp of each segment's spectrum, amplified
    # where a ratio's denominator is small (noise bins), 1e-13 at most here.
    for got, want in zip([*h, *coh], [*want_h, *want_coh], strict=True):
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=0)
