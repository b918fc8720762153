"""Chapter 1 (the bench and its recordings) and Appendix A (bench parameters)."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import xarray as xr

from fsmbench.bench.blocks import physical_plant
from fsmbench.bench.params import Bench, param_rows
from fsmbench.io.signals import EXPERIMENTS, SIGNALS
from fsmbench.report.html import Note, Section, Table

__all__ = ["bench_section", "parameters_appendix", "recordings_table"]

# Parameter groups (first part of a parameter's key) in words.
_GROUPS = {
    "datasheet.sercalo": "Sercalo datasheet", "datasheet.newport": "Newport datasheet",
    "converter": "ADC and DAC", "sercalo": "Sercalo", "current_amplifier": "current amplifier",
    "voltage_amplifier": "voltage amplifier", "newport": "Newport", "quad_diode": "4QD",
    "attocube": "Attocube", "geometry": "geometry", "environment": "environment",
    "scaling": "scaling (ESRF study 6)",
}


def _group(key: str) -> str:
    parts = key.split(".")
    head = ".".join(parts[:2]) if parts[0] == "datasheet" else parts[0]
    words = _GROUPS.get(head, head.replace("_", " "))
    return words[0].upper() + words[1:]


def bench_section(bench: Bench, *, recordings: Mapping[str, xr.Dataset],
                  skipped: Mapping[str, str], source: str, is_twin: bool) -> Section:
    """"1. The bench and its recordings": the bench in words with its key numbers, the records.

    Parameters
    ----------
    bench : Bench
        Nominal parameters give every number quoted; the true ones are
        quoted only when ``is_twin``.
    recordings : mapping experiment -> Dataset
        The records loaded (coordinate ``t`` [s], attribute ``fs_hz`` [Hz]).
    skipped : mapping experiment -> reason
        Experiments not loaded, with the reason in words.
    source : str
        Where the records come from (folder, or the twin).
    is_twin : bool
        The records were simulated by the digital twin.
    """
    nom = bench.nominal
    plant = physical_plant(nom)
    g_uc = plant.dc_gain(output="Rh", input="Uch")
    g_un = plant.dc_gain(output="Rh", input="Unh")
    conv = nom.converter
    ser = nom.sercalo
    gi = nom.current_amp_gain_a_per_v()
    qd = nom.quad_diode.gain_v_per_rad
    blocks: list[str | Table | Note] = [
        "The bench stabilises a laser beam with a Sercalo voice-coil mirror (the actuator) "
        "while a Newport FSM-300 mirror tilts the beam to emulate the motion of a sample. A "
        "four-quadrant photodiode (4QD) measures the beam angle, and an Attocube "
        "interferometer measures the length of the beam path, which the stabilisation must "
        "not disturb. A real-time target samples every signal at "
        f"{conv.fs_hz:g} Hz with {conv.bits}-bit converters over ±{conv.range_v / 2:g} V: one "
        f"step is {conv.lsb_v * 1e6:.1f} µV, and rounding adds white noise of "
        f"{conv.quantisation_psd_v2_per_hz:.3g} V²/Hz (ESRF study 1.6).",
        "Signal chain (ESRF study Figs. 1 and 2): the DAC voltage Uc drives a current amplifier, "
        f"Gi = 1/(R + Rc + Lc·s), nominally {gi.h * 1e3:.2f} mA/V (h) and {gi.v * 1e3:.2f} "
        "mA/V (v). The coil current tilts the Sercalo, a mass-spring-damper per axis with "
        f"resonances at {ser.resonance_hz.h:g} Hz (h) and {ser.resonance_hz.v:g} Hz (v) and "
        f"damping ratios {ser.damping_ratio.h:.2g} and {ser.damping_ratio.v:.2g} derived from "
        "its datasheet. The beam reflects twice on the Sercalo and once on the Newport, whose "
        f"metrology reads {nom.newport.metrology_gain_rad_per_v * 1e3:.2f} mrad of mirror "
        "angle per volt. The 4QD converts the beam angle to volts (Gd, nominally "
        f"{qd.h:g} V/rad (h) and {qd.v:g} V/rad (v), ESRF study Table 2). The voltage across the "
        f"coil is amplified {nom.voltage_amplifier.gain:g} times (Ga, "
        f"{nom.voltage_amplifier.cutoff_hz:g} Hz low pass).",
        f"Nominal static gains: {g_uc * 1e3:.2f} mrad of beam angle per volt on the Sercalo's "
        f"horizontal command and {g_un * 1e3:.2f} mrad per volt on the Newport's. Pure delays: "
        f"{plant.input_delay_s['Uch'] * 1e3:.2f} ms on the Sercalo path (one sample of "
        "computation and half a sample of hold) and "
        f"{plant.input_delay_s['Unh'] * 1e3:.2f} ms on the Newport path.",
        Note("The ESRF study's 1.2 derives a damping ratio of 0.33 % from the datasheet with "
             "two slips (28.4 mA/deg is a current per angle, and 282.9 deg/V is not in its "
             "Table 1); the datasheet itself gives the ratios above.", ref="errata E1–E3"),
    ]
    if is_twin:
        true = bench.true
        blocks.append(
            "The records below were simulated by the digital twin. It runs the 'true' "
            "parameters, which differ from the nominal ones as the real bench did: for "
            f"example its current-amplifier gain is {true.current_amp_gain_a_per_v().h * 1e3:.2f}"
            " mA/V (h) where the components give "
            f"{gi.h * 1e3:.2f} mA/V (ESRF study 2.2), and its Sercalo resonates at "
            f"{true.sercalo.resonance_hz.h:g} Hz and {true.sercalo.resonance_hz.v:g} Hz. "
            "Appendix A lists both sets.")
    blocks.append(Table(
        caption="Signals of the recordings (ESRF study section 2)",
        header=("signal", "what it is", "unit"),
        rows=tuple((s.name, s.long_name.replace(" - ", ", "), s.units)
                   for s in SIGNALS.values())))
    blocks.append(recordings_table(recordings, skipped=skipped, source=source))
    return Section(title="1. The bench and its recordings", blocks=tuple(blocks), anchor="bench")


def _duration_s(ds: xr.Dataset) -> float:
    t = ds["t"].data  # numpy, or Dask for a long record: only its two ends are read
    first, last = (float(np.asarray(v)) for v in (t[0], t[-1]))
    return last - first + 1.0 / float(ds.attrs["fs_hz"])


def recordings_table(recordings: Mapping[str, xr.Dataset], *, skipped: Mapping[str, str],
                     source: str) -> Table:
    """One row per experiment: what it is, length [s], sampling rate [Hz], samples, signals.

    Experiments not loaded get a row saying why. Known experiments come in
    the ESRF study's order, others after them.
    """
    names = [n for n in EXPERIMENTS if n in recordings or n in skipped]
    names += [n for n in (*recordings, *skipped) if n not in names]
    rows = []
    for name in names:
        info = EXPERIMENTS.get(name)
        what = f"{info.description} (ESRF study {info.section})" if info else ""
        if name in recordings:
            ds = recordings[name]
            signals = ", ".join(str(v) for v in ds.data_vars)
            rows.append((name, what, f"{_duration_s(ds):.2f}", f"{float(ds.attrs['fs_hz']):g}",
                         str(ds.sizes["t"]), signals))
        else:
            rows.append((name, what, "–", "–", "–", f"not loaded: {skipped[name]}"))
    return Table(caption=f"Recordings ({source})",
                 header=("experiment", "what was done", "length [s]", "sampling rate [Hz]",
                         "samples", "signals"),
                 rows=tuple(rows))


def parameters_appendix(bench: Bench, *, is_twin: bool) -> Section:
    """"Appendix A. Bench parameters": every parameter with its value, unit and source.

    Parameters
    ----------
    bench : Bench
    is_twin : bool
        Add the twin's true values (only when the records are the twin's).
    """
    rows = []
    for r in param_rows(bench):
        unit = "–" if r.unit == "1" else r.unit
        values = (r.nominal, r.true or "–") if is_twin else (r.nominal,)
        rows.append((_group(r.key), r.doc, *values, unit, r.source, r.key))
    header = ("block", "parameter", "nominal", *(("true (twin)",) if is_twin else ()), "unit",
              "source", "name in the bench file")
    text = ("Nominal: what is known before identification (datasheets, measured components, "
            "the ESRF study's Table 2). docs/model.md derives each value. Values with h and v are "
            "per axis.")
    if is_twin:
        text += (" True: what the digital twin simulates; datasheet rows have no true value.")
    return Section(title="Appendix A. Bench parameters", anchor="parameters", blocks=(
        text, Table(caption="Bench parameters", header=header, rows=tuple(rows))))
