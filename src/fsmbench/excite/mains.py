"""Multisine lines on mains harmonics: which, a one-line warning, and the grids that avoid them.

A bench's mains pickup (50 Hz or 60 Hz and its harmonics) is periodic like a
multisine; averaging over periods keeps it on every line it falls on as a
bias of the FRF. A line ``f`` of a grid of spacing ``r`` is *on* a harmonic
``m F`` when ``|f - m F| <= r / 2``: the harmonic is on that line's DFT bin,
or between it and a neighbour, leaking into both.

When do the odd grids avoid every harmonic? The harmonics sit at bins
``m q`` with ``q = F / r``. If ``q`` is a whole number, harmonic ``m`` is on
bin ``m q`` exactly: an odd bin for ``m = 1`` when ``q`` is odd, never when
``q`` is even; the odd-odd grid (``k = 1 mod 4``) is hit by ``m = q mod 4``
when ``q`` is odd (odd numbers are their own inverse mod 4), never when ``q``
is even. If ``q = a / b`` is not whole (``b >= 2``), the positions ``m a / b``
modulo 2 run through multiples of ``gcd(a, 2b) / b``, one of them within
``1 / b <= 1/2`` bin of an odd bin: some harmonic reaches an odd line (in a
wide enough band). So **the odd and odd-odd grids avoid every harmonic of
``F`` when ``F / r`` is an even whole number**, and the odd grid only then
(50 Hz at 1 Hz or 0.5 Hz: yes; at 2 Hz, 25 lines: no).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["harmonic_list", "mains_free_resolution", "mains_hits", "mains_warning",
           "odd_grids_avoid_mains"]

# Relative rounding accepted when a ratio of frequencies is taken as a whole number.
_WHOLE_RTOL = 1e-9


def _whole(x: float) -> int | None:
    n = round(x)
    return n if abs(x - n) <= _WHOLE_RTOL * max(1.0, abs(x)) else None


def mains_hits(lines_hz: np.ndarray, *, resolution_hz: float, mains_hz: float) -> np.ndarray:
    """Which lines are on a mains harmonic (within half a line spacing), shape (L,) of bool.

    Parameters
    ----------
    lines_hz : ndarray, shape (L,)
        Multisine lines [Hz].
    resolution_hz : float
        Spacing of the full grid, ``1/period`` [Hz].
    mains_hz : float
        Mains frequency [Hz]; 0 gives no hit.
    """
    f = np.asarray(lines_hz, dtype=float)
    if mains_hz <= 0:
        return np.zeros(f.shape, dtype=bool)
    m = np.maximum(np.rint(f / mains_hz), 1.0)
    return np.abs(f - m * mains_hz) <= 0.5 * resolution_hz * (1 + _WHOLE_RTOL)


def odd_grids_avoid_mains(*, resolution_hz: float, mains_hz: float) -> bool:
    """``mains_hz / resolution_hz`` is an even whole number (see the module notes)."""
    q = _whole(mains_hz / resolution_hz)
    return q is not None and q > 0 and q % 2 == 0


def mains_free_resolution(*, resolution_hz: float, mains_hz: float, fs_hz: float,
                          max_divisor: int = 100_000) -> float | None:
    """The coarsest resolution ``<= resolution_hz`` whose odd grids avoid every harmonic [Hz].

    ``mains_hz / (2 j)`` for the smallest whole ``j`` that also gives a period of
    a whole number of samples at ``fs_hz``; None if no ``j <= max_divisor`` does.
    """
    j = max(1, math.ceil(mains_hz / (2 * resolution_hz) * (1 - _WHOLE_RTOL)))
    for jj in range(j, max_divisor + 1):
        r = mains_hz / (2 * jj)
        if _whole(fs_hz / r) is not None:
            return r
    return None


def harmonic_list(harmonics_hz: list[float]) -> str:
    """``50, 100, …, 2000 Hz`` for evenly spaced frequencies, else a short list [Hz]."""
    h = harmonics_hz
    if len(h) > 4 and np.allclose(np.diff(h), h[1] - h[0]):
        return f"{h[0]:g}, {h[1]:g}, …, {h[-1]:g} Hz"
    if len(h) > 4:
        return f"{h[0]:g}, {h[1]:g}, … ({len(h)} harmonics), {h[-1]:g} Hz"
    return ", ".join(f"{x:g}" for x in h) + " Hz"


def mains_warning(design: Any) -> str | None:
    """One line: the multisine's excited lines on mains harmonics and the fix, or None.

    ``design`` is an :class:`~fsmbench.excite.design.ExcitationDesign`; only
    multisines with ``mains_hz > 0`` are checked (noise and chirps are not periodic).
    """
    mains = float(getattr(design, "mains_hz", 0.0))
    if design.kind != "multisine" or mains <= 0:
        return None
    res = design.fs_hz / design.period_samples
    hit = mains_hits(design.lines_hz, resolution_hz=res, mains_hz=mains)
    if not np.any(hit):
        return None
    n = int(hit.sum())
    harmonics = sorted({float(m) * mains for m in np.rint(design.lines_hz[hit] / mains)})
    q = mains / res
    if odd_grids_avoid_mains(resolution_hz=res, mains_hz=mains):
        fix = (f"--odd puts every harmonic of {mains:g} Hz on a non-excited line "
               f"({mains:g} Hz is {q:.0f} lines of {res:g} Hz, an even number)")
    else:
        r = mains_free_resolution(resolution_hz=res, mains_hz=mains, fs_hz=design.fs_hz)
        fix = ("" if r is None else
               f"--odd with --resolution {r:g} puts every harmonic of {mains:g} Hz on a "
               f"non-excited line ({mains:g} Hz is {mains / r:.0f} lines, an even number; "
               f"at {res:g} Hz it is {q:.6g})")
    return (f"{design.input} multisine: {n} excited line{'s' if n != 1 else ''} on harmonics "
            f"of the {mains:g} Hz mains ({harmonic_list(harmonics)}), where the bench's mains "
            f"pickup stays as a bias after averaging; {fix + ', or ' if fix else ''}"
            "--skip-mains leaves them out")
