"""Monte Carlo: every draw that breaks a requirement is named, and the verdict says so at ≥ 5 %."""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fsmbench.bench.params import Bench, default_bench
from fsmbench.report.sections.montecarlo import montecarlo_section, robustness_sentence
from fsmbench.scale.breaches import (
    NOTABLE_SHARE,
    Limits,
    breach_sentence,
    requirement_outcomes,
)
from fsmbench.scale.montecarlo import (
    PARAMETERS,
    DrawResult,
    MonteCarloResult,
    MonteCarloSetup,
    Ranges,
    run_montecarlo,
)
from fsmbench.scale.montecarlo_run import designed_controller, format_table

N = 6  # draws simulated: enough for a limit between the smallest and largest margins
DURATION_S = 5.0  # the shortest record the repeatability experiments accept is 4.5 s

# (requirement name, metric key prefix, per axis)
_JUDGED = (("gain_margin", "gain_margin_db", True), ("phase_margin", "phase_margin_deg", True),
           ("modulus_margin", "modulus_margin", True), ("stable", "spectral_radius", False))


@pytest.fixture(scope="module")
def bench() -> Bench:
    return default_bench()


@pytest.fixture(scope="module")
def simulated(bench: Bench) -> MonteCarloResult:
    setup = MonteCarloSetup(bench=bench, controller=designed_controller(bench),
                            duration_s=DURATION_S, settle_s=2.0)
    return run_montecarlo(setup, n=N, seed=11)


def _recount(draws: Sequence[DrawResult], limits: Limits) -> dict[str, set[int]]:
    """Which draws break each requirement, from the per-draw values with numpy alone."""
    stable = np.array([d.stable for d in draws])
    index = np.array([d.index for d in draws])
    bound = {"gain_margin": limits.gain_margin_min_db,
             "phase_margin": limits.phase_margin_min_deg,
             "modulus_margin": limits.modulus_margin_min}
    out = {"stable": set(index[~stable].tolist())}
    for name, key, _per_axis in _JUDGED[:3]:
        ok = np.ones(len(draws), dtype=bool)
        for a in "hv":
            x = np.array([d.metrics[f"{key}.{a}"] for d in draws], dtype=float)
            with np.errstate(invalid="ignore"):
                ok &= np.isposinf(x) | (np.isfinite(x) & (x >= bound[name]))
        out[name] = set(index[~(ok & stable)].tolist())
    return out


def _check(result: MonteCarloResult) -> dict[str, Any]:
    """The outcomes equal the recount; each breach carries its draw's seed, factors, values."""
    limits = result.setup.limits
    expected = _recount(result.draws, limits)
    by_index = {d.index: d for d in result.draws}
    outcomes = {o.requirement.name: o for o in result.requirements()}
    assert set(outcomes) == {name for name, _k, _p in _JUDGED}
    for name, key, per_axis in _JUDGED:
        o = outcomes[name]
        assert {b.index for b in o.breaches} == expected[name], name
        assert [b.index for b in o.breaches] == sorted(expected[name])
        assert o.share == len(expected[name]) / len(result.draws)
        for b in o.breaches:
            d = by_index[b.index]
            assert (b.noise_seed, dict(b.factors)) == (d.noise_seed, dict(d.factors))
            if per_axis:
                np.testing.assert_array_equal([b.values[a] for a in "hv"],
                                              [d.metrics[f"{key}.{a}"] for a in "hv"])
            else:
                assert b.values["loop"] == d.metrics[key]
    return {name: o.to_json() for name, o in outcomes.items()}


def test_simulated_draws_below_a_tight_limit_are_named(simulated: MonteCarloResult) -> None:
    # Limits at the median of the draws' worse axis: some draws break each margin by
    # construction, some meet it.
    worse = {k: np.min([simulated.metric(f"{k}.{a}") for a in "hv"], axis=0)
             for k in ("gain_margin_db", "phase_margin_deg", "modulus_margin")}
    tight = Limits(gain_margin_min_db=float(np.median(worse["gain_margin_db"])),
                   phase_margin_min_deg=float(np.median(worse["phase_margin_deg"])),
                   modulus_margin_min=float(np.median(worse["modulus_margin"])))
    result = dataclasses.replace(simulated, setup=dataclasses.replace(simulated.setup,
                                                                      limits=tight))
    doc = result.to_json()
    assert (doc["format"], doc["format_version"]) == ("fsmbench.montecarlo", 3)
    json.dumps(doc, allow_nan=False)
    outcomes = _check(result)
    for name in ("gain_margin", "phase_margin", "modulus_margin"):
        assert 0 < outcomes[name]["broken"] < N, name
    assert [r["name"] for r in doc["requirements"]] == list(outcomes)
    assert doc["requirements"] == list(outcomes.values())
    assert doc["limits"]["phase_margin_min_deg"] == tight.phase_margin_min_deg
    phase = outcomes["phase_margin"]
    first = phase["breaches"][0]
    sentence = breach_sentence(phase, first)
    assert sentence.startswith(f"draw {first['index']}: phase margin ")
    assert f"< {tight.phase_margin_min_deg:.1f}°" in sentence
    assert f"noise seed {first['noise_seed']}" in sentence and "resonance ×" in sentence
    # The command's table and the report name every breaking draw.
    table = format_table(result)
    assert f"broken by {phase['broken']} of {N}" in table
    assert all(breach_sentence(phase, b) in table for b in phase["breaches"])
    section = montecarlo_section(doc)
    cells = {c for block in section.blocks if hasattr(block, "rows")
             for row in block.rows for c in row}
    assert ", ".join(str(b["index"]) for b in phase["breaches"]) in cells


def test_the_design_limits_are_the_default(simulated: MonteCarloResult) -> None:
    assert simulated.setup.limits == Limits()
    _check(simulated)


def _draw(index: int, *, stable: bool, metrics: dict[str, float]) -> DrawResult:
    return DrawResult(index=index, noise_seed=1000 + index, stable=stable,
                      factors=dict.fromkeys(PARAMETERS, 1.0), parameters={}, metrics=metrics)


_MARGIN = st.one_of(st.floats(min_value=-10, max_value=80), st.just(math.inf),
                    st.just(math.nan))


@st.composite
def _draws(draw: Any) -> list[DrawResult]:
    n = draw(st.integers(min_value=1, max_value=12))
    out = []
    for i in range(n):
        rho = draw(st.floats(min_value=0.5, max_value=1.2))
        metrics = {f"{k}.{a}": (draw(_MARGIN) if rho < 1 else math.nan)
                   for k in ("gain_margin_db", "phase_margin_deg", "modulus_margin")
                   for a in "hv"}
        out.append(_draw(i, stable=rho < 1, metrics={**metrics, "spectral_radius": rho}))
    return draw(st.permutations(out))


@settings(max_examples=60, deadline=None)
@given(draws=_draws(), limit=st.floats(min_value=0, max_value=60))
def test_outcomes_are_the_recount_for_any_draws(draws: list[DrawResult], limit: float) -> None:
    limits = Limits(gain_margin_min_db=limit / 6, phase_margin_min_deg=limit,
                    modulus_margin_min=limit / 60)
    expected = _recount(draws, limits)
    for o in requirement_outcomes(draws, limits=limits):
        assert [b.index for b in o.breaches] == sorted(expected[o.requirement.name])
        assert o.notable == (len(expected[o.requirement.name]) >= NOTABLE_SHARE * len(draws))
        for b in o.breaches:
            json.dumps(b.to_json(), allow_nan=False)


def _payload(n: int, broken: int) -> dict[str, Any]:
    """montecarlo.json's requirements for ``n`` draws, ``broken`` of them below 30°."""
    draws = [_draw(i, stable=True, metrics={
        "spectral_radius": 0.9, "gain_margin_db.h": 10.0, "gain_margin_db.v": 10.0,
        "modulus_margin.h": 0.6, "modulus_margin.v": 0.6, "phase_margin_deg.h": 45.0,
        "phase_margin_deg.v": 25.0 if i < broken else 45.0}) for i in range(n)]
    return {"n": n, "seed": 0, "bench": "the packaged twin", "controller": {"name": "K"},
            "duration_s": 5.0, "settle_s": 2.0, "ranges": Ranges().to_json(),
            "requirements": [o.to_json() for o in requirement_outcomes(draws, limits=Limits())]}


@pytest.mark.parametrize(("n", "broken", "said"), [
    (20, 1, True),  # 5 %: the threshold itself
    (40, 1, False),  # 2.5 %
    (21, 1, False),  # 4.8 %, just below
    (20, 3, True),  # the 3 of 20
    (20, 0, False),
])
def test_robustness_sentence_from_five_percent(n: int, broken: int, said: bool) -> None:
    sentence = robustness_sentence(_payload(n, broken))
    assert bool(sentence) == said
    if said:
        assert f"phase margin ≥ 30° broken by {broken} of {n} draws" in sentence
        assert f"({100 * broken / n:.0f} %: draws {', '.join(map(str, range(broken)))})" \
            in sentence
        assert "gain margin" not in sentence


def _design() -> dict[str, Any]:
    """design.json's payload, only what the summary's loop rows read (a loop within limits)."""
    axis = {"stable": True, "gain_margin_db": 12.0, "phase_margin_deg": 45.0,
            "sensitivity_at_1hz": 1e-4, "crossover_hz": 35.0}
    loop = {"h": axis, "v": axis, "meets_objective": True}
    return {"fsmbench_controller": loop, "seed_controller": loop,
            "robustness": {"all_stable": True, "cases": [{"stable": True}] * 9,
                           "worst_gain_margin_db": 8.0},
            "closed_loop_twin": None, "closed_loop_skipped": "not simulated in this test"}


@pytest.mark.parametrize(("n", "broken"), [(20, 3), (40, 1)])
def test_the_verdict_robustness_row_names_a_requirement_five_percent_break(
        n: int, broken: int) -> None:
    from fsmbench.report.html import visible_text
    from fsmbench.report.summary import Specification, StudyEvidence, build_summary
    from fsmbench.report.verdict import verdict_html

    def summary(montecarlo: dict[str, Any] | None) -> Any:
        return build_summary(
            StudyEvidence(
                source="test",
                is_twin=True,
                skipped={},
                n_experiments=13,
                n_read=13,
                identification=None,
                plant_source="identified",
                plant_identified=True,
                budget=None,
                design=_design(),
                montecarlo=montecarlo),
            spec=Specification())

    payload = _payload(n, broken)
    without, with_mc = summary(None), summary(payload)
    row = {r.name: r for r in with_mc.requirements}["robust_stability"]
    said = broken >= NOTABLE_SHARE * n
    assert ("Monte Carlo" in row.explanation) == said
    assert robustness_sentence(payload) in row.explanation
    assert (f"broken by {broken} of {n} draws" in verdict_html(with_mc)) == said
    # The draws are another test of the same robustness: the verdict itself is unchanged.
    assert [r.passed for r in with_mc.requirements] == [r.passed for r in without.requirements]
    assert with_mc.verdict_status == without.verdict_status
    # The report's section names every breaking draw, whatever the share.
    text = " ".join(visible_text([montecarlo_section(payload)]))
    assert f"phase margin ≥ 30° 20{n - broken}" not in text  # cells are apart, not joined
    assert f"Draws breaking: phase margin ≥ 30° ({broken} of {n}" in text
    assert ", ".join(map(str, range(broken))) in text


def test_the_study_reads_version_3_only(tmp_path: Any) -> None:
    from fsmbench.scale.montecarlo_run import read_montecarlo

    doc = {"format": "fsmbench.montecarlo", "format_version": 3, **_payload(20, 1)}
    (tmp_path / "montecarlo.json").write_text(json.dumps(doc))
    assert read_montecarlo(tmp_path) == read_montecarlo(tmp_path / "montecarlo.json") == doc
    (tmp_path / "old.json").write_text(json.dumps({**doc, "format_version": 2}))
    with pytest.raises(ValueError, match=r"old\.json: fsmbench\.montecarlo version 2, .* run "
                                         "fsmbench montecarlo again"):
        read_montecarlo(tmp_path / "old.json")
    (tmp_path / "other.json").write_text(json.dumps({"format": "fsmbench.budget"}))
    with pytest.raises(ValueError, match=r"other\.json: not a fsmbench\.montecarlo file"):
        read_montecarlo(tmp_path / "other.json")
    with pytest.raises(ValueError, match="no such file"):
        read_montecarlo(tmp_path / "absent")
