"""Issue 24's done means: the Sercalo identified with the loop closed within the open-loop
tolerances, on the twin with the real bench's features, the beam error bounded.

Checked against the twin's own truth (``twin_truth``: the parameters it was simulated
with), on the two runs that failed before the stages were merged and the fit's band began
at 10 Hz: ``real_bench.toml`` seed 3 (the refined stage's fit failed on its coherence and
the first stage's vertical damping was +869 %) and the packaged twin's seed 8 (the refined
stage alone put the h mode at the v mode's 251 Hz, -39 %); and ``real_bench.toml`` seed 5
(stage 1, designed at 0.9 of the bound on the bench file's model, added 30.4 µrad against
30: the model under-predicted the cross-axis response by 12 %) and seed 2 (the Bode delay
continued its noisy lowest lines with a slope of +1 and the fit came out 1.35 samples off
when stage 2's excitation changed by 4 %).
"""

from __future__ import annotations

import pytest

from fsmbench.bench.params import Bench, default_bench, real_bench
from fsmbench.control.loaded import running_controller
from fsmbench.tune.measure import MeasurementOptions, measure_closed_loop, model_excess

# The open-loop identification's tolerances (issue 24): resonance 0.5 %, damping 25 %,
# static gains 3 % (the looser of 1-3 %), delay one sample (1e-4 s at 10 kHz).
_TOLERANCE = {"resonance_hz": 0.005, "damping_ratio": 0.25, "dc_gain_v_per_a": 0.03}
_DELAY_S = 1e-4


@pytest.mark.slow  # one two-stage measurement: ~30 s alone, ~1.5 min on 2 busy cores
@pytest.mark.parametrize(("which", "seed"),
                         [("real_bench", 3), ("twin", 8), ("real_bench", 5), ("real_bench", 2)])
def test_identified_with_the_loop_closed_within_open_loop_tolerances(which: str,
                                                                     seed: int) -> None:
    b: Bench = real_bench() if which == "real_bench" else default_bench()
    bound = 30e-6
    m = measure_closed_loop(true_bench=b, model=b, controller=running_controller(None, bench=b),
                            options=MeasurementOptions(max_error_rad=bound), seed=seed)
    truth = m.stages[0][1].truth
    found = m.identification.to_json()
    assert m.note == ""  # the merged stages identified the Sercalo
    for axis in ("h", "v"):
        for key, tol in _TOLERANCE.items():
            rel = found["sercalo"][axis][key] / truth["sercalo"][axis][key] - 1.0
            assert abs(rel) <= tol, f"{which} seed {seed}: {axis} {key} {100 * rel:+.2f} %"
    assert abs(found["delay_s"]["sercalo"] - truth["delay_s"]["sercalo"]) <= _DELAY_S
    # The fit's lines start at 10 Hz (below, the joint estimate falls short of the plant).
    assert m.identification.sercalo is not None
    assert float(m.identification.sercalo.frf.frequency_hz.min()) >= 10.0
    # The beam error the measurement added stays under the user's bound, on both axes.
    assert max(m.tracking_added_rad().values()) <= bound


def test_model_excess_is_the_largest_measured_over_predicted_ratio() -> None:
    """Stage 2's fill is divided by what stage 1 measured over what its designs predicted."""
    from types import SimpleNamespace

    from fsmbench.ident.closed_loop import TrackingDuringMeasurement

    def tracking(record: str, h: float, v: float) -> TrackingDuringMeasurement:
        return TrackingDuringMeasurement(record=record, before_rms_rad={"h": 1.0, "v": 1.0},
                                         during_rms_rad={"h": 1.0, "v": 1.0},
                                         added_rms_rad={"h": h, "v": v})

    designs = [SimpleNamespace(design=SimpleNamespace(input="Uch"), worst_beam_rms_rad=27e-6),
               SimpleNamespace(design=SimpleNamespace(input="Ucv"), worst_beam_rms_rad=20e-6)]
    ident = SimpleNamespace(tracking=(tracking("data_cl_uch", 28.1e-6, 30.36e-6),
                                      tracking("data_cl_ucv", 19e-6, 21e-6)))
    # 30.36 / 27 = 1.124 (the worst axis of Uch) against 21 / 20 = 1.05 for Ucv
    assert model_excess(ident, designs) == pytest.approx(30.36 / 27)  # type: ignore[arg-type]
    within = SimpleNamespace(tracking=(tracking("data_cl_uch", 20e-6, float("nan")),))
    assert model_excess(within, designs) == 1.0  # type: ignore[arg-type]


def test_a_stage_1_that_locates_nothing_is_measured_once_again() -> None:
    """The first records' outputs shuffled in time (no longer the excitation's response):
    stage 1 locates nothing from them, is measured again, and locates both modes within
    the open-loop resonance tolerance; the repeat is said and its records counted."""
    import dataclasses

    import numpy as np

    from fsmbench.twin.closed_loop import play_closed_loop

    b = default_bench()
    calls: list[int] = []

    def play(plays, *, controller, settle_s, seed, progress):  # type: ignore[no-untyped-def]
        run = play_closed_loop(plays, bench=b, controller=controller, seed=seed,
                               settle_s=settle_s, progress=progress)
        calls.append(seed)
        if len(calls) > 1:
            return run
        rng = np.random.default_rng(0)
        spoiled = {}
        for name, ds in run.recordings.items():
            ds = ds.copy(deep=True)
            for sig in ("Vph", "Vpv"):
                ds[sig].values[:] = rng.permutation(ds[sig].values)
            spoiled[name] = ds
        return dataclasses.replace(run, recordings=spoiled)

    said: list[str] = []
    m = measure_closed_loop(model=b, controller=running_controller(None, bench=b), play=play,
                            options=MeasurementOptions(refine=False), seed=4,
                            progress=said.append)
    assert calls == [4, 6]  # the repeat draws new noise
    assert m.note.startswith("stage 1 was measured again") and any(
        s.startswith("stage 1 was measured again") for s in said)
    one = sum(e.duration_s for e in m.stages[-1][1].experiments)
    assert m.duration_s == pytest.approx(len(m.stages) * one)  # the spoiled records count
    truth = m.stages[-1][1].truth
    found = m.identification.to_json()["sercalo"]
    for axis in ("h", "v"):
        rel = found[axis]["resonance_hz"] / truth["sercalo"][axis]["resonance_hz"] - 1.0
        assert abs(rel) <= _TOLERANCE["resonance_hz"], (axis, rel)
