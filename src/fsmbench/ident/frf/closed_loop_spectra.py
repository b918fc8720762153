"""The closed-loop records' spectra, as the joint estimators read them.

:mod:`fsmbench.ident.frf.closed_loop` estimates the plant from these:

* the periodic estimator cuts each record into whole periods (normalised DFT of
  each), keeps the lines its excitation excites and those both records share, and
  averages the periods;
* the LPM takes the DFT of each whole record, on the lines of its band;
* the direct method divides the cross-spectra of ``y`` and ``u`` summed over the
  periods, or over each line's LPM window, by the number of blocks summed.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from fsmbench.ident.frf.lpm import LpmOptions

if TYPE_CHECKING:
    from fsmbench.ident.frf.closed_loop import ClosedLoopRecord

__all__: list[str] = []

# A line of the recorded excitation is excited above this fraction of the strongest line's
# power: the excitation is the commanded one, exact, whose FFT holds round-off at ~1e-32 of
# its lines elsewhere; a shaped multisine's lines span at most 1e6 in power.
_EXCITED_RELATIVE_POWER = 1e-12


@dataclass(frozen=True, eq=False)
class _PeriodicRecord:
    """One closed-loop record cut into its steady periods.

    Attributes
    ----------
    record : ClosedLoopRecord
    period : int
        The excitation's period [samples].
    periods : int
        Whole periods kept (after the transient).
    blocks : ndarray, complex, shape (periods, period // 2 + 1, 4)
        Normalised DFT of ``[y, u]`` in each kept period [V].
    excitation_mean : ndarray, complex, shape (period // 2 + 1,)
        The excitation's DFT averaged over the kept periods [V].
    lines : ndarray of int
        The lines the excitation excites.
    first : int
        The first sample of the kept periods.
    dropped : int
        Leading periods dropped (the loop's transient).
    """

    record: ClosedLoopRecord
    period: int
    periods: int
    blocks: NDArray[np.complex128]
    excitation_mean: NDArray[np.complex128]
    lines: NDArray[np.intp]
    first: int
    dropped: int


@dataclass(frozen=True, eq=False)
class _MeanResponses:
    """The responses to the excitation on the shared lines, averaged over the periods.

    Attributes
    ----------
    s_yr, s_ur : ndarray, complex, shape (F, 2, 2)
        Of the 4QD outputs and of the commands (column ``j``: record ``j``) [V/V].
    u_mean : ndarray, complex, shape (F, 2, 2)
        The commands' mean DFT (column ``j``: record ``j``) [V].
    """

    s_yr: NDArray[np.complex128]
    s_ur: NDArray[np.complex128]
    u_mean: NDArray[np.complex128]


@dataclass(frozen=True, eq=False)
class _CrossSpectra:
    """Cross-spectra of ``y`` and ``u`` summed over blocks, for the direct method.

    Attributes
    ----------
    phi_yu, phi_uu, phi_yy : ndarray, complex, shape (F, 2, 2)
        Sums of ``y u^H``, ``u u^H`` and ``y y^H`` [V^2].
    blocks : float
        Blocks summed (periods, or each line's window in both records).
    """

    phi_yu: NDArray[np.complex128]
    phi_uu: NDArray[np.complex128]
    phi_yy: NDArray[np.complex128]
    blocks: float


def _period_blocks(
    x: NDArray[np.float64], n: int, first: int, periods: int
) -> NDArray[np.complex128]:
    """Normalised DFT of each period, (periods, n//2 + 1, ...)."""
    seg = x[first : first + periods * n].reshape(periods, n, *x.shape[1:])
    return np.fft.rfft(seg, axis=1) / math.sqrt(n)


def _excited_lines(excitation_blocks: NDArray[np.complex128]) -> NDArray[np.intp]:
    """Lines ``k >= 1`` the excitation excites, from its periods' DFTs (P, n//2 + 1)."""
    power = np.abs(excitation_blocks.mean(axis=0)) ** 2
    # The excitation is recorded as commanded (digital, exact): every line it holds
    # above round-off is excited, however the lines are shaped.
    lines = np.flatnonzero(power > _EXCITED_RELATIVE_POWER * power[1:].max())
    return lines[lines > 0]


def _shared_lines(parts: Sequence[_PeriodicRecord]) -> NDArray[np.intp]:
    """The lines both records excite, on the one period they must share.

    Raises
    ------
    ValueError
        The periods differ, or no line is excited in both.
    """
    first, second = parts[0], parts[1]
    if first.period != second.period:
        raise ValueError(
            f"{first.record.name} repeats every {first.period} samples, "
            f"{second.record.name} every {second.period}: play both on the same "
            "grid"
        )
    lines = np.intersect1d(first.lines, second.lines)
    if lines.size == 0:
        raise ValueError(
            f"no line is excited in both {first.record.name} and "
            f"{second.record.name}: excite both commands on the same grid"
        )
    return lines


def _mean_responses(parts: Sequence[_PeriodicRecord], lines: NDArray[np.intp]) -> _MeanResponses:
    """``S_yr``, ``S_ur`` and the mean commands on ``lines``, from the periods' mean."""
    s_yr = np.empty((lines.size, 2, 2), dtype=complex)
    s_ur = np.empty((lines.size, 2, 2), dtype=complex)
    u_mean = np.empty((lines.size, 2, 2), dtype=complex)  # columns: the mean commands
    for j, part in enumerate(parts):
        zm = part.blocks[:, lines, :].mean(axis=0)  # (F, 4): [y; u], averaged over the periods
        rm = part.excitation_mean
        s_yr[:, :, j] = zm[:, :2] / rm[lines, None]
        s_ur[:, :, j] = zm[:, 2:] / rm[lines, None]
        u_mean[:, :, j] = zm[:, 2:]
    return _MeanResponses(s_yr=s_yr, s_ur=s_ur, u_mean=u_mean)


def _period_spectra(parts: Sequence[_PeriodicRecord], lines: NDArray[np.intp]) -> _CrossSpectra:
    """The cross-spectra on ``lines`` summed over every kept period of both records."""
    phi_yu = np.zeros((lines.size, 2, 2), dtype=complex)
    phi_uu = np.zeros((lines.size, 2, 2), dtype=complex)
    phi_yy = np.zeros((lines.size, 2, 2), dtype=complex)
    blocks = 0
    for part in parts:
        yl, ul = part.blocks[:, lines, :2], part.blocks[:, lines, 2:]
        phi_yu += np.einsum("pfa,pfb->fab", yl, np.conj(ul))
        phi_uu += np.einsum("pfa,pfb->fab", ul, np.conj(ul))
        phi_yy += np.einsum("pfa,pfb->fab", yl, np.conj(yl))
        blocks += part.periods
    return _CrossSpectra(phi_yu=phi_yu, phi_uu=phi_uu, phi_yy=phi_yy, blocks=blocks)


def _record_dft(rec: ClosedLoopRecord, length: int) -> NDArray[np.complex128]:
    """Normalised DFT of ``[y, u]`` over the record's last ``length`` samples, (L/2 + 1, 4)."""
    z = np.hstack([rec.outputs, rec.commands])[-length:]
    return np.fft.rfft(z, axis=0) / math.sqrt(length)


def _lpm_lines(length: int, *, fs_hz: float, options: LpmOptions) -> NDArray[np.intp]:
    """The lines of a record of ``length`` samples at ``fs_hz`` [Hz] the LPM estimates.

    Raises
    ------
    ValueError
        Fewer lines than one LPM window, or no line in the band.
    """
    n = options.n
    n_lines = length // 2 + 1
    if n_lines < 2 * n + 1:
        raise ValueError(
            f"{length} samples give {n_lines} lines, fewer than the LPM window of "
            f"{2 * n + 1}; use longer records"
        )
    f_all = np.arange(n_lines) * fs_hz / length
    keep = f_all > 0
    if options.f_min_hz is not None:
        keep &= f_all >= options.f_min_hz
    if options.f_max_hz is not None:
        keep &= f_all <= options.f_max_hz
    lines = np.flatnonzero(keep)[:: options.stride]
    if lines.size == 0:
        raise ValueError(f"no line in the band [{options.f_min_hz}, {options.f_max_hz}] Hz")
    return lines


def _window_spectra(
    records: Sequence[ClosedLoopRecord], lines: NDArray[np.intp], *, length: int, half_width: int
) -> _CrossSpectra:
    """The cross-spectra summed over each line's LPM window (``2 half_width + 1`` lines) of
    both records' last ``length`` samples."""
    width = 2 * half_width + 1
    start = np.clip(lines - half_width, 0, length // 2 + 1 - width)
    idx = start[:, None] + np.arange(width)[None, :]
    phi_yu = np.zeros((lines.size, 2, 2), dtype=complex)
    phi_uu = np.zeros((lines.size, 2, 2), dtype=complex)
    phi_yy = np.zeros((lines.size, 2, 2), dtype=complex)
    for rec in records:
        z = _record_dft(rec, length)
        zw = z[idx]  # (F, W, 4)
        y, u = zw[:, :, :2], zw[:, :, 2:]
        phi_yu += np.einsum("fwa,fwb->fab", y, np.conj(u))
        phi_uu += np.einsum("fwa,fwb->fab", u, np.conj(u))
        phi_yy += np.einsum("fwa,fwb->fab", y, np.conj(y))
    return _CrossSpectra(phi_yu=phi_yu, phi_uu=phi_uu, phi_yy=phi_yy, blocks=2.0 * width)
