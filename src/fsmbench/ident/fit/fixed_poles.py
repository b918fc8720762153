"""Residues and constant of a rational model whose poles are given, by linear least squares.

With the poles fixed (the Sercalo's modes replaced by their leakage-free
estimates, :func:`fsmbench.ident.sercalo.refit_with_poles`) the model
``Σ r_k/(s − a_k) + D`` is linear in its residues and ``D``: each element of
the matrix is a weighted linear least-squares fit, the residues of a pair
``a, ā`` conjugate so that the model is real.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["FixedPoleFit", "fit_residues"]


@dataclass(frozen=True, eq=False)
class FixedPoleFit:
    """The linear part of a rational model with given poles.

    Attributes
    ----------
    residues : ndarray, complex, shape (n, p, m)
        Residue of each pole for each element (conjugate for a pole pair), units of
        the response times rad/s.
    d : ndarray, shape (p, m)
        The constant term, units of the response.
    """

    residues: NDArray[np.complex128]
    d: NDArray[np.float64]


def fit_residues(s: NDArray[np.complex128], h: NDArray[np.complex128], *,
                 w: NDArray[np.float64], poles: NDArray[np.complex128]) -> FixedPoleFit:
    """Residues and ``D`` of each element by weighted linear least squares.

    Parameters
    ----------
    s : ndarray, complex, shape (F,)
        ``j 2π f`` of the lines [rad/s].
    h : ndarray, complex, shape (F, p, m)
        The response fitted.
    w : ndarray, shape (F, p, m)
        Weight of each line and element (0 drops it).
    poles : ndarray, complex, shape (n,)
        The poles [rad/s], pairs with both members.
    """
    basis = _pole_basis(s, poles)
    groups = _pole_groups(poles)  # the basis's column order
    p, m = h.shape[1], h.shape[2]
    residues = np.zeros((poles.size, p, m), dtype=complex)
    d = np.zeros((p, m))
    for i in range(p):
        for jj in range(m):
            ww = w[:, i, jj]
            a_mat = basis * ww[:, None]
            rhs = h[:, i, jj] * ww
            x, *_ = np.linalg.lstsq(np.vstack([a_mat.real, a_mat.imag]),
                                    np.concatenate([rhs.real, rhs.imag]), rcond=None)
            col = 0
            for k, j in groups:
                if j is not None:
                    residues[k, i, jj] = x[col] + 1j * x[col + 1]
                    residues[j, i, jj] = x[col] - 1j * x[col + 1]
                    col += 2
                else:
                    residues[k, i, jj] = x[col]
                    col += 1
            d[i, jj] = x[col]
    return FixedPoleFit(residues=residues, d=d)


def _pole_basis(s: NDArray[np.complex128], poles: NDArray[np.complex128]
                ) -> NDArray[np.complex128]:
    """Columns at ``s`` [rad/s] of a real-coefficient partial-fraction model, then ``D``.

    A pair ``a, ā`` gives ``1/(s−a) + 1/(s−ā)`` and ``j/(s−a) − j/(s−ā)`` (the real and
    imaginary parts of its residue), a real pole ``1/(s−a)``; shape (F, columns).
    """
    cols = []
    for k, j in _pole_groups(poles):
        a = poles[k]
        if j is not None:
            cols.append(1 / (s - a) + 1 / (s - np.conj(a)))
            cols.append(1j / (s - a) - 1j / (s - np.conj(a)))
        else:
            cols.append(1 / (s - a))
    cols.append(np.ones_like(s))  # D
    return np.column_stack(cols)


def _pole_groups(poles: NDArray[np.complex128]) -> list[tuple[int, int | None]]:
    """The poles in model order: ``(k, j)`` for a pair (``j`` the conjugate's index),
    ``(k, None)`` for a real pole; the basis's columns and the residues read this order."""
    groups: list[tuple[int, int | None]] = []
    done: set[int] = set()
    for k, a in enumerate(poles):
        if k in done:
            continue
        if abs(a.imag) > 0:
            j = int(np.flatnonzero(np.isclose(poles, np.conj(a)))[0])
            done.update({k, j})
            groups.append((k, j))
        else:
            done.add(k)
            groups.append((k, None))
    return groups
