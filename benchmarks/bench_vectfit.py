"""Benchmark: fsmbench ``vector_fit`` vs scikit-rf ``VectorFitting`` on the same FRF matrix.

Data: a 2x2 bench-like FRF matrix (the seed's section 2.3 identification,
``Uch``/``Ucv`` -> ``Vph``/``Vpv``): two lightly damped modes (zeta = 1e-3) at
250 Hz and 411 Hz with cross-coupling, a real pole at 80 Hz and a constant
feed-through, sampled on the seed's 1 Hz Welch grid from 1 Hz to 5 kHz
(5000 points), with 1 % relative complex Gaussian measurement noise.

Both fit the same model structure: 5 common poles (1 real + 2 complex pairs)
and a constant term, no proportional term.

(a) fsmbench: ``vector_fit(..., options=VectorFitOptions(n_poles=5))``: relaxed,
    stable, fast (QR-compressed) VF iterated to a relative pole movement of
    1e-6, default weights 1/|H|, plus the pole covariance; (a') the same with
    uniform weights, i.e. scikit-rf's unweighted criterion.
(b) scikit-rf: ``VectorFitting(Network).vector_fit(n_poles_real=1,
    n_poles_cmplx=2, init_pole_spacing=...)`` (``fit_constant=True``,
    ``fit_proportional=False``), run on the FRF stored as a 2x2 s-parameter
    network (no physics of s-parameters is used by the fit).

Errors are computed identically for both on the fit grid, per element, and the
worst element is shown:
  rel. rms vs data  : sqrt(mean |H_fit - H|^2 / |H|^2) against the noisy data
  norm. rms vs data : ||H_fit - H|| / ||H|| against the noisy data
  rel. rms vs truth : sqrt(mean |H_fit - H0|^2 / |H0|^2) against the noise-free H0
(1 % noise puts the floor of the first at ~0.01.)

Run: ``python benchmarks/bench_vectfit.py [--repeats 7] [--seed 0]``. On a
loaded machine, ``OPENBLAS_NUM_THREADS=1`` gives steadier timings for both.
"""

from __future__ import annotations

import argparse
import logging
import os
import warnings

import numpy as np
import scipy

from fsmbench.ident.fit.vectfit import VectorFit, VectorFitOptions, vector_fit
from timing import timed_runs

F_HZ = np.arange(1.0, 5001.0)  # the seed's 1 Hz Welch grid, 1 Hz .. 5 kHz
ZETA = 1e-3
NOISE = 0.01  # relative complex noise (rms of |noise| / |H|)
INPUTS, OUTPUTS = ("Uch", "Ucv"), ("Vph", "Vpv")


def truth() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Poles (rad/s), residues (n, 2, 2) and D (2, 2) of the bench-like reference model."""
    poles, residues = [], []
    modes = {  # (frequency, Hz): rank-1-ish modal gains incl. cross-coupling
        250.0: np.array([[0.15, 1.0], [0.8, 0.1]]),
        411.0: np.array([[1.0, 0.2], [0.15, 0.7]]),
    }
    for f0, gain in modes.items():
        w = 2.0 * np.pi * f0
        a = complex(-ZETA * w, w * np.sqrt(1.0 - ZETA**2))
        r = gain * w * (0.3 + 1.0j)
        poles += [a, a.conjugate()]
        residues += [r, r.conj()]
    a_real = -2.0 * np.pi * 80.0
    poles.append(complex(a_real))
    residues.append(np.array([[2.0, 0.5], [0.1, 1.0]]) * abs(a_real) + 0j)
    d = np.array([[0.01, -0.002], [0.003, 0.02]])
    return np.array(poles), np.array(residues), d


def evaluate(poles: np.ndarray, residues: np.ndarray, d: np.ndarray) -> np.ndarray:
    s = 2j * np.pi * F_HZ
    return np.einsum("fn,npm->fpm", 1.0 / (s[:, None] - poles[None]), residues) + d[None]


def make_data(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(noisy FRF, noise-free FRF), both (F, 2, 2)."""
    h0 = evaluate(*truth())
    rng = np.random.default_rng(seed)
    noise = (rng.standard_normal(h0.shape) + 1j * rng.standard_normal(h0.shape)) / np.sqrt(2)
    return h0 * (1.0 + NOISE * noise), h0


def run_fsmbench(h: np.ndarray, weights: np.ndarray | None = None) -> VectorFit:
    return vector_fit(F_HZ, h, weights=weights, input_names=INPUTS, output_names=OUTPUTS,
                      options=VectorFitOptions(n_poles=5))


def run_skrf(h: np.ndarray, spacing: str) -> object:
    import skrf
    from skrf.vectorFitting import VectorFitting

    network = skrf.Network(frequency=skrf.Frequency.from_f(F_HZ, unit="Hz"), s=h)
    vf = VectorFitting(network)
    vf.vector_fit(n_poles_real=1, n_poles_cmplx=2, init_pole_spacing=spacing,
                  fit_constant=True, fit_proportional=False)
    return vf


def skrf_response(vf: object) -> np.ndarray:
    p, m = len(OUTPUTS), len(INPUTS)
    out = np.empty((F_HZ.size, p, m), dtype=complex)
    for i in range(p):
        for j in range(m):
            out[:, i, j] = vf.get_model_response(i, j, F_HZ)  # type: ignore[attr-defined]
    return out


def errors(fit: np.ndarray, h: np.ndarray, h0: np.ndarray) -> tuple[float, float, float]:
    rel = np.sqrt(np.mean(np.abs(fit - h) ** 2 / np.abs(h) ** 2, axis=0)).max()
    norm = (np.linalg.norm(fit - h, axis=0) / np.linalg.norm(h, axis=0)).max()
    rel0 = np.sqrt(np.mean(np.abs(fit - h0) ** 2 / np.abs(h0) ** 2, axis=0)).max()
    return float(rel), float(norm), float(rel0)


def modes_of(poles: np.ndarray) -> str:
    pairs = sorted((p for p in np.asarray(poles) if p.imag > 0), key=abs)
    return ", ".join(f"{abs(p) / 2 / np.pi:.4f} Hz / zeta {-p.real / abs(p):.4e}" for p in pairs)



def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7, help="timed repetitions (>= 7)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    repeats = max(7, args.repeats)
    logging.getLogger("skrf").setLevel(logging.ERROR)
    warnings.filterwarnings("ignore", module="skrf")
    try:
        import skrf
    except ImportError:
        raise SystemExit("scikit-rf is not installed: pip install 'fsmbench[bench]'") from None

    h, h0 = make_data(args.seed)
    threads = os.environ.get("OPENBLAS_NUM_THREADS", "default")
    print(f"numpy {np.__version__}, scipy {scipy.__version__}, scikit-rf {skrf.__version__}, "
          f"{os.cpu_count()} CPU(s), OPENBLAS_NUM_THREADS={threads}")
    print(f"2x2 FRF, {F_HZ.size} points {F_HZ[0]:g}-{F_HZ[-1]:g} Hz, {NOISE:.0%} noise, "
          f"5 poles + D, {repeats} timed runs each\n")

    rows = []
    t, runs = timed_runs(lambda: run_fsmbench(h), repeats)
    fit = run_fsmbench(h)
    rows.append(("(a) fsmbench vector_fit", t, runs, errors(fit.response(F_HZ), h, h0),
                 modes_of(fit.poles)))
    ones = np.ones(F_HZ.size)
    t, runs = timed_runs(lambda: run_fsmbench(h, ones), repeats)
    fit_u = run_fsmbench(h, ones)
    rows.append(("(a') fsmbench, uniform weights", t, runs,
                 errors(fit_u.response(F_HZ), h, h0), modes_of(fit_u.poles)))
    for spacing in ("lin", "log"):
        t, runs = timed_runs(lambda s=spacing: run_skrf(h, s), repeats)  # type: ignore[misc]
        vf = run_skrf(h, spacing)
        rows.append((f"(b) scikit-rf VectorFitting ({spacing})", t, runs,
                     errors(skrf_response(vf), h, h0), modes_of(vf.poles)))  # type: ignore[attr-defined]

    print(f"{'':38s} {'median':>9s}  {'rel.rms/data':>12s} {'norm.rms/data':>13s} "
          f"{'rel.rms/truth':>13s}")
    for name, t, runs, (e1, e2, e3), _ in rows:
        print(f"{name:38s} {t * 1e3:7.1f} ms  {e1:12.3e} {e2:13.3e} {e3:13.3e}   "
              f"(runs ms: {', '.join(f'{r * 1e3:.0f}' for r in runs)})")
    print()
    for name, *_, modes in rows:
        print(f"{name:38s} modes: {modes}")
    print(f"{'truth':38s} modes: {modes_of(truth()[0])}")
    print(f"\nfsmbench: {fit.iterations} relocations, converged={fit.converged}; "
          f"mode std: " + ", ".join(f"{m.resonance_hz_std:.1e} Hz / {m.damping_ratio_std:.1e}"
                                    for m in fit.modes()))
    t_ours = rows[0][1]
    for name, t, *_ in rows[2:]:
        print(f"speed-up {name[4:]} / fsmbench: {t / t_ours:.2f}x")


if __name__ == "__main__":
    main()
