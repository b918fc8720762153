"""Report sections of the foundation: the bench, its parameters, its recordings."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import xarray as xr

from fsmbench.bench.blocks import physical_plant
from fsmbench.bench.params import Bench, param_rows
from fsmbench.report.html import Section, Table, figure_from_matplotlib
from fsmbench.report.plots import experiment_figure, huddle_figure

__all__ = ["bench_section", "parameters_section", "recordings_section"]

# Seed figure numbers of the time plots, and the seed's trim of each record (t0).
SEED_TIME_FIGURES = {
    "data_cal_pd_h": ("Fig. 8", 1.0), "data_cal_pd_v": ("Fig. 9", 1.0),
    "data_uch": ("Fig. 15", 1.0), "data_ucv": ("Fig. 16", 1.0),
    "data_unh": ("Fig. 23", 3.0), "data_unv": ("Fig. 24", 1.5),
    **{f"data_huddle_test_{i}": ("Fig. 29-30", 1.0) for i in range(1, 6)},
    "data_rep_h": ("Fig. 44", 0.0), "data_rep_v": ("Fig. 44", 0.0),
}


def bench_section(bench: Bench) -> Section:
    """What the bench is, with its key numbers computed from the parameters."""
    nom, true = bench.nominal, bench.true
    plant = physical_plant(nom)
    g_uc = plant.dc_gain(output="Rh", input="Uch")
    g_un = plant.dc_gain(output="Rh", input="Unh")
    conv = nom.converter
    paragraphs = (
        "The bench stabilises a laser beam with a Sercalo voice-coil mirror (the actuator) "
        "while a Newport FSM-300 tilts the beam to emulate sample motion. A four-quadrant "
        "photodiode (4QD) measures the beam angle, and an Attocube interferometer measures "
        "the beam path, which the stabilisation must not disturb. A real-time target samples "
        f"everything at {conv.fs_hz:g} Hz with {conv.bits}-bit converters over "
        f"±{conv.range_v / 2:g} V (one step = {conv.lsb_v * 1e6:.1f} µV).",
        "Signal chain (seed Fig. 1): the DAC voltage Uc drives a current amplifier "
        f"(Gi = 1/(R + Rc + Lc s), nominal {nom.current_amp_gain_a_per_v().h * 1e3:.2f} mA/V). "
        "The coil current tilts the Sercalo (a "
        f"{nom.sercalo.resonance_hz.h:g} Hz / {nom.sercalo.resonance_hz.v:g} Hz "
        "mass-spring-damper per axis). The beam reflects twice on the Sercalo and once on the "
        "Newport, and the 4QD converts the beam angle to volts (Gd). The voltage across the "
        f"coil is amplified {nom.voltage_amplifier.gain:g} times (Ga, "
        f"{nom.voltage_amplifier.cutoff_hz:g} Hz low pass).",
        f"Nominal static gains: {g_uc * 1e3:.2f} mrad of beam angle per volt on Uch, "
        f"{g_un * 1e3:.2f} mrad per volt on Unh. Pure delays: "
        f"{plant.input_delay_s['Uch'] * 1e3:.2f} ms on the Sercalo path and "
        f"{plant.input_delay_s['Unh'] * 1e3:.2f} ms on the Newport path.",
        "The digital twin simulates the 'true' parameters, which differ from the nominal ones "
        "as the real bench did (for example its current-amplifier gain, "
        f"{true.current_amp_gain_a_per_v().h * 1e3:.2f} mA/V, seed 2.2).",
    )
    return Section(title="1. The bench", paragraphs=paragraphs, anchor="bench")


def parameters_section(bench: Bench) -> Section:
    """Every parameter with its nominal and true value, unit and source."""
    rows = tuple((r.key, r.nominal, r.true, r.unit, r.source, r.doc) for r in param_rows(bench))
    table = Table(caption="Bench parameters (datasheet rows have no true value)",
                  header=("parameter", "nominal", "true (twin)", "unit", "source", "meaning"),
                  rows=rows)
    return Section(title="2. Parameters", tables=(table,), anchor="parameters",
                   paragraphs=("Nominal: what is known before identification (datasheets, "
                               "measured components, the seed's Table 2). True: what the "
                               "digital twin simulates. docs/model.md derives each value.",))


def _record_row(name: str, ds: xr.Dataset) -> tuple[str, ...]:
    t = np.asarray(ds["t"].values)
    signals = ", ".join(str(v) for v in ds.data_vars)
    return (name, f"{t[-1] - t[0] + 1 / float(ds.attrs['fs_hz']):.2f}",
            f"{float(ds.attrs['fs_hz']):g}", str(ds.sizes["t"]), signals)


def recordings_section(recordings: Mapping[str, xr.Dataset], *, bench: Bench,
                       skipped: Mapping[str, str], source: str) -> Section:
    """Time-domain plots of every experiment, as the seed shows them."""
    gn0 = bench.nominal.newport.metrology_gain_rad_per_v
    rows = tuple(_record_row(n, ds) for n, ds in recordings.items())
    rows += tuple((n, "-", "-", "-", f"skipped: {why}") for n, why in skipped.items())
    table = Table(caption=f"Recordings ({source})",
                  header=("experiment", "length [s]", "fs [Hz]", "samples", "signals"), rows=rows)
    figures = []
    for name, ds in recordings.items():
        if name.startswith("data_huddle_test"):
            continue
        ref, trim = SEED_TIME_FIGURES.get(name, ("", 0.0))
        fig = experiment_figure(ds, gn0_rad_per_v=gn0, trim_s=trim)
        figures.append(figure_from_matplotlib(
            fig, title=f"{name}: time signals", seed_ref=ref,
            caption=(f"{ds.attrs.get('description', '')} Grey: the part the seed's processing "
                     "removes." if trim else str(ds.attrs.get("description", "")))))
    huddles = {n: ds for n, ds in recordings.items() if n.startswith("data_huddle_test")}
    if huddles:
        figures.append(figure_from_matplotlib(
            huddle_figure(huddles), title="Huddle tests: Attocube", seed_ref="Fig. 29",
            caption="Va after the seed's trimming (t >= 1 s, 100 s kept), mean removed."))
        for name, ds in huddles.items():
            figures.append(figure_from_matplotlib(
                experiment_figure(ds, gn0_rad_per_v=gn0, trim_s=1.0),
                title=f"{name}: time signals", seed_ref="Fig. 30",
                caption=str(ds.attrs.get("description", ""))))
    return Section(title="3. Experiments", tables=(table,), figures=tuple(figures),
                   anchor="experiments",
                   paragraphs=("Every record as recorded: commands (DAC), measurements (ADC) "
                               "and the Attocube distance. Long records are drawn as min/max "
                               "envelopes, so every extreme is visible.",))
