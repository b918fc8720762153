"""The plant checked on the recorded closed loop through its own commands (MATLAB's ``compare``).

:mod:`fsmbench.control.validation` predicts the closed loop's tracking error by
simulating the loop, so it tests the plant, the noise model and the loop's
nonlinearities at once. Where the Sercalo DAC's rounding is a dead band (the
command moves by less than a step per sample), its limit cycles set the error
and follow the last details of the loop: no model predicts their amplitude.
This check tests the plant alone, on the same records, without the loop:

Predicted
    ``Vp`` from the recorded commands ``Uch, Ucv, Unh, Unv`` through the
    identified plant (its input delays included), the commands rounded to the
    DAC's grid first: a real-time target records its controller's output, the DAC
    plays it rounded (a no-op for commands on the grid). Linear convolution (FFT,
    zero padded); the first ``max(settle_s, 10 τ)`` are left out, τ the slowest
    decay time of the plant's modes (the zero initial state's transient, e^-10).
Residual
    recorded less predicted ``Vp``, its repeatable part (the mean period of the
    Newport's motion: a small gain error on its large sine) removed, Welch PSD with
    a Hann window of one period. What the commands do not explain: the bench's
    noise, whatever the loop did.
Reference
    The same noise measured with no command: the open-loop huddle tests (1, 2, 4)
    present, Welch PSD, their median per line (a test recorded with the loop left
    closed does not move it).

The check: the residual's power over the reference's in each band of
:data:`BANDS_HZ` (to the Nyquist frequency) at most :data:`MAX_EXCESS`. A plant
off by a fraction of a resonance's width leaves that fraction of the command's
response in the residual, so the test is as strong as the commands are rich at the
resonances. On a bench whose DAC limit-cycles there (the independent simulator's hot
bench: 10⁵–10⁶ times the noise), a resonance 0.01 % off reads 5× and a delay one sample
off 48×; on the twin with no dead band, 0.2 % reads 4× and one sample only 1.15×.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Final

import numpy as np
import scipy.fft
import xarray as xr
from numpy.typing import NDArray

from fsmbench.bench.blocks import PlantModel
from fsmbench.checks import Check
from fsmbench.jsonutil import plain_json
from fsmbench.signal.welch import hanning, pwelch

__all__ = ["BANDS_HZ", "MAX_EXCESS", "OutputErrorCheck", "output_error_check",
           "without_mean_period"]

FloatArray = NDArray[np.float64]

#: Band edges of the comparison [Hz], the last band running to the Nyquist frequency: a
#: decade each from 2 Hz (below, the 1 Hz motion's harmonics and the record's length leave
#: too few independent lines), the Sercalo's resonances (250–450 Hz on the ESRF bench) in
#: the third.
BANDS_HZ: Final = (2.0, 20.0, 200.0, 2000.0)
#: Residual over reference power a right plant gives at most, per band. Each band power is
#: a Welch average of ≥ 18 lines over ≥ 30 half-overlapping periods (its scatter a few %),
#: and the noise of two records of one bench differs by its drift: 2× is a model error
#: adding as much power as the bench's own noise.
MAX_EXCESS: Final = 2.0
_COMMANDS: Final = ("Uch", "Ucv", "Unh", "Unv")
_OPEN_HUDDLES: Final = ("data_huddle_test_1", "data_huddle_test_2", "data_huddle_test_4")


@dataclass(frozen=True)
class OutputErrorCheck:
    """The recorded 4QD readings against the plant's response to the recorded commands.

    Attributes
    ----------
    experiments : tuple of str
        The closed-loop records compared.
    reference : tuple of str
        The open-loop huddle tests whose noise is the reference.
    bands_hz : tuple of (float, float)
    excess : dict axis -> tuple of float
        Residual over reference power per band, h and v (the records' largest).
    explained : dict axis -> float
        Share of the recorded ``Vp`` variance (after the left-out start) the prediction
        explains, the records' smallest [1].
    rounded : bool
        The recorded commands were off the DAC's grid and were rounded to it.
    left_out_s : float
        Start of each record left out [s].
    check : Check
        ``plant_output_error``.
    """

    experiments: tuple[str, ...]
    reference: tuple[str, ...]
    bands_hz: tuple[tuple[float, float], ...]
    excess: dict[str, tuple[float, ...]]
    explained: dict[str, float]
    rounded: bool
    left_out_s: float
    check: Check

    @property
    def passed(self) -> bool:
        """Every band of both axes within :data:`MAX_EXCESS`."""
        return self.check.passed

    def to_json(self) -> dict[str, Any]:
        """JSON-ready dict."""
        return plain_json({
            "experiments": list(self.experiments), "reference": list(self.reference),
            "bands_hz": [list(b) for b in self.bands_hz],
            "residual_over_noise": {a: list(v) for a, v in self.excess.items()},
            "explained_variance": self.explained, "commands_rounded": self.rounded,
            "left_out_s": self.left_out_s, "limit": MAX_EXCESS, "passed": self.passed})


def _slowest_decay_s(plant: PlantModel) -> float:
    if not plant.sys.nstates:
        return 0.0
    poles = np.linalg.eigvals(np.asarray(plant.sys.A, dtype=float))
    rates = [-float(np.real(p)) for p in poles if np.real(p) < 0]
    return 1.0 / min(rates) if rates else 0.0


def without_mean_period(x: FloatArray, period: int) -> tuple[FloatArray, int]:
    """``x`` (n, k) cut to whole periods, less its mean period, and the number of periods."""
    n = x.shape[0] // period
    whole = x[: n * period].reshape(n, period, x.shape[1])
    return (whole - whole.mean(axis=0, keepdims=True)).reshape(n * period, x.shape[1]), n


def _psd(x: FloatArray, *, fs_hz: float, period: int, name: str) -> tuple[FloatArray, FloatArray]:
    """One-sided PSD of ``Vph, Vpv`` (columns of ``x``, mean removed): Hann of one period."""
    window = hanning(period)
    x = x - x.mean(axis=0)
    cols = [pwelch(x[:, i], window=window, nfft=period, fs_hz=fs_hz, x_name=f"{name} {c}")
            for i, c in enumerate(("Vph", "Vpv"))]
    return np.asarray(cols[0].f_hz, dtype=float), np.column_stack([c.values for c in cols])


def _predicted(ds: xr.Dataset, plant: PlantModel, *, fs_hz: float, lsb_v: float,
               span_v: float, responses: dict[int, NDArray[np.complex128]]
               ) -> tuple[FloatArray, FloatArray, bool]:
    """``(Vp recorded (n, 2), Vp predicted (n, 2), commands rounded)``, means removed.

    ``responses``: the plant's response per FFT length, filled here (the two records
    of a study share one length, and the response is most of the cost).
    """
    u = np.column_stack([np.asarray(ds[c].values, dtype=float) for c in _COMMANDS])
    on_grid = np.round(u / lsb_v) * lsb_v
    rounded = bool(np.max(np.abs(u - on_grid)) > 1e-6 * lsb_v)
    top = span_v / 2.0 - lsb_v
    u = np.clip(on_grid, -top - lsb_v, top)
    vp = np.column_stack([np.asarray(ds[c].values, dtype=float) for c in ("Vph", "Vpv")])
    n = u.shape[0]
    m = scipy.fft.next_fast_len(2 * n, real=True)
    if m not in responses:
        f = np.fft.rfftfreq(m, 1.0 / fs_hz)
        responses[m] = plant.frequency_response(f[1:], outputs=("Vph", "Vpv"),
                                                inputs=_COMMANDS).values
    spectrum = np.fft.rfft(u - u.mean(axis=0), n=m, axis=0)
    y = np.zeros((spectrum.shape[0], 2), dtype=complex)
    y[1:] = np.einsum("foi,fi->fo", responses[m], spectrum[1:])
    return vp - vp.mean(axis=0), np.fft.irfft(y, n=m, axis=0)[:n], rounded


def _huddle_noise(recordings: Mapping[str, xr.Dataset], reference: list[str], *,
                  fs_hz: float, period: int) -> NDArray[np.float64]:
    """The 4QD's noise PSD (Vph, Vpv) as the open-loop huddle tests give it: their median."""
    noise = []
    for h in reference:
        v = np.column_stack([np.asarray(recordings[h][c].values, dtype=float)
                             for c in ("Vph", "Vpv")])
        noise.append(_psd(v, fs_hz=fs_hz, period=period, name=h)[1])
    return np.asarray(np.median(noise, axis=0))


def _excess_check(excess: Mapping[str, list[float]], *,
                  bands: tuple[tuple[float, float], ...], usable: list[str]) -> Check:
    """The largest output error against the huddle noise, over axes and bands."""
    worst_axis, worst_band = max(((a, k) for a in "hv" for k in range(len(bands))),
                                 key=lambda ak: excess[ak[0]][ak[1]])
    worst = excess[worst_axis][worst_band]
    ok = worst <= MAX_EXCESS
    lo, hi = bands[worst_band]
    subject = ", ".join(f"{n}.mat: Vph, Vpv" for n in usable)
    advice = "" if ok else (
        f"{worst_axis}: between {lo:g} and {hi:g} Hz the recorded 4QD reading less the "
        f"identified plant's response to the recorded commands holds {worst:.3g}× the "
        f"open-loop huddle tests' noise: the plant does not explain its own closed loop's "
        "records there (a path, delay or resonance of the model not the bench's, or a "
        "command recorded other than played)")
    return Check("plant_output_error", ok, worst,
                 f"≤ {MAX_EXCESS:g}× the open-loop huddle tests' noise in every band",
                 subject=subject, advice=advice, unit="×")


def output_error_check(recordings: Mapping[str, xr.Dataset], names: list[str], *,
                       plant: PlantModel, fs_hz: float, lsb_v: float, span_v: float,
                       period_s: float = 1.0, settle_s: float = 2.0) -> OutputErrorCheck | None:
    """Compare the closed-loop records' ``Vp`` with the plant's response to their commands.

    Parameters
    ----------
    recordings : mapping of experiment name to Dataset
        Needs ``names`` (with ``t``, the four commands, ``Vph``, ``Vpv``) and at least
        one open-loop huddle test with ``Vph``, ``Vpv``.
    names : list of str
        The closed-loop records (``data_rep_h``, ``data_rep_v``).
    plant : PlantModel
        The identified plant (``Vph, Vpv ← Uch, Ucv, Unh, Unv`` with delays).
    fs_hz : float
        The records' rate [Hz].
    lsb_v, span_v : float
        One DAC step and the DAC's full span [V].
    period_s, settle_s : float
        The Newport's period and the least start left out [s].

    Returns
    -------
    OutputErrorCheck or None
        None when a record lacks a signal, no open-loop huddle test is there, or a
        record holds fewer than 3 periods after the start left out.
    """
    reference = [h for h in _OPEN_HUDDLES if h in recordings
                 and all(c in recordings[h] for c in ("Vph", "Vpv"))]
    usable = [n for n in names if n in recordings
              and all(c in recordings[n] for c in (*_COMMANDS, "Vph", "Vpv"))]
    if not reference or not usable:
        return None
    period = round(period_s * fs_hz)
    left_out = max(settle_s, 10.0 * _slowest_decay_s(plant))
    skip = round(left_out * fs_hz)
    ref = _huddle_noise(recordings, reference, fs_hz=fs_hz, period=period)
    edges = [*(b for b in BANDS_HZ if b < fs_hz / 2), fs_hz / 2]
    bands = tuple((float(lo), float(hi)) for lo, hi in itertools.pairwise(edges))
    excess = {a: [0.0] * len(bands) for a in "hv"}
    explained = {a: 1.0 for a in "hv"}
    rounded = False
    responses: dict[int, NDArray[np.complex128]] = {}
    for name in usable:
        vp, pred, was_rounded = _predicted(recordings[name], plant, fs_hz=fs_hz, lsb_v=lsb_v,
                                           span_v=span_v, responses=responses)
        rounded = rounded or was_rounded
        if (vp.shape[0] - skip) // period < 3:
            return None
        # The repeatable part removed, the noise's power scaled back by the 1 − 1/N it took.
        resid, periods = without_mean_period((vp - pred)[skip:], period)
        f, p = _psd(resid, fs_hz=fs_hz, period=period, name=name)
        p = p / (1.0 - 1.0 / periods)
        for i, a in enumerate("hv"):
            var_vp = float(np.var(vp[skip:, i]))
            share = 1.0 - float(np.var(resid[:, i])) / var_vp if var_vp > 0 else 0.0
            explained[a] = min(explained[a], share)
            for k, (lo, hi) in enumerate(bands):
                inside = (f >= lo) & (f <= hi)
                num = float(np.trapezoid(p[inside, i], f[inside]))
                den = float(np.trapezoid(ref[inside, i], f[inside]))
                excess[a][k] = max(excess[a][k], num / den if den > 0 else math.inf)
    check = _excess_check(excess, bands=bands, usable=usable)
    return OutputErrorCheck(
        experiments=tuple(usable), reference=tuple(reference), bands_hz=bands,
        excess={a: tuple(v) for a, v in excess.items()}, explained=explained,
        rounded=rounded, left_out_s=float(left_out), check=check)
