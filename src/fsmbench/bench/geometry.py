"""Beam path of the Attocube measurement: an exact 2-D ray trace (ESRF study 4.1, 4.2, 11.3).

Geometry (ESRF study 4.1, Fig. 33). The Attocube reference surface is the plane
``x = -L`` through ``O = (-L, 0)``. The beam leaves ``O`` along ``+x``, hits
the Sercalo mirror at ``S = (0, 0)`` (nominally at 45°), goes up to the Newport
mirror at ``X = (0, H)`` (flat, perpendicular to the beam), comes back to the
Sercalo and returns to the plane ``x = -L``. With a Sercalo angle error
``δθc`` (mirror line at ``π/4 - δθc``, the ESRF study's sign) the beam goes
``O → S → Y → M → T`` and the round-trip path is
``|S-O| + |Y-S| + |M-Y| + |T-M|``; the path error is that minus ``2(L + H)``.

The tracer
----------
Rays are a point and a unit direction (complex numbers), mirrors and the
Attocube plane are lines through a pivot with a normal, reflection is
specular; nothing is linearised. At 1e-7 rad the path error is 1e-14 m on a
0.2 m path, so a plain ``path − 2(L+H)`` in float64 (the ESRF study's MATLAB code)
is off by ~1e-16 m, 0.5 %. Here everything is *nominal + deviation*: the
nominal bench is axis-aligned (exact), directions are ``i**q·exp(i·dev)``
(quarter turns are exact) and each segment's length change is computed from
small quantities only; what rounding is left (~1e-23 m, in the ±4Hθ terms
that cancel, below) is < 1e-9 relative over the ESRF study's range.

Derivation of the small-angle law (flat Newport, no translation)
-----------------------------------------------------------------
Reflection on a line at angle β maps a direction at angle φ to ``2β − φ``.
With the Sercalo at ``π/4 − θ`` (θ = δθc) the beam leaves S at ``π/2 − 2θ``
(2θ from the Newport normal), comes back at ``−π/2 + 2θ`` and leaves M at
``π − 4θ``: the returning beam is tilted by **4θ** (two reflections on a
mirror turned by θ). With ``s = sin 2θ``, ``c2 = cos 2θ``, ``c4 = cos 4θ``:

* ``|Y − S| = H / c2``,
* M is on the Sercalo line ``y = x·tan(π/4 − θ)`` and on the returning ray
  ``y = 2H − x·cot 2θ``; using ``tan(π/4 − θ) = (1 − s)/c2`` and
  ``cos 4θ = 1 − 2s²``: ``H − M_y = H/(1 + 2s)``,
  ``M_x = H·sin 4θ / ((1 − s)(1 + 2s))``,
* ``|M − Y| = (H − M_y)/c2 = H / ((1 + 2s)·c2)``,
* ``|T − M| = (L + M_x) / c4``.

Hence ``P(θ) = L + H/c2 + H/((1 + 2s)c2) + (L + M_x)/c4``. ``P`` is exactly
even (``P(−θ) − P(θ)`` reduces to ``4Hs/(c2(1 − 4s²)) − 4Hs/(c2(1 − 4s²))``),
and the power series (``sin 2θ = 2θ − 4θ³/3``, ``1/c2 = 1 + 2θ²``,
``1/c4 = 1 + 8θ²`` …) gives term by term

* S→Y: ``+2Hθ²``; Y→M: ``−4Hθ + 18Hθ²``; M→T: ``+4Hθ − 8Hθ² + 8Lθ²``

(the first-order terms cancel because M slides along a 45° mirror), so

    ΔP = P − 2(L + H) = k·θ² + k4·θ⁴ + O(θ⁶),
    k  = 12·H + 8·L            [m/rad²]
    k4 = 76·H + 160·L/3        [m/rad⁴]

(k4 from exact rational power-series arithmetic). The quadratic law's relative
error is ``(k4/k)·θ²`` (6.47·θ² for H = L): 6.5e-8 at the ESRF study's largest angle
1e-4 rad. The Attocube reports half the round-trip change (ESRF study 4.2), so the
*measured* distance error is ``k/2·θ² = (6H + 4L)·θ²``.

For H = L = 0.05 m, ``k = 1.0 m/rad²``: that is why the ESRF study's eq. (8)
``δL = δθc²`` looks right, but the coefficient carries units (m/rad²) and
depends on H and L, and 1 µrad gives 1e-12 m = 1 pm of path (0.5 pm
measured), not the 1 nm of the ESRF study's Table 4.

Relation to ESRF study 11.3 (``ΔL = L/cos α − L ≈ Lα²/2``): that is the excess of
*one straight leg* of length L tilted by α (:func:`tilted_leg_excess`). In
the trace the return leg M→T is tilted by exactly α = 4θ and contributes
``8Lθ² = Lα²/2``; the two H legs add ``12Hθ²``, not ``H·(2θ)²``, because the
second hit point M moves along the mirror. In terms of the returning beam
angle α = 4δθc (what the 4QD sees), the measured error is
``(6H + 4L)/16 · α²`` = 0.031 α² for H = L = 0.05 m, against 0.05 α² from
11.3 with L = 0.1 m.

Perpendicular motion (ESRF study 4.2): translating a mirror by δd along its
reflecting-side normal shortens each reflection's path by ``2δd·cos(i)``
(i the incidence angle). The Sercalo is hit twice at 45°: ``−2√2·δd`` round
trip (``−√2·δd`` measured); the Newport once at normal incidence: ``−2δd``
(``−δd`` measured).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "AngleErrorTable",
    "BeamPath",
    "BeamPathFigure",
    "PerpendicularMotion",
    "QuadraticLawFit",
    "SmallAngleLaw",
    "angle_error_table",
    "beam_path_figure_data",
    "closed_form_path_error",
    "esrf_beam_path",
    "esrf_theta_range",
    "fit_quadratic_law",
    "perpendicular_motion",
    "small_angle_law",
    "tilted_leg_excess",
    "trace_bench",
]

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]

# i**q for q = 0..3: multiplying by these is exact in floating point.
_QUARTER_TURNS = (1.0 + 0.0j, 1.0j, -1.0 + 0.0j, -1.0j)


def esrf_theta_range() -> FloatArray:
    """The ESRF study's Sercalo angle-error range ``logspace(-7, -4, 100)`` [rad], shape (100,)."""
    return np.logspace(-7.0, -4.0, 100)


def _check_length(name: str, value: float) -> float:
    value = float(value)
    if not np.isfinite(value) or value <= 0.0:
        raise ValueError(f"{name} must be a positive finite length in m, got {value!r}")
    return value


def _frozen(a: ArrayLike) -> FloatArray:
    # Results are frozen dataclasses; make their arrays read-only too.
    out = np.array(a, dtype=float)
    out.flags.writeable = False
    return out


def _points(z: ComplexArray) -> FloatArray:
    return _frozen(np.stack([z.real, z.imag], axis=-1))


def _json(a: ArrayLike) -> float | list[float]:
    arr = np.asarray(a, dtype=float)
    return float(arr) if arr.ndim == 0 else list(arr.tolist())


def _to_json(obj: object, **extra: object) -> dict[str, object]:
    """A result dataclass as plain floats, ints, strings and lists (units in the keys)."""
    out: dict[str, object] = {}
    for name in obj.__dataclass_fields__:  # type: ignore[attr-defined]
        v = getattr(obj, name)
        if isinstance(v, np.ndarray):
            out[name] = _json(v)
        elif isinstance(v, tuple):
            out[name] = list(v)
        else:
            out[name] = v
    for name, v in extra.items():
        out[name] = _json(v) if isinstance(v, np.ndarray) else v
    return out


def _cross(a: ArrayLike, b: ArrayLike) -> FloatArray:
    """2-D cross product ``a.x·b.y − a.y·b.x`` of complex-encoded vectors."""
    return np.asarray((np.conj(a) * np.asarray(b)).imag, dtype=float)


@dataclass(frozen=True)
class _Line:
    """A mirror or the Attocube plane: a line through ``pivot`` (its nominal hit point).

    The line's direction is ``exp(i·(eighths·π/4 + tilt))``; it is translated by
    ``shift`` along its reflecting-side normal ``side·i·direction``.
    """

    pivot: complex
    eighths: int
    tilt: FloatArray
    shift: FloatArray
    side: int

    def direction(self) -> ComplexArray:
        return np.exp(1j * (self.eighths * np.pi / 4)) * np.exp(1j * self.tilt)

    def normal(self) -> ComplexArray:
        return self.side * 1j * self.direction()


@dataclass(frozen=True)
class _Ray:
    """Point ``nominal + offset``, direction ``i**quarter · exp(i·dev)``."""

    nominal: complex
    offset: ComplexArray
    quarter: int
    dev: FloatArray


def _propagate(ray: _Ray, line: _Line) -> tuple[_Ray, FloatArray, FloatArray]:
    """Intersect ``ray`` with ``line``: (ray at the hit point, length, length − nominal).

    Solves ``P + t·d = q + s·u`` with cross products. The nominal segment
    ``line.pivot − ray.nominal`` equals ``t0·i**quarter`` exactly, so the
    length change ``t − t0`` only involves small, exactly computed terms.
    """
    turn = _QUARTER_TURNS[ray.quarter % 4]
    d = turn * np.exp(1j * ray.dev)
    d_minus_d0 = turn * np.expm1(1j * ray.dev)  # no cancellation at tiny angles
    u = line.direction()
    nominal_vec = line.pivot - ray.nominal
    t0 = abs(nominal_vec)
    if nominal_vec != t0 * turn:
        raise AssertionError("nominal bench is not axis-aligned along the ray")
    small = line.shift * line.normal() - ray.offset  # (q − q0) − (P − P0)
    denom = _cross(d, u)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = _cross(nominal_vec + small, d) / denom
        excess = _cross(small - t0 * d_minus_d0, u) / denom
    length = t0 + excess
    bad = ~np.isfinite(length) | (length <= 0.0)  # parallel, or the line is behind the ray
    excess, length, s = (np.where(bad, np.nan, a) for a in (excess, length, s))
    hit = _Ray(line.pivot, line.shift * line.normal() + s * u, ray.quarter, ray.dev)
    return hit, length, excess


def _reflect(ray: _Ray, line: _Line) -> _Ray:
    # Reflection on a line at angle β maps direction angle φ to 2β − φ.
    return _Ray(ray.nominal, ray.offset, line.eighths - ray.quarter, 2.0 * line.tilt - ray.dev)


@dataclass(frozen=True)
class BeamPath:
    """Points and length of the Attocube beam path for each input (ESRF study 4.1, Fig. 33).

    Arrays have the broadcast shape ``(...)`` of the inputs; points have shape
    ``(..., 2)`` holding (x, y) in m. ``path_error_m`` is the round-trip change;
    :attr:`measured_error_m` is what the Attocube reports (half of it).
    """

    h_m: float
    l_m: float
    theta_rad: FloatArray
    newport_angle_rad: FloatArray
    sercalo_shift_m: FloatArray
    newport_shift_m: FloatArray
    O: FloatArray  # noqa: E741 - the seed's point names are kept on purpose
    S: FloatArray
    Y: FloatArray
    M: FloatArray
    T: FloatArray
    segment_lengths_m: FloatArray
    path_length_m: FloatArray
    path_error_m: FloatArray
    return_angle_rad: FloatArray

    @property
    def nominal_path_m(self) -> float:
        """Nominal round-trip path ``2(L + H)`` [m]."""
        return 2.0 * (self.l_m + self.h_m)

    @property
    def measured_error_m(self) -> FloatArray:
        """Distance error the Attocube reports: half the round-trip change [m] (ESRF study 4.2)."""
        return _frozen(0.5 * self.path_error_m)

    def to_json(self) -> dict[str, object]:
        """Plain floats and lists, units in the keys."""
        return _to_json(
            self, measured_error_m=self.measured_error_m, nominal_path_m=self.nominal_path_m
        )


def trace_bench(
    theta_rad: ArrayLike,
    *,
    h_m: float,
    l_m: float,
    newport_angle_rad: ArrayLike = 0.0,
    sercalo_shift_m: ArrayLike = 0.0,
    newport_shift_m: ArrayLike = 0.0,
) -> BeamPath:
    """Trace O → Sercalo → Newport → Sercalo → Attocube plane, exactly.

    Parameters
    ----------
    theta_rad : array_like, shape (...)
        Sercalo angle error δθc [rad] about S; positive turns the mirror line
        to ``π/4 − δθc`` (the ESRF study's sign: Y moves to ``x > 0``).
    h_m, l_m : float
        H (Sercalo to Newport) and L (Attocube plane to Sercalo) [m].
    newport_angle_rad : array_like, broadcastable
        Newport rotation about X [rad], counter-clockwise positive.
    sercalo_shift_m, newport_shift_m : array_like, broadcastable
        Mirror translation along its reflecting-side normal [m] (towards the
        incoming beam: positive shortens the path).

    Returns
    -------
    BeamPath
        Hit points, segment lengths, round-trip path and its change, and the
        angle of the returning beam to ``−x`` (positive towards ``+y``).
        Entries whose beam misses a line (parallel or behind) are NaN.
    """
    h = _check_length("h_m", h_m)
    length = _check_length("l_m", l_m)
    theta, alpha, dc, dn = (
        np.array(a, dtype=float)
        for a in np.broadcast_arrays(theta_rad, newport_angle_rad, sercalo_shift_m, newport_shift_m)
    )
    zero = np.zeros_like(theta)
    sercalo = _Line(0j, 1, -theta, dc, +1)  # y = x at 45°, reflecting side up-left
    newport = _Line(1j * h, 0, alpha, dn, -1)  # y = H, reflecting side down
    attocube = _Line(-length + 0j, 2, zero, zero, +1)  # x = −L

    ray = _Ray(-length + 0j, zero.astype(complex), 0, zero)
    hits, lengths, excesses = [], [], []
    for line in (sercalo, newport, sercalo, attocube):
        ray, seg, excess = _propagate(ray, line)
        hits.append(_points(ray.nominal + ray.offset))
        lengths.append(seg)
        excesses.append(excess)
        if line is not attocube:
            ray = _reflect(ray, line)
    # The first-order length changes of Y→M and M→T cancel; summing the
    # excesses (not the lengths) keeps the second-order result exact.
    path_error = excesses[0] + excesses[1] + excesses[2] + excesses[3]
    return BeamPath(
        h_m=h, l_m=length, theta_rad=_frozen(theta), newport_angle_rad=_frozen(alpha),
        sercalo_shift_m=_frozen(dc), newport_shift_m=_frozen(dn),
        O=_points(np.full_like(theta, -length, dtype=complex)),
        S=hits[0], Y=hits[1], M=hits[2], T=hits[3],
        segment_lengths_m=_frozen(np.stack(lengths, axis=-1)),
        path_length_m=_frozen(2.0 * (length + h) + path_error),
        path_error_m=_frozen(path_error),
        # The final direction is −exp(i·dev): its angle above −x is −dev.
        return_angle_rad=_frozen(-ray.dev),
    )


def esrf_beam_path(theta_rad: ArrayLike, *, h_m: float, l_m: float) -> BeamPath:
    """The ESRF study's closed-form points Y, M, T (4.1 MATLAB code), for comparison.

    Same formulas and the same ``norm`` sum as the ESRF study; ``theta_rad`` must be
    non-zero (the ESRF study divides by ``tan(2θ)``). The return angle is the ESRF study's
    assumed ``4θ``.
    """
    h = _check_length("h_m", h_m)
    length = _check_length("l_m", l_m)
    th = np.array(theta_rad, dtype=float)
    if np.any(th == 0.0):
        raise ValueError("esrf_beam_path: theta_rad must be non-zero (the ESRF study divides by "
                         "tan 2θ)")
    one = np.ones_like(th)
    o = np.stack([-length * one, 0.0 * one], axis=-1)
    s = np.zeros_like(o)
    y = np.stack([h * np.tan(2 * th), h * one], axis=-1)
    m_scale = 2 * h / (np.tan(np.pi / 4 - th) + 1 / np.tan(2 * th))
    m = m_scale[..., None] * np.stack([one, np.tan(np.pi / 4 - th)], axis=-1)
    t = np.stack([-length * one, m[..., 1] + (length + m[..., 0]) * np.tan(4 * th)], axis=-1)
    segs = np.stack(
        [np.linalg.norm(b - a, axis=-1) for a, b in ((o, s), (s, y), (y, m), (m, t))], axis=-1
    )
    path = segs.sum(axis=-1)
    zero = np.zeros_like(th)
    return BeamPath(
        h_m=h, l_m=length, theta_rad=_frozen(th), newport_angle_rad=_frozen(zero),
        sercalo_shift_m=_frozen(zero), newport_shift_m=_frozen(zero),
        O=_frozen(o), S=_frozen(s), Y=_frozen(y), M=_frozen(m), T=_frozen(t),
        segment_lengths_m=_frozen(segs), path_length_m=_frozen(path),
        path_error_m=_frozen(path - 2.0 * (length + h)), return_angle_rad=_frozen(4 * th),
    )


def closed_form_path_error(theta_rad: ArrayLike, *, h_m: float, l_m: float) -> FloatArray:
    """Exact round-trip path change ``P(θ) − 2(L + H)`` [m] from the derived closed form.

    The terms are regrouped so that no first-order quantities cancel
    (accurate to ~1e-15 relative at any angle); see the module docstring.
    ``theta_rad`` : array_like of Sercalo angle errors [rad], any shape.
    """
    h = _check_length("h_m", h_m)
    length = _check_length("l_m", l_m)
    th = np.asarray(theta_rad, dtype=float)
    if th.size <= _BLOCK:
        return _path_error(th, h, length)
    # A record's angles (10^6 samples) in blocks: the expression's dozen temporaries then
    # stay in the cache, a third faster; every element's arithmetic is the same.
    flat = th.reshape(-1)
    out = np.empty_like(flat)
    for start in range(0, flat.size, _BLOCK):
        out[start:start + _BLOCK] = _path_error(flat[start:start + _BLOCK], h, length)
    return out.reshape(th.shape)


_BLOCK: Final = 16384  # elements per block of closed_form_path_error (128 kB per temporary)


def _path_error(th: FloatArray, h: float, length: float) -> FloatArray:
    """:func:`closed_form_path_error` of ``th`` [rad] (any shape) for checked H, L [m]."""
    s, c2, c4 = np.sin(2 * th), np.cos(2 * th), np.cos(4 * th)
    sin2 = np.sin(th) ** 2
    legs_tilt = 2 * h * sin2 / c2 + 2 * h * sin2 / ((1 + 2 * s) * c2) + 2 * length * s**2 / c4
    # −2Hs/(1+2s) (Y→M shortening) + M_x/c4 (M→T lengthening), combined:
    slide = (2 * h * s / (1 + 2 * s)) * (2 * np.sin(3 * th) * np.sin(th) + s * c4) / ((1 - s) * c4)
    return np.asarray(legs_tilt + slide, dtype=float)


def tilted_leg_excess(alpha_rad: ArrayLike, *, length_m: float) -> FloatArray:
    """ESRF study 11.3 law, exact: ``L/cos α − L`` [m] for a straight leg tilted by α [rad]."""
    length = _check_length("length_m", length_m)
    a = np.asarray(alpha_rad, dtype=float)
    return np.asarray(2 * length * np.sin(a / 2) ** 2 / np.cos(a), dtype=float)


@dataclass(frozen=True)
class SmallAngleLaw:
    """``ΔP ≈ k·θ² + k4·θ⁴`` for the round-trip path; the Attocube reports half."""

    h_m: float
    l_m: float
    k_m_per_rad2: float
    k4_m_per_rad4: float

    def path_error_m(self, theta_rad: ArrayLike, *, quartic: bool = False) -> FloatArray:
        """Round-trip path change [m] for Sercalo angle errors ``theta_rad`` [rad], any shape."""
        th2 = np.asarray(theta_rad, dtype=float) ** 2
        out = self.k_m_per_rad2 * th2 + (self.k4_m_per_rad4 * th2**2 if quartic else 0.0)
        return np.asarray(out, dtype=float)

    def measured_error_m(self, theta_rad: ArrayLike, *, quartic: bool = False) -> FloatArray:
        """Distance error the Attocube reports [m]: half the round-trip change."""
        return 0.5 * self.path_error_m(theta_rad, quartic=quartic)

    def relative_truncation(self, theta_rad: ArrayLike) -> FloatArray:
        """Relative error of the quadratic law, ``(k4/k)·θ²`` (leading term)."""
        th = np.asarray(theta_rad, dtype=float)
        return np.asarray(self.k4_m_per_rad4 / self.k_m_per_rad2 * th**2, dtype=float)

    def to_json(self) -> dict[str, object]:
        """Plain floats, units in the keys."""
        return _to_json(self, measured_k_m_per_rad2=0.5 * self.k_m_per_rad2)


def small_angle_law(*, h_m: float, l_m: float) -> SmallAngleLaw:
    """Derived coefficients ``k = 12H + 8L`` [m/rad²] and ``k4 = 76H + 160L/3`` [m/rad⁴]."""
    h = _check_length("h_m", h_m)
    length = _check_length("l_m", l_m)
    return SmallAngleLaw(h, length, 12.0 * h + 8.0 * length, 76.0 * h + 160.0 * length / 3.0)


@dataclass(frozen=True)
class QuadraticLawFit:
    """Least-squares fit ``ΔP = k_fit·θ²`` to the ray trace (ESRF study Fig. 34)."""

    h_m: float
    l_m: float
    theta_min_rad: float
    theta_max_rad: float
    n_points: int
    k_fit_m_per_rad2: float
    k_derived_m_per_rad2: float
    relative_difference: float
    max_relative_residual: float
    loglog_slope: float

    @property
    def measured_k_fit_m_per_rad2(self) -> float:
        """Coefficient of the distance the Attocube reports (half the round trip)."""
        return 0.5 * self.k_fit_m_per_rad2

    def to_json(self) -> dict[str, object]:
        """Plain floats, units in the keys."""
        return _to_json(self, measured_k_fit_m_per_rad2=self.measured_k_fit_m_per_rad2)


def fit_quadratic_law(
    theta_rad: ArrayLike | None = None, *, h_m: float, l_m: float
) -> QuadraticLawFit:
    """Fit ``ΔP = k·θ²`` to the ray trace over ``theta_rad`` (default: the ESRF study's range).

    Each point is weighted by ``1/θ²`` (a fit of ``ΔP/θ²``), i.e. equal
    relative weight across the four decades; the trace is exact enough for it.
    ``theta_rad`` : array_like, shape (n,), non-zero Sercalo angle errors [rad].
    """
    th = esrf_theta_range() if theta_rad is None else np.asarray(theta_rad, dtype=float).ravel()
    if th.size < 2 or np.any(th == 0.0):
        raise ValueError("fit_quadratic_law needs at least two non-zero angles")
    path = trace_bench(th, h_m=h_m, l_m=l_m)
    ratio = path.path_error_m / th**2
    k_fit = float(np.mean(ratio))
    law = small_angle_law(h_m=h_m, l_m=l_m)
    slope = float(np.polyfit(np.log(np.abs(th)), np.log(path.path_error_m), 1)[0])
    return QuadraticLawFit(
        h_m=path.h_m, l_m=path.l_m, theta_min_rad=float(np.min(np.abs(th))),
        theta_max_rad=float(np.max(np.abs(th))), n_points=int(th.size), k_fit_m_per_rad2=k_fit,
        k_derived_m_per_rad2=law.k_m_per_rad2, relative_difference=k_fit / law.k_m_per_rad2 - 1,
        max_relative_residual=float(np.max(np.abs(ratio / k_fit - 1.0))), loglog_slope=slope,
    )


@dataclass(frozen=True)
class AngleErrorTable:
    """ESRF study Table 4 recomputed: path and measured error for given Sercalo angle errors."""

    h_m: float
    l_m: float
    theta_rad: FloatArray
    path_error_m: FloatArray
    measured_error_m: FloatArray
    law_path_error_m: FloatArray

    def to_json(self) -> dict[str, object]:
        """Plain floats and lists, units in the keys."""
        return _to_json(self)


def angle_error_table(
    theta_rad: ArrayLike = (1e-6, 5e-6, 10e-6), *, h_m: float, l_m: float
) -> AngleErrorTable:
    """ESRF study Table 4 from the ray trace; default angles are the ESRF study's 1, 5, 10 µrad.

    ``theta_rad`` : array_like, shape (n,) [rad]. Errors are in m.
    """
    th = np.asarray(theta_rad, dtype=float).ravel()
    path = trace_bench(th, h_m=h_m, l_m=l_m)
    law = small_angle_law(h_m=h_m, l_m=l_m)
    return AngleErrorTable(
        h_m=path.h_m, l_m=path.l_m, theta_rad=_frozen(th), path_error_m=path.path_error_m,
        measured_error_m=path.measured_error_m, law_path_error_m=_frozen(law.path_error_m(th)),
    )


@dataclass(frozen=True)
class PerpendicularMotion:
    """Path change for a mirror translated along its normal (ESRF study 4.2, eqs. 9–10)."""

    mirror: str
    shift_m: FloatArray
    theta_rad: float
    reflections: int
    cos_incidence: tuple[float, ...]
    path_change_m: FloatArray
    closed_form_m: FloatArray

    @property
    def measured_change_m(self) -> FloatArray:
        """Distance change the Attocube reports [m]: half the round-trip change."""
        return _frozen(0.5 * self.path_change_m)

    @property
    def path_per_shift(self) -> float:
        """Round-trip path change per unit translation, ``−2·Σ cos(i)`` (ESRF study: 2)."""
        return -2.0 * float(sum(self.cos_incidence))

    def to_json(self) -> dict[str, object]:
        """Plain floats and lists, units in the keys."""
        return _to_json(
            self, measured_change_m=self.measured_change_m, path_per_shift=self.path_per_shift
        )


def perpendicular_motion(
    shift_m: ArrayLike, *, mirror: Literal["sercalo", "newport"], h_m: float, l_m: float,
    theta_rad: float = 0.0,
) -> PerpendicularMotion:
    """Round-trip path change when ``mirror`` moves by ``shift_m`` along its normal.

    Parameters
    ----------
    shift_m : array_like, shape (...)
        Translation towards the incoming beam [m].
    mirror : {"sercalo", "newport"}
        Which mirror moves.
    h_m, l_m : float
        Bench geometry [m].
    theta_rad : float
        Sercalo angle error at which to evaluate [rad]. The closed form
        ``−2·δd·Σ cos(i)`` is exact at 0; the path is even in θ, so away from
        0 it is off by a relative O(θ²) (for the Newport exactly
        ``−δd·∂P/∂H = −δd·(2 + 12θ² + …)`` against ``−2δd·cos 2θ``: 8θ²).
    """
    if mirror not in ("sercalo", "newport"):
        raise ValueError(f"mirror must be 'sercalo' or 'newport', not {mirror!r}")
    shift = np.asarray(shift_m, dtype=float)
    key = "sercalo_shift_m" if mirror == "sercalo" else "newport_shift_m"
    moved = trace_bench(theta_rad, h_m=h_m, l_m=l_m, **{key: shift})
    still = trace_bench(theta_rad, h_m=h_m, l_m=l_m)
    # Incidence angles from the unmoved trace: directions before each hit.
    seg = still.segment_lengths_m
    pts = [still.O, still.S, still.Y, still.M]
    dirs = [(b - a) / n for a, b, n in zip(pts[:-1], pts[1:], seg[:3], strict=True)]
    cos_i: tuple[float, ...]
    if mirror == "sercalo":
        beta = np.pi / 4 - theta_rad  # mirror line angle; the normal is i·u
        normal = np.array([-np.sin(beta), np.cos(beta)])
        cos_i = (abs(float(dirs[0] @ normal)), abs(float(dirs[2] @ normal)))
    else:
        cos_i = (abs(float(dirs[1][1])),)
    change = moved.path_error_m - still.path_error_m
    return PerpendicularMotion(
        mirror=mirror, shift_m=_frozen(shift), theta_rad=float(theta_rad),
        reflections=len(cos_i), cos_incidence=cos_i, path_change_m=_frozen(change),
        closed_form_m=_frozen(-2.0 * shift * sum(cos_i)),
    )


@dataclass(frozen=True)
class BeamPathFigure:
    """Polylines for drawing the beam path (ESRF study Fig. 35), all (x, y) in m."""

    theta_rad: float
    labels: tuple[str, ...]
    beam: FloatArray
    nominal_beam: FloatArray
    sercalo_mirror: FloatArray
    newport_mirror: FloatArray
    attocube_plane: FloatArray

    def to_json(self) -> dict[str, object]:
        """Plain floats and lists, units in the keys."""
        return _to_json(self)


def beam_path_figure_data(
    theta_rad: float = 2 * np.pi / 180, *, h_m: float, l_m: float
) -> BeamPathFigure:
    """Points to plot the traced path at a large angle (ESRF study Fig. 35 uses θ = 2°).

    Returns the beam polyline O, S, Y, M, T (shape (5, 2)), the nominal
    O, S, X, S, O, and segments (shape (2, 2)) for the tilted Sercalo, the
    Newport and the Attocube plane.
    """
    path = trace_bench(float(theta_rad), h_m=h_m, l_m=l_m)
    h, length = path.h_m, path.l_m
    beam = np.stack([path.O, path.S, path.Y, path.M, path.T])
    nominal = np.array([[-length, 0.0], [0.0, 0.0], [0.0, h], [0.0, 0.0], [-length, 0.0]])
    half = 0.3 * min(h, length)
    u = np.array([np.cos(np.pi / 4 - theta_rad), np.sin(np.pi / 4 - theta_rad)])
    ys = np.array([beam[:, 1].min(), beam[:, 1].max()])
    return BeamPathFigure(
        theta_rad=float(theta_rad), labels=("O", "S", "Y", "M", "T"), beam=_frozen(beam),
        nominal_beam=_frozen(nominal), sercalo_mirror=_frozen(np.stack([-half * u, half * u])),
        newport_mirror=_frozen([[-half, h], [half, h]]),
        attocube_plane=_frozen([[-length, ys[0] - half], [-length, ys[1] + half]]),
    )
