"""Open- against closed-loop identification of the Sercalo at equal measurement time (issue 24).

For the packaged twin and ``real_bench.toml`` (the twin with the real bench's
features: second modes, mode-shape angles), several random seeds:

* **closed loop**: :func:`fsmbench.tune.measure.measure_closed_loop` with the ESRF
  study's controller running, the beam error the measurement adds bounded at
  30 µrad rms (two stages of 2 × 33 s: 132 s of records; the Sercalo fitted on
  both stages' lines merged, from 10 Hz);
* **open loop**: the ESRF study's open-loop records ``data_uch``, ``data_ucv`` (white
  noise on the coil command, loop open) of the same total length (66 s each),
  identified by ``fsmbench identify``'s pipeline (:func:`fsmbench.ident.pipeline.identify`).

Printed per run: the relative error of each Sercalo parameter against the twin's
truth, the delay error in samples, the beam's motion during the measurement
(closed loop: what the excitation added, by synchronous averaging; open loop:
the 4QD's rms while excited, the loop being open), and the CPU time of each
(measurement simulated + identification). The peer for the timing is the open-loop
identification: the ratio is closed / open.

    python benchmarks/bench_closed_loop_ident.py [--seeds 1 2 3]
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import numpy as np

from fsmbench.bench.params import Bench, default_bench, real_bench
from fsmbench.control.loaded import running_controller
from fsmbench.ident.pipeline import identify
from fsmbench.tune.measure import MeasurementOptions, measure_closed_loop
from fsmbench.twin.simulate import simulate_bench

KEYS = (("resonance_hz", "f0"), ("damping_ratio", "zeta"), ("dc_gain_v_per_a", "gain"))
TOL = {"resonance_hz": 0.005, "damping_ratio": 0.25, "dc_gain_v_per_a": 0.03}


def _errors(found: dict[str, Any], truth: dict[str, Any]) -> dict[str, float]:
    out = {}
    for axis in ("h", "v"):
        for key, short in KEYS:
            f = (found.get("sercalo") or {}).get(axis, {}).get(key)
            out[f"{short}.{axis}"] = (float("nan") if f is None
                                      else f / truth["sercalo"][axis][key] - 1.0)
    d = (found.get("delay_s") or {}).get("sercalo")
    out["delay_samples"] = (float("nan") if d is None
                            else (d - truth["delay_s"]["sercalo"]) * 1e4)
    return out


def _closed(bench: Bench, seed: int) -> tuple[dict[str, float], float, float, float]:
    t0 = time.process_time()
    ctrl = running_controller(None, bench=bench)
    m = measure_closed_loop(true_bench=bench, model=bench, controller=ctrl,
                            options=MeasurementOptions(max_error_rad=30e-6), seed=seed)
    cpu = time.process_time() - t0
    truth = m.stages[0][1].truth
    beam = max(m.tracking_added_rad().values())
    return _errors(m.identification.to_json(), truth), m.duration_s, beam, cpu


def _open(bench: Bench, seed: int, duration_s: float) -> tuple[dict[str, float], float, float]:
    t0 = time.process_time()
    run = simulate_bench(bench, seed=seed, duration_s=duration_s / 2,
                         experiments=["data_uch", "data_ucv"])
    result = identify(run.recordings, bench=bench)
    cpu = time.process_time() - t0
    gd = bench.nominal.quad_diode.gain_v_per_rad
    beam = 0.0
    for name, sig, axis in (("data_uch", "Vph", "h"), ("data_ucv", "Vpv", "v")):
        ds = run.recordings[name]
        t = ds["t"].values
        e = ds[sig].values[t > t[0] + 1.0] / abs(gd[axis])  # after the ESRF study's trim
        beam = max(beam, float(np.std(e)))
    return _errors(result.to_json(), run.truth), beam, cpu


def _row(label: str, err: dict[str, float]) -> str:
    cells = []
    for key, short in KEYS:
        for axis in ("h", "v"):
            v = err[f"{short}.{axis}"]
            mark = "" if abs(v) <= TOL[key] else "!"
            cells.append(f"{100 * v:+7.2f}{mark:1s}")
    return f"{label:28s}" + " ".join(cells) + f" {err['delay_samples']:+6.2f}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    args = ap.parse_args()
    print("relative errors [%] (! beyond the open-loop tolerances: resonance 0.5 %, damping "
          "25 %, gains 3 %); delay [samples]")
    print(f"{'run':28s}" + " ".join(f"{s + '.' + a:>8s}" for _k, s in KEYS for a in "hv")
          + "  delay")
    ratios = []
    for name, bench in (("twin", default_bench()), ("real_bench", real_bench())):
        for seed in args.seeds:
            err_c, dur, beam_c, cpu_c = _closed(bench, seed)
            err_o, beam_o, cpu_o = _open(bench, seed, dur)
            print(_row(f"{name} seed {seed} closed", err_c)
                  + f"  beam {1e6 * beam_c:7.1f} µrad  {dur:5.0f} s  cpu {cpu_c:5.1f} s")
            print(_row(f"{name} seed {seed} open", err_o)
                  + f"  beam {1e6 * beam_o:7.1f} µrad  {dur:5.0f} s  cpu {cpu_o:5.1f} s")
            ratios.append(cpu_c / cpu_o)
    print(f"CPU time closed / open loop (peer: fsmbench identify on open-loop records of the "
          f"same length): median {np.median(ratios):.2f}x")


if __name__ == "__main__":
    main()
