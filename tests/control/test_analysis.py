"""Plant analysis: RGA, coprime factors, scaling and the 6.1 objective."""

from __future__ import annotations

import control as ct
import numpy as np
import pytest

from fsmbench.bench.blocks import PlantModel
from fsmbench.bench.params import Bench
from fsmbench.control.analysis import (
    analyse_plant,
    control_objective,
    normalized_coprime_factors,
    rga,
    rga_number,
)
from fsmbench.control.freq import evaluate_ss


def test_rga_of_a_diagonal_plant_is_identity() -> None:
    rng = np.random.default_rng(0)
    d = rng.normal(size=(7, 2)) + 1j * rng.normal(size=(7, 2))
    g = np.zeros((7, 2, 2), dtype=complex)
    g[:, 0, 0], g[:, 1, 1] = d[:, 0], d[:, 1]
    np.testing.assert_allclose(rga(g), np.broadcast_to(np.eye(2), g.shape), atol=1e-15)
    assert np.all(rga_number(g) < 1e-15)  # exact zeros off the diagonal: rounding only


def test_rga_of_a_2x2_matches_the_closed_form() -> None:
    g = np.array([[2.0, 0.3], [-0.5, 1.0]])
    lam11 = 1.0 / (1.0 - g[0, 1] * g[1, 0] / (g[0, 0] * g[1, 1]))
    expected = np.array([[lam11, 1 - lam11], [1 - lam11, lam11]])
    np.testing.assert_allclose(rga(g), expected, rtol=1e-14)  # rounding only


def _factor_checks(sys: ct.StateSpace) -> None:
    cf = normalized_coprime_factors(sys)
    f = np.logspace(-1, 5, 80)
    s = 2j * np.pi * f
    n, m, g = evaluate_ss(cf.n, s), evaluate_ss(cf.m, s), evaluate_ss(sys, s)
    # M^-1 N = G: one solve per frequency; relative to the plant's peak gain.
    np.testing.assert_allclose(np.linalg.solve(m, n), g, atol=1e-9 * np.max(np.abs(g)))
    eye = n @ np.conj(np.swapaxes(n, 1, 2)) + m @ np.conj(np.swapaxes(m, 1, 2))
    # Normalisation N N~ + M M~ = I holds to the Riccati solution's accuracy.
    np.testing.assert_allclose(eye, np.broadcast_to(np.eye(eye.shape[1]), eye.shape), atol=1e-8)
    assert np.all(np.linalg.eigvals(np.asarray(cf.m.A)).real < 0)  # stable factors
    # Two routes to b_max (Gramians of [N M], Riccati X Z): same number to 1e-8.
    assert cf.b_max == pytest.approx(cf.b_max_riccati, rel=1e-8)
    assert 0 < cf.b_max < 1


def test_coprime_factors_of_the_bench(true_plant: PlantModel) -> None:
    gcgi = ct.series(true_plant.blocks["Gi"], true_plant.blocks["Gc"])
    _factor_checks(ct.ss(gcgi.A, gcgi.B, gcgi.C, gcgi.D))


def test_coprime_factors_with_feedthrough() -> None:
    sys = ct.ss([[-1.0, 2.0], [0.0, -3.0]], [[1.0], [1.0]], [[1.0, 0.5]], [[0.2]])
    _factor_checks(sys)


def test_coprime_margin_of_a_first_order_lag() -> None:
    """G = 1/(s+a): b_max = 1/sqrt(1 + rho(XZ)), X = Z = sqrt(a^2+1) - a (Glover–McFarlane)."""
    a = 2.0
    cf = normalized_coprime_factors(ct.ss([[-a]], [[1.0]], [[1.0]], [[0.0]]))
    x = np.sqrt(a**2 + 1) - a
    assert cf.b_max == pytest.approx(1 / np.sqrt(1 + x * x), rel=1e-10)  # closed form


def test_objective_of_6_1(bench: Bench) -> None:
    obj = control_objective(bench.nominal)
    assert obj.frequency_hz == 1.0
    assert obj.sensitivity_bound == pytest.approx(2e-4, rel=1e-12)  # 10 µrad / 5e-2 rad
    assert obj.loop_gain_sufficient == pytest.approx(5001.0)
    assert obj.loop_gain_necessary == pytest.approx(4999.0)
    # Table 5's 1 V on the Newport moves the beam by 2 gn = 5.24 mrad, 10x below 6.1's stroke.
    assert obj.table5_stroke_rad == pytest.approx(5.24e-3, rel=1e-12)
    assert obj.to_json()["sensitivity_bound_at_1hz"] == pytest.approx(2e-4)


def test_plant_analysis(bench: Bench, nominal_plant: PlantModel, true_plant: PlantModel) -> None:
    nom = analyse_plant(nominal_plant, params=bench.nominal)
    # Nominal: no coupling, no 4QD rotation: a diagonal plant.
    assert np.max(nom.rga_number) < 1e-12 and nom.rotation_rad == 0.0
    tru = analyse_plant(true_plant, params=bench.nominal)
    np.testing.assert_allclose(tru.decoupler @ tru.g0, np.eye(2), atol=1e-12)  # inverse
    assert abs(tru.rotation_rad) < 0.05  # 15 mrad 4QD rotation + 2 % coil coupling
    assert np.max(np.abs(tru.coupling)) < 0.05
    assert tru.singular_values.shape == (tru.f_hz.size, 2)
    assert np.all(tru.singular_values[:, 0] >= tru.singular_values[:, 1])
    assert tru.inputs_suffice  # 10 V of Uc outweighs 1 V of Un below the Newport's roll-off
    js = tru.to_json()
    assert js["coprime"]["b_max"] == pytest.approx(tru.coprime.b_max)
