"""Excitation design: lines on the grid and only there, rms, crest factors, periods, chirps."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import check_grad

from fsmbench.excite.design import (
    crest_factor,
    design_chirp,
    design_multisine,
    design_noise,
    grid_lines,
    lp_norm_and_gradient,
    multisine_period,
    schroeder_phases,
)

FS = 10_000.0


@pytest.fixture(scope="module")
def ms500():
    """500 lines, 1..500 Hz every 1 Hz, crest factor minimised, 3 periods + 1 transient."""
    return design_multisine(input="Uch", band_hz=(1.0, 500.0), resolution_hz=1.0,
                            amplitude_rms_v=0.015, fs_hz=FS, seed=4, periods=3,
                            transient_periods=1)


def _spectrum(period: np.ndarray) -> np.ndarray:
    return np.abs(np.fft.rfft(period))


def test_multisine_energy_on_the_grid_lines_only(ms500) -> None:
    one = ms500.one_period()
    mag = _spectrum(one)
    k = np.rint(ms500.lines_hz * ms500.period_samples / FS).astype(int)
    np.testing.assert_array_equal(k, np.arange(1, 501))
    on = np.zeros(mag.size, dtype=bool)
    on[k] = True
    # Each line has amplitude a: |X_k| = N a / 2; rounding of one irfft is ~1e-16 of that.
    np.testing.assert_allclose(mag[on], 0.5 * one.size * ms500.line_amplitude_v, rtol=1e-10)
    # Everything else is FFT round-off: below 1e-10 of a line (the brief's bound).
    assert mag[~on].max() < 1e-10 * mag[on].min()


def test_rms_equals_the_request_and_periods_repeat_exactly(ms500) -> None:
    one = ms500.one_period()
    # Parseval on whole bins: the rms of equal lines is a sqrt(L/2), exact to round-off.
    assert np.sqrt(np.mean(one**2)) == pytest.approx(0.015, rel=1e-12)
    x = ms500.samples_v.reshape(ms500.periods + ms500.transient_periods, -1)
    assert x.shape == (4, 10_000)
    np.testing.assert_array_equal(x, np.broadcast_to(x[0], x.shape))  # tiled: bit for bit


def test_crest_factor_minimised_below_random_and_two(ms500) -> None:
    # Measured: 1.38 against a median of 3.62 for random phases (21 draws, seed 4).
    assert ms500.crest_factor < 2.0
    assert ms500.crest_factor_random_phase is not None
    assert ms500.crest_factor < 0.5 * ms500.crest_factor_random_phase
    schroeder = crest_factor(multisine_period(harmonics=np.arange(1, 501),
                                              phases_rad=schroeder_phases(500),
                                              n_samples=10_000, amplitude_v=1.0))
    assert ms500.crest_factor < schroeder  # the iterations improve on their start (1.66)
    assert ms500.crest_factor == pytest.approx(crest_factor(ms500.one_period()), rel=1e-15)


def test_random_phases_are_the_seeds_and_plain() -> None:
    a = design_multisine(input="Ucv", band_hz=(10.0, 100.0), resolution_hz=2.0,
                         amplitude_rms_v=0.01, fs_hz=FS, seed=11, phase_method="random")
    b = design_multisine(input="Ucv", band_hz=(10.0, 100.0), resolution_hz=2.0,
                         amplitude_rms_v=0.01, fs_hz=FS, seed=11, phase_method="random")
    c = design_multisine(input="Ucv", band_hz=(10.0, 100.0), resolution_hz=2.0,
                         amplitude_rms_v=0.01, fs_hz=FS, seed=12, phase_method="random")
    np.testing.assert_array_equal(a.samples_v, b.samples_v)
    assert not np.array_equal(a.phases_rad, c.phases_rad)
    # Random phases of 46 lines: crest factor well above a minimised one (~1.4-1.8).
    assert a.crest_factor > 2.0


def test_lp_gradient_matches_finite_differences() -> None:
    k = np.arange(3, 60, 2)
    phases = np.random.default_rng(0).uniform(0, 2 * np.pi, k.size)
    f = lambda ph: lp_norm_and_gradient(ph, k, 1000, 8.0)[0]  # noqa: E731
    g = lambda ph: lp_norm_and_gradient(ph, k, 1000, 8.0)[1]  # noqa: E731
    # Central differences of step 1.5e-8 on a norm ~1.5: error ~1e-7 of the gradient's size.
    assert check_grad(f, g, phases) < 1e-5 * np.linalg.norm(g(phases))


@pytest.mark.parametrize(("grid", "rule"), [("odd", lambda k: k % 2 == 1),
                                            ("odd-odd", lambda k: k % 4 == 1)])
def test_odd_and_odd_odd_grids(grid: str, rule) -> None:
    k = grid_lines(band_hz=(1.0, 200.0), resolution_hz=1.0, fs_hz=FS, grid=grid)
    expected = np.array([i for i in range(1, 201) if rule(i)])
    np.testing.assert_array_equal(k, expected)
    d = design_multisine(input="Uch", band_hz=(1.0, 200.0), resolution_hz=1.0,
                         amplitude_rms_v=0.01, fs_hz=FS, grid=grid)
    mag = _spectrum(d.one_period())
    assert mag[expected].min() > 1e10 * np.delete(mag, expected).max()  # only those lines
    assert d.crest_factor < 2.0


def test_log_grid_is_nearest_lines_without_duplicates() -> None:
    k = grid_lines(band_hz=(1.0, 2000.0), resolution_hz=0.5, fs_hz=FS, log_grid=True,
                   lines_per_decade=20)
    assert np.all(np.diff(k) > 0)  # increasing, so no duplicates
    assert k[0] == 2 and k[-1] == 4000  # the band's ends (1 Hz and 2000 Hz at 0.5 Hz)
    ratio = np.diff(np.log10(k[k > 200]))  # where the grid is finer than the sequence
    # 20 per decade: steps of 0.05 decade, off by at most one grid line (< 0.005 decade here).
    np.testing.assert_allclose(ratio, 0.05, atol=0.005)
    odd = grid_lines(band_hz=(1.0, 2000.0), resolution_hz=0.5, fs_hz=FS, log_grid=True,
                     grid="odd", lines_per_decade=20)
    assert np.all(odd % 2 == 1)


def test_grid_refuses_what_cannot_be_played() -> None:
    with pytest.raises(ValueError, match="whole number of samples"):
        grid_lines(band_hz=(1.0, 10.0), resolution_hz=0.3, fs_hz=FS)
    with pytest.raises(ValueError, match="no full grid line"):
        grid_lines(band_hz=(6000.0, 7000.0), resolution_hz=1.0, fs_hz=FS)
    with pytest.raises(ValueError, match="0 < low < high"):
        grid_lines(band_hz=(100.0, 10.0), resolution_hz=1.0, fs_hz=FS)
    with pytest.raises(ValueError, match="unknown input 'Uxx'"):
        design_multisine(input="Uxx", band_hz=(1.0, 10.0), resolution_hz=1.0,
                         amplitude_rms_v=0.01, fs_hz=FS)


def test_noise_is_the_twins_band_noise_at_the_rms_asked() -> None:
    d = design_noise(input="Uch", band_hz=(1.0, 2000.0), amplitude_rms_v=0.015, fs_hz=FS,
                     duration_s=20.0, seed=3, periods=2)
    one = d.one_period()
    assert np.sqrt(np.mean(one**2)) == pytest.approx(0.015, rel=1e-12)  # scaled exactly
    np.testing.assert_array_equal(d.samples_v[:one.size], d.samples_v[one.size:])
    f = np.fft.rfftfreq(one.size, 1 / FS)
    p = np.abs(np.fft.rfft(one)) ** 2
    # 4th-order Butterworth: 48 dB down an octave above the band, so < 1 % of the power.
    assert p[f > 4000].sum() < 0.01 * p.sum()
    assert p[(f > 1) & (f < 2000)].sum() > 0.9 * p.sum()


@pytest.mark.parametrize("method", ["linear", "log"])
def test_chirp_instantaneous_frequency_covers_the_band(method: str) -> None:
    d = design_chirp(input="Unh", band_hz=(5.0, 1000.0), amplitude_rms_v=0.1, fs_hz=FS,
                     duration_s=4.0, method=method)
    x = d.one_period()
    assert np.sqrt(np.mean(x**2)) == pytest.approx(0.1, rel=1e-12)
    # Instantaneous frequency from the zero crossings (linear interpolation between samples):
    # half a cycle between two crossings.
    i = np.flatnonzero(np.signbit(x[:-1]) != np.signbit(x[1:]))
    tz = (i + x[i] / (x[i] - x[i + 1])) / FS
    f_inst = 0.5 / np.diff(tz)
    t = 0.5 * (tz[1:] + tz[:-1])
    expected = 5.0 + 995.0 * t / 4.0 if method == "linear" else 5.0 * 200.0 ** (t / 4.0)
    # Interpolating a sine's crossing linearly errs by O((2 pi f / fs)^2): < 0.5 % at
    # 1 kHz and 10 kHz; the sweep's own change within half a cycle is smaller still.
    np.testing.assert_allclose(f_inst, expected, rtol=0.01)
    # The whole band: the first half cycle (at 5 Hz, 0.1 s) already sweeps ~2 % of a linear
    # band; the last ends at 1 kHz.
    assert f_inst.min() < 5.0 + 0.02 * 995.0 and f_inst.max() > 1000.0 * 0.99
