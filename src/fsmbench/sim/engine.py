"""The per-sample engine of the bench: plant, converters and controller at 10 kHz.

Each sample ``k`` does what the real-time target does:

1. the ADC reads the plant outputs plus their noise, quantised to the
   converter's step and clipped to its rails;
2. the controller (if any) reads its ADC channels, scaled to beam angle,
   and computes its commands (``u = -K R`` with the sign folded in);
3. the commands plus the open-loop excitation are quantised and clipped by
   the DAC and stored;
4. the plant advances one sample with those commands (delays are states of
   the discrete plant, see :mod:`fsmbench.sim.discretize`).

The quantisers make the loop nonlinear, so it cannot be vectorised; the
step is compiled with numba. ``run_loop_python`` runs the identical source
as plain Python (numba's ``py_func``), for the benchmark and as a cross-check.

The loop starts from a given plant and controller state and hands back the
state it ends in, so a run cut into blocks gives, sample for sample, the
bits of one run of the whole length (:mod:`fsmbench.sim.stream` relies on it).
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass
from typing import Any

import numpy as np

from fsmbench.sim.codegen import specialised_kernel
from fsmbench.sim.discretize import DiscretePlant
from fsmbench.sim.kernel import loop_body

__all__ = [
    "DiscreteController",
    "LoopResult",
    "Quantiser",
    "per_plant",
    "run_loop",
    "run_loop_python",
]


@dataclass(frozen=True)
class Quantiser:
    """A bipolar converter: ``bits`` over ``range_v`` (e.g. 16 bit, -10 V .. +10 V).

    Codes run from ``-2**(bits-1)`` to ``2**(bits-1) - 1`` (two's complement),
    so the positive rail is one step below ``+range/2``. ``bits = 0`` disables
    quantisation and clipping (an ideal converter, for linear checks).
    """

    range_v: float
    bits: int

    @property
    def lsb_v(self) -> float:
        """Quantisation step [V]."""
        return self.range_v / 2**self.bits if self.bits > 0 else 0.0

    def apply(self, x: np.ndarray) -> np.ndarray:
        """Quantise and clip an array [V] (vectorised, same rule as the engine)."""
        if self.bits == 0:
            return np.asarray(x, dtype=float).copy()
        lsb = self.lsb_v
        code = np.clip(np.floor(np.asarray(x) / lsb + 0.5), -(2 ** (self.bits - 1)),
                       2 ** (self.bits - 1) - 1)
        return code * lsb


@dataclass(frozen=True)
class DiscreteController:
    """``x[k+1] = a x + b e``, ``u = c x + d e`` wired between ADC and DAC channels.

    Attributes
    ----------
    a, b, c, d : arrays (nk, nk), (nk, ni), (no, nk), (no, ni)
        Already including the input scaling (volts to radians) and the
        feedback sign: the engine adds ``u`` to the DAC commands as is.
    adc_inputs : tuple of int
        Indices of the ADC channels the controller reads.
    dac_outputs : tuple of int
        Indices of the DAC channels it drives.
    name : str
    """

    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    d: np.ndarray
    adc_inputs: tuple[int, ...]
    dac_outputs: tuple[int, ...]
    name: str


@dataclass(frozen=True)
class LoopResult:
    """Samples of one run: ADC readings, DAC commands and noise-free internal signals.

    Attributes
    ----------
    adc : array (n, n_adc) [V]
    dac : array (n, n_dac) [V]
    internal : array (n, n_internal) [plant output units]
    plant_state : array (nz,)
        Plant state after the last sample (the next run's ``z0``).
    controller_state : array (nk,)
        Controller state after the last sample (the next run's ``xk0``).
    """

    adc: np.ndarray
    dac: np.ndarray
    internal: np.ndarray
    plant_state: np.ndarray
    controller_state: np.ndarray


def _coo(m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(rows, cols, values) of a dense matrix's non-zeros, rows interleaved.

    Entries are sorted by their rank within their row, then by row: the
    first entry of every row, then the second of every row, and so on. The
    sum for each row is still accumulated in column order, so results equal
    a row-by-row product bit for bit.
    """
    rows, cols = np.nonzero(m)
    rank = np.zeros(rows.size, dtype=np.int64)
    for r in np.unique(rows):
        where = np.flatnonzero(rows == r)
        rank[where] = np.arange(where.size)
    order = np.lexsort((rows, rank))
    return (rows[order].astype(np.int64), cols[order].astype(np.int64),
            np.ascontiguousarray(m[rows[order], cols[order]], dtype=float))


_PER_PLANT: dict[tuple[int, str], Any] = {}


def per_plant(plant: DiscretePlant, what: str, build: Any) -> Any:
    """``build(plant)``, computed once per plant object (a stream steps one plant many times).

    Keyed by identity (the plant's arrays make it unhashable); the entry goes
    when the plant does.
    """
    key = (id(plant), what)
    if key not in _PER_PLANT:
        _PER_PLANT[key] = build(plant)
        weakref.finalize(plant, _PER_PLANT.pop, key, None)
    return _PER_PLANT[key]


def _sparse(plant: DiscretePlant) -> tuple[np.ndarray, ...]:
    return (*_coo(np.hstack([plant.a, plant.b])), *_coo(plant.c))


def _prepare(plant: DiscretePlant, *, u_ext: np.ndarray, adc_noise: np.ndarray,
             adc: Quantiser, dac: Quantiser, controller: DiscreteController | None,
             n_adc: int, z0: np.ndarray | None, xk0: np.ndarray | None,
             adc_cubic: np.ndarray | None = None) -> tuple[Any, ...]:
    n_steps = u_ext.shape[0]
    cubic = np.zeros(n_adc) if adc_cubic is None else np.array(adc_cubic, dtype=float)
    if cubic.shape != (n_adc,):
        raise ValueError(f"adc_cubic must have shape {(n_adc,)}, got {cubic.shape}")
    if u_ext.shape[1] != plant.b.shape[1]:
        raise ValueError(f"u_ext has {u_ext.shape[1]} columns, plant has {plant.b.shape[1]} inputs")
    if adc_noise.shape != (n_steps, n_adc):
        raise ValueError(f"adc_noise must have shape {(n_steps, n_adc)}, got {adc_noise.shape}")
    if controller is None:
        ak = np.zeros((0, 0))
        bk = np.zeros((0, 0))
        ck = np.zeros((0, 0))
        dk = np.zeros((0, 0))
        k_in = np.zeros(0, dtype=np.int64)
        k_out = np.zeros(0, dtype=np.int64)
    else:
        ak, bk, ck, dk = (np.ascontiguousarray(x, dtype=float)
                          for x in (controller.a, controller.b, controller.c, controller.d))
        k_in = np.asarray(controller.adc_inputs, dtype=np.int64)
        k_out = np.asarray(controller.dac_outputs, dtype=np.int64)
    # Copies: the kernel updates the state in place, the caller's arrays stay as given.
    z = np.zeros(plant.a.shape[0]) if z0 is None else np.array(z0, dtype=float)
    if z.shape != (plant.a.shape[0],):
        raise ValueError(f"z0 must have shape {(plant.a.shape[0],)}, got {z.shape}")
    xk = np.zeros(ak.shape[0]) if xk0 is None else np.array(xk0, dtype=float)
    if xk.shape != (ak.shape[0],):
        raise ValueError(f"xk0 must have shape {(ak.shape[0],)}, got {xk.shape}")

    def rails(q: Quantiser) -> tuple[float, float, float]:
        if q.bits == 0:
            return 0.0, -np.inf, np.inf
        return q.lsb_v, -(2.0 ** (q.bits - 1)), 2.0 ** (q.bits - 1) - 1.0

    a_lsb, a_lo, a_hi = rails(adc)
    d_lsb, d_lo, d_hi = rails(dac)
    out_adc = np.zeros((n_steps, n_adc))
    out_dac = np.zeros((n_steps, plant.b.shape[1]))
    out_int = np.zeros((n_steps, plant.c.shape[0] - n_adc))
    args = (*per_plant(plant, "sparse", _sparse), n_adc,
            np.ascontiguousarray(adc_noise, dtype=float), cubic,
            a_lsb, a_lo, a_hi, ak, bk, ck, dk, k_in, k_out,
            np.ascontiguousarray(u_ext, dtype=float), d_lsb, d_lo, d_hi, z, xk,
            out_adc, out_dac, out_int)
    return args


def run_loop(plant: DiscretePlant, *, u_ext: np.ndarray, adc_noise: np.ndarray, adc: Quantiser,
             dac: Quantiser, controller: DiscreteController | None = None, n_adc: int,
             z0: np.ndarray | None = None, xk0: np.ndarray | None = None,
             specialise: bool = False, adc_cubic: np.ndarray | None = None) -> LoopResult:
    """Run the compiled loop.

    Parameters
    ----------
    plant : DiscretePlant
        Its first ``n_adc`` outputs go through the ADC; the rest are internal.
    u_ext : array (n, n_dac) [V]
        Open-loop commands (excitations) added to the controller's output.
    adc_noise : array (n, n_adc) [V]
        Noise added to each ADC channel before quantisation.
    adc, dac : Quantiser
    controller : DiscreteController, optional
        ``None`` for open loop.
    n_adc : int
    z0 : array (nz,), optional
        Initial plant state (default zero); not modified.
    xk0 : array (nk,), optional
        Initial controller state (default zero); not modified.
    specialise : bool
        Compile a loop for this plant with its products unrolled
        (:mod:`fsmbench.sim.codegen`): ~5x faster per sample, bit-identical,
        one compilation per plant (cached on disk). Worth it for long runs
        of one plant (the twin); the generic loop suits one-off plants.
    adc_cubic : array (n_adc,), optional
        Cubic non-linearity of each ADC channel's sensor, applied to the
        noise-free output before the noise: ``y + c y**3`` [1/V**2]
        (default zeros: linear sensors).
    """
    args = _prepare(plant, u_ext=u_ext, adc_noise=adc_noise, adc=adc, dac=dac,
                    controller=controller, n_adc=n_adc, z0=z0, xk0=xk0, adc_cubic=adc_cubic)
    if specialise:
        per_plant(plant, "kernel", specialised_kernel)(*args)
    else:
        loop_body(*args)
    return _result(args)


def run_loop_python(plant: DiscretePlant, *, u_ext: np.ndarray, adc_noise: np.ndarray,
                    adc: Quantiser, dac: Quantiser, controller: DiscreteController | None = None,
                    n_adc: int, z0: np.ndarray | None = None,
                    xk0: np.ndarray | None = None,
                    adc_cubic: np.ndarray | None = None) -> LoopResult:
    """The same loop as :func:`run_loop`, interpreted (slow; benchmark and cross-check)."""
    args = _prepare(plant, u_ext=u_ext, adc_noise=adc_noise, adc=adc, dac=dac,
                    controller=controller, n_adc=n_adc, z0=z0, xk0=xk0, adc_cubic=adc_cubic)
    # py_func is the undecorated Python source of the compiled loop.
    loop_body.py_func(*args)
    return _result(args)


def _result(args: tuple[Any, ...]) -> LoopResult:
    # args ends with z, xk (updated in place by the loop), out_adc, out_dac, out_int.
    return LoopResult(adc=args[-3], dac=args[-2], internal=args[-1], plant_state=args[-5],
                      controller_state=args[-4])
