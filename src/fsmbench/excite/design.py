"""Excitation signals for identification: multisines, band-limited noise, chirps.

A *multisine* is a sum of equal-amplitude cosines on the lines ``k/T`` of a
period ``T`` (``resolution_hz = 1/T``)::

    x[n] = a * sum_k cos(2 pi k n / N + phi_k),   N = fs T samples per period

so every line falls exactly on a DFT bin of one period and nothing leaks
between lines. The grid holds every line of the band (``full``), only odd
ones (``odd``: even lines stay free to show even nonlinear distortions) or
``odd-odd`` (lines 1, 5, 9, ...: the odd lines left out show odd
distortions), linearly or log-spaced (the grid lines nearest a geometric
sequence, without duplicates).

Phases are random (uniform, from the ESRF study), Schroeder's or the crest factor
minimised: Schroeder's phases as start, then the time-frequency swapping of
van der Ouderaa, Schoukens and Renneboog (1988: clip the peaks, keep the
phases the clipped signal has on the grid lines), then Guillaume's L_p
minimisation (1991) for increasing p (a smooth path to the L_inf norm, i.e.
the peak). The crest factor is ``max|x| / rms(x)`` over the samples played.
Lines on mains harmonics can be left out (``skip_mains``, :mod:`fsmbench.excite.mains`).

*Noise* is the ESRF study's: Gaussian, 4th-order Butterworth band-pass
(:class:`fsmbench.sim.excitation.ExcitationStream`), scaled to the rms asked.
*Chirps* sweep the band once per period, linearly or logarithmically.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy.optimize import minimize
from scipy.signal import chirp as scipy_chirp

from fsmbench.excite.mains import mains_hits
from fsmbench.sim.excitation import Excitation, ExcitationStream

__all__ = [
    "CHANNELS",
    "N_RANDOM_REFERENCE",
    "ChirpMethod",
    "ExcitationDesign",
    "GridKind",
    "PhaseMethod",
    "SignalKind",
    "chirp_signal",
    "crest_factor",
    "design_chirp",
    "design_multisine",
    "design_noise",
    "grid_lines",
    "lp_norm_and_gradient",
    "minimise_crest_factor",
    "multisine_period",
    "random_phase_crest_factor",
    "schroeder_phases",
]

SignalKind = Literal["multisine", "noise", "chirp"]
GridKind = Literal["full", "odd", "odd-odd"]
PhaseMethod = Literal["random", "schroeder", "minimised"]
ChirpMethod = Literal["linear", "log"]

#: DAC channels an excitation can be designed for (the seed's signal names).
CHANNELS = ("Uch", "Ucv", "Unh", "Unv")

# Random-phase draws whose median crest factor is the reference a design is compared with.
N_RANDOM_REFERENCE = 21


@dataclass(frozen=True, eq=False)
class ExcitationDesign:
    """One designed excitation: the samples a target plays and how they were made.

    Compared by identity (it holds arrays); the arrays are read-only.

    Attributes
    ----------
    input : str
        DAC channel, the ESRF study's signal name (``Uch``, ``Ucv``, ``Unh``, ``Unv``).
    kind : {"multisine", "noise", "chirp"}
    fs_hz : float
        Sampling rate of the samples [Hz].
    samples_v : ndarray, shape (n,)
        Everything played, transient periods first [V].
    period_samples : int
        Samples per period.
    periods : int
        Steady-state periods (after the transient ones).
    transient_periods : int
        Leading periods an FRF estimator should drop (0 or more).
    amplitude_rms_v : float
        Rms of one period [V].
    band_hz : (float, float)
        Band asked for [Hz].
    seed : int
        Seed of the random phases / the noise.
    crest_factor : float
        ``max|x| / rms`` of one period [1].
    lines_hz : ndarray, shape (L,)
        Multisine lines [Hz] (empty for noise and chirps).
    phases_rad : ndarray, shape (L,)
        Phase of each line [rad] (cosine phase at the period's first sample).
    line_amplitude_v : float
        Amplitude of every multisine line [V] (0 for noise and chirps).
    grid : {"full", "odd", "odd-odd"}
    log_grid : bool
    phase_method : {"random", "schroeder", "minimised"}
    crest_factor_random_phase : float or None
        Median crest factor of plain random-phase multisines on the same lines
        (:data:`N_RANDOM_REFERENCE` draws from the ESRF study) [1]; None for noise and chirps.
    chirp_method : {"linear", "log"} or None
    after_end : {"zero", "repeat"}
        What a player does after the last sample: stop (zero) or repeat the
        steady-state periods (multisines: the signal stays periodic).
    mains_hz : float
        Mains frequency whose harmonics the multisine's lines were checked
        against [Hz] (0: not checked; :mod:`fsmbench.excite.mains`).
    skipped_lines_hz : tuple of float
        Grid lines left out because they are on mains harmonics [Hz].
    """

    input: str
    kind: SignalKind
    fs_hz: float
    samples_v: np.ndarray
    period_samples: int
    periods: int
    transient_periods: int
    amplitude_rms_v: float
    band_hz: tuple[float, float]
    seed: int
    crest_factor: float
    lines_hz: np.ndarray
    phases_rad: np.ndarray
    line_amplitude_v: float = 0.0
    grid: GridKind = "full"
    log_grid: bool = False
    phase_method: PhaseMethod = "minimised"
    crest_factor_random_phase: float | None = None
    chirp_method: ChirpMethod | None = None
    after_end: Literal["zero", "repeat"] = "zero"
    mains_hz: float = 0.0
    skipped_lines_hz: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        # Arrays are stored read-only, so the design stays what was checked and written.
        for name in ("samples_v", "lines_hz", "phases_rad"):
            x = np.array(getattr(self, name), dtype=float)
            x.setflags(write=False)
            object.__setattr__(self, name, x)

    @property
    def period_s(self) -> float:
        """Length of one period [s]."""
        return self.period_samples / self.fs_hz

    @property
    def duration_s(self) -> float:
        """Length of everything played [s]."""
        return self.samples_v.size / self.fs_hz

    @property
    def transient_samples(self) -> int:
        """Samples of the leading transient periods."""
        return self.transient_periods * self.period_samples

    def one_period(self) -> np.ndarray:
        """The first steady-state period [V], shape (period_samples,)."""
        k0 = self.transient_samples
        return self.samples_v[k0:k0 + self.period_samples]


# ------------------------------------------------------------------ grid and phases


def _period_samples(*, resolution_hz: float, fs_hz: float) -> int:
    n = fs_hz / resolution_hz
    if not np.isfinite(n) or n < 4 or abs(n - round(n)) > 1e-9 * n:
        raise ValueError(f"a resolution of {resolution_hz:g} Hz needs a period of "
                         f"{n:g} samples at {fs_hz:g} Hz; choose one that divides the "
                         "sampling rate into a whole number of samples")
    return round(n)


def _allowed(k: np.ndarray, grid: GridKind) -> np.ndarray:
    if grid == "full":
        return np.ones(k.shape, dtype=bool)
    if grid == "odd":
        return k % 2 == 1
    if grid == "odd-odd":
        return k % 4 == 1
    raise ValueError(f"unknown grid {grid!r}; use full, odd or odd-odd")


def grid_lines(*, band_hz: tuple[float, float], resolution_hz: float, fs_hz: float,
               grid: GridKind = "full", log_grid: bool = False,
               lines_per_decade: float = 50.0) -> np.ndarray:
    """Harmonic numbers ``k`` of a multisine's lines (line ``k`` is at ``k * resolution_hz``).

    Parameters
    ----------
    band_hz : (float, float)
        Lowest and highest frequency [Hz], both included; only lines strictly
        between DC and Nyquist are kept.
    resolution_hz : float
        Line spacing of the full grid, ``1/period`` [Hz].
    fs_hz : float
        Sampling rate [Hz]; the period must be a whole number of samples.
    grid : {"full", "odd", "odd-odd"}
        Every line; odd ``k`` only; or ``k = 1, 5, 9, ...`` only.
    log_grid : bool
        Keep only the allowed lines nearest a geometric sequence over the
        band with ``lines_per_decade`` points per decade (duplicates dropped,
        so the low end, where the grid is coarser than the sequence, has fewer).
    lines_per_decade : float
        Density of the log sequence [1/decade].

    Returns
    -------
    ndarray of int, shape (L,), increasing.

    Raises
    ------
    ValueError
        A band that is not ``0 < low < high``, a period that is not a whole
        number of samples, or no line in the band.
    """
    lo, hi = (float(x) for x in band_hz)
    if not (np.isfinite(lo) and np.isfinite(hi) and 0 < lo < hi):
        raise ValueError(f"the band must be 0 < low < high [Hz], got {lo:g} to {hi:g} Hz")
    n = _period_samples(resolution_hz=resolution_hz, fs_hz=fs_hz)
    k_lo = max(1, int(np.ceil(lo / resolution_hz - 1e-9)))
    k_hi = min(int(np.floor(hi / resolution_hz + 1e-9)), (n - 1) // 2)
    k = np.arange(k_lo, k_hi + 1)
    k = k[_allowed(k, grid)]
    if k.size == 0:
        raise ValueError(f"no {grid} grid line between {lo:g} and {hi:g} Hz at a resolution of "
                         f"{resolution_hz:g} Hz below Nyquist ({fs_hz / 2:g} Hz)")
    if log_grid and k.size > 1:
        if not lines_per_decade > 0:
            raise ValueError(f"lines per decade must be > 0, got {lines_per_decade:g}")
        decades = np.log10(k[-1] / k[0])
        targets = np.geomspace(k[0], k[-1], max(2, int(np.ceil(decades * lines_per_decade)) + 1))
        # Nearest allowed line of each target (k is sorted): compare both neighbours.
        i = np.clip(np.searchsorted(k, targets), 1, k.size - 1)
        left, right = k[i - 1], k[i]
        k = np.unique(np.where(targets - left <= right - targets, left, right))
    return k.astype(int)


def schroeder_phases(n_lines: int) -> np.ndarray:
    """Schroeder's phases ``-pi i (i-1) / L`` for ``L`` equal lines [rad], shape (L,).

    (Schroeder 1970): low crest factor for consecutive harmonics, a good start
    for any grid.
    """
    i = np.arange(1, n_lines + 1, dtype=float)
    return np.mod(-np.pi * i * (i - 1) / n_lines, 2 * np.pi)


def multisine_period(*, harmonics: np.ndarray, phases_rad: np.ndarray, n_samples: int,
                     amplitude_v: float) -> np.ndarray:
    """One period ``a * sum_k cos(2 pi k n / N + phi_k)`` [V], shape (N,).

    Parameters
    ----------
    harmonics : ndarray of int, shape (L,)
        Line numbers ``k``, ``0 < k < N/2``.
    phases_rad : ndarray, shape (L,)
        Phases [rad].
    n_samples : int
        Samples per period ``N``.
    amplitude_v : float
        Amplitude ``a`` of every line [V].
    """
    spec = np.zeros(n_samples // 2 + 1, dtype=complex)
    # irfft(X)[n] = (1/N) (X0 + 2 Re sum X_k e^{j2pi kn/N}): X_k = N a/2 e^{j phi} gives a cos.
    spec[np.asarray(harmonics)] = 0.5 * n_samples * amplitude_v * np.exp(1j * phases_rad)
    return np.fft.irfft(spec, n=n_samples)


def crest_factor(x: np.ndarray) -> float:
    """``max|x| / rms(x)`` of a signal [1] (sqrt 2 for a sine)."""
    x = np.asarray(x, dtype=float)
    return float(np.max(np.abs(x)) / np.sqrt(np.mean(x * x)))


def random_phase_crest_factor(*, harmonics: np.ndarray, n_samples: int,
                              rng: np.random.Generator,
                              draws: int = N_RANDOM_REFERENCE) -> tuple[float, np.ndarray]:
    """Median crest factor of ``draws`` random-phase multisines, and the first draw's phases.

    Returns
    -------
    (float, ndarray of shape (L,))
        The median [1] and the phases of the first draw [rad].
    """
    factors = []
    first = np.zeros(0)
    for i in range(draws):
        phases = rng.uniform(0.0, 2.0 * np.pi, harmonics.size)
        if i == 0:
            first = phases
        factors.append(crest_factor(multisine_period(harmonics=harmonics, phases_rad=phases,
                                                     n_samples=n_samples, amplitude_v=1.0)))
    return float(np.median(factors)), first


def lp_norm_and_gradient(phases: np.ndarray, harmonics: np.ndarray, n_samples: int,
                          p: float) -> tuple[float, np.ndarray]:
    """``(mean |u|^p)^(1/p)`` of the unit-rms multisine ``u`` and its gradient on the phases."""
    a = np.sqrt(2.0 / harmonics.size)  # unit rms
    u = multisine_period(harmonics=harmonics, phases_rad=phases, n_samples=n_samples,
                         amplitude_v=a)
    au = np.abs(u)
    m = np.mean(au**p)
    norm = m ** (1.0 / p)
    # d norm / d phi_k = norm^(1-p) / N * sum_n |u|^(p-1) sgn(u) (-a sin(2 pi k n/N + phi_k))
    #                  = -norm^(1-p) / N * a * Im(e^{j phi_k} conj(G_k)),
    # with G = rfft(|u|^(p-1) sgn u).
    g = np.fft.rfft(au ** (p - 1.0) * np.sign(u))[harmonics]
    grad = -(norm ** (1.0 - p)) / n_samples * a * np.imag(np.exp(1j * phases) * np.conj(g))
    return float(norm), grad


def minimise_crest_factor(*, harmonics: np.ndarray, n_samples: int,
                          start_rad: np.ndarray | None = None, clip_iterations: int = 300,
                          p_values: tuple[float, ...] = (4.0, 8.0, 16.0, 32.0, 64.0, 128.0),
                          lp_iterations: int = 200) -> np.ndarray:
    """Phases of a low-crest-factor multisine on ``harmonics`` [rad], shape (L,).

    Deterministic: Schroeder's phases (or ``start_rad``), then
    ``clip_iterations`` of clipping and phase swapping with a clipping level
    that tightens from 10 % to 1 % below the current peak, then L-BFGS on the
    L_p norm for each ``p`` in turn. The phases of the lowest crest factor
    met on the way are returned.

    Parameters
    ----------
    harmonics : ndarray of int, shape (L,)
        Line numbers, ``0 < k < n_samples/2``.
    n_samples : int
        Samples per period.
    start_rad : ndarray, shape (L,), optional
        Starting phases [rad] (default Schroeder's).
    clip_iterations : int
        Time-frequency swapping iterations.
    p_values : tuple of float
        Norms minimised in turn.
    lp_iterations : int
        L-BFGS iterations per norm.
    """
    harmonics = np.asarray(harmonics, dtype=int)
    phases = schroeder_phases(harmonics.size) if start_rad is None else np.array(start_rad)
    if harmonics.size < 2:
        return np.mod(phases, 2 * np.pi)

    def cf(ph: np.ndarray) -> float:
        return crest_factor(multisine_period(harmonics=harmonics, phases_rad=ph,
                                             n_samples=n_samples, amplitude_v=1.0))

    best, best_cf = phases.copy(), cf(phases)
    for step in np.geomspace(0.1, 0.01, clip_iterations):
        x = multisine_period(harmonics=harmonics, phases_rad=phases, n_samples=n_samples,
                             amplitude_v=1.0)
        level = (1.0 - step) * np.max(np.abs(x))
        phases = np.angle(np.fft.rfft(np.clip(x, -level, level))[harmonics])
        c = cf(phases)
        if c < best_cf:
            best, best_cf = phases.copy(), c
    phases = best.copy()
    for p in p_values:
        res = minimize(lp_norm_and_gradient, phases, args=(harmonics, n_samples, p), jac=True,
                       method="L-BFGS-B", options={"maxiter": lp_iterations})
        phases = np.asarray(res.x)
        c = cf(phases)
        if c < best_cf:
            best, best_cf = phases.copy(), c
    return np.mod(best, 2 * np.pi)


# ------------------------------------------------------------------ designs


def _check_common(*, input: str, amplitude_rms_v: float, periods: int,
                  transient_periods: int) -> None:
    if input not in CHANNELS:
        raise ValueError(f"unknown input {input!r}; the bench's DAC channels are "
                         f"{', '.join(CHANNELS)}")
    if not (np.isfinite(amplitude_rms_v) and amplitude_rms_v > 0):
        raise ValueError(f"the rms amplitude must be a positive number of volts, got "
                         f"{amplitude_rms_v!r}")
    if periods < 1 or transient_periods < 0:
        raise ValueError(f"need at least 1 period and no negative transient periods, got "
                         f"{periods} and {transient_periods}")


def design_multisine(*, input: str, band_hz: tuple[float, float], resolution_hz: float,
                     amplitude_rms_v: float, fs_hz: float, seed: int = 0, periods: int = 1,
                     transient_periods: int = 0, grid: GridKind = "full",
                     log_grid: bool = False, lines_per_decade: float = 50.0,
                     phase_method: PhaseMethod = "minimised", mains_hz: float = 0.0,
                     skip_mains: bool = False) -> ExcitationDesign:
    """A periodic multisine of equal lines, rms ``amplitude_rms_v``.

    Parameters
    ----------
    input : str
        DAC channel (``Uch``, ``Ucv``, ``Unh``, ``Unv``).
    band_hz : (float, float)
        Band [Hz] (see :func:`grid_lines`).
    resolution_hz : float
        ``1/period`` [Hz]; ``fs_hz / resolution_hz`` must be a whole number.
    amplitude_rms_v : float
        Rms of the signal [V].
    fs_hz : float
        Sampling rate of the target [Hz].
    seed : int
        Seed of the random phases (``random``) and of the random-phase reference.
    periods, transient_periods : int
        Steady-state periods, then how many more are played first for the
        system to settle (an FRF estimator drops them).
    grid, log_grid, lines_per_decade
        See :func:`grid_lines`.
    phase_method : {"random", "schroeder", "minimised"}
        Phases: random (uniform), Schroeder's, or the crest factor minimised
        (:func:`minimise_crest_factor`).
    mains_hz : float
        Mains frequency [Hz] whose harmonics the lines are checked against
        (:func:`fsmbench.excite.mains.mains_hits`; 0: none).
    skip_mains : bool
        Leave the lines on mains harmonics out of the grid (they stay
        non-excited; the phases are optimised on the lines left).
    """
    _check_common(input=input, amplitude_rms_v=amplitude_rms_v, periods=periods,
                  transient_periods=transient_periods)
    if not float(band_hz[1]) < fs_hz / 2:
        # Refused, not clipped: the description would name a band with no line in its top.
        raise ValueError(f"the multisine band must end below Nyquist ({fs_hz / 2:g} Hz), got "
                         f"{float(band_hz[0]):g} to {float(band_hz[1]):g} Hz")
    n = _period_samples(resolution_hz=resolution_hz, fs_hz=fs_hz)
    k = grid_lines(band_hz=band_hz, resolution_hz=resolution_hz, fs_hz=fs_hz, grid=grid,
                   log_grid=log_grid, lines_per_decade=lines_per_decade)
    if not (np.isfinite(mains_hz) and mains_hz >= 0):
        raise ValueError(f"the mains frequency must be 0 or positive [Hz], got {mains_hz!r}")
    skipped: tuple[float, ...] = ()
    if skip_mains and mains_hz > 0:
        hit = mains_hits(k * (fs_hz / n), resolution_hz=fs_hz / n, mains_hz=mains_hz)
        skipped = tuple(float(f) for f in k[hit] * (fs_hz / n))
        k = k[~hit]
        if k.size == 0:
            raise ValueError(f"every line between {band_hz[0]:g} and {band_hz[1]:g} Hz is on a "
                             f"harmonic of the {mains_hz:g} Hz mains; nothing left to excite")
    rng = np.random.default_rng(seed)
    cf_random, random_phases = random_phase_crest_factor(harmonics=k, n_samples=n, rng=rng)
    if phase_method == "random":
        phases = random_phases
    elif phase_method == "schroeder":
        phases = schroeder_phases(k.size)
    elif phase_method == "minimised":
        phases = minimise_crest_factor(harmonics=k, n_samples=n)
    else:
        raise ValueError(f"unknown phase method {phase_method!r}; use random, schroeder or "
                         "minimised")
    a = amplitude_rms_v * np.sqrt(2.0 / k.size)  # rms of L equal lines: a sqrt(L/2)
    one = multisine_period(harmonics=k, phases_rad=phases, n_samples=n, amplitude_v=a)
    return ExcitationDesign(
        input=input, kind="multisine", fs_hz=float(fs_hz),
        samples_v=np.tile(one, periods + transient_periods), period_samples=n, periods=periods,
        transient_periods=transient_periods, amplitude_rms_v=float(amplitude_rms_v),
        band_hz=(float(band_hz[0]), float(band_hz[1])), seed=int(seed),
        crest_factor=crest_factor(one), lines_hz=k * (fs_hz / n), phases_rad=phases,
        line_amplitude_v=float(a), grid=grid, log_grid=log_grid, phase_method=phase_method,
        crest_factor_random_phase=cf_random, after_end="repeat", mains_hz=float(mains_hz),
        skipped_lines_hz=skipped)


def _record_samples(duration_s: float, fs_hz: float) -> int:
    n = round(duration_s * fs_hz)
    if not np.isfinite(duration_s) or n < 4:
        raise ValueError(f"a duration of {duration_s:g} s is fewer than 4 samples at "
                         f"{fs_hz:g} Hz")
    return n


def _periodic(*, input: str, kind: SignalKind, one: np.ndarray, fs_hz: float,
              amplitude_rms_v: float, band_hz: tuple[float, float], seed: int, periods: int,
              transient_periods: int,
              chirp_method: ChirpMethod | None = None) -> ExcitationDesign:
    one = one * (amplitude_rms_v / np.sqrt(np.mean(one * one)))  # the rms asked, exactly
    return ExcitationDesign(
        input=input, kind=kind, fs_hz=float(fs_hz),
        samples_v=np.tile(one, periods + transient_periods), period_samples=one.size,
        periods=periods, transient_periods=transient_periods,
        amplitude_rms_v=float(amplitude_rms_v), band_hz=(float(band_hz[0]), float(band_hz[1])),
        seed=int(seed), crest_factor=crest_factor(one), lines_hz=np.zeros(0),
        phases_rad=np.zeros(0), chirp_method=chirp_method, after_end="zero")


def design_noise(*, input: str, band_hz: tuple[float, float], amplitude_rms_v: float,
                 fs_hz: float, duration_s: float, seed: int = 0, periods: int = 1,
                 transient_periods: int = 0) -> ExcitationDesign:
    """Band-limited Gaussian noise as the ESRF study injects it, ``duration_s`` per period.

    The twin's own noise excitation (:class:`~fsmbench.sim.excitation.ExcitationStream`,
    4th-order Butterworth band-pass of white Gaussian noise from
    ``numpy.random.default_rng(ESRF study)``), scaled so that one period's rms is
    ``amplitude_rms_v`` exactly [V]. ``periods > 1`` repeats the same record
    (periodic noise).
    """
    _check_common(input=input, amplitude_rms_v=amplitude_rms_v, periods=periods,
                  transient_periods=transient_periods)
    lo, hi = (float(x) for x in band_hz)
    if not (np.isfinite(lo) and np.isfinite(hi) and 0 < lo < hi < fs_hz / 2):
        raise ValueError(f"the noise band must be 0 < low < high < Nyquist ({fs_hz / 2:g} Hz), "
                         f"got {lo:g} to {hi:g} Hz")
    n = _record_samples(duration_s, fs_hz)
    stream = ExcitationStream(Excitation(input, "noise", amplitude_rms_v, 0.0,
                                         band_hz=(lo, hi)),
                              fs_hz=fs_hz, rng=np.random.default_rng(seed))
    return _periodic(input=input, kind="noise", one=stream.next(0, n), fs_hz=fs_hz,
                     amplitude_rms_v=amplitude_rms_v, band_hz=(lo, hi), seed=seed,
                     periods=periods, transient_periods=transient_periods)


def chirp_signal(*, band_hz: tuple[float, float], fs_hz: float, n_samples: int,
                 method: ChirpMethod = "linear") -> np.ndarray:
    """Unit-amplitude sine sweep from ``band_hz[0]`` to ``band_hz[1]`` over ``n_samples``.

    Instantaneous frequency ``f0 + (f1 - f0) t / T`` (linear) or
    ``f0 (f1/f0)^(t/T)`` (log) [Hz], ``T = n_samples / fs_hz``; starts at phase 0 of a sine.
    """
    t = np.arange(n_samples) / fs_hz
    span = n_samples / fs_hz
    return np.asarray(scipy_chirp(t, f0=band_hz[0], t1=span, f1=band_hz[1],
                                  method="linear" if method == "linear" else "logarithmic",
                                  phi=-90.0))


def design_chirp(*, input: str, band_hz: tuple[float, float], amplitude_rms_v: float,
                 fs_hz: float, duration_s: float, method: ChirpMethod = "linear",
                 periods: int = 1, transient_periods: int = 0,
                 seed: int = 0) -> ExcitationDesign:
    """A swept sine over the band, ``duration_s`` per sweep, rms ``amplitude_rms_v`` [V].

    ``seed`` is recorded only (a chirp has nothing random).
    """
    _check_common(input=input, amplitude_rms_v=amplitude_rms_v, periods=periods,
                  transient_periods=transient_periods)
    lo, hi = (float(x) for x in band_hz)
    if not (np.isfinite(lo) and np.isfinite(hi) and 0 < lo < hi < fs_hz / 2):
        raise ValueError(f"the chirp band must be 0 < low < high < Nyquist ({fs_hz / 2:g} Hz), "
                         f"got {lo:g} to {hi:g} Hz")
    if method not in ("linear", "log"):
        raise ValueError(f"unknown chirp sweep {method!r}; use linear or log")
    n = _record_samples(duration_s, fs_hz)
    one = chirp_signal(band_hz=(lo, hi), fs_hz=fs_hz, n_samples=n, method=method)
    return _periodic(input=input, kind="chirp", one=one, fs_hz=fs_hz,
                     amplitude_rms_v=amplitude_rms_v, band_hz=(lo, hi), seed=seed,
                     periods=periods, transient_periods=transient_periods, chirp_method=method)
