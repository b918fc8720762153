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
    own = int(np.argmin([abs(fn - resonance_hz) for fn, *_ in pairs]))
    fixed_fn = np.array([fn for fn, *_ in pairs])
    fixed_zeta = np.array([z for _, z, *_ in pairs])
    fs = float(frf.fs_hz)
    d0 = float(np.asarray(fit.d)[i, j])
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
    n_own = 2 + len(pairs)

    def shaped(x: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        fn, zeta = fixed_fn.copy(), fixed_zeta.copy()
        fn[own], zeta[own] = x[0], x[1]
        # A mass-spring mode driven by a force has no zero: numerator c0 alone. A free
        # c1 (a zero) would mimic a delay, -s tau c0, and take its place.
        return fn, zeta, np.column_stack([x[2:n_own], np.zeros(len(pairs))])

    def with_tail(x: FloatArray) -> StateSpace3:
        fn, zeta, num = shaped(x)
        wt = 2 * math.pi * x[-2]
        return mode_sum(natural_freq_hz=np.append(fn, x[-2]),
                        damping_ratio=np.append(zeta, TAIL_DAMPING),
                        numerator=np.vstack([num, [x[-1] * wt * wt, 0.0]]))

    def with_constant(x: FloatArray) -> StateSpace3:
        fn, zeta, num = shaped(x)
        return mode_sum(natural_freq_hz=fn, damping_ratio=zeta, numerator=num,
                        direct=float(x[-1]), direct_pole_hz=fs)

    x_own = [pairs[own][0], pairs[own][1]] + [c0 for _, _, c0, _ in pairs]
    scale_num = [max(abs(c0), 1e-12) for *_, c0, _ in pairs]
    dc_scale = max(scale_num) / (2 * math.pi * pairs[own][0]) ** 2
    scale_own = [pairs[own][0], max(pairs[own][1], 1e-3), *scale_num]
    scale_gain = max(abs(d0), 1e-3 * dc_scale)
    lower_own = np.full(n_own, -np.inf)
    upper_own = np.full(n_own, np.inf)
    lower_own[:2], upper_own[:2] = (1.0, 1e-5), (0.5 * fs, 1.0)
    f = frf.frequency_hz
    h = frf.frf.sel(output=output, input=input_).values
    coh = np.nan_to_num(frf.coherence.sel(output=output, input=input_).values, nan=0.0)
    sigma = line_std(frf, output, input_)
    sel = ((f >= lo) & (f <= hi) & (coh >= min_coherence) & np.isfinite(h)
           & np.isfinite(sigma) & (sigma > 0))
    if sel.sum() < 3 * (n_own + 3):
        raise ValueError(f"{input_} → {output}: {int(sel.sum())} coherent lines in "
                         f"{lo:.0f}–{hi:.0f} Hz for {n_own + 3} parameters")
    # Welch lines are correlated over the window's noise bandwidth; LPM and periodic
    # estimates carry their variance per line (nearly independent).
    correlated = (1.5 * frf.nfft / frf.window_length if frf.estimator == "welch" else 1.0)
    common = dict(delay_start_s=start.delay_s, fs_hz=fs, sensor=sensor,
                  correlated_lines=correlated, resolve_sensor=resolve_sensor)
    constant = fit_jointly(f[sel], h[sel], sigma[sel], path=with_constant,
                           start=np.array([*x_own, d0]), scale=np.array([*scale_own, scale_gain]),
                           lower=np.append(lower_own, -np.inf), upper=np.append(upper_own, np.inf),
                           **common)  # type: ignore[arg-type]
    tail = fit_jointly(f[sel], h[sel], sigma[sel], path=with_tail,
                       start=np.array([*x_own, tail_start_hz, d0]),
                       scale=np.array([*scale_own, tail_start_hz, scale_gain]),
                       lower=np.append(lower_own, [1.02 * hi, -np.inf]),
                       upper=np.append(upper_own, [TAIL_MAX_FRACTION_OF_FS * fs, np.inf]),
                       **common)  # type: ignore[arg-type]
    unit = constant.reduced_chi2 * max(correlated / constant.stride, 1.0)
    gain = (constant.weighted_cost - tail.weighted_cost) / max(unit, 1e-300)
    if gain > TAIL_LR:
        return dataclasses.replace(tail, method=f"{tail.method}; a weaker mode above the band")
    return dataclasses.replace(constant, method=f"{constant.method}; a constant above the band")


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
