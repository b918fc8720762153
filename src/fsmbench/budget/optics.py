"""ESRF study 4.1–4.2 and 11.3 recomputed from the exact ray trace (:mod:`fsmbench.bench.geometry`).

* 4.1: the quadratic law fitted to the trace over the ESRF study's range (Fig. 34),
  checked against the derived ``k = 12H + 8L`` at several angles and
  geometries, and Table 4 recomputed (errata E15);
* 4.2: perpendicular motion of each mirror (eqs. 9–10, errata E18);
* 11.3: the ESRF study's ``ΔL = L α²/2`` against the traced law in terms of the
  beam angle α = 4δθc (errata E17).
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from fsmbench.bench.geometry import (
    AngleErrorTable,
    BeamPathFigure,
    PerpendicularMotion,
    QuadraticLawFit,
    angle_error_table,
    beam_path_figure_data,
    fit_quadratic_law,
    perpendicular_motion,
    small_angle_law,
    trace_bench,
)
from fsmbench.bench.params import BenchParams

__all__ = ["SEED_4_1", "GeometryBudget", "LawCheck", "geometry_budget", "law_checks"]

#: Seed 4.1 eq. (8) coefficient [m/rad²], Table 4 [rad → m], 4.2 eqs. (9)–(10), 11.3 L [m].
SEED_4_1: dict[str, object] = {
    "eq8_m_per_rad2": 1.0,
    "table4_theta_rad": [1e-6, 5e-6, 10e-6],
    "table4_error_m": [1e-9, 25e-9, 100e-9],
    "eq9_sercalo_path_per_shift": 2.0,
    "eq10_newport_path_per_shift": 2.0,
    "law_11_3_length_m": 0.1,
}


@dataclass(frozen=True)
class LawCheck:
    """Trace against ``k·θ²`` at one angle and geometry (relative difference, and after k4θ⁴)."""

    h_m: float
    l_m: float
    theta_rad: float
    trace_m: float
    law_m: float
    relative_difference: float
    relative_difference_quartic: float


def law_checks(*, sizes_m: tuple[float, ...] = (0.02, 0.05, 0.1),
               thetas_rad: tuple[float, ...] = (1e-6, 1e-5, 1e-4, 1e-3)) -> tuple[LawCheck, ...]:
    """Compare the ray trace with ``k θ²`` (and ``k θ² + k4 θ⁴``) over a grid of H, L and θ."""
    out = []
    th = np.asarray(thetas_rad, dtype=float)
    for h in sizes_m:
        for length in sizes_m:
            law = small_angle_law(h_m=h, l_m=length)
            trace = trace_bench(th, h_m=h, l_m=length).path_error_m
            quad = law.path_error_m(th)
            quart = law.path_error_m(th, quartic=True)
            for i, t in enumerate(th):
                out.append(LawCheck(h, length, float(t), float(trace[i]), float(quad[i]),
                                    float(trace[i] / quad[i] - 1.0),
                                    float(trace[i] / quart[i] - 1.0)))
    return tuple(out)


@dataclass(frozen=True)
class GeometryBudget:
    """The beam-path geometry of the bench, ESRF study 4.1, 4.2 and 11.3 recomputed.

    ``path_error_m_per_rad2``: round-trip path per squared Sercalo angle error
    (k); ``measured_error_m_per_rad2``: what the Attocube reports (k/2);
    ``measured_error_m_per_beam_rad2``: per squared beam angle α = 4δθc,
    ``(k/2)/16``; ``seed_11_3_m_per_beam_rad2``: the ESRF study's ``L/2`` (L = 0.1 m).
    """

    h_m: float
    l_m: float
    path_error_m_per_rad2: float
    path_error_m_per_rad4: float
    measured_error_m_per_rad2: float
    measured_error_m_per_beam_rad2: float
    seed_11_3_m_per_beam_rad2: float
    fit: QuadraticLawFit
    table4: AngleErrorTable
    checks: tuple[LawCheck, ...]
    max_check_relative_difference: float
    sercalo_motion: PerpendicularMotion
    newport_motion: PerpendicularMotion
    figure: BeamPathFigure

    def to_json(self) -> dict[str, object]:
        """Plain floats, lists and dicts, SI units; the ESRF study's numbers under ``seed``."""
        out: dict[str, object] = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if hasattr(v, "to_json"):
                out[f.name] = v.to_json()
            elif f.name == "checks":
                out[f.name] = [{g.name: getattr(c, g.name) for g in fields(c)} for c in v]
            else:
                out[f.name] = v
        out["seed"] = dict(SEED_4_1)
        return out


def geometry_budget(params: BenchParams) -> GeometryBudget:
    """ESRF study 4.1, 4.2 and the 11.3 law for the bench's H and L."""
    h, length = params.geometry.h_m, params.geometry.l_m
    law = small_angle_law(h_m=h, l_m=length)
    checks = law_checks()
    beam = float(np.max(np.abs(params.sercalo.beam_angle_per_mirror_angle.as_array())))
    shift = np.array([1e-9, 1e-6])
    return GeometryBudget(
        h_m=h, l_m=length, path_error_m_per_rad2=law.k_m_per_rad2,
        path_error_m_per_rad4=law.k4_m_per_rad4,
        measured_error_m_per_rad2=0.5 * law.k_m_per_rad2,
        measured_error_m_per_beam_rad2=0.5 * law.k_m_per_rad2 / beam**2,
        seed_11_3_m_per_beam_rad2=0.5 * float(SEED_4_1["law_11_3_length_m"]),  # type: ignore[arg-type]
        fit=fit_quadratic_law(h_m=h, l_m=length),
        table4=angle_error_table(h_m=h, l_m=length), checks=checks,
        max_check_relative_difference=max(abs(c.relative_difference) for c in checks
                                          if c.theta_rad <= 1e-4),
        sercalo_motion=perpendicular_motion(shift, mirror="sercalo", h_m=h, l_m=length),
        newport_motion=perpendicular_motion(shift, mirror="newport", h_m=h, l_m=length),
        figure=beam_path_figure_data(h_m=h, l_m=length))
