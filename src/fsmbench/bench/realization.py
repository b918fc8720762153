"""Minimal state-space realisations and the plant's delays as Padé or exact samples.

python-control's ``minreal`` and ``balred`` need slycot, which fsmbench does not
install; a model with Padé delays on every input then carries dozens of states
that one loop cannot see or reach, and ``control.stability_margins`` (which goes
through the transfer function's polynomials) drowns in their near-cancelling
roots. Here, with numpy and scipy only:

* :func:`minimal_realization` removes the uncontrollable and the unobservable
  states by the orthogonal staircase (Kalman) decomposition, each rank decided
  from an SVD, on a diagonally balanced copy (rank decisions need comparable
  row and column scales: the bench mixes 1e-4 rad/V gains and 1e5 rad/s poles);
* :func:`pade_delays` puts a Padé approximant in front of each input;
* :func:`zoh_with_delays` samples a model driven through a zero-order hold with
  a delay on each input, exactly: whole samples as ``z^-n`` (delay-line states)
  and the fractional remainder by the modified z-transform (the hold's step
  lands inside a sample period: the input reaches the states through two
  matrices, the sample's own and the previous one's).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from typing import Literal

import control as ct
import numpy as np
from scipy import linalg

Delays = Literal["pade", "exact", "none"]

__all__ = [
    "DEFAULT_TOL",
    "Delays",
    "balance_states",
    "gamma_integral",
    "minimal_realization",
    "pade_delays",
    "plant_model",
    "select",
    "zoh_with_delays",
]

#: Relative rank tolerance of the staircase: a block's singular value below this
#: times the balanced system's norm counts as zero. sqrt(eps), MATLAB ``minreal``'s:
#: rounding in the staircase reaches 1e-10 on mixed lightly damped modes, the
#: bench's weakest genuine coupling (the other axis's mode through the 4QD's
#: rotation) is 1e-3.
DEFAULT_TOL = float(np.sqrt(np.finfo(float).eps))

# A delay within this many samples of a whole number of samples is that number:
# 1.5 Ts minus the hold's half sample is 1 Ts, not 1 Ts plus a rounding residue.
_WHOLE_SAMPLE_TOL = 1e-9


def _abcd(sys: ct.StateSpace) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    a, b, c, d = (np.array(x, dtype=float) for x in (sys.A, sys.B, sys.C, sys.D))
    n = a.shape[0]
    return (a.reshape(n, n), b.reshape(n, d.shape[1]), c.reshape(d.shape[0], n), d)


def _named(sys: ct.StateSpace, a: np.ndarray, b: np.ndarray, c: np.ndarray,
           d: np.ndarray, *, name: str | None = None) -> ct.StateSpace:
    """A new system with ``sys``'s sample time and signal names."""
    kwargs = {} if name is None and not sys.name else {"name": name or sys.name}
    return ct.ss(a, b, c, d, sys.dt, inputs=list(sys.input_labels),
                 outputs=list(sys.output_labels), **kwargs)


def balance_states(a: np.ndarray, b: np.ndarray, c: np.ndarray, *,
                   sweeps: int = 50) -> np.ndarray:
    """Diagonal state scaling ``t`` (powers of 2) that balances ``[A B; C 0]``.

    ``T^-1 A T``, ``T^-1 B``, ``C T`` with ``T = diag(t)`` have each state's row
    and column of similar norm (MATLAB's ``ssbal``; Parlett–Reinsch on the
    states only, so inputs and outputs keep their units). Shape (n,).
    """
    n = a.shape[0]
    t = np.ones(n)
    a, b, c = np.abs(a), np.abs(b), np.abs(c)
    off = a - np.diag(np.diag(a))
    for _ in range(sweeps):
        done = True
        for i in range(n):
            col = off[:, i].sum() + c[:, i].sum()
            row = off[i, :].sum() + b[i, :].sum()
            if col == 0 or row == 0:
                continue
            f = 2.0 ** round(0.5 * math.log2(row / col))
            if f == 1.0:
                continue
            done = False
            off[:, i] *= f
            c[:, i] *= f
            off[i, :] /= f
            b[i, :] /= f
            t[i] *= f
        if done:
            break
    return t


def _staircase(a: np.ndarray, b: np.ndarray, tol: float) -> tuple[int, np.ndarray]:
    """Controllable subspace of ``(A, B)``: its dimension and an orthogonal basis first.

    Returns ``(nc, q)``: the first ``nc`` columns of the orthogonal ``q`` span
    the controllable subspace (``q.T A q`` is block upper triangular with the
    controllable part first). Each step's rank is the count of singular values
    above ``tol``.
    """
    n = a.shape[0]
    q = np.eye(n)
    at = a.copy()
    block = b.copy()
    nc = 0
    while nc < n and block.size:
        u, s, _ = np.linalg.svd(block, full_matrices=True)
        r = int(np.sum(s > tol))
        if r == 0:
            break
        t = np.eye(n)
        t[nc:, nc:] = u
        at = t.T @ at @ t
        q = q @ t
        block = at[nc + r:, nc:nc + r]
        nc += r
    return nc, q


def _structural(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Indices of the states an input reaches and an output sees through nonzero entries.

    The others are exactly uncontrollable or unobservable (a sub-system's unused
    blocks) and go before any rounding: kept, an unused block's large couplings
    would set the scale of every later rank decision.
    """
    n = a.shape[0]
    link = a != 0

    def closure(start: np.ndarray, step: np.ndarray) -> np.ndarray:
        seen = start.copy()
        while True:
            grown = seen | step[:, seen].any(axis=1)
            if (grown == seen).all():
                return seen
            seen = grown

    reached = closure(np.asarray((b != 0).any(axis=1)).reshape(n), link)
    seen = closure(np.asarray((c != 0).any(axis=0)).reshape(n), link.T)
    return np.flatnonzero(reached & seen)


def minimal_realization(sys: ct.StateSpace, *, tol: float = DEFAULT_TOL,
                        name: str | None = None) -> ct.StateSpace:
    """A minimal realisation of ``sys`` (continuous or discrete), same names and sample time.

    The states no input reaches and those no output sees are removed by two
    orthogonal staircase reductions (controllability, then observability of what
    is left), on a diagonally balanced copy (:func:`balance_states`). The
    response is unchanged to rounding (the transformations are orthogonal); the
    state count is the McMillan degree when the rank decisions are right.

    Parameters
    ----------
    sys : control.StateSpace
    tol : float
        Relative rank tolerance: a singular value below ``tol`` times the norm of
        the balanced ``[A B]`` (``[A; C]``) is zero.
    name : str, optional
        Name of the result (default: ``sys``'s).
    """
    a, b, c, d = _abcd(sys)
    keep = _structural(a, b, c)
    a, b, c = a[np.ix_(keep, keep)], b[keep], c[:, keep]
    if a.shape[0] == 0:
        return _named(sys, a, b, c, d, name=name)
    t = balance_states(a, b, c)
    ab, bb, cb = a * (t[None, :] / t[:, None]), b / t[:, None], c * t[None, :]
    n = ab.shape[0]
    scale = max(float(np.linalg.norm(np.hstack([ab, bb]), 2)), np.finfo(float).tiny)
    nc, q = _staircase(ab, bb, tol * scale)
    if nc < n:
        ab, bb, cb = (q.T @ ab @ q)[:nc, :nc], (q.T @ bb)[:nc], (cb @ q)[:, :nc]
    no = nc
    if nc:
        scale = max(float(np.linalg.norm(np.vstack([ab, cb]), 2)), np.finfo(float).tiny)
        no, q = _staircase(ab.T, cb.T, tol * scale)
        if no < nc:
            ab, bb, cb = (q.T @ ab @ q)[:no, :no], (q.T @ bb)[:no], (cb @ q)[:, :no]
    if no == n:  # nothing to remove numerically: keep the exact (pruned) entries
        return _named(sys, a, b, c, d, name=name)
    return _named(sys, ab, bb, cb, d, name=name)


@functools.cache
def _unit_pade(order: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Balanced realisation of the Padé approximant of ``e^-s`` (:func:`control.pade`).

    The companion form's coefficients span 1 to ``order!``-sized numbers (6.7e5
    for order 6); the approximant is all-pass and stable, so its balanced
    realisation has unit Gramians and O(1) entries.
    """
    num, den = ct.pade(1.0, order)
    a, b, c, d = _abcd(ct.tf2ss(ct.tf(num, den)))
    p = linalg.solve_continuous_lyapunov(a, -b @ b.T)
    q = linalg.solve_continuous_lyapunov(a.T, -c.T @ c)
    r = linalg.cholesky(0.5 * (p + p.T), lower=True)
    u, s2, _ = np.linalg.svd(r.T @ q @ r)
    t = r @ u / s2[None, :] ** 0.25
    t_inv = np.linalg.solve(t, np.eye(t.shape[0]))
    return t_inv @ a @ t, t_inv @ b, c @ t, d


def pade_delays(sys: ct.StateSpace, delays_s: Mapping[str, float], *,
                order: int = 6) -> ct.StateSpace:
    """``sys`` with a Padé approximant of ``order`` in front of each delayed input.

    Each approximant ``N(s tau) / D(s tau)`` (:func:`control.pade`) is realised
    for ``tau = 1`` and time-scaled (``A/tau``, ``B/tau``), so its coefficients
    stay O(1) instead of spanning ``tau^-order``. Inputs missing from
    ``delays_s`` or with no delay pass straight through. The result is continuous
    and not minimal in general (:func:`minimal_realization`).
    """
    if sys.dt not in (0, None):
        raise ValueError("Padé delays are continuous: sys must be continuous")
    a, b, c, d = _abcd(sys)
    n, m = b.shape
    blocks = []
    for inp in sys.input_labels:
        tau = float(delays_s.get(inp, 0.0))
        if tau < 0:
            raise ValueError(f"input {inp}: negative delay {tau} s")
        if tau == 0 or order == 0:
            blocks.append((np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)),
                           np.ones((1, 1))))
            continue
        pa, pb, pc, pd = _unit_pade(order)
        blocks.append((pa / tau, pb / tau, pc, pd))
    # Delay blocks side by side: w' = Aw w + Bw u, u_delayed = Cw w + Dw u.
    aw = linalg.block_diag(*(blk[0] for blk in blocks)) if blocks else np.zeros((0, 0))
    bw = linalg.block_diag(*(blk[1] for blk in blocks))
    cw = linalg.block_diag(*(blk[2] for blk in blocks))
    dw = linalg.block_diag(*(blk[3] for blk in blocks))
    nw = aw.shape[0]
    bw, cw = bw.reshape(nw, m), cw.reshape(m, nw)
    big_a = np.block([[a, b @ cw], [np.zeros((nw, n)), aw]])
    big_b = np.vstack([b @ dw, bw])
    big_c = np.hstack([c, d @ cw])
    return _named(sys, big_a, big_b, big_c, d @ dw)


def zoh_with_delays(sys: ct.StateSpace, delays_s: Mapping[str, float], *,
                    dt: float) -> ct.StateSpace:
    """Exact zero-order-hold sampling at ``dt`` of ``sys`` with a delay on each input.

    A delay ``tau = l dt + delta`` (``0 <= delta < dt``) holds input ``j``'s
    sample ``u[k - l]`` on the plant from ``k dt + delta`` to ``(k+1) dt + delta``,
    so over one period ``x[k+1] = Phi x[k] + G1 u[k-l] + G0 u[k-l-1]`` with
    ``G1 = int_0^(dt-delta) e^(A s) ds B`` and
    ``G0 = e^(A (dt-delta)) int_0^delta e^(A s) ds B`` (the modified z-transform:
    exact, no approximation). The past samples are ``l`` (``l + 1`` when
    ``delta > 0``) delay-line states per input; whole samples are ``z^-l``
    exactly. The response is exact at the sampling instants for a piecewise
    constant input.

    Parameters
    ----------
    sys : control.StateSpace
        Continuous system.
    delays_s : mapping of input name to delay [s]
        Delay from the held sample to the plant's input (the hold itself is
        modelled by the sampling: a plant model whose delays include the hold's
        half sample must pass ``tau - dt/2``).
    dt : float
        Sample time [s].
    """
    if sys.dt not in (0, None):
        raise ValueError("zoh_with_delays samples a continuous system")
    if not dt > 0:
        raise ValueError(f"dt must be positive, got {dt}")
    a, b, c, d = _abcd(sys)
    m = b.shape[1]
    phi, _ = gamma_integral(a, b, dt)
    whole: list[int] = []
    frac: list[float] = []
    for inp in sys.input_labels:
        w, f = _whole_and_fraction(inp, float(delays_s.get(inp, 0.0)), dt=dt)
        whole.append(w)
        frac.append(f)
    big_a, big_b, big_c = _sampled_with_delay_lines(a, b, c, d, phi=phi, whole=whole, frac=frac,
                                                    dt=dt)
    big_d = d * np.array([1.0 if whole[j] == 0 and frac[j] == 0 else 0.0 for j in range(m)])
    return ct.ss(big_a, big_b, big_c, big_d, dt, inputs=list(sys.input_labels),
                 outputs=list(sys.output_labels), **({"name": sys.name} if sys.name else {}))


def gamma_integral(a: np.ndarray, b: np.ndarray, h_s: float) -> tuple[np.ndarray, np.ndarray]:
    """``(e^{A h}, int_0^h e^{A s} ds B)`` over a hold of ``h_s`` [s].

    From one exponential of the augmented matrix ``[[A, B], [0, 0]]``.
    """
    n, m = b.shape
    aug = np.zeros((n + m, n + m))
    aug[:n, :n] = a * h_s
    aug[:n, n:] = b * h_s
    e = linalg.expm(aug)
    return e[:n, :n], e[:n, n:]


def _whole_and_fraction(inp: str, tau: float, *, dt: float) -> tuple[int, float]:
    """One input's delay ``tau`` [s] as whole samples of ``dt`` [s] and the rest [s].

    A delay within :data:`_WHOLE_SAMPLE_TOL` samples of a whole number is that number.

    Raises
    ------
    ValueError
        Naming the input, for a negative delay.
    """
    if tau < 0:
        raise ValueError(f"input {inp}: negative delay {tau} s after the hold")
    x = tau / dt
    whole = round(x) if abs(x - round(x)) < _WHOLE_SAMPLE_TOL else math.floor(x)
    return whole, 0.0 if abs(x - round(x)) < _WHOLE_SAMPLE_TOL else (x - whole) * dt


def _sampled_with_delay_lines(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray, *,
                              phi: np.ndarray, whole: Sequence[int], frac: Sequence[float],
                              dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(A, B, C)`` sampled at ``dt`` [s]: the plant's states, then each input's delay line.

    Parameters
    ----------
    a, b, c, d : arrays (n, n), (n, m), (p, n), (p, m)
        Continuous system.
    phi : array (n, n)
        ``e^(A dt)``.
    whole, frac : sequences of length m
        Each input's delay as whole samples and the remaining fraction [s]
        (:func:`_whole_and_fraction`).
    dt : float
        Sample time [s].
    """
    n, m = b.shape
    # Delay line of input j: its past samples u[k-1] ... u[k-n_j].
    lengths = [w + (1 if f > 0 else 0) for w, f in zip(whole, frac, strict=True)]
    starts = np.concatenate([[0], np.cumsum(lengths)]).astype(int) + n
    nt = int(starts[-1])
    big_a = np.zeros((nt, nt))
    big_b = np.zeros((nt, m))
    big_c = np.zeros((c.shape[0], nt))
    big_a[:n, :n] = phi
    big_c[:, :n] = c
    for j in range(m):
        s0, nj = int(starts[j]), lengths[j]
        if nj:
            big_b[s0, j] = 1.0
            for i in range(1, nj):
                big_a[s0 + i, s0 + i - 1] = 1.0
        e_late, g_late = gamma_integral(a, b, dt - frac[j])  # the part of the period after delta
        _, g_early = gamma_integral(a, b, frac[j])
        g1, g0 = g_late[:, j], e_late @ g_early[:, j]
        _route_held_sample(big_a, big_b, g1, j=j, lag=whole[j], start=s0)
        if frac[j] > 0:
            _route_held_sample(big_a, big_b, g0, j=j, lag=whole[j] + 1, start=s0)
        # The output at k dt sees the sample that is on the plant then.
        lag = whole[j] + (1 if frac[j] > 0 else 0)
        if lag == 0:
            continue
        big_c[:, s0 + lag - 1] += d[:, j]
    return big_a, big_b, big_c


def _route_held_sample(big_a: np.ndarray, big_b: np.ndarray, col: np.ndarray, *, j: int,
                       lag: int, start: int) -> None:
    """Add the gain ``col`` (n,) of input ``j``'s sample ``u[k - lag]`` to the plant's states.

    The sample enters through the input itself (lag 0) or through its delay
    line, whose first state is ``start``; ``big_a``, ``big_b`` change in place.
    """
    n = col.shape[0]
    if lag == 0:
        big_b[:n, j] += col
    else:
        big_a[:n, start + lag - 1] += col


def select(sys: ct.StateSpace, *, outputs: Sequence[str] | None = None,
           inputs: Sequence[str] | None = None) -> ct.StateSpace:
    """The sub-system between named inputs and outputs (all by default)."""
    outs = list(sys.output_labels if outputs is None else outputs)
    ins = list(sys.input_labels if inputs is None else inputs)
    a, b, c, d = _abcd(sys)
    oi = [_index(sys.output_labels, o, "output") for o in outs]
    ii = [_index(sys.input_labels, i, "input") for i in ins]
    return ct.ss(a, b[:, ii], c[oi, :], d[np.ix_(oi, ii)], sys.dt, inputs=ins, outputs=outs)


def _index(labels: Sequence[str], name: str, kind: str) -> int:
    try:
        return list(labels).index(name)
    except ValueError:
        raise KeyError(f"no {kind} named {name!r}; {kind}s are {list(labels)}") from None


def plant_model(sys: ct.StateSpace, delays_s: Mapping[str, float], *,
                delays: Delays = "pade", order: int = 6, dt: float | None = None,
                minimal: bool = True, tol: float = DEFAULT_TOL,
                name: str | None = None) -> ct.StateSpace:
    """A delay-free continuous ``sys`` with its input delays, as one python-control model.

    Parameters
    ----------
    sys : control.StateSpace
        Continuous, delay-free.
    delays_s : mapping of input name to delay [s]
        As a plant carries them (:attr:`fsmbench.bench.blocks.PlantModel.input_delay_s`):
        they include the hold's half sample (:func:`fsmbench.bench.blocks.input_delays_s`).
    delays : {"pade", "exact", "none"}
        ``"pade"``: continuous, each delay a Padé approximant of ``order``;
        ``"exact"``: sampled at ``dt`` through a zero-order hold, each delay
        less the hold's half sample exact (:func:`zoh_with_delays`: whole
        samples ``z^-n``, the fraction by the modified z-transform);
        ``"none"``: the delays left out (sampled by a zero-order hold if ``dt``).
    order : int
        Padé order.
    dt : float, optional
        Sample time [s]; required by ``"exact"``, refused by ``"pade"``.
    minimal : bool
        Return :func:`minimal_realization` (default) rather than the assembled model.
    tol : float
        Rank tolerance of the minimal realisation.
    name : str, optional
    """
    if delays == "pade":
        if dt is not None:
            raise ValueError("Padé delays give a continuous model; for a sampled one use "
                             "delays='exact' with dt")
        model = pade_delays(sys, delays_s, order=order)
    elif delays == "exact":
        if dt is None:
            raise ValueError("exact delays need a sample time: pass dt (a continuous model "
                             "cannot hold a pure delay; use delays='pade')")
        late = {}
        for inp in sys.input_labels:
            tau = float(delays_s.get(inp, 0.0))
            if tau < 0.5 * dt * (1 - _WHOLE_SAMPLE_TOL):
                raise ValueError(f"input {inp}: delay {tau:g} s is shorter than the hold's "
                                 f"half sample {0.5 * dt:g} s it includes")
            late[inp] = max(tau - 0.5 * dt, 0.0)
        model = zoh_with_delays(sys, late, dt=dt)
    elif delays == "none":
        model = sys if dt is None else zoh_with_delays(sys, {}, dt=dt)
    else:
        raise ValueError(f"delays={delays!r}: use 'pade', 'exact' or 'none'")
    if minimal:
        return minimal_realization(model, tol=tol, name=name)
    return model if name is None else _named(model, *_abcd(model), name=name)
