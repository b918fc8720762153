"""The Attocube distance signal: its error sources and the Table 3 configurations."""

from __future__ import annotations

import numpy as np
import pytest

from fsmbench.bench.geometry import closed_form_path_error, small_angle_law
from fsmbench.bench.params import Bench
from fsmbench.sim.attocube import VaComponents, air_sensitivity, attocube_distance
from fsmbench.sim.noise import source_rng

N = 200_000  # 20 s at 10 kHz: long enough for the rms of 1 s-scale drifts


def _va(bench: Bench, *, theta_c: np.ndarray | None = None, comp: bool, alu: bool) -> VaComponents:
    zeros = np.zeros((N, 2))
    return attocube_distance(bench.true, theta_c_rad=zeros if theta_c is None else theta_c,
                             theta_n_rad=zeros, compensation_unit=comp, shielding=alu,
                             fs_hz=1e4, rng_for=lambda s: source_rng(5, "test", s))


def test_geometric_error_is_half_the_traced_round_trip(bench: Bench) -> None:
    geo = bench.true.geometry
    theta = np.zeros((N, 2))
    theta[:, 0] = np.linspace(-1e-4, 1e-4, N)
    theta[:, 1] = 3e-5
    va = _va(bench, theta_c=theta, comp=True, alu=True)
    # The Sercalo's beam factor is ±4 (two reflections), so its angle error is
    # the mirror angle itself; the Attocube reports half the round trip.
    expected = 0.5 * (closed_form_path_error(theta[:, 0], h_m=geo.h_m, l_m=geo.l_m)
                      + closed_form_path_error(theta[:, 1], h_m=geo.h_m, l_m=geo.l_m))
    np.testing.assert_allclose(va.geometric_m, expected, rtol=1e-12, atol=0)
    law = small_angle_law(h_m=geo.h_m, l_m=geo.l_m)
    # Quadratic law k/2·θ²: its truncation (k4/k)θ² < 1e-7 at 1e-4 rad.
    np.testing.assert_allclose(va.geometric_m, law.measured_error_m(theta[:, 0])
                               + law.measured_error_m(theta[:, 1]), rtol=1e-7)


def test_compensation_unit_and_shielding_reduce_the_air_error(bench: Bench) -> None:
    bare = _va(bench, comp=False, alu=False).std_m()["air"]
    comp = _va(bench, comp=True, alu=False).std_m()["air"]
    both = _va(bench, comp=True, alu=True).std_m()["air"]
    assert bare > comp > both > 0


def test_components_add_up_to_the_resolution(bench: Bench) -> None:
    va = _va(bench, comp=False, alu=False)
    raw = va.geometric_m + va.perpendicular_m + va.air_m + va.frame_m + va.noise_m
    res = bench.true.attocube.resolution_m
    assert np.max(np.abs(va.total_m - raw)) <= 0.5 * res + 1e-18  # rounding to the resolution
    assert va.noise_m.std() == pytest.approx(bench.true.attocube.noise_rms_m, rel=0.01)


def test_air_sensitivities_at_1530_nm(bench: Bench) -> None:
    s = air_sensitivity(bench.true)
    # Ciddor at 20 °C, 101325 Pa, 50 %RH, 1530 nm (tests/bench/test_air.py checks the
    # model against ref_index); the seed rounds them to 1 ppm/K, 0.27 ppm/hPa,
    # 0.01 ppm/%RH (errata E16). Tolerances: the last digit quoted.
    assert s.dn_dt_per_k * 1e6 == pytest.approx(-0.9445, abs=5e-4)
    assert s.dn_dp_per_pa * 1e8 == pytest.approx(0.265, abs=5e-3)
    assert s.dn_drh_per_pct * 1e6 == pytest.approx(-0.0087, abs=5e-5)
