"""The excitation's own transient periods, read from what ``fsmbench excite`` writes."""

from __future__ import annotations

import json
from pathlib import Path

from fsmbench.excite.design import design_multisine
from fsmbench.excite.files import write_excitation
from fsmbench.ident.load import excitation_transients


def test_transients_by_experiment(tmp_path: Path) -> None:
    for channel, transient in (("Uch", 3), ("Unv", 0)):
        design = design_multisine(input=channel, band_hz=(1.0, 100.0), resolution_hz=1.0,
                                  amplitude_rms_v=0.01, fs_hz=1000.0, seed=1, periods=2,
                                  transient_periods=transient, grid="odd-odd",
                                  phase_method="random")
        write_excitation(design, tmp_path, stem=f"ms_{channel}")
    (tmp_path / "identification.json").write_text(json.dumps({"format": "other"}))
    (tmp_path / "broken.json").write_text("{")
    assert excitation_transients(tmp_path) == {"data_uch": 3, "data_unv": 0}
