"""The error budget (ESRF study 4): every source's contribution to the measured distance.

Sources and mechanisms
----------------------
Beam-angle sources (4.5), each through the plant and the loop
(:mod:`fsmbench.budget.propagation`), each reaching ``Va`` twice:

* *geometric* (4.1): quadratic in the beam angle, a bias and a fluctuation;
* *piston* (4.2): the mirrors' spot offsets turn their angles into a
  perpendicular motion, linear.

Their geometric terms do not add: ``(Σ αₛ)²`` has cross products. The row
``geometric cross terms`` holds ``Var(all) − Σₛ Var(s)``, so the RSS of the
rows is the total exactly. Linear sources: air (4.3), frame (4.4), the
Attocube's noise and resolution.

Every rms is that of a record of ``window_s`` with its mean removed (what the
huddle tests and the repeatability measurement see): spectra are weighted by
``1 − sinc²(f T)``.
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, fields

import control as ct
import numpy as np
from numpy.typing import NDArray

from fsmbench.bench.blocks import PlantModel
from fsmbench.bench.params import BenchParams
from fsmbench.budget.environment import SEED_4_3, air_budget, frame_budget
from fsmbench.budget.huddle import DacNoiseEstimate, QdNoiseEstimate
from fsmbench.budget.propagation import (
    NoiseInput,
    PropagatedSource,
    QuadraticDistance,
    budget_grid,
    combined_quadratic,
    loop_response,
    propagate,
)
from fsmbench.budget.provenance import row_provenance
from fsmbench.budget.quantisation import SEED_4_5
from fsmbench.budget.spectra import window_weight

__all__ = [
    "SOURCE_IDS",
    "AngleSources",
    "BudgetRow",
    "ErrorBudget",
    "angle_sources",
    "budget_table",
    "error_budget",
    "noise_inputs",
    "source_id",
]

FloatArray = NDArray[np.float64]

#: Stable JSON id of each row and angle source; the display name may change, the id not.
SOURCE_IDS: dict[str, str] = {
    "ADC quantisation (4QD channels)": "qd_adc_quantisation",
    "4QD electronic noise": "qd_electronic_noise",
    "Sercalo DAC quantisation": "sercalo_dac_quantisation",
    "Newport DAC quantisation": "newport_dac_quantisation",
    "Newport angle noise": "newport_angle_noise",
    "geometric cross terms between angle sources": "geometric_cross_terms",
    "air refractive index": "air_refractive_index",
    "metrology frame expansion": "frame_expansion",
    "Attocube noise": "attocube_noise",
    "Attocube resolution": "attocube_resolution",
}


def source_id(name: str) -> str:
    """The JSON id of a budget source (:data:`SOURCE_IDS`; else its name in snake case)."""
    known = SOURCE_IDS.get(name)
    if known is not None:
        return known
    return re.sub(r"[^0-9a-z]+", "_", name.lower()).strip("_")


@dataclass(frozen=True)
class BudgetRow:
    """One source: fluctuation rms and bias of the measured distance [m], and the study's figure.

    ``angle_rms_rad``: beam-angle rms (both axes in quadrature) for angle
    sources, else None. ``seed_m``: the ESRF study's own number where it gives one.
    ``perpendicular_rms_m`` and ``quadratic_rms_m``: an angle source's piston
    and geometric parts (``rms_m`` is their root sum of squares), None for a
    linear row. ``provenance``: ``measured``, ``derived`` or ``assumed``
    (:mod:`fsmbench.budget.provenance`), ``provenance_detail`` in words,
    ``replace_by`` the measurement that would replace an assumed row.
    """

    name: str
    section: str
    mechanism: str
    rms_m: float
    bias_m: float
    angle_rms_rad: float | None
    seed_m: float | None
    seed_note: str
    perpendicular_rms_m: float | None = None
    quadratic_rms_m: float | None = None
    provenance: str = "derived"
    provenance_detail: str = ""
    replace_by: str = ""

    def to_json(self) -> dict[str, object]:
        """Plain values and the row's stable ``id`` (:func:`source_id`)."""
        return {"id": source_id(self.name), **{f.name: getattr(self, f.name) for f in fields(self)}}


@dataclass(frozen=True)
class ErrorBudget:
    """The budget for one configuration.

    ``sources``: propagated angle sources (spectra for the figures);
    ``geometric_all``: their joint quadratic term; ``rows``: the table.
    """

    closed_loop: bool
    compensation_unit: bool
    shielding: bool
    window_s: float | None
    spectra_origin: Mapping[str, str]
    sources: Mapping[str, PropagatedSource]
    geometric_all: QuadraticDistance
    rows: tuple[BudgetRow, ...]
    total_rms_m: float
    total_bias_m: float
    limiting: str

    @property
    def angle_psd_all(self) -> NDArray[np.complex128]:
        """Beam-angle PSD of all sources together [rad²/Hz], shape (F, 2, 2).

        The sources are independent, so their spectra add; on the grid every
        source shares (``sources[...].f_hz``). Its diagonal's cumulative rms ends
        at the root sum of squares of the sources' angle rms.
        """
        return np.asarray(sum(s.angle_psd for s in self.sources.values()), dtype=complex)

    @property
    def configuration(self) -> str:
        """E.g. ``"closed loop, compensation unit, aluminium shielding"``."""
        parts = ["closed loop" if self.closed_loop else "open loop"]
        if self.compensation_unit:
            parts.append("compensation unit")
        if self.shielding:
            parts.append("aluminium shielding")
        return ", ".join(parts)

    def to_json(self) -> dict[str, object]:
        """Rows, total and limiting source; per-source angle and distance scalars.

        ``angle_sources`` and ``limiting_id`` use the ids of :func:`source_id`; the
        display name is each entry's ``name`` (and ``limiting``).
        """
        return {"configuration": self.configuration, "closed_loop": self.closed_loop,
                "compensation_unit": self.compensation_unit, "shielding": self.shielding,
                "window_s": self.window_s, "spectra_origin": dict(self.spectra_origin),
                "rows": [r.to_json() for r in self.rows], "total_rms_m": self.total_rms_m,
                "total_bias_m": self.total_bias_m, "limiting": self.limiting,
                "limiting_id": source_id(self.limiting),
                "angle_sources": {source_id(k): s.to_json() for k, s in self.sources.items()},
                "geometric_all": {"mean_m": self.geometric_all.mean_m,
                                  "std_m": self.geometric_all.std_m}}


def noise_inputs(params: BenchParams, f_hz: FloatArray, *, closed_loop: bool,
                 qd_noise: QdNoiseEstimate | None = None,
                 dac_noise: DacNoiseEstimate | None = None,
                 ) -> tuple[tuple[NoiseInput, ...], dict[str, str]]:
    """The beam-angle sources of 4.5 as one-sided input PSDs on ``f_hz`` (F, 2).

    The Sercalo DAC is a source only in closed loop: a constant command has
    no quantisation noise. Measured spectra (huddle tests) replace the white
    models when given. Returns the inputs and, for the 4QD and the Sercalo
    DAC, where their spectra came from.
    """
    conv = params.converter
    fs = conv.fs_hz
    one = np.ones((f_hz.size, 2))
    quant = conv.lsb_v**2 / (6.0 * fs)  # one-sided q²/(6 fs) = 2Γ
    gd2 = params.quad_diode.gain_v_per_rad.as_array() ** 2
    if qd_noise is None:
        qd_v2 = one * 2.0 * params.quad_diode.noise_rms_v.as_array() ** 2 / fs
        origin = "nominal white noise (no open-loop huddle test)"
    else:
        qd_v2 = np.stack([np.interp(f_hz, qd_noise.f_hz, qd_noise.psd_v2_per_hz[:, i])
                          for i in range(2)], axis=1)
        origin = "huddle tests " + ", ".join(qd_noise.tests)
    if dac_noise is None:
        dac_v2 = one * quant
        dac_origin = "white q²/(12 fs) (ESRF study 4.5c)"
    else:
        dac_v2 = np.stack([np.interp(f_hz, dac_noise.f_hz, dac_noise.psd_v2_per_hz[:, i])
                           for i in range(2)], axis=1)
        dac_origin = "measured in huddle tests " + ", ".join(dac_noise.tests)
    nea = params.newport.angle_noise_rms_rad
    out = [
        NoiseInput("ADC quantisation (4QD channels)", "sensor", one * quant / gd2,
                   "q²/(12 fs) on Vph, Vpv, seen as a beam angle through 1/Gd", "4.5a-b"),
        NoiseInput("4QD electronic noise", "sensor", qd_v2 / gd2,
                   f"4QD output noise ({origin}) through 1/Gd", "4.5b"),
        NoiseInput("Newport DAC quantisation", "newport_dac", one * quant,
                   "q²/(12 fs) on Unh, Unv through the Newport", "4.5a"),
        NoiseInput("Newport angle noise", "newport_angle", one * 2.0 * nea**2 / fs,
                   f"mirror noise-equivalent angle {nea * 1e6:g} µrad rms, white to fs/2",
                   "4.5a"),
    ]
    if closed_loop:
        out.insert(2, NoiseInput("Sercalo DAC quantisation", "sercalo_dac", dac_v2,
                                 f"quantisation of Uch, Ucv ({dac_origin}) through the Sercalo",
                                 "4.5c"))
    return tuple(out), {"qd": origin, "sercalo_dac": dac_origin if closed_loop else "none"}


_SEED_ROW = {
    "ADC quantisation (4QD channels)": (SEED_4_5["qd_lsb_distance_m"], "4.5b: 1 LSB → 0.5 nm"),
    "4QD electronic noise": (SEED_4_5["qd_distance_m"], "4.5b: 1 mV per quadrant → 1.5 nm"),
    "Sercalo DAC quantisation": (SEED_4_5["sercalo_dac_distance_rms_m"],
                                 "4.5c: 1.647e-11 m rms (10 Hz–1 kHz, open loop, linear law)"),
    "Newport DAC quantisation": (None, "4.5a: 0.2 µrad rms of mirror angle, no distance"),
    "Newport angle noise": (None, "4.5a: Γd = 3.6e-15 rad²/Hz, no distance"),
}


def _wvar(f: FloatArray, psd: FloatArray, w: FloatArray) -> float:
    return float(np.sum(psd * w) * (f[1] - f[0]))


@dataclass(frozen=True)
class AngleSources:
    """The beam-angle sources propagated through one loop state (open or closed)."""

    closed_loop: bool
    f_hz: FloatArray
    sources: Mapping[str, PropagatedSource]
    geometric_all: QuadraticDistance
    spectra_origin: Mapping[str, str]


def angle_sources(params: BenchParams, *, plant: PlantModel, controller: ct.StateSpace | None,
                  closed_loop: bool = True, qd_noise: QdNoiseEstimate | None = None,
                  dac_noise: DacNoiseEstimate | None = None, df_hz: float = 0.1) -> AngleSources:
    """Propagate the 4.5 sources through the plant and the loop (see :func:`error_budget`)."""
    f = budget_grid(fs_hz=params.converter.fs_hz, df_hz=df_hz)
    loop = loop_response(plant, params=params, f_hz=f, controller=controller,
                         closed_loop=closed_loop)
    inputs, origin = noise_inputs(params, f, closed_loop=closed_loop, qd_noise=qd_noise,
                                  dac_noise=dac_noise)
    sources = {s.name: propagate(s, loop, params=params) for s in inputs}
    return AngleSources(closed_loop=closed_loop, f_hz=f, sources=sources,
                        geometric_all=combined_quadratic(sources, params=params),
                        spectra_origin=origin)


def budget_table(params: BenchParams, angles: AngleSources, *, compensation_unit: bool = True,
                 shielding: bool = True, window_s: float | None = 100.0) -> ErrorBudget:
    """Assemble the rows for one configuration from propagated angle sources."""
    f, sources, geo_all = angles.f_hz, angles.sources, angles.geometric_all
    w = window_weight(f, window_s=window_s)
    rows: list[BudgetRow] = []
    quad_vars = 0.0
    for name, s in sources.items():
        qv = _wvar(f, s.quadratic.psd_m2_per_hz, w)
        pv = _wvar(f, s.perpendicular_psd_m2_per_hz, w)
        quad_vars += qv
        seed_m, note = _SEED_ROW[name]
        rows.append(BudgetRow(
            name=name, section=s.seed_section, mechanism="piston (4.2) + geometric (4.1)",
            rms_m=math.sqrt(pv + qv),
            bias_m=s.quadratic.mean_m, angle_rms_rad=float(np.hypot(*s.angle_rms_rad)),
            seed_m=seed_m, seed_note=note, perpendicular_rms_m=math.sqrt(pv),
            quadratic_rms_m=math.sqrt(qv)))
    cross = max(_wvar(f, geo_all.psd_m2_per_hz, w) - quad_vars, 0.0)
    rows.append(BudgetRow("geometric cross terms between angle sources", "4.1",
                          "geometric (4.1)", math.sqrt(cross), 0.0, None, None, ""))
    air = air_budget(params, compensation_unit=compensation_unit, shielding=shielding,
                     window_s=window_s)
    frame = frame_budget(params, window_s=window_s)
    att = params.attocube
    nyq = params.converter.fs_hz / 2.0
    white_w = float(np.mean(window_weight(np.linspace(0.0, nyq, 20001), window_s=window_s)))
    rows += [
        BudgetRow("air refractive index", "4.3", "linear",
                  air.window_rms_m, 0.0, None, SEED_4_3["eq11_m"],
                  "eq. (11): √(20² + 50² + 4²) = 54 nm for the compensation unit's ranges"),
        BudgetRow("metrology frame expansion", "4.4", "linear", frame.window_rms_m, 0.0, None,
                  None, "≈1 µm/K (aluminium), 60 nm/K (invar); frame within 0.1 K"),
        BudgetRow("Attocube noise", "—", "linear", att.noise_rms_m * math.sqrt(white_w), 0.0,
                  None, None, "not in the ESRF study's budget"),
        BudgetRow("Attocube resolution", "—", "linear",
                  att.resolution_m / math.sqrt(12.0) * math.sqrt(white_w), 0.0, None, None,
                  "not in the ESRF study's budget"),
    ]
    expansion = params.geometry.frame_expansion_per_k
    rows = [dataclasses.replace(r, provenance=prov.kind, provenance_detail=prov.detail,
                                replace_by=prov.replace_by)
            for r in rows
            for prov in (row_provenance(r.name, angles.spectra_origin,
                                        frame_expansion_per_k=expansion),)]
    total = math.sqrt(sum(r.rms_m**2 for r in rows))
    limiting = max(rows, key=lambda r: r.rms_m).name
    return ErrorBudget(
        closed_loop=angles.closed_loop, compensation_unit=compensation_unit, shielding=shielding,
        window_s=window_s, spectra_origin=angles.spectra_origin, sources=sources,
        geometric_all=geo_all, rows=tuple(rows), total_rms_m=total,
        total_bias_m=geo_all.mean_m, limiting=limiting)


def error_budget(params: BenchParams, *, plant: PlantModel, controller: ct.StateSpace | None,
                 closed_loop: bool = True, compensation_unit: bool = True,
                 shielding: bool = True, window_s: float | None = 100.0,
                 qd_noise: QdNoiseEstimate | None = None,
                 dac_noise: DacNoiseEstimate | None = None, df_hz: float = 0.1) -> ErrorBudget:
    """Propagate every source to the measured distance and assemble the table.

    Parameters
    ----------
    params : BenchParams
        Noise levels, geometry, environment (usually ``bench.nominal``).
    plant : PlantModel
        Plant with outputs ``Rh, Rv`` (physical or identified).
    controller : control.StateSpace or None
        ``K: Rh, Rv → Uch, Ucv`` closed as ``U = −K R`` (ESRF study 9.2; continuous,
        or discrete as the ESRF study's 9.3 ``Kd``); needed in closed loop.
    closed_loop, compensation_unit, shielding : bool
        Configuration (ESRF study Table 3; default: the repeatability measurement's).
    window_s : float or None
        Record length T [s] (mean removed); None: stationary values.
    qd_noise : QdNoiseEstimate, optional
        4QD noise measured in the huddle tests; default the nominal white noise.
    dac_noise : DacNoiseEstimate, optional
        Sercalo DAC error measured in the closed-loop huddle tests; default the
        white ``q²/(12 fs)`` (which a command of ~1 LSB rms does not meet).
    df_hz : float
        Grid step [Hz] (:func:`~fsmbench.budget.propagation.budget_grid`).
    """
    angles = angle_sources(params, plant=plant, controller=controller, closed_loop=closed_loop,
                           qd_noise=qd_noise, dac_noise=dac_noise, df_hz=df_hz)
    return budget_table(params, angles, compensation_unit=compensation_unit,
                        shielding=shielding, window_s=window_s)
