"""The static (matplotlib) renderer of figure specs: files, no clipping, legend, decimation."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from fsmbench.report.figures.spec import H_COLOR, V_COLOR, Bars, Figure, Label, Line, Panel, Rule
from fsmbench.report.figures.static import PNG_DPI, export_figures, render_matplotlib

N_RECORD = 1_000_000


def _bode() -> Figure:
    f_hz = np.logspace(0, 4, 400)
    s = 2j * np.pi * f_hz
    h = (2 * np.pi * 300) ** 2 / (s**2 + 2 * 0.05 * 2 * np.pi * 300 * s + (2 * np.pi * 300) ** 2)
    mag = np.abs(h)
    mag[:3] = 0.0  # a log axis leaves values ≤ 0 out
    phase = np.degrees(np.unwrap(np.angle(h * np.exp(-s * 1e-4))))
    return Figure("fig5_bode", "Plant frequency response", "c", seed_ref="Fig. 5", share_x=True,
                  panels=(
                      Panel((Line(f_hz, mag, name="h", color=H_COLOR, group="h"),
                             Line(f_hz, 0.5 * mag, name="v", color=V_COLOR, group="v")),
                            "Frequency [Hz]", "Gain [V/V]", x_log=True, y_log=True, height=2,
                            labels=(Label(300.0, 10.0, "resonance"),)),
                      Panel((Line(f_hz, phase, name="h", color=H_COLOR, group="h"),
                             Line(f_hz, phase - 10, name="v", color=V_COLOR, group="v")),
                            "Frequency [Hz]", "Phase [deg]", x_log=True,
                            rules=(Rule(-180.0, name="−180°"), Rule(1000.0, axis="x")))))


def _time() -> Figure:
    rng = np.random.default_rng(1)
    t_s = np.arange(N_RECORD) / 10_000.0
    panels = []
    for p in range(4):
        traces = []
        for k, (name, color) in enumerate((("command", H_COLOR), ("response", V_COLOR))):
            y = np.sin(2 * np.pi * (0.1 + p + k) * t_s) + 0.1 * rng.standard_normal(N_RECORD)
            y[rng.integers(N_RECORD)] = 7.0 + p  # a lone spike: must survive decimation
            y[rng.integers(N_RECORD)] = -5.0 - k
            traces.append(Line(t_s, y, name=name, color=color, group=name, decimate=True))
        panels.append(Panel(tuple(traces), "Time [s]", f"Channel {p + 1} [V]",
                            shade=(0.0, 5.0)))
    return Figure("time_record", "Time record", "c", tuple(panels), share_x=True)


def _nyquist() -> Figure:
    f_hz = np.logspace(0, 3.5, 300)
    s = 2j * np.pi * f_hz
    loop = 3 * (2 * np.pi * 100) ** 2 / (s * (s + 2 * np.pi * 50)) * np.exp(-s * 2e-4)
    return Figure("fig40_nyquist", "Open-loop Nyquist plot", "c", seed_ref="Fig. 40",
                  panels=(Panel((Line(loop.real, loop.imag, name="h"),
                                 Line(loop.real, -loop.imag, name="h", dash="dash",
                                      legend=False),
                                 Line(np.array([-1.0]), np.array([0.0]), name="critical point",
                                      markers=True, color="#d62728")),
                                "Real part [-]", "Imaginary part [-]", x_range=(-3.0, 1.0),
                                y_range=(-2.0, 2.0), equal_aspect=True,
                                rules=(Rule(-1.0, axis="x", dash="dot"),)),))


def _bars() -> Figure:
    cats = ("sensor noise", "actuator noise", "quantisation", "disturbance")
    return Figure("budget_bars", "Error budget", "c", columns=2, panels=(
        Panel((Bars(cats, np.array([3.0, 1.5, 0.2, 4.0]), name="h", color=H_COLOR),
               Bars(cats, np.array([2.0, 2.5, 0.1, 5.5]), name="v", color=V_COLOR)),
              "Contributor", "rms beam angle [µrad]"),
        Panel((Bars(cats[:2], np.array([-1.0, 2.0]), name="difference"),),
              "Contributor", "Difference [µrad]", title="h − v")))


@pytest.fixture(scope="module")
def specs() -> list[Figure]:
    return [_bode(), _time(), _nyquist(), _bars()]


@pytest.fixture(scope="module")
def drawn(specs: list[Figure]) -> list[tuple[Figure, object]]:
    out = []
    for spec in specs:
        mfig = render_matplotlib(spec)
        mfig.canvas.draw()  # limits and equal aspect as saved
        out.append((spec, mfig))
    return out


def test_export_writes_png_and_pdf(specs: list[Figure], drawn: list[tuple[Figure, object]],
                                   tmp_path: Path) -> None:
    size_in = {spec.key: mfig.get_size_inches() for spec, mfig in drawn}
    out = tmp_path / "figures"
    paths = export_figures(specs, out, formats=("png", "pdf"), workers=1)
    assert paths == [out / f"{s.key}.{fmt}" for s in specs for fmt in ("png", "pdf")]
    assert sorted(p.name for p in out.iterdir()) == sorted(p.name for p in paths)  # no .part
    for path in paths:
        data = path.read_bytes()
        # A figure is tens of kB; a few MB would mean undecimated lines.
        assert 5_000 < len(data) < 3_000_000, (path.name, len(data))
        if path.suffix == ".png":
            assert data.startswith(b"\x89PNG\r\n\x1a\n")
            with Image.open(path) as img:
                w_in, h_in = size_in[path.stem]
                # The canvas has the whole pixels of the size (matplotlib truncates).
                assert img.size == (int(w_in * PNG_DPI), int(h_in * PNG_DPI))
                # PNG stores whole pixels per metre: 150 dpi is kept to 1e-4.
                assert img.info["dpi"] == pytest.approx((PNG_DPI, PNG_DPI), rel=1e-4)
        else:
            assert data.startswith(b"%PDF-") and data.rstrip().endswith(b"%%EOF")
            assert b"/CreationDate" not in data  # reproducible


def test_export_is_reproducible_and_replaces(specs: list[Figure], tmp_path: Path) -> None:
    first = export_figures(specs[2:3], tmp_path, formats=["pdf"], workers=1)[0].read_bytes()
    (tmp_path / "fig40_nyquist.png").write_bytes(b"old")
    paths = export_figures(specs[2:3], tmp_path, formats=["pdf", "png"], workers=1)
    assert paths[0].read_bytes() == first
    assert paths[1].read_bytes().startswith(b"\x89PNG")


def test_worker_processes_write_the_same_files(specs: list[Figure], tmp_path: Path) -> None:
    some = specs[1:3]  # a decimated record and a fixed-range figure
    here = export_figures(some, tmp_path / "one", formats=("png", "pdf"), workers=1)
    pool = export_figures(some, tmp_path / "two", formats=("png", "pdf"), workers=2)
    assert [p.name for p in here] == [p.name for p in pool]
    for a, b in zip(here, pool, strict=True):  # records decimated before sending: same drawing
        assert a.read_bytes() == b.read_bytes(), a.name


def _plotted(spec: Figure, i: int, axis: str) -> np.ndarray:
    """Every finite value the spec places on one axis of panel ``i`` (log: every positive one)."""
    panel = spec.panels[i]
    log = panel.x_log if axis == "x" else panel.y_log
    values: list[np.ndarray] = []
    for trace in panel.traces:
        if isinstance(trace, Line):
            values.append(trace.x if axis == "x" else trace.y)
        elif axis == "y":
            values.append(trace.values)
    values += [np.array([r.value]) for r in panel.rules if r.axis == axis]
    values += [np.array([lab.x if axis == "x" else lab.y]) for lab in panel.labels]
    v = np.concatenate(values) if values else np.array([])
    return v[np.isfinite(v) & (v > 0)] if log else v[np.isfinite(v)]


def test_nothing_is_clipped(drawn: list[tuple[Figure, object]]) -> None:
    checked = 0
    for spec, mfig in drawn:
        for i, (panel, ax) in enumerate(zip(spec.panels, mfig.axes, strict=True)):
            for axis, fixed in (("x", panel.x_range), ("y", panel.y_range)):
                lo, hi = sorted(ax.get_xlim() if axis == "x" else ax.get_ylim())
                if fixed is not None:
                    assert (lo, hi) == pytest.approx(fixed, rel=1e-12), (spec.key, axis)
                    continue
                if axis == "x" and all(isinstance(t, Bars) for t in panel.traces):
                    continue  # categories: checked on the bars below
                values = _plotted(spec, i, axis)
                assert values.size
                assert lo <= values.min() and values.max() <= hi, (spec.key, i, axis)
                checked += 1
            bars = [b for b in panel.traces if isinstance(b, Bars)]
            if bars:  # every bar, with its category, inside the x range
                lo, hi = ax.get_xlim()
                for patch in ax.patches:
                    assert lo <= patch.get_x() and patch.get_x() + patch.get_width() <= hi
                assert len(ax.patches) == sum(b.values.size for b in bars)
                assert [t.get_text() for t in ax.get_xticklabels()] == list(
                    dict.fromkeys(c for b in bars for c in b.categories))
    assert checked == 14  # bode 2 × 2 axes, time 4 × 2, bars 2 × y (Nyquist: both fixed)


def test_log_axes_and_fixed_ranges(drawn: list[tuple[Figure, object]]) -> None:
    (_, bode), _, (_, nyq), _ = drawn
    mag, phase = bode.axes
    assert (mag.get_xscale(), mag.get_yscale(), phase.get_yscale()) == ("log", "log", "linear")
    assert mag.get_shared_x_axes().joined(mag, phase)
    assert not any(t.get_visible() and t.get_text() for t in mag.get_xticklabels())
    assert phase.get_xlabel() == "Frequency [Hz]" and mag.get_xlabel() == ""
    y = next(ln for ln in mag.get_lines() if ln.get_gid() == "p0t0").get_ydata()
    assert np.isnan(y[:3]).all() and np.isfinite(y[3:]).all()  # zeros left out on log y
    assert nyq.axes[0].get_aspect() == 1.0
    assert bode.get_suptitle() == "Plant frequency response (ESRF study Fig. 5)"


def test_legend_has_one_entry_per_group(drawn: list[tuple[Figure, object]]) -> None:
    names = {spec.key: [t.get_text() for t in mfig.legends[0].get_texts()]
             for spec, mfig in drawn}
    assert names == {"fig5_bode": ["h", "v"], "time_record": ["command", "response"],
                     "fig40_nyquist": ["h", "critical point"],
                     "budget_bars": ["h", "v", "difference"]}
    _, time_fig = drawn[1]
    handles = time_fig.legends[0].legend_handles
    assert [h.get_color() for h in handles] == [H_COLOR, V_COLOR]


def test_decimated_lines_keep_every_extreme(drawn: list[tuple[Figure, object]]) -> None:
    spec, mfig = drawn[1]
    for i, (panel, ax) in enumerate(zip(spec.panels, mfig.axes, strict=True)):
        for k, trace in enumerate(panel.traces):
            assert isinstance(trace, Line)
            line = next(ln for ln in ax.get_lines() if ln.get_gid() == f"p{i}t{k}")
            x, y = line.get_xdata(), line.get_ydata()
            assert y.size <= 2 * 2000 + 2000  # decimated: at most 2 points per bin + a tail
            assert y.max() == trace.y.max() and y.min() == trace.y.min()  # exactly
            assert np.all(np.diff(x) >= 0) and np.isin(x, trace.x).all()  # samples, in order


def test_bad_input_is_refused(specs: list[Figure], tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="figure format 'svg'"):
        export_figures(specs[:1], tmp_path, formats=["svg"])
    with pytest.raises(ValueError, match="used twice"):
        export_figures([specs[2], specs[2]], tmp_path, formats=["pdf"])
    bad = Figure("bad_range", "t", "c", (Panel((Line([1.0, 10.0], [1.0, 2.0]),), "x [Hz]",
                                                "y [-]", x_log=True, x_range=(0.0, 10.0)),))
    with pytest.raises(ValueError, match=r"figure bad_range, panel 1: x range .* positive"):
        export_figures([specs[2], bad], tmp_path, formats=["png"], workers=1)
    # Nothing for the refused calls, nothing for the bad figure.
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fig40_nyquist.png"]


def test_importing_the_report_does_not_import_matplotlib() -> None:
    code = ("import sys, fsmbench.report, fsmbench.report.figures.static; "
            "sys.exit('matplotlib' in sys.modules)")
    assert subprocess.run([sys.executable, "-c", code], check=False).returncode == 0
