"""The ESRF study step by step in Python: records, identification, budget, design, margins.

Run:  python examples/step_by_step.py [OUT_DIR]      (or FSMBENCH_EXAMPLE_OUT=OUT_DIR)

The digital twin records the thirteen experiments (5 s each, so the example runs in
under a minute) into ``OUT_DIR/records``; from there on it is what you would do with
your own folder: read it, identify the plant, compute the budget, design, and check
the ESRF study's controller and fsmbench's on the identified plant, continuous and as
the real-time target samples them. Figures go to ``OUT_DIR/step_by_step.png``.
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

import control as ct
import matplotlib
import numpy as np

import fsmbench

matplotlib.use("Agg")  # files only, no display
import matplotlib.pyplot as plt

TS_S = 1e-4  # the bench's sample time [s]


def main(out: Path) -> None:
    bench = fsmbench.load_bench()                      # the packaged Sercalo bench
    records = out / "records"
    fsmbench.simulate(bench, seed=1, duration_s=5.0, out_dir=records)
    loaded = fsmbench.load_recordings(records, bench=bench)   # as for a folder of yours
    print(f"read {len(loaded.recordings)} records from {records}")

    ident = fsmbench.identify(loaded, bench=bench)
    plant = ident.plant
    print(f"identified plant: {plant.source}; warnings: {list(ident.warnings) or 'none'}")
    g = plant.to_control(outputs=["Rh", "Rv"], inputs=["Uch", "Ucv"])
    print(f"Uch, Ucv -> Rh, Rv: {g.nstates} states (minimal, Padé delays), "
          f"DAC delay {plant.input_delay_s['Uch'] * 1e6:.1f} µs")

    budget = fsmbench.budget(loaded, bench=bench, plant=ident)
    print(f"distance error budget: {budget.total_rms_m * 1e9:.2f} nm rms "
          f"(limiting: {budget.limiting})")

    design = fsmbench.design(ident, bench=bench)
    controllers = {"ESRF study (9.2)": design.result.controllers["seed_controller"],
                   "fsmbench": design.result.controllers["fsmbench_controller"]}

    print(f"{'controller':18s} {'axis':4s} {'kind':10s} {'GM dB':>7s} {'GR dB':>7s} "
          f"{'PM °':>6s} {'DM ms':>6s} {'fc Hz':>6s}")
    for name, k in controllers.items():
        for kind, kk in (("continuous", k),
                         ("sampled", ct.sample_system(k, TS_S, method="tustin"))):
            for axis in ("Rh", "Rv"):
                m = fsmbench.margins(plant, kk, channel=axis)
                print(f"{name:18s} {axis:4s} {kind:10s} {m.gain_margin_db:7.2f} "
                      f"{m.gain_reduction_margin_db:7.2f} {m.phase_margin_deg:6.1f} "
                      f"{m.delay_margin_s * 1e3:6.2f} {m.crossover_hz:6.1f}")

    # Bode of the sampled loops (h axis) and their sensitivity, up to Nyquist.
    f = np.geomspace(0.1, 0.999 * 0.5 / TS_S, 2000)
    fig, (ax_mag, ax_ph, ax_s) = plt.subplots(3, 1, figsize=(8, 10), sharex=True)
    for name, k in controllers.items():
        kd = ct.sample_system(k, TS_S, method="tustin")
        lg = fsmbench.loop_gain(plant, kd)
        r = ct.frequency_response(lg[0, 0], 2 * np.pi * f)
        m = fsmbench.margins(lg, channel="Rh")
        line, = ax_mag.semilogx(f, 20 * np.log10(r.magnitude), label=name)
        phase = np.degrees(np.unwrap(np.angle(r.complex)))
        # Unwrapped phase is known up to 360°: put it in (-360°, 0°] at the crossover, so
        # its distance to -180° there reads as the phase margin.
        phase -= 360.0 * np.ceil(np.interp(m.crossover_hz, f, phase) / 360.0)
        ax_ph.semilogx(f, phase, color=line.get_color())
        if np.isfinite(m.gain_margin_db):
            ax_mag.plot(m.phase_crossover_hz, -m.gain_margin_db, "v", color=line.get_color())
        s = ct.frequency_response(fsmbench.sensitivity(lg)[0, 0], 2 * np.pi * f)
        ax_s.semilogx(f, 20 * np.log10(s.magnitude), color=line.get_color(), label=name)
    ax_mag.axhline(0.0, color="k", lw=0.5)
    ax_mag.set_ylabel("|L| [dB]")
    ax_mag.legend()
    ax_ph.axhline(-180.0, color="k", lw=0.5)
    ax_ph.set_ylabel("arg L [deg]")
    ax_s.set_ylabel("|S| [dB]")
    ax_s.set_xlabel("frequency [Hz]")
    fig.suptitle("Loops on the identified plant, h axis, sampled at 10 kHz")
    path = out / "step_by_step.png"
    fig.savefig(path, dpi=80)
    print(f"wrote {path}")


if __name__ == "__main__":
    target = sys.argv[1] if len(sys.argv) > 1 else os.environ.get("FSMBENCH_EXAMPLE_OUT")
    folder = Path(target) if target else Path(tempfile.mkdtemp(prefix="fsmbench-example-"))
    folder.mkdir(parents=True, exist_ok=True)
    main(folder)
