"""The whole study on the twin: time per stage, the report's size, and the report
against its peer, in one run.

    python benchmarks/bench_study.py [--repeats 3] [--duration S]

Runs ``fsmbench study`` on the twin ``--repeats`` times (after one warm-up
run that fills the compiled-kernel cache) and prints the median wall time
of each stage (``timings.json``) and of the whole study; then the same study with
its stages one after the other in one process (``run_study(parallel=False)``, the
peer of the forked stages) and the ratio. Then, on the same
figures, times the interactive report (figure specs → plotly.js JSON → one
HTML file) against the peer it replaced: matplotlib drawing every figure to
a PNG (``report.static.export_figures``), and prints the ratio.
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time
from pathlib import Path

from fsmbench.report.html import iter_figures, render_report
from fsmbench.study import run_study
from timing import timed_runs


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--duration", type=float, default=None,
                        help="twin record length [s] (default: the seed's)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        run_study(out_dir=root / "warm-up", duration_s=args.duration)
        walls: list[float] = []
        stages: dict[str, list[float]] = {}
        for i in range(args.repeats):
            t0 = time.perf_counter()
            result = run_study(out_dir=root / f"run{i}", duration_s=args.duration)
            walls.append(time.perf_counter() - t0)
            for name, s in json.loads((root / f"run{i}" / "timings.json").read_text())[
                    "seconds"].items():
                stages.setdefault(name, []).append(s)
        print(f"fsmbench study on the twin, median of {args.repeats} runs "
              f"(durations: {'the seed' if args.duration is None else args.duration} s)")
        for name, values in stages.items():
            print(f"  {name:<12s} {statistics.median(values):7.2f} s")
        print(f"  {'whole study':<12s} {statistics.median(walls):7.2f} s")
        serial = []
        for i in range(args.repeats):
            t0 = time.perf_counter()
            run_study(out_dir=root / f"serial{i}", duration_s=args.duration, parallel=False)
            serial.append(time.perf_counter() - t0)
        print(f"  {'one after the other':<12s} {statistics.median(serial):7.2f} s "
              f"(run_study(parallel=False)); side by side "
              f"{statistics.median(serial) / statistics.median(walls):.2f}x faster")
        report = Path(result.report)
        print(f"report.html: {report.stat().st_size / 1e6:.2f} MB")

        # The report build on the same sections, against matplotlib PNGs of the same figures.
        from fsmbench.report.figures.static import export_figures

        sections = result.sections
        n_figures = sum(1 for _ in iter_figures(sections))
        html_s = timed_runs(lambda: render_report(title="t", sections=sections),
                            args.repeats)[0]
        png_s = timed_runs(lambda: export_figures(iter_figures(sections), root / "png",
                                                  formats=("png",)), 1, warm_up=False)[0]
        print(f"{n_figures} figures: interactive report build {html_s:.2f} s; matplotlib PNGs "
              f"of the same figures {png_s:.2f} s; ratio {png_s / html_s:.1f}x")


if __name__ == "__main__":
    main()
