"""The 4QD amplifier from two kinds of record: the delays give its lag, the lines its order.

The 4QD amplifier (a low pass in front of the ADC) sits on every path to the
4QD. Two records see it in different ways:

* **its lag**: the Sercalo's effective delay on ``Uc → Vp`` less the pure delay
  of ``Uc → Vc`` (no 4QD there) and the coil's lag
  (:func:`fsmbench.ident.totals.qd_amplifier_lag_s`), with its std;
* **its shape**: the Newport's lines, up to 4 kHz, where a first order and a
  Butterworth of the same lag droop differently.

The Newport's lines alone confound it: an over-damped FSM-300 has a real pole
near 1.7 kHz, and an amplifier near 2 kHz trades bandwidth with the mirror's
natural frequency along a flat valley (an independent simulator's bench with a
first-order amplifier at 2 kHz: the lines "resolved" 1686 ± 184 Hz and put the
Newport at 1174 Hz for 1077). So the amplifier is decided by both:

1. the lag must be measured (above three of its std);
2. each order is fitted to the Newport's lines with the bandwidth that gives that
   lag; the order is determined when the other fits worse by more than
   :data:`~fsmbench.ident.delay.joint.RESOLVED_LR` noise units (summed over
   the axes);
3. determined: the amplifier is reported on its own (a finding on
   ``quad_diode.bandwidth_hz`` and ``bandwidth_order``), the Newport fitted with
   it, and the lag's std carried into the Newport's parameters as a random
   part, ``qd_amplifier_lag`` (refits at the lag ± its std, their rms shift);
4. not determined: no amplifier is claimed; the Newport is fitted with the order
   that fits better, and the other order's difference is a bounded part of its
   parameters.

Without a measured lag the lines' own conclusion stands only when it has no
lag to contradict (no Sercalo record): a lag measured as zero rejects a
bandwidth the Newport's lines resolved (their extra pole is the mirror's own,
named), and the fit without amplifier stands.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Final

from fsmbench.checks import Check, Finding
from fsmbench.ident.delay.joint import RESOLVED_LR, SensorEstimate
from fsmbench.ident.delay.sampled import SensorLowpass
from fsmbench.ident.frf.response import FrequencyResponse
from fsmbench.ident.newport import (
    NewportAxisFit,
    NewportDynamics,
    SensorShift,
    fit_newport_axis,
)

__all__ = ["AXIS_LAG_SIGMAS", "LAG_SIGMAS", "AmplifierDecision", "axis_lag_check",
           "decide_amplifier", "with_decided_sensor"]

#: A lag is measured when it is above this many of its standard deviations.
LAG_SIGMAS: Final = 3.0
#: Group delay per 1/ω_b of each order: 1 (first order), √2 (Butterworth).
_PER_RAD: Final = {1: 1.0, 2: math.sqrt(2.0)}
#: The Newport's parameters an undecided amplifier moves, its effective delay among them
#: (a first order and a Butterworth of one lag read 3.5 µs apart on the real-bench twin).
_SHIFTED: Final = ("gain_v_per_v", "natural_freq_hz", "damping_ratio", "effective_delay_s")
_ORDER_WORDS: Final = {1: "first-order", 2: "second-order (Butterworth)"}


@dataclass(frozen=True)
class AmplifierDecision:
    """What the records decide about the 4QD amplifier.

    Attributes
    ----------
    lag_s, lag_std_s : float
        The lag the delays measure and its std [s].
    sensor : SensorLowpass or None
        The amplifier the Newport is fitted with (None: the lines' own fit stands).
    resolved : bool
        Order and bandwidth determined: the amplifier is reported on its own.
    order_lr : float
        How much worse the other order fits, in noise units (0 when not compared).
    shifts : dict of axis to SensorShift
        The Newport parameters' parts: the lag's std (random, ``measured``), or the
        other order (a bound).
    words : str
        The decision in words, with the evidence.
    findings : tuple of Finding
        ``quad_diode.bandwidth_hz`` and ``bandwidth_order`` when resolved and the
        bench file states otherwise.
    """

    lag_s: float
    lag_std_s: float
    sensor: SensorLowpass | None
    resolved: bool
    order_lr: float = 0.0
    shifts: dict[str, SensorShift] = field(default_factory=dict)
    words: str = ""
    findings: tuple[Finding, ...] = ()


def _bandwidth(lag_s: float, order: int) -> float:
    return _PER_RAD[order] / (2.0 * math.pi * lag_s)


def _shift(a: NewportAxisFit, b: NewportAxisFit) -> dict[str, float]:
    return {k: float(getattr(a, k) - getattr(b, k)) for k in _SHIFTED}


def _cost(fits: dict[str, NewportAxisFit]) -> float:
    return sum(f.weighted_cost for f in fits.values())


def _unit(*fit_sets: dict[str, NewportAxisFit]) -> float:
    units = [f.noise_unit for fits in fit_sets for f in fits.values()
             if math.isfinite(f.noise_unit)]
    return min(units) if units else 1.0


def decide_amplifier(frf: FrequencyResponse, dyn: NewportDynamics, *, lag_s: float,
                     lag_std_s: float, model: SensorLowpass) -> AmplifierDecision:
    """Decide the 4QD amplifier from the delays' lag and the Newport's lines (module notes).

    Parameters
    ----------
    frf : FrequencyResponse
        The Newport's matrix ``dyn`` was fitted on.
    dyn : NewportDynamics
        The Newport fitted with the bench model's amplifier (its bandwidth free
        where the lines resolve one).
    lag_s, lag_std_s : float
        The amplifier's lag from the delays and its std [s] (NaN: not measured).
    model : SensorLowpass
        The bench file's amplifier (0: none).
    """
    if not (math.isfinite(lag_s) and math.isfinite(lag_std_s)):
        return AmplifierDecision(lag_s, lag_std_s, None, False)
    # The axes these lines give (an axis whose record is missing is the bench file's).
    fitted = [a for a in dyn.axes if f"Un{a}" in frf.input_names]
    if lag_s <= LAG_SIGMAS * lag_std_s:
        return _no_measured_lag(dyn, fitted, lag_s=lag_s, lag_std_s=lag_std_s, model=model)
    by_order = {o: {axis: fit_newport_axis(frf, axis, sensor=SensorLowpass(
        bandwidth_hz=_bandwidth(lag_s, o), order=o), resolve_sensor=False)
        for axis in fitted} for o in (1, 2)}
    unit = _unit(*by_order.values())
    cost = {o: _cost(f) for o, f in by_order.items()}
    best = min(cost, key=lambda o: cost[o])
    other = 3 - best
    lr = (cost[other] - cost[best]) / unit
    lag_words = (f"the delays measure a 4QD amplifier lag of {lag_s * 1e6:.3g} ± "
                 f"{lag_std_s * 1e6:.2g} µs (the Sercalo's effective delay less the pure one "
                 "of Uc → Vc and the coil's lag)")
    if lr <= RESOLVED_LR:
        return _undecided_order(by_order, fitted, best=best, lr=lr, lag_s=lag_s,
                                lag_std_s=lag_std_s, lag_words=lag_words)
    sensor = SensorLowpass(bandwidth_hz=_bandwidth(lag_s, best), order=best)
    shifts = _lag_std_shifts(frf, fitted, by_order[best], best=best, lag_s=lag_s,
                             lag_std_s=lag_std_s)
    bw = sensor.bandwidth_hz
    bw_std = bw * lag_std_s / lag_s
    findings = _amplifier_findings(model, best=best, bw=bw, bw_std=bw_std, lr=lr,
                                   lag_words=lag_words)
    return AmplifierDecision(
        lag_s, lag_std_s, sensor, True, lr, shifts,
        words=(f"{lag_words}; the Newport's lines choose a {_ORDER_WORDS[best]} low pass "
               f"(the other order fits {lr:.3g} noise units worse): the 4QD amplifier is a "
               f"{_ORDER_WORDS[best]} low pass at {bw:.4g} ± {bw_std:.2g} Hz, and the "
               "Newport's parameters carry the lag's std"),
        findings=tuple(findings))


def _no_measured_lag(dyn: NewportDynamics, fitted: list[str], *, lag_s: float,
                     lag_std_s: float, model: SensorLowpass) -> AmplifierDecision:
    """No lag above :data:`LAG_SIGMAS` of its std (``lag_s``, ``lag_std_s`` [s]): no
    amplifier, and a low pass the lines of the ``fitted`` axes claim is the Newport's own."""
    claimed = [fit for a in fitted if (fit := dyn.axes[a]).sensor is not None
               and fit.sensor.source == "fitted"]
    if not claimed:
        return AmplifierDecision(lag_s, lag_std_s, None, False)
    # The lines want a pole the delays do not show: the mirror's own, not the 4QD's.
    lines = "; ".join(f"{_ORDER_WORDS[a.sensor.order]} at {a.sensor.bandwidth_hz:.4g} Hz "
                      f"({a.axis})" for a in claimed if a.sensor is not None)
    return AmplifierDecision(
        lag_s, lag_std_s, model, False,
        words=(f"the Newport's lines fit better with another low pass ({lines}), but the "
               f"delays measure no 4QD amplifier lag ({lag_s * 1e6:+.3g} ± "
               f"{lag_std_s * 1e6:.2g} µs): that pole is the Newport's own, which its "
               "second-order model leaves out; no 4QD amplifier is reported, and the "
               "Newport is fitted without it"))


def _undecided_order(by_order: dict[int, dict[str, NewportAxisFit]], fitted: list[str], *,
                     best: int, lr: float, lag_s: float, lag_std_s: float,
                     lag_words: str) -> AmplifierDecision:
    """The lag measured (``lag_s``, ``lag_std_s`` [s]) but not the order: the Newport with
    the ``best`` order, the other's difference a bound (``lr`` noise units apart)."""
    other = 3 - best
    shifts = {a: SensorShift(axis=a, lag_s=lag_s,
                             half_width={k: abs(v) for k, v in _shift(
                                 by_order[other][a], by_order[best][a]).items()},
                             by_order={o: _shift(by_order[o][a], by_order[best][a])
                                       for o in (1, 2)})
              for a in fitted}
    return AmplifierDecision(
        lag_s, lag_std_s, SensorLowpass(bandwidth_hz=_bandwidth(lag_s, best), order=best),
        False, lr, shifts,
        words=(f"{lag_words}; the Newport's lines cannot tell its order (a "
               f"{_ORDER_WORDS[other]} low pass of that lag fits only {lr:.3g} noise units "
               f"worse, under {RESOLVED_LR:.3g}): no amplifier is reported on its own; the "
               "Newport is fitted with the better order and carries the other's difference "
               "as a bound; state the amplifier in the bench file to remove it"))


def _lag_std_shifts(frf: FrequencyResponse, fitted: list[str],
                    at_lag: dict[str, NewportAxisFit], *, best: int, lag_s: float,
                    lag_std_s: float) -> dict[str, SensorShift]:
    """The Newport's parameters moved by the lag's std: refits at ``lag_s ± lag_std_s``
    [s] (the ``best`` order), their rms shift from the fits at the lag (``at_lag``)."""
    lo, hi = lag_s - lag_std_s, lag_s + lag_std_s
    edges = {lag: {a: fit_newport_axis(frf, a, sensor=SensorLowpass(
        bandwidth_hz=_bandwidth(lag, best), order=best), resolve_sensor=False) for a in fitted}
        for lag in (lo, hi) if lag > 0}
    shifts = {}
    for a in fitted:
        moved = [_shift(e[a], at_lag[a]) for e in edges.values()]
        # The lag is measured on the Sercalo's records, with their noise: its std moves the
        # Newport's parameters at random from run to run. The two sigma points' rms shift is
        # that one-sigma part (a bound's uniform 1/sqrt(3) understated it: the Newport's
        # gains on the independent simulator's 5 kHz Butterworth bench, std(z) 1.17).
        shifts[a] = SensorShift(axis=a, lag_s=lag_s,
                                half_width={k: math.sqrt(sum(m[k] ** 2 for m in moved)
                                                         / len(moved)) if moved else 0.0
                                            for k in _SHIFTED},
                                by_order={best: moved[-1] if moved else dict.fromkeys(_SHIFTED,
                                                                                    0.0)},
                                measured=True)
    return shifts


def _amplifier_findings(model: SensorLowpass, *, best: int, bw: float, bw_std: float,
                        lr: float, lag_words: str) -> list[Finding]:
    """Findings on the bench file's amplifier (``model``) when the resolved one, the
    ``best`` order at ``bw`` ± ``bw_std`` [Hz], differs from it."""
    findings: list[Finding] = []
    if not (model.limited and model.order == best
            and abs(model.bandwidth_hz - bw) <= 2 * bw_std):
        other = 3 - best
        records = "data_uch.mat, data_ucv.mat, data_unh.mat, data_unv.mat"
        findings = [
            Finding("nominal.quad_diode.bandwidth_hz", model.bandwidth_hz, bw, "Hz", records,
                    f"the 4QD amplifier: {lag_words}, and the Newport's lines choose its "
                    f"order ({_ORDER_WORDS[other]} fits {lr:.3g} noise units worse): a "
                    f"{_ORDER_WORDS[best]} low pass at {bw:.4g} ± {bw_std:.2g} Hz", bw_std)]
        if not (model.limited and model.order == best):
            findings.append(Finding(
                "nominal.quad_diode.bandwidth_order", float(model.order), float(best), "1",
                records, f"the 4QD amplifier's order ({_ORDER_WORDS[best]})"))
    return findings


def with_decided_sensor(dyn: NewportDynamics, decision: AmplifierDecision, *,
                        axes: tuple[str, ...]) -> NewportDynamics:
    """The Newport refitted with a resolved decision's amplifier, each identified axis
    saying so: source ``"fitted"`` (the records decide it), the bandwidth's std from the
    lag's, and how much worse the other order fits. Unchanged when not resolved.

    Parameters
    ----------
    dyn : NewportDynamics
        The refit with ``decision.sensor`` held fixed.
    decision : AmplifierDecision
    axes : tuple of str
        The axes the records gave (an assumed axis keeps the bench file's label).
    """
    sensor = decision.sensor
    if not decision.resolved or sensor is None or decision.lag_s <= 0:
        return dyn
    bw_std = sensor.bandwidth_hz * decision.lag_std_s / decision.lag_s
    estimate = SensorEstimate(order=sensor.order, bandwidth_hz=sensor.bandwidth_hz,
                              source="fitted", bandwidth_std_hz=bw_std,
                              lower_bound_hz=math.nan, likelihood_ratio=decision.order_lr)
    return replace(dyn, axes={a: (replace(fit, sensor=estimate) if a in axes else fit)
                              for a, fit in dyn.axes.items()})


#: The two axes' 4QD lags (one amplifier feeds both outputs) agree within this many
#: standard deviations of their difference, or a quarter sample: two channels of one
#: amplifier differ by far less (the real-bench twin: 0.2 µs).
AXIS_LAG_SIGMAS: Final = 5.0


def axis_lag_check(lags: Mapping[str, tuple[float, float]], *, fs_hz: float) -> Check | None:
    """``qd_lag_across_axes``: each axis's 4QD lag (its Sercalo run's effective delay less
    its pure ``Uc → Vc`` delay and its coil's lag) against the other's.

    One amplifier feeds both 4QD outputs: lags apart by more than
    ``max(AXIS_LAG_SIGMAS σ, ¼ sample)`` mean one run's 4QD channels were delayed (a
    buffer, a time base), the run with the longer lag (a delay never advances a signal).
    None without both axes.

    Parameters
    ----------
    lags : mapping of axis to (lag [s], std [s])
    fs_hz : float
        The records' rate [Hz].
    """
    if set(lags) != {"h", "v"} or not all(math.isfinite(v) for pair in lags.values()
                                          for v in pair):
        return None
    (lh, sh), (lv, sv) = lags["h"], lags["v"]
    limit = max(AXIS_LAG_SIGMAS * math.hypot(sh, sv), 0.25 / fs_hz)
    diff = lh - lv
    later = "h" if diff > 0 else "v"
    record = f"data_uc{later}"
    subject = "data_uch.mat, data_ucv.mat: Vph, Vpv"
    words = f"{abs(diff) * 1e6:.3g} µs ({abs(diff) * fs_hz:.3g} samples)"
    if abs(diff) <= limit:
        return Check("qd_lag_across_axes", True, abs(diff), f"≤ {limit * 1e6:.3g} µs (one "
                     "amplifier feeds both outputs)", subject, unit="s")
    return Check(
        "qd_lag_across_axes", False, abs(diff), f"≤ {limit * 1e6:.3g} µs (one amplifier "
        "feeds both outputs)", subject,
        f"the 4QD output of {record}.mat lags the other axis's by {words} on the same "
        f"amplifier (h {lh * 1e6:.4g} µs, v {lv * 1e6:.4g} µs beyond each coil's path): "
        f"{record}'s 4QD channels were delayed (a buffer, a time base shifted when it was "
        f"saved), or its command Uc{later} was; either way its Sercalo path's delay is not "
        f"the bench's: record {record} again (no 4QD amplifier is inferred from it)",
        unit="s")
