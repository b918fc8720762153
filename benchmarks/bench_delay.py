"""Delay estimation: speed of the sampled path model against its peers, accuracy against the truth.

    python benchmarks/bench_delay.py [--repeats 20] [--seeds 5]

1. Speed of :func:`fsmbench.ident.delay.sampled.sampled_response` (the model the
   joint delay fit evaluates hundreds of times): the Sercalo-like path of two
   modes with a Butterworth sensor, 2000 lines, a delay of 2 samples plus a
   hold (whole samples, so that the peers can do it too), against
   ``scipy.signal.cont2discrete(method="zoh")`` + ``dfreqresp`` and
   python-control's ``sample_system(method="zoh")`` + ``frequency_response``
   (each times ``z^-2``). All three are checked equal first (to 1e-9). The
   peers cannot delay by a fraction of a sample (the joint fit must), and
   scipy goes through a transfer function (it warns of badly conditioned
   coefficients on this path).
2. Accuracy: the Sercalo path delay on the default twin (10 kHz) and on the
   real-bench twin at 5, 10 and 20 kHz, over ``--seeds`` noise seeds of the
   seed's 10 s records: the phase-only estimate (Bode's gain-phase relation)
   and the joint fit (its own poles, the hold, a fractional delay, the 4QD
   amplifier as the bench model knows it: unlimited), against the truth plus
   the real bench's 4QD amplifier lag (22.5 us, which an unknown sensor's
   delay includes). Median and largest absolute errors, in microseconds.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import statistics

import control as ct
import numpy as np
import scipy.signal as sig

from fsmbench.bench.blocks import replace_params
from fsmbench.bench.params import Bench, default_bench, real_bench
from fsmbench.ident.delay.sampled import SensorLowpass, mode_sum, sampled_response, series
from fsmbench.ident.frf.experiment import experiment_frf
from fsmbench.ident.pipeline import ESRF_TRIMS_S
from fsmbench.ident.sercalo import fit_sercalo
from fsmbench.twin import simulate_bench
from timing import timed_runs

FS = 10_000.0


def speed(repeats: int) -> None:
    path = mode_sum(natural_freq_hz=np.array([410.0, 1850.0]),
                    damping_ratio=np.array([0.0012, 0.01]),
                    numerator=np.array([[6.6e6, 0.0], [1.3e6, 0.0]]))
    sensor = SensorLowpass(bandwidth_hz=10_000.0, order=2)
    f = np.linspace(1.0, 0.45 * FS, 2000)
    delay = 2.5 / FS  # two samples after the hold's half
    a, b, c = series(path, sensor.state_space())
    z2 = np.exp(-2j * np.pi * f / FS * 2)

    def ours() -> np.ndarray:
        return sampled_response(path, f_hz=f, fs_hz=FS, delay_s=delay, sensor=sensor)

    def scipy_way() -> np.ndarray:
        ad, bd, cd, dd, _ = sig.cont2discrete((a, b[:, None], c[None, :], np.zeros((1, 1))),
                                              1 / FS, method="zoh")
        _, h = sig.dfreqresp((ad, bd, cd, dd, 1 / FS), w=2 * np.pi * f / FS)
        return h * z2

    def control_way() -> np.ndarray:
        sysd = ct.sample_system(ct.ss(a, b[:, None], c[None, :], 0), 1 / FS, method="zoh")
        return np.asarray(sysd.frequency_response(2 * np.pi * f).complex).ravel() * z2

    ref = ours()
    for name, fn in (("scipy", scipy_way), ("python-control", control_way)):
        err = float(np.max(np.abs(fn() - ref) / np.abs(ref)))
        assert err < 1e-9, f"{name} differs by {err:.2e}"
    t_ours, _ = timed_runs(ours, repeats)
    print(f"1. sampled response, 2000 lines, 6 states (median of {repeats})")
    print(f"   fsmbench sampled_response        {1e3 * t_ours:8.3f} ms")
    for name, fn in (("scipy cont2discrete+dfreqresp", scipy_way),
                     ("python-control sample_system", control_way)):
        t, _ = timed_runs(fn, repeats)
        print(f"   {name:32s} {1e3 * t:8.3f} ms   fsmbench is {t / t_ours:5.1f}x faster")


def _bench_at(make, fs_hz: float) -> Bench:
    b = make()
    return Bench(datasheet=b.datasheet,
                 nominal=replace_params(b.nominal, converter={"fs_hz": fs_hz}),
                 true=replace_params(b.true, converter={"fs_hz": fs_hz}))


def accuracy(seeds: int) -> None:
    print(f"\n2. Sercalo path delay error [us], {seeds} seeds, 10 s records, Welch 1 s")
    print(f"   {'bench':22s} {'phase only: median, max':>26s} {'joint fit: median, max':>26s}")
    cases = [("default twin 10 kHz", default_bench, 10_000.0)] + [
        (f"real bench {fs / 1000:g} kHz", real_bench, fs) for fs in (5_000.0, 10_000.0, 20_000.0)]
    for label, make, fs in cases:
        bench = _bench_at(make, fs)
        lag = SensorLowpass.from_params(bench.true).group_delay_s
        bode, joint = [], []
        for seed in range(seeds):
            run = simulate_bench(bench, seed=seed, duration_s=10.0,
                                 experiments=["data_uch", "data_ucv"])
            frf = experiment_frf(run.recordings, columns=[("data_uch", "Uch"), ("data_ucv", "Ucv")],
                                 trims_s=ESRF_TRIMS_S)
            target = run.truth["delay_s"]["sercalo"] + lag
            sid = fit_sercalo(frf, gi_a_per_v={"h": 0.01, "v": 0.01},
                              sensor=SensorLowpass.from_params(bench.nominal))
            bode += [abs(d.delay_s - target) * 1e6 for d in sid.delays]
            joint += [abs(j.effective_delay_s - target) * 1e6 for j in sid.joint_delays]
        print(f"   {label:22s} {statistics.median(bode):12.1f} {max(bode):10.1f}    "
              f"{statistics.median(joint):12.1f} {max(joint):10.1f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument("--seeds", type=int, default=5)
    args = parser.parse_args()
    speed(args.repeats)
    accuracy(args.seeds)


if __name__ == "__main__":
    main()
