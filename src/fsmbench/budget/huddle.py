"""Huddle tests (ESRF study 3): noise of the 4QD and of the Attocube in the five configurations.

Processing as the ESRF study's 3.2–3.5: samples with ``t < t0`` (1 s) are removed,
the first ``tend·fs`` (100 s) kept; the mean is removed (the ESRF study removes it
from ``Va`` only; removing it from ``Vph``, ``Vpv`` changes nothing but the
0 Hz and first Welch bins); ``Va`` is low-passed at 50 Hz
(:func:`~fsmbench.budget.spectra.first_order_lowpass`); PSDs with
``pwelch(x, hanning(ceil(1*fs)), [], [], fs)``.

The ESRF study's conclusion (3.6) is a comparison of configurations (Table 3). It
is computed here as rms ratios in stated bands of ``Va``:

* ``drift``: the rms of the 1 s means (content below ~0.5 Hz);
* ``3–50 Hz`` and ``50 Hz–fs/2``: the Welch PSD summed over the band (from
  3 Hz: the 1 s Hann window's main lobe is ±2 Hz wide);
* ``total``: the time-domain rms.

A ratio is called significant when ``|ln ratio| > 2·√(σ₁² + σ₂²)``, σ the
relative standard deviation of each rms. σ comes from the spectrum's shape:
``σ_power² = ΣP²/(ΣP)²`` over independent spectral values (a Hann-tapered
periodogram of the 1 s means; for Welch bands, bins per equivalent noise
bandwidth and the Welch averages), ``σ_rms = σ_power/2``. For drifts with
correlation times near the record length this is approximate (a few degrees
of freedom); the sentence reports the ratios either way.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields
from typing import Any, Final

import control as ct
import numpy as np
import xarray as xr
from numba import njit
from numpy.typing import NDArray

from fsmbench.bench.blocks import newport_beam_matrix
from fsmbench.bench.esrf import tustin
from fsmbench.bench.huddle_tests import (
    HUDDLE_CONFIGS,
    HUDDLE_NAME,
    band_id,
    huddle_number,
    trim_huddle,
)
from fsmbench.bench.params import BenchParams
from fsmbench.budget.long_record import LongRecordSummary, summarise_long_record
from fsmbench.budget.signals import block_means, is_lazy, lowpass, trim_record
from fsmbench.budget.spectra import cumulative_power, esrf_welch
from fsmbench.jsonutil import hv
from fsmbench.signal.welch import hanning

__all__ = [
    "HUDDLE_CONFIGS",
    "PRACTICAL_CHANGE",
    "BandRms",
    "ConfigComparison",
    "DacNoiseEstimate",
    "HuddleAnalysis",
    "HuddleRecord",
    "QdNoiseEstimate",
    "analyse_huddle",
    "analyse_huddle_record",
    "band_id",
    "check_trim",
    "compare_huddle_records",
    "estimate_dac_noise",
    "estimate_qd_noise",
    "huddle_number",
    "run_controller",
    "trim_huddle",
]

FloatArray = NDArray[np.float64]

# Welch bands start at 3 Hz: the 1 s Hann window's main lobe spans ±2 Hz, so the
# bins below carry the drift's leakage.
_BANDS_HZ = ((3.0, 50.0), (50.0, math.inf))


@dataclass(frozen=True)
class BandRms:
    """rms of a band [signal unit] and its relative standard deviation (estimate)."""

    band: str
    f_lo_hz: float
    f_hi_hz: float
    rms: float
    rel_std: float


def _welch_band(f: FloatArray, psd: FloatArray, lo: float, hi: float, *, enbw_hz: float,
                averages: float) -> tuple[float, float]:
    sel = (f >= lo) & (f < hi) if math.isfinite(hi) else f >= lo
    p = psd[sel]
    df = float(f[1] - f[0])
    power = float(p.sum() * df)
    if power <= 0:
        return 0.0, math.inf
    n_ind = max(1.0, (p.sum() ** 2 / float((p**2).sum())) * df / enbw_hz)
    return math.sqrt(power), 0.5 / math.sqrt(n_ind * averages)


def _drift(x: Any, fs: float) -> tuple[float, float]:
    return _drift_of_means(block_means(x, per=round(fs)))


def _drift_of_means(m: FloatArray) -> tuple[float, float]:
    """Rms and relative std of the 1 s means ``m`` about their mean (the drift band)."""
    nb = m.size
    m = m - m.mean()
    # Independent spectral values of the 1 s means: a Hann-tapered periodogram (the
    # plain one leaks a red drift across all bins, which then look independent),
    # its shape-weighted bin count divided by the taper's ENBW of 1.5 bins.
    p = np.abs(np.fft.rfft(m * np.hanning(nb))[1:]) ** 2
    if nb < 2 or p.sum() <= 0:
        return 0.0, math.inf
    n_ind = max(1.0, p.sum() ** 2 / float((p**2).sum()) / 1.5)
    return float(np.sqrt(np.mean(m**2))), 0.5 / math.sqrt(n_ind)


def check_trim(ds: xr.Dataset, *, name: str, t0_s: float = 1.0) -> None:
    """Raise the trim's ValueError (naming ``name``) if fewer than 2 s remain after ``t0_s``.

    Reads only the first samples of ``t`` for a record out of core.
    """
    if not is_lazy(ds["t"].data):
        trim_huddle(ds, name=name, t0_s=t0_s)
        return
    fs = float(ds.attrs["fs_hz"])
    trim = trim_record(ds, t0_s=t0_s, duration_s=None, fs_hz=fs)
    if trim.n < 2 * math.ceil(fs):
        raise ValueError(f"{name}: {trim.n / fs:.3g} s left after removing t < {t0_s:g} s; "
                         "the huddle analysis needs at least 2 s (two 1 s Welch windows)")


def _trimmed(ds: xr.Dataset, *, name: str, t0_s: float, duration_s: float | None,
             fs: float) -> dict[str, Any]:
    """Mean-removed ``Va``, ``Vph``, ``Vpv`` after the trim (a record in memory)."""
    sig = trim_huddle(ds, name=name, t0_s=t0_s, duration_s=duration_s)
    return {k: sig[k] - sig[k].mean() for k in ("Va", "Vph", "Vpv")}


@dataclass(frozen=True)
class HuddleRecord:
    """One huddle test after the ESRF study's processing.

    ``f_hz`` (F,) and the one-sided PSDs ``psd_va_m2_per_hz``,
    ``psd_vph_v2_per_hz``, ``psd_vpv_v2_per_hz`` (F,) of the mean-removed
    signals; ``bands``: Va rms per band (drift, 3–50 Hz, 50 Hz–fs/2, total);
    ``va_lowpass_m`` (N,) [m]: the trimmed, mean-removed ``Va`` through the ESRF
    study's 50 Hz low pass, for the report's time figure (None out of core, where
    the figure draws the stability analysis's envelope).
    """

    name: str
    number: int
    closed_loop: bool
    compensation_unit: bool
    shielding: bool
    fs_hz: float
    duration_s: float
    va_rms_m: float
    va_lpf_rms_m: float
    vph_rms_v: float
    vpv_rms_v: float
    f_hz: FloatArray
    psd_va_m2_per_hz: FloatArray
    psd_vph_v2_per_hz: FloatArray
    psd_vpv_v2_per_hz: FloatArray
    welch_averages: float
    bands: tuple[BandRms, ...]
    va_lowpass_m: FloatArray | None = field(default=None, repr=False)

    def cumulative_rms(self, signal: str) -> FloatArray:
        """Cumulative rms from 0 Hz of ``"Va"`` [m], ``"Vph"`` or ``"Vpv"`` [V], shape (F,)."""
        psd = {"Va": self.psd_va_m2_per_hz, "Vph": self.psd_vph_v2_per_hz,
               "Vpv": self.psd_vpv_v2_per_hz}[signal]
        return np.sqrt(cumulative_power(self.f_hz, psd))

    def band(self, name: str) -> BandRms:
        """The band called ``name``."""
        for b in self.bands:
            if b.band == name:
                return b
        raise KeyError(f"no band {name!r}; bands are {[b.band for b in self.bands]}")

    def to_json(self) -> dict[str, object]:
        """Scalars and bands (the spectra stay in memory for the figures)."""
        out: dict[str, object] = {f.name: getattr(self, f.name) for f in fields(self)
                                  if not f.name.startswith("psd") and f.name not in
                                  ("f_hz", "bands", "va_lowpass_m")}
        out["bands"] = [{"id": band_id(b.band), "name": b.band, "low_hz": b.f_lo_hz,
                         "high_hz": b.f_hi_hz, "va_rms_m": b.rms, "rel_std": b.rel_std}
                        for b in self.bands]
        return out


def analyse_huddle_record(ds: xr.Dataset, *, name: str | None = None, t0_s: float = 1.0,
                          duration_s: float | None = None, lpf_hz: float = 50.0,
                          summary: LongRecordSummary | None = None) -> HuddleRecord:
    """ESRF study 3.2–3.5 on one record: trim, remove means, low-pass Va, Welch PSDs, band rms.

    Parameters
    ----------
    ds : xarray.Dataset
        ``Vph``, ``Vpv`` [V] and ``Va`` [m] on ``t`` [s], attribute ``fs_hz``.
    name : str, optional
        ``data_huddle_test_<n>`` (default: the ``experiment`` attribute).
    t0_s, duration_s : float
        The ESRF study's trim: drop ``t < t0``, keep ``duration`` [s] (None: the
        whole rest of the record, however long; out of core when ``ds`` holds
        Dask arrays).
    lpf_hz : float
        Corner of the low pass applied to Va [Hz] (ESRF study 3.3: 50 Hz).
    summary : LongRecordSummary, optional
        The record reduced out of core (:func:`~fsmbench.budget.long_record.summarise_long_record`
        with the same trim); computed here when ``ds`` holds Dask arrays and none is given.

    Raises
    ------
    ValueError
        Naming the record: not a Table 3 huddle test, a signal missing, < 2 s left.
    """
    name = str(ds.attrs.get("experiment", "")) if name is None else name
    number = huddle_number(name)
    closed, comp, alu = HUDDLE_CONFIGS[number]
    fs = float(ds.attrs["fs_hz"])
    if summary is None and is_lazy(ds["Va"].data):
        summary = summarise_long_record(ds, name=name, t0_s=t0_s, duration_s=duration_s,
                                        lpf_hz=lpf_hz)
    if summary is not None:  # out of core: the reductions of two sequential reads
        s_va, s_ph, s_pv = (summary.psd[k] for k in ("Va", "Vph", "Vpv"))
        va_lpf_rms = summary.va_lowpass_rms_m
        va_rms, vph_rms, vpv_rms = (summary.rms[k] for k in ("Va", "Vph", "Vpv"))
        drift = _drift_of_means(summary.va_second_means_m)
        n_samples = summary.n_samples
        va_lowpass = None
    else:
        sig = _trimmed(ds, name=name, t0_s=t0_s, duration_s=duration_s, fs=fs)
        va, vph, vpv = sig["Va"], sig["Vph"], sig["Vpv"]
        va_lowpass = lowpass(va, cutoff_hz=lpf_hz, fs_hz=fs)
        va_lpf_rms = float(np.sqrt(np.mean((va_lowpass - va_lowpass.mean()) ** 2)))
        s_va = esrf_welch(va, fs_hz=fs, name=f"{name}.Va")
        s_ph = esrf_welch(vph, fs_hz=fs, name=f"{name}.Vph")
        s_pv = esrf_welch(vpv, fs_hz=fs, name=f"{name}.Vpv")
        va_rms, vph_rms, vpv_rms = (float(np.sqrt(np.mean(x**2))) for x in (va, vph, vpv))
        drift = _drift(va, fs)
        n_samples = int(va.shape[0])
    f = np.asarray(s_va.f_hz)
    psd_va = np.asarray(s_va.values, dtype=float)
    w = hanning(s_va.window_length)
    enbw = fs * float((w**2).sum()) / float(w.sum()) ** 2
    bands = []
    rms, rel = drift
    bands.append(BandRms("drift", 0.0, 0.5, rms, rel))
    for lo, hi in _BANDS_HZ:
        hi_eff = min(hi, fs / 2.0)
        r, s = _welch_band(f, psd_va, lo, hi, enbw_hz=enbw, averages=s_va.effective_averages)
        bands.append(BandRms(f"{lo:g}–{hi_eff:g} Hz", lo, hi_eff, r, s))
    total_var = sum(b.rms**2 for b in bands)
    total_rel = (math.sqrt(sum((b.rms**2 * 2 * b.rel_std) ** 2 for b in bands if
                               math.isfinite(b.rel_std))) / (2 * total_var)
                 if total_var > 0 else math.inf)
    bands.append(BandRms("total", 0.0, fs / 2.0, va_rms, total_rel))
    return HuddleRecord(
        name=name, number=number, closed_loop=closed, compensation_unit=comp, shielding=alu,
        fs_hz=fs, duration_s=n_samples / fs, va_rms_m=va_rms, va_lpf_rms_m=va_lpf_rms,
        vph_rms_v=vph_rms, vpv_rms_v=vpv_rms,
        f_hz=f, psd_va_m2_per_hz=psd_va,
        psd_vph_v2_per_hz=np.asarray(s_ph.values, dtype=float),
        psd_vpv_v2_per_hz=np.asarray(s_pv.values, dtype=float),
        welch_averages=float(s_va.effective_averages), bands=tuple(bands),
        va_lowpass_m=va_lowpass)


@dataclass(frozen=True)
class QdNoiseEstimate:
    """4QD electronic noise from the open-loop huddle tests.

    ``psd_v2_per_hz`` (F, 2): mean Vph, Vpv PSD of the tests minus the ADC
    quantisation (``q²/(6 fs)`` one-sided) and the beam motion of the
    Newport's angle noise (``Gd² · Mn² · 2σθ²/fs``), floored at 0.
    """

    tests: tuple[str, ...]
    f_hz: FloatArray
    psd_v2_per_hz: FloatArray
    raw_rms_v: tuple[float, float]
    rms_v: tuple[float, float]
    adc_rms_v: float
    newport_rms_v: tuple[float, float]

    def to_json(self) -> dict[str, object]:
        """Scalars, SI units."""
        return {"tests": list(self.tests), "raw_rms_v": hv(self.raw_rms_v),
                "rms_v": hv(self.rms_v), "adc_rms_v": self.adc_rms_v,
                "newport_rms_v": hv(self.newport_rms_v)}


def estimate_qd_noise(records: Sequence[HuddleRecord], *,
                      params: BenchParams) -> QdNoiseEstimate | None:
    """Average the open-loop tests' 4QD PSDs and remove the known contributions (None if none)."""
    ol = [r for r in records if not r.closed_loop]
    if not ol:
        return None
    f = ol[0].f_hz
    if any(r.f_hz.shape != f.shape or not np.allclose(r.f_hz, f) for r in ol):
        raise ValueError("open-loop huddle tests have different Welch grids (sampling rates)")
    raw = np.stack([np.mean([r.psd_vph_v2_per_hz for r in ol], axis=0),
                    np.mean([r.psd_vpv_v2_per_hz for r in ol], axis=0)], axis=1)
    conv = params.converter
    fs = conv.fs_hz
    adc = conv.lsb_v**2 / (6.0 * fs)
    gd = params.quad_diode.gain_v_per_rad.as_array()
    mn = newport_beam_matrix(params)
    sig2 = params.newport.angle_noise_rms_rad**2
    newport = gd**2 * (mn**2).sum(axis=1) * 2.0 * sig2 / fs  # (2,) one-sided, white
    psd = np.maximum(raw - adc - newport[None, :], 0.0)
    df = float(f[1] - f[0])

    def rms(p: FloatArray) -> tuple[float, float]:
        v = np.sqrt(p.sum(axis=0) * df)
        return (float(v[0]), float(v[1]))

    nrms = np.sqrt(newport * fs / 2.0)
    return QdNoiseEstimate(tests=tuple(r.name for r in ol), f_hz=f, psd_v2_per_hz=psd,
                           raw_rms_v=rms(raw), rms_v=rms(psd), adc_rms_v=math.sqrt(adc * fs / 2),
                           newport_rms_v=(float(nrms[0]), float(nrms[1])))


@dataclass(frozen=True)
class DacNoiseEstimate:
    """Quantisation error of the Sercalo DAC measured in the closed-loop huddle tests.

    The unquantised command ``u = −K·Vp/Gd`` is rebuilt by running the
    controller on the recorded 4QD signals (from rest at the record's start,
    as the loop did); ``e = Uc − u`` is the DAC's error (|e| ≤ q/2 when the
    controller is the one that ran). ``psd_v2_per_hz`` (F, 2) one-sided;
    ``white_ratio`` (h, v): its mean over ``band_hz`` divided by ``q²/(6 fs)``.
    """

    tests: tuple[str, ...]
    f_hz: FloatArray
    psd_v2_per_hz: FloatArray
    rms_v: tuple[float, float]
    command_rms_v: tuple[float, float]
    max_abs_error_lsb: float
    band_hz: tuple[float, float]
    white_ratio: tuple[float, float]

    def to_json(self) -> dict[str, object]:
        """Scalars, SI units."""
        return {"tests": list(self.tests), "rms_v": hv(self.rms_v),
                "command_rms_v": hv(self.command_rms_v),
                "max_abs_error_lsb": self.max_abs_error_lsb, "band_hz": list(self.band_hz),
                "white_ratio": hv(self.white_ratio)}


@njit(cache=True)
def _state_space_run(a: FloatArray, b: FloatArray, c: FloatArray, d: FloatArray,
                     u: FloatArray) -> FloatArray:  # pragma: no cover - compiled
    # Explicit loops into preallocated state vectors: small matrix products allocate a new
    # array per call, which made this recursion ~10x slower than its arithmetic.
    n_t, n_in = u.shape
    n_x, n_out = a.shape[0], c.shape[0]
    y = np.empty((n_t, n_out))
    x = np.zeros(n_x)
    x_next = np.empty(n_x)
    for k in range(n_t):
        for i in range(n_out):
            acc = 0.0
            for j in range(n_x):
                acc += c[i, j] * x[j]
            for j in range(n_in):
                acc += d[i, j] * u[k, j]
            y[k, i] = acc
        for i in range(n_x):
            acc = 0.0
            for j in range(n_x):
                acc += a[i, j] * x[j]
            for j in range(n_in):
                acc += b[i, j] * u[k, j]
            x_next[i] = acc
        x, x_next = x_next, x
    return y


def run_controller(k: ct.StateSpace, r: FloatArray) -> FloatArray:
    """``K`` (discrete) applied to ``r`` (2, N) from rest; returns (2, N).

    The recursion runs compiled (numba): K holds a double integrator, so its
    polynomial or pole-zero forms are too ill-conditioned for a filter
    cascade, and a Python loop takes seconds per 10⁶ samples.
    """
    a, b, c, d = (np.ascontiguousarray(x, dtype=float) for x in (k.A, k.B, k.C, k.D))
    return np.asarray(_state_space_run(a, b, c, d, np.ascontiguousarray(r.T))).T


def estimate_dac_noise(recordings: Mapping[str, xr.Dataset], *, controller: ct.StateSpace,
                       params: BenchParams, t0_s: float = 1.0, duration_s: float = 100.0,
                       band_hz: tuple[float, float] = (350.0, 450.0),
                       ) -> tuple[DacNoiseEstimate | None, dict[str, str]]:
    """Measure the Sercalo DAC's quantisation error in the closed-loop huddle tests.

    Parameters
    ----------
    recordings : mapping
        Records; the closed-loop huddle tests holding ``Uch, Ucv`` are used.
    controller : control.StateSpace
        ``K: Rh, Rv → Uch, Ucv`` as it ran (discrete at ``1/fs``, or continuous:
        then Tustin at ``1/fs`` as the ESRF study's 9.3), closed as ``U = −K R``.
    params : BenchParams
        4QD gains the real-time code divides by (nominal), converter.
    band_hz : (float, float)
        Band of the white-noise comparison [Hz] (default: around the modes).

    Returns
    -------
    (DacNoiseEstimate or None, dict)
        The estimate (None if no record qualifies) and the records left out, with why.
    """
    conv = params.converter
    fs, q = conv.fs_hz, conv.lsb_v
    kd = controller if controller.dt else tustin(controller, ts_s=conv.ts_s)
    if not np.isclose(float(kd.dt), 1.0 / fs):
        raise ValueError(f"controller sampled at {kd.dt} s, records at {1.0 / fs} s")
    gd = params.quad_diode.gain_v_per_rad.as_array()
    used, psds, cmd, skipped, worst = [], [], [], {}, 0.0
    for name in sorted(recordings):
        m = HUDDLE_NAME.match(name)
        if m is None or not HUDDLE_CONFIGS.get(int(m.group(1)), (False,))[0]:
            continue
        ds = recordings[name]
        if "Uch" not in ds or "Ucv" not in ds:
            skipped[name] = "no Uch, Ucv recorded"
            continue
        if is_lazy(ds["Uch"].data):
            # A long record: the quantisation error is white, its first duration_s (the
            # seed's 100 s) give the estimate; the controller runs causally from rest.
            trim = trim_record(ds, t0_s=t0_s, duration_s=duration_s, fs_hz=fs)
            ds = ds.isel(t=slice(0, trim.start + trim.n)).compute()
        r = np.stack([np.asarray(ds["Vph"].values) / gd[0], np.asarray(ds["Vpv"].values) / gd[1]])
        u = -run_controller(kd, r)
        t = np.asarray(ds["t"].values)
        keep = np.flatnonzero(t >= t0_s)[: round(duration_s * fs)]
        e = np.stack([np.asarray(ds["Uch"].values), np.asarray(ds["Ucv"].values)])[:, keep]
        e = e - u[:, keep]
        worst_here = float(np.max(np.abs(e)) / q)
        if worst_here > 0.75:  # rounding gives ≤ 0.5 LSB; more means another controller ran
            skipped[name] = (f"recorded Uc is not the quantised output of the controller "
                             f"(max |Uc − u| = {worst_here:.2f} LSB)")
            continue
        worst = max(worst, worst_here)
        used.append(name)
        spectra = [esrf_welch(e[i], fs_hz=fs, name=f"{name}.Uc error") for i in (0, 1)]
        f = np.asarray(spectra[0].f_hz)
        psds.append([np.asarray(sp.values, dtype=float) for sp in spectra])
        cmd.append(np.sqrt(np.mean((u[:, keep] - u[:, keep].mean(axis=1, keepdims=True)) ** 2,
                                   axis=1)))
    if not used:
        return None, skipped
    psd = np.mean(np.asarray(psds), axis=0).T  # (F, 2)
    df = float(f[1] - f[0])
    rms = np.sqrt(psd.sum(axis=0) * df)
    sel = (f >= band_hz[0]) & (f < band_hz[1])
    ratio = psd[sel].mean(axis=0) / (q**2 / (6.0 * fs))
    c = np.mean(cmd, axis=0)
    return DacNoiseEstimate(
        tests=tuple(used), f_hz=f, psd_v2_per_hz=psd, rms_v=(float(rms[0]), float(rms[1])),
        command_rms_v=(float(c[0]), float(c[1])), max_abs_error_lsb=worst, band_hz=band_hz,
        white_ratio=(float(ratio[0]), float(ratio[1]))), skipped


#: A ratio of rms within ±10 % is "no change" in practice, whatever its statistical
#: significance: the budget's terms are known to no better than that.
PRACTICAL_CHANGE: Final = 0.10


@dataclass(frozen=True)
class ConfigComparison:
    """Ratio of Va rms per band between two configurations (numerator / denominator).

    ``significant``: beyond twice the two estimates' combined relative spread;
    ``practical``: beyond ±:data:`PRACTICAL_CHANGE`. A change is reported only when
    both hold; the sentence says which of the two a band misses.
    """

    effect: str
    numerator: str
    denominator: str
    ratios: Mapping[str, float]
    significant: Mapping[str, bool]
    sentence: str
    practical: Mapping[str, bool] = field(default_factory=dict)

    def to_json(self) -> dict[str, object]:
        """Plain values; ``bands``: one entry per band, ids of :func:`band_id`."""
        return {"effect": self.effect, "numerator": self.numerator,
                "denominator": self.denominator, "practical_change": PRACTICAL_CHANGE,
                "bands": [{"id": band_id(b), "name": b, "ratio": r,
                           "significant": self.significant[b],
                           "practical": self.practical.get(b, False)}
                          for b, r in self.ratios.items()],
                "sentence": self.sentence}


# (effect, numerator test, denominator test): what changes between them (seed Table 3).
_COMPARISONS = (("compensation unit", 2, 1), ("aluminium shielding in open loop", 4, 2),
                ("aluminium shielding in closed loop", 5, 3), ("closed loop", 3, 2))


def _ratio_words(band: str, r: float, *, significant: bool, practical: bool) -> str:
    change = f"{'reduces' if r < 1 else 'increases'} the {band} rms by {100 * abs(r - 1):.0f} %"
    if significant and practical:
        return f"{change} (×{r:.2f}, significant)"
    if significant:
        return (f"no change in practice in the {band} rms (×{r:.2f}: statistically "
                f"significant, but within ±{100 * PRACTICAL_CHANGE:.0f} %)")
    return f"no significant change in the {band} rms (×{r:.2f})"


def compare_huddle_records(effect: str, a: HuddleRecord, b: HuddleRecord) -> ConfigComparison:
    ratios, sig, practical = {}, {}, {}
    parts = []
    for ba in a.bands:
        bb = b.band(ba.band)
        # A zero or non-finite rms is no measurement: no ratio, never a finding.
        comparable = all(math.isfinite(x) and x > 0 for x in (ba.rms, bb.rms))
        r = ba.rms / bb.rms if comparable else math.nan
        spread = 2.0 * math.hypot(ba.rel_std, bb.rel_std)
        ratios[ba.band] = r
        sig[ba.band] = bool(comparable and abs(math.log(r)) > spread)
        practical[ba.band] = bool(comparable and abs(math.log(r)) > math.log1p(PRACTICAL_CHANGE))
        parts.append(_ratio_words(ba.band, r, significant=sig[ba.band],
                                  practical=practical[ba.band]) if comparable
                     else f"{ba.band}: not comparable (zero or non-finite rms)")
    changes = [k for k in ratios if sig[k] and practical[k] and k != "total"]
    verdict = (f"changes Va in practice in {', '.join(changes)}" if changes else
               f"makes no practical change to Va in any band (none both significant and "
               f"beyond ±{100 * PRACTICAL_CHANGE:.0f} %)")
    sentence = (f"{effect[0].upper()}{effect[1:]} (test {a.number} / test {b.number}): "
                + "; ".join(parts) + f". The {effect} {verdict}.")
    return ConfigComparison(effect, a.name, b.name, ratios, sig, sentence, practical)


@dataclass(frozen=True)
class HuddleAnalysis:
    """All huddle tests present, the configuration comparisons and the 4QD noise."""

    records: Mapping[int, HuddleRecord]
    comparisons: tuple[ConfigComparison, ...]
    qd_noise: QdNoiseEstimate | None
    conclusion: str

    def to_json(self) -> dict[str, object]:
        """``records`` keyed by test number (as strings), comparisons, conclusion."""
        return {"records": {str(k): r.to_json() for k, r in self.records.items()},
                "comparisons": [c.to_json() for c in self.comparisons],
                "qd_noise": None if self.qd_noise is None else self.qd_noise.to_json(),
                "conclusion": self.conclusion}


def analyse_huddle(recordings: Mapping[str, xr.Dataset], *, params: BenchParams,
                   t0_s: float = 1.0, duration_s: float | None = None,
                   lpf_hz: float = 50.0,
                   summaries: Mapping[str, LongRecordSummary] | None = None) -> HuddleAnalysis:
    """ESRF study section 3 on every ``data_huddle_test_<n>`` in ``recordings``.

    Parameters
    ----------
    recordings : mapping of str to xarray.Dataset
        Records by experiment name; names other than ``data_huddle_test_<n>`` are ignored.
    params : BenchParams
        ADC, 4QD gains and Newport angle noise (subtracted from the 4QD spectra).
    t0_s, duration_s, lpf_hz : float
        As :func:`analyse_huddle_record`.
    summaries : mapping of str to LongRecordSummary, optional
        Records already reduced out of core, by experiment name.

    Raises
    ------
    ValueError
        If no huddle test is present, or (naming it) if one is unusable.
    """
    names = sorted((n for n in recordings if HUDDLE_NAME.match(n)), key=huddle_number)
    if not names:
        raise ValueError("no huddle test (data_huddle_test_1..5) in the recordings")
    records = {huddle_number(n): analyse_huddle_record(
        recordings[n], name=n, t0_s=t0_s, duration_s=duration_s, lpf_hz=lpf_hz,
        summary=(summaries or {}).get(n))
               for n in names}
    comps = tuple(compare_huddle_records(effect, records[a], records[b])
                  for effect, a, b in _COMPARISONS if a in records and b in records)
    if comps:
        conclusion = " ".join(c.sentence for c in comps)
        ecu = next((c for c in comps if c.effect == "compensation unit"), None)
        if ecu is not None:
            agree = not (ecu.significant["drift"] or ecu.significant["total"])
            conclusion += (" The ESRF study (3.6) found no significant effect of the compensation "
                           "unit on the stability of the measurement; on the drift and the "
                           f"total rms these records {'agree' if agree else 'disagree'}.")
    else:
        conclusion = ("No pair of configurations differing by one element is present; "
                      "no comparison is possible.")
    return HuddleAnalysis(records=records, comparisons=comps,
                          qd_noise=estimate_qd_noise(list(records.values()), params=params),
                          conclusion=conclusion)
