"""The 4QD outputs' noise terms fitted on the open-loop huddle tests' spectra.

Used by :mod:`fsmbench.ident.noise_model` (its module notes state the rules):
the bins fitted (the long Welch spectrum below 4 Hz, the 1 s one above), white +
1/f (+ the random walk) per axis, the mains family and its lines, the 1/f
noise's flattening, the offset's drift and walk on block means. The fitters
themselves are :mod:`fsmbench.ident.fit.noise_fitting`'s.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fsmbench.bench.axes import AXES
from fsmbench.bench.params import QuadDiodeParams
from fsmbench.ident.fit.noise_fitting import (
    LINE_HALF_HZ,
    LR_TERM,
    Z_LINE,
    Z_TERM,
    Broadband,
    Estimate,
    Spectrum,
    block_cov,
    broadband,
    drift_fit,
    line_estimate,
    line_excess,
    welch,
)

__all__ = ["MIN_LONG_S", "AxisFit", "QdBand", "QdTerms", "fit_qd_terms", "near_harmonics",
           "qd_band"]

FloatArray = NDArray[np.float64]
#: Where the 1 s spectrum takes over from the long one [Hz].
SPLIT_HZ = 4.0
#: Shortest records [s] with a long spectrum (three segments of half the shortest record).
MIN_LONG_S = 8.0


def near_harmonics(f: FloatArray, f0: float | None) -> NDArray[np.bool_]:
    """Bins within the line half-width of a harmonic of f0 (none when f0 is None)."""
    k = np.round(f / (f0 or 1.0))
    return np.asarray((f0 is not None) & (k >= 1) & (np.abs(f - k * (f0 or 1.0)) <= LINE_HALF_HZ))


@dataclass(frozen=True, eq=False)
class QdBand:
    """The 4QD outputs' bins fitted, both Welch spectra joined at :data:`SPLIT_HZ`."""

    fs: float  # sampling rate of the records [Hz]
    s1: Spectrum  # 1 s Hann windows (the seed's)
    sl: Spectrum | None  # windows of half the shortest record (None: records too short)
    f_lo: float  # lowest frequency fitted [Hz]
    f_hi: float  # highest [Hz]: Nyquist's main lobe and the amplifier's -0.5 dB left out
    f: FloatArray  # (F,) the bins [Hz]
    t_w: FloatArray  # (F,) window length of each bin's spectrum [s]
    g: FloatArray  # (F,) independent values per bin (ν/c)
    src: FloatArray  # (F,) which spectrum: 0, 1 in the order long, 1 s
    p: FloatArray  # (F, 2) Vph, Vpv PSD [V²/Hz]


def qd_band(xs: list[FloatArray], *, fs: float, qd: QuadDiodeParams) -> QdBand:
    """The bins fitted, from the tests' (3, N) Vph, Vpv, Va records at ``fs`` [Hz].

    ``qd`` is the bench file's 4QD: its amplifier's bandwidth ends the band.
    """
    n_min = min(x.shape[1] for x in xs)
    s1 = welch(xs, math.ceil(fs), fs)
    # The long window: half the shortest record, at most 2**21 samples (memory of the FFTs).
    sl = welch(xs, min(n_min // 2, 2**21), fs) if n_min / fs >= MIN_LONG_S else None
    f_hi = fs / 2 - 2.0 / s1.t_w
    if qd.bandwidth_hz > 0:  # where the file's amplifier attenuates by 0.5 dB
        f_hi = min(f_hi, qd.bandwidth_hz * (10**0.05 - 1) ** (0.5 / qd.bandwidth_order))
    f_lo = 4.0 / sl.t_w if sl is not None else SPLIT_HZ
    parts = [(sp, np.flatnonzero((sp.f >= lo) & (sp.f < hi))) for sp, lo, hi in
             ([(sl, f_lo, SPLIT_HZ)] if sl is not None else []) + [(s1, SPLIT_HZ, f_hi)]]
    f, t_w, g, src = (np.concatenate(a) for a in zip(*[
        (sp.f[i], np.full(i.size, sp.t_w), np.full(i.size, sp.g), np.full(i.size, float(k)))
        for k, (sp, i) in enumerate(parts)], strict=True))
    p = np.concatenate([sp.s[i][:, [0, 1], [0, 1]].real for sp, i in parts])  # (F, 2)
    return QdBand(fs, s1, sl, f_lo, f_hi, f, t_w, g, src, p)


@dataclass(frozen=True, eq=False)
class AxisFit:
    """One 4QD output's broadband fit and its 1/f amplitude."""

    broadband: Broadband  # white + 1/f (+ the walk, fixed)
    flicker: Estimate  # A [V/√Hz at 1 Hz]: value 0 when not significant, the file's if short


def _fit_axis(band: QdBand, ch: int, *, mask: NDArray[np.bool_], f_min: float,
             qd: QuadDiodeParams, b2: float = 0.0) -> AxisFit:
    """White + 1/f of output ``ch`` (0 Vph, 1 Vpv) on the bins ``mask``, the walk ``b2`` fixed.

    ``f_min`` [Hz] is FlickerStream's lowest corner, ``b2`` [V²/s]. The 1/f term
    is dropped when not significant, and is the bench file's (``qd``) when the
    records are too short for the long spectrum.
    """
    args = (band.f[mask], band.t_w[mask], band.p[mask, ch], band.g[mask], band.src[mask])
    fs = band.fs
    if band.sl is None:  # too short: white only, the file's 1/f
        a = qd.flicker_asd_v_per_rthz[AXES[ch]]
        return AxisFit(broadband(*args, fs=fs, f_min=f_min, fit_flicker=False, a2=a * a, b2=b2),
                       Estimate(a, a))
    bb = broadband(*args, fs=fs, f_min=f_min, fit_flicker=True, b2=b2)
    sd2, a = math.sqrt(bb.cov[1, 1]), math.sqrt(bb.a2)
    est = Estimate(a, a, sd2 / (2 * a) if a else math.sqrt(sd2), bb.a2 > Z_TERM * sd2)
    if est.significant:
        return AxisFit(bb, est)
    return AxisFit(broadband(*args, fs=fs, f_min=f_min, fit_flicker=False, b2=b2),
                   dataclasses.replace(est, value=0.0))


@dataclass(frozen=True, eq=False)
class QdTerms:
    """The 4QD outputs' noise terms (module notes of :mod:`fsmbench.ident.noise_model`)."""

    fits: tuple[AxisFit, ...]  # h, v: the final fits (mains lines out, the walk fixed)
    mask: NDArray[np.bool_]  # the band's bins fitted (the mains lines out)
    f_min: float  # FlickerStream's lowest corner [Hz]
    f_min_measured: bool  # the profile found a flattening in the band (else the file's)
    mains: float | None  # mains frequency [Hz] (None: no significant line)
    drift: dict[str, Estimate]  # offset drift per axis [V/s]
    walk: dict[str, Estimate]  # offset random walk per axis [V/√s]
    lines: dict[str, tuple[Estimate, ...]]  # mains amplitude per axis and harmonic [V peak]
    engine: tuple[float, ...]  # the engine's amplitude per harmonic, shared [V peak]


def fit_qd_terms(band: QdBand, xs: list[FloatArray], *, qd: QuadDiodeParams) -> QdTerms:
    """Broadband, mains, 1/f floor and drift of both outputs (``xs``: the tests' records)."""
    f_hi = band.f_hi
    # Broadband clear of both mains families, then the family, then refit without its lines.
    clear = ~(near_harmonics(band.f, 50.0) | near_harmonics(band.f, 60.0))
    fits = [_fit_axis(band, ch, mask=clear, f_min=qd.flicker_min_hz, qd=qd) for ch in (0, 1)]
    harmonics = {f0: range(1, int((f_hi - LINE_HALF_HZ) // f0) + 1) for f0 in (50.0, 60.0)}
    mains = _mains_family(band, fits, harmonics=harmonics)
    mask = ~near_harmonics(band.f, mains)
    fits = [_fit_axis(band, ch, mask=mask, f_min=qd.flicker_min_hz, qd=qd) for ch in (0, 1)]
    fits, f_min, f_min_measured = _flicker_floor(band, fits, mask=mask, qd=qd)
    drift, walk = _offset_drift(xs, fits, fs=band.fs, f_min=f_min)
    if walk["h"].value or walk["v"].value:
        fits = [_fit_axis(band, ch, mask=mask, f_min=f_min, qd=qd, b2=walk[a].value ** 2)
                for ch, a in enumerate(AXES)]
    lines, engine = _mains_lines(band, fits, mains=mains, harmonics=harmonics)
    return QdTerms(tuple(fits), mask, f_min, f_min_measured, mains, drift, walk, lines, engine)


def _line(band: QdBand, ch: int, *, f0: float, bb: Broadband) -> tuple[float, float, float]:
    """:func:`line_excess` of the line at ``f0`` [Hz] on the 1 s spectrum over ``bb``."""
    return line_excess(band.s1, ch, f0,
                       lambda fr: bb.psd(fr, np.full_like(fr, band.s1.t_w), band.fs))


def _mains_family(band: QdBand, fits: list[AxisFit], *,
                  harmonics: dict[float, range]) -> float | None:
    """50 or 60 Hz: the family whose significant lines (harmonics not shared) have the
    larger Σz²; None when neither has one."""
    scores = dict.fromkeys(harmonics, 0.0)
    for f0, other in ((50.0, 60.0), (60.0, 50.0)):
        for m, ch in ((m, ch) for m in harmonics[f0] for ch in (0, 1)):
            if abs(m * f0 - other * round(m * f0 / other)) > 2 * LINE_HALF_HZ:  # not shared
                ex, sd0, _ = _line(band, ch, f0=m * f0, bb=fits[ch].broadband)
                scores[f0] += (ex / sd0) ** 2 if ex > Z_LINE * sd0 else 0.0
    return max(scores, key=lambda k: scores[k]) if max(scores.values()) > 0 else None


def _flicker_floor(band: QdBand, fits: list[AxisFit], *, mask: NDArray[np.bool_],
                   qd: QuadDiodeParams) -> tuple[list[AxisFit], float, bool]:
    """The fits, ``flicker_min_hz`` [Hz] and whether the profile measured it.

    The file's, unless the profile likelihood over ``f_lo/10`` to 1 Hz beats it by
    2Δℓ > 9 on the axes with a significant 1/f term (the fits are then redone).
    """
    f_min, measured = qd.flicker_min_hz, False
    if band.sl is not None and (sig_axes := [ch for ch in (0, 1) if fits[ch].flicker.significant]):
        f_lo = band.f_lo
        grid = np.geomspace(f_lo / 10, 1.0, max(2, math.ceil(4 * math.log10(10 / f_lo)) + 1))
        nll = [sum(_fit_axis(band, ch, mask=mask, f_min=fm, qd=qd).broadband.nll
                   for ch in sig_axes) for fm in grid]
        if 2 * (sum(fits[ch].broadband.nll for ch in sig_axes) - min(nll)) > LR_TERM:
            f_min, measured = float(grid[int(np.argmin(nll))]), True
            fits = [_fit_axis(band, ch, mask=mask, f_min=f_min, qd=qd) for ch in (0, 1)]
    return fits, f_min, measured


def _offset_drift(xs: list[FloatArray], fits: list[AxisFit], *, fs: float, f_min: float
                  ) -> tuple[dict[str, Estimate], dict[str, Estimate]]:
    """Drift [V/s] and random walk [V/√s] per axis, GLS and REML on block means.

    ``fits`` give the white and 1/f noise the block means' covariance holds;
    ``fs`` [Hz], ``f_min`` FlickerStream's lowest corner [Hz].
    """
    # Drift on means over whole seconds (whole mains cycles), at most 400 per test.
    n_min = min(x.shape[1] for x in xs)
    t_b = float(max(1, math.ceil(n_min / fs / 400)))
    mb = round(t_b * fs)
    nb = [x.shape[1] // mb for x in xs]
    drift: dict[str, Estimate] = {}
    walk: dict[str, Estimate] = {}
    for ch, axis in enumerate(AXES):
        bb = fits[ch].broadband
        stat = block_cov(max(nb), m=mb, fs=fs, white_var=bb.w * fs / 2, a2=bb.a2, f_min=f_min)
        drift[axis], walk[axis] = drift_fit(
            [x[ch, :n * mb].reshape(n, mb).mean(axis=1) for x, n in zip(xs, nb, strict=True)],
            [stat[:n, :n] for n in nb], t_b)
    return drift, walk


def _mains_lines(band: QdBand, fits: list[AxisFit], *, mains: float | None,
                 harmonics: dict[float, range]
                 ) -> tuple[dict[str, tuple[Estimate, ...]], tuple[float, ...]]:
    """Each axis's mains lines up to the last significant harmonic [V peak], and the
    engine's shared amplitude per harmonic (the rms of the axes') [V peak]."""
    lines: dict[str, tuple[Estimate, ...]] = dict.fromkeys(AXES, ())
    engine: tuple[float, ...] = ()
    if mains:
        raw = {a: [line_estimate(*_line(band, ch, f0=m * mains, bb=fits[ch].broadband))
                   for m in harmonics[mains]] for ch, a in enumerate(AXES)}
        top = max((i + 1 for a in AXES for i, e in enumerate(raw[a]) if e.significant), default=0)
        lines = {a: tuple(raw[a][:top]) for a in AXES}
        engine = tuple(math.hypot(lines["h"][i].value, lines["v"][i].value) / math.sqrt(2)
                       for i in range(top))
    return lines, engine
