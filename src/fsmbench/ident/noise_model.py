"""The bench's noise sources fitted to the open-loop huddle tests, in the engine's parameters.

:func:`fit_noise_model` fits the 4QD outputs (``Vph`` → h, ``Vpv`` → v) and
``Va`` of huddle tests 1, 2, 4 (seed trim t ≥ 1 s, mean removed, Welch PSDs
averaged weighted by effective averages) with what
:class:`~fsmbench.sim.stream.BenchStream` simulates. Rules and reasons:

* Band: 1 s Hann windows (the seed's) from 4 Hz and, for records ≥ 8 s, windows
  of half the shortest record (three segments) from ``4/T`` to 4 Hz: four bins
  clear the main lobe (DC, drift leakage). Out: the Nyquist bin and its main
  lobe, what lies above the file's 4QD amplifier's -0.5 dB (the engine adds the
  noise after it), ±3 Hz around mains harmonics (main lobe ±2 Hz, +1 Hz for a
  grid off 50/60 Hz).
* Fit: Whittle maximum likelihood ``Σ (ν/c)(ln S + P/S)`` (ν effective averages,
  c = ``nfft Σw⁴/(Σw²)²`` bins per independent value), by Fisher scoring,
  terms ≥ 0. Not least squares in log-PSD: a ν-average is Gamma distributed,
  ``ln P`` is biased by ψ(ν) − ln ν and wrongly weighted. Robust start: a
  Cauchy-loss fit of the log ratios of groups of bins (those of the fit error);
  groups beyond 5 std are then left out (rarely any where the model holds), so
  a shape the model lacks stays in its band. Model: white + A²·Φ + b²·Ψ, Φ the
  exact PSD of :class:`~fsmbench.sim.noise.FlickerStream` (AR(1) sum), Ψ the
  random walk's, each through the Hann kernel (three points at ±0.71/T match
  its second moment 1/(3T²)): no curvature bias of 1/f in the lowest bins.
* Significance: 1/f and slope above 3 std (one-sided 0.13 %); the walk: REML
  likelihood ratio above 9 (the same level on a boundary, χ̄² 50:50); a mains
  line above 5 std (~100 candidates per axis). Otherwise 0 in the engine.
* ``flicker_min_hz``: the file's, unless the profile likelihood over ``f_lo/10``
  to 1 Hz (A is defined at 1 Hz) beats it by 2Δℓ > 9: a flattening in the band.
* Mains: 50 or 60 Hz, the family whose significant lines (harmonics not shared)
  have the larger Σz². A line's power: its ±3 Hz bins less the model scaled to
  the bins 3–10 Hz either side; amplitude √(2P). The engine shares one tuple:
  it gets the per-harmonic rms of the axes (the right total power).
* Drift: means over whole seconds (whole mains cycles, ≤ 400 per test); REML of
  the walk's b², GLS of one slope shared by the tests (an offset each), with the
  exact block-mean covariance of the fitted white and 1/f noise.
* Known parts: the 4QD's own floor is the fit's less ``q²/(6 fs)`` and the
  Newport's ``Gd² Σ Mn² 2σθ²/fs`` (as :func:`~fsmbench.budget.huddle.estimate_qd_noise`);
  the Attocube's is ``Va``'s (white + C/f² from 20 Hz: air and thermal drifts
  have corners ≤ 0.16 Hz, C takes their tails) less ``r²/(6 fs)`` and the
  Newport's piston ``4 s² σθ²/fs``. σθ, s, Mn, q, r are the file's (assumed);
  the 4QD–``Va`` cross-spectrum measures σθ as a check.
* Fit error: 10 log10(P/S) on consecutive fitted bins averaged in groups of
  0.2 dB Welch scatter ``√(c/(ν n))`` (a whole band where too few). A band is
  flagged when its median |error| exceeds 1.5 dB and three times that scatter.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from fsmbench.bench.axes import AXES, PerAxis
from fsmbench.bench.blocks import newport_beam_matrix
from fsmbench.bench.huddle_tests import HUDDLE_CONFIGS, band_id, huddle_number, trim_huddle
from fsmbench.bench.params import BenchParams
from fsmbench.checks import Notice
from fsmbench.ident.fit.noise_fitting import (
    DB,
    ERROR_BANDS_HZ,
    Z_TERM,
    Estimate,
    Spectrum,
    groups,
    smeared,
    whittle,
)
from fsmbench.ident.fit.qd_noise import (
    MIN_LONG_S,
    AxisFit,
    QdBand,
    QdTerms,
    fit_qd_terms,
    near_harmonics,
    qd_band,
)
from fsmbench.jsonutil import plain_json, stamped
from fsmbench.sim.spectra import flicker_psd, walk_psd

__all__ = ["ERROR_BANDS_HZ", "BandError", "Estimate", "NoiseModelFit", "fit_noise_model"]

FloatArray = NDArray[np.float64]
_FORMAT = ("fsmbench.noise_model", 1)
_SIGNALS = ("Vph", "Vpv", "Va")
_VA_LO_HZ = 20.0
_FLAG_DB = 1.5
_ASSUMED = "assumed (bench file)"
_OPEN = {f"data_huddle_test_{k}" for k, (closed, _, _) in HUDDLE_CONFIGS.items() if not closed}


@dataclass(frozen=True)
class BandError:
    """Model against measured PSD of one signal in one band.

    Attributes
    ----------
    signal : {"Vph", "Vpv", "Va"}
    low_hz, high_hz : float
        The band [Hz].
    median_abs_db, worst_abs_db : float
        Median, largest |10 log10(P/S)| of the smoothed points [dB] (NaN: none).
    scatter_db : float
        Median Welch scatter (std) of one smoothed point [dB].
    points : int
        Smoothed points in the band (0: no fit there).
    """

    signal: str
    low_hz: float
    high_hz: float
    median_abs_db: float
    worst_abs_db: float
    scatter_db: float
    points: int

    @property
    def flagged(self) -> bool:
        """Median |error| above 1.5 dB and above three times the Welch scatter."""
        return bool(self.points and self.median_abs_db > max(_FLAG_DB, 3 * self.scatter_db))

    def to_json(self) -> dict[str, Any]:
        """The fields, ``id`` (``band_0p1_1_hz``) and ``flagged``."""
        return {**plain_json(asdict(self)), "flagged": self.flagged,
                "id": band_id(f"{self.low_hz:g}–{self.high_hz:g} Hz")}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> BandError:
        """Inverse of :meth:`to_json`."""
        return cls(str(d["signal"]), _num(d["low_hz"]), _num(d["high_hz"]),
                   _num(d["median_abs_db"]), _num(d["worst_abs_db"]), _num(d["scatter_db"]),
                   int(d["points"]))


@dataclass(frozen=True)
class NoiseModelFit:
    """The bench's noise model (module notes); its JSON keys are these field names.

    ``Mapping`` fields are ``{"h": …, "v": …}`` pairs. ``noise_rms_v``: the 4QD's
    own white noise per sample at ``engine_fs_hz`` [V]; ``floor_psd_v2_per_hz``:
    the fitted white floor [V²/Hz], less ``adc_psd_v2_per_hz`` and
    ``newport_psd_v2_per_hz``. ``mains_amplitude_v``: per axis and harmonic
    [V peak]; ``mains_engine_amplitude_v``: the engine's shared tuple.
    ``fit_band_hz``, ``va_fit_band_hz``: (low, high) [Hz] (NaN: no fit).
    ``newport_noise_rad``: the Newport's angle noise [rad rms]: ``estimate`` from
    the 4QD–Va cross-spectrum, ``value`` what the fit and the engine use (the
    estimate when resolved, ``significant``; else the bench file's).
    ``provenance``: parameter → ``"measured (tests)"`` or ``"assumed (bench file)…"``.
    """

    tests: tuple[str, ...]
    reason: str
    fs_hz: float
    engine_fs_hz: float
    qd_gain_v_per_rad: Mapping[str, float]
    qd_gain_source: str
    fit_band_hz: tuple[float, float]
    va_fit_band_hz: tuple[float, float]
    noise_rms_v: Mapping[str, Estimate]
    floor_psd_v2_per_hz: Mapping[str, float]
    adc_psd_v2_per_hz: float
    newport_psd_v2_per_hz: Mapping[str, float]
    flicker_asd_v_per_rthz: Mapping[str, Estimate]
    flicker_min_hz: float
    mains_freq_hz: float
    mains_amplitude_v: Mapping[str, tuple[Estimate, ...]]
    mains_engine_amplitude_v: tuple[float, ...]
    offset_drift_v_per_s: Mapping[str, Estimate]
    offset_random_walk_v_per_rts: Mapping[str, Estimate]
    attocube_noise_rms_m: Estimate
    va_floor_psd_m2_per_hz: float
    va_newport_psd_m2_per_hz: float
    newport_noise_rad: Estimate
    fit_errors: tuple[BandError, ...]
    notices: tuple[Notice, ...]
    provenance: Mapping[str, str]

    def apply(self, params: BenchParams) -> BenchParams:
        """``params`` with this model's 4QD, Newport and Attocube noise (engine values)."""
        def pair(d: Mapping[str, Estimate]) -> PerAxis:
            return PerAxis(h=d["h"].value, v=d["v"].value)

        qd = dataclasses.replace(
            params.quad_diode, noise_rms_v=pair(self.noise_rms_v),
            flicker_asd_v_per_rthz=pair(self.flicker_asd_v_per_rthz),
            flicker_min_hz=self.flicker_min_hz, mains_freq_hz=self.mains_freq_hz,
            mains_amplitude_v=tuple(self.mains_engine_amplitude_v),
            offset_drift_v_per_s=pair(self.offset_drift_v_per_s),
            offset_random_walk_v_per_rts=pair(self.offset_random_walk_v_per_rts))
        att = dataclasses.replace(params.attocube, noise_rms_m=self.attocube_noise_rms_m.value)
        newport = dataclasses.replace(params.newport,
                                      angle_noise_rms_rad=self.newport_noise_rad.value)
        return dataclasses.replace(params, quad_diode=qd, attocube=att, newport=newport)

    def qd_psd_v2_per_hz(self, f_hz: FloatArray, *, axis: str, total: bool = True) -> FloatArray:
        """Broadband one-sided PSD the engine gives a 4QD output, lines apart [V²/Hz].

        Parameters
        ----------
        f_hz : array, shape (F,)
            Frequencies [Hz], > 0.
        axis : {"h", "v"}
        total : bool
            Add the ADC quantisation and the assumed Newport floor (as recorded).

        Returns
        -------
        array, shape (F,)
            White + exact 1/f (FlickerStream's) + random walk at ``engine_fs_hz``.
        """
        fs, f = self.engine_fs_hz, np.asarray(f_hz, dtype=float)
        out = 2 * self.noise_rms_v[axis].value ** 2 / fs + np.zeros_like(f)
        if total:
            out = out + self.adc_psd_v2_per_hz + self.newport_psd_v2_per_hz[axis]
        if a := self.flicker_asd_v_per_rthz[axis].value:
            out = out + a**2 * flicker_psd(f, f_min_hz=self.flicker_min_hz, fs_hz=fs)
        return out + self.offset_random_walk_v_per_rts[axis].value ** 2 * walk_psd(f, fs_hz=fs)

    def to_json(self) -> dict[str, Any]:
        """Plain JSON: ``format``, ``format_version``, then every field by name."""
        def enc(v: Any) -> Any:
            if isinstance(v, Estimate | BandError | Notice):
                return v.to_json()
            if isinstance(v, Mapping):
                return {k: enc(x) for k, x in v.items()}
            return [enc(x) for x in v] if isinstance(v, tuple) else v

        body = {f.name: enc(getattr(self, f.name)) for f in dataclasses.fields(self)}
        # JSON keys are ids: "quad_diode.noise_rms_v" nests as quad_diode → noise_rms_v.
        nested: dict[str, dict[str, str]] = {}
        for key, words in self.provenance.items():
            group, _dot, name = key.partition(".")
            nested.setdefault(group, {})[name] = words
        body["provenance"] = nested
        return stamped(plain_json(body), format=_FORMAT[0], version=_FORMAT[1])

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> NoiseModelFit:
        """Inverse of :meth:`to_json`."""
        if (d.get("format"), d.get("format_version")) != _FORMAT:
            raise ValueError(f"not a {_FORMAT[0]} v{_FORMAT[1]} document")
        est, num = Estimate.from_json, _num
        dec: dict[str, Callable[[Any], Any]] = {
            "Estimate": est, "float": num, "str": str, "tuple[str, ...]": tuple,
            "Mapping[str, str]": dict,
            "Mapping[str, float]": lambda x: {a: num(x[a]) for a in AXES},
            "Mapping[str, Estimate]": lambda x: {a: est(x[a]) for a in AXES},
            "Mapping[str, tuple[Estimate, ...]]": lambda x: {a: tuple(map(est, x[a]))
                                                             for a in AXES},
            "tuple[float, float]": lambda x: (num(x[0]), num(x[1])),
            "tuple[float, ...]": lambda x: tuple(map(num, x)),
            "tuple[BandError, ...]": lambda x: tuple(map(BandError.from_json, x)),
            "tuple[Notice, ...]": lambda x: tuple(Notice(**n) for n in x)}
        d = {**d, "provenance": {f"{group}.{name}": words
                                 for group, names in d["provenance"].items()
                                 for name, words in names.items()}}
        return cls(**{f.name: dec[str(f.type)](d[f.name]) for f in dataclasses.fields(cls)})


def _num(x: Any) -> float:
    return math.nan if x is None else float(x)


# --------------------------------------------------------------------------- records, checks
def _open_tests(recordings: Mapping[str, xr.Dataset], notices: list[Notice]
                ) -> tuple[list[str], list[FloatArray], float | None]:
    """Names, trimmed (3, N) Vph, Vpv, Va records and rate of the usable open-loop tests."""
    names = sorted((n for n in recordings if n in _OPEN), key=huddle_number)
    rates = {n: float(recordings[n].attrs["fs_hz"]) for n in names}
    for n in names[1:]:
        if rates[n] != rates[names[0]]:
            raise ValueError(f"{n}: sampled at {rates[n]:g} Hz, but {names[0]} at "
                             f"{rates[names[0]]:g} Hz; the open-loop huddle tests must share "
                             "one sampling rate")
    used, xs = [], []
    for n in names:
        try:
            sig = trim_huddle(recordings[n], name=n)
        except ValueError as exc:
            notices.append(Notice("other", n, f"{exc}; test not used"))
            continue
        x = np.stack([sig[v] for v in _SIGNALS])
        if bad := [v for v, row in zip(_SIGNALS, x, strict=True) if not np.isfinite(row).all()]:
            notices.append(Notice("numeric", n, f"NaN or infinite samples in {', '.join(bad)}: "
                                  "test not used for the noise model"))
        elif flat := [v for v, row in zip(_SIGNALS, x, strict=True) if np.ptp(row) == 0]:
            notices.append(Notice("numeric", n, f"{', '.join(flat)} constant (no noise to fit): "
                                  "test not used for the noise model"))
        else:
            used.append(n)
            xs.append(x)
    return used, xs, (rates[names[0]] if names else None)


def _errors(signal: str, f: FloatArray, p: FloatArray, s: FloatArray, g: FloatArray,
            src: FloatArray, fs: float) -> list[BandError]:
    """Fit error per band on the groups of :func:`_groups` (module notes)."""
    labels = groups(f, g, src)
    err = np.abs(10 * np.log10(np.bincount(labels, p) / np.bincount(labels, s)))
    scat, first = DB / np.sqrt(np.bincount(labels, g)), f[np.unique(labels, return_index=True)[1]]
    out = []
    for lo, hi in ERROR_BANDS_HZ:
        e, sc = err[(first >= lo) & (first < hi)], scat[(first >= lo) & (first < hi)]
        out.append(BandError(signal, lo, min(hi, fs / 2), *(
            (float(np.median(e)), float(e.max()), float(np.median(sc))) if e.size
            else (math.nan,) * 3), int(e.size)))
    return out


_KEYS = ("noise_rms_v", "flicker_asd_v_per_rthz", "flicker_min_hz", "mains_freq_hz",
         "mains_amplitude_v", "offset_drift_v_per_s", "offset_random_walk_v_per_rts")
_INPUTS = ("quad_diode.gain_v_per_rad", "quad_diode.rotation_rad",
           "quad_diode.mains_phase_wander_rad_per_rts", "converter.range_v", "converter.bits",
           "attocube.resolution_m", "newport.angle_noise_rms_rad",
           "newport.beam_angle_per_mirror_angle", "geometry.newport_spot_offset_m")


def _assumed(params: BenchParams, *, reason: str, notices: list[Notice],
             gains: dict[str, float], source: str, fs: float) -> NoiseModelFit:
    """The bench file's noise values, all assumed (no usable record)."""
    qd, att, nan = params.quad_diode, params.attocube.noise_rms_m, math.nan

    def pair(x: PerAxis) -> dict[str, Estimate]:
        return {a: Estimate(x[a], x[a]) for a in AXES}

    amps = tuple(Estimate(a, a) for a in qd.mains_amplitude_v)
    notices.append(Notice("other", "noise model", f"{reason}: every noise value is the bench "
                          "file's (assumed)"))
    keys = [f"quad_diode.{k}" for k in _KEYS] + ["attocube.noise_rms_m", *_INPUTS]
    return NoiseModelFit(
        (), reason, fs, params.converter.fs_hz, gains, source, (nan, nan), (nan, nan),
        pair(qd.noise_rms_v), dict.fromkeys(AXES, nan), nan, dict.fromkeys(AXES, nan),
        pair(qd.flicker_asd_v_per_rthz), qd.flicker_min_hz, qd.mains_freq_hz,
        dict.fromkeys(AXES, amps), tuple(qd.mains_amplitude_v), pair(qd.offset_drift_v_per_s),
        pair(qd.offset_random_walk_v_per_rts), Estimate(att, att), nan, nan,
        Estimate(params.newport.angle_noise_rms_rad, nan, nan, False), (), tuple(notices),
        {k: f"{_ASSUMED}: {reason}" for k in keys})


#: The cross-spectrum's σθ replaces the bench file's when it is resolved this well:
#: a relative standard deviation ≤ 20 % (its square, the PSD, within ±40 %).
_NEWPORT_RESOLVED = 5.0


def _newport(s1: Spectrum, vsel: NDArray[np.intp], params: BenchParams, gd: FloatArray,
             notices: list[Notice]) -> Estimate:
    """The Newport's angle noise σθ from the 4QD–Va cross-spectrum [rad rms].

    The mirror's noise moves the beam on the 4QD (``Gd Mn θ``) and the path by its
    piston (``s Σ θ``), the only noise the two share: ``Re CSD(Vp, Va) = Gd s (Mn 1)
    2σθ²/fs``. ``value`` is the estimate when resolved (:data:`_NEWPORT_RESOLVED`
    standard deviations), else the bench file's; ``significant``: the estimate is used.
    """
    fs = 2 * float(s1.f[-1])
    s_off, sig = params.geometry.newport_spot_offset_m, params.newport.angle_noise_rms_rad
    k = gd * s_off * newport_beam_matrix(params).sum(axis=1) * 2.0 / fs  # Re CSD / σθ²
    if not vsel.size or np.any(k == 0):
        return Estimate(sig, math.nan, math.nan, False)
    pv = s1.s[vsel, 2, 2].real
    est = np.array([s1.s[vsel, i, 2].real.mean() for i in (0, 1)]) / k
    # Var of Re CSD is Pxx Pyy / (2 nu) per bin; c bins per independent value.
    var = np.array([s1.c * np.mean(s1.s[vsel, i, i].real * pv) / (2 * s1.nu * vsel.size)
                    for i in (0, 1)]) / k**2
    s2, sd2 = float(np.sum(est / var) / np.sum(1 / var)), float(np.sum(1 / var)) ** -0.5
    sth = math.sqrt(max(s2, 0.0))
    sd = sd2 / (2 * sth) if sth else math.sqrt(sd2)
    used = bool(sth > _NEWPORT_RESOLVED * sd)
    if used and abs(sth - sig) > Z_TERM * sd:
        notices.append(Notice("other", "Vph, Vpv, Va", f"the 4QD–Va cross-spectrum gives a "
                              f"Newport angle noise of {1e6 * sth:.3g} ± {1e6 * sd:.2g} µrad rms "
                              f"(with the file's spot offset), the bench file assumes "
                              f"{1e6 * sig:.3g} µrad: the measured value is used for the 4QD and "
                              "Va floors and the engine"))
    elif not used:
        notices.append(Notice("other", "Vph, Vpv, Va", f"the Newport angle noise is not resolved "
                              f"by the 4QD–Va cross-spectrum ({1e6 * sth:.3g} ± {1e6 * sd:.2g} "
                              f"µrad rms): the bench file's {1e6 * sig:.3g} µrad is used "
                              "(assumed)"))
    return Estimate(sth if used else sig, sth, sd, used)


def _attocube(s1: Spectrum, vsel: NDArray[np.intp], params: BenchParams, sigma_rad: float,
              fs_eng: float, notices: list[Notice]
              ) -> tuple[Estimate, float, float, FloatArray]:
    """Va floor (white + C/f²), its Newport piston (σθ given), Va's model on ``vsel``."""
    fs = 2 * float(s1.f[-1])
    fv, pv = s1.f[vsel], s1.s[vsel, 2, 2].real
    gv = np.full(fv.shape, s1.g)
    xv = np.column_stack([np.ones_like(fv), smeared(lambda x: x**-2.0, fv, fv * 0 + s1.t_w)])
    th, cov, _ = whittle(pv, xv, gv, np.zeros_like(fv), groups(fv, gv, np.zeros_like(fv)))
    s_off = params.geometry.newport_spot_offset_m
    piston = 4.0 * s_off**2 * sigma_rad**2 / fs  # s (θnh + θnv): 2 s² σθ², one-sided 2/fs
    own = th[0] - params.attocube.resolution_m**2 / (6.0 * fs) - piston
    rms = math.sqrt(max(own, 0.0) * fs_eng / 2)
    va = Estimate(rms, rms, math.sqrt(cov[0, 0]) * fs_eng / (4 * rms) if rms else math.nan)
    if own <= 0:
        notices.append(Notice("other", "Va", f"the Va floor {th[0]:.3g} m²/Hz is not above the "
                              "Newport piston and the resolution: the Attocube's own noise is "
                              "set to 0"))
    elif piston > 0.5 * th[0]:
        notices.append(Notice("other", "Va", f"{100 * piston / th[0]:.0f} % of the Va floor is "
                              f"the Newport angle noise's piston ({1e6 * sigma_rad:.3g} µrad, "
                              f"spot offset {1e3 * s_off:.3g} mm, the bench file's): the "
                              "Attocube's own noise rests on that offset"))
    return va, float(th[0]), piston, xv @ th


# --------------------------------------------------------------------------- the fit
def fit_noise_model(recordings: Mapping[str, xr.Dataset], *, params: BenchParams,
                    qd_gain_v_per_rad: tuple[float, float] | None = None) -> NoiseModelFit:
    """Fit the engine's noise parameters to the open-loop huddle tests (module notes).

    Parameters
    ----------
    recordings : mapping of str to xarray.Dataset
        Records by experiment name; ``data_huddle_test_1``, ``_2``, ``_4`` (open
        loop) are used: ``t`` [s], ``Vph``, ``Vpv`` [V], ``Va`` [m], each (N,),
        attribute ``fs_hz`` [Hz]. Others are ignored.
    params : BenchParams
        The bench file's nominal parameters: converter, Newport angle noise, beam
        geometry, spot offset, 4QD amplifier (assumed, not measured).
    qd_gain_v_per_rad : (float, float), optional
        Identified 4QD gains (h, v) [V/rad]; default the bench file's (said so).

    Returns
    -------
    NoiseModelFit
        Without a usable open-loop test: the bench file's values, all assumed.

    Raises
    ------
    ValueError
        Naming the test, if the open-loop tests' sampling rates differ.
    """
    notices: list[Notice] = []
    qd, conv = params.quad_diode, params.converter
    source = "nominal" if qd_gain_v_per_rad is None else "identified"
    gd = np.asarray(qd.gain_v_per_rad.as_array() if qd_gain_v_per_rad is None
                    else qd_gain_v_per_rad, dtype=float)
    gains = {a: float(gd[i]) for i, a in enumerate(AXES)}
    if qd_gain_v_per_rad is None:
        notices.append(Notice("other", "4QD gains", "no identified 4QD gains: the Newport's "
                              "share of the 4QD floors uses the bench file's (nominal) gains"))
    tests, xs, fs_rec = _open_tests(recordings, notices)
    if not tests or fs_rec is None:
        return _assumed(params, reason="no open-loop huddle test (data_huddle_test_1, 2, 4)"
                        + (" usable" if fs_rec else " in the recordings"), notices=notices,
                        gains=gains, source=source, fs=fs_rec or conv.fs_hz)
    fs, fs_eng, n_min = fs_rec, conv.fs_hz, min(x.shape[1] for x in xs)
    if fs != fs_eng:
        notices.append(Notice("rate", ", ".join(tests), f"records at {fs:g} Hz, bench file at "
                              f"{fs_eng:g} Hz: white noises are per sample at the file's rate"))
    band = qd_band(xs, fs=fs, qd=qd)
    if band.sl is None:
        notices.append(Notice("other", "Vph, Vpv", f"records of {n_min / fs:.3g} s, shorter than "
                              f"the {MIN_LONG_S:g} s the 1/f fit needs: only the white floor "
                              "was fitted; the 1/f noise is the bench file's"))
    terms = fit_qd_terms(band, xs, qd=qd)
    if terms.mains:
        notices.append(Notice("other", "Vph, Vpv", f"mains at {terms.mains:g} Hz, "
                              f"{len(terms.engine)} harmonic(s): the engine shares one amplitude "
                              "per harmonic between the axes and gets the rms of the two axes' "
                              "amplitudes (both reported)"))
    # The Newport's angle noise from the 4QD–Va cross-spectrum (the file's if not resolved),
    # then the 4QD's own white noise: the floor less the ADC and that Newport share.
    s1, f_hi = band.s1, band.f_hi
    vsel = np.flatnonzero((s1.f >= _VA_LO_HZ) & (s1.f < f_hi) & ~near_harmonics(s1.f, terms.mains))
    check = _newport(s1, vsel, params, gd, notices)
    adc = conv.lsb_v**2 / (6.0 * fs)
    newport = (gd**2 * (newport_beam_matrix(params) ** 2).sum(axis=1) * 2.0
               * check.value**2 / fs)
    white, undetermined = _qd_white(terms.fits, adc=adc, newport=newport, fs_eng=fs_eng,
                                    params=params, notices=notices)
    va, va_floor, piston, s_va = _attocube(s1, vsel, params, check.value, fs_eng, notices)
    errors = _fit_errors(band, terms, vsel=vsel, s_va=s_va, notices=notices)
    prov = _provenance(tests, terms=terms, short=band.sl is None, newport=check.significant,
                       identified=source == "identified", undetermined=undetermined)
    fits = terms.fits
    return NoiseModelFit(
        tuple(tests), "", fs, fs_eng, gains, source, (band.f_lo, f_hi), (_VA_LO_HZ, f_hi), white,
        {a: fits[ch].broadband.w for ch, a in enumerate(AXES)}, adc,
        {a: float(newport[ch]) for ch, a in enumerate(AXES)},
        {a: fits[ch].flicker for ch, a in enumerate(AXES)}, terms.f_min,
        terms.mains or qd.mains_freq_hz, terms.lines, terms.engine, terms.drift, terms.walk, va,
        va_floor, piston, check, tuple(errors), tuple(notices), prov)


def _qd_white(fits: tuple[AxisFit, ...], *, adc: float, newport: FloatArray, fs_eng: float,
              params: BenchParams, notices: list[Notice]
              ) -> tuple[dict[str, Estimate], list[str]]:
    """The 4QD's own white noise per axis [V rms per sample at ``fs_eng`` Hz] and the axes
    whose floor does not exceed the ADC's ``adc`` and the Newport's ``newport`` [V²/Hz]."""
    white = {}
    undetermined = []
    for ch, axis in enumerate(AXES):
        rms = math.sqrt(max(own := fits[ch].broadband.w - adc - newport[ch], 0.0) * fs_eng / 2)
        sd = math.sqrt(fits[ch].broadband.cov[0, 0]) * fs_eng / (4 * rms) if rms else math.nan
        white[axis] = Estimate(rms, rms, sd)
        if own <= 0:
            # The floor is all the ADC's and the Newport's (as its angle noise measured at
            # low frequency predicts it there): the records do not separate the 4QD's own
            # noise, which is not zero for that; the engine keeps the bench file's.
            white[axis] = Estimate(float(params.quad_diode.noise_rms_v[axis]), 0.0, math.nan,
                                   significant=False)
            undetermined.append(axis)
            notices.append(Notice(
                "other", _SIGNALS[ch],
                f"the white floor ({fits[ch].broadband.w:.3g} V²/Hz) is not above the ADC's and "
                f"the Newport's share ({adc + newport[ch]:.3g} V²/Hz): the records do not "
                "separate the 4QD's own white noise from the Newport's; the bench file's is "
                "kept (assumed)"))
    return white, undetermined


def _fit_errors(band: QdBand, terms: QdTerms, *, vsel: NDArray[np.intp], s_va: FloatArray,
                notices: list[Notice]) -> list[BandError]:
    """The fit error per band of Vph, Vpv and Va (``s_va``: Va's model on ``vsel``); a
    notice for each band flagged."""
    f, t_w, p, g, src, mask, fs = band.f, band.t_w, band.p, band.g, band.src, terms.mask, band.fs
    errors = [e for ch in (0, 1) for e in _errors(
        _SIGNALS[ch], f[mask], p[mask, ch], terms.fits[ch].broadband.psd(f[mask], t_w[mask], fs),
        g[mask], src[mask], fs)]
    s1 = band.s1
    errors += _errors("Va", s1.f[vsel], s1.s[vsel, 2, 2].real, s_va, np.full(vsel.size, s1.g),
                      np.zeros(vsel.size), fs)
    notices.extend(
        Notice("other", e.signal, f"model misfit in {e.low_hz:g}–{e.high_hz:g} Hz: median "
               f"|error| {e.median_abs_db:.2f} dB (worst {e.worst_abs_db:.2f} dB, Welch scatter "
               f"{e.scatter_db:.2f} dB) > {_FLAG_DB:g} dB: a shape the engine cannot simulate "
               "(e.g. a resonance in the noise)")
        for e in errors if e.flagged)
    return errors


def _provenance(tests: list[str], *, terms: QdTerms, short: bool, newport: bool,
                identified: bool, undetermined: list[str]) -> dict[str, str]:
    """Parameter → where its value comes from (``NoiseModelFit.provenance``).

    ``short``: records too short for the 1/f fit; ``newport``: the cross-spectrum
    resolved the Newport's angle noise; ``identified``: the 4QD gains were;
    ``undetermined``: the axes whose own white noise is the bench file's.
    """
    why = {"flicker_asd_v_per_rthz": "records too short" if short else "",
           "flicker_min_hz": "" if terms.f_min_measured else "no flattening in the band",
           "mains_freq_hz": "" if terms.mains else "no significant mains line"}
    prov = {f"quad_diode.{k}": f"{_ASSUMED}: {why[k]}" if why.get(k) else
            f"measured ({', '.join(tests)})" for k in _KEYS}
    prov["attocube.noise_rms_m"] = f"measured ({', '.join(tests)})"
    prov |= dict.fromkeys(_INPUTS, _ASSUMED)
    if newport:
        prov["newport.angle_noise_rms_rad"] = (f"measured ({', '.join(tests)}: the 4QD–Va "
                                               "cross-spectrum)")
    if identified:
        prov["quad_diode.gain_v_per_rad"] = "measured (identification)"
    if undetermined:
        prov["quad_diode.noise_rms_v"] = (f"{_ASSUMED}: not separated from the Newport's "
                                          f"noise ({', '.join(undetermined)})")
    return prov
