"""The Sercalo fit's quality is its misfit net of the lines' own noise, Welch included."""

from __future__ import annotations

import numpy as np
import scipy.signal

from fsmbench.ident.frf.response import spectral_matrix
from fsmbench.ident.sercalo import relative_fit_error
from fsmbench.signal.welch import hanning

FS = 10_000.0


def test_the_true_response_fits_a_noisy_welch_estimate_within_its_noise() -> None:
    """A short, noisy record's Welch lines scatter by several % about the true response;
    the true response's misfit net of that scatter is near 0, where the raw rms is the
    scatter itself (what refused the weak bench's plant at 5.9 %)."""
    rng = np.random.default_rng(4)
    b, a = scipy.signal.butter(2, 800.0, fs=FS)
    u = rng.standard_normal(120_000)
    y = scipy.signal.lfilter(b, a, u)
    y = y + rng.standard_normal(y.size) * 0.5 * np.std(y)
    frf = spectral_matrix(u, y[:, None], input_names=["Uch"], output_names=["Vph"],
                          window=hanning(10_000), fs_hz=FS)
    _, h = scipy.signal.freqz(b, a, worN=frf.frequency_hz, fs=FS)
    model = h[:, None, None]
    keep = (frf.frequency_hz >= 10) & (frf.frequency_hz <= 1000)
    raw = float(np.sqrt(np.mean((np.abs(model[keep, 0, 0])
                                 / np.abs(frf.frf.values[keep, 0, 0]) - 1) ** 2)))
    net = relative_fit_error(frf, model, min_coherence=0.5)["Vph/Uch"]
    assert raw > 0.02  # the lines' own scatter (23 averages, γ² ~0.8)
    # Net of it, what is left is the root of a difference of two estimates that each
    # scatter by ~sqrt(2/N) over N ~ 200 independent lines: ~(2/N)^(1/4) = 0.3 of the raw
    # rms (0.26 here); without the subtraction it is the raw rms itself.
    assert net < 0.5 * raw, (net, raw)
