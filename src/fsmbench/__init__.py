"""fsmbench: a fast-steering-mirror beam-stabilisation bench from recordings to report.

The study step by step (:mod:`fsmbench.api`; ``docs/api.md``)::

    import fsmbench
    bench = fsmbench.load_bench()                      # or a bench file
    run = fsmbench.simulate(bench, duration_s=5.0)     # or fsmbench.load_recordings(folder)
    ident = fsmbench.identify(run, bench=bench)        # ESRF study section 2
    budget = fsmbench.budget(run, bench=bench, plant=ident)        # 3, 4, 11
    design = fsmbench.design(ident, bench=bench)       # 5-10
    k = design.result.controllers["fsmbench_controller"]
    fsmbench.margins(ident.plant, k, channel="Rh")     # also loop_gain, sensitivity, ...
    fsmbench.study(out_dir="out")                      # all of it, with the report

Stages (one sub-package each): ``bench`` (parameters and physics), ``twin``
(the digital twin), ``io`` (recordings), ``ident`` (identification),
``budget`` (noise and error budget), ``control`` (analysis and design),
``report`` (figures and HTML). ``fsmbench.cli`` is the command line.

Importing fsmbench imports none of scipy, python-control, xarray or numba: each
function imports what it needs when called.
"""

from fsmbench.api import (
    budget,
    complementary,
    design,
    identify,
    load_bench,
    load_recordings,
    loop_gain,
    margins,
    physical_plant,
    sensitivity,
    simulate,
    study,
)
from fsmbench.version import __version__

__all__ = [
    "__version__",
    "budget",
    "complementary",
    "design",
    "identify",
    "load_bench",
    "load_recordings",
    "loop_gain",
    "margins",
    "physical_plant",
    "sensitivity",
    "simulate",
    "study",
]
