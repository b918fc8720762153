"""The report's identification section (seed section 2)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import xarray as xr

from fsmbench.bench.params import Bench
from fsmbench.ident.calibration import trim_recording
from fsmbench.ident.compare import comparison_rows
from fsmbench.ident.frf import FrequencyResponse, spectral_matrix
from fsmbench.ident.pipeline import Identification
from fsmbench.ident.welch import hanning
from fsmbench.report.html import Section, Table, figure_from_matplotlib
from fsmbench.report.ident_plots import (
    coherence_figure,
    current_amplifier_figure,
    delay_figure,
    frf_matrix_figure,
    qd_regression_figure,
    weights_figure,
)

__all__ = ["identification_section"]


def _g(x: float) -> str:
    return f"{x:.6g}"


def _amplifier_frfs(result: Identification, recordings: Mapping[str, xr.Dataset]
                    ) -> dict[str, FrequencyResponse]:
    out = {}
    for axis, (exp, u, v) in (("h", ("data_uch", "Uch", "Vch")), ("v", ("data_ucv", "Ucv", "Vcv"))):
        ds = trim_recording(recordings[exp], t0_s=result.options.trims_s.get(exp, 1.0))
        fs = float(ds.attrs["fs_hz"])
        out[axis] = spectral_matrix(ds[u].values, ds[v].values, input_names=[u], output_names=[v],
                                    window=hanning(int(np.ceil(result.options.window_s * fs))),
                                    fs_hz=fs)
    return out


def identification_section(result: Identification, *, recordings: Mapping[str, xr.Dataset],
                           bench: Bench, truth: Mapping[str, Any] | None) -> Section:
    """Figures and tables of the identification, identified values against the reference."""
    ident = result.to_json()
    rows = comparison_rows(ident, reference=truth, bench=bench)
    ref_kind = "true value (twin)" if truth is not None else "nominal value"
    table = Table(
        caption=f"Identified against the {ref_kind}" + (
            " (targets of the identification issue)" if truth is not None else ""),
        header=("quantity", "identified", ref_kind, "difference", "target", "met"),
        rows=tuple((r.key, _g(r.identified), _g(r.reference), f"{r.relative_difference:+.2%}",
                    r.target, {True: "yes", False: "NO", None: "-"}[r.within_target])
                   for r in rows))
    tables = [table]
    paragraphs = [
        "Section 2 of the seed, run on the recordings: the 4QD is calibrated against the "
        "Newport metrology (2.1), the current amplifiers from Uc → Vc with Ga and Zc taken as "
        "known (2.2), the Sercalo from Uc → Vp by weighted vector fitting after removing the "
        "delay estimated from the phase (2.3), the Newport gains and delay (2.4), and the "
        "blocks are assembled with the seed's connect (2.5).",
    ]
    if result.warnings:
        paragraphs.append("Quality warnings — do not trust the affected results: "
                          + " ".join(result.warnings))
    else:
        paragraphs.append("Quality checks passed: fit converged, direct paths within 5 % rms "
                          "and explaining > 90 % of the recorded variance, modal fits converged.")
    if result.skipped:
        paragraphs.append("Skipped: " + "; ".join(f"{k} ({v})" for k, v in result.skipped.items())
                          + ".")
    figures = []
    if result.qd:
        figures.append(figure_from_matplotlib(
            qd_regression_figure(result.qd, recordings), title="4QD calibration",
            seed_ref="Fig. 10", caption="Linear regression of the 4QD voltage on the beam angle "
            "(twice the Newport mirror angle from its metrology)."))
    if result.current_amp:
        figures.append(figure_from_matplotlib(
            current_amplifier_figure(result.current_amp, _amplifier_frfs(result, recordings),
                                     bench.nominal),
            title="Current amplifier", seed_ref="Figs. 12–14",
            caption="Top: Uc → Vc measured, and Ga·Zc·Gi with the theoretical and the "
                    "identified Gi. Bottom: |Ga Zc Gi|/|Ga Zc| over the averaging band."))
    if result.sercalo is not None:
        s = result.sercalo
        model = np.full(s.frf.frf.shape, np.nan, dtype=complex)
        f = s.frf.frequency_hz
        model[f > 0] = s.fit.response(f[f > 0])
        figures += [
            figure_from_matplotlib(coherence_figure(s.frf, title="Sercalo: coherence"),
                                   title="Sercalo coherence", seed_ref="Fig. 17",
                                   caption="Coherence of Uc → Vp (1 s Hann window)."),
            figure_from_matplotlib(
                frf_matrix_figure(s.frf, delay_s=s.delay_s, model=model, part="magnitude",
                                  title="Sercalo: Uc → Vp"),
                title="Sercalo FRF matrix and fit, magnitude", seed_ref="Figs. 18, 21",
                caption=f"Delay {1e3 * s.delay_s:.4f} ms removed; dashed: the fitted model "
                        f"({s.fit.n_poles} poles, modes refined on the time records)."),
            figure_from_matplotlib(
                frf_matrix_figure(s.frf, delay_s=s.delay_s, model=model, part="phase",
                                  title="Sercalo: Uc → Vp, phase"),
                title="Sercalo FRF matrix and fit, phase", seed_ref="Figs. 19, 22", caption=""),
            figure_from_matplotlib(weights_figure(s), title="Fit weights", seed_ref="Fig. 20",
                                   caption="The seed's weights: coherence, 10 within ±10 % of "
                                           "each column's resonance, 0 above 1 kHz; divided "
                                           "by |H| in the fit (relative error)."),
        ]
        modes = result.sercalo_modes()
        tables.append(Table(
            caption="Sercalo modes (frequency-domain output error on the full records; "
                    "standard errors are 1 sigma)",
            header=("axis", "resonance [Hz]", "± [Hz]", "damping ratio", "±",
                    "from the 1 s Welch fit"),
            rows=tuple((a, f"{m['resonance_hz']:.4f}", f"{m['resonance_hz_std']:.2g}",
                        f"{m['damping_ratio']:.4e}", f"{m['damping_ratio_std']:.2g}",
                        _welch_damping(result, a)) for a, m in modes.items())))
        tables.append(Table(
            caption="Fit quality: rms relative magnitude error, 10 Hz–1 kHz where coherence > "
                    "0.9, and variance accounted for by the model in the time domain",
            header=("path", "rms relative error", "VAF"),
            rows=tuple((k, f"{v:.2%}", _vaf(result, k)) for k, v in s.fit_error.items())))
    if result.newport is not None:
        n = result.newport
        figures += [
            figure_from_matplotlib(coherence_figure(n.frf, title="Newport: coherence"),
                                   title="Newport coherence", seed_ref="Fig. 25", caption=""),
            figure_from_matplotlib(
                frf_matrix_figure(n.frf, delay_s=n.delay_s, model=None, part="magnitude",
                                  title="Newport: Un → Vp"),
                title="Newport FRF matrix, magnitude", seed_ref="Fig. 26",
                caption=f"Signed low-frequency gains {n.gain_v_per_v['h']:.4f} (h) and "
                        f"{n.gain_v_per_v['v']:.4f} (v) V/V over "
                        f"{n.band_hz[0]:g}–{n.band_hz[1]:g} Hz."),
            figure_from_matplotlib(delay_figure(n), title="Newport delay", seed_ref="Fig. 28",
                                   caption="Phase before and after removing the delay "
                                           "estimated from the phase (the seed assumes 0.5 ms)."),
        ]
    delays = [(f"{d.input} → {d.output}", f"{1e3 * d.delay_s:.4f}", f"{1e3 * d.std_s:.2g}",
               f"{d.band_hz[0]:.0f}–{d.band_hz[1]:.0f}")
              for part in (result.sercalo, result.newport) if part is not None
              for d in part.delays]
    if delays:
        tables.append(Table(caption="Delays estimated from the phase (Bode gain–phase relation)",
                            header=("path", "delay [ms]", "± [ms]", "band [Hz]"),
                            rows=tuple(delays)))
    tables.append(Table(caption="Blocks of the assembled system (2.5)",
                        header=("block", "from"),
                        rows=tuple((k, v) for k, v in result.plant_blocks.items())))
    return Section(title="4. Identification", anchor="identification",
                   paragraphs=tuple(paragraphs), tables=tuple(tables), figures=tuple(figures))


def _welch_damping(result: Identification, axis: str) -> str:
    if result.modes is None:
        return "-"
    return f"{result.modes.initial[axis][1]:.4e}"


def _vaf(result: Identification, key: str) -> str:
    out, inp = key.split("/")
    for v in result.validation:
        if v.output == out and v.input == inp:
            return f"{v.vaf:.5f}"
    return "-"
