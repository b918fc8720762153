"""The compiled per-sample loop of :mod:`fsmbench.sim.engine`, on its own.

:mod:`fsmbench.sim.codegen` reads :func:`loop_body`'s source to write a loop unrolled for
one plant, and the module it generates imports :func:`quantise_scalar`: both build on this
module, and the engine on both.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["loop_body", "quantise_scalar"]


@njit(cache=True, nogil=True, error_model="numpy")
def quantise_scalar(x: float, lsb: float, lo: float, hi: float) -> float:
    if lsb <= 0.0:
        return x
    code = np.floor(x / lsb + 0.5)
    if code < lo:
        code = lo
    elif code > hi:
        code = hi
    return code * lsb


@njit(cache=True, nogil=True, error_model="numpy")
def loop_body(ab_row: np.ndarray, ab_col: np.ndarray, ab_val: np.ndarray,
               c_row: np.ndarray, c_col: np.ndarray, c_val: np.ndarray, n_adc: int,
               adc_noise: np.ndarray, adc_cubic: np.ndarray,
               adc_lsb: float, adc_lo: float, adc_hi: float,
               ak: np.ndarray, bk: np.ndarray, ck: np.ndarray, dk: np.ndarray,
               k_in: np.ndarray, k_out: np.ndarray, u_ext: np.ndarray,
               dac_lsb: float, dac_lo: float, dac_hi: float, z0: np.ndarray, xk0: np.ndarray,
               out_adc: np.ndarray, out_dac: np.ndarray, out_int: np.ndarray) -> None:
    # Plant matrices are in coordinate form (row, col, value): [A | B] acting
    # on [z; u], and C acting on z. The bench's discrete plant is ~90 % zeros
    # (block-diagonal modes, delay lines); entries are ordered so that
    # consecutive updates hit different rows, which keeps the CPU's
    # multiply-add chains independent (1.6x faster than row-by-row CSR).
    n_steps = u_ext.shape[0]
    nz = z0.shape[0]
    ny = out_adc.shape[1] + out_int.shape[1]
    n_ab = ab_row.shape[0]
    n_c = c_row.shape[0]
    y = np.zeros(ny)
    nu = u_ext.shape[1]
    nk = ak.shape[0]
    ni = k_in.shape[0]
    no = k_out.shape[0]
    zu = np.zeros(nz + nu)
    for i in range(nz):
        zu[i] = z0[i]
    z_next = np.zeros(nz)
    xk = np.zeros(nk)
    for i in range(nk):
        xk[i] = xk0[i]
    xk_next = np.zeros(nk)
    e = np.zeros(ni)
    for k in range(n_steps):
        # Plant outputs and ADC.
        # <outputs> (fsmbench.sim.codegen replaces this block for one plant)
        for i in range(ny):
            y[i] = 0.0
        for q in range(n_c):
            y[c_row[q]] += c_val[q] * zu[c_col[q]]
        # </outputs>
        for i in range(n_adc):
            yi = y[i]
            if adc_cubic[i] != 0.0:
                # Sensor non-linearity y (1 + c y**2) (a 4QD's compression).
                yi = yi + adc_cubic[i] * yi * yi * yi
            out_adc[k, i] = quantise_scalar(yi + adc_noise[k, i], adc_lsb, adc_lo, adc_hi)
        for i in range(n_adc, ny):
            out_int[k, i - n_adc] = y[i]
        # Controller.
        for i in range(ni):
            e[i] = out_adc[k, k_in[i]]
        for i in range(nu):
            zu[nz + i] = u_ext[k, i]
        for i in range(no):
            acc = 0.0
            for j in range(nk):
                acc += ck[i, j] * xk[j]
            for j in range(ni):
                acc += dk[i, j] * e[j]
            zu[nz + k_out[i]] += acc
        for i in range(nk):
            acc = 0.0
            for j in range(nk):
                acc += ak[i, j] * xk[j]
            for j in range(ni):
                acc += bk[i, j] * e[j]
            xk_next[i] = acc
        for i in range(nk):
            xk[i] = xk_next[i]
        # DAC.
        for i in range(nu):
            zu[nz + i] = quantise_scalar(zu[nz + i], dac_lsb, dac_lo, dac_hi)
            out_dac[k, i] = zu[nz + i]
        # Plant update.
        # <update> (fsmbench.sim.codegen replaces this block for one plant)
        for i in range(nz):
            z_next[i] = 0.0
        for q in range(n_ab):
            z_next[ab_row[q]] += ab_val[q] * zu[ab_col[q]]
        # </update>
        for i in range(nz):
            zu[i] = z_next[i]
    # Hand the state back (in place) for the next block.
    for i in range(nz):
        z0[i] = zu[i]
    for i in range(nk):
        xk0[i] = xk[i]
