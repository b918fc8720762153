"""A synthetic figure set shaped like fsmbench's HTML report, for plotting-library benchmarks.

The set is library-neutral (frozen dataclasses of float32 arrays), so every plotting
library draws exactly the same numbers: 18 Bode figures, 20 time-series figures,
15 spectrum figures and 4 bar/Nyquist figures (57 in all). Seeded, so every run and
every library sees identical data.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Figure", "Panel", "Trace", "make_figure_set"]

N_BODE_FIGS, N_TIME_FIGS, N_SPEC_FIGS, N_OTHER_FIGS = 18, 20, 15, 4
N_FREQ = 5000            # points per Bode / spectrum trace
N_RECORD = 1_000_000     # samples of the record behind each time-series trace
N_ENVELOPE_BINS = 2000   # min/max bins -> 2 * 2000 = 4000 drawn points per trace
FS_HZ = 10_000.0         # sample rate of the synthetic records


@dataclass(frozen=True)
class Trace:
    """One drawn trace.

    Parameters
    ----------
    name : str
        Legend entry.
    x, y : numpy.ndarray
        Abscissa and ordinate, float32, shape (n,), units of the panel's axes.
    kind : str
        ``"line"`` or ``"bar"``.
    """

    name: str
    x: np.ndarray
    y: np.ndarray
    kind: str = "line"


@dataclass(frozen=True)
class Panel:
    """One axes box of a figure (panels of a figure are stacked and share x)."""

    ylabel: str
    traces: tuple[Trace, ...]
    ylog: bool = False


@dataclass(frozen=True)
class Figure:
    """One report figure: stacked panels sharing one x axis.

    ``height_px`` is the height the report gives the whole figure [px].
    """

    title: str
    xlabel: str
    xlog: bool
    panels: tuple[Panel, ...]
    height_px: int

    @property
    def n_points(self) -> int:
        """Number of (x, y) points drawn in the figure."""
        return sum(t.x.size for p in self.panels for t in p.traces)


def _f32(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float32)


def _bode(rng: np.random.Generator, i: int) -> Figure:
    f_hz = np.logspace(0, 4, N_FREQ)
    s = 2j * np.pi * f_hz
    mags, phases = [], []
    for k in range(4):
        f0 = rng.uniform(80, 900)
        zeta = rng.uniform(0.02, 0.3)
        delay_s = rng.uniform(20e-6, 120e-6)
        w0 = 2 * np.pi * f0
        h = w0**2 / (s**2 + 2 * zeta * w0 * s + w0**2) * np.exp(-s * delay_s)
        # measured FRFs are noisy: 2 % multiplicative complex noise
        h = h * (1 + 0.02 * (rng.standard_normal(N_FREQ) + 1j * rng.standard_normal(N_FREQ)))
        name = f"axis {k + 1}"
        mags.append(Trace(name, _f32(f_hz), _f32(np.abs(h))))
        phases.append(Trace(name, _f32(f_hz), _f32(np.degrees(np.unwrap(np.angle(h))))))
    return Figure(f"Bode plot {i + 1}", "frequency [Hz]", True,
                  (Panel("magnitude [-]", tuple(mags), ylog=True),
                   Panel("phase [deg]", tuple(phases))), 520)


def _envelope(record: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Min/max envelope, interleaved: (t [s], value), each shape (2 * N_ENVELOPE_BINS,)."""
    bins = record.reshape(N_ENVELOPE_BINS, -1)
    y = np.empty(2 * N_ENVELOPE_BINS, dtype=np.float32)
    y[0::2], y[1::2] = bins.min(axis=1), bins.max(axis=1)
    t_bin_s = np.arange(N_ENVELOPE_BINS) * (bins.shape[1] / FS_HZ)
    return _f32(np.repeat(t_bin_s, 2)), y


def _time(rng: np.random.Generator, i: int) -> Figure:
    t_s = np.arange(N_RECORD, dtype=np.float32) / np.float32(FS_HZ)
    panels = []
    for p in range(4):
        traces = []
        for k in range(2):
            f_hz = np.float32(rng.uniform(0.05, 2.0))
            record = (np.sin(np.float32(2 * np.pi) * f_hz * t_s)
                      + np.float32(0.1) * rng.standard_normal(N_RECORD, dtype=np.float32))
            traces.append(Trace(("command", "response")[k], *_envelope(record)))
        panels.append(Panel(f"channel {p + 1} [V]", tuple(traces)))
    return Figure(f"Time record {i + 1}", "time [s]", False, tuple(panels), 720)


def _spectrum(rng: np.random.Generator, i: int) -> Figure:
    f_hz = np.logspace(-1, np.log10(5000.0), N_FREQ)
    df_hz = np.gradient(f_hz)
    asds, cums = [], []
    for k in range(5):
        floor = 10 ** rng.uniform(-7, -5)
        asd = floor * np.sqrt(1 + (rng.uniform(1, 20) / f_hz) ** 2)
        for f_peak in rng.uniform(10, 2000, size=3):
            asd += 20 * floor / (1 + ((f_hz - f_peak) / (0.01 * f_peak)) ** 2)
        # Welch estimate with ~16 averages: chi-square scatter of about 25 %
        asd *= np.sqrt(rng.chisquare(32, N_FREQ) / 32)
        name = f"sensor {k + 1}"
        asds.append(Trace(name, _f32(f_hz), _f32(asd)))
        cums.append(Trace(name, _f32(f_hz), _f32(np.sqrt(np.cumsum(asd**2 * df_hz)))))
    return Figure(f"Noise spectrum {i + 1}", "frequency [Hz]", True,
                  (Panel("ASD [V/√Hz]", tuple(asds), ylog=True),
                   Panel("cumulative rms [V]", tuple(cums), ylog=True)), 520)


def _other(rng: np.random.Generator, i: int) -> Figure:
    if i % 2 == 0:
        x = _f32(np.arange(300))
        bars = (Trace("budget share", x, _f32(rng.exponential(1.0, 300)), kind="bar"),)
        return Figure(f"Error budget {i + 1}", "contributor index [-]", False,
                      (Panel("rms contribution [µrad]", bars),), 420)
    f_hz = np.logspace(0, 3.5, 300)
    s = 2j * np.pi * f_hz
    traces = []
    for k in range(4):
        w0 = 2 * np.pi * rng.uniform(50, 300)
        loop = 3 * w0**2 / (s * (s + 0.5 * w0)) * np.exp(-s * rng.uniform(1e-4, 4e-4))
        traces.append(Trace(f"loop {k + 1}", _f32(loop.real), _f32(loop.imag)))
    return Figure(f"Nyquist plot {i + 1}", "real part [-]", False,
                  (Panel("imaginary part [-]", tuple(traces)),), 520)


def make_figure_set(*, seed: int = 0) -> tuple[Figure, ...]:
    """The 57-figure synthetic report, in report order (figures of one kind interleaved).

    Parameters
    ----------
    seed : int
        Seed of the numpy generator; the same seed gives bit-identical arrays.
    """
    rng = np.random.default_rng(seed)
    kinds = ([(_bode, i) for i in range(N_BODE_FIGS)] + [(_time, i) for i in range(N_TIME_FIGS)]
             + [(_spectrum, i) for i in range(N_SPEC_FIGS)]
             + [(_other, i) for i in range(N_OTHER_FIGS)])
    figs = [make(rng, i) for make, i in kinds]
    # report order: sections interleaved like the study report (Bode, time, spectrum ...)
    order = sorted(range(len(figs)), key=lambda j: (kinds[j][1], j))
    return tuple(figs[j] for j in order)
