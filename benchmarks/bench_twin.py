"""Twin simulation speed against its peers, in one run.

    python benchmarks/bench_twin.py [--repeats 5] [--skip-full]

1. Linear open loop, the twin's discrete plant (24 states, 4 inputs, 12
   outputs), 200 000 samples: fsmbench's compiled loop vs python-control's
   ``forced_response`` and scipy's ``dlsim`` on the same system.
2. Closed loop with 16-bit quantisation and the seed's controller: the
   compiled loop vs the identical loop interpreted by Python (per-sample).
3. The whole seed experiment set at default lengths (737.5 s of records,
   7.4 million samples), one core: ``simulate_bench`` without file output.

Prints median times and ratios. Single-threaded by construction (the loop is
sequential); BLAS threads are pinned to one for fairness.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import argparse
from collections.abc import Callable

import control as ct
import numpy as np
import scipy.signal as sig

from fsmbench.bench.esrf import esrf_decentralised_controller
from fsmbench.bench.params import default_bench
from fsmbench.sim.controller import feedback_controller
from fsmbench.sim.engine import Quantiser, run_loop, run_loop_python
from fsmbench.sim.plant import ADC_CHANNELS, twin_discrete
from timing import timed_runs


def median_time(fn: Callable[[], object], repeats: int) -> float:
    """Median time [s]; this script warms up explicitly where it matters."""
    return timed_runs(fn, repeats, warm_up=False)[0]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--skip-full", action="store_true", help="skip the full experiment set")
    args = parser.parse_args()

    bench = default_bench()
    plant = twin_discrete(bench.true)
    n_adc = len(ADC_CHANNELS)
    ideal = Quantiser(range_v=20.0, bits=0)
    conv = Quantiser(range_v=20.0, bits=16)
    rng = np.random.default_rng(0)

    # 1. linear open loop
    n = 200_000
    u = np.zeros((n, 4))
    u[:, 0] = 0.02 * rng.standard_normal(n)
    u[:, 2] = 0.1 * rng.standard_normal(n)
    zeros = np.zeros((n, n_adc))
    for spec in (False, True):  # compile (or load) both loops before timing
        run_loop(plant, u_ext=u[:10], adc_noise=zeros[:10], adc=ideal, dac=ideal, n_adc=n_adc,
                 specialise=spec)
    t_gen = median_time(lambda: run_loop(plant, u_ext=u, adc_noise=zeros, adc=ideal, dac=ideal,
                                         n_adc=n_adc), args.repeats)
    t_ours = median_time(lambda: run_loop(plant, u_ext=u, adc_noise=zeros, adc=ideal, dac=ideal,
                                          n_adc=n_adc, specialise=True), args.repeats)
    sys_d = ct.ss(plant.a, plant.b, plant.c, np.zeros((plant.c.shape[0], 4)), plant.ts_s)
    tgrid = np.arange(n) * plant.ts_s
    t_fr = median_time(lambda: ct.forced_response(sys_d, T=tgrid, U=u.T), max(1, args.repeats // 2))
    t_dlsim = median_time(lambda: sig.dlsim((plant.a, plant.b, plant.c,
                                             np.zeros((plant.c.shape[0], 4)), plant.ts_s), u),
                          max(1, args.repeats // 2))
    ours = run_loop(plant, u_ext=u, adc_noise=zeros, adc=ideal, dac=ideal, n_adc=n_adc,
                    specialise=True)
    ref = np.asarray(ct.forced_response(sys_d, T=tgrid, U=u.T).outputs).T
    err = np.max(np.abs(ours.adc - ref[:, :n_adc])) / np.max(np.abs(ref[:, :n_adc]))
    print(f"1. linear open loop, {n} samples, {plant.a.shape[0]} states")
    print(f"   fsmbench run_loop, this plant {t_ours * 1e3:7.1f} ms"
          f"  ({t_ours / n * 1e9:6.0f} ns/sample, unrolled: sim.codegen)")
    print(f"   fsmbench run_loop, generic    {t_gen * 1e3:7.1f} ms"
          f"  ({t_gen / n * 1e9:6.0f} ns/sample)")
    print(f"   control.forced_response     {t_fr * 1e3:9.1f} ms"
          f"  -> fsmbench {t_fr / t_ours:6.0f}x faster (generic {t_fr / t_gen:.0f}x)")
    print(f"   scipy.signal.dlsim          {t_dlsim * 1e3:9.1f} ms"
          f"  -> fsmbench {t_dlsim / t_ours:6.0f}x faster (generic {t_dlsim / t_gen:.0f}x)")
    print(f"   max relative difference vs forced_response: {err:.1e}")

    # 2. closed loop with quantisation
    ctrl = feedback_controller(esrf_decentralised_controller(),
                               gd_v_per_rad=bench.nominal.quad_diode.gain_v_per_rad,
                               ts_s=plant.ts_s)
    noise = 1e-3 * rng.standard_normal((n, n_adc))
    t_cl = median_time(lambda: run_loop(plant, u_ext=u, adc_noise=noise, adc=conv, dac=conv,
                                        controller=ctrl, n_adc=n_adc, specialise=True),
                       args.repeats)
    n_py = 5_000
    t_py = median_time(lambda: run_loop_python(plant, u_ext=u[:n_py], adc_noise=noise[:n_py],
                                               adc=conv, dac=conv, controller=ctrl,
                                               n_adc=n_adc), max(1, args.repeats // 2))
    per_py = t_py / n_py
    per_ours = t_cl / n
    print(f"2. closed loop, 16-bit converters, seed controller ({ctrl.a.shape[0]} states)")
    print(f"   fsmbench run_loop           {per_ours * 1e9:9.0f} ns/sample")
    print(f"   same loop in Python         {per_py * 1e9:9.0f} ns/sample  -> fsmbench "
          f"{per_py / per_ours:6.0f}x faster")

    # 3. the full experiment set
    if not args.skip_full:
        from fsmbench.twin.experiments import esrf_experiments
        from fsmbench.twin.simulate import simulate_bench

        total_s = sum(s.duration_s for s in esrf_experiments())
        t_full = median_time(lambda: simulate_bench(bench, seed=0), max(1, args.repeats // 2))
        print(f"3. all 13 experiments, {total_s:g} s of records "
              f"({total_s * bench.true.converter.fs_hz / 1e6:.1f} M samples)")
        print(f"   simulate_bench (no file output) {t_full:7.2f} s  (target < 10 s on one core)")


if __name__ == "__main__":
    main()
