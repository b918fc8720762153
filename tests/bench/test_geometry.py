"""Beam-path geometry (ESRF study 4.1, 4.2, 11.3): exact ray trace, small-angle law, errata."""

from __future__ import annotations

import dataclasses
import json
import math
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fsmbench.bench import geometry
from fsmbench.bench.geometry import (
    angle_error_table,
    beam_path_figure_data,
    closed_form_path_error,
    esrf_beam_path,
    esrf_theta_range,
    fit_quadratic_law,
    perpendicular_motion,
    small_angle_law,
    tilted_leg_excess,
    trace_bench,
)

SIZES = (0.02, 0.05, 0.1)
GEOMETRIES = [(h, length) for h in SIZES for length in SIZES]
SEED_H = SEED_L = 0.05


# ---------------------------------------------------------------- an independent naive tracer
def _naive_trace(theta: float, h: float, length: float, alpha: float, dc: float, dn: float):
    """Textbook Cartesian trace (d − 2(d·n)n, t = (q−p)·n / d·n), no precision tricks."""

    def hit(p, d, q, n):
        t = np.dot(q - p, n) / np.dot(d, n)
        return p + t * d, t

    def reflect(d, n):
        return d - 2 * np.dot(d, n) * n

    beta = math.pi / 4 - theta
    ns = np.array([-math.sin(beta), math.cos(beta)])
    nn = np.array([math.sin(alpha), -math.cos(alpha)])
    qs, qn = dc * ns, np.array([0.0, h]) + dn * nn
    o, d = np.array([-length, 0.0]), np.array([1.0, 0.0])
    s, t1 = hit(o, d, qs, ns)
    d = reflect(d, ns)
    y, t2 = hit(s, d, qn, nn)
    d = reflect(d, nn)
    m, t3 = hit(y, d, qs, ns)
    d = reflect(d, ns)
    t, t4 = hit(m, d, o, np.array([1.0, 0.0]))
    return (s, y, m, t), t1 + t2 + t3 + t4


@pytest.mark.parametrize("theta", [1e-3, 0.01, 0.05, -0.02])
@pytest.mark.parametrize(
    ("alpha", "dc", "dn"),
    [(0.0, 0.0, 0.0), (0.01, 0.0, 0.0), (0.0, 1e-3, 0.0), (-0.02, 2e-3, -1e-3)],
)
def test_trace_matches_an_independent_naive_tracer(theta, alpha, dc, dn) -> None:
    """Newport rotation and both translations, at angles where float64 cancellation is harmless."""
    h, length = 0.05, 0.08
    pts, path = _naive_trace(theta, h, length, alpha, dc, dn)
    bp = trace_bench(theta, h_m=h, l_m=length, newport_angle_rad=alpha,
                     sercalo_shift_m=dc, newport_shift_m=dn)
    for got, want in zip((bp.S, bp.Y, bp.M, bp.T), pts, strict=True):
        # A few ulp of the 0.1 m geometry in the naive trace: 1e-15 m.
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-15)
    # Naive path sums four ~0.05 m lengths: absolute rounding ~1e-16 m.
    assert float(bp.path_length_m) == pytest.approx(path, rel=0, abs=1e-15)


# ---------------------------------------------------------------- the seed's closed forms
@pytest.mark.parametrize(("h", "length"), GEOMETRIES)
def test_trace_reproduces_seed_closed_form_points(h, length) -> None:
    """ESRF study 4.1 formulas for Y, M, T agree with the trace (relative to each point's size)."""
    theta = np.concatenate([esrf_theta_range(), [1e-3, 1e-2, math.radians(2.0)]])
    bp = trace_bench(theta, h_m=h, l_m=length)
    seed = esrf_beam_path(theta, h_m=h, l_m=length)
    for name in ("Y", "M", "T"):
        got, want = getattr(bp, name), getattr(seed, name)
        scale = np.linalg.norm(want, axis=-1)
        err = np.linalg.norm(got - want, axis=-1) / scale
        # Both are exact in float64; 1e-12 leaves three decades for trig rounding.
        # M is compared with |M| ~ 4Hθ (2e-8 m at 1e-7 rad): a plain trace fails this.
        assert err.max() < 1e-12, name


@pytest.mark.parametrize(("h", "length"), GEOMETRIES)
def test_seed_path_error_only_differs_by_its_float_floor(h, length) -> None:
    """The study's norm-sum path error equals the trace up to float64 rounding of a 0.4 m sum."""
    theta = esrf_theta_range()
    bp = trace_bench(theta, h_m=h, l_m=length)
    seed = esrf_beam_path(theta, h_m=h, l_m=length)
    # Four norms of ≤0.1 m plus the subtraction: ≤ 8 ulp(0.4 m) ≈ 4e-16 m.
    np.testing.assert_allclose(seed.path_error_m, bp.path_error_m, rtol=0, atol=4e-16)


# ---------------------------------------------------------------- exactness and the law
@pytest.mark.parametrize(("h", "length"), GEOMETRIES)
def test_trace_path_error_equals_derived_closed_form(h, length) -> None:
    theta = np.concatenate([esrf_theta_range(), [1e-3, 0.01, 0.1, 0.3]])
    bp = trace_bench(theta, h_m=h, l_m=length)
    exact = closed_form_path_error(theta, h_m=h, l_m=length)
    # Rounding left in the trace: ~1e-23 m on ±4Hθ terms → < 1e-9 relative at 1e-7 rad.
    np.testing.assert_allclose(bp.path_error_m, exact, rtol=1e-8, atol=0)


def _series(n_terms: int = 8):
    """Taylor coefficients of P(θ) − 2(L+H) per unit H and per unit L, in exact rationals."""

    def mul(a, b):
        c = [Fraction(0)] * n_terms
        for i, ai in enumerate(a):
            for j in range(n_terms - i):
                c[i + j] += ai * b[j]
        return c

    def inv(a):
        b = [Fraction(0)] * n_terms
        b[0] = 1 / a[0]
        for n in range(1, n_terms):
            b[n] = -sum(a[k] * b[n - k] for k in range(1, n + 1)) / a[0]
        return b

    def trig(w, odd):
        return [Fraction((-1) ** ((n - odd) // 2) * w**n, math.factorial(n)) if n % 2 == odd
                else Fraction(0) for n in range(n_terms)]

    def lin(*terms):
        return [sum(c * t[i] for c, t in terms) for i in range(n_terms)]

    one = [Fraction(1)] + [Fraction(0)] * (n_terms - 1)
    s, c2, c4 = trig(2, 1), trig(2, 0), trig(4, 0)
    one_2s, one_s = lin((1, one), (2, s)), lin((1, one), (-1, s))
    per_h = lin((1, inv(c2)), (1, inv(mul(one_2s, c2))),
                (2, mul(mul(s, c2), inv(mul(mul(one_s, one_2s), c4)))), (-2, one))
    per_l = lin((1, inv(c4)), (-1, one))
    return per_h, per_l


def test_small_angle_coefficients_are_the_exact_series_of_the_closed_form() -> None:
    """k = 12H + 8L and k4 = 76H + 160L/3; every odd order vanishes (P is even)."""
    per_h, per_l = _series()
    assert per_h[2] == 12 and per_l[2] == 8
    assert per_h[4] == 76 and per_l[4] == Fraction(160, 3)
    assert all(per_h[n] == 0 and per_l[n] == 0 for n in (0, 1, 3, 5, 7))
    law = small_angle_law(h_m=0.03, l_m=0.07)
    assert law.k_m_per_rad2 == pytest.approx(12 * 0.03 + 8 * 0.07, rel=1e-15)  # float rounding
    assert law.k4_m_per_rad4 == pytest.approx(76 * 0.03 + 160 * 0.07 / 3, rel=1e-15)


@pytest.mark.parametrize(("h", "length"), GEOMETRIES)
@pytest.mark.parametrize("theta", [1e-7, 1e-6, 1e-5, 1e-4, 1e-3, 3e-3])
def test_quadratic_law_against_trace(h, length, theta) -> None:
    law = small_angle_law(h_m=h, l_m=length)
    got = float(trace_bench(theta, h_m=h, l_m=length).path_error_m)
    rel = abs(got / float(law.path_error_m(theta)) - 1)
    # Next term k4·θ⁴ (×1.01 for the θ⁶ tail) plus the trace's rounding (< 1e-9 at 1e-7).
    assert rel <= 1.01 * float(law.relative_truncation(theta)) + 1e-9
    # With the quartic term the residual is k6·θ⁶, k6 = 2456H/5 + 15616L/45 (exact series).
    per_h, per_l = _series()
    k6 = float(per_h[6]) * h + float(per_l[6]) * length
    quartic = float(law.path_error_m(theta, quartic=True))
    assert abs(got - quartic) <= 1.01 * k6 * theta**6 + 1e-9 * got  # θ⁸ tail and rounding


@pytest.mark.parametrize("theta", [1e-6, 1e-3, 0.05])
def test_path_error_is_even_in_theta(theta) -> None:
    pos = trace_bench(theta, h_m=0.03, l_m=0.09).path_error_m
    neg = trace_bench(-theta, h_m=0.03, l_m=0.09).path_error_m
    assert float(neg) == pytest.approx(float(pos), rel=1e-9)  # trace rounding, see above


def test_measured_error_is_half_the_round_trip() -> None:
    bp = trace_bench([1e-6, 1e-5], h_m=SEED_H, l_m=SEED_L)
    np.testing.assert_array_equal(bp.measured_error_m, 0.5 * bp.path_error_m)
    law = small_angle_law(h_m=SEED_H, l_m=SEED_L)
    assert law.to_json()["measured_k_m_per_rad2"] == pytest.approx(0.5)  # (6H + 4L) = 0.5 m


def test_fit_over_the_seed_range() -> None:
    """ESRF study Fig. 34: quadratic over logspace(-7, -4, 100); k = 1.0 m/rad² for H = L = 5 cm."""
    fit = fit_quadratic_law(h_m=SEED_H, l_m=SEED_L)
    assert fit.n_points == 100
    assert fit.k_derived_m_per_rad2 == pytest.approx(1.0, rel=1e-15)
    # The fit can only sit above k by the mean quartic term, (k4/k)·mean(θ²) ≈ 5e-9.
    mean_quartic = float(np.mean(small_angle_law(h_m=SEED_H, l_m=SEED_L)
                                 .relative_truncation(esrf_theta_range())))
    assert 0 <= fit.relative_difference <= 1.01 * mean_quartic + 1e-10  # + trace rounding
    assert fit.max_relative_residual < 1e-7  # largest quartic term, 6.5e-8 at 1e-4 rad
    assert fit.loglog_slope == pytest.approx(2.0, abs=1e-7)  # quartic bends the slope by ~4e-9
    assert fit.measured_k_fit_m_per_rad2 == pytest.approx(0.5, rel=1e-7)


def test_table_4_recomputed_and_the_seed_unit_slip() -> None:
    """ESRF study Table 4 says 1, 25, 100 nm for 1, 5, 10 µrad; the law gives pm (×1e-3)."""
    table = angle_error_table(h_m=SEED_H, l_m=SEED_L)
    expected_path_m = np.array([1e-12, 25e-12, 100e-12])
    np.testing.assert_allclose(table.path_error_m, expected_path_m, rtol=1e-9)  # quartic ≤ 6.5e-10
    np.testing.assert_allclose(table.measured_error_m, expected_path_m / 2, rtol=1e-9)
    seed_table_m = np.array([1e-9, 25e-9, 100e-9])
    # The seed's eq. (8) evaluated in nm instead of m: off by exactly 1000 on the path.
    np.testing.assert_allclose(seed_table_m / table.path_error_m, 1000.0, rtol=1e-9)


def test_return_beam_is_tilted_by_four_theta_and_11_3_law() -> None:
    """Two reflections on the Sercalo: return beam at 4θ; its leg obeys the study's L/cos α − L."""
    theta = np.array([1e-3, 1e-2, 0.1])
    bp = trace_bench(theta, h_m=SEED_H, l_m=SEED_L)
    np.testing.assert_allclose(bp.return_angle_rad, 4 * theta, rtol=1e-14)  # exact angle sums
    m_to_t = bp.segment_lengths_m[..., 3]
    leg = SEED_L + bp.M[..., 0]  # horizontal extent of the tilted return leg
    # m_to_t − leg subtracts two ~0.05 m numbers: eps·0.05 / (0.8·θ²·0.05) ≤ 3e-10 at 1e-3.
    np.testing.assert_allclose(m_to_t - leg, tilted_leg_excess(4 * theta, length_m=1.0) * leg,
                               rtol=1e-9)
    # 11.3 with L = 0.1 m and α = 4θ: 0.05·α² = 0.8θ² vs measured (6H+4L)θ² = 0.5θ² (×1.6).
    seed_11_3 = tilted_leg_excess(4e-6, length_m=0.1)
    measured = float(trace_bench(1e-6, h_m=SEED_H, l_m=SEED_L).measured_error_m)
    assert seed_11_3 / measured == pytest.approx(1.6, rel=1e-6)  # θ² corrections at 1e-6 rad


@pytest.mark.parametrize("alpha", [1e-3, 0.01, -0.02])
def test_newport_rotation_with_tracking(alpha) -> None:
    """Sercalo at −α/2 retro-reflects; the tracking residual δ still costs k·δ², no linear term."""
    delta = np.array([-1e-5, 0.0, 1e-5])
    bp = trace_bench(-alpha / 2 + delta, h_m=SEED_H, l_m=SEED_L, newport_angle_rad=alpha)
    # At tracking the path is 2(L + H cos α): the Newport's own cosine term.
    assert float(bp.path_error_m[1]) == pytest.approx(-2 * SEED_H * (1 - math.cos(alpha)), rel=1e-9)
    assert float(bp.return_angle_rad[1]) == pytest.approx(0.0, abs=1e-18)  # exact angle sum
    excess = bp.path_error_m - bp.path_error_m[1]
    k = small_angle_law(h_m=SEED_H, l_m=SEED_L).k_m_per_rad2
    np.testing.assert_allclose(excess[[0, 2]], k * 1e-10, rtol=1e-3)  # α-dependent θ² terms
    assert abs(excess[2] - excess[0]) < 1e-6 * excess[2]  # no first-order term


# ---------------------------------------------------------------- perpendicular motion (4.2)
@pytest.mark.parametrize(
    ("mirror", "per_shift"), [("sercalo", -2 * math.sqrt(2)), ("newport", -2.0)]
)
def test_perpendicular_motion_closed_form(mirror, per_shift) -> None:
    shift = np.array([1e-9, -5e-8, 1e-6])
    pm = perpendicular_motion(shift, mirror=mirror, h_m=SEED_H, l_m=SEED_L)
    assert pm.path_per_shift == pytest.approx(per_shift, rel=1e-15)  # cos 45° rounding
    # Excess terms are ~shift·1: rounding ≈ eps·|shift|.
    np.testing.assert_allclose(pm.path_change_m, pm.closed_form_m, rtol=1e-12)
    np.testing.assert_allclose(pm.path_change_m, per_shift * shift, rtol=1e-12)
    np.testing.assert_allclose(pm.measured_change_m, per_shift * shift / 2, rtol=1e-12)
    assert pm.reflections == (2 if mirror == "sercalo" else 1)


def test_seed_eqs_9_10_hold_for_the_newport_only() -> None:
    """Seed: δL = 2δd for both mirrors. The Sercalo, hit twice at 45°, gives 2√2·δd."""
    serc = perpendicular_motion(1e-9, mirror="sercalo", h_m=SEED_H, l_m=SEED_L)
    newp = perpendicular_motion(1e-9, mirror="newport", h_m=SEED_H, l_m=SEED_L)
    assert abs(float(newp.path_change_m)) == pytest.approx(2e-9, rel=1e-12)
    assert abs(float(serc.path_change_m)) / 2e-9 == pytest.approx(math.sqrt(2), rel=1e-12)


@pytest.mark.parametrize("theta", [1e-4, 1e-3, 0.01])
def test_perpendicular_motion_away_from_nominal(theta) -> None:
    h, length, shift = 0.04, 0.06, 1e-7
    newp = perpendicular_motion(shift, mirror="newport", h_m=h, l_m=length, theta_rad=theta)
    # Moving the flat Newport is H → H − δd, and P is linear in H: −δd·∂P/∂H exactly.
    s, c4 = math.sin(2 * theta), math.cos(4 * theta)
    h_part = float(closed_form_path_error(theta, h_m=h, l_m=length)) - 2 * length * s**2 / c4
    assert float(newp.path_change_m) == pytest.approx(-shift * (2 + h_part / h), rel=1e-9)
    serc = perpendicular_motion(shift, mirror="sercalo", h_m=h, l_m=length, theta_rad=theta)
    for pm in (newp, serc):
        rel = abs(float(pm.path_change_m) / float(pm.closed_form_m) - 1)
        # Closed form exact at θ = 0, path even in θ: O(θ²); the Newport's is exactly 8θ².
        assert rel <= 10 * theta**2


# ---------------------------------------------------------------- API behaviour
def test_vectorised_shapes_and_broadcasting() -> None:
    theta = np.full((3, 4), 1e-5)
    alpha = np.linspace(0, 1e-3, 4)
    bp = trace_bench(theta, h_m=0.05, l_m=0.05, newport_angle_rad=alpha)
    assert bp.path_error_m.shape == (3, 4)
    assert bp.M.shape == (3, 4, 2)
    assert bp.segment_lengths_m.shape == (3, 4, 4)
    for j, a in enumerate(alpha):  # same as one-at-a-time
        one = trace_bench(1e-5, h_m=0.05, l_m=0.05, newport_angle_rad=a)
        # SIMD and scalar libm may differ by an ulp; the ±4Hθ cancellation turns that into
        # eps·4H/(kθ) ≈ 4e-12 relative at 1e-5 rad.
        assert float(bp.path_error_m[1, j]) == pytest.approx(float(one.path_error_m), rel=1e-10)


def test_beam_missing_the_attocube_plane_is_nan() -> None:
    # θ = −0.2 rad: M falls beyond x = −L, so the return leg would run backwards.
    bp = trace_bench([1e-3, -0.2], h_m=0.05, l_m=0.05)
    assert np.isfinite(bp.path_error_m[0]) and np.isnan(bp.path_error_m[1])


def test_results_are_frozen_and_json_plain() -> None:
    bp = trace_bench([1e-6, 2e-6], h_m=0.05, l_m=0.05)
    with pytest.raises(dataclasses.FrozenInstanceError):
        bp.h_m = 1.0  # type: ignore[misc]
    with pytest.raises(ValueError, match="read-only"):
        bp.path_error_m[0] = 0.0
    for obj in (bp, fit_quadratic_law(h_m=0.05, l_m=0.05), small_angle_law(h_m=0.05, l_m=0.05),
                angle_error_table(h_m=0.05, l_m=0.05),
                perpendicular_motion([1e-9], mirror="sercalo", h_m=0.05, l_m=0.05),
                beam_path_figure_data(h_m=0.05, l_m=0.05)):
        data = obj.to_json()
        assert json.loads(json.dumps(data)) == data


def test_figure_data_at_two_degrees() -> None:
    """ESRF study Fig. 35: θ = 2°; the polyline is the ESRF study's O, S, Y, M, T."""
    fig = beam_path_figure_data(math.radians(2.0), h_m=0.05, l_m=0.05)
    seed = esrf_beam_path(math.radians(2.0), h_m=0.05, l_m=0.05)
    want = np.stack([seed.O, seed.S, seed.Y, seed.M, seed.T])
    np.testing.assert_allclose(fig.beam, want, rtol=0, atol=1e-15)  # a few ulp of 0.05 m
    assert fig.beam.shape == (5, 2) and fig.labels == ("O", "S", "Y", "M", "T")
    assert fig.nominal_beam[2].tolist() == [0.0, 0.05]
    assert np.all(fig.attocube_plane[:, 0] == -0.05)


@pytest.mark.parametrize("bad", [0.0, -0.05, float("nan"), float("inf")])
def test_bad_lengths_are_rejected(bad) -> None:
    with pytest.raises(ValueError, match="h_m"):
        trace_bench(1e-6, h_m=bad, l_m=0.05)
    with pytest.raises(ValueError, match="l_m"):
        small_angle_law(h_m=0.05, l_m=bad)


def test_seed_formula_needs_nonzero_angle_and_mirror_name_is_checked() -> None:
    with pytest.raises(ValueError, match="non-zero"):
        esrf_beam_path([0.0, 1e-6], h_m=0.05, l_m=0.05)
    with pytest.raises(ValueError, match="mirror"):
        perpendicular_motion(1e-9, mirror="attocube", h_m=0.05, l_m=0.05)  # type: ignore[arg-type]


@settings(max_examples=25, deadline=None)
@given(st.integers(min_value=1, max_value=3 * geometry._BLOCK + 7),
       st.sampled_from([(), (2,), (3,)]))
def test_the_path_error_of_a_record_in_blocks_is_the_whole_expression(
        n: int, trailing: tuple[int, ...]) -> None:
    """A long record is evaluated in blocks (cache-sized temporaries): the same arithmetic
    on every element, so the same bits as one expression, whatever the shape."""
    theta = 1e-4 * np.random.default_rng(n).standard_normal((n, *trailing))
    blocks = closed_form_path_error(theta, h_m=0.12, l_m=0.45)
    assert blocks.shape == theta.shape
    np.testing.assert_array_equal(blocks, geometry._path_error(theta, 0.12, 0.45))
