"""The coprime-factor margin (seed 5.1) on identified plants: which realisation solves.

    python benchmarks/bench_coprime.py [--seed N]

For the four benches of the test suite (the packaged one, ``real_bench.toml`` and
the two of ``tests/data/benches``) the twin's identification experiments are
simulated and identified, and the Riccati equations of the normalised coprime
factors of the scaled plant (``Uc/10 V → R/10 µrad``) are solved three ways:

- scipy's ``solve_continuous_are`` on the identified realisation as it is
  (column by column: each mode once per input, a non-minimal model);
- the same on :func:`fsmbench.control.analysis.balanced_minimal` of it (what
  fsmbench does);
- SLICOT's ``sb02md`` through python-control's ``care(method="slycot")`` on the
  realisation as it is, when slycot is installed (``pip install slycot``).

It prints, per bench and method, whether a stabilising solution was found, the
relative Riccati residual, the median time of 5 runs, and ``b_max``.
"""

from __future__ import annotations

import argparse
import statistics
import time
import warnings
from collections.abc import Callable
from pathlib import Path

import control as ct
import numpy as np
from scipy import linalg

from fsmbench.bench.params import default_bench, load_bench, real_bench
from fsmbench.control.analysis import balanced_minimal
from fsmbench.ident.pipeline import identify
from fsmbench.twin import simulate_bench

BENCHES = Path(__file__).resolve().parents[1] / "tests" / "data" / "benches"
IDENT = ("data_cal_pd_h", "data_cal_pd_v", "data_uch", "data_ucv", "data_unh", "data_unv")


def _scaled(plant: object) -> ct.StateSpace:
    sub = plant.subsystem(outputs=["Rh", "Rv"], inputs=["Uch", "Ucv"])  # type: ignore[attr-defined]
    sc = default_bench().nominal.scaling
    return ct.ss(sub.A, sub.B * sc.uc_max_v, sub.C / sc.error_max_rad,
                 sub.D * sc.uc_max_v / sc.error_max_rad)


def _filter_are(sys: ct.StateSpace, solver: Callable[..., np.ndarray]) -> tuple[np.ndarray, float]:
    a, b, c, d = (np.asarray(x, dtype=float) for x in (sys.A, sys.B, sys.C, sys.D))
    r = np.eye(d.shape[0]) + d @ d.T
    z = solver(a.T, c.T, b @ b.T, r, b @ d.T)
    res = a @ z + z @ a.T - (z @ c.T + b @ d.T) @ np.linalg.solve(r, c @ z + d @ b.T) + b @ b.T
    return z, float(np.linalg.norm(res) / np.linalg.norm(b @ b.T))


def _scipy(a: np.ndarray, b: np.ndarray, q: np.ndarray, r: np.ndarray, s: np.ndarray) -> np.ndarray:
    return np.asarray(linalg.solve_continuous_are(a, b, q, r, s=s))


def _slycot(a: np.ndarray, b: np.ndarray, q: np.ndarray, r: np.ndarray,
            s: np.ndarray) -> np.ndarray:
    with warnings.catch_warnings():
        # SLICOT warns, and returns a solution anyway, when it is inaccurate: a failure here.
        warnings.simplefilter("error")
        x, _l, _g = ct.care(a, b, q, r, S=s, method="slycot")
    return np.asarray(x)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seed", type=int, default=3)
    args = parser.parse_args()
    try:
        import slycot  # noqa: F401
        methods = [("scipy, as identified", False, _scipy), ("scipy, balanced minimal", True,
                                                              _scipy),
                   ("SLICOT, as identified", False, _slycot)]
    except ImportError:
        methods = [("scipy, as identified", False, _scipy),
                   ("scipy, balanced minimal", True, _scipy)]
        print("(slycot is not installed: SLICOT's sb02md left out)")
    benches = {"packaged": default_bench(), "real_bench.toml": real_bench(),
               "stiff": load_bench(BENCHES / "stiff_bench.toml"),
               "soft": load_bench(BENCHES / "soft_bench.toml")}
    print(f"{'bench':<16} {'method':<24} {'states':>6} {'solved':>7} {'residual':>10} "
          f"{'time [ms]':>10} {'b_max':>8}")
    for name, bench in benches.items():
        run = simulate_bench(bench, seed=args.seed, experiments=IDENT)
        ident = identify(run.recordings, bench=default_bench(), source=name)
        if ident.plant is None:
            print(f"{name:<16} identification failed: {ident.skipped}")
            continue
        raw = _scaled(ident.plant)
        for label, minimal, solver in methods:
            sys = balanced_minimal(raw) if minimal else raw
            times = []
            try:
                for _ in range(5):
                    t0 = time.perf_counter()
                    z, residual = _filter_are(sys, solver)
                    times.append(time.perf_counter() - t0)
                a, b, c, d = (np.asarray(x, dtype=float) for x in (sys.A, sys.B, sys.C, sys.D))
                x_ = linalg.solve_continuous_are(a, b, c.T @ c, np.eye(2) + d.T @ d, s=c.T @ d)
                b_max = 1.0 / np.sqrt(1.0 + np.max(np.real(np.linalg.eigvals(x_ @ z))))
                print(f"{name:<16} {label:<24} {sys.nstates:>6} {'yes':>7} {residual:>10.1e} "
                      f"{1e3 * statistics.median(times):>10.2f} {b_max:>8.4f}")
            except (np.linalg.LinAlgError, ValueError, ArithmeticError, Warning) as exc:
                print(f"{name:<16} {label:<24} {sys.nstates:>6} {'no':>7} "
                      f"({str(exc).splitlines()[0][:40]})")


if __name__ == "__main__":
    main()
