"""The local polynomial method (LPM): FRF, noise variance and transient of any excitation.

R. Pintelon, J. Schoukens, G. Vandersteen, K. Barbé, "Estimation of
nonparametric noise and FRF models for multivariable systems — Part I:
Theory", Mechanical Systems and Signal Processing 24(3), 2010, pp. 573–595.

On the DFT of the whole record (normalised by ``L^-1/2``, lines
``k = 0 .. L/2``) the output of a linear system is exactly

    Y(k) = G(k) U(k) + T(k) + V(k),

where ``T`` (the transient: the system's state at the record's ends, the
"leakage" of a non-periodic record) is a smooth function of frequency, as is
``G``, and ``V`` is the noise. Around each line ``k``, over the ``2n + 1``
lines ``k + r`` (``r = -n .. n``, the window shifted to stay inside the band
at its ends), both are expanded in polynomials of degree ``R``::

    G(k + r) = G(k) + sum_s g_s r^s,   T(k + r) = T(k) + sum_s t_s r^s,

and the ``2 (R + 1)`` complex coefficients are the linear least-squares
solution ``theta = K^+ Y`` with the regressor rows
``K(r) = [U(k+r) r^0 .. U(k+r) r^R, r^0 .. r^R]``. Then ``G(k) = theta_0``,
``T(k) = theta_{R+1}``, and from the residual ``E = Y - K theta``:

* noise variance ``s2_V(k) = |E|^2 / q`` with ``q = 2n + 1 - 2 (R + 1)``
  degrees of freedom (the residual of a least-squares fit with ``2 (R+1)``
  parameters has expectation ``q s2_V`` when ``V`` is uncorrelated over
  lines with locally constant variance — the paper's eq. (21));
* ``var G(k) = s2_V(k) [(K^H K)^-1]_00``.

Choice of the window (``half_width=None``): ``q >= 2 (R + 1) + 1``, i.e.
``n = 2 (R + 1)`` (13 lines for the default ``R = 2``). Fewer dof make the
variance estimate itself noisy (its relative std is ``1/sqrt(q)``, 38 % at
``q = 7``); a wider window makes the polynomial approximation of ``G`` worse
at a sharp resonance (the method's bias, ``O(((2n+1) df / B)^(R+1))`` for a
mode of 3 dB bandwidth ``B``, small once the record is much longer than
``1/B``).

Neighbouring lines share most of their windows, so the estimates at adjacent
lines are correlated. ``stride`` keeps every ``stride``-th line only;
``stride = 2n + 1`` gives windows that do not overlap, hence nearly
independent lines — what a weighted fit that treats lines as independent
needs. The estimate is at every line by default.

Implementation: all lines at once, by blocks of lines, with NumPy batched
products and 2(R+1) x 2(R+1) inverses (columns scaled: ``r / n`` instead of
``r``, the input divided by its rms over the window); no Python loop over
lines.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fsmbench.ident.frf.estimate import FrfEstimate, simo_signals

__all__ = ["LPM_NOISE_SMOOTHING", "LpmOptions", "default_half_width", "local_polynomial_frf"]

# Lines per batch: bounds memory at ~(block x (2n+1) x 2(R+1)) complex values
# (~40 MB for the default window), whatever the record's length.
_BLOCK_LINES = 32768


def default_half_width(degree: int) -> int:
    """``n = 2 (R + 1)``: residual dof ``q = 2 (R + 1) + 1`` (see the module notes)."""
    return 2 * (degree + 1)


@dataclass(frozen=True)
class LpmOptions:
    """Options of :func:`local_polynomial_frf`.

    Attributes
    ----------
    degree : int
        Degree ``R`` of the local polynomials of ``G`` and ``T`` (>= 0).
    half_width : int or None
        ``n``: the window is ``2n + 1`` lines; None: ``2 (R + 1)``.
    stride : int
        Keep every ``stride``-th line (1: every line; ``2n + 1``: windows
        that do not overlap).
    f_min_hz, f_max_hz : float or None
        Keep the lines inside this band, Hz (every line is still used by the
        windows of its neighbours).
    transient : bool
        Fit the transient polynomial (the LPM); False fits ``G`` alone (the
        local *rational* method's special case without leakage term, for comparison).
    confidence : float
        Level of the confidence bound.
    noise_smoothing : int
        Half width, in estimated lines, of a running median of the noise
        variance ``s2_V`` (0: none). One line's ``s2_V`` has ``q`` (7) complex
        degrees of freedom: as a weight it makes a fit's lines heavy-tailed
        (a line whose noise came out low counts too much) and a likelihood
        ratio test falsely sure. The noise spectrum is smooth;
        the median over ``2 w + 1`` lines (scaled to a mean, 2/π of their
        dof) replaces it, except where one line is 5× its neighbours (a mains
        line), which keeps its own.
    """

    degree: int = 2
    half_width: int | None = None
    stride: int = 1
    f_min_hz: float | None = None
    f_max_hz: float | None = None
    transient: bool = True
    confidence: float = 0.95
    noise_smoothing: int = 0

    def __post_init__(self) -> None:
        if self.noise_smoothing < 0:
            raise ValueError(f"noise_smoothing must be >= 0, got {self.noise_smoothing}")
        if self.degree < 0:
            raise ValueError(f"degree must be >= 0, got {self.degree}")
        if self.stride < 1:
            raise ValueError(f"stride must be >= 1, got {self.stride}")
        n_par = (2 if self.transient else 1) * (self.degree + 1)
        if self.half_width is not None and 2 * self.half_width + 1 <= n_par:
            raise ValueError(f"a window of {2 * self.half_width + 1} lines leaves no degree of "
                             f"freedom for {n_par} parameters; widen half_width")
        if not 0.0 < self.confidence < 1.0:
            raise ValueError(f"confidence must be in (0, 1), got {self.confidence!r}")

    @property
    def n(self) -> int:
        """Half width ``n`` in lines."""
        return default_half_width(self.degree) if self.half_width is None else self.half_width


def _solve_block(u: NDArray[np.complex128], y: NDArray[np.complex128],
                 lines: NDArray[np.intp], n: int, degree: int, transient: bool
                 ) -> tuple[NDArray[np.complex128], NDArray[np.complex128],
                            NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """LPM at ``lines``: G (B, p), T (B, p), s2_V (B, p), [(K^H K)^-1]_00 (B,), |U|^2 (B,)."""
    width = 2 * n + 1
    n_lines = u.size
    start = np.clip(lines - n, 0, n_lines - width)  # window shifted inside the band at its ends
    idx = start[:, None] + np.arange(width)[None, :]  # (B, W)
    r = (idx - lines[:, None]) / n  # scaled offsets, |r| <= 2
    powers = r[:, :, None] ** np.arange(degree + 1)[None, None, :]  # (B, W, R+1)
    uw = u[idx]  # (B, W)
    scale = np.sqrt(np.mean(np.abs(uw) ** 2, axis=1))
    scale = np.where(scale > 0.0, scale, 1.0)
    cols = [uw[:, :, None] / scale[:, None, None] * powers]
    if transient:
        cols.append(powers.astype(complex))
    k_mat = np.concatenate(cols, axis=2)  # (B, W, n_par)
    yw = y[idx]  # (B, W, p)
    kh = np.conj(np.swapaxes(k_mat, 1, 2))
    inv = np.linalg.inv(kh @ k_mat)  # (B, n_par, n_par)
    theta = inv @ (kh @ yw)  # (B, n_par, p)
    resid = yw - k_mat @ theta
    q = width - k_mat.shape[2]
    s2v = np.sum(np.abs(resid) ** 2, axis=1) / q
    g = theta[:, 0, :] / scale[:, None]
    t = theta[:, degree + 1, :] if transient else np.zeros_like(g)
    inv00 = inv[:, 0, 0].real / scale**2
    return g, t, s2v, inv00, np.abs(u[lines]) ** 2


def local_polynomial_frf(
    inputs: ArrayLike,
    outputs: ArrayLike,
    *,
    fs_hz: float,
    input_name: str,
    output_names: Sequence[str],
    options: LpmOptions | None = None,
    source: str = "the record",
) -> FrfEstimate:
    """SIMO FRF of one record of arbitrary excitation by the local polynomial method.

    Parameters
    ----------
    inputs : array_like, float, shape (L,)
        Measured excitation, U_in.
    outputs : array_like, float, shape (L, p) or (L,)
        Measured responses, U_out, same ``L``.
    fs_hz : float
        Sampling frequency, Hz.
    input_name : str
        Name of the input (the column).
    output_names : sequence of str
        ``p`` output names.
    options : LpmOptions, optional
        Degree, window, stride, band, confidence.
    source : str
        Named in error messages (e.g. the file).

    Returns
    -------
    FrfEstimate
        ``estimator="lpm"``, lines ``k fs / L`` (every ``stride``-th within the
        band), ``transient`` ``T(k)`` in U_out (normalised DFT), ``dof = (q,)``,
        ``snr = |G U|^2 / s2_V`` per line of the record.

    Raises
    ------
    ValueError
        Non-finite samples, unequal lengths, a record with fewer lines than
        one window, an input without power, or no line in the band.
    """
    opts = options or LpmOptions()
    u, y, names = simo_signals(inputs, outputs, input_name=input_name,
                               output_names=output_names, source=source)
    if not np.any(u != u[0]):
        raise ValueError(f"{source}: the input {input_name} is constant (no excitation)")
    n = opts.n
    length = u.size
    uf = np.fft.rfft(u) / np.sqrt(length)
    yf = np.fft.rfft(y, axis=0) / np.sqrt(length)
    if uf.size < 2 * n + 1:
        raise ValueError(f"{source}: {length} samples give {uf.size} lines, fewer than the "
                         f"LPM window of {2 * n + 1}; use a longer record")
    f_all = np.arange(uf.size) * fs_hz / length
    lines = _band_lines(f_all, opts, input_name=input_name, source=source)
    fits = _local_fits(uf, yf, lines, options=opts)
    return _lpm_estimate(fits, lines, frequency_hz=f_all[lines], length=length, fs_hz=fs_hz,
                         input_name=input_name, output_names=names, options=opts)


class _LocalFits(NamedTuple):
    """The LPM at each estimated line: ``g`` and the transient ``t`` (B, p), the noise
    variance ``s2v`` (B, p) with its ``dof``, ``[(K^H K)^-1]_00`` ``inv00`` (B,) and
    ``|U|^2`` ``pu`` (B,) (module notes; normalised DFT)."""

    g: NDArray[np.complex128]
    t: NDArray[np.complex128]
    s2v: NDArray[np.float64]
    inv00: NDArray[np.float64]
    pu: NDArray[np.float64]
    dof: float


def _band_lines(f_all: NDArray[np.float64], options: LpmOptions, *, input_name: str,
                source: str) -> NDArray[np.intp]:
    """Every ``stride``-th line of ``f_all`` [Hz] within the band.

    Raises
    ------
    ValueError
        No line in the band.
    """
    keep = np.ones(f_all.size, dtype=bool)
    if options.f_min_hz is not None:
        keep &= f_all >= options.f_min_hz
    if options.f_max_hz is not None:
        keep &= f_all <= options.f_max_hz
    lines = np.flatnonzero(keep)[:: options.stride]
    if lines.size == 0:
        raise ValueError(f"{source}: no line of {input_name} in the band "
                         f"[{options.f_min_hz}, {options.f_max_hz}] Hz")
    return lines


def _local_fits(uf: NDArray[np.complex128], yf: NDArray[np.complex128],
                lines: NDArray[np.intp], *, options: LpmOptions) -> _LocalFits:
    """The LPM on ``lines`` of the input's and outputs' DFTs, by blocks of lines, and the
    noise variance (smoothed when ``options.noise_smoothing``) with its dof."""
    n = options.n
    p = yf.shape[1]
    g = np.empty((lines.size, p), dtype=complex)
    t = np.empty((lines.size, p), dtype=complex)
    s2v = np.empty((lines.size, p))
    inv00 = np.empty(lines.size)
    pu = np.empty(lines.size)
    for lo in range(0, lines.size, _BLOCK_LINES):
        sl = slice(lo, lo + _BLOCK_LINES)
        g[sl], t[sl], s2v[sl], inv00[sl], pu[sl] = _solve_block(
            uf, yf, lines[sl], n, options.degree, options.transient)
    n_par = (2 if options.transient else 1) * (options.degree + 1)
    dof = float(2 * n + 1 - n_par)
    if options.noise_smoothing:
        s2v, dof = _smoothed(s2v, options.noise_smoothing, dof)
    return _LocalFits(g=g, t=t, s2v=s2v, inv00=inv00, pu=pu, dof=dof)


def _lpm_estimate(fits: _LocalFits, lines: NDArray[np.intp], *,
                  frequency_hz: NDArray[np.float64], length: int, fs_hz: float,
                  input_name: str, output_names: Sequence[str],
                  options: LpmOptions) -> FrfEstimate:
    """The :class:`FrfEstimate` of :func:`local_polynomial_frf` from its fits on ``lines``
    (``frequency_hz`` [Hz]) of a record of ``length`` samples at ``fs_hz`` [Hz]."""
    g, s2v, pu = fits.g, fits.s2v, fits.pu
    var = s2v * fits.inv00[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        snr = np.abs(g) ** 2 * pu[:, None] / s2v
    one_sided = np.where((lines == 0) | (2 * lines == length), 1.0, 2.0)
    return FrfEstimate(
        frequency_hz=frequency_hz, frf=g[:, :, None], frf_variance=var[:, :, None],
        output_noise_psd=(one_sided[:, None] * s2v / fs_hz)[:, :, None],
        input_psd=(one_sided * pu / fs_hz)[:, None], snr=snr[:, :, None],
        input_names=(str(input_name),), output_names=tuple(output_names), fs_hz=float(fs_hz),
        resolution_hz=float(fs_hz) / length, estimator="lpm",
        options={"degree": options.degree, "half_width": options.n, "stride": options.stride,
                 "transient": options.transient, "record_samples": int(length),
                 "noise_smoothing": options.noise_smoothing},
        dof=(fits.dof,),
        transient=fits.t[:, :, None] if options.transient else None,
        confidence=options.confidence)


#: The identification's half width of the noise variance's running median (7 estimated
#: lines, ~31 dof instead of 7: the weighted fits' stds were optimistic).
LPM_NOISE_SMOOTHING = 3
#: A line whose noise variance is this many times its neighbours' median keeps its own
#: (a mains line, a spur): the median would hide it.
_SPUR = 5.0


def _smoothed(s2v: NDArray[np.float64], half_width: int, dof: float
              ) -> tuple[NDArray[np.float64], float]:
    """Running median of each output's noise variance over ``2 w + 1`` lines (see
    :class:`LpmOptions`), scaled to a mean, and the dof it carries."""
    lines, outputs = s2v.shape
    width = 2 * half_width + 1
    # Median of chi2(2 dof)/(2 dof): (1 - 2/(9 * 2 dof))^3 of its mean (Wilson-Hilferty).
    to_mean = 1.0 / (1.0 - 2.0 / (9.0 * 2.0 * dof)) ** 3
    out = np.empty_like(s2v)
    if lines < width:
        return s2v, dof
    for j in range(outputs):
        padded = np.pad(s2v[:, j], half_width, mode="reflect")
        windows = np.lib.stride_tricks.sliding_window_view(padded, width)
        med = np.median(windows, axis=1) * to_mean
        out[:, j] = np.where(s2v[:, j] > _SPUR * med, s2v[:, j], med)
    return out, float(min(dof * width * 2.0 / np.pi, dof * lines))
