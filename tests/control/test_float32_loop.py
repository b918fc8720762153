"""The twin's closed loop with the exported controllers rounded to float32."""

from __future__ import annotations

import numpy as np

from fsmbench.bench.esrf import esrf_decentralised_controller
from fsmbench.bench.params import Bench
from fsmbench.control.export import discretise
from fsmbench.control.float32_loop import float32_closed_loop
from fsmbench.sim.controller import closed_loop_spectral_radius, sercalo_feedback
from fsmbench.sim.plant import ADC_CHANNELS, bench_discrete


def test_float64_radius_is_the_engines_loop_with_the_mat_realisation(bench: Bench) -> None:
    k = esrf_decentralised_controller()
    loop = float32_closed_loop(bench, k, name="seed")
    ts = bench.true.converter.ts_s
    kd = discretise(k, ts_s=ts)
    gd = bench.nominal.quad_diode.gain_v_per_rad
    fb = sercalo_feedback(a=kd.A, b=kd.B, c=kd.C, d=kd.D, gd_v_per_rad=(gd.h, gd.v), name="k")
    other = closed_loop_spectral_radius(bench_discrete(bench), fb, n_adc=len(ADC_CHANNELS))
    # Two realisations (DF2T sections, the scaled Tustin cascade) of one controller: the same
    # poles up to float64 eigenvalue rounding of a ~60-state loop.
    assert abs(loop.radius_float64 - other) < 1e-9
    assert loop.radius_float64 < 1.0


def test_float32_keeps_the_seed_loop_stable_and_its_poles_close(bench: Bench) -> None:
    loop = float32_closed_loop(bench, esrf_decentralised_controller(), name="seed")
    assert loop.sos_stable and loop.state_space_stable
    # float32 rounds each coefficient by <= 6e-8 relative; a pole moves by that times its
    # sensitivity, far below the 1e-4 that would change a mode's frequency by 0.2 Hz.
    assert 0.0 < loop.pole_shift_sos < 1e-4 and 0.0 < loop.pole_shift_state_space < 1e-4
    js = loop.to_json()
    assert set(js["response_error_sos"]) == {"h", "v"}
    assert all(0.0 < v < 1e-2 for v in js["response_error_sos"].values())
    assert np.isfinite(js["radius_float32_sos"])
