"""The ESRF study's controller on the twin's plant: minimal models, delays, margins, FRD.

Run:  python examples/loop_margins.py [OUT_DIR]      (or FSMBENCH_EXAMPLE_OUT=OUT_DIR)

No records needed (a few seconds): the twin's own plant from physics, its delay as Padé
approximants of growing order and exactly (sampled), the margins of each, python-control's
own margins on the exact frequency response (an FRD), and a Nyquist plot of both axes to
``OUT_DIR/loop_margins.png``.
"""

from __future__ import annotations

import os
import sys
import tempfile
import warnings
from pathlib import Path

import control as ct
import matplotlib
import numpy as np

import fsmbench
from fsmbench.control import esrf_decentralised_controller

matplotlib.use("Agg")  # files only, no display
import matplotlib.pyplot as plt

TS_S = 1e-4  # the bench's sample time [s]


def main(out: Path) -> None:
    plant = fsmbench.physical_plant(parameters="true")    # the twin's truth
    k = esrf_decentralised_controller()                   # ESRF study 9.2: Rh, Rv -> Uch, Ucv

    print("Uch -> Rh: states of the minimal model")
    for order in (2, 6):
        g = plant.to_control(order=order, outputs=["Rh"], inputs=["Uch"])
        print(f"  Padé order {order}: {g.nstates}")
    gd = plant.to_control(delays="exact", dt=TS_S, outputs=["Rh"], inputs=["Uch"])
    print(f"  sampled at {TS_S * 1e6:.0f} µs, delay exact: {gd.nstates}")

    print("h axis margins (GM dB, PM deg, delay margin ms)")
    for order in (1, 2, 6):
        m = fsmbench.margins(plant, k, channel="Rh", order=order)
        print(f"  Padé {order}: {m.gain_margin_db:.3f} {m.phase_margin_deg:.3f} "
              f"{m.delay_margin_s * 1e3:.3f}")
    kd = ct.sample_system(k, TS_S, method="tustin")
    m = fsmbench.margins(plant, kd, channel="Rh")
    print(f"  sampled: {m.gain_margin_db:.3f} {m.phase_margin_deg:.3f} "
          f"{m.delay_margin_s * 1e3:.3f}")

    # python-control's margins on the exact response: plant FRD times the controller.
    f = np.geomspace(1.0, 4000.0, 4000)
    g_frd = plant.to_frd(f, outputs=["Rh"], inputs=["Uch"])
    kh = ct.ss(k.A, k.B[:, [0]], k.C[[0], :], k.D[[0]][:, [0]])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        gm, pm, _, _, wgc, _ = ct.stability_margins(g_frd * kh)
    print(f"  control.stability_margins on the FRD: {20 * np.log10(gm):.3f} {pm:.3f} "
          f"(crossover {wgc / (2 * np.pi):.2f} Hz)")

    fig, ax = plt.subplots(figsize=(6, 6))
    lg = fsmbench.loop_gain(plant, kd)
    fz = np.geomspace(5.0, 0.999 * 0.5 / TS_S, 3000)
    for i, axis in enumerate(("Rh", "Rv")):
        r = ct.frequency_response(lg[i, i], 2 * np.pi * fz).complex
        ax.plot(r.real, r.imag, label=f"L {axis} (sampled)")
    circle = np.exp(1j * np.linspace(0, 2 * np.pi, 200))
    ax.plot(circle.real, circle.imag, "k:", lw=0.8, label="|L| = 1")
    ax.plot([-1], [0], "r+", ms=12)
    ax.set(xlim=(-3, 1), ylim=(-3, 1), xlabel="Re L", ylabel="Im L", aspect="equal",
           title="ESRF study's controller on the twin: Nyquist, 5 Hz to Nyquist")
    ax.legend(loc="lower right")
    path = out / "loop_margins.png"
    fig.savefig(path, dpi=80)
    print(f"wrote {path}")


if __name__ == "__main__":
    target = sys.argv[1] if len(sys.argv) > 1 else os.environ.get("FSMBENCH_EXAMPLE_OUT")
    folder = Path(target) if target else Path(tempfile.mkdtemp(prefix="fsmbench-example-"))
    folder.mkdir(parents=True, exist_ok=True)
    main(folder)
