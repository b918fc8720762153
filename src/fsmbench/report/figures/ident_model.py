"""The identified model against the records (MATLAB's ``compare``) and its Bode with the
uncertainty band of its parameters (MATLAB's ``bode(sys, 'sd', 3)``).

Drawing only: the numbers come from :mod:`fsmbench.ident.compare` and
:mod:`fsmbench.ident.model_band`, carried on the identification.
"""

from __future__ import annotations

import numpy as np

from fsmbench.ident.compare import ModelComparison
from fsmbench.ident.model_band import ModelBand
from fsmbench.report.figures.spec import H_COLOR, V_COLOR, Figure, Line, Panel

__all__ = ["model_band_figure", "model_compare_figure"]

_RECORDED = "#7f7f7f"
_MODEL = "#d62728"

_KEYS_WORDS = {"quad_diode.gain_v_per_rad": "4QD gains",
               "current_amplifier.r_buffer_ohm": "current-amplifier gains",
               "current_amplifier.r_ohm": "current-amplifier gains",
               "sercalo.resonance_hz": "Sercalo resonances",
               "sercalo.damping_ratio": "Sercalo dampings",
               "sercalo.dc_gain_rad_per_a": "Sercalo static gains",
               "newport.gain_rad_per_v": "Newport gains",
               "newport.natural_freq_hz": "Newport natural frequency",
               "newport.damping_ratio": "Newport damping",
               "newport.internal_delay_s": "Newport internal lag",
               "converter.dac_extra_delay_s": "converter latency"}


def _fit_words(fit_percent: float) -> str:
    return "not compared" if not np.isfinite(fit_percent) else f"fit {fit_percent:.1f} %"


def model_compare_figure(comparison: ModelComparison, *,
                         key: str = "ident_model_compare") -> Figure | None:
    """One panel per record and output: the recorded output and the identified model's over
    a short window, the NRMSE fit in the legend (None when nothing was compared)."""
    if not comparison.fits:
        return None
    panels = []
    for f in comparison.fits:
        fit = _fit_words(f.fit_percent)
        # The coil voltages swing volts, the 4QD's millivolts.
        scale, unit = (1.0, "V") if f.output.startswith("Vc") else (1e3, "mV")
        panels.append(Panel(
            traces=(Line(f.t_s, scale * f.y_v, name="recorded output", color=_RECORDED,
                         width=1.2, group="recorded"),
                    Line(f.t_s, scale * f.y_model_v,
                         name="identified model (its NRMSE fit in each panel's title)",
                         color=_MODEL, dash="dash", width=1.2, group="model")),
            x_label="Time from the record's start [s]",
            y_label=f"{f.output}, mean removed [{unit}]",
            title=f"{f.experiment}: {f.input} → {f.output}, {fit}"))
    fits = "; ".join(f"{f.experiment} {f.output} {f.fit_percent:.1f} %" for f in comparison.fits)
    caption = (
        "The identified plant (a minimal sampled model with its delays exact, a zero-order "
        "hold at the records' rate) driven by each open-loop identification record's "
        "recorded command, against the recorded outputs (MATLAB's compare). Fit: "
        "100 (1 − ‖y − ŷ‖ / ‖y − mean(y)‖) per output, in percent, over the whole record "
        "after the settling interval (100 % is perfect, 0 % no better than the mean). As "
        "MATLAB's compare does on detrended data, the command's mean is removed before "
        "simulating and each output's and the model's mean over the compared span before "
        "comparing (the DC offsets and drifts are not the model's). The model starts at "
        f"rest: the first {comparison.settle_s:g} s, or the identification's trim of the "
        "record when longer, are left out. Each panel shows the first "
        f"{1e3 * comparison.window_s:.0f} ms of the compared span, every sample; zoom to "
        f"compare. Fits: {fits}. A path the model has no coupling on (the Newport's cross "
        "paths) fits about 0 %, and white noise bounds any path's fit: a perfect model "
        "fits 100 (1 − σ_noise/σ_output) % at most.")
    return Figure(key=key, title="The identified model against the identification records "
                                 "(NRMSE fit)",
                  caption=caption, panels=tuple(panels), columns=2)


def _key_words(keys: tuple[str, ...]) -> str:
    words: list[str] = []
    for k in keys:
        stem = ".".join(k.split(".")[1:3])
        w = _KEYS_WORDS.get(stem, stem)
        if w not in words:
            words.append(w)
    return ", ".join(words)


def model_band_figure(band: ModelBand, *, key: str = "ident_model_bode_band") -> Figure:
    """The identified model's Bode on its direct paths with ±n std bands (magnitude, phase)
    and the band's half-width (magnitude in percent, phase in degrees)."""
    n = band.n_sigma
    f = band.f_hz
    mags, phases, widths = [], [], []
    for p in band.paths:
        axis = "h" if p.input.endswith("h") else "v"
        color = H_COLOR if axis == "h" else V_COLOR
        path = f"{p.input} → {p.output}"
        mag = p.magnitude_v_per_v
        lo = np.maximum(mag - n * p.magnitude_std_v_per_v, 1e-3 * mag)
        hi = mag + n * p.magnitude_std_v_per_v
        band_name = f"±{n:g} std band, {axis} axis"
        model_name = f"identified model, {axis} axis"
        mags.append(Panel(
            traces=(Line(f, lo, upper=hi, name=band_name, color=color, opacity=0.35,
                         group=f"band_{axis}"),
                    Line(f, mag, name=model_name, color=color, width=1.3,
                         group=f"model_{axis}")),
            x_label="Frequency [Hz]", y_label=f"|{p.output}/{p.input}| [V/V]", x_log=True,
            y_log=True, title=path, height=2.0))
        phases.append(Panel(
            traces=(Line(f, p.phase_deg - n * p.phase_std_deg,
                         upper=p.phase_deg + n * p.phase_std_deg, name=band_name, color=color,
                         opacity=0.35, group=f"band_{axis}", legend=False),
                    Line(f, p.phase_deg, name=model_name, color=color, width=1.3,
                         group=f"model_{axis}", legend=False)),
            x_label="Frequency [Hz]", y_label="Phase, delay included [deg]", x_log=True,
            height=1.3))
        with np.errstate(divide="ignore", invalid="ignore"):
            rel = 100.0 * n * p.magnitude_std_v_per_v / mag
        widths.append(Panel(
            traces=(Line(f, rel, name=f"magnitude's ±{n:g} std [%]", color="#2ca02c",
                         group="width_mag"),
                    Line(f, n * p.phase_std_deg, name=f"phase's ±{n:g} std [deg]",
                         color="#9467bd", dash="dash", group="width_phase")),
            x_label="Frequency [Hz]", y_label=f"±{n:g} std half-width [% or deg]", x_log=True,
            height=1.0))
    widest = "; ".join(
        f"{p.input} → {p.output} {100 * n * float(np.nanmax(p.magnitude_std_v_per_v / p.magnitude_v_per_v)):.2g} % "  # noqa: E501
        f"and {n * float(np.nanmax(p.phase_std_deg)):.2g}°" for p in band.paths)
    caption = (
        f"The identified model's Bode on the direct paths with a ±{n:g} standard-deviation "
        "band (MATLAB's bode(sys, 'sd', 3)). The band propagates the total standard deviation "
        "of every identified parameter the bench model is built from "
        f"({_key_words(band.keys) or 'none with a std'}) to the response to first order: the "
        "plant rebuilt from the bench file that matches the records with each parameter "
        "moved by ±1 std in turn (central differences), the parameters taken independent "
        "(no covariance between them), the stds added in quadrature; the relative "
        "magnitude std so found is laid on the identified model's own response. At DC the "
        f"band's half-width is {n:g} times the static gain's std. The bottom row gives the "
        "band's half-width: "
        f"the magnitude's in percent, the phase's in degrees. Widest: {widest}.")
    return Figure(key=key, title="The identified model's Bode with its uncertainty band",
                  caption=caption, panels=(*mags, *phases, *widths),
                  columns=len(band.paths), share_x=True)
