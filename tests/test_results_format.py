"""Every JSON file of a study is a documented format a user can script against.

Checked on the twin study's output folder (``twin_study``): each file names its
format (``fsmbench.<name>``) and an int version; no key holds a space, dash,
en dash or ``>``; (h, v) pairs are ``{"h", "v"}`` objects, never 2-element
lists; ``budget.json`` says each thing once; ``docs/results.md`` describes
every format found.
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from fsmbench.study import StudyResult

DOC = Path(__file__).resolve().parents[1] / "docs" / "results.md"

# Keys are ids: letters, digits, underscores; no space, dash, en dash, ">", "/", ".".
_BAD_KEY = re.compile(r"[^A-Za-z0-9_]")

# Keys whose 2-element numeric lists are NOT an (h, v) pair: frequency bands
# [low, high], test amplitudes, candidate sets, per-reflection or per-section
# values. Any other 2-element list under a key is taken for an (h, v) pair.
NOT_HV = frozenset({
    "band_hz", "current_amp_band_hz", "newport_band_hz",  # [low_hz, high_hz]
    "fit_band_hz", "va_fit_band_hz",  # the noise model's bands, [low_hz, high_hz]
    "limits",  # a ratio's accepted band, [low, high]
    "shift_m", "path_change_m", "closed_form_m", "measured_change_m",  # per test shift
    "cos_incidence",  # per reflection
    "extra_integrators", "damping_scales", "frequency_scales", "gain_scales",  # candidates
    "crossovers_hz",  # every crossing, however many
    "prewarp_frequency_hz",  # per second-order section
})

# The pairs converted for issue 9, each an {"h", "v"} object in its file.
HV_PATHS = {
    "budget.json": [
        "noise.qd_gain_v_per_rad", "noise.qd_angle_per_volt_rad_per_v",
        "noise.qd_noise_v", "noise.qd_noise_angle_rad", "noise.qd_lsb_angle_rad",
        "noise.sercalo_dc_gain_rad_per_v",
        "dac_noise.rms_v", "dac_noise.command_rms_v", "dac_noise.white_ratio",
        "huddle_comparison.qd_noise.raw_rms_v", "huddle_comparison.qd_noise.rms_v",
        "huddle_comparison.qd_noise.newport_rms_v",
        "repeatability.h.tracking_rms_rad", "repeatability.v.tracking_rms_rad",
        "repeatability.h.seed_law_distance_std_m", "repeatability.v.seed_law_distance_std_m",
        "budget.angle_sources.qd_electronic_noise.angle_rms_rad",
        "budget.angle_sources.sercalo_dac_quantisation.angle_rms_rad",
    ],
    "twin-data/twin_truth.json": [
        "realized.data_huddle_test_1.qd_noise_v", "realized.data_rep_h.newport_angle_noise_rad",
    ],
}


def _files(out: Path) -> list[Path]:
    """Every JSON file of the output folder and its sub-folders (twin-data)."""
    return sorted(out.glob("*.json")) + sorted(out.glob("*/*.json"))


def _load(path: Path) -> dict[str, Any]:
    data = json.loads(path.read_text(encoding="utf-8"))
    assert isinstance(data, dict), f"{path.name}: not a JSON object"
    return data


def _walk(node: Any, path: str = "") -> Iterator[tuple[str, str, Any]]:
    """(dotted path, key, value) of every dict entry, depth first."""
    if isinstance(node, dict):
        for key, value in node.items():
            here = f"{path}.{key}" if path else key
            yield here, key, value
            yield from _walk(value, here)
    elif isinstance(node, list):
        for i, value in enumerate(node):
            yield from _walk(value, f"{path}[{i}]")


def _get(tree: dict[str, Any], dotted: str) -> Any:
    node: Any = tree
    for part in dotted.split("."):
        assert isinstance(node, dict) and part in node, f"missing {dotted}"
        node = node[part]
    return node


def _is_pair(value: Any) -> bool:
    return (isinstance(value, list) and len(value) == 2
            and all(v is None or (isinstance(v, int | float) and not isinstance(v, bool))
                    for v in value))


@pytest.fixture(scope="module")
def out(twin_study: StudyResult) -> Path:
    return Path(twin_study.out_dir)


def test_the_study_writes_the_expected_files(out: Path) -> None:
    names = {str(p.relative_to(out)) for p in _files(out)}
    # At least these; any other JSON file is held to the same rules below.
    assert {"identification.json", "budget.json", "design.json", "controllers_sos.json",
            "summary.json", "study.json", "timings.json", "twin-data/twin_truth.json"} <= names


def test_every_file_names_its_format_and_version(out: Path) -> None:
    for path in _files(out):
        data = _load(path)
        fmt, version = data.get("format"), data.get("format_version")
        assert isinstance(fmt, str) and fmt.startswith("fsmbench."), (path.name, fmt)
        assert isinstance(version, int) and not isinstance(version, bool) and version >= 1, \
            (path.name, version)


def test_stamped_formats(out: Path) -> None:
    """The stamped files with their versions (bumped where the shape changed)."""
    expected = {"identification.json": ("fsmbench.identification", 4),
                "budget.json": ("fsmbench.budget", 4),
                "design.json": ("fsmbench.design", 2),
                "summary.json": ("fsmbench.summary", 3),
                "validation.json": ("fsmbench.validation", 1),
                "twin-data/twin_truth.json": ("fsmbench.twin_truth", 3)}
    for name, stamp in expected.items():
        data = _load(out / name)
        assert (data["format"], data["format_version"]) == stamp, name


def test_no_punctuation_in_keys(out: Path) -> None:
    bad = [f"{p.relative_to(out)}: {where}" for p in _files(out)
           for where, key, _ in _walk(_load(p)) if _BAD_KEY.search(key)]
    assert bad == []


def test_no_hv_pair_as_a_list(out: Path) -> None:
    lists = [f"{p.relative_to(out)}: {where} = {value}" for p in _files(out)
             for where, key, value in _walk(_load(p))
             if _is_pair(value) and key not in NOT_HV]
    assert lists == []
    for name, paths in HV_PATHS.items():
        data = _load(out / name)
        for dotted in paths:
            value = _get(data, dotted)
            assert isinstance(value, dict) and set(value) == {"h", "v"}, (name, dotted, value)
            assert all(isinstance(v, float) for v in value.values()), (name, dotted, value)


def test_keys_are_ids_and_names_are_values(out: Path) -> None:
    budget = _load(out / "budget.json")
    sources = budget["budget"]["angle_sources"]
    assert sources["qd_electronic_noise"]["name"] == "4QD electronic noise"
    rows = {r["id"]: r for r in budget["budget"]["rows"]}
    assert budget["budget"]["limiting"] == rows[budget["budget"]["limiting_id"]]["name"]
    assert set(sources) <= set(rows)  # every angle source is a row, under the same id
    for record in budget["huddle"].values():
        bands = {b["id"]: b for b in record["bands"]}
        assert {"drift", "band_3_50_hz", "total"} <= set(bands)
        assert bands["band_3_50_hz"]["low_hz"] == 3.0 and bands["band_3_50_hz"]["name"] \
            == "3–50 Hz"
    truth = _load(out / "twin-data" / "twin_truth.json")
    assert set(truth["cross_coupling_dc_gain"]) == {
        "Ich_to_Vpv_v_per_a", "Icv_to_Vph_v_per_a", "Unh_to_Vpv_v_per_v", "Unv_to_Vph_v_per_v"}


def test_budget_has_no_duplicated_blocks(out: Path) -> None:
    budget = _load(out / "budget.json")
    assert not {"sources", "total_rms_m", "total_bias_m", "limiting", "plant"} & set(budget)
    assert budget["budget"]["total_rms_m"] > 0 and budget["plant_source"]


def test_every_format_is_documented(out: Path) -> None:
    doc = DOC.read_text(encoding="utf-8")
    for path in _files(out):
        data = _load(path)
        fmt = data["format"]
        assert f"`{fmt}`" in doc, f"{path.name}: format {fmt} not in docs/results.md"
        assert re.search(rf"`{re.escape(fmt)}`[^\n]*\bversion {data['format_version']}\b",
                         doc), f"{fmt} version {data['format_version']} not in the doc"


def test_helpers_refuse_what_is_not_a_pair_or_a_format() -> None:
    from fsmbench.jsonutil import hv, stamped

    assert hv((1.0, 2.0)) == {"h": 1.0, "v": 2.0}
    with pytest.raises(ValueError, match="2 values, got 3"):
        hv([1.0, 2.0, 3.0])
    assert list(stamped({"a": 1, "format": "x"}, format="fsmbench.x", version=3)) == [
        "format", "format_version", "a"]
    with pytest.raises(ValueError, match="fsmbench-output"):
        stamped({}, format="fsmbench-output", version=1)
