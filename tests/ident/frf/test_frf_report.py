"""The report's FRF figure: confidence bounds when (and only when) there is a variance."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.stats as st

from fsmbench.ident.frf.estimate import FrfEstimate, circular_bound_factor
from fsmbench.ident.frf.response import spectral_matrix
from fsmbench.report.figures.ident import estimator_description, frf_matrix_figure
from fsmbench.signal.welch import hanning

F_HZ = np.arange(1, 101) * 2.0


def _estimate() -> FrfEstimate:
    h = np.ones((F_HZ.size, 1, 1), dtype=complex) * (2.0 + 0.0j)
    var = np.full(h.shape, 0.01)  # std 0.1
    return FrfEstimate(frequency_hz=F_HZ, frf=h, frf_variance=var,
                       output_noise_psd=np.ones(h.shape), input_psd=np.ones((F_HZ.size, 1)),
                       snr=np.full(h.shape, 400.0), input_names=("Uch",), output_names=("Vph",),
                       fs_hz=1e4, resolution_hz=0.5, estimator="periodic", dof=(4.0,))


def test_bounds_drawn_from_the_variance() -> None:
    fr = _estimate().to_frequency_response()
    fig = frf_matrix_figure(fr, delay_s=0.0, model=None, key="k", title="t", caption="c",
                            seed_ref="")
    mag, phase = fig.panels
    bounds = [t for t in mag.traces if "confidence" in t.name]
    assert len(bounds) == 2
    # The variance is estimated on 4 complex dof: |e|^2/var_hat is F(2, 8), and the 95 %
    # radius sqrt(F^-1(0.95; 2, 8)) std (Hotelling), wider than the known-variance 1.73.
    r = float(np.sqrt(st.f.ppf(0.95, 2, 8))) * 0.1
    assert r > circular_bound_factor(0.95) * 0.1
    np.testing.assert_allclose(bounds[0].y, 2.0 - r)
    np.testing.assert_allclose(bounds[1].y, 2.0 + r)
    ph = [t for t in phase.traces if "confidence" in t.name]
    np.testing.assert_allclose(ph[1].y, np.degrees(np.arcsin(r / 2.0)))
    assert "averaged over the periods" in estimator_description(fr)


def test_welch_has_no_band(rng: np.random.Generator) -> None:
    u = rng.standard_normal(4000)
    fr = spectral_matrix(u, 0.5 * u + 0.01 * rng.standard_normal(4000), input_names=["Uch"],
                         output_names=["Vph"], window=hanning(400), fs_hz=1e3)
    fig = frf_matrix_figure(fr, delay_s=0.0, model=None, key="k", title="t", caption="c",
                            seed_ref="")
    assert not any("confidence" in t.name for p in fig.panels for t in p.traces)
    assert estimator_description(fr) == "Welch H1, 0.4 s Hann window"


def test_lpm_description() -> None:
    est = _estimate()
    fr = FrfEstimate(**{**est.__dict__, "estimator": "lpm"}).to_frequency_response()
    assert estimator_description(fr).startswith("local polynomial method on the whole 2 s")
    with pytest.raises(ValueError, match="confidence"):
        circular_bound_factor(1.0)
