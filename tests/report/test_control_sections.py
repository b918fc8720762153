"""The control chapters (ESRF study 5–10) as report sections: order, words, units, figures."""

from __future__ import annotations

import ast
import hashlib
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from fsmbench.bench.blocks import PlantModel
from fsmbench.bench.params import Bench
from fsmbench.control.study import DesignResult, design_study
from fsmbench.report.figures.spec import Figure, Line
from fsmbench.report.html import Note, Section, Table, iter_figures, render_report, visible_text
from fsmbench.report.sections.control import control_sections
from fsmbench.stages import DesignStage
from fsmbench.twin.verify import verify_on_twin

TITLES = ["5. Plant uncertainty", "6. Plant scaling and control objective",
          "7. Plant analysis", "8. Active damping", "9. Decentralised control of the Sercalo",
          "10. Newport control"]
CODE_KEY = re.compile(r"_controller|_hz|_db")
UNIT = re.compile(r"\[[^\[\]]+\]")
SRC = Path(__file__).resolve().parents[2] / "src" / "fsmbench"


@pytest.fixture(scope="session")
def stage(nominal_plant: PlantModel, bench: Bench) -> DesignStage:
    """The design stage's objects on the nominal plant, built once (about 25 s with the twin).

    Built from its two parts rather than by ``stages.design_stage``, which
    also writes the controller files this module does not read.
    """
    result = design_study(nominal_plant, bench=bench)
    # 6 s of twin (2 s settling) instead of the stage's 12 s: the table's wording and
    # consistency are under test here, not the twin's statistics (tests/twin).
    check = verify_on_twin(result.controllers["fsmbench_controller"], bench=bench,
                           plant=nominal_plant, name="fsmbench controller", seed=0,
                           duration_s=6.0)
    return DesignStage(result=result, twin_check=check, payload=result.to_json())


@pytest.fixture(scope="session")
def sections(stage: DesignStage) -> list[Section]:
    return control_sections(stage.result, twin_check=stage.twin_check,
                            plant_source="physical model, nominal parameters")


def _digest(line: Line) -> str:
    return hashlib.sha1(line.x.tobytes() + line.y.tobytes()).hexdigest()


# Reference curves every plot of their kind carries; not results.
REFERENCES = {"|L| = 1", "critical point −1"}


def test_six_sections_in_the_seeds_order(sections: list[Section]) -> None:
    assert [s.title for s in sections] == TITLES
    assert all(s.blocks for s in sections)


def test_figure_keys_unique_and_seed_figures_present(sections: list[Section]) -> None:
    figs = list(iter_figures(sections))
    keys = [f.key for f in figs]
    assert len(keys) == len(set(keys))
    refs = {f.seed_ref: f.key for f in figs if f.seed_ref}
    assert refs == {"Fig. 41": "fig41_seed_loop_gain", "Fig. 42": "fig42_newport_to_beam",
                    "Fig. 43": "fig43_newport_loop_gain"}
    render_report(title="control", sections=sections)  # the renderer accepts every block


def test_no_result_curve_in_two_figures(sections: list[Section]) -> None:
    seen: dict[str, str] = {}
    for fig in iter_figures(sections):
        mine = {_digest(t) for p in fig.panels for t in p.traces
                if isinstance(t, Line) and t.name not in REFERENCES
                and t.x.size > 2}  # a marker (the 6.1 bound), not a curve
        for d in mine:
            assert d not in seen, f"{fig.key} repeats a curve of {seen.get(d)}"
            seen[d] = fig.key


def test_every_axis_label_has_a_unit(sections: list[Section]) -> None:
    for fig in iter_figures(sections):
        for p in fig.panels:
            for label in (p.x_label, p.y_label):
                assert UNIT.search(label), f"{fig.key}: axis label '{label}' has no unit"


def test_no_code_keys_in_any_text(sections: list[Section]) -> None:
    texts = [t for t in visible_text(sections) if t]
    assert len(texts) > 200  # the walk reached every block
    bad = [t for t in texts if CODE_KEY.search(t)]
    assert not bad, bad


def test_only_nyquist_panels_fix_a_window(sections: list[Section]) -> None:
    fixed = []
    for fig in iter_figures(sections):
        for p in fig.panels:
            if p.x_range is not None or p.y_range is not None:
                fixed.append(fig.key)
                assert p.equal_aspect
                assert p.x_range is not None and p.y_range is not None
                # the window is centred on the critical point −1
                assert np.mean(p.x_range) == pytest.approx(-1.0)
                assert np.mean(p.y_range) == pytest.approx(0.0, abs=1e-12)
    assert sorted(set(fixed)) == ["fsmbench_controller_nyquist", "seed_controller_nyquist"]


def test_iff_section_explains_e25(sections: list[Section], stage: DesignStage) -> None:
    iff = sections[3]
    notes = [b for b in iff.blocks if isinstance(b, Note)]
    assert any(n.ref == "errata E25" and "unobservable" in n.text for n in notes)
    figs = [b for b in iff.blocks if isinstance(b, Figure)]
    assert [f.key for f in figs] == ["iff_uc_to_vp"]
    # the note sits before the figure it explains, and the figure carries its own
    idx = next(i for i, b in enumerate(iff.blocks) if isinstance(b, Note))
    assert iff.blocks.index(figs[0]) == idx + 1
    assert not stage.result.iff.loop_stable and "E25" in figs[0].note
    text = " ".join(b for b in iff.blocks if isinstance(b, str))
    assert "UNSTABLE" in text


def _table(sec: Section, start: str) -> Table:
    return next(b for b in sec.blocks if isinstance(b, Table) and b.caption.startswith(start))


def test_margins_tables_give_the_objective_verdict(sections: list[Section],
                                                  stage: DesignStage) -> None:
    res: DesignResult = stage.result
    sec9 = sections[4]
    for who, lp in (("the ESRF study's controller", res.seed), ("fsmbench's controller",
                                                           res.fsmbench)):
        tab = _table(sec9, f"Margins of {who}")
        assert tab.header == ("quantity", "h", "v")
        rows = {r[0]: r[1:] for r in tab.rows}
        verdict = next(v for k, v in rows.items() if k.startswith("meets the objective of 6.1"))
        assert verdict == tuple("yes" if lp.axes[a].meets_objective else "no" for a in "hv")
        pm = rows["phase margin [deg]"]
        assert [float(x) for x in pm] == pytest.approx(
            [lp.axes[a].margins.phase_margin_deg for a in "hv"], abs=0.051)  # printed to 0.1°
    text = " ".join(b for b in sec9.blocks if isinstance(b, str))
    assert "the ESRF study's controller does NOT meet it" in text  # E27 on this plant
    assert "fsmbench's controller meets it" in text
    # every erratum of the control chapters is cited next to its result
    cited = " ".join([b.ref for s in sections for b in s.blocks if isinstance(b, Note)]
                     + [f.note for f in iter_figures(sections)])
    assert all(f"E{n}" in cited for n in range(22, 28))


def test_robustness_small_multiples_mark_the_unstable_cases(sections: list[Section],
                                                           stage: DesignStage) -> None:
    res: DesignResult = stage.result
    figs = {f.key: f for f in iter_figures(sections)}
    for key, rob in (("seed_controller_robustness", res.seed_robustness),
                     ("fsmbench_controller_robustness", res.robustness)):
        assert rob is not None
        fig = figs[key]
        assert len(fig.panels) == 6 and fig.columns == 3  # h and v × three resonance factors
        curves = [t for p in fig.panels for t in p.traces]
        assert len(curves) == 2 * len(rob.loops)
        marked = [(p.title, "UNSTABLE" in t.name) for p in fig.panels for t in p.traces]
        n_unstable = sum(not (lp.stable and lp.nyquist.stable) for lp in rob.loops)
        # each unstable case is marked on the axis whose loop alone is unstable
        expected = sum(not lp.axes[a].stable for lp in rob.loops for a in "hv")
        assert sum(m for _, m in marked) == expected
        assert (expected == 0) == (n_unstable == 0)
    assert res.seed_robustness is not None
    assert not res.seed_robustness.all_stable  # the seed's notch is not robust (E27)
    text = " ".join(b for b in sections[4].blocks if isinstance(b, str))
    assert "perturbed plants are unstable with the ESRF study's controller" in text


def test_twin_table_matches_the_check(sections: list[Section], stage: DesignStage) -> None:
    tab = _table(sections[4], "fsmbench's controller simulated on the packaged twin")
    chk = stage.twin_check
    for row, axis in zip(tab.rows, "hv", strict=True):
        assert float(row[1]) == pytest.approx(1e6 * chk.measured_rms_rad[axis], abs=0.006)
        assert float(row[2]) == pytest.approx(1e6 * chk.predicted_rms_rad[axis], abs=0.006)
        # the ratio printed is measured over predicted (to the 3 decimals printed)
        assert float(row[3]) == pytest.approx(float(row[1]) / float(row[2]), abs=2e-3)


def _imports_matplotlib(path: Path) -> bool:
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                 else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
        if any(n.split(".")[0] == "matplotlib" for n in names):
            return True
    return False


def test_control_numerics_do_not_draw() -> None:
    files = [*sorted((SRC / "control").glob("*.py")), SRC / "report" / "figures" / "control.py",
             SRC / "report" / "sections" / "control.py"]
    assert not [f.name for f in files if _imports_matplotlib(f)]
    # python-control itself imports matplotlib.pyplot; fsmbench must add nothing to it
    # (no backend switch, no figure module).
    code = ("import sys, control\n"
            "before = {m for m in sys.modules if m.startswith('matplotlib')}\n"
            "import fsmbench.control, fsmbench.report.sections.control\n"
            "after = {m for m in sys.modules if m.startswith('matplotlib')}\n"
            "print(sorted(after - before))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "[]"


# ------------------------------------------------- Bode figures (issue 33, "Figures")

LOOP_GAIN_FIGURES = {"fig41_seed_loop_gain": "seed", "fsmbench_controller_loop_gain": "fsmbench",
                     "fig43_newport_loop_gain": "newport"}
BODE_FIGURES = (*LOOP_GAIN_FIGURES, "iff_uc_to_vp")


def _figures(sections: list[Section]) -> dict[str, Figure]:
    return {f.key: f for f in iter_figures(sections)}


def test_bode_phase_spans_the_band_of_its_magnitude(sections: list[Section]) -> None:
    figs = _figures(sections)
    for key in BODE_FIGURES:
        fig = figs[key]
        n = fig.columns
        mags, phases = fig.panels[:n], fig.panels[n:]
        assert all("Phase" in p.y_label for p in phases), key
        for mag, ph in zip(mags, phases, strict=True):
            curves = [(m, p) for m, p in zip(mag.traces, ph.traces, strict=False)
                      if m.x.size > 2]
            assert curves, key
            for m, p in curves:
                drawn = p.x[np.isfinite(p.y)]
                assert drawn.min() == m.x.min() and drawn.max() == m.x.max(), (key, p.name)
        lo, hi = mags[0].traces[0].x[[0, -1]]
        assert f"from {lo:.3g} Hz to {hi:.4g} Hz" in fig.caption, key


def test_loop_phase_anchored_at_the_crossover_reads_the_margins(sections: list[Section],
                                                                stage: DesignStage) -> None:
    figs = _figures(sections)
    for key, attr in LOOP_GAIN_FIGURES.items():
        lp = getattr(stage.result, attr)
        for i, axis in enumerate("hv"):
            m = lp.axes[axis].margins
            phase = figs[key].panels[2 + i].traces[0]
            at = float(np.interp(np.log(m.crossover_hz), np.log(phase.x), phase.y))
            assert at + 180.0 == pytest.approx(m.phase_margin_deg, abs=2.0), (key, axis)
    # fsmbench's loop is conditionally stable: its phase is below −180° where |L| ≫ 1,
    # and that region is drawn.
    fig = figs["fsmbench_controller_loop_gain"]
    mag, phase = fig.panels[0].traces[0], fig.panels[2].traces[0]
    low = mag.x < 1.0
    assert np.all(mag.y[low] > 40.0) and np.all(phase.y[low] < -180.0)


def test_loop_gain_magnitude_in_db_with_its_margins_marked(sections: list[Section],
                                                           stage: DesignStage) -> None:
    figs = _figures(sections)
    n_reduction = 0
    for key, attr in LOOP_GAIN_FIGURES.items():
        lp = getattr(stage.result, attr)
        fig = figs[key]
        for i, axis in enumerate("hv"):
            mag, phase = fig.panels[i], fig.panels[2 + i]
            assert mag.y_label == f"|L{axis}| [dB]" and not mag.y_log
            assert [r.value for r in mag.rules if r.axis == "y"] == [0.0]
            inband = lp.f_hz <= lp.nyquist_hz
            np.testing.assert_allclose(mag.traces[0].y,
                                       20 * np.log10(np.abs(lp.loop[inband, i, i])))
            m = lp.axes[axis].margins
            marks = {t.name.split(" margin")[0]: t for t in mag.traces[1:]}
            gm = marks[f"{axis}: gain"]
            assert f"{m.gain_margin_db:.1f} dB" in gm.name
            np.testing.assert_allclose(gm.x, [m.phase_crossover_hz] * 2)
            np.testing.assert_allclose(gm.y, [-m.gain_margin_db, 0.0])
            # the segment ends on the drawn |L| (within the grid's interpolation)
            on = np.interp(np.log(m.phase_crossover_hz), np.log(mag.traces[0].x),
                           mag.traces[0].y)
            assert on == pytest.approx(-m.gain_margin_db, abs=0.5)
            if np.isfinite(m.gain_reduction_margin_db):
                n_reduction += 1
                gr = marks[f"{axis}: gain-reduction"]
                assert f"{m.gain_reduction_margin_db:.1f} dB" in gr.name
                np.testing.assert_allclose(gr.x, [m.gain_reduction_crossover_hz] * 2)
                np.testing.assert_allclose(gr.y, [0.0, m.gain_reduction_margin_db])
                at = np.interp(np.log(m.gain_reduction_crossover_hz),
                               np.log(mag.traces[0].x), mag.traces[0].y)
                assert at == pytest.approx(m.gain_reduction_margin_db, abs=0.5)
            else:
                assert f"{axis}: gain-reduction" not in marks
            pm = phase.traces[1]
            assert f"phase margin {m.phase_margin_deg:.1f}°" in pm.name
            np.testing.assert_allclose(pm.y, [-180.0, -180.0 + m.phase_margin_deg])
    assert n_reduction == 2  # fsmbench's controller, both axes


def test_gain_reduction_margin_is_read_on_the_negative_real_axis(stage: DesignStage) -> None:
    for axis in "hv":
        lp = stage.result.fsmbench
        m = lp.axes[axis].margins
        assert 1.0 < m.gain_reduction_crossover_hz < m.crossover_hz
        i = "hv".index(axis)
        li = np.interp(np.log(m.gain_reduction_crossover_hz), np.log(lp.f_hz),
                       lp.loop[:, i, i].real)
        # on the negative real axis, |L| = 10^(gr / 20)
        assert li == pytest.approx(-10 ** (m.gain_reduction_margin_db / 20), rel=0.02)


def test_robustness_loop_gains_in_db(sections: list[Section]) -> None:
    figs = _figures(sections)
    for key in ("seed_controller_robustness", "fsmbench_controller_robustness"):
        for p in figs[key].panels:
            assert p.y_label.endswith("[dB]") and not p.y_log


# ------------------------------------- closed-loop step and sample-motion responses

def _balanced(sys: Any) -> Any:
    """``sys`` with its state scaled by scipy's ``matrix_balance`` (the SI plant spans ~30
    decades; python-control's step simulation needs it balanced)."""
    import control as ct
    from scipy.linalg import matrix_balance

    a, (sc, _) = matrix_balance(np.asarray(sys.A), permute=False, separate=True)
    return ct.ss(a, np.asarray(sys.B) / sc[:, None], np.asarray(sys.C) * sc[None, :], sys.D)


def test_step_responses_against_python_control(stage: DesignStage,
                                               nominal_plant: PlantModel) -> None:
    """The responses against an independent construction of the same loop:
    python-control's ``feedback`` and ``step_response`` on the Padé loop, and the
    frequency responses' DC values in closed form."""
    import control as ct

    from fsmbench.control.loops import delayed_subsystem

    res = stage.result
    assert set(res.responses) == {"seed_controller", "fsmbench_controller"}
    for name, r in res.responses.items():
        k = res.controllers[name]
        g = delayed_subsystem(nominal_plant, outputs=["Rh", "Rv"],
                              inputs=["Uch", "Ucv", "Unh", "Unv"], pade_order=r.pade_order)
        gu, gd = g[:, :2], g[:, 2:]
        # T = feedback(G K, I); S Gn = feedback(Gn, K G) seen from d: y = Gn d − G K y
        t_sys = ct.feedback(gu * k, ct.ss([], [], [], np.eye(2)))
        sgn_sys = ct.feedback(ct.ss([], [], [], np.eye(2)), gu * k) * gd
        _, y_t = ct.step_response(_balanced(t_sys), T=r.t_s)
        _, y_d = ct.step_response(_balanced(sgn_sys), T=r.t_s)
        for i in range(2):
            np.testing.assert_allclose(r.reference_step[:, i], y_t[i, i], atol=1e-6)
            np.testing.assert_allclose(r.disturbance_step_rad_per_v[:, i], y_d[i, i],
                                       atol=1e-6 * np.max(np.abs(y_d[i, i])))
        # final values: integral action, T(0) = 1 and (S Gn)(0) = 0; the curves settle there
        np.testing.assert_allclose(r.reference_final, 1.0, atol=1e-9)
        np.testing.assert_allclose(r.disturbance_final_rad_per_v, 0.0, atol=1e-9)
        np.testing.assert_allclose(r.reference_step[-1], 1.0, atol=2e-3)
        # the frequency responses are the loop analysis' own T and Fig. 42's S Gn
        lp = res.loops[name]
        for i in range(2):
            t_lp = np.interp(np.log(r.f_hz[:50]), np.log(lp.f_hz),
                             np.abs(lp.complementary[:, i, i]))
            np.testing.assert_allclose(np.abs(r.complementary[:50, i]), t_lp, rtol=1e-3)
        np.testing.assert_allclose(
            r.disturbance_rad_per_v,
            np.stack([res.newport_to_beam.closed[name][:, i, i] for i in range(2)], axis=1))
        assert np.all(np.isfinite(r.reference_step)) and r.reference_step[0, 0] == 0.0


def test_step_response_figure(sections: list[Section], stage: DesignStage) -> None:
    fig = _figures(sections)["closed_loop_step_responses"]
    assert fig.key in [b.key for b in sections[4].blocks if isinstance(b, Figure)]
    assert len(fig.panels) == 8 and fig.columns == 2
    res = stage.result
    names = {t.name for p in fig.panels for t in p.traces}
    assert names == {"with the ESRF study's controller", "with fsmbench's controller",
                     "Sercalo loop open"}
    for i, p in enumerate(fig.panels[:2]):
        assert p.y_label.endswith("[1]")
        seed = p.traces[0]
        np.testing.assert_allclose(seed.y, res.responses["seed_controller"].reference_step[:, i])
        np.testing.assert_allclose(seed.x, 1e3 * res.responses["seed_controller"].t_s)
    for p in fig.panels[2:4]:
        assert p.y_label.endswith("[µrad/V]")
    for p in fig.panels[4:]:
        assert "[dB" in p.y_label and p.x_log
    text = " ".join(b for b in sections[4].blocks if isinstance(b, str))
    over = res.responses["fsmbench_controller"].overshoot()
    assert f"fsmbench's controller: {100 * over[0]:.0f} % (h)" in text
