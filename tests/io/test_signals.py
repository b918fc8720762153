"""fsmbench.io.signals: the ESRF study's signal table and experiments."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import pytest

from fsmbench.io.signals import (
    ADC_SIGNALS,
    DAC_SIGNALS,
    EXPERIMENTS,
    SIGNALS,
    TIME,
    ExperimentInfo,
    SignalInfo,
)

SEED = Path(__file__).resolve().parents[3] / "shared" / "seed" / "000_a877da0cab020a03.txt"

# Seed section 2 table, row by row.
TABLE = [
    ("Uch", "Voltage Sent to Sercalo - Horizontal", "V"),
    ("Ucv", "Voltage Sent to Sercalo - Vertical", "V"),
    ("Unh", "Voltage Sent to Newport - Horizontal", "V"),
    ("Unv", "Voltage Sent to Newport - Vertical", "V"),
    ("Vph", "4Q Photodiode Measurement - Horizontal", "V"),
    ("Vpv", "4Q Photodiode Measurement - Vertical", "V"),
    ("Vch", "Measured Voltage across the Inductance - Horizontal", "V"),
    ("Vcv", "Measured Voltage across the Inductance - Vertical", "V"),
    ("Vnh", "Newport Metrology - Horizontal", "V"),
    ("Vnv", "Newport Metrology - Vertical", "V"),
    ("Va", "Attocube Measurement", "m"),
]

# The seed's load lines (sections 2, 3, 11), union per file.
LOADS = {
    "data_cal_pd_h": ("t", "Vph", "Vpv", "Vnh"),
    "data_cal_pd_v": ("t", "Vph", "Vpv", "Vnv"),
    "data_uch": ("t", "Uch", "Vch", "Vph", "Vpv"),
    "data_ucv": ("t", "Ucv", "Vcv", "Vph", "Vpv"),
    "data_unh": ("t", "Unh", "Vph", "Vpv"),
    "data_unv": ("t", "Unv", "Vph", "Vpv"),
    "data_huddle_test_1": ("t", "Vph", "Vpv", "Va"),
    "data_huddle_test_2": ("t", "Vph", "Vpv", "Va"),
    "data_huddle_test_3": ("t", "Uch", "Ucv", "Vph", "Vpv", "Va"),
    "data_huddle_test_4": ("t", "Vph", "Vpv", "Va"),
    "data_huddle_test_5": ("t", "Uch", "Ucv", "Vph", "Vpv", "Va"),
    "data_rep_h": ("t", "Uch", "Ucv", "Unh", "Unv", "Vph", "Vpv", "Vnh", "Vnv", "Va"),
    "data_rep_v": ("t", "Uch", "Ucv", "Unh", "Unv", "Vph", "Vpv", "Vnh", "Vnv", "Va"),
}


def test_signal_table_is_the_seeds_in_order() -> None:
    assert list(SIGNALS) == [row[0] for row in TABLE]


@pytest.mark.parametrize(("name", "long_name", "units"), TABLE)
def test_signal_row(name: str, long_name: str, units: str) -> None:
    assert SIGNALS[name] == SignalInfo(name=name, long_name=long_name, units=units)


def test_adc_and_dac_sets() -> None:
    assert ADC_SIGNALS == ("Vph", "Vpv", "Vch", "Vcv", "Vnh", "Vnv")
    assert DAC_SIGNALS == ("Uch", "Ucv", "Unh", "Unv")
    assert not set(ADC_SIGNALS) & set(DAC_SIGNALS)
    assert set(ADC_SIGNALS) | set(DAC_SIGNALS) | {"Va"} == set(SIGNALS)
    assert all(SIGNALS[s].units == "V" for s in (*ADC_SIGNALS, *DAC_SIGNALS))


def test_experiments_are_exactly_the_seeds() -> None:
    assert list(EXPERIMENTS) == list(LOADS)


@pytest.mark.parametrize(("name", "required"), LOADS.items())
def test_experiment_required_variables(name: str, required: tuple[str, ...]) -> None:
    info = EXPERIMENTS[name]
    assert info.name == name
    assert info.required == required
    assert info.required[0] == TIME
    assert all(v in SIGNALS for v in info.required[1:])
    assert info.description
    assert re.fullmatch(r"\d+\.\d+(, \d+\.\d+)*", info.section)


@pytest.mark.parametrize(
    ("name", "section"),
    [("data_cal_pd_h", "2.1"), ("data_uch", "2.2, 2.3"), ("data_unv", "2.4"),
     ("data_huddle_test_5", "3.1"), ("data_rep_v", "11.1")],
)
def test_experiment_sections(name: str, section: str) -> None:
    assert EXPERIMENTS[name].section == section


@pytest.mark.parametrize(
    ("obj", "field"),
    [(SIGNALS["Vph"], "units"), (EXPERIMENTS["data_uch"], "required")],
)
def test_records_are_frozen(obj: SignalInfo | ExperimentInfo, field: str) -> None:
    with pytest.raises(dataclasses.FrozenInstanceError):
        setattr(obj, field, "x")


@pytest.mark.skipif(not SEED.is_file(), reason="ESRF study text not beside the repository")
def test_required_variables_match_the_seed_text() -> None:
    """Parse every load('...data_*.mat', ...) of the ESRF study, commented ones included."""
    text = re.sub(r"\.\.\.\s*\n\s*", "", SEED.read_text(encoding="utf-8"))
    found: dict[str, list[str]] = {}
    for file, args in re.findall(r"load\('[^']*?(data_\w+)\.mat',([^)]*)\)", text):
        names = found.setdefault(file, [])
        names += [v for v in re.findall(r"'(\w+)'", args) if v not in names]
    assert {k: tuple(v) for k, v in found.items()} == {k: v.required for k, v in
                                                       EXPERIMENTS.items()}
