"""Issue 30: records whose fault is in the record, named for what it is.

Each test corrupts short twin records (5 s, the packaged bench) as the issue's
users found them and asserts the check that names the fault, its file and its
words, and that the words name no cause the records rule out: a record too
short for its analysis is not "zero throughout"; a channel recorded twice is
not "a swap"; a clipped ``Vch`` is named before its gain is read 16 % low; a
closed-loop record saved as ``data_uch`` is not "raise the excitation"; one
run's 4QD outputs delayed by 20 samples are not a 1 ms 4QD amplifier.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
import xarray as xr

from fsmbench.bench.params import default_bench
from fsmbench.checks import Check, failed
from fsmbench.ident.pipeline import identify
from fsmbench.io.folder import check_recording
from fsmbench.twin import TwinRun, simulate_bench

Edit = Callable[[xr.Dataset], xr.Dataset]


@pytest.fixture(scope="module")
def run() -> TwinRun:
    return simulate_bench(seed=7, duration_s=5.0)


def _checks(ds: xr.Dataset, name: str) -> list[Check]:
    return check_recording(ds, name=name, fs_hz=1e4)[0]


def _with(ds: xr.Dataset, **signals: np.ndarray) -> xr.Dataset:
    out = ds.copy(deep=True)
    for k, v in signals.items():
        out[k] = (("t",), np.asarray(v, dtype=float), ds[k].attrs)
    return out


def test_a_record_too_short_is_named_for_its_length_not_for_its_signals(run: TwinRun
                                                                        ) -> None:
    ds = run.recordings["data_uch"].isel(t=slice(0, 10))
    bad = failed(_checks(ds, "data_uch"))
    assert [c.name for c in bad] == ["record_length"]  # not "Uch is zero throughout"
    assert "10 samples" in bad[0].advice and "needs 3 s" in bad[0].advice


def test_a_channel_recorded_twice_is_named_not_called_a_swap(run: TwinRun) -> None:
    ds = run.recordings["data_uch"]
    bad = failed(_checks(_with(ds, Vpv=ds["Vph"].values), "data_uch"))
    assert [c.name for c in bad] == ["channels_distinct"]
    assert bad[0].subject.endswith("Vph, Vpv") and "swap" not in bad[0].advice


@pytest.mark.parametrize(("signal", "share"), [("Vch", 0.3), ("Vph", 0.3), ("Vch", 0.5)])
def test_a_clipped_noise_run_signal_is_named(run: TwinRun, signal: str, share: float) -> None:
    ds = run.recordings["data_uch"]
    x = ds[signal].values
    peak = float(np.max(np.abs(x - x.mean())))
    clipped = np.clip(x, x.mean() - share * peak, x.mean() + share * peak)
    bad = failed(_checks(_with(ds, **{signal: clipped}), "data_uch"))
    assert [c.name for c in bad] == ["signal_clipped"] and bad[0].subject.endswith(signal)
    # Its clean twin passes: a noise run's signal is never flat at its extremes.
    assert not failed(_checks(ds, "data_uch"))


def test_a_closed_loop_record_saved_as_the_noise_run_is_named(run: TwinRun) -> None:
    rep = run.recordings["data_rep_h"]
    as_uch = xr.Dataset({"Uch": rep["Uch"], "Vph": rep["Vph"], "Vpv": rep["Vpv"],
                         "Vch": run.recordings["data_uch"]["Vch"].isel(
                             t=slice(0, rep.sizes["t"]))},
                        coords=rep.coords, attrs={**rep.attrs, "experiment": "data_uch"})
    ident = identify({**run.recordings, "data_uch": as_uch}, bench=default_bench())
    bad = [c for c in ident.checks if c.name == "open_loop_record" and not c.passed]
    assert [c.subject for c in bad] == ["data_uch.mat: Uch"]
    assert "recorded with the loop closed" in bad[0].advice
    assert "raise the excitation" not in " ".join(ident.skipped.values())
    assert ident.sercalo is None


def test_one_run_s_4qd_outputs_delayed_are_named_there(run: TwinRun) -> None:
    ds = run.recordings["data_uch"]
    late = {s: np.r_[np.zeros(20), ds[s].values[:-20]] for s in ("Vph", "Vpv")}
    ident = identify({**run.recordings, "data_uch": _with(ds, **late)},
                     bench=default_bench())
    bad = [c for c in ident.checks if c.name == "qd_lag_across_axes" and not c.passed]
    assert len(bad) == 1 and "the 4QD output of data_uch.mat lags" in bad[0].advice
    assert "20 samples" in bad[0].advice
    assert ident.sercalo is None  # its delay is not the bench's
    # No 4QD amplifier is inferred from it.
    assert not any("4QD amplifier is a" in n.message for n in ident.notices)
    assert not any(f.key.startswith("nominal.quad_diode.bandwidth") for f in ident.findings)
