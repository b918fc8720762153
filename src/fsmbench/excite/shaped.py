"""Multisines shaped for a closed-loop measurement: the same beam motion on every line.

With the loop closed, the plant's estimate on a line is as precise as the
loop's output on that line stands above the noise: ``G = S_yr S_ur^-1`` has
relative variance ``var(v) / |S_yr r|^2`` (:mod:`fsmbench.ident.frf.closed_loop`),
and ``S_yr r`` is the beam motion the excitation makes, which is also what a
user's bound on the tracking error limits. So the most precise measurement
within a bound moves the beam equally on every excited line: each line's
amplitude is inversely proportional to the closed loop's response from the
excitation to the beam, ``|T_R(f)| = max over Rh, Rv``.

The response comes from a model, and the Sercalo's resonance may have moved
(the drift a re-identification is for): a line amplitude set by the model's
response at a sharp resonance would be tens of times too large at the real one.
So ``T_R`` is taken as its largest value over a set of models (the bench model
with its modes moved by the design's robust set, ±5 % and damping ×0.5 and ×2):
a line near a resonance gets the amplitude that keeps the beam within its share
wherever in the set the resonance really is. Amplitudes are limited to a
``dynamic_range`` between the largest and the smallest line.

Phases: Schroeder's for an arbitrary power spectrum (Schroeder 1970,
``phi_k = -2 pi sum_{l<k} (k - l) p_l`` with ``p_l`` each line's share of the
power), then clipping iterations with the amplitudes held (the time-frequency
swapping of :func:`fsmbench.excite.design.minimise_crest_factor`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from fsmbench.bench.params import Bench, BenchParams
from fsmbench.excite.closed_loop import closed_loop_peaks, injection_input, robust_loops
from fsmbench.excite.design import (
    ExcitationDesign,
    GridKind,
    _period_samples,
    crest_factor,
    grid_lines,
)
from fsmbench.excite.limits import input_response
from fsmbench.sim.discretize import DiscretePlant
from fsmbench.sim.engine import DiscreteController
from fsmbench.sim.plant import bench_discrete

if TYPE_CHECKING:
    from fsmbench.excite.closed_loop import ClosedLoopLimitReport

__all__ = ["BoundedMeasurement", "beam_bounded_measurement", "beam_response",
           "multisine_of_lines", "resonance_bands", "shaped_multisine", "shaped_phases",
           "worst_beam_rms"]

# Grid of a resonance band for its largest response (41 Hz wide at 411 Hz ±5 %: 0.01 Hz steps,
# a tenth of a 0.1 %-damped mode's half-power width).
_BAND_POINTS = 4000
# Share of the beam-error budget (its square) for the lines outside the resonance bands; the
# rest goes to the bands, whose lines carry the modes' frequency and damping.
_OUTSIDE_SHARE = 0.5
#: Largest ratio of the largest to the smallest line amplitude, default.
DEFAULT_DYNAMIC_RANGE = 1e3


def beam_response(loops: Sequence[DiscretePlant], f_hz: np.ndarray, *, input: str,
                  bands_hz: Sequence[tuple[float, float]] = (),
                  band_points: int = _BAND_POINTS) -> np.ndarray:
    """Largest ``|T_R(f)|`` over ``loops`` and the two beam axes [rad/V], shape (F,).

    Parameters
    ----------
    loops : sequence of DiscretePlant
        Closed loops (:func:`fsmbench.sim.closed_loop.closed_loop_plant`) with
        outputs ``Rh``, ``Rv``.
    f_hz : ndarray, shape (F,)
        Lines [Hz].
    input : str
        The loop's input the excitation enters (``Uch`` or ``ref_Vph`` …).
    bands_hz : sequence of (float, float)
        Bands where a resonance may sit anywhere (the robust set's resonance shifts
        are a continuum, its models only a few points of it): a line inside one
        gets the largest response of each model over the whole band, on a grid
        of ``band_points`` (so that a mode of 0.1 % damping is resolved).
    band_points : int
        Points of that grid per band.
    """
    f = np.asarray(f_hz, dtype=float)
    out = np.zeros(f.size)
    for loop in loops:
        h = input_response(loop, f, input=input, outputs=("Rh", "Rv"))
        out = np.maximum(out, np.abs(h).max(axis=1))
        for lo, hi in bands_hz:
            inside = (f >= lo) & (f <= hi)
            if inside.any():
                fine = np.linspace(lo, hi, band_points)
                peak = np.abs(input_response(loop, fine, input=input,
                                             outputs=("Rh", "Rv"))).max()
                out[inside] = np.maximum(out[inside], peak)
    return out


def _worst_parts(loops: Sequence[DiscretePlant], f: np.ndarray, a: np.ndarray, *, input: str,
                 bands_hz: Sequence[tuple[float, float]], shift: float, n_shifts: int
                 ) -> tuple[float, list[float], list[np.ndarray]]:
    """``sum a^2 |T|^2`` outside the bands (worst model) and per band (worst model and move)."""
    inside = np.zeros(f.size, dtype=bool)
    masks = []
    for lo, hi in bands_hz:
        sel = (f >= lo) & (f <= hi) & ~inside
        masks.append(sel)
        inside |= sel
    out_sum = 0.0
    if (~inside).any():
        out_sum = float(np.sum((a[~inside] * beam_response(loops, f[~inside], input=input)) ** 2))
    shifts = np.linspace(1.0 - shift, 1.0 + shift, n_shifts)
    band_sums = []
    for (lo, hi), sel in zip(bands_hz, masks, strict=True):
        worst = 0.0
        if sel.any():
            fine = np.linspace(lo / (1.0 + shift), hi / (1.0 - shift), 2 * _BAND_POINTS)
            for loop in loops:
                mag = np.abs(input_response(loop, fine, input=input,
                                            outputs=("Rh", "Rv"))).max(axis=1)
                moved = np.interp(f[sel][None, :] / shifts[:, None], fine, mag)  # (S, L_band)
                worst = max(worst, float(np.max(np.sum((a[sel][None, :] * moved) ** 2,
                                                       axis=1))))
        band_sums.append(worst)
    return out_sum, band_sums, masks


def worst_beam_rms(loops: Sequence[DiscretePlant], f_hz: np.ndarray, amplitudes_v: np.ndarray,
                   *, input: str, bands_hz: Sequence[tuple[float, float]] = (),
                   shift: float = 0.05, n_shifts: int = 201) -> float:
    """The largest rms beam error lines of ``amplitudes_v`` add, over models and moves [rad].

    In the periodic steady state each line adds ``a |T_R(f)|`` in amplitude, so the
    rms is ``sqrt(sum_k a_k^2 |T_R(f_k)|^2 / 2)``. Outside ``bands_hz`` each line counts
    with its largest response over ``loops`` and the two axes. Inside a band the mode
    may sit anywhere: the band's lines count with the response of each model moved
    by every factor ``s`` in ``[1 - shift, 1 + shift]`` (``T_s(f) = T(f / s)``, a mode
    moved with its neighbourhood), the worst ``s`` and model kept.

    Parameters
    ----------
    loops : sequence of DiscretePlant
    f_hz, amplitudes_v : ndarray, shape (L,)
        Lines [Hz] and their amplitudes [V].
    input : str
        The loops' input the excitation enters.
    bands_hz : sequence of (float, float)
    shift : float
        Largest relative move of a mode [1].
    n_shifts : int
        Moves tried.
    """
    out_sum, band_sums, _ = _worst_parts(loops, np.asarray(f_hz, dtype=float),
                                         np.asarray(amplitudes_v, dtype=float), input=input,
                                         bands_hz=bands_hz, shift=shift, n_shifts=n_shifts)
    return float(np.sqrt((out_sum + sum(band_sums)) / 2.0))


def shaped_phases(amplitudes: np.ndarray, harmonics: np.ndarray, *, n_samples: int,
                  clip_iterations: int = 100) -> np.ndarray:
    """Low-crest-factor phases for lines of given amplitudes [rad], shape (L,).

    Schroeder's phases of the power spectrum, then ``clip_iterations`` of clipping
    1 %–5 % below the peak with the amplitudes held; the lowest crest factor met is kept.
    """
    a = np.asarray(amplitudes, dtype=float)
    k = np.asarray(harmonics, dtype=int)
    p = a**2 / np.sum(a**2)
    cum = np.cumsum(p)
    # phi_k = -2 pi sum_{l<k} (k - l) p_l, with k and l counted as line indices.
    idx = np.arange(a.size)
    weighted = np.cumsum(idx * p)
    phases = -2 * np.pi * (idx * np.concatenate([[0.0], cum[:-1]])
                           - np.concatenate([[0.0], weighted[:-1]]))

    def signal(ph: np.ndarray) -> np.ndarray:
        spec = np.zeros(n_samples // 2 + 1, dtype=complex)
        spec[k] = 0.5 * n_samples * a * np.exp(1j * ph)
        return np.fft.irfft(spec, n=n_samples)

    best = np.mod(phases, 2 * np.pi)
    best_cf = crest_factor(signal(best))
    for step in np.geomspace(0.05, 0.01, clip_iterations):
        x = signal(phases)
        level = (1.0 - step) * np.max(np.abs(x))
        phases = np.angle(np.fft.rfft(np.clip(x, -level, level))[k])
        cf = crest_factor(signal(phases))
        if cf < best_cf:
            best, best_cf = np.mod(phases, 2 * np.pi), cf
    return best


def _lines(*, band_hz: tuple[float, float], resolution_hz: float, fs_hz: float,
           grid: GridKind, log_grid: bool, lines_per_decade: float,
           dense_bands_hz: Sequence[tuple[float, float]]) -> tuple[np.ndarray, int]:
    """Harmonic numbers of the lines (a grid's, plus every line of the dense bands) and N."""
    n = _period_samples(resolution_hz=resolution_hz, fs_hz=fs_hz)
    k = grid_lines(band_hz=band_hz, resolution_hz=resolution_hz, fs_hz=fs_hz, grid=grid,
                   log_grid=log_grid, lines_per_decade=lines_per_decade)
    for lo, hi in dense_bands_hz:
        lo, hi = max(lo, band_hz[0]), min(hi, band_hz[1])
        if lo < hi:
            k = np.union1d(k, grid_lines(band_hz=(lo, hi), resolution_hz=resolution_hz,
                                         fs_hz=fs_hz, grid=grid))
    return k.astype(int), n


def multisine_of_lines(*, input: str, harmonics: np.ndarray, amplitudes_v: np.ndarray,
                       n_samples: int, fs_hz: float, band_hz: tuple[float, float],
                       periods: int = 1, transient_periods: int = 0, grid: GridKind = "full",
                       log_grid: bool = False) -> ExcitationDesign:
    """A periodic multisine of given line amplitudes with low-crest-factor phases.

    Parameters
    ----------
    input : str
        The command (``Uch`` …).
    harmonics : ndarray of int, shape (L,)
        Lines ``k`` (frequency ``k fs / N``).
    amplitudes_v : ndarray, shape (L,)
        Each line's amplitude [V].
    n_samples : int
        Samples per period ``N``.
    fs_hz : float
    band_hz : (float, float)
        The band named in the description [Hz].
    periods, transient_periods : int
    grid, log_grid
        How the lines were chosen (for the description).

    Raises
    ------
    ValueError
        No positive amplitude, or bad periods.
    """
    a = np.asarray(amplitudes_v, dtype=float)
    k = np.asarray(harmonics, dtype=int)
    if a.shape != k.shape or not np.all(a > 0) or not np.all(np.isfinite(a)):
        raise ValueError("every line needs a finite amplitude > 0 V")
    if periods < 1 or transient_periods < 0:
        raise ValueError(f"need at least 1 period and no negative transient periods, got "
                         f"{periods} and {transient_periods}")
    phases = shaped_phases(a, k, n_samples=n_samples)
    spec = np.zeros(n_samples // 2 + 1, dtype=complex)
    spec[k] = 0.5 * n_samples * a * np.exp(1j * phases)
    one = np.fft.irfft(spec, n=n_samples)
    rng = np.random.default_rng(0)
    draws = []
    for _ in range(21):
        spec_r = np.zeros(n_samples // 2 + 1, dtype=complex)
        spec_r[k] = a * np.exp(2j * np.pi * rng.uniform(size=k.size))
        draws.append(crest_factor(np.fft.irfft(spec_r, n=n_samples)))
    return ExcitationDesign(
        input=input, kind="multisine", fs_hz=float(fs_hz),
        samples_v=np.tile(one, periods + transient_periods), period_samples=n_samples,
        periods=periods, transient_periods=transient_periods,
        amplitude_rms_v=float(np.sqrt(np.sum(a**2) / 2.0)),
        band_hz=(float(band_hz[0]), float(band_hz[1])), seed=0, crest_factor=crest_factor(one),
        lines_hz=k * (fs_hz / n_samples), phases_rad=phases, line_amplitude_v=float(np.max(a)),
        grid=grid, log_grid=log_grid, phase_method="schroeder",
        crest_factor_random_phase=float(np.median(draws)), after_end="repeat")


def shaped_multisine(*, input: str, band_hz: tuple[float, float], resolution_hz: float,
                     amplitude_rms_v: float, fs_hz: float, loops: Sequence[DiscretePlant],
                     loop_input: str, periods: int = 1, transient_periods: int = 0,
                     grid: GridKind = "full", log_grid: bool = False,
                     lines_per_decade: float = 50.0,
                     dense_bands_hz: Sequence[tuple[float, float]] = (),
                     resonance_bands_hz: Sequence[tuple[float, float]] = (),
                     dynamic_range: float = DEFAULT_DYNAMIC_RANGE) -> tuple[ExcitationDesign,
                                                                          np.ndarray]:
    """A multisine whose lines move the beam equally with the loop closed (module notes).

    Parameters
    ----------
    input : str
        The command excited (``Uch``, ``Ucv``).
    band_hz, resolution_hz, grid, log_grid, lines_per_decade
        The lines (:func:`fsmbench.excite.design.grid_lines`).
    amplitude_rms_v : float
        Rms of the signal [V].
    fs_hz : float
    loops : sequence of DiscretePlant
        Closed loops of the models the shape must hold for (the first the model).
    loop_input : str
        Their input the excitation enters.
    periods, transient_periods : int
    dense_bands_hz : sequence of (float, float)
        Bands [Hz] where every line of the grid is kept besides a log grid's (the
        modes: a lightly damped mode is ~1 Hz wide, a log grid's spacing there tens).
    resonance_bands_hz : sequence of (float, float)
        Bands [Hz] where a resonance may be anywhere (:func:`beam_response`).
    dynamic_range : float
        Largest ratio between line amplitudes (> 1).

    Returns
    -------
    (ExcitationDesign, ndarray)
        The design (``line_amplitude_v`` the largest line's) and every line's
        amplitude [V], shape (L,).

    Raises
    ------
    ValueError
        Bad amplitude, periods, band or dynamic range.
    """
    if not (np.isfinite(amplitude_rms_v) and amplitude_rms_v > 0):
        raise ValueError(f"the rms amplitude must be a positive number of volts, got "
                         f"{amplitude_rms_v!r}")
    if not dynamic_range > 1:
        raise ValueError(f"the dynamic range of the lines must be > 1, got {dynamic_range!r}")
    k, n = _lines(band_hz=band_hz, resolution_hz=resolution_hz, fs_hz=fs_hz, grid=grid,
                  log_grid=log_grid, lines_per_decade=lines_per_decade,
                  dense_bands_hz=dense_bands_hz)
    f = k * (fs_hz / n)
    gain = beam_response(loops, f, input=loop_input, bands_hz=resonance_bands_hz)
    gain = np.maximum(gain, np.max(gain) / dynamic_range)
    a = 1.0 / gain
    a *= amplitude_rms_v / np.sqrt(np.sum(a**2) / 2.0)  # rms of lines a_l: sqrt(sum a_l^2 / 2)
    design = multisine_of_lines(input=input, harmonics=k, amplitudes_v=a, n_samples=n,
                                fs_hz=fs_hz, band_hz=band_hz, periods=periods,
                                transient_periods=transient_periods, grid=grid,
                                log_grid=log_grid)
    return design, a


@dataclass(frozen=True, eq=False)
class BoundedMeasurement:
    """A closed-loop measurement of one command designed within a beam-error bound.

    Attributes
    ----------
    design : ExcitationDesign
    line_amplitudes_v : ndarray, shape (L,)
        Each line's amplitude [V].
    report : ClosedLoopLimitReport
        Its peaks through the model's closed loop (every limit checked).
    worst_beam_rms_rad : float
        The largest rms beam error it adds over the models of the robust set and
        both axes, in the periodic steady state [rad] (what the bound is held to).
    """

    design: ExcitationDesign
    line_amplitudes_v: np.ndarray
    report: ClosedLoopLimitReport
    worst_beam_rms_rad: float


def resonance_bands(bench: Bench, *, width: float = 0.05) -> list[tuple[float, float]]:
    """``f (1 ± width)`` around the Sercalo resonance of each axis the model knows [Hz].

    An identified bench's resonances (its ``sercalo`` values), else the bench file's nominal ones.
    """
    values = (bench.model.values.get("sercalo") if bench.model is not None else None) or {}
    out = []
    for axis in ("h", "v"):
        f0 = (float(values[axis]["resonance_hz"]) if axis in values
              else float(bench.nominal.sercalo.resonance_hz[axis]))
        out.append((f0 * (1.0 - width), f0 * (1.0 + width)))
    return out


def _budgeted_amplitudes(loops: Sequence[DiscretePlant], f_hz: np.ndarray, *, input: str,
                         bands_hz: Sequence[tuple[float, float]], shift: float,
                         rms_rad: float) -> np.ndarray:
    """Line amplitudes [V] whose worst rms beam error over the models and moves is ``rms_rad``.

    Each line's amplitude is inversely proportional to its largest response
    (within :data:`DEFAULT_DYNAMIC_RANGE`); the budget is shared in squares:
    :data:`_OUTSIDE_SHARE` for the lines outside the resonance bands, the rest
    split evenly between the bands the excitation reaches.

    Parameters
    ----------
    loops : sequence of DiscretePlant
        The robust set's closed loops.
    f_hz : ndarray, shape (L,)
        The lines [Hz].
    input : str
        The loops' input the excitation enters.
    bands_hz : sequence of (float, float)
        The resonance bands [Hz].
    shift : float
        Largest relative move of a mode [1].
    rms_rad : float
        The rms beam error the lines may add together [rad].
    """
    gain = beam_response(loops, f_hz, input=input, bands_hz=bands_hz)
    a = 1.0 / np.maximum(gain, np.max(gain) / DEFAULT_DYNAMIC_RANGE)
    out_sum, band_sums, masks = _worst_parts(loops, f_hz, a, input=input, bands_hz=bands_hz,
                                             shift=shift, n_shifts=201)
    # The budget (the rms squared, x 2 for amplitudes) in shares: half for the lines
    # outside the resonance bands, the rest split between the bands.
    budget = 2.0 * rms_rad ** 2
    band_share = (1.0 - _OUTSIDE_SHARE) / max(1, sum(1 for b in band_sums if b > 0))
    scale = np.full(f_hz.size,
                    math.sqrt(_OUTSIDE_SHARE * budget / out_sum) if out_sum > 0 else 0.0)
    for mask, part in zip(masks, band_sums, strict=True):
        if part > 0:
            scale[mask] = math.sqrt(band_share * budget / part)
    if out_sum == 0:
        scale[scale == 0] = np.max(scale)
    return a * scale


def _within_closed_loop_limits(design: ExcitationDesign, amplitudes_v: np.ndarray, *,
                               peaks_options: dict[str, Any]
                               ) -> tuple[ExcitationDesign, np.ndarray, ClosedLoopLimitReport]:
    """The design, its line amplitudes [V] and its peaks, scaled down if a converter or the
    4QD's compression needs it.

    ``peaks_options`` are :func:`fsmbench.excite.closed_loop.closed_loop_peaks`'s
    keyword arguments (the model's closed loop, its limits).
    """
    report = closed_loop_peaks(design, **peaks_options)
    if not report.fits:
        factor = report.fitting_amplitude_rms_v() / design.amplitude_rms_v
        amplitudes_v = amplitudes_v * factor
        design = dataclasses.replace(design, samples_v=design.samples_v * factor,
                                     amplitude_rms_v=design.amplitude_rms_v * factor,
                                     line_amplitude_v=design.line_amplitude_v * factor)
        report = closed_loop_peaks(design, **peaks_options)
    return design, amplitudes_v, report


def beam_bounded_measurement(*, bench: Bench, params: BenchParams, controller: DiscreteController,
                             channel: str, max_error_rad: float, at: str = "output",
                             band_hz: tuple[float, float] = (0.5, 2000.0),
                             resolution_hz: float = 0.5, periods: int = 8,
                             transient_periods: int = 1, lines_per_decade: float = 20.0,
                             dense_width: float = 0.05, fill: float = 0.9,
                             max_qd_compression: float = 0.01,
                             loops: Sequence[DiscretePlant] | None = None,
                             controller_name: str = "", model: str = "") -> BoundedMeasurement:
    """The largest shaped multisine on ``channel`` whose added beam error stays within the bound.

    Odd lines (no mains harmonic at 0.5 Hz resolution, and none where a 1 Hz
    disturbance puts its lines) on a log grid plus every odd line within
    ``dense_width`` of each resonance (:func:`resonance_bands`), shaped over the
    robust set (:func:`fsmbench.excite.closed_loop.robust_loops`) and scaled so that
    the worst model's rms beam error is ``fill`` of ``max_error_rad``; then scaled down
    further if a converter or the 4QD's compression needs it (checked through the
    model's closed loop, :func:`fsmbench.excite.closed_loop.closed_loop_peaks`).

    Parameters
    ----------
    bench : Bench
        The model (packaged or identified): its engine plant and resonances.
    params : BenchParams
        Converters and 4QD of the model (``bench.nominal`` for a real bench).
    controller : DiscreteController
        The running loop's controller.
    channel : str
        ``Uch`` or ``Ucv``.
    max_error_rad : float
        The bound on the rms beam error the measurement adds [rad].
    at : {"output", "reference"}
    band_hz, resolution_hz, periods, transient_periods, lines_per_decade, dense_width
        The lines and the record.
    fill : float
        Fraction of the bound used (the rest is margin), in (0, 1].
    max_qd_compression : float
        4QD compression limit [1].
    loops : sequence of DiscretePlant, optional
        The robust set's closed loops (computed once per bench and controller).

    Raises
    ------
    ValueError
        A bound or fill that is not positive.
    """

    if not (math.isfinite(max_error_rad) and max_error_rad > 0):
        raise ValueError(f"the beam-error bound must be a positive angle, got {max_error_rad!r}")
    if not 0 < fill <= 1:
        raise ValueError(f"the fraction of the bound used must be in (0, 1], got {fill!r}")
    loops = list(loops) if loops is not None else robust_loops(bench, controller)
    inp = injection_input(controller, channel=channel, at=at)
    fs = params.converter.fs_hz
    dense = resonance_bands(bench, width=dense_width)
    k, n = _lines(band_hz=band_hz, resolution_hz=resolution_hz, fs_hz=fs, grid="odd",
                  log_grid=True, lines_per_decade=lines_per_decade, dense_bands_hz=dense)
    f = k * (fs / n)
    amplitudes = _budgeted_amplitudes(loops, f, input=inp, bands_hz=dense, shift=dense_width,
                                      rms_rad=fill * max_error_rad)
    design = multisine_of_lines(input=channel, harmonics=k, amplitudes_v=amplitudes,
                                n_samples=n, fs_hz=fs, band_hz=band_hz, periods=periods,
                                transient_periods=transient_periods, grid="odd", log_grid=True)
    peaks_options = {"params": params, "plant": bench_discrete(bench), "controller": controller,
                     "controller_name": controller_name, "at": at,
                     "model": model or "bench model", "max_qd_compression": max_qd_compression,
                     "max_error_rad": max_error_rad}
    design, amplitudes, report = _within_closed_loop_limits(design, amplitudes,
                                                            peaks_options=peaks_options)
    worst = worst_beam_rms(loops, f, amplitudes, input=inp, bands_hz=dense, shift=dense_width)
    return BoundedMeasurement(design=design, line_amplitudes_v=amplitudes, report=report,
                              worst_beam_rms_rad=worst)
