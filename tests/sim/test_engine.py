"""The compiled loop against python-control and scipy on linear cases, and its converters."""

from __future__ import annotations

import control as ct
import numpy as np
import pytest
import scipy.signal as sig

from fsmbench.bench.esrf import esrf_decentralised_controller
from fsmbench.bench.params import Bench
from fsmbench.sim.engine import Quantiser, run_loop, run_loop_python
from fsmbench.sim.plant import ADC_CHANNELS, DAC_CHANNELS, twin_discrete

IDEAL = Quantiser(range_v=20.0, bits=0)
N_ADC = len(ADC_CHANNELS)


@pytest.fixture(scope="module")
def plant(bench: Bench):
    return twin_discrete(bench.true)


def _excitation(n: int, seed: int = 1) -> np.ndarray:
    rng = np.random.default_rng(seed)
    u = np.zeros((n, 4))
    u[:, 0] = 0.02 * rng.standard_normal(n)
    u[:, 1] = 0.02 * rng.standard_normal(n)
    u[:, 2] = 0.1 * rng.standard_normal(n)
    return u


def test_open_loop_is_the_discrete_plant(plant) -> None:
    n = 3000
    u = _excitation(n)
    res = run_loop(plant, u_ext=u, adc_noise=np.zeros((n, N_ADC)), adc=IDEAL, dac=IDEAL,
                   n_adc=N_ADC)
    _, y, _ = sig.dlsim((plant.a, plant.b, plant.c, np.zeros((plant.c.shape[0], 4)), plant.ts_s), u)
    # Same arithmetic in a different order: rounding only.
    np.testing.assert_allclose(res.adc, y[:, :N_ADC], atol=1e-12 * np.max(np.abs(y[:, :N_ADC])))
    np.testing.assert_allclose(res.internal, y[:, N_ADC:],
                               atol=1e-12 * np.max(np.abs(y[:, N_ADC:])))
    np.testing.assert_array_equal(res.dac, u)


def test_closed_loop_matches_python_control(bench: Bench, plant) -> None:
    """Linear closed loop (ideal converters) against python-control's feedback of the blocks."""
    from fsmbench.sim.controller import feedback_controller

    ts = plant.ts_s
    ctrl = feedback_controller(esrf_decentralised_controller(),
                               gd_v_per_rad=bench.nominal.quad_diode.gain_v_per_rad, ts_s=ts)
    n = 4000
    u = _excitation(n)
    res = run_loop(plant, u_ext=u, adc_noise=np.zeros((n, N_ADC)), adc=IDEAL, dac=IDEAL,
                   controller=ctrl, n_adc=N_ADC)
    # python-control: plant P (4 in, all out); K' reads Vph, Vpv and adds to Uch, Ucv.
    p_sys = ct.ss(plant.a, plant.b, plant.c, np.zeros((plant.c.shape[0], 4)), ts)
    k_sys = ct.ss(ctrl.a, ctrl.b, ctrl.c, ctrl.d, ts)
    sel_y = np.zeros((2, plant.c.shape[0]))
    sel_y[0, ADC_CHANNELS.index("Vph")] = 1
    sel_y[1, ADC_CHANNELS.index("Vpv")] = 1
    sel_u = np.zeros((4, 2))
    sel_u[DAC_CHANNELS.index("Uch"), 0] = 1
    sel_u[DAC_CHANNELS.index("Ucv"), 1] = 1
    loop_k = ct.ss([], [], [], sel_u) * k_sys * ct.ss([], [], [], sel_y)
    cl = ct.feedback(p_sys, loop_k, sign=+1)
    resp = ct.forced_response(cl, T=np.arange(n) * ts, U=u.T)
    y = np.asarray(resp.outputs).T
    scale = np.max(np.abs(y[:, :N_ADC]), axis=0) + 1e-300  # Vnv stays zero here
    assert np.max(np.abs(res.adc - y[:, :N_ADC]) / scale) < 1e-9  # rounding in two algebras


def test_compiled_and_interpreted_loops_agree(bench: Bench, plant) -> None:
    from fsmbench.sim.controller import feedback_controller

    ctrl = feedback_controller(esrf_decentralised_controller(),
                               gd_v_per_rad=bench.nominal.quad_diode.gain_v_per_rad,
                               ts_s=plant.ts_s)
    n = 300
    q = Quantiser(range_v=20.0, bits=16)
    rng = np.random.default_rng(2)
    noise = 1e-3 * rng.standard_normal((n, N_ADC))
    a = run_loop(plant, u_ext=_excitation(n), adc_noise=noise, adc=q, dac=q, controller=ctrl,
                 n_adc=N_ADC)
    b = run_loop_python(plant, u_ext=_excitation(n), adc_noise=noise, adc=q, dac=q,
                        controller=ctrl, n_adc=N_ADC)
    np.testing.assert_allclose(a.adc, b.adc, rtol=0, atol=1e-12)
    np.testing.assert_allclose(a.dac, b.dac, rtol=0, atol=1e-12)


def test_converters_quantise_and_clip(plant) -> None:
    q = Quantiser(range_v=20.0, bits=16)
    n = 200
    u = np.zeros((n, 4))
    u[:, 0] = np.linspace(-12, 12, n)  # beyond both rails
    u[:, 2] = 1e-4 * np.arange(n)  # below and around one step
    res = run_loop(plant, u_ext=u, adc_noise=np.zeros((n, N_ADC)), adc=q, dac=q, n_adc=N_ADC)
    lsb = 20.0 / 2**16
    codes = res.dac / lsb
    np.testing.assert_allclose(codes, np.round(codes), atol=1e-9)
    assert res.dac[:, 0].min() == pytest.approx(-10.0)
    assert res.dac[:, 0].max() == pytest.approx(10.0 - lsb)  # two's complement top code
    np.testing.assert_allclose(res.dac[:, 2], q.apply(u[:, 2]))
    adc_codes = res.adc / lsb
    np.testing.assert_allclose(adc_codes, np.round(adc_codes), atol=1e-9)


def test_quantiser_apply_rounds_to_nearest() -> None:
    q = Quantiser(range_v=20.0, bits=16)
    lsb = q.lsb_v
    x = np.array([0.49 * lsb, 0.51 * lsb, -0.51 * lsb, 3.2 * lsb, 11.0, -11.0])
    np.testing.assert_allclose(q.apply(x), [0.0, lsb, -lsb, 3 * lsb, 10 - lsb, -10.0])
    assert Quantiser(range_v=20.0, bits=0).apply(x)[0] == x[0]


def test_shape_errors(plant) -> None:
    with pytest.raises(ValueError, match="adc_noise must have shape"):
        run_loop(plant, u_ext=np.zeros((5, 4)), adc_noise=np.zeros((4, N_ADC)), adc=IDEAL,
                 dac=IDEAL, n_adc=N_ADC)
    with pytest.raises(ValueError, match="columns"):
        run_loop(plant, u_ext=np.zeros((5, 3)), adc_noise=np.zeros((5, N_ADC)), adc=IDEAL,
                 dac=IDEAL, n_adc=N_ADC)
