"""Plotly against Bokeh for the interactive HTML report: page size, build and load time.

    .venv/bin/python benchmarks/bench_report_libs.py [--repeats 5] [--keep DIR]

One synthetic 57-figure set shaped like fsmbench's report (``_report_figures``), the
same float32 data for every variant, each written as ONE self-contained offline HTML
file with the library's JavaScript inlined once:

* Plotly A -- figure JSON as plain dicts, arrays as plotly.js typed arrays
  (``{"dtype": "f4", "bdata": base64}``), ``Plotly.newPlot`` per ``<div>``; eager, and
  lazy (IntersectionObserver renders visible figures, the rest in idle time).
* Plotly B -- ``plotly.graph_objects`` + ``make_subplots`` + ``to_html`` per figure.
* Bokeh -- ``bokeh.plotting`` figures in ``gridplot`` s, one document,
  ``file_html(..., resources=INLINE)``.

Build time is Python data -> HTML string. Load times are measured in headless Debian
Chromium (Playwright, no browser download) from navigation start: "first screen" is the
first frame after the first 2 figures have rendered, "all" the first frame after all 57
have. Prints medians, the ratios Plotly A : Bokeh and any browser console errors.
"""

from __future__ import annotations

import argparse
import base64
import json
import os
import statistics
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, field
from importlib.metadata import version
from importlib.resources import files
from pathlib import Path

import numpy as np
from playwright.sync_api import Browser, sync_playwright

from _report_figures import Figure, make_figure_set
from timing import timed_runs

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--no-first-run"]
VIEWPORT = {"width": 1280, "height": 800}
LOAD_TIMEOUT_MS = 180_000  # a 57-figure page must render well within 3 minutes, else it failed
COLORS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd")


# ---------------------------------------------------------------- Plotly A: plain dicts


def _typed(a: np.ndarray) -> dict[str, str]:
    """A float32 array as a plotly.js typed-array spec (little-endian, as x86 browsers)."""
    return {"dtype": "f4", "bdata": base64.b64encode(a.astype("<f4").tobytes()).decode("ascii")}


def plotly_dict(fig: Figure) -> dict[str, object]:
    """Plotly figure JSON (``data``, ``layout``) of ``fig`` built as plain dicts."""
    data = []
    layout: dict[str, object] = {
        "title": {"text": fig.title}, "height": fig.height_px,
        "margin": {"l": 70, "r": 20, "t": 50, "b": 50},
        # "coupled": one x axis for the column, stacked rows each with their own y axis
        "grid": {"rows": len(fig.panels), "columns": 1, "pattern": "coupled", "ygap": 0.12},
        "xaxis": {"type": "log" if fig.xlog else "linear", "title": {"text": fig.xlabel}},
    }
    for r, panel in enumerate(fig.panels):
        yname = "y" if r == 0 else f"y{r + 1}"
        layout["yaxis" if r == 0 else f"yaxis{r + 1}"] = {
            "type": "log" if panel.ylog else "linear", "title": {"text": panel.ylabel}}
        for k, tr in enumerate(panel.traces):
            trace: dict[str, object] = {
                "type": "bar" if tr.kind == "bar" else "scatter", "name": tr.name,
                "x": _typed(tr.x), "y": _typed(tr.y), "xaxis": "x", "yaxis": yname,
                "legendgroup": tr.name, "showlegend": r == 0,
                "marker": {"color": COLORS[k % len(COLORS)]}}
            if tr.kind != "bar":
                trace.update(mode="lines", line={"width": 1, "color": COLORS[k % len(COLORS)]})
            data.append(trace)
    return {"data": data, "layout": layout}


_PLOTLY_EAGER_JS = """
const T = window.__fsm = {};
const divs = [...document.querySelectorAll('div.fsm-fig')];
const stamp = (key) => () => requestAnimationFrame(() => { T[key] = performance.now(); });
const promises = divs.map((div) => {
  const spec = JSON.parse(document.getElementById(div.id + '-json').textContent);
  return Plotly.newPlot(div, spec.data, spec.layout, {responsive: true});
});
Promise.all(promises.slice(0, 2)).then(stamp('first'));
Promise.all(promises).then(stamp('all'), (e) => { T.error = String(e); });
"""

_PLOTLY_LAZY_JS = """
const T = window.__fsm = {};
const divs = [...document.querySelectorAll('div.fsm-fig')];
const started = new Set();
let done = 0, firstDone = 0;
const stamp = (key) => requestAnimationFrame(() => { T[key] = performance.now(); });
function render(div) {
  if (started.has(div)) return;
  started.add(div);
  observer.unobserve(div);
  const spec = JSON.parse(document.getElementById(div.id + '-json').textContent);
  Plotly.newPlot(div, spec.data, spec.layout, {responsive: true}).then(() => {
    if (divs.indexOf(div) < 2 && ++firstDone === 2) stamp('first');
    if (++done === divs.length) stamp('all');
  }, (e) => { T.error = String(e); });
}
const observer = new IntersectionObserver((entries) => {
  for (const e of entries) if (e.isIntersecting) render(e.target);
}, {rootMargin: '200px'});
divs.forEach((d) => observer.observe(d));
function idle(deadline) {
  const next = divs.find((d) => !started.has(d));
  if (next === undefined) return;
  if (deadline.timeRemaining() > 0) render(next);
  requestIdleCallback(idle);
}
requestIdleCallback(idle);
"""


def _json_script(id_: str, obj: object) -> str:
    # "</" inside a <script> would end it early
    text = json.dumps(obj, separators=(",", ":")).replace("</", "<\\/")
    return f'<script type="application/json" id="{id_}">{text}</script>'


def plotly_js() -> str:
    """plotly.min.js as shipped inside the plotly Python package."""
    return (files("plotly") / "package_data" / "plotly.min.js").read_text(encoding="utf-8")


def build_plotly_a(figs: tuple[Figure, ...], js: str, *, lazy: bool = False) -> str:
    """Self-contained HTML page, Plotly path A (plain dicts + typed arrays)."""
    parts = ['<!DOCTYPE html><html><head><meta charset="utf-8"><title>report</title>',
             f"<script>{js}</script></head><body>"]
    for i, fig in enumerate(figs):
        parts.append(f'<div class="fsm-fig" id="fig{i}" style="height:{fig.height_px}px"></div>')
        parts.append(_json_script(f"fig{i}-json", plotly_dict(fig)))
    parts.append(f"<script>{_PLOTLY_LAZY_JS if lazy else _PLOTLY_EAGER_JS}</script></body></html>")
    return "".join(parts)


# ---------------------------------------------------------------- Plotly B: graph_objects

# Test instrumentation only: to_html() calls Plotly.newPlot inline and drops the promise.
_PLOTLY_B_HOOK_JS = """
const T = window.__fsm = {};
const _promises = [];
const _newPlot = Plotly.newPlot;
Plotly.newPlot = (...args) => { const p = _newPlot(...args); _promises.push(p); return p; };
"""
_PLOTLY_B_DONE_JS = """
const stamp = (key) => () => requestAnimationFrame(() => { T[key] = performance.now(); });
Promise.all(_promises.slice(0, 2)).then(stamp('first'));
Promise.all(_promises).then(stamp('all'), (e) => { T.error = String(e); });
"""


def build_plotly_b(figs: tuple[Figure, ...], js: str) -> str:
    """Self-contained HTML page, Plotly path B (graph_objects, validated, ``to_html``)."""
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots

    parts = ['<!DOCTYPE html><html><head><meta charset="utf-8"><title>report</title>',
             f"<script>{js}</script><script>{_PLOTLY_B_HOOK_JS}</script></head><body>"]
    for i, fig in enumerate(figs):
        n = len(fig.panels)
        gofig = make_subplots(rows=n, cols=1, shared_xaxes=True, vertical_spacing=0.12 / n)
        for r, panel in enumerate(fig.panels):
            for k, tr in enumerate(panel.traces):
                color = COLORS[k % len(COLORS)]
                if tr.kind == "bar":
                    trace = go.Bar(x=tr.x, y=tr.y, name=tr.name, marker_color=color)
                else:
                    trace = go.Scatter(x=tr.x, y=tr.y, name=tr.name, mode="lines",
                                       line={"width": 1, "color": color},
                                       legendgroup=tr.name, showlegend=r == 0)
                gofig.add_trace(trace, row=r + 1, col=1)
            gofig.update_yaxes(type="log" if panel.ylog else "linear",
                               title_text=panel.ylabel, row=r + 1, col=1)
        gofig.update_xaxes(type="log" if fig.xlog else "linear")
        gofig.update_xaxes(title_text=fig.xlabel, row=n, col=1)
        gofig.update_layout(title_text=fig.title, height=fig.height_px,
                            margin={"l": 70, "r": 20, "t": 50, "b": 50})
        parts.append(gofig.to_html(include_plotlyjs=False, full_html=False, div_id=f"fig{i}",
                                   default_height=f"{fig.height_px}px"))
    parts.append(f"<script>{_PLOTLY_B_DONE_JS}</script></body></html>")
    return "".join(parts)


# ---------------------------------------------------------------- Bokeh

# Test instrumentation only. Bokeh's own readiness signal: Document.is_idle turns true
# when every root view has finished rendering (the same test that fires DocumentReady).
_BOKEH_PROBE_JS = """
<script>
(function () {
  const T = window.__fsm = {};
  function poll() {
    const B = window.Bokeh;
    if (B !== undefined && B.documents.length > 0) {
      const doc = B.documents[0];
      const roots = doc.roots();
      if (T.first === undefined && roots.length >= 2) {
        const views = roots.slice(0, 2).map((m) => B.index.get(m));
        if (views.every((v) => v != null && v.has_finished())) T.first = performance.now();
      }
      if (roots.length === %d && doc.is_idle) {
        if (T.first === undefined) T.first = performance.now();
        T.all = performance.now();
        return;
      }
    }
    requestAnimationFrame(poll);
  }
  requestAnimationFrame(poll);
})();
</script>
"""


def build_bokeh(figs: tuple[Figure, ...]) -> str:
    """Self-contained HTML page, Bokeh (one document, ``file_html`` with INLINE resources)."""
    from bokeh.document import Document
    from bokeh.embed import file_html
    from bokeh.layouts import gridplot
    from bokeh.plotting import figure
    from bokeh.resources import INLINE

    roots = []
    for fig in figs:
        n = len(fig.panels)
        plots = []
        for r, panel in enumerate(fig.panels):
            p = figure(width=1180, height=(fig.height_px - 60) // n,
                       title=fig.title if r == 0 else None,
                       x_axis_type="log" if fig.xlog else "linear",
                       y_axis_type="log" if panel.ylog else "linear",
                       x_axis_label=fig.xlabel if r == n - 1 else None,
                       y_axis_label=panel.ylabel)
            if plots:  # stacked panels share the x range (pan/zoom together)
                p.x_range = plots[0].x_range
            for k, tr in enumerate(panel.traces):
                color = COLORS[k % len(COLORS)]
                legend = {"legend_label": tr.name} if r == 0 else {}
                if tr.kind == "bar":
                    p.vbar(x=tr.x, top=tr.y, width=0.8, color=color, **legend)
                else:
                    p.line(tr.x, tr.y, line_width=1, color=color, **legend)
            plots.append(p)
        roots.append(gridplot([[p] for p in plots], merge_tools=True))
    doc = Document()
    # file_html(list_of_roots) re-walks every model of the document on each add_root
    # (quadratic: ~20 s of 39 s for this set); freezing defers that to one walk.
    with doc.models.freeze():
        for root in roots:
            doc.add_root(root)
    html = file_html(doc, resources=INLINE, title="report")
    return html.replace("</body>", _BOKEH_PROBE_JS % len(figs) + "</body>", 1)


# ---------------------------------------------------------------- browser


@dataclass(frozen=True)
class LoadResult:
    """Load times of one page in Chromium, from navigation start [ms], plus page checks."""

    first_ms: float
    all_ms: float
    errors: tuple[str, ...] = field(default=())


def load_page(browser: Browser, path: Path, *, check_js: str | None = None
              ) -> tuple[LoadResult, object]:
    """Open ``path`` in a fresh browser context; wait until ``window.__fsm.all`` is set.

    ``check_js`` (optional) is evaluated after rendering; its value is returned second.
    """
    ctx = browser.new_context(viewport=VIEWPORT)
    page = ctx.new_page()
    errors: list[str] = []
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: errors.append(f"uncaught: {e}"))
    page.goto(path.as_uri(), wait_until="load", timeout=LOAD_TIMEOUT_MS)
    page.wait_for_function("() => window.__fsm && (window.__fsm.all !== undefined"
                           " || window.__fsm.error !== undefined)",
                           timeout=LOAD_TIMEOUT_MS, polling=50)
    t = page.evaluate("() => window.__fsm")
    if "error" in t:
        errors.append(f"render promise rejected: {t['error']}")
    checked = page.evaluate(check_js) if check_js else None
    ctx.close()
    return LoadResult(t.get("first", float("nan")), t.get("all", float("nan")),
                      tuple(errors)), checked


# Typed-array check: what plotly.js decoded for figure 0, trace 0 (x and y of the Bode
# magnitude), and how many figure divs hold a drawn plot.
_PLOTLY_CHECK_JS = """() => {
  const gd = document.getElementById('fig0');
  const tr = gd._fullData[0];
  const sum = (a) => Array.from(a).reduce((s, v) => s + v, 0);
  return {version: Plotly.version, n_drawn: document.querySelectorAll('.js-plotly-plot').length,
          x_type: tr.x.constructor.name,
          n: tr.x.length, x_sum: sum(tr.x), y_sum: sum(tr.y),
          y_range: gd._fullLayout.yaxis.range};
}"""
# Bokeh: number of root views, and of canvases (inside shadow roots) actually drawn.
_BOKEH_CHECK_JS = """() => {
  let canvases = 0;
  const walk = (root) => root.querySelectorAll('*').forEach((el) => {
    if (el.tagName === 'CANVAS') canvases++;
    if (el.shadowRoot) walk(el.shadowRoot);
  });
  walk(document);
  return {version: Bokeh.version, n_roots: Bokeh.documents[0].roots().length,
          n_canvas: canvases};
}"""


# ---------------------------------------------------------------- main


@dataclass(frozen=True)
class VariantResult:
    """Medians for one library variant: sizes [MB], times [ms]."""

    name: str
    html_mb: float
    build_ms: float
    first_ms: float
    all_ms: float
    errors: tuple[str, ...]
    check: object


def run_variant(name: str, build: Callable[[], str], browser: Browser, outdir: Path,
                *, repeats: int, check_js: str, build_ms: float | None = None) -> VariantResult:
    """Time ``build`` (unless ``build_ms`` is given), write the page, load it ``repeats`` times."""
    holder: list[str] = []

    def once() -> None:
        holder[:] = [build()]  # keep only the last page: each is tens of MB

    if build_ms is None:
        build_ms = timed_runs(once, repeats, warm_up=False)[0] * 1e3
    else:
        once()
    html = holder[0]
    path = outdir / (name.replace(" ", "_").replace(",", "").replace("(", "").replace(")", "")
                     + ".html")
    path.write_text(html, encoding="utf-8")
    load_page(browser, path)  # warm-up: OS file cache, browser start-up paths
    loads, errors, check = [], [], None
    for _ in range(repeats):
        res, check = load_page(browser, path, check_js=check_js)
        loads.append(res)
        errors.extend(e for e in res.errors if e not in errors)
    return VariantResult(name, len(html.encode("utf-8")) / 1e6, build_ms,
                         statistics.median(r.first_ms for r in loads),
                         statistics.median(r.all_ms for r in loads), tuple(errors), check)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--keep", type=Path, default=None,
                        help="folder to keep the generated HTML pages in")
    args = parser.parse_args()

    # imports outside the timed builds (the runs are not warmed up: a Bokeh build is ~20 s)
    import bokeh.plotting  # noqa: F401
    import plotly.graph_objects  # noqa: F401

    figs = make_figure_set(seed=0)
    n_points = sum(f.n_points for f in figs)
    js = plotly_js()
    print(f"{len(figs)} figures, {n_points / 1e6:.2f} M points drawn (float32); plotly "
          f"{version('plotly')} (plotly.js in package: {len(js) / 1e6:.2f} MB), "
          f"bokeh {version('bokeh')}, playwright {version('playwright')}")

    with tempfile.TemporaryDirectory() as tmp, sync_playwright() as pw:
        outdir = args.keep or Path(tmp)
        outdir.mkdir(parents=True, exist_ok=True)
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
        print(f"browser: Chromium {browser.version}, viewport {VIEWPORT['width']}x"
              f"{VIEWPORT['height']} px, {args.repeats} loads per variant (+1 warm-up)")
        results = [run_variant("Plotly A (dicts, typed arrays)",
                               lambda: build_plotly_a(figs, js), browser, outdir,
                               repeats=args.repeats, check_js=_PLOTLY_CHECK_JS)]
        # Lazy page differs from A only in ~30 lines of JS: same build cost as A.
        results.append(run_variant("Plotly A lazy (IntersectionObserver)",
                                   lambda: build_plotly_a(figs, js, lazy=True), browser, outdir,
                                   repeats=args.repeats, check_js=_PLOTLY_CHECK_JS,
                                   build_ms=results[0].build_ms))
        results.append(run_variant("Plotly B (graph_objects)", lambda: build_plotly_b(figs, js),
                                   browser, outdir, repeats=args.repeats,
                                   check_js=_PLOTLY_CHECK_JS))
        results.append(run_variant("Bokeh (file_html, INLINE)", lambda: build_bokeh(figs),
                                   browser, outdir, repeats=args.repeats,
                                   check_js=_BOKEH_CHECK_JS))
        browser.close()

    report(results, figs)
    # the machine may be shared: say how busy it was (times scale with it)
    print(f"load average (1, 5, 15 min) at the end: {os.getloadavg()}, {os.cpu_count()} CPUs")


def _check_typed_arrays(check: dict[str, object], figs: tuple[Figure, ...]) -> str:
    """Compare what plotly.js decoded for figure 0, trace 0 with the float32 arrays sent."""
    tr = figs[0].panels[0].traces[0]
    want_x, want_y = float(tr.x.astype(np.float64).sum()), float(tr.y.astype(np.float64).sum())
    got_x, got_y = float(check["x_sum"]), float(check["y_sum"])  # type: ignore[arg-type]
    # both sums add the same float32 values in float64, only the order may differ: 1e-9 rel
    ok = (check["n"] == tr.x.size and abs(got_x - want_x) <= 1e-9 * abs(want_x)
          and abs(got_y - want_y) <= 1e-9 * abs(want_y))
    return (f"{'decoded correctly' if ok else 'MISMATCH'}: {check['n']} points as "
            f"{check['x_type']}, sum x {got_x:.6g} (sent {want_x:.6g}), "
            f"sum y {got_y:.6g} (sent {want_y:.6g}), y range {check['y_range']}")


def report(results: list[VariantResult], figs: tuple[Figure, ...]) -> None:
    """Print the table, the ratios Plotly A : Bokeh, page checks and console errors."""
    print()
    print(f"{'library / variant':38s} {'HTML [MB]':>9s} {'build [ms]':>10s} "
          f"{'first screen [ms]':>17s} {'all rendered [ms]':>17s}")
    for r in results:
        print(f"{r.name:38s} {r.html_mb:9.2f} {r.build_ms:10.0f} {r.first_ms:17.0f} "
              f"{r.all_ms:17.0f}")
    a, bokeh = results[0], results[-1]
    print(f"\nratios Plotly A : Bokeh   size {a.html_mb / bokeh.html_mb:.2f}   "
          f"build {a.build_ms / bokeh.build_ms:.2f}   first screen "
          f"{a.first_ms / bokeh.first_ms:.2f}   all rendered {a.all_ms / bokeh.all_ms:.2f}")
    lazy = results[1]
    print(f"ratios Plotly A lazy : Bokeh   first screen {lazy.first_ms / bokeh.first_ms:.2f}   "
          f"all rendered {lazy.all_ms / bokeh.all_ms:.2f}")
    print("(times are medians; load times from navigation start; build = data -> HTML string)")
    print()
    for r in results:
        check = r.check
        if isinstance(check, dict) and "x_sum" in check:
            print(f"{r.name}: plotly.js {check['version']}, {check['n_drawn']} of {len(figs)} "
                  f"figures drawn; typed arrays {_check_typed_arrays(check, figs)}")
        elif isinstance(check, dict):
            print(f"{r.name}: BokehJS {check['version']}, {check['n_roots']} of {len(figs)} "
                  f"root views, {check['n_canvas']} canvases drawn")
        print(f"  console errors: {'; '.join(r.errors) if r.errors else 'none'}")


if __name__ == "__main__":
    main()
