"""Vector fitting: exact recovery, weights, scaling, stability, noise, realisation, bad input."""

from __future__ import annotations

import dataclasses
import json

import control
import numpy as np
import pytest

from fsmbench.ident.fit.vectfit import Mode, VectorFit, VectorFitOptions, vector_fit

F_HZ = np.arange(1.0, 5001.0)  # the seed's 1 Hz Welch grid, 1 Hz .. 5 kHz
ZETA = 1e-3
MODES_HZ = (250.0, 411.0)


def reference(p: int = 2, m: int = 2, *, unstable: bool = False, seed: int = 7
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Known p x m model: modes at 250 and 411 Hz (zeta 1e-3), a real pole at 80 Hz, and D.

    Returns poles (rad/s, pairs adjacent), residues (5, p, m), D (p, m).
    """
    rng = np.random.default_rng(seed)
    poles, residues = [], []
    for f0 in MODES_HZ:
        w = 2.0 * np.pi * f0
        a = complex(-ZETA * w, w * np.sqrt(1.0 - ZETA**2))
        if unstable and f0 == MODES_HZ[1]:
            a = complex(-a.real, a.imag)
        r = w * (rng.uniform(0.2, 1.0, (p, m)) + 1j * rng.uniform(0.5, 1.5, (p, m)))
        poles += [a, a.conjugate()]
        residues += [r, r.conj()]
    a_real = -2.0 * np.pi * 80.0
    poles.append(complex(a_real))
    residues.append(abs(a_real) * rng.uniform(0.5, 2.0, (p, m)) + 0j)
    d = rng.uniform(-0.02, 0.02, (p, m))
    return np.array(poles), np.array(residues), d


def evaluate(f_hz: np.ndarray, poles: np.ndarray, residues: np.ndarray,
             d: np.ndarray) -> np.ndarray:
    s = 2j * np.pi * f_hz
    return np.einsum("fn,npm->fpm", 1.0 / (s[:, None] - poles[None]), residues) + d[None]


def relative_error(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b) / np.abs(b)))


def matched_pole_error(found: np.ndarray, true: np.ndarray) -> float:
    """Largest relative distance from each true pole to the nearest found pole."""
    return float(max(np.min(np.abs(found - t)) / abs(t) for t in true))


def noisy(h: np.ndarray, level: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    noise = (rng.standard_normal(h.shape) + 1j * rng.standard_normal(h.shape)) / np.sqrt(2.0)
    return h * (1.0 + level * noise)


@pytest.fixture(scope="module")
def model() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return reference()


@pytest.fixture(scope="module")
def frf(model: tuple[np.ndarray, np.ndarray, np.ndarray]) -> np.ndarray:
    return evaluate(F_HZ, *model)


# ----------------------------------------------------------------------------- exact recovery


@pytest.mark.parametrize(
    "options",
    [
        VectorFitOptions(n_poles=5),
        VectorFitOptions(n_poles=5, relax=False),
        VectorFitOptions(n_poles=5, initial_poles="log"),
        VectorFitOptions(n_poles=5, initial_poles="peaks"),
        VectorFitOptions(n_poles=5, initial_poles="aaa"),
        VectorFitOptions(),  # automatic order from the peaks
        VectorFitOptions(initial_poles="log"),
        VectorFitOptions(initial_poles="aaa"),
    ],
    ids=["n5", "n5-classical", "n5-log", "n5-peaks", "n5-aaa", "auto", "auto-log", "auto-aaa"],
)
def test_exact_recovery(model: tuple, frf: np.ndarray, options: VectorFitOptions) -> None:
    fit = vector_fit(F_HZ, frf, options=options)
    assert fit.n_poles == 5
    assert fit.converged
    # 1e-8: noise-free rational data; the fit is limited only by float64 round-off (~1e-12 seen)
    assert matched_pole_error(fit.poles, model[0]) < 1e-8
    # 1e-10: same reason; the response is reproduced to ~1e-13 relative
    assert relative_error(fit.response(F_HZ), frf) < 1e-10
    assert fit.rms_error.shape == (2, 2)
    assert np.all(fit.rms_error < 1e-10)  # 1e-10: as above
    np.testing.assert_allclose(fit.d, model[2], rtol=1e-8, atol=1e-12)  # round-off only
    # conjugate pairs adjacent, positive imaginary part first
    k = 0
    while k < fit.n_poles:
        if fit.poles[k].imag != 0.0:
            assert fit.poles[k].imag > 0.0
            assert fit.poles[k + 1] == np.conj(fit.poles[k])
            np.testing.assert_array_equal(fit.residues[k + 1], np.conj(fit.residues[k]))
            k += 2
        else:
            k += 1


def test_convergence_record(frf: np.ndarray) -> None:
    options = VectorFitOptions(n_poles=5, tolerance=1e-9)
    fit = vector_fit(F_HZ, frf, options=options)
    assert fit.converged
    assert fit.iterations == len(fit.history) >= 1
    assert fit.history[-1] < options.tolerance
    assert fit.options is options
    stalled = vector_fit(F_HZ, frf, options=VectorFitOptions(n_poles=5, max_iterations=1,
                                                             initial_poles="log"))
    assert not stalled.converged  # one relocation from log-spaced poles cannot settle
    assert stalled.iterations <= 1


def test_surplus_poles_do_not_spoil_an_exact_fit(model: tuple, frf: np.ndarray) -> None:
    fit = vector_fit(F_HZ, frf, options=VectorFitOptions(n_poles=8))
    assert fit.n_poles == 8
    assert np.all(np.isfinite(fit.poles))
    # 1e-9: the five true poles are found; the surplus ones only add round-off
    assert matched_pole_error(fit.poles, model[0]) < 1e-9
    assert relative_error(fit.response(F_HZ), frf) < 1e-9


def test_automatic_order_removes_spurious_poles() -> None:
    poles, residues, d = reference()
    h = evaluate(F_HZ, poles[:4], residues[:4], d)  # two modes, no real pole
    fit = vector_fit(F_HZ, h)
    assert fit.n_poles == 4
    assert relative_error(fit.response(F_HZ), h) < 1e-10  # round-off only


@pytest.mark.parametrize("asymptote", ["none", "d", "de"])
def test_asymptotes(model: tuple, asymptote: str) -> None:
    poles, residues, d = model
    e = np.array([[1e-6, -2e-6], [3e-6, 5e-7]]) if asymptote == "de" else np.zeros((2, 2))
    d = d if asymptote != "none" else np.zeros((2, 2))
    h = evaluate(F_HZ, poles, residues, d) + 2j * np.pi * F_HZ[:, None, None] * e[None]
    fit = vector_fit(F_HZ, h, options=VectorFitOptions(n_poles=5, asymptote=asymptote))  # type: ignore[arg-type]
    assert relative_error(fit.response(F_HZ), h) < 1e-10  # round-off only
    np.testing.assert_allclose(fit.e, e, rtol=1e-7, atol=1e-15)  # round-off only
    if asymptote == "none":
        np.testing.assert_array_equal(fit.d, 0.0)


# ----------------------------------------------------------------------------- shapes


@pytest.mark.parametrize("shape", [(1, 3), (3, 2), (1, 1)])
def test_non_square(shape: tuple[int, int]) -> None:
    p, m = shape
    poles, residues, d = reference(p, m)
    h = evaluate(F_HZ, poles, residues, d)
    ins = [f"in{j}" for j in range(m)]
    outs = [f"out{i}" for i in range(p)]
    fit = vector_fit(F_HZ, h, input_names=ins, output_names=outs,
                     options=VectorFitOptions(n_poles=5))
    assert fit.residues.shape == (5, p, m)
    assert fit.d.shape == fit.e.shape == fit.rms_error.shape == (p, m)
    assert fit.response(F_HZ).shape == (F_HZ.size, p, m)
    assert fit.input_names == tuple(ins) and fit.output_names == tuple(outs)
    assert matched_pole_error(fit.poles, poles) < 1e-8  # noise-free: round-off only
    assert relative_error(fit.response(F_HZ), h) < 1e-10  # noise-free: round-off only


def test_siso_one_dimensional_input() -> None:
    poles, residues, d = reference(1, 1)
    h = evaluate(F_HZ, poles, residues, d)
    fit_1d = vector_fit(F_HZ, h[:, 0, 0], weights=1.0 / np.abs(h[:, 0, 0]))
    fit_3d = vector_fit(F_HZ, h)
    assert fit_1d.shape == (1, 1) and fit_1d.input_names == ("u0",)
    assert fit_1d.output_names == ("y0",)
    # 1e-12: the same problem (1-D weights = the default 1/|H|), identical arithmetic up to order
    np.testing.assert_allclose(fit_1d.poles, fit_3d.poles, rtol=1e-12)
    assert relative_error(fit_1d.response(F_HZ), h) < 1e-10  # noise-free: round-off only


# ----------------------------------------------------------------------------- weights


def test_zero_weight_drops_points(frf: np.ndarray) -> None:
    cutoff = 1000.0
    weights = np.where(F_HZ[:, None, None] < cutoff, 1.0 / np.abs(frf), 0.0)
    spoiled = frf.copy()
    above = np.greater(F_HZ, cutoff)
    rng = np.random.default_rng(3)
    spoiled[above] = 1e6 * (rng.standard_normal(spoiled[above].shape) + 10j)
    a = vector_fit(F_HZ, frf, weights=weights)
    b = vector_fit(F_HZ, spoiled, weights=weights)
    np.testing.assert_array_equal(a.poles, b.poles)  # the spoiled points are never used
    np.testing.assert_array_equal(a.residues, b.residues)
    assert b.frequency_range_hz == (1.0, cutoff - 1.0)
    # the fit still describes the clean model above the cutoff (noise-free: round-off)
    assert relative_error(b.response(F_HZ), frf) < 1e-9


def test_per_element_weights_shape(frf: np.ndarray) -> None:
    w = np.ones((1, 2, 2))  # broadcast over frequency
    fit = vector_fit(F_HZ, frf, weights=w, options=VectorFitOptions(n_poles=5))
    assert relative_error(fit.response(F_HZ), frf) < 1e-9  # noise-free: round-off only


def test_element_without_weight_is_left_out(frf: np.ndarray) -> None:
    weights = 1.0 / np.abs(frf)
    weights[:, 1, 0] = 0.0
    fit = vector_fit(F_HZ, frf, weights=weights, options=VectorFitOptions(n_poles=5))
    assert np.isnan(fit.rms_error[1, 0])
    np.testing.assert_array_equal(fit.residues[:, 1, 0], 0.0)
    keep = np.ones((2, 2), dtype=bool)
    keep[1, 0] = False
    assert np.all(fit.rms_error[keep] < 1e-10)  # noise-free: round-off only


def test_scale_invariance(frf: np.ndarray) -> None:
    scaled = frf.copy()
    scaled[:, 0, 1] *= 1e6
    a = vector_fit(F_HZ, frf)
    b = vector_fit(F_HZ, scaled)
    assert a.n_poles == b.n_poles
    # 1e-10: default 1/|H| weights make the pole step exactly scale-invariant; round-off only
    np.testing.assert_allclose(b.poles, a.poles, rtol=1e-10)
    np.testing.assert_allclose(b.residues[:, 0, 1], 1e6 * a.residues[:, 0, 1], rtol=1e-8)
    np.testing.assert_allclose(b.rms_error, a.rms_error, atol=1e-12)


# ----------------------------------------------------------------------------- stability


@pytest.mark.parametrize("n_poles", [5, None])
def test_stable_enforcement(n_poles: int | None) -> None:
    poles, residues, d = reference(unstable=True)
    assert np.any(poles.real > 0.0)
    h = evaluate(F_HZ, poles, residues, d)
    # max_poles bounds the automatic search: stable poles keep improving the fit slowly
    options = VectorFitOptions(n_poles=n_poles, max_poles=9, stable=True)
    fit = vector_fit(F_HZ, h, options=options)
    assert np.all(fit.poles.real < 0.0)
    assert fit.rms_error.max() > 1e-6  # a stable model cannot reproduce an unstable one


def test_unstable_poles_allowed_when_asked() -> None:
    poles, residues, d = reference(unstable=True)
    h = evaluate(F_HZ, poles, residues, d)
    fit = vector_fit(F_HZ, h, options=VectorFitOptions(n_poles=5, stable=False))
    assert matched_pole_error(fit.poles, poles) < 1e-8  # noise-free: round-off only


# ----------------------------------------------------------------------------- noise


def test_noisy_modes_and_standard_errors(frf: np.ndarray) -> None:
    options = VectorFitOptions(n_poles=5)
    fits = [vector_fit(F_HZ, noisy(frf, 0.01, seed), options=options) for seed in range(30)]
    modes = np.array([[(md.resonance_hz, md.damping_ratio) for md in f.modes()] for f in fits])
    stds = np.array([[(md.resonance_hz_std, md.damping_ratio_std) for md in f.modes()]
                     for f in fits])
    assert modes.shape == (30, 2, 2)
    # 0.1 % and 10 %: the brief's accuracy targets; seen 3e-6 and 1 % with 1 % noise
    assert np.all(np.abs(modes[:, :, 0] / MODES_HZ - 1.0) < 1e-3)
    assert np.all(np.abs(modes[:, :, 1] / ZETA - 1.0) < 0.1)
    # reported standard errors vs the Monte Carlo spread over 30 seeds: the ratio of two
    # sd estimates from 30 samples has ~13 % relative sd, so [0.5, 2] is a > 5 sigma band
    ratio = stds.mean(axis=0) / modes.std(axis=0, ddof=1)
    assert np.all((ratio > 0.5) & (ratio < 2.0)), ratio
    # weighted relative rms error sits at the noise level (1 %)
    rms = np.array([f.rms_error for f in fits])
    assert np.all(np.abs(rms - 0.01) < 0.002)  # 0.002: 5000-point rms of 1 % noise, +/- 20 %


def test_noisy_automatic_order(frf: np.ndarray) -> None:
    fit = vector_fit(F_HZ, noisy(frf, 0.01, 11))
    assert fit.n_poles == 5  # BIC: the noise does not justify more poles
    got = [md.resonance_hz for md in fit.modes()]
    np.testing.assert_allclose(got, MODES_HZ, rtol=1e-3)  # 0.1 %: the brief's target


# ----------------------------------------------------------------------------- realisation


@pytest.mark.parametrize("shape", [(2, 2), (1, 3)])
def test_to_statespace(shape: tuple[int, int]) -> None:
    p, m = shape
    h = evaluate(F_HZ, *reference(p, m))
    ins, outs = [f"U{j}" for j in range(m)], [f"V{i}" for i in range(p)]
    fit = vector_fit(F_HZ, h, input_names=ins, output_names=outs,
                     options=VectorFitOptions(n_poles=5))
    sys = fit.to_statespace()
    assert isinstance(sys, control.StateSpace)
    assert sys.input_labels == ins and sys.output_labels == outs
    assert sys.nstates == 5 * m
    resp = control.frequency_response(sys, 2.0 * np.pi * F_HZ, squeeze=False)
    got = np.moveaxis(resp.complex, -1, 0)
    # 1e-9: the same rational function evaluated two ways; differences are round-off
    assert relative_error(got, fit.response(F_HZ)) < 1e-9
    a = sys.A
    # block diagonal: real poles 1x1, pairs [[sigma, omega], [-omega, sigma]]
    blocks = np.zeros_like(a, dtype=bool)
    for j in range(m):
        base = 5 * j
        k = 0
        while k < 5:
            pole = fit.poles[k]
            if pole.imag != 0.0:
                np.testing.assert_array_equal(
                    a[base + k : base + k + 2, base + k : base + k + 2],
                    [[pole.real, pole.imag], [-pole.imag, pole.real]],
                )
                blocks[base + k : base + k + 2, base + k : base + k + 2] = True
                k += 2
            else:
                assert a[base + k, base + k] == pole.real
                blocks[base + k, base + k] = True
                k += 1
    np.testing.assert_array_equal(a[~blocks], 0.0)
    np.testing.assert_allclose(sys.D, fit.d)


def test_to_statespace_rejects_proportional_term(frf: np.ndarray) -> None:
    h = frf + 2j * np.pi * F_HZ[:, None, None] * 1e-6
    fit = vector_fit(F_HZ, h, options=VectorFitOptions(n_poles=5, asymptote="de"))
    with pytest.raises(ValueError, match="proportional term E"):
        fit.to_statespace()


def test_modes_sorted(frf: np.ndarray) -> None:
    modes = vector_fit(F_HZ, frf).modes()
    assert all(isinstance(md, Mode) for md in modes)
    assert [round(md.resonance_hz, 6) for md in modes] == list(MODES_HZ)
    np.testing.assert_allclose([md.damping_ratio for md in modes], ZETA, rtol=1e-8)


def test_json_round_trip(frf: np.ndarray) -> None:
    fit = vector_fit(F_HZ, noisy(frf, 0.01, 1), input_names=["Uch", "Ucv"],
                     output_names=["Vph", "Vpv"], options=VectorFitOptions(n_poles=5))
    doc = json.loads(json.dumps(fit.to_json(), allow_nan=False))
    assert doc["input_names"] == ["Uch", "Ucv"] and len(doc["modes"]) == 2
    back = VectorFit.from_json(doc)
    np.testing.assert_array_equal(back.poles, fit.poles)
    np.testing.assert_array_equal(back.residues, fit.residues)
    np.testing.assert_array_equal(back.pole_covariance, fit.pole_covariance)
    assert back.modes() == fit.modes()
    assert back.options == fit.options and back.history == fit.history


def test_result_is_read_only(frf: np.ndarray) -> None:
    fit = vector_fit(F_HZ, frf, options=VectorFitOptions(n_poles=5))
    with pytest.raises(ValueError, match="read-only"):
        fit.poles[0] = 0.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        fit.iterations = 3  # type: ignore[misc]


# ----------------------------------------------------------------------------- bad input


def _bad(**kw: object) -> dict:
    h = np.ones((10, 2, 2), dtype=complex)
    args = {"frequency_hz": np.arange(1.0, 11.0), "response": h}
    args.update(kw)
    return args


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (_bad(response=np.where(np.arange(10)[:, None, None] == 3, np.nan, 1.0 + 0j)
              * np.ones((10, 2, 2))), "NaN/inf"),
        (_bad(response=np.ones((9, 2, 2))), "shape"),
        (_bad(response=np.ones((10, 2))), "shape"),
        (_bad(frequency_hz=np.array([1.0, 2, 3, 3, 5, 6, 7, 8, 9, 10])), "strictly increasing"),
        (_bad(frequency_hz=np.arange(10.0, 0.0, -1.0)), "strictly increasing"),
        (_bad(frequency_hz=np.arange(-1.0, 9.0)), "non-negative"),
        (_bad(frequency_hz=np.array([1.0, np.nan, 3, 4, 5, 6, 7, 8, 9, 10])), "NaN"),
        (_bad(weights=-np.ones((10, 2, 2))), "non-negative"),
        (_bad(weights=np.ones((3, 2))), "broadcast"),
        (_bad(weights=np.zeros((10, 2, 2))), "non-zero weight"),
        (_bad(input_names=["a"]), "input_names"),
        (_bad(output_names=["a", "a"]), "duplicate"),
        (_bad(options=VectorFitOptions(n_poles=25)), "n_poles=25"),
    ],
    ids=["nan", "length", "ndim", "repeated-f", "decreasing-f", "negative-f", "nan-f",
         "negative-weight", "weight-shape", "all-zero-weight", "input-names", "dup-names",
         "too-many-poles"],
)
def test_bad_input(args: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        vector_fit(args.pop("frequency_hz"), args.pop("response"), **args)


@pytest.mark.parametrize(
    ("kw", "message"),
    [
        ({"n_poles": 0}, "n_poles"),
        ({"n_poles": 40}, "n_poles"),
        ({"max_iterations": 0}, "max_iterations"),
        ({"tolerance": 0.0}, "tolerance"),
        ({"asymptote": "e"}, "asymptote"),
        ({"initial_poles": "random"}, "initial_poles"),
    ],
)
def test_bad_options(kw: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        VectorFitOptions(**kw)
