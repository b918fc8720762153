"""Issue 24's done means: the Sercalo identified with the loop closed within the open-loop
tolerances, on the twin with the real bench's features, the beam error bounded.

Checked against the twin's own truth (``twin_truth``: the parameters it was simulated
with), on the two runs that failed before the stages were merged and the fit's band began
at 10 Hz: ``real_bench.toml`` seed 3 (the refined stage's fit failed on its coherence and
the first stage's vertical damping was +869 %) and the packaged twin's seed 8 (the refined
stage alone put the h mode at the v mode's 251 Hz, -39 %).
"""

from __future__ import annotations

import pytest

from fsmbench.bench.params import Bench, default_bench, real_bench
from fsmbench.sim.loaded import running_controller
from fsmbench.tune.measure import MeasurementOptions, measure_closed_loop

# The open-loop identification's tolerances (issue 24): resonance 0.5 %, damping 25 %,
# static gains 3 % (the looser of 1-3 %), delay one sample (1e-4 s at 10 kHz).
_TOLERANCE = {"resonance_hz": 0.005, "damping_ratio": 0.25, "dc_gain_v_per_a": 0.03}
_DELAY_S = 1e-4


@pytest.mark.slow  # one two-stage measurement: ~30 s alone, ~1.5 min on 2 busy cores
@pytest.mark.parametrize(("which", "seed"), [("real_bench", 3), ("twin", 8)])
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
