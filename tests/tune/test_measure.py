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
from fsmbench.sim.loaded import running_controller
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
