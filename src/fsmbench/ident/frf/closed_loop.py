"""The plant's FRF matrix from closed-loop records: the joint input–output method.

With the loop closed, the command ``u`` carries the controller's answer to the
sensor's noise ``v``: ``u = S_i (r - K v)`` (excitation ``r`` added at the
controller's output, input sensitivity ``S_i = (I + K G)^-1``). The *direct*
method, the spectra of ``y`` against ``u`` as in open loop,
``G_d = Φ_yu Φ_uu^-1``, is then biased by ``Φ_vu Φ_uu^-1``: where the
excitation does not dominate the noise it tends to ``-1/K`` (Ljung, *System
Identification*, 2nd ed., 1999, §13.4; Pintelon & Schoukens 2012, §9.4).

The excitation is independent of the noise, so it is the instrument. Per line
``k``, the responses of ``u`` and ``y`` to ``r`` in experiment ``j`` (``r``
on input ``j``) give the columns of ``S_ur`` and ``S_yr``, and

    G = S_yr S_ur^-1                                               (2×2 MIMO)

the *joint input–output* (indirect) estimate, consistent whatever the loop
(Pintelon & Schoukens 2012, §2.7 and §9.4; with ``r`` injected at the
reference instead, ``S_ur = S_i K`` and the same product gives ``G``).

Two estimators of ``S_yr`` and ``S_ur``, each with the variance of every line:

``periodic``
    The excitation repeats (a multisine): the period averages ``U``, ``Y``
    (after ``transient_periods`` dropped) on the lines the excitation excites in
    *both* experiments; ``G = Y U^-1`` with ``Y = [Y_1 Y_2]``,
    ``U = [U_1 U_2]``. To first order ``dG = (dY - G dU) U^-1``, so with the
    per-period residuals ``e_p = (Y_p - Y) - G (U_p - U)`` of experiment ``j``
    (sample variance ``s_e²`` over its ``P`` periods)::

        var G_il = sum_j |(U^-1)_jl|^2 s_e,ij^2 / P_j.

    It holds the input noise and the input/output covariance the feedback makes.

``lpm``
    Any excitation: the local polynomial method (Pintelon et al. 2010) on the
    whole record, with ``r`` as the input and the four signals ``[y; u]`` as
    outputs, each with its own transient polynomial. The residuals' full 4×4
    covariance ``C_V`` per line (the feedback correlates ``u`` and ``y``) gives
    ``Cov(column j of [S_yr; S_ur]) = C_V [(K^H K)^-1]_00``, and
    ``var G_il = sum_j |(S_ur^-1)_jl|^2 ([I, -G] Cov_j [I, -G]^H)_ii``.

Both return a :class:`ClosedLoopFrf`: ``plant`` is an
:class:`~fsmbench.ident.frf.estimate.FrfEstimate` (inputs ``Uch, Ucv``, outputs
``Vph, Vpv``) that the open-loop fit (:func:`fsmbench.ident.sercalo.fit_sercalo`)
consumes as it is; ``direct`` is the direct method on the same lines and data,
shown beside it for its bias.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from fsmbench.ident.frf.closed_loop_leakage import (
    LeakageOptions,
    _smooth,
    leakage_corrected_lines,
    mean_variance,
)
from fsmbench.ident.frf.closed_loop_spectra import (
    _CrossSpectra,
    _excited_lines,
    _lpm_lines,
    _mean_responses,
    _period_blocks,
    _period_spectra,
    _PeriodicRecord,
    _record_dft,
    _shared_lines,
    _window_spectra,
)
from fsmbench.ident.frf.estimate import FrfEstimate
from fsmbench.ident.frf.lpm import LpmOptions
from fsmbench.ident.frf.periodic import detect_period

__all__ = [
    "ClosedLoopFrf",
    "ClosedLoopRecord",
    "closed_loop_frf",
    "joint_lpm",
    "joint_periodic",
    "settled_periods",
]

COMMANDS = ("Uch", "Ucv")
OUTPUTS = ("Vph", "Vpv")


@dataclass(frozen=True, eq=False)
class ClosedLoopRecord:
    """One closed-loop experiment: the excitation, the commands and the 4QD outputs.

    Attributes
    ----------
    excitation : ndarray, shape (L,)
        The excitation as played [V] (the instrument).
    commands : ndarray, shape (L, 2)
        ``Uch, Ucv`` as the DAC gave them [V].
    outputs : ndarray, shape (L, 2)
        ``Vph, Vpv`` [V].
    fs_hz : float
    name : str
        For messages (e.g. ``data_cl_uch``).
    """

    excitation: NDArray[np.float64]
    commands: NDArray[np.float64]
    outputs: NDArray[np.float64]
    fs_hz: float
    name: str = "record"

    def __post_init__(self) -> None:
        r = np.asarray(self.excitation, dtype=float)
        u = np.asarray(self.commands, dtype=float)
        y = np.asarray(self.outputs, dtype=float)
        if r.ndim != 1 or u.shape != (r.size, 2) or y.shape != (r.size, 2):
            raise ValueError(f"{self.name}: the excitation {r.shape}, commands {u.shape} and "
                             f"outputs {y.shape} must be (L,), (L, 2), (L, 2)")
        if not (np.all(np.isfinite(r)) and np.all(np.isfinite(u)) and np.all(np.isfinite(y))):
            raise ValueError(f"{self.name}: NaN or inf samples")
        if not np.any(r != r[0]):
            raise ValueError(f"{self.name}: the excitation is constant (nothing was played)")
        object.__setattr__(self, "excitation", r)
        object.__setattr__(self, "commands", u)
        object.__setattr__(self, "outputs", y)


@dataclass(frozen=True, eq=False)
class ClosedLoopFrf:
    """The plant and the loop's responses to the excitation, line by line.

    Attributes
    ----------
    plant : FrfEstimate
        ``G`` (``Uch, Ucv → Vph, Vpv`` [V/V]) by the joint input–output method,
        with the variance of every line; ``estimator`` is ``"periodic"`` or ``"lpm"``.
    s_ur, s_yr : ndarray, complex, shape (F, 2, 2)
        Responses of the commands and of the 4QD outputs to the excitation
        (column ``j``: experiment ``j``) [V/V]; with the excitation at the
        controller's output ``s_ur`` is the input sensitivity ``(I + K G)^-1``.
    direct : FrfEstimate
        The direct method ``Φ_yu Φ_uu^-1`` on the same lines and data (its
        variance is the one open-loop theory would give: it ignores the bias).
    method : str
        In words.
    """

    plant: FrfEstimate
    s_ur: NDArray[np.complex128]
    s_yr: NDArray[np.complex128]
    direct: FrfEstimate
    method: str

    @property
    def frequency_hz(self) -> NDArray[np.float64]:
        """Lines [Hz], shape (F,)."""
        return self.plant.frequency_hz

    def summary(self) -> dict[str, Any]:
        """JSON-ready: method, estimator, lines, median relative std per element."""
        return {"method": self.method, **self.plant.summary()}


def _inverse_2x2(m: NDArray[np.complex128]) -> NDArray[np.complex128]:
    """Inverses of a stack of 2×2 matrices (NaN where singular)."""
    det = m[:, 0, 0] * m[:, 1, 1] - m[:, 0, 1] * m[:, 1, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = np.empty_like(m)
        inv[:, 0, 0] = m[:, 1, 1] / det
        inv[:, 1, 1] = m[:, 0, 0] / det
        inv[:, 0, 1] = -m[:, 0, 1] / det
        inv[:, 1, 0] = -m[:, 1, 0] / det
    return inv


def _estimate(f: NDArray[np.float64], g: NDArray[np.complex128], var: NDArray[np.float64],
              dof: Sequence[float], *, n_blocks: Sequence[float],
              u_cols: NDArray[np.complex128],
              noise_var: NDArray[np.float64], fs_hz: float, resolution_hz: float,
              block: int, estimator: str, options: dict[str, Any]) -> FrfEstimate:
    """An :class:`FrfEstimate` of ``G`` with the conventions of the open-loop estimators.

    ``u_cols`` (F, 2): each column's own command on its line (normalised DFT, one block);
    ``noise_var`` (F, 2, 2): the residual variance per output and column (one block);
    ``dof`` the noise variance's degrees of freedom per column; ``n_blocks`` the blocks
    averaged per column. ``snr = |G_il|^2 / (n_blocks var G_il)`` per block, so that the
    coherence has its open-loop meaning (a noise-free input and that output noise).
    """
    blocks = np.asarray(n_blocks, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        snr = np.abs(g) ** 2 / (blocks[None, None, :] * var)
    snr = np.where(np.isfinite(snr), snr, 0.0)
    one_sided = np.where(np.isclose(f, fs_hz / 2) | (f == 0), 1.0, 2.0)
    return FrfEstimate(
        frequency_hz=f, frf=g, frf_variance=np.maximum(var, 0.0),
        output_noise_psd=one_sided[:, None, None] * noise_var / fs_hz,
        input_psd=one_sided[:, None] * np.abs(u_cols) ** 2 / fs_hz, snr=snr,
        input_names=COMMANDS, output_names=OUTPUTS, fs_hz=float(fs_hz),
        resolution_hz=float(resolution_hz), estimator=estimator,
        options={**options, "block_samples": int(block)}, dof=tuple(float(d) for d in dof))


def _project(g: NDArray[np.complex128], cov: NDArray[np.complex128]) -> NDArray[np.float64]:
    """``diag([I, -G] C [I, -G]^H)`` per line: the variance of ``y - G u`` (F, 2)."""
    f = g.shape[0]
    proj = np.concatenate([np.broadcast_to(np.eye(2), (f, 2, 2)), -g], axis=2)  # (F, 2, 4)
    e = proj @ cov @ np.conj(np.swapaxes(proj, 1, 2))
    return np.real(np.diagonal(e, axis1=1, axis2=2))


def _g_and_variance(s_yr: NDArray[np.complex128], s_ur: NDArray[np.complex128],
                    cov: Sequence[NDArray[np.complex128]]
                    ) -> tuple[NDArray[np.complex128], NDArray[np.float64],
                               NDArray[np.float64]]:
    """``G = S_yr S_ur^-1`` and ``var G_il`` from each column's 4×4 covariance of ``[S_yr; S_ur]``.

    Returns G (F, 2, 2), var G (F, 2, 2) and the variance of ``dS_yr - G dS_ur`` per output
    and column (F, 2, 2).
    """
    inv = _inverse_2x2(s_ur)
    g = s_yr @ inv
    resid = np.stack([_project(g, c) for c in cov], axis=2)
    var = np.einsum("fij,fjl->fil", resid, np.abs(inv) ** 2)
    return g, var, resid


def _direct(f: NDArray[np.float64], spectra: _CrossSpectra, *,
            fs_hz: float, resolution_hz: float, block: int, estimator: str) -> FrfEstimate:
    """``Φ_yu Φ_uu^-1`` with the variance open-loop theory gives it, ``Φ_ee,i (Φ_uu^-1)_ll / n``.

    ``Φ`` are ``spectra``'s sums over their ``n`` blocks. ``Φ_ee`` is what the direct model
    leaves of ``Φ_yy``; the bias the feedback adds is not in that variance (it is what the
    comparison shows).
    """
    n_blocks = float(spectra.blocks)
    phi_yu = spectra.phi_yu / spectra.blocks
    phi_uu = spectra.phi_uu / spectra.blocks
    phi_yy = spectra.phi_yy / spectra.blocks
    inv = _inverse_2x2(phi_uu)
    g = phi_yu @ inv
    explained = np.real(np.einsum("fij,fjk,fik->fi", g, phi_uu, np.conj(g)))
    res = np.maximum(np.real(np.diagonal(phi_yy, axis1=1, axis2=2)) - explained, 0.0)
    var = res[:, :, None] * np.real(np.diagonal(inv, axis1=1, axis2=2))[:, None, :] / n_blocks
    u_cols = np.sqrt(np.real(np.diagonal(phi_uu, axis1=1, axis2=2)))
    return _estimate(f, g, var, (n_blocks - 1.0,) * 2, n_blocks=(n_blocks,) * 2, u_cols=u_cols,
                     noise_var=np.broadcast_to(res[:, :, None], g.shape).copy(), fs_hz=fs_hz,
                     resolution_hz=resolution_hz, block=block, estimator=estimator,
                     options={"method": "direct (y against u, the excitation ignored)"})


def settled_periods(z: NDArray[np.complex128], *, smoothing_lines: int = 7,
                    threshold: float = 1.5) -> int:
    """Leading periods to drop: those still carrying the loop's transient.

    ``z`` (P, L, C): each period's DFT on the excited lines. The last half of the
    periods (at least 2) is the reference; each line's noise variance is their
    scatter (smoothed over ``smoothing_lines``). A period has settled when its mean
    squared departure from the reference's mean, in units of that variance, is
    within ``threshold`` times what noise alone gives, ``1 + 1/H`` (``H`` periods in
    the reference): a lightly damped resonance's ringing stands out on its lines
    long after the rest has settled. At least one period is dropped (the loop's
    answer to the excitation's start) and at least two are kept.
    """
    p = z.shape[0]
    h = max(2, p // 2)
    ref = z[p - h:]
    mean = ref.mean(axis=0)
    var = np.sum(np.abs(ref - mean) ** 2, axis=0) / (h - 1)
    var = _smooth(var, smoothing_lines)
    var = np.where(var > 0, var, np.inf)
    expected = 1.0 + 1.0 / h
    for i in range(1, p - 2 + 1):
        stat = float(np.mean(np.abs(z[i] - mean) ** 2 / var))
        if stat <= threshold * expected:
            return i
    return p - 2


def _period_variance(parts: Sequence[_PeriodicRecord], lines: NDArray[np.intp],
                     g: NDArray[np.complex128], u_mean: NDArray[np.complex128], *,
                     smoothing_lines: int, period_correlation: bool
                     ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``var G`` and the residual noise per line and column from the periods' scatter."""
    # Residual of each period, e_p = (Y_p - Y) - G (U_p - U): the noise G sees [V per line].
    noise = np.empty((lines.size, 2, 2))
    mean_var = np.empty((lines.size, 2, 2))  # the variance of its mean over the periods
    for j, part in enumerate(parts):
        z, periods = part.blocks, part.periods
        dz = z[:, lines, :] - z[:, lines, :].mean(axis=0)[None]
        e = dz[:, :, :2] - np.einsum("fab,pfb->pfa", g, dz[:, :, 2:])
        noise[:, :, j] = _smooth(np.sum(np.abs(e) ** 2, axis=0) / (periods - 1),
                                 smoothing_lines)
        lag1 = _smooth(np.real(np.sum(e[1:] * np.conj(e[:-1]), axis=0)), smoothing_lines)
        mean_var[:, :, j] = (mean_variance(noise[:, :, j], lag1, periods)
                             if period_correlation else noise[:, :, j] / periods)
    var = np.einsum("fij,fjl->fil", mean_var, np.abs(_inverse_2x2(u_mean)) ** 2)
    return var, noise


def _leakage_free(parts: Sequence[_PeriodicRecord], lines: NDArray[np.intp],
                  options: LeakageOptions
                  ) -> tuple[NDArray[np.complex128], NDArray[np.complex128],
                             NDArray[np.complex128], NDArray[np.float64], NDArray[np.float64],
                             NDArray[np.complex128]]:
    """``S_yr``, ``S_ur``, ``G``, ``var G``, the residual noise (per period's line) and the
    mean commands, from the whole records with the noise's leakage removed
    (:mod:`fsmbench.ident.frf.closed_loop_leakage`)."""
    s_yr = np.empty((lines.size, 2, 2), dtype=complex)
    s_ur = np.empty((lines.size, 2, 2), dtype=complex)
    u_cols = np.empty((lines.size, 2), dtype=complex)
    cov, noise_cov = [], []
    for j, part in enumerate(parts):
        rec, periods = part.record, part.periods
        seg = slice(part.first, part.first + periods * part.period)
        lc = leakage_corrected_lines(rec.excitation[seg],
                                     np.hstack([rec.outputs, rec.commands])[seg],
                                     periods=periods, lines=lines, options=options)
        s_yr[:, :, j] = lc.z[:, :2] / lc.r[:, None]
        s_ur[:, :, j] = lc.z[:, 2:] / lc.r[:, None]
        u_cols[:, j] = lc.z[:, 2 + j] / math.sqrt(periods)  # one period's scale
        noise_cov.append(lc.noise_cov)
        cov.append(lc.noise_cov * ((1.0 + lc.leverage) / np.abs(lc.r) ** 2)[:, None, None])
    g, var, _resid = _g_and_variance(s_yr, s_ur, cov)
    noise = np.stack([_project(g, c) for c in noise_cov], axis=2)
    return s_yr, s_ur, g, var, noise, u_cols


def joint_periodic(records: Sequence[ClosedLoopRecord], *, period_samples: int | None = None,
                   transient_periods: int | None = None,
                   smoothing_lines: int = 7,
                   period_correlation: bool = False,
                   leakage: LeakageOptions | None = None) -> ClosedLoopFrf:
    """``G = Y U^-1`` from periodic excitations, one record per command (see the module notes).

    Parameters
    ----------
    records : sequence of 2 ClosedLoopRecord
        The excitation on ``Uch`` (or its reference), then on ``Ucv``.
    period_samples : int, optional
        The excitation's period [samples]; default found on each record
        (:func:`fsmbench.ident.frf.periodic.detect_period`), and the two must agree.
    transient_periods : int, optional
        Whole periods dropped at the start of each record (the loop's transient);
        default found on each record (:func:`settled_periods`).
    period_correlation : bool
        The variance of the periods' mean from the residual's variance *and* its
        correlation between consecutive periods (:func:`mean_variance`); False (the
        default): the variance over ``P``, as if the periods were independent. True
        gives each line near a notched resonance its right variance (on the twin,
        estimated / true 1.1-3.0 instead of 2.8-8.5) but the errors it then weights are
        the same leakage on neighbouring lines (|correlation| 0.7-0.8 between
        410.75, 411.25 and 411.75 Hz over 12 seeds), which the Sercalo fit's
        independent weights cannot take: over 8 twin seeds the damping's median error
        fell from 5.3 to 2.5 %, but on real_bench.toml seed 1 the vertical mode came
        out 1.15 % low with 18 times its damping (+0.01 % and +0.4 % without). A leakage
        term across lines (the LPM's transient) is the cure, not this alone.
    leakage : LeakageOptions, optional
        The lines from the whole records with the noise's leakage across neighbouring
        lines fitted out on the non-harmonic bins
        (:mod:`fsmbench.ident.frf.closed_loop_leakage`); None (the default): the
        periods' mean and scatter. Its variance is calibrated under a narrowband noise
        where the periods' scatter overstates it (tests: mean |z|^2 1.17 against
        0.38), but on the twin's notched resonances it is still overstated (|z| 0.1-0.8
        on stage 1's lines within 3 Hz), and the Sercalo fits were not better: the
        cached records of 14 two-stage measurements (6 ``real_bench.toml``, 8 twin),
        stages merged, damping within 25 % on 28 / 28 axis-runs against 27 / 28, but
        rms damping error 7.4 % against 3.4 % on ``real_bench.toml`` and one delay
        1.34 samples off (within 0.45 without).
    smoothing_lines : int
        The residual noise's variance is averaged over this many neighbouring
        excited lines (odd): the noise spectrum is smooth, and ``P - 1`` degrees
        of freedom alone make inverse-variance weights scatter (3 dof for 4
        periods: a weight's relative spread is ~60 %). 1: each line's own.

    Raises
    ------
    ValueError
        Not two records, rates or periods that differ, fewer than two periods
        left, or no line excited in both.
    """
    if len(records) != 2:
        raise ValueError(f"the 2x2 plant needs two closed-loop records (one per command), got "
                         f"{len(records)}")
    fs = records[0].fs_hz
    parts = [_periodic_record(rec, reference=records[0], period_samples=period_samples,
                              transient_periods=transient_periods,
                              smoothing_lines=smoothing_lines) for rec in records]
    lines = _shared_lines(parts)
    n = parts[0].period
    f = lines * fs / n
    opts: dict[str, Any] = {"period_samples": int(n), "periods_used": [p.periods for p in parts],
                            "transient_periods": [p.dropped for p in parts],
                            "transient_periods_found": transient_periods is None,
                            "n_lines": int(lines.size)}
    plant, s_yr, s_ur = _periodic_plant(parts, lines, f, options=opts, leakage=leakage,
                                        smoothing_lines=smoothing_lines,
                                        period_correlation=period_correlation)
    direct = _direct(f, _period_spectra(parts, lines), fs_hz=fs, resolution_hz=fs / n, block=n,
                     estimator="periodic")
    return ClosedLoopFrf(plant=plant, s_ur=s_ur, s_yr=s_yr, direct=direct,
                         method="joint input-output, periodic averaging")


def _periodic_record(rec: ClosedLoopRecord, *, reference: ClosedLoopRecord,
                     period_samples: int | None, transient_periods: int | None,
                     smoothing_lines: int) -> _PeriodicRecord:
    """One record cut into whole periods, its transient dropped, with its excited lines.

    Parameters
    ----------
    rec : ClosedLoopRecord
    reference : ClosedLoopRecord
        The first record: ``rec`` must share its sampling rate [Hz].
    period_samples : int or None
        The excitation's period [samples]; None: detected on ``rec``.
    transient_periods : int or None
        Whole periods dropped at the start; None: :func:`settled_periods`.
    smoothing_lines : int
        Excited lines the transient test's noise variance is averaged over.

    Raises
    ------
    ValueError
        Another rate, no period found, or fewer than two periods left.
    """
    fs = reference.fs_hz
    if abs(rec.fs_hz - fs) > 1e-9 * fs:
        raise ValueError(f"{rec.name} is sampled at {rec.fs_hz:g} Hz, {reference.name} at "
                         f"{fs:g} Hz")
    n = period_samples or detect_period(rec.excitation)
    if n is None:
        raise ValueError(f"{rec.name}: the excitation is not periodic; use the LPM")
    total = rec.excitation.size // n
    if total < (3 if transient_periods is None else transient_periods + 2):
        raise ValueError(f"{rec.name}: {total} whole period(s) of {n} samples; after "
                         f"{transient_periods or 1} transient period(s) at least 2 are "
                         "needed")
    offset = rec.excitation.size - total * n
    r = _period_blocks(rec.excitation, n, offset, total)
    z = _period_blocks(np.hstack([rec.outputs, rec.commands]), n, offset, total)
    lines = _excited_lines(r)
    drop = (settled_periods(z[:, lines, :2], smoothing_lines=smoothing_lines)
            if transient_periods is None else transient_periods)
    r, z = r[drop:], z[drop:]
    return _PeriodicRecord(record=rec, period=n, periods=total - drop, blocks=z,
                           excitation_mean=r.mean(axis=0), lines=lines,
                           first=offset + drop * n, dropped=drop)


def _periodic_plant(parts: Sequence[_PeriodicRecord], lines: NDArray[np.intp],
                    f: NDArray[np.float64], *, options: dict[str, Any],
                    leakage: LeakageOptions | None, smoothing_lines: int,
                    period_correlation: bool
                    ) -> tuple[FrfEstimate, NDArray[np.complex128], NDArray[np.complex128]]:
    """``G = S_yr S_ur^-1`` with its variance on ``lines`` (``f`` [Hz]), and the ``S_yr``,
    ``S_ur`` it comes from.

    From the periods' mean and scatter, or with ``leakage`` from the whole records with the
    noise's leakage removed (:func:`joint_periodic`). ``options`` are the estimate's, its
    method and noise options added here.
    """
    fs, n = parts[0].record.fs_hz, parts[0].period
    p_used = [p.periods for p in parts]
    means = _mean_responses(parts, lines)
    if leakage is not None:
        s_yr, s_ur, g, var, noise, u_cols = _leakage_free(parts, lines, leakage)
        dof = [leakage.dof * leakage.smoothing_lines] * 2
        opts = {**options, "leakage": leakage.to_json(),
                "method": "joint input-output (G = S_yr S_ur^-1), periodic averaging, the "
                          "noise's leakage across lines removed"}
    else:
        s_yr, s_ur = means.s_yr, means.s_ur
        g = s_yr @ _inverse_2x2(s_ur)
        var, noise = _period_variance(parts, lines, g, means.u_mean,
                                      smoothing_lines=smoothing_lines,
                                      period_correlation=period_correlation)
        u_cols = np.stack([means.u_mean[:, j, j] for j in range(2)], axis=1)
        dof = [(p - 1.0) * smoothing_lines for p in p_used]
        opts = {**options, "noise_smoothing_lines": smoothing_lines,
                "method": "joint input-output (G = S_yr S_ur^-1), periodic averaging"}
    plant = _estimate(f, g, var, dof, n_blocks=[float(p) for p in p_used], u_cols=u_cols,
                      noise_var=noise, fs_hz=fs, resolution_hz=fs / n, block=n,
                      estimator="periodic", options=opts)
    return plant, s_yr, s_ur


def _lpm_columns(r: NDArray[np.complex128], z: NDArray[np.complex128],
                 lines: NDArray[np.intp], n: int, degree: int
                 ) -> tuple[NDArray[np.complex128], NDArray[np.complex128],
                            NDArray[np.complex128]]:
    """LPM with one input ``r`` and outputs ``z`` (B lines).

    Returns θ_0 (B, q) (the responses of ``z`` to ``r``), their covariance (B, q, q) and the
    residual covariance ``C_V`` of ``z`` per line (B, q, q).
    """
    width = 2 * n + 1
    start = np.clip(lines - n, 0, r.size - width)
    idx = start[:, None] + np.arange(width)[None, :]
    rr = (idx - lines[:, None]) / n
    powers = rr[:, :, None] ** np.arange(degree + 1)[None, None, :]
    rw = r[idx]
    scale = np.sqrt(np.mean(np.abs(rw) ** 2, axis=1))
    scale = np.where(scale > 0.0, scale, 1.0)
    k_mat = np.concatenate([rw[:, :, None] / scale[:, None, None] * powers,
                            powers.astype(complex)], axis=2)  # (B, W, 2(R+1))
    kh = np.conj(np.swapaxes(k_mat, 1, 2))
    inv = np.linalg.inv(kh @ k_mat)
    zw = z[idx]  # (B, W, q)
    theta = inv @ (kh @ zw)
    resid = zw - k_mat @ theta
    dof = width - k_mat.shape[2]
    c_v = np.einsum("bwa,bwc->bac", resid, np.conj(resid)) / dof
    inv00 = inv[:, 0, 0].real / scale**2
    return theta[:, 0, :] / scale[:, None], c_v * inv00[:, None, None], c_v


def joint_lpm(records: Sequence[ClosedLoopRecord], *, options: LpmOptions | None = None
              ) -> ClosedLoopFrf:
    """``G = S_yr S_ur^-1`` by the local polynomial method, any excitation (module notes).

    Parameters
    ----------
    records : sequence of 2 ClosedLoopRecord
        The excitation on ``Uch`` (or its reference), then on ``Ucv``; cut to the
        shorter one's length (kept from their ends) so that they share their lines.
    options : LpmOptions, optional
        Degree, window and band; default stride ``2n + 1`` (windows that do not
        overlap: nearly independent lines, what the variance-weighted fit assumes).

    Raises
    ------
    ValueError
        Not two records, rates that differ, too short a record, no line in the band.
    """
    if len(records) != 2:
        raise ValueError(f"the 2x2 plant needs two closed-loop records (one per command), got "
                         f"{len(records)}")
    opts = options or LpmOptions(stride=2 * LpmOptions().n + 1)
    fs = records[0].fs_hz
    if abs(records[1].fs_hz - fs) > 1e-9 * fs:
        raise ValueError(f"{records[1].name} is sampled at {records[1].fs_hz:g} Hz, "
                         f"{records[0].name} at {fs:g} Hz")
    length = min(rec.excitation.size for rec in records)
    n = opts.n
    lines = _lpm_lines(length, fs_hz=fs, options=opts)
    f = lines * fs / length
    s_yr = np.empty((lines.size, 2, 2), dtype=complex)
    s_ur = np.empty((lines.size, 2, 2), dtype=complex)
    cov: list[NDArray[np.complex128]] = []
    noise_cols: list[NDArray[np.complex128]] = []
    u_cols = np.empty((lines.size, 2), dtype=complex)
    for j, rec in enumerate(records):
        r = np.fft.rfft(rec.excitation[-length:]) / math.sqrt(length)
        z = _record_dft(rec, length)
        theta, c, c_v = _lpm_columns(r, z, lines, n, opts.degree)
        s_yr[:, :, j] = theta[:, :2]
        s_ur[:, :, j] = theta[:, 2:]
        cov.append(c)
        noise_cols.append(c_v)
        u_cols[:, j] = theta[:, 2 + j] * r[lines]
    g, var, _resid = _g_and_variance(s_yr, s_ur, cov)
    dof = 2 * n + 1 - 2 * (opts.degree + 1)
    # The noise of y - G u per line of the whole record (normalised DFT) [V^2].
    noise = np.stack([_project(g, c_v) for c_v in noise_cols], axis=2)
    options_json = {"degree": opts.degree, "half_width": n, "stride": opts.stride,
                    "record_samples": int(length),
                    "method": "joint input-output (G = S_yr S_ur^-1), local polynomial method"}
    plant = _estimate(f, g, var, (float(dof),) * 2, n_blocks=(1.0, 1.0),
                      u_cols=u_cols, noise_var=noise,
                      fs_hz=fs, resolution_hz=fs / length, block=length, estimator="lpm",
                      options=options_json)
    # The direct method on the same lines: spectra summed over each line's window, both records.
    direct = _direct(f, _window_spectra(records, lines, length=length, half_width=n), fs_hz=fs,
                     resolution_hz=fs / length, block=length, estimator="lpm")
    return ClosedLoopFrf(plant=plant, s_ur=s_ur, s_yr=s_yr, direct=direct,
                         method="joint input-output, local polynomial method")


def closed_loop_frf(records: Sequence[ClosedLoopRecord], *,
                    estimator: Literal["auto", "periodic", "lpm"] = "auto",
                    transient_periods: int | None = None,
                    lpm_options: LpmOptions | None = None) -> ClosedLoopFrf:
    """The plant from two closed-loop records: periodic averaging or the LPM.

    ``"auto"``: periodic when both excitations repeat with at least
    ``transient_periods + 2`` whole periods (3 when the transient is found from the
    records), else the LPM.
    """
    if estimator not in ("auto", "periodic", "lpm"):
        raise ValueError(f"estimator must be auto, periodic or lpm, got {estimator!r}")
    if estimator == "auto":
        periodic = True
        for rec in records:
            n = detect_period(rec.excitation)
            if n is None or rec.excitation.size // n < (transient_periods or 1) + 2:
                periodic = False
        estimator = "periodic" if periodic else "lpm"
    if estimator == "periodic":
        return joint_periodic(records, transient_periods=transient_periods)
    return joint_lpm(records, options=lpm_options)
