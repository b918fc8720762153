"""The controller a closed-loop record ran, read from the record itself.

In a closed-loop record (huddle tests 3 and 5, ``data_rep_h/v``) the command
``Uch`` is computed from the 4QD reading ``Vph`` by the real-time controller and
nothing else: ``Uch = −K_h (Vph / g_used)`` sample by sample, with ``K_h`` the
ESRF study's controller of 9.2 (Tustin at the record's rate, errata E-K1) and
``g_used`` the 4QD gain the real-time code divided by [V/rad]. The relation
has no noise input (the controller is a program), so a least-squares fit of
``Uch`` on ``K_h Vph`` over the whole record gives ``1/g_used`` with its sign:

* the loop's sign and gain as they ran, which no bench file can give: a
  Sercalo mounted the other way ran with ``g_used`` of the other sign (the
  experimenter flipped the controller, or the loop would not have been
  stable); the validation and the budget simulate the recorded loop with it;
* a record whose command is zero throughout was not a closed loop (named, not
  compared with the open-loop huddle tests);
* a command the ESRF study's controller does not explain (under half of its
  variance) ran another controller.

The controller's initial state at the record's start is unknown: it adds a
polynomial of degree 2 (the double integrator; the other poles decay within
20 ms), fitted alongside and the first :data:`SETTLE_S` left out. A command
of less than a few converter steps is mostly the DAC's rounding: such a record
still gives the sign, with a gain biased by the rounding (5 % on the twin's
huddle tests, whose commands are 0.5 step rms), so records with a command of
at least :data:`MIN_STEPS` steps rms decide the gain when there are any.
"""

from __future__ import annotations

import functools
import weakref
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Final, Literal

import numpy as np
import scipy.signal
import xarray as xr

from fsmbench.bench.esrf import esrf_decentralised_zpk

__all__ = [
    "CLOSED_LOOP_EXPLAINED",
    "CLOSED_LOOP_RECORDS",
    "MIN_EXPLAINED",
    "MIN_STEPS",
    "ROUNDING_BIAS",
    "SETTLE_S",
    "ControllerFit",
    "RateWitness",
    "RecordedController",
    "closed_loop_in_open_run",
    "esrf_sos",
    "fit_record",
    "rate_witness",
    "recorded_controllers",
]

#: The study's records made with the loop closed (ESRF study 3.1 Table 3, 11.1).
CLOSED_LOOP_RECORDS: Final = ("data_huddle_test_3", "data_huddle_test_5", "data_rep_h",
                              "data_rep_v")
#: Seconds left out at a record's start: the other poles' transients (352.5, 491.2 rad/s
#: and faster: under e^-7 after 20 ms) and the recording's own start.
SETTLE_S: Final = 0.2
#: Share of the command's variance the ESRF study's controller must explain for the record
#: to have run it. Quantised to 0.5 step rms the twin's huddle tests are 0.65 explained;
#: a command a step or more rms is > 0.99; another controller or a command with an
#: excitation added is below.
MIN_EXPLAINED: Final = 0.5
#: Converter steps rms from which a record's command decides the gain (under it the
#: rounding biases the gain by several %).
MIN_STEPS: Final = 10.0
#: The gain's bias bound when only commands under :data:`MIN_STEPS` steps decide it
#: (relative): 5 % measured on the twin's huddle tests (0.5 step rms), doubled.
ROUNDING_BIAS: Final = 0.1
#: How many times less of a command another rate must leave unexplained than ``t``'s to
#: say ``t`` is wrong: on the twin the right rate leaves 4e-7, an octave off 9e-3.
RATE_PREFERENCE: Final = 10.0
#: Lags [samples] tried between the reading and the command (a real-time code that
#: writes its command a sample later).
_LAGS: Final = (0, 1, 2)

_AXES: Final = {"h": ("Uch", "Vph"), "v": ("Ucv", "Vpv")}
Verdict = Literal["seed", "zero", "other", "absent"]


@dataclass(frozen=True)
class ControllerFit:
    """One record's fit of its command on the ESRF study's controller.

    Attributes
    ----------
    record : str
    command_rms_v : float
        The command's rms about its mean [V].
    steps_rms : float
        The same in converter steps.
    gd_used_v_per_rad : float
        ``g_used``: the 4QD gain the loop divided by [V/rad], signed (nan for a zero command).
    gd_used_std_v_per_rad : float
        Its standard deviation from the fit's residual (taken as white: the rounding of a
        command many steps wide) [V/rad].
    explained : float
        Share of the command's variance the controller explains (0–1).
    lag_samples : int
        Samples between the reading and the command.
    """

    record: str
    command_rms_v: float
    steps_rms: float
    gd_used_v_per_rad: float
    gd_used_std_v_per_rad: float
    explained: float
    lag_samples: int

    @property
    def verdict(self) -> Verdict:
        """``zero`` (no command), ``seed`` (the controller explains it) or ``other``."""
        if not self.command_rms_v > 0:
            return "zero"
        return "seed" if self.explained >= MIN_EXPLAINED else "other"

    def to_json(self) -> dict[str, Any]:
        """Plain values."""
        return {"record": self.record, "command_rms_v": self.command_rms_v,
                "steps_rms": self.steps_rms, "gd_used_v_per_rad": self.gd_used_v_per_rad,
                "gd_used_std_v_per_rad": self.gd_used_std_v_per_rad,
                "explained": self.explained, "lag_samples": self.lag_samples,
                "verdict": self.verdict}


@dataclass(frozen=True)
class RecordedController:
    """What the closed-loop records say the loop of one axis ran.

    Attributes
    ----------
    axis : {"h", "v"}
    command, reading : str
        ``Uch``/``Vph`` or ``Ucv``/``Vpv``.
    fits : tuple of ControllerFit
        One per closed-loop record holding both signals.
    gd_used_v_per_rad : float
        The records' ``g_used`` [V/rad], signed: from those whose command is at
        least :data:`MIN_STEPS` steps rms when there are any, else from all that ran
        the controller (nan when none did).
    gd_used_std_v_per_rad : float
        Its scatter over those records (the rounding's bias when only sub-step
        commands decide) [V/rad].
    """

    axis: str
    command: str
    reading: str
    fits: tuple[ControllerFit, ...]
    gd_used_v_per_rad: float
    gd_used_std_v_per_rad: float

    @property
    def verdict(self) -> Verdict:
        """``seed`` when a record ran the ESRF study's controller, ``zero`` when every
        command was zero, ``other`` when none ran it, ``absent`` without records."""
        if not self.fits:
            return "absent"
        verdicts = {f.verdict for f in self.fits}
        if "seed" in verdicts:
            return "seed"
        return "zero" if verdicts == {"zero"} else "other"

    @property
    def sign(self) -> int:
        """The sign of ``g_used`` (0 when not judged)."""
        g = self.gd_used_v_per_rad
        return 0 if not np.isfinite(g) else (1 if g > 0 else -1)

    def records(self, verdict: Verdict) -> list[str]:
        """The records with that verdict."""
        return [f.record for f in self.fits if f.verdict == verdict]

    def words(self) -> str:
        """One line: what the records say of this axis's loop."""
        if self.verdict == "absent":
            return f"no closed-loop record holds {self.command} and {self.reading}"
        if self.verdict == "zero":
            return (f"{self.command} is zero throughout in {', '.join(self.records('zero'))}: "
                    "the loop was not closed")
        if self.verdict == "other":
            worst = max(self.fits, key=lambda f: f.command_rms_v)
            return (f"the ESRF study's controller explains {100 * worst.explained:.0f} % of "
                    f"{self.command} in {worst.record}: another controller ran")
        return (f"{self.command} = −K{self.axis}({self.reading} / {self.gd_used_v_per_rad:+.4g} "
                f"V/rad) in {', '.join(self.records('seed'))} (the ESRF study's controller "
                "of 9.2)")

    def to_json(self) -> dict[str, Any]:
        """Plain values."""
        return {"axis": self.axis, "command": self.command, "reading": self.reading,
                "verdict": self.verdict, "gd_used_v_per_rad": self.gd_used_v_per_rad,
                "gd_used_std_v_per_rad": self.gd_used_std_v_per_rad,
                "fits": [f.to_json() for f in self.fits], "words": self.words()}


def esrf_sos(axis: str, fs_hz: float) -> np.ndarray:
    """``K_axis`` by Tustin at ``fs_hz`` as second-order sections (per axis from its zpk: a
    state-space column of the 2×2 block would carry the other axis's poles as round-off)."""
    k = esrf_decentralised_zpk()[axis]
    z, p, g = scipy.signal.bilinear_zpk(np.asarray(k.zeros_rad_s), np.asarray(k.poles_rad_s),
                                        k.gain, fs_hz)
    sos: np.ndarray = scipy.signal.zpk2sos(z, p, g)
    return sos


def _fittable(ds: xr.Dataset, *, command: str, reading: str) -> bool:
    """The record has the command and the reading, of one length, every sample finite."""
    if command not in ds or reading not in ds:
        return False
    u = np.asarray(ds[command].values, dtype=np.float64)
    y = np.asarray(ds[reading].values, dtype=np.float64)
    return u.size == y.size and bool(np.all(np.isfinite(u)) and np.all(np.isfinite(y)))


@functools.lru_cache(maxsize=2)
def _polynomial_basis(n: int, fs_hz: float) -> np.ndarray:
    """Orthonormal ``[1, t, t^2]`` over ``n`` samples at ``fs_hz``, shape (n, 3), read-only.

    The same for every record of one length (the closed-loop records share theirs): its
    QR of a 1e6 x 3 matrix was half of a record's fit.
    """
    t = np.arange(n) / fs_hz
    t = t / max(float(t[-1]), 1.0 / fs_hz)  # scaled to [0, 1]: a well-conditioned polynomial
    poly = np.column_stack([np.ones_like(t), t, t * t])
    q, _ = np.linalg.qr(poly / np.linalg.norm(poly, axis=0))
    q.setflags(write=False)
    return q


# A record's fit by dataset identity: the rate's witness, the records' screening and the
# budget's huddle screen each fit the same closed-loop records (a second of the study's
# CPU). A dataset is never modified in place, and its entries go with it.
_FITTED: dict[tuple[Any, ...], ControllerFit] = {}


def _fit_key(ds: xr.Dataset, *, record: str, command: str, reading: str, axis: str,
             fs_hz: float, step_v: float) -> tuple[Any, ...]:
    return (id(ds), record, command, reading, axis, float(fs_hz), float(step_v))


def _keep_fit(ds: xr.Dataset, key: tuple[Any, ...], fit: ControllerFit) -> None:
    _FITTED[key] = fit
    weakref.finalize(ds, _FITTED.pop, key, None)


def _record_fit(ds: xr.Dataset, *, record: str, command: str, reading: str, axis: str,
                fs_hz: float, step_v: float) -> ControllerFit:
    """:func:`fit_record` of ``ds``'s ``command`` on its ``reading``, each fit once."""
    key = _fit_key(ds, record=record, command=command, reading=reading, axis=axis,
                   fs_hz=fs_hz, step_v=step_v)
    fit = _FITTED.get(key)
    if fit is None:
        fit = fit_record(record, np.asarray(ds[command].values, dtype=np.float64),
                         np.asarray(ds[reading].values, dtype=np.float64), axis=axis,
                         fs_hz=fs_hz, step_v=step_v)
        _keep_fit(ds, key, fit)
    return fit


def fit_record(record: str, u: np.ndarray, y: np.ndarray, *, axis: str, fs_hz: float,
               step_v: float) -> ControllerFit:
    k0 = round(SETTLE_S * fs_hz)
    uc = u[k0:]
    rms = float(np.std(uc)) if uc.size else 0.0
    if uc.size < 3 or not rms > 0:
        return ControllerFit(record, 0.0, 0.0, float("nan"), float("nan"), 0.0, 0)
    sos = esrf_sos(axis, fs_hz)
    # The polynomial is the same for every lag: projected out once (Frisch-Waugh-Lovell),
    # the controller's coefficient and the residual are those of the full least squares
    # on [K y, 1, t, t^2], at a third of its cost (a 1e6 x 4 lstsq per lag).
    q = _polynomial_basis(uc.size, fs_hz)
    u_perp = uc - q @ (q.T @ uc)
    var_u = float(np.var(uc))
    mean_y = float(np.mean(y))
    best: tuple[float, int, float, float] | None = None
    for lag in _LAGS:
        yl = np.concatenate([np.zeros(lag), y[:y.size - lag]]) - mean_y
        w = scipy.signal.sosfilt(sos, yl)[k0:]
        w_perp = w - q @ (q.T @ w)  # K y after the polynomial
        ww = float(w_perp @ w_perp)
        c = float(w_perp @ u_perp) / ww if ww > 0 else 0.0
        resid = u_perp - c * w_perp
        explained = 1.0 - float(np.var(resid)) / var_u
        if best is None or explained > best[0]:
            # The coefficient's std under a white residual: σ_r / |w| after the polynomial.
            c_std = float(np.std(resid)) / max(float(np.sqrt(ww)), 1e-300)
            best = (explained, lag, c, c_std)
    assert best is not None
    explained, lag, c, c_std = best
    # u = −(1/g_used) K y  →  the fitted coefficient c = −1/g_used, dg = dc / c².
    gd_used = -1.0 / c if c != 0 else float("inf")
    gd_std = c_std / (c * c) if c != 0 else float("inf")
    return ControllerFit(record, rms, rms / step_v, gd_used, gd_std, max(explained, 0.0), lag)


@dataclass(frozen=True)
class RateWitness:
    """The rate at which the ESRF study's controller explains a closed-loop record.

    Attributes
    ----------
    record, command : str
    labelled_fs_hz : float
        The rate the record's ``t`` gives [Hz].
    explained : dict of float to float
        Share of the command's variance explained with the controller discretised
        at each rate tried [Hz → 0–1].
    """

    record: str
    command: str
    labelled_fs_hz: float
    explained: dict[float, float]

    @property
    def fs_hz(self) -> float:
        """The rate that explains the command best [Hz]."""
        return max(self.explained, key=lambda f: self.explained[f])

    @property
    def contradicts(self) -> bool:
        """Another rate leaves :data:`RATE_PREFERENCE` times less of the command unexplained
        than ``t``'s (the command's slow part, the answer to the 1 Hz motion, is explained
        at any rate: the rate shows in what is left)."""
        left = {f: max(1.0 - e, 1e-12) for f, e in self.explained.items()}
        own = left.get(self.labelled_fs_hz, 1.0)
        return self.fs_hz != self.labelled_fs_hz and left[self.fs_hz] * RATE_PREFERENCE < own


def rate_witness(recordings: Mapping[str, xr.Dataset], *, fs_hz: float, step_v: float
                 ) -> RateWitness | None:
    """The controller's rate in the closed-loop record whose command is largest.

    The ESRF study's controller is continuous (9.2) and runs discretised at the
    converter's rate: its notches and lead sit at fixed frequencies in Hz, so the
    same samples read with ``t``'s step off by two put them an octave away and the
    controller no longer explains the command. The command must span at least
    :data:`MIN_STEPS` converter steps (a sub-step command is the DAC's rounding).
    None without such a record.
    """
    best: tuple[float, str, str, str] | None = None
    for name in CLOSED_LOOP_RECORDS:
        ds = recordings.get(name)
        if ds is None:
            continue
        for command, reading in _AXES.values():
            if command not in ds or reading not in ds:
                continue
            u = np.asarray(ds[command].values, dtype=np.float64)
            steps = float(np.std(u)) / step_v if u.size else 0.0
            if steps >= MIN_STEPS and (best is None or steps > best[0]):
                best = (steps, name, command, reading)
    if best is None:
        return None
    _, name, command, reading = best
    ds = recordings[name]
    explained = {}
    for fs in (fs_hz, 2.0 * fs_hz, 0.5 * fs_hz):
        fit = _record_fit(ds, record=name, command=command, reading=reading,
                          axis=command[-1], fs_hz=fs, step_v=step_v)
        explained[fs] = fit.explained
    return RateWitness(name, command, fs_hz, explained)


#: An open-loop noise run whose command the ESRF study's controller explains this well
#: was recorded with the loop closed: noise on Uch is not a function of Vph (a run with
#: the excitation on explains ~0), a closed loop's command is (0.65 at half a step, > 0.99
#: above a few steps).
CLOSED_LOOP_EXPLAINED: Final = 0.9


def closed_loop_in_open_run(ds: xr.Dataset, *, command: str, reading: str, fs_hz: float,
                            step_v: float) -> ControllerFit | None:
    """The fit of an open-loop run's command on the ESRF study's controller when it explains
    at least :data:`CLOSED_LOOP_EXPLAINED` of it (a closed-loop record saved under the
    open-loop run's name), else None."""
    if command not in ds or reading not in ds:
        return None
    u = np.asarray(ds[command].values, dtype=np.float64)
    y = np.asarray(ds[reading].values, dtype=np.float64)
    if u.size != y.size or u.size < round(2 * SETTLE_S * fs_hz):
        return None
    fit = fit_record(str(ds.attrs.get("experiment", "")), u, y, axis=command[-1],
                      fs_hz=fs_hz, step_v=step_v)
    return fit if fit.explained >= CLOSED_LOOP_EXPLAINED else None


def recorded_controllers(recordings: Mapping[str, xr.Dataset], *, fs_hz: float,
                         step_v: float) -> dict[str, RecordedController]:
    """The controller each axis's closed-loop records ran (see the module notes).

    Parameters
    ----------
    recordings : mapping of experiment name to Dataset
        The study's records; those of :data:`CLOSED_LOOP_RECORDS` present with
        the axis's command and reading are read (``t`` [s], signals [V]).
    fs_hz : float
        The records' sampling rate [Hz] (the controller is discretised at it).
    step_v : float
        One converter step [V] (20 V / 2^16 on the ESRF bench).

    Returns
    -------
    dict of axis to RecordedController
        ``"h"`` and ``"v"``, each with its verdict (``absent`` without records).
    """
    wanted = {axis: [(ds, name, command, reading, axis) for name in CLOSED_LOOP_RECORDS
                     if (ds := recordings.get(name)) is not None
                     and _fittable(ds, command=command, reading=reading)]
              for axis, (command, reading) in _AXES.items()}
    out: dict[str, RecordedController] = {}
    for axis, (command, reading) in _AXES.items():
        fits = [_record_fit(ds, record=name, command=command, reading=reading, axis=axis,
                            fs_hz=fs_hz, step_v=step_v) for ds, name, *_ in wanted[axis]]
        ran = [f for f in fits if f.verdict == "seed"]
        deciding = [f for f in ran if f.steps_rms >= MIN_STEPS] or ran
        if deciding:
            values = np.array([f.gd_used_v_per_rad for f in deciding])
            weights = np.array([f.steps_rms for f in deciding])
            gd = float(np.average(values, weights=weights))
            fitted = float(np.sqrt(np.sum((weights * [f.gd_used_std_v_per_rad
                                                      for f in deciding]) ** 2))
                           / np.sum(weights))
            spread = float(np.sqrt(np.average((values - gd) ** 2, weights=weights)))
            std = float(np.hypot(fitted, spread))
            if all(f.steps_rms < MIN_STEPS for f in deciding):
                # Only sub-step commands: the rounding's bias (5 % on the twin's 0.5-step
                # huddle commands), bounded at 10 %.
                std = max(std, ROUNDING_BIAS * abs(gd))
        else:
            gd, std = float("nan"), float("nan")
        out[axis] = RecordedController(axis, command, reading, tuple(fits), gd, std)
    return out
