"""Golden runs: the whole study on four benches, every JSON number kept, to compare two
versions of fsmbench (a refactor must leave the outputs unchanged).

    python benchmarks/golden_runs.py --out DIR [--duration S]
    python benchmarks/golden_runs.py --compare OLD_DIR NEW_DIR [--rtol 1e-12]

The first form runs ``fsmbench study`` on the twin of each bench: the packaged bench,
``real_bench.toml`` and the two benches of ``tests/data/benches`` (``stiff_bench.toml``,
``soft_bench.toml``, built for these tests and not by the twin's own parameters), and
writes ``DIR/<bench>.json``: every number of every JSON file the study wrote, keyed by
``file:path.to.value`` (timings and run.json excepted: wall-clock times). The second form
compares two such folders and prints each key whose values differ by more than
``rtol`` relative (``atol`` 1e-300 for exact zeros), each key in one and not the other,
and a one-line summary; it exits 1 when anything differs.

``rtol`` 1e-12: the same code on the same machine gives the same bits; a refactor that
only reorders independent floating-point sums moves a value by a few ulp (~1e-15), far
inside it.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
BENCHES = {"packaged": None, "real_bench": "real_bench.toml",
           "stiff_bench": str(ROOT / "tests" / "data" / "benches" / "stiff_bench.toml"),
           "soft_bench": str(ROOT / "tests" / "data" / "benches" / "soft_bench.toml")}
_SKIPPED = {"timings.json", "run.json"}


def _numbers(doc: Any, prefix: str) -> Iterator[tuple[str, float]]:
    """Every number in a JSON document, keyed by its path."""
    if isinstance(doc, dict):
        for key, value in doc.items():
            yield from _numbers(value, f"{prefix}.{key}")
    elif isinstance(doc, list):
        for i, value in enumerate(doc):
            yield from _numbers(value, f"{prefix}[{i}]")
    elif isinstance(doc, bool) or doc is None or isinstance(doc, str):
        return
    elif isinstance(doc, (int, float)):
        yield prefix, float(doc)


def run(out: Path, duration_s: float | None) -> None:
    """Study each bench's twin; write its numbers."""
    from fsmbench.bench.params import load_bench
    from fsmbench.study import run_study

    out.mkdir(parents=True, exist_ok=True)
    for name, path in BENCHES.items():
        with tempfile.TemporaryDirectory() as tmp:
            study = Path(tmp) / "study"
            run_study(out_dir=study, bench=load_bench(path), duration_s=duration_s)
            numbers: dict[str, float] = {}
            for file in sorted(study.rglob("*.json")):
                if file.name in _SKIPPED:
                    continue
                rel = file.relative_to(study).as_posix()
                numbers.update(_numbers(json.loads(file.read_text(encoding="utf-8")), rel))
        (out / f"{name}.json").write_text(json.dumps(numbers, indent=0, sort_keys=True))
        print(f"{name}: {len(numbers)} numbers", flush=True)


def compare(old: Path, new: Path, rtol: float) -> int:
    """Print the differences; 0 when none."""
    differ = 0
    total = 0
    for name in BENCHES:
        a = json.loads((old / f"{name}.json").read_text())
        b = json.loads((new / f"{name}.json").read_text())
        for key in sorted(set(a) ^ set(b)):
            print(f"{name}: {key} only in {'old' if key in a else 'new'}")
            differ += 1
        for key in sorted(set(a) & set(b)):
            x, y = a[key], b[key]
            total += 1
            same = (x == y or (math.isnan(x) and math.isnan(y))
                    or abs(x - y) <= rtol * max(abs(x), abs(y)) + 1e-300)
            if not same:
                print(f"{name}: {key}: {x!r} -> {y!r}")
                differ += 1
    print(f"{total} numbers compared on {len(BENCHES)} benches, {differ} differ (rtol {rtol:g})")
    return 1 if differ else 0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, help="write the four benches' numbers here")
    parser.add_argument("--duration", type=float, default=None,
                        help="twin record length [s] (default: the ESRF study's)")
    parser.add_argument("--compare", nargs=2, type=Path, metavar=("OLD", "NEW"))
    parser.add_argument("--rtol", type=float, default=1e-12)
    args = parser.parse_args()
    if args.compare:
        sys.exit(compare(*args.compare, args.rtol))
    if args.out is None:
        parser.error("--out DIR or --compare OLD NEW")
    run(args.out, args.duration)


if __name__ == "__main__":
    main()
