"""The draws of a Monte Carlo: which plant parameters move, by how much, from which seed.

Each draw perturbs the twin's plant (``bench.true``) within its uncertainty
(:class:`Ranges`: resonance and damping from the design's robustness check,
gains and delays from the identification's targets). Draw ``i`` depends on the
run's seed and ``i`` only (``SeedSequence(ESRF study).spawn(n)[i]``), so the draws are
the same whatever the number of workers.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from fsmbench.bench.params import BenchParams
from fsmbench.bench.perturbed import PARAMETERS, perturbed_bench
from fsmbench.control.design import DesignOptions
from fsmbench.jsonutil import plain_json
from fsmbench.twin.compare import TARGETS

__all__ = ["PARAMETERS", "RANGE_OF_PARAMETER", "Draw", "Ranges", "draw_parameters",
           "parameter_values", "perturbed_bench"]

# The loosest identification target on a gain, and the delay targets [s].
_GAIN_TOLERANCE = max(TARGETS[f"{k}.{a}"][1] for a in "hv"
                      for k in ("qd_gain_v_per_rad", "current_amp_gain_a_per_v",
                                "newport_gain_v_per_v"))
# The delay targets are in samples of the converter's rate ("samples" kind); the ranges are in
# seconds (what a TOML gives), here one sample of the packaged bench's 10 kHz. For another
# rate give the ranges in the TOML.
_PACKAGED_TS_S = 1e-4
assert TARGETS["delay_s.sercalo"][0] == TARGETS["delay_s.newport"][0] == "samples"
_DAC_DELAY_TOLERANCE_S = TARGETS["delay_s.sercalo"][1] * _PACKAGED_TS_S
_NEWPORT_DELAY_TOLERANCE_S = TARGETS["delay_s.newport"][1] * _PACKAGED_TS_S

#: The :class:`Ranges` attribute each drawn parameter comes from.
RANGE_OF_PARAMETER: dict[str, str] = {
    **{k: k.split(".")[0] for k in PARAMETERS if "." in k},
    "dac_delay_offset_s": "dac_delay_s", "newport_delay_offset_s": "newport_delay_s",
}

def _interval(values: Sequence[float]) -> tuple[float, float]:
    return (float(min(values)), float(max(values)))


_DESIGN = DesignOptions()


@dataclass(frozen=True)
class Ranges:
    """Where the draws fall: ``(low, high)`` per kind of parameter.

    Scales multiply the twin's true value (each axis drawn on its own);
    offsets add to the delays [s] (clipped at zero delay).

    Attributes
    ----------
    resonance_scale : (float, float)
        Uniform; default the design's robust set, ``DesignOptions().frequency_scales``.
    damping_scale : (float, float)
        Log-uniform; default ``DesignOptions().damping_scales``.
    qd_gain_scale, current_amp_gain_scale, newport_gain_scale : (float, float)
        Uniform; default ``1 ± 3 %`` (the loosest identification target on a gain).
    dac_delay_s, newport_delay_s : (float, float)
        Uniform offsets [s]; default the identification's delay targets (± 0.1 ms,
        one sample).
    """

    resonance_scale: tuple[float, float] = _interval(_DESIGN.frequency_scales)
    damping_scale: tuple[float, float] = _interval(_DESIGN.damping_scales)
    qd_gain_scale: tuple[float, float] = (1 - _GAIN_TOLERANCE, 1 + _GAIN_TOLERANCE)
    current_amp_gain_scale: tuple[float, float] = (1 - _GAIN_TOLERANCE, 1 + _GAIN_TOLERANCE)
    newport_gain_scale: tuple[float, float] = (1 - _GAIN_TOLERANCE, 1 + _GAIN_TOLERANCE)
    dac_delay_s: tuple[float, float] = (-_DAC_DELAY_TOLERANCE_S, _DAC_DELAY_TOLERANCE_S)
    newport_delay_s: tuple[float, float] = (-_NEWPORT_DELAY_TOLERANCE_S,
                                            _NEWPORT_DELAY_TOLERANCE_S)

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            lo, hi = getattr(self, f.name)
            if not (math.isfinite(lo) and math.isfinite(hi)) or lo > hi:
                raise ValueError(f"range {f.name} must be finite with low <= high, got "
                                 f"({lo}, {hi})")
            if f.name.endswith("_scale") and lo <= 0:
                raise ValueError(f"range {f.name} is a factor and must be > 0, got ({lo}, {hi})")

    @classmethod
    def nominal(cls) -> Ranges:
        """Zero-width ranges: every draw is the twin's own plant."""
        return cls(**{f.name: ((0.0, 0.0) if f.name.endswith("_s") else (1.0, 1.0))
                      for f in dataclasses.fields(cls)})

    def to_json(self) -> dict[str, Any]:
        """``{key: [low, high]}``."""
        return plain_json(dataclasses.asdict(self))


@dataclass(frozen=True)
class Draw:
    """One draw: its index, its noise seed and its factors (:data:`PARAMETERS` keys)."""

    index: int
    noise_seed: int
    factors: Mapping[str, float]


def draw_parameters(*, seed: int, n: int, ranges: Ranges) -> list[Draw]:
    """The ``n`` draws of a run: draw ``i`` from ``SeedSequence(ESRF study).spawn(n)[i]`` alone.

    Each child sequence spawns two: one seeds the generator of the factors
    (drawn in the order of :data:`PARAMETERS`), the other gives the twin's
    noise seed (a 32-bit integer).
    """
    if n < 1:
        raise ValueError(f"the number of draws must be >= 1, got {n}")
    out = []
    for i, child in enumerate(np.random.SeedSequence(seed).spawn(n)):
        params_ss, noise_ss = child.spawn(2)
        rng = np.random.default_rng(params_ss)
        factors: dict[str, float] = {}
        for key in PARAMETERS:
            lo, hi = getattr(ranges, RANGE_OF_PARAMETER[key])
            u = float(rng.uniform())  # always drawn, so a zero-width range keeps the stream
            if key.startswith("damping_scale"):
                factors[key] = float(math.exp(math.log(lo) + u * (math.log(hi) - math.log(lo))))
            else:
                factors[key] = lo + u * (hi - lo)
        out.append(Draw(index=i, noise_seed=int(noise_ss.generate_state(1, np.uint32)[0]),
                        factors=factors))
    return out


def parameter_values(p: BenchParams, *,
                     identified: Mapping[str, Any] | None = None) -> dict[str, float]:
    """The drawn plant's values, SI (for the rows of ``montecarlo.json``).

    ``identified``: an identified bench's values (``bench.model.values``): the
    Sercalo's modes come from it, not from the bench file's physics.
    """
    gi = p.current_amp_gain_a_per_v()
    out: dict[str, float] = {}
    for a in "hv":
        if identified is not None and "sercalo" in identified:
            out[f"sercalo.resonance_hz.{a}"] = float(identified["sercalo"][a]["resonance_hz"])
            out[f"sercalo.damping_ratio.{a}"] = float(identified["sercalo"][a]["damping_ratio"])
        else:
            out[f"sercalo.resonance_hz.{a}"] = p.sercalo.resonance_hz[a]
            out[f"sercalo.damping_ratio.{a}"] = p.sercalo.damping_ratio[a]
        out[f"quad_diode.gain_v_per_rad.{a}"] = p.quad_diode.gain_v_per_rad[a]
        out[f"current_amp_gain_a_per_v.{a}"] = gi[a]
        out[f"newport.gain_rad_per_v.{a}"] = p.newport.gain_rad_per_v[a]
    out["converter.dac_delay_s"] = float(p.converter.dac_delay_samples) * p.converter.ts_s
    out["newport.internal_delay_s"] = p.newport.internal_delay_s
    return out
