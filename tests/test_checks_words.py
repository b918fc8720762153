"""A check reads as words with its unit, never as a code key (issue: "FAILED (814.9, …)")."""

from __future__ import annotations

import pytest

from fsmbench.checks import CHECK_TITLES, Check


@pytest.mark.parametrize(("check", "expected"), [
    (Check("newport_phase_bandwidth", False, 814.9, "within 25 % of the datasheet's 600 Hz",
           "Newport h (Unh → Vph)", "check its tuning", unit="Hz"),
     "Newport h (Unh → Vph): Newport phase bandwidth failed (814.9 Hz, limit within 25 % of "
     "the datasheet's 600 Hz); check its tuning"),
    (Check("qd_gain_vs_nominal", True, 1.14, "0.5 to 2 times the nominal 34", unit="×"),
     "4QD gain against the bench file's passed (1.14×, limit 0.5 to 2 times the nominal 34)"),
    (Check("coprime_factor_margin", False, None, "computable", advice="singular"),
     "robust stability margin b_max failed (not computed, limit computable); singular"),
    (Check("calibration_r2", True, 0.999981, "≥ 0.9"),
     "4QD calibration linearity r² passed (1, limit ≥ 0.9)"),
])
def test_sentence_is_words_with_units(check: Check, expected: str) -> None:
    assert check.sentence() == expected


def test_every_check_the_code_makes_has_words() -> None:
    """Each name passed to Check(...) in the package has a title (grep of the sources)."""
    import re
    from pathlib import Path

    import fsmbench

    root = Path(fsmbench.__file__).parent
    names: set[str] = set()
    for path in root.rglob("*.py"):
        text = path.read_text()
        names |= set(re.findall(r'\bCheck\(\s*"([a-z0-9_]+)"', text))
        names |= set(re.findall(r'_(?:factor|ratio)_check\(\s*"([a-z0-9_]+)"', text))
        names |= set(re.findall(r'\("(newport_[a-z_]+_bandwidth)"', text))
    assert names, "the grep found no check"
    assert sorted(names - set(CHECK_TITLES)) == []
    assert all("_" not in title.replace("b_max", "") for title in CHECK_TITLES.values())
