"""Seed 2.3's delay, fitted with the Sercalo's own poles and the 4QD amplifier's bandwidth.

The phase-only estimate (:mod:`fsmbench.ident.delay.bode`) starts the fit and the
vector fit of the matrix with that delay removed gives its poles and
residues. Then each direct path ``Uc → Vp`` is fitted again as the
converters sample it (:func:`fsmbench.ident.delay.joint.fit_jointly`): its
resonance and damping free, the residues of every pole pair and a constant
term free, the other axis's poles (tiny on this path) kept, with the hold,
a delay of any fraction of a sample and the 4QD amplifier's low pass. The
lines are those the phase-only estimate used (its band, coherence ≥ the
threshold): where a Welch window smears the resonance the coherence drops
and those lines stay out.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from fsmbench.ident.delay.bode import DelayEstimate
from fsmbench.ident.delay.joint import JointFit, fit_jointly, line_std
from fsmbench.ident.delay.sampled import SensorLowpass, StateSpace3, mode_sum
from fsmbench.ident.fit.vectfit_model import VectorFit
from fsmbench.ident.frf.response import FrequencyResponse

__all__ = ["joint_path_delays", "sercalo_path_delay", "with_sensor"]

if TYPE_CHECKING:  # sercalo imports this module
    from fsmbench.ident.sercalo import SercaloIdentification

FloatArray = NDArray[np.float64]

#: Likelihood-ratio threshold of the tail's pair (chi-square, 1 extra parameter, 95 %).
TAIL_LR = 3.84
#: Highest frequency of the tail's pair, as a fraction of the rate (clear of Nyquist, where
#: a sampled pair aliases onto itself).
TAIL_MAX_FRACTION_OF_FS = 0.4
#: Damping of the tail's pair: a lightly damped mode's; below its resonance, where it is
#: fitted, the tail hardly depends on it.
TAIL_DAMPING = 0.01


def sercalo_path_delay(frf: FrequencyResponse, *, output: str, input_: str, fit: VectorFit,
                       start: DelayEstimate, resonance_hz: float, sensor: SensorLowpass,
                       min_coherence: float, resolve_sensor: bool = False) -> JointFit:
    """One direct path fitted with its poles, its delay and the sensor (see the module).

    Parameters
    ----------
    frf : FrequencyResponse
        The measured ``Uc → Vp`` matrix, delay included.
    output, input_ : str
        The path, e.g. ``"Vph"``, ``"Uch"``.
    fit : VectorFit
        Vector fit of the matrix with ``start``'s delay removed (the starting model).
    start : DelayEstimate
        The path's phase-only delay: the starting delay and the band [Hz].
    resonance_hz : float
        The path's resonance [Hz]: the pole pair nearest it is fitted, the others kept.
    sensor : SensorLowpass
        The bench model's 4QD amplifier.
    min_coherence : float
        Lines below it are left out.
    resolve_sensor : bool
        Also try the sensor's bandwidth free. Off by default: the Sercalo's
        coherent band (up to ~1 kHz with the seed's excitation) cannot separate
        a 4QD amplifier of several kHz from a delay, and the tails of the modes
        above the band would pass for one; the Newport's paths, coherent twice
        as high with a simpler model, are where the bandwidth is resolved
        (:mod:`fsmbench.ident.newport`).

    Returns
    -------
    JointFit
        ``parameters`` = resonance [Hz], damping ratio, then ``(c0, c1)`` of each
        pair and the constant term (units of the path).

    Raises
    ------
    ValueError
        The fit has a real pole (not a mirror's mode) or too few lines.
    """
    pairs = _pole_pairs(fit, output=output, input_=input_)
    model = _PathModel.around(pairs, resonance_hz=resonance_hz, fs_hz=float(frf.fs_hz))
    fs = model.fs_hz
    lo, hi = start.band_hz
    # Above the band the path goes on to higher, weaker modes (a plate's rocking, the
    # other axis's); in the band only their tails show, which the vector fit lumps into
    # its constant D. Two models of it are fitted: that constant (on a pole at the
    # sampling rate, see mode_sum), and one more pair above the band, its frequency free
    # and its damping a lightly damped mode's. The pair is kept when it lowers the
    # weighted squared residual by more than 3.84 noise units (its one extra parameter,
    # 95 %): a constant leaves a real tail's rise with frequency to the delay and the
    # poles (-60 us on the real-bench twin), a pair with no tail to fit trades its
    # frequency against the delay.
    tail_start_hz = min(max(2.0 * hi, hi + 100.0), TAIL_MAX_FRACTION_OF_FS * fs)
    st = _own_start(fit, pairs, output=output, input_=input_, own=model.own, fs_hz=fs)
    f, h, sigma = _coherent_lines(frf, output=output, input_=input_, band_hz=(lo, hi),
                                  min_coherence=min_coherence, n_params=model.n_own + 3)
    # Welch lines are correlated over the window's noise bandwidth; LPM and periodic
    # estimates carry their variance per line (nearly independent).
    correlated = (1.5 * frf.nfft / frf.window_length if frf.estimator == "welch" else 1.0)
    common = dict(delay_start_s=start.delay_s, fs_hz=fs, sensor=sensor,
                  correlated_lines=correlated, resolve_sensor=resolve_sensor)
    constant = fit_jointly(f, h, sigma, path=model.with_constant, start=np.array([*st.x, st.d0]),
                           scale=np.array([*st.scale, st.scale_gain]),
                           lower=np.append(st.lower, -np.inf), upper=np.append(st.upper, np.inf),
                           **common)  # type: ignore[arg-type]
    tail = fit_jointly(f, h, sigma, path=model.with_tail,
                       start=np.array([*st.x, tail_start_hz, st.d0]),
                       scale=np.array([*st.scale, tail_start_hz, st.scale_gain]),
                       lower=np.append(st.lower, [1.02 * hi, -np.inf]),
                       upper=np.append(st.upper, [TAIL_MAX_FRACTION_OF_FS * fs, np.inf]),
                       **common)  # type: ignore[arg-type]
    unit = constant.reduced_chi2 * max(correlated / constant.stride, 1.0)
    gain = (constant.weighted_cost - tail.weighted_cost) / max(unit, 1e-300)
    if gain > TAIL_LR:
        return dataclasses.replace(tail, method=f"{tail.method}; a weaker mode above the band")
    return dataclasses.replace(constant, method=f"{constant.method}; a constant above the band")


def _pole_pairs(fit: VectorFit, *, output: str, input_: str
                ) -> list[tuple[float, float, float, float]]:
    """Each pole pair of the vector fit on one path: (wn [Hz], ζ, c0, c1) of ``(c1 s + c0)/(…)``.

    Raises ``ValueError`` when the fit has a real pole (not a mirror's mode).
    """
    poles = np.asarray(fit.poles, dtype=complex)
    if np.any(np.abs(poles.imag) <= 0):
        raise ValueError(f"{input_} → {output}: the vector fit has a real pole; the joint "
                         "delay fit models pole pairs only")
    upper = poles[poles.imag > 0]
    i, j = list(fit.output_names).index(output), list(fit.input_names).index(input_)
    residues = np.asarray(fit.residues, dtype=complex)[:, i, j]
    pairs = []
    for p in upper:
        r = residues[int(np.argmin(np.abs(poles - p)))]
        # r/(s − p) + r̄/(s − p̄) = (2 Re r · s − 2 Re(r p̄)) / (s² − 2 Re p · s + |p|²)
        pairs.append((abs(p) / (2 * math.pi), -p.real / abs(p),
                      -2 * (r * np.conj(p)).real, 2 * r.real))
    return pairs


@dataclass(frozen=True, eq=False)
class _PathModel:
    """The path's modes with its own pair free: ``x`` = (wn [Hz], ζ, c0 of every pair, …).

    The other pairs keep their fitted frequency and damping; after the pairs' c0,
    ``x`` ends with the tail above the band: (a pair's frequency [Hz], its static
    gain) or the constant term (units of the path).
    """

    fixed_fn: FloatArray  # every pair's natural frequency [Hz]
    fixed_zeta: FloatArray  # every pair's damping ratio
    own: int  # the path's own pair
    fs_hz: float  # converter rate [Hz]: the constant term's pole

    @classmethod
    def around(cls, pairs: list[tuple[float, float, float, float]], *, resonance_hz: float,
               fs_hz: float) -> _PathModel:
        """The model of :func:`_pole_pairs`'s pairs, its own the one nearest ``resonance_hz``."""
        own = int(np.argmin([abs(fn - resonance_hz) for fn, *_ in pairs]))
        return cls(fixed_fn=np.array([fn for fn, *_ in pairs]),
                   fixed_zeta=np.array([z for _, z, *_ in pairs]), own=own, fs_hz=fs_hz)

    @property
    def n_own(self) -> int:
        """Parameters of the pairs: the own pair's frequency and damping, each pair's c0."""
        return 2 + self.fixed_fn.size

    def shaped(self, x: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Natural frequencies [Hz], damping ratios and numerators (c0, c1) of the pairs."""
        fn, zeta = self.fixed_fn.copy(), self.fixed_zeta.copy()
        fn[self.own], zeta[self.own] = x[0], x[1]
        # A mass-spring mode driven by a force has no zero: numerator c0 alone. A free
        # c1 (a zero) would mimic a delay, -s tau c0, and take its place.
        return fn, zeta, np.column_stack([x[2:self.n_own], np.zeros(self.fixed_fn.size)])

    def with_tail(self, x: FloatArray) -> StateSpace3:
        """The pairs and one more, lightly damped, above the band."""
        fn, zeta, num = self.shaped(x)
        wt = 2 * math.pi * x[-2]
        return mode_sum(natural_freq_hz=np.append(fn, x[-2]),
                        damping_ratio=np.append(zeta, TAIL_DAMPING),
                        numerator=np.vstack([num, [x[-1] * wt * wt, 0.0]]))

    def with_constant(self, x: FloatArray) -> StateSpace3:
        """The pairs and a constant term (on a pole at the sampling rate)."""
        fn, zeta, num = self.shaped(x)
        return mode_sum(natural_freq_hz=fn, damping_ratio=zeta, numerator=num,
                        direct=float(x[-1]), direct_pole_hz=self.fs_hz)


@dataclass(frozen=True)
class _OwnStart:
    """Start, scale and bounds of the pairs' parameters (:class:`_PathModel`'s ``x[:n_own]``)."""

    x: list[float]  # own pair's frequency [Hz] and damping, then every pair's c0
    scale: list[float]  # their typical magnitudes
    lower: FloatArray  # their bounds
    upper: FloatArray
    d0: float  # the vector fit's constant term on the path (units of the path)
    scale_gain: float  # scale of the tail's gain or the constant term (units of the path)


def _own_start(fit: VectorFit, pairs: list[tuple[float, float, float, float]], *, output: str,
               input_: str, own: int, fs_hz: float) -> _OwnStart:
    """The vector fit's values as the start; the own pair within 1 Hz–fs/2, ζ in [1e-5, 1]."""
    i, j = list(fit.output_names).index(output), list(fit.input_names).index(input_)
    d0 = float(np.asarray(fit.d)[i, j])
    n_own = 2 + len(pairs)
    x_own = [pairs[own][0], pairs[own][1]] + [c0 for _, _, c0, _ in pairs]
    scale_num = [max(abs(c0), 1e-12) for *_, c0, _ in pairs]
    dc_scale = max(scale_num) / (2 * math.pi * pairs[own][0]) ** 2
    scale_own = [pairs[own][0], max(pairs[own][1], 1e-3), *scale_num]
    scale_gain = max(abs(d0), 1e-3 * dc_scale)
    lower_own = np.full(n_own, -np.inf)
    upper_own = np.full(n_own, np.inf)
    lower_own[:2], upper_own[:2] = (1.0, 1e-5), (0.5 * fs_hz, 1.0)
    return _OwnStart(x_own, scale_own, lower_own, upper_own, d0, scale_gain)


def _coherent_lines(frf: FrequencyResponse, *, output: str, input_: str,
                    band_hz: tuple[float, float], min_coherence: float, n_params: int
                    ) -> tuple[FloatArray, NDArray[np.complex128], FloatArray]:
    """The path's lines in the band [Hz] with coherence and a standard deviation: f, H, std.

    Raises ``ValueError`` with fewer than three lines per parameter (``n_params``).
    """
    lo, hi = band_hz
    f = frf.frequency_hz
    h = frf.frf.sel(output=output, input=input_).values
    coh = np.nan_to_num(frf.coherence.sel(output=output, input=input_).values, nan=0.0)
    sigma = line_std(frf, output, input_)
    sel = ((f >= lo) & (f <= hi) & (coh >= min_coherence) & np.isfinite(h)
           & np.isfinite(sigma) & (sigma > 0))
    if sel.sum() < 3 * n_params:
        raise ValueError(f"{input_} → {output}: {int(sel.sum())} coherent lines in "
                         f"{lo:.0f}–{hi:.0f} Hz for {n_params} parameters")
    return f[sel], h[sel], sigma[sel]


def joint_path_delays(frf: FrequencyResponse, *, fit: VectorFit,
                      starts: tuple[DelayEstimate, ...], resonances_hz: Mapping[str, float],
                      sensor: SensorLowpass, min_coherence: float) -> tuple[JointFit, ...]:
    """:func:`sercalo_path_delay` for each direct path (``starts`` in the same order)."""
    out = []
    for est in starts:
        if est.output is None or est.input is None:
            raise ValueError("the phase-only delays must name their paths")
        out.append(sercalo_path_delay(frf, output=est.output, input_=est.input, fit=fit,
                                      start=est, resonance_hz=resonances_hz[est.input],
                                      sensor=sensor, min_coherence=min_coherence))
    return tuple(out)


def with_sensor(sid: SercaloIdentification, sensor: SensorLowpass) -> SercaloIdentification:
    """The joint delay fits again with another 4QD amplifier (one the Newport's lines resolved).

    Only the split of the delay changes: the Sercalo's band sees the amplifier as a lag,
    so the effective delay removed before the vector fit (``delay_s``) stays, and the fit,
    the modes and ``Gc`` with it; ``pure_delay_s`` loses the amplifier's group delay.
    """
    if not sid.joint_delays:
        return sid
    joint = joint_path_delays(sid.frf, fit=sid.fit, starts=sid.delays,
                              resonances_hz=sid.resonances_hz, sensor=sensor,
                              min_coherence=sid.options.min_coherence)
    joint = tuple(dataclasses.replace(j, sensor=dataclasses.replace(j.sensor, source="Newport"))
                  for j in joint)
    return dataclasses.replace(sid, joint_delays=joint)
