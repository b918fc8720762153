"""Run a bench's thirteen recordings and write them with ``truth.json``."""

from __future__ import annotations

import json
import math
import time
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.io import savemat

from .bench import IndBench
from .experiments import EXPERIMENTS, Record, run_experiment
from .model import bench_model
from .truth import bench_file_toml, truth

__all__ = ["BenchRun", "simulate_bench", "write_bench"]

FRAMES = ("indsim frames: beam (x, y) at the 4QD, +x/+y where a positive Unh/Unv tilts "
          "the beam (Newport beam factor +2); Sercalo b = mount * 4 * phi; 4QD reads "
          "(cos θ b_x + sin θ b_y, -sin θ b_x + cos θ b_y) times its signed gains "
          "(indsim.bench).")


@dataclass(frozen=True)
class BenchRun:
    """A simulated bench: its records and its truth (JSON-ready)."""

    bench: IndBench
    records: dict[str, Record]
    truth: dict[str, Any]


def _rng(seed: int, bench: str, experiment: str) -> np.random.Generator:
    """Independent, reproducible noise per (seed, bench, experiment)."""
    key = [seed, zlib.crc32(bench.encode()), zlib.crc32(experiment.encode())]
    return np.random.default_rng(np.random.SeedSequence(key))


def simulate_bench(bench: IndBench, seed: int = 0, duration_scale: float = 1.0,
                   experiments: list[str] | None = None) -> BenchRun:
    """Run the study's recordings on ``bench``.

    Parameters
    ----------
    bench : IndBench
        The bench.
    seed : int
        Noise seed (combined with the bench's and each experiment's name).
    duration_scale : float
        Fraction of the study's lengths (at least a few seconds per file).
    experiments : list of str, optional
        Subset of the thirteen (default all).
    """
    model = bench_model(bench)
    names = experiments or list(EXPERIMENTS)
    records = {n: run_experiment(model, n, _rng(seed, bench.name, n), duration_scale)
               for n in names}
    tr: dict[str, Any] = {"format": "indsim.truth", "format_version": 1,
                          "name": bench.name, "description": bench.description,
                          "seed": seed, "duration_scale": duration_scale, "frames": FRAMES,
                          "parameters": bench.as_dict()}
    tr.update(truth(model))
    tr["experiments"] = {n: r.protocol for n, r in records.items()}
    tr["realized"] = {n: r.realized for n, r in records.items()}
    return BenchRun(bench, records, tr)


def _clean(x: Any) -> Any:
    """JSON-ready: NumPy scalars to Python, non-finite numbers to null."""
    if isinstance(x, dict):
        return {str(k): _clean(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_clean(v) for v in x]
    if isinstance(x, np.generic):
        x = x.item()
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def write_bench(run: BenchRun, out_dir: Path, compress: bool = False) -> Path:
    """Write ``out_dir/<experiment>.mat`` (MATLAB v5, column vectors) and ``truth.json``.

    ``compress`` zips each variable (about 5x smaller, 10x slower to write).
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    for name, rec in run.records.items():
        savemat(out_dir / f"{name}.mat",
                {k: np.ascontiguousarray(v, dtype=np.float64).reshape(-1, 1)
                 for k, v in rec.signals.items()},
                format="5", do_compression=compress, oned_as="column")
    (out_dir / "truth.json").write_text(json.dumps(_clean(run.truth), indent=1,
                                                   allow_nan=False) + "\n")
    return out_dir


def summary_line(run: BenchRun, seconds: float) -> str:
    """One line about a written bench (the CLI prints it)."""
    t = run.truth
    s, c = t["observable_signs"], t["controller"]["multiplier"]
    return (f"{run.bench.name}: fs {t['fs_hz']:.0f} Hz, Gd {t['qd_gain_v_per_rad']['h']:+.1f}/"
            f"{t['qd_gain_v_per_rad']['v']:+.1f} V/rad, Ich->Vph {s['Ich_to_Vph']:+.0f}, "
            f"Icv->Vpv {s['Icv_to_Vpv']:+.0f}, controller x{c['h']:+.3g}/{c['v']:+.3g}, "
            f"delays {1e6 * t['delay_s']['sercalo']:.0f}/{1e6 * t['delay_s']['newport']:.0f} us, "
            f"{len(run.records)} files, {seconds:.1f} s")


def timed_write(bench: IndBench, out: Path, seed: int, duration_scale: float,
                compress: bool = False, toml: bool = False) -> str:
    """Simulate and write one bench (and ``out/<bench>.toml``); return its summary line."""
    t0 = time.perf_counter()
    run = simulate_bench(bench, seed, duration_scale)
    write_bench(run, out / bench.name, compress)
    if toml:
        (out / f"{bench.name}.toml").write_text(bench_file_toml(run.truth))
    return summary_line(run, time.perf_counter() - t0)
