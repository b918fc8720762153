"""Exact zero-order-hold discretisation with per-input (fractional) delays.

The DAC holds each command for one sample; the continuous plant sees input
``j`` delayed by ``tau_j = (m_j + f_j) T`` (integer ``m_j``, fraction
``0 <= f_j < 1``). Over one sample the delayed input takes the older value for
``f_j T`` and the newer one for ``(1 - f_j) T``, so (modified z-transform)::

    x[k+1] = Phi x[k] + Gamma(f T-part) u_j[k-m_j-1] + Gamma((1-f) T-part) u_j[k-m_j]

with ``Gamma_1 = e^{A (1-f) T} Gamma(f T)``, ``Gamma_0 = Gamma((1-f) T)`` and
``Gamma(h) = int_0^h e^{A s} ds B``, all from one matrix exponential of the
augmented matrix ``[[A, B], [0, 0]]``. Past commands are kept as extra states
(shift registers), giving a plain delay-free discrete system
``z[k+1] = Ad z[k] + Bd u[k]``, ``y[k] = Cd z[k]`` that the simulation engine
steps without any special case.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

# One matrix exponential of the hold for both samplers (bench.realization's), re-exported.
from fsmbench.bench.realization import gamma_integral

__all__ = ["DiscretePlant", "gamma_integral", "zoh_with_delays"]


@dataclass(frozen=True)
class DiscretePlant:
    """Delay-free discrete system ``z[k+1] = a z[k] + b u[k]``, ``y[k] = c z[k]``.

    Attributes
    ----------
    a : array (nz, nz)
    b : array (nz, m)
    c : array (p, nz)
    ts_s : float
        Sampling period [s].
    input_names, output_names : tuple of str
    n_plant_states : int
        The first states are the plant's; the rest hold past inputs.
    input_delay_samples : tuple of float
        Delay of each input in samples, before the hold (what was asked for).
    """

    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    ts_s: float
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]
    n_plant_states: int
    input_delay_samples: tuple[float, ...]

    def frequency_response(self, f_hz: np.ndarray) -> np.ndarray:
        """Response ``c (zI - a)^-1 b`` at ``z = exp(j 2 pi f T)``, shape (nf, p, m)."""
        f = np.asarray(f_hz, dtype=float).ravel()
        z = np.exp(2j * np.pi * f * self.ts_s)
        n = self.a.shape[0]
        lhs = z[:, None, None] * np.eye(n)[None] - self.a[None]
        x = np.linalg.solve(lhs, np.broadcast_to(self.b, (f.size, *self.b.shape)).astype(complex))
        return np.einsum("pn,fnm->fpm", self.c, x)


def zoh_with_delays(a: np.ndarray, b: np.ndarray, c: np.ndarray, *, ts_s: float,
                    input_delay_samples: Sequence[float],
                    input_names: Sequence[str], output_names: Sequence[str],
                    d: np.ndarray | None = None) -> DiscretePlant:
    """Discretise ``dx/dt = A x + B u(t - tau)``, ``y = C x + D u(t - tau)`` for a held input.

    Parameters
    ----------
    a, b, c : arrays (n, n), (n, m), (p, n)
        Continuous plant.
    ts_s : float
        Sampling period T [s].
    input_delay_samples : sequence of float, length m
        Delay of each input in samples (>= 0, fractional allowed), counted
        from the command sample to the start of its hold.
    input_names, output_names : sequences of str
    d : array (p, m), optional
        Direct feedthrough (an identified model's constant above its band). At
        sample ``k`` the delayed held input is the command of sample
        ``k - ceil(tau/T)``, a state of the shift register, so the discrete model
        keeps ``y[k] = c z[k]``; an input with feedthrough needs a delay of at
        least one sample (a real converter's), else ValueError.

    Returns
    -------
    DiscretePlant
        States: the n plant states, then for each input its past commands
        ``u[k-1], u[k-2], ...`` as far back as its delay needs.
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    c = np.asarray(c, dtype=float)
    n, m = b.shape
    delays = [float(d) for d in input_delay_samples]
    if len(delays) != m:
        raise ValueError(f"{len(delays)} delays given for {m} inputs")
    if any(d < 0 for d in delays):
        raise ValueError(f"input delays must be >= 0 samples, got {delays}")
    phi, _ = gamma_integral(a, b, ts_s)
    split = _split_delays(delays)
    ad, bd = _delay_line_system(a, b, phi=phi, split=split, ts_s=ts_s)
    cd = np.zeros((c.shape[0], ad.shape[0]))
    cd[:, :n] = c
    if d is not None:
        _add_feedthrough(cd, np.asarray(d, dtype=float), n_plant_states=n, lags=split.lags,
                         input_names=input_names)
    return DiscretePlant(a=ad, b=bd, c=cd, ts_s=ts_s, input_names=tuple(input_names),
                         output_names=tuple(output_names), n_plant_states=n,
                         input_delay_samples=tuple(delays))


class _DelaySplit(NamedTuple):
    """Each input's delay as whole samples, a fraction of a sample, and register length."""

    whole: list[int]
    frac: list[float]
    lags: list[int]


def _split_delays(delays: Sequence[float]) -> _DelaySplit:
    """Split each delay [samples] into whole samples and a fraction of one.

    The fraction is rounded to 1e-9 of a sample so that 3.5000000001 is 3.5,
    not 4 minus a sliver; an input keeps ``lags`` past commands (one more than
    its whole samples when a fraction remains).
    """
    whole = [int(np.floor(d + 1e-9)) for d in delays]
    frac = [max(0.0, d - w) if d - w > 1e-9 else 0.0 for d, w in zip(delays, whole, strict=True)]
    lags = [w + (1 if f > 0 else 0) for w, f in zip(whole, frac, strict=True)]
    return _DelaySplit(whole=whole, frac=frac, lags=lags)


def _held_input_gains(a: np.ndarray, bj: np.ndarray, *, frac: float,
                      ts_s: float) -> tuple[np.ndarray, np.ndarray]:
    """``(Gamma_0, Gamma_1)`` of one input: the newer and the older command's gains.

    Parameters
    ----------
    a : array (n, n)
        Continuous state matrix [1/s].
    bj : array (n, 1)
        The input's column of B.
    frac : float
        Fractional part of the input's delay [samples], in ``[0, 1)``.
    ts_s : float
        Sampling period T [s].
    """
    if frac > 0:
        e_rest, g_new = gamma_integral(a, bj, (1.0 - frac) * ts_s)
        _, g_old_part = gamma_integral(a, bj, frac * ts_s)
        return g_new, e_rest @ g_old_part
    _, g_new = gamma_integral(a, bj, ts_s)
    return g_new, np.zeros((a.shape[0], 1))


def _delay_line_system(a: np.ndarray, b: np.ndarray, *, phi: np.ndarray, split: _DelaySplit,
                       ts_s: float) -> tuple[np.ndarray, np.ndarray]:
    """``(Ad, Bd)``: the plant's states, then each input's shift register of past commands.

    Parameters
    ----------
    a, b : arrays (n, n), (n, m)
        Continuous plant.
    phi : array (n, n)
        ``e^{A T}``.
    split : _DelaySplit
        The inputs' delays (:func:`_split_delays`).
    ts_s : float
        Sampling period T [s].
    """
    n, m = b.shape
    whole, frac, lags = split
    nz = n + sum(lags)
    ad = np.zeros((nz, nz))
    bd = np.zeros((nz, m))
    ad[:n, :n] = phi
    offset = n
    for j in range(m):
        g_new, g_old = _held_input_gains(a, b[:, j:j + 1], frac=frac[j], ts_s=ts_s)
        # Register r_j = [u_j[k-1], ..., u_j[k-lags_j]] occupies states offset .. offset+lags-1.
        taps = {whole[j]: g_new}
        if frac[j] > 0:
            taps[whole[j] + 1] = g_old
        for lag, g in taps.items():
            if lag == 0:
                bd[:n, j:j + 1] += g
            else:
                ad[:n, offset + lag - 1:offset + lag] += g
        if lags[j] > 0:
            bd[offset, j] = 1.0
            for i in range(1, lags[j]):
                ad[offset + i, offset + i - 1] = 1.0
        offset += lags[j]
    return ad, bd


def _add_feedthrough(cd: np.ndarray, d: np.ndarray, *, n_plant_states: int, lags: Sequence[int],
                     input_names: Sequence[str]) -> None:
    """Add the direct feedthrough ``d`` (p, m) to ``cd`` in place, on the register states.

    Raises
    ------
    ValueError
        ``d``'s shape is not (p, m), or an input with feedthrough has no delay.
    """
    m = len(lags)
    if d.shape != (cd.shape[0], m):
        raise ValueError(f"d has shape {d.shape}, expected {(cd.shape[0], m)}")
    offset = n_plant_states
    for j in range(m):
        if np.any(d[:, j] != 0.0):
            if lags[j] == 0:
                raise ValueError(f"input {input_names[j]} has a direct feedthrough and no "
                                 "delay: the sampled loop would have an algebraic loop")
            # u(kT - tau) with the hold is the command issued lags_j samples ago.
            cd[:, offset + lags[j] - 1] += d[:, j]
        offset += lags[j]
