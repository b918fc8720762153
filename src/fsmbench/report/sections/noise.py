"""Report: the bench's noise as the identification fitted it (subsection of chapter 2).

Every number comes from :class:`fsmbench.ident.noise_model.NoiseModelFit`; nothing
is computed here.
"""

from __future__ import annotations

import math
from typing import Any

from fsmbench.report.html import Block, Section, Table

__all__ = ["noise_subsection"]


def _value(est: Any, scale: float, spec: str = ".3g") -> str:
    if not est.significant and est.value == 0.0:
        return f"not significant ({format(est.estimate * scale, spec)})"
    std = "" if not math.isfinite(est.std) else f" ± {format(est.std * scale, '.2g')}"
    return f"{format(est.value * scale, spec)}{std}"


def _origin(fit: Any, key: str) -> str:
    words = str(fit.provenance.get(key, ""))
    return "measured" if words.startswith("measured") else "assumed (bench file)"


def noise_subsection(fit: Any | None) -> Section:
    """The fitted noise model: values, where each comes from, and the fit error per band."""
    title = "The bench's noise, fitted to the huddle tests"
    if fit is None:
        return Section(title=title, anchor="noise-model", blocks=(
            "No open-loop huddle test (1, 2 or 4) was recorded: a simulation of this bench "
            "uses the bench file's noise levels, assumed, not measured.",))
    if not fit.tests:
        return Section(title=title, anchor="noise-model", blocks=(
            f"Not fitted: {fit.reason}. A simulation of this bench uses the bench file's noise "
            "levels, assumed.",))
    rows = [
        ("4QD white noise [mV rms per sample]", _value(fit.noise_rms_v["h"], 1e3),
         _value(fit.noise_rms_v["v"], 1e3), _origin(fit, "quad_diode.noise_rms_v")),
        ("4QD 1/f noise at 1 Hz [µV/√Hz]", _value(fit.flicker_asd_v_per_rthz["h"], 1e6),
         _value(fit.flicker_asd_v_per_rthz["v"], 1e6),
         _origin(fit, "quad_diode.flicker_asd_v_per_rthz")),
        ("4QD offset drift [µV/s]", _value(fit.offset_drift_v_per_s["h"], 1e6),
         _value(fit.offset_drift_v_per_s["v"], 1e6),
         _origin(fit, "quad_diode.offset_drift_v_per_s")),
        ("4QD offset random walk [µV/√s]", _value(fit.offset_random_walk_v_per_rts["h"], 1e6),
         _value(fit.offset_random_walk_v_per_rts["v"], 1e6),
         _origin(fit, "quad_diode.offset_random_walk_v_per_rts")),
    ]
    for i, (h, v) in enumerate(zip(fit.mains_amplitude_v["h"], fit.mains_amplitude_v["v"],
                                   strict=True), start=1):
        rows.append((f"mains line {i} × {fit.mains_freq_hz:g} Hz [mV peak]", _value(h, 1e3),
                     _value(v, 1e3), _origin(fit, "quad_diode.mains_amplitude_v")))
    rows += [
        ("Newport angle noise [µrad rms]", _value(fit.newport_noise_rad, 1e6), "(both axes)",
         _origin(fit, "newport.angle_noise_rms_rad")),
        ("Attocube noise floor [nm rms per sample]", _value(fit.attocube_noise_rms_m, 1e9),
         "", _origin(fit, "attocube.noise_rms_m")),
    ]
    errors = [e for e in fit.fit_errors if e.points]
    err_rows = tuple((e.signal, f"{e.low_hz:g}–{e.high_hz:g}", f"{e.median_abs_db:.2f}",
                      f"{e.worst_abs_db:.2f}", f"{e.scatter_db:.2f}",
                      "misfit" if e.flagged else "within scatter") for e in errors)
    worst = max(errors, key=lambda e: e.median_abs_db, default=None)
    blocks: list[Block] = [
        (f"A simulation of this bench (--bench, the closed-loop row, the model's check on "
         f"the recorded loop) uses the noise its own huddle tests show ({', '.join(fit.tests)}):"
         f" the engine's white, 1/f, mains and drift terms fitted by Whittle's likelihood to "
         f"the 4QD outputs' spectra from {fit.fit_band_hz[0]:.3g} Hz to "
         f"{fit.fit_band_hz[1]:.4g} Hz, the Attocube's floor from "
         f"{fit.va_fit_band_hz[0]:.3g} Hz, and the Newport's angle noise from the 4QD–Va "
         f"cross-spectrum. A term that does not pass its significance test is left out."),
        Table(caption="The noise model (± one standard deviation)",
              header=("source", "h", "v", "from"), rows=tuple(rows)),
        Table(caption="Model against the measured spectra, per decade",
              header=("signal", "band [Hz]", "median |error| [dB]", "worst |error| [dB]",
                      "Welch scatter [dB]", "verdict"), rows=err_rows),
    ]
    if worst is not None:
        blocks.append(f"The largest median error is {worst.median_abs_db:.2f} dB ({worst.signal}, "
                      f"{worst.low_hz:g}–{worst.high_hz:g} Hz) against a Welch scatter of "
                      f"{worst.scatter_db:.2f} dB: "
                      + ("a shape the engine cannot simulate is flagged there." if worst.flagged
                         else "the model holds within the estimate's own scatter."))
    blocks += [n.message[0].upper() + n.message[1:] + "." for n in fit.notices]
    return Section(title=title, anchor="noise-model", blocks=tuple(blocks))
