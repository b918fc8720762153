"""The records' sampling rate, against each other first and the bench file second.

Each record's rate comes from its own ``t`` (the loader's ``fs_hz``). The
records of one session share the converter's clock: the rate most of them
have is the bench's. A record at another rate contradicts them (a failed
``sampling_rate`` check naming it and both rates); a bench file that states
another rate is a finding (``nominal.converter.fs_hz``), and the
identification works at the records' rate. A bench file's rate is never used
to call correct ``t`` wrong.

``t`` itself can be wrong while the records agree (every file saved with the
step of another rate): the physics the records carry says so. The
closed-loop records ran the ESRF study's controller discretised at the
converter's real rate; when that controller explains their commands at twice
or half the rate ``t`` gives and not at ``t``'s own
(:func:`~fsmbench.ident.evidence.recorded_loop.rate_witness`), ``t`` is off
by that factor and the check names it.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Final

import xarray as xr

from fsmbench.bench.params import BenchParams
from fsmbench.checks import Check, Finding
from fsmbench.ident.current_amp import identify_current_amplifier
from fsmbench.ident.evidence.recorded_loop import RateWitness

__all__ = ["AMPLIFIER_RATE_PREFERENCE", "RATE_TOLERANCE", "RateEvidence",
           "controller_rate_check", "current_amplifier_rate_check", "records_rate"]

#: Two rates within this relative difference are one clock (a real-time target's rate
#: is set to a few ppm; 1 % is the loader's tolerance on a rate from ``t``).
RATE_TOLERANCE: Final = 0.01


@dataclass(frozen=True)
class RateEvidence:
    """What the records say of the sampling rate.

    Attributes
    ----------
    fs_hz : float
        The rate most records share (the bench's) [Hz]; the bench file's when no
        record gives one.
    bench_fs_hz : float
        The bench file's ``converter.fs_hz`` [Hz].
    by_record : dict of str to float
        Each record's own rate [Hz].
    checks : tuple of Check
        ``sampling_rate``, failed, for each record at another rate than the others.
    by_experiment : dict of str to tuple of Check
        The failed check each odd record answers for.
    findings : tuple of Finding
        ``nominal.converter.fs_hz`` when the records' rate is not the bench file's.
    """

    fs_hz: float
    bench_fs_hz: float
    by_record: dict[str, float] = field(default_factory=dict)
    checks: tuple[Check, ...] = ()
    by_experiment: dict[str, tuple[Check, ...]] = field(default_factory=dict)
    findings: tuple[Finding, ...] = ()


def _same(a: float, b: float) -> bool:
    return abs(a / b - 1.0) <= RATE_TOLERANCE


def records_rate(recordings: Mapping[str, xr.Dataset], *, bench_fs_hz: float) -> RateEvidence:
    """The records' common rate, the records at another one, and the bench file's departure.

    Parameters
    ----------
    recordings : mapping of experiment name to Dataset
        Each with its ``fs_hz`` attribute (the rate its ``t`` gives) [Hz].
    bench_fs_hz : float
        The bench file's converter rate [Hz].
    """
    rates = {name: float(ds.attrs["fs_hz"]) for name, ds in recordings.items()
             if float(ds.attrs.get("fs_hz", 0.0)) > 0}
    if not rates:
        return RateEvidence(bench_fs_hz, bench_fs_hz)
    groups: list[list[str]] = []
    for name, fs in rates.items():
        for g in groups:
            if _same(rates[g[0]], fs):
                g.append(name)
                break
        else:
            groups.append([name])
    # The most records; on a tie, the bench file's rate if one of them has it.
    groups.sort(key=lambda g: (len(g), _same(rates[g[0]], bench_fs_hz)), reverse=True)
    main = groups[0]
    fs = sorted(rates[n] for n in main)[len(main) // 2]
    checks: list[Check] = []
    by_experiment: dict[str, tuple[Check, ...]] = {}
    for g in groups[1:]:
        for name in g:
            check = Check(
                "sampling_rate", False, rates[name],
                f"within {100 * RATE_TOLERANCE:g} % of the other records' {fs:g} Hz",
                f"{name}.mat: t",
                f"t steps at {rates[name]:g} Hz where {len(main)} other record"
                f"{'s' if len(main) > 1 else ''} ({', '.join(sorted(main)[:3])}"
                f"{' …' if len(main) > 3 else ''}) step at {fs:g} Hz: either this record was "
                "made at another rate, or its t was saved with another step; the records "
                "cannot tell which: check how it was recorded and saved", unit="Hz")
            checks.append(check)
            by_experiment[name] = (check,)
    findings: tuple[Finding, ...] = ()
    if not _same(fs, bench_fs_hz):
        findings = (Finding(
            "nominal.converter.fs_hz", bench_fs_hz, fs, "Hz",
            ", ".join(f"{n}.mat" for n in sorted(main)),
            f"the recordings are sampled at {fs:g} Hz (their t's step), not at the bench "
            "file's rate; the identification works at the records' rate"),)
    return RateEvidence(fs, bench_fs_hz, rates, tuple(checks), by_experiment, findings)


#: How many times the coil path's reduced chi-square at ``t``'s rate must exceed another
#: rate's to say ``t`` is wrong: on the twin the right rate gives 0.84, an octave off
#: 4.4e3 and 1.9e4.
AMPLIFIER_RATE_PREFERENCE: Final = 10.0


def current_amplifier_rate_check(recordings: Mapping[str, xr.Dataset], *,
                                 params: BenchParams, trim_s: float = 1.0) -> Check | None:
    """``rate_vs_current_amplifier``: the rate at which the coil path ``Uc → Vc`` fits.

    The path's analog corners are fixed in Hz (the coil's ``R/L``, the monitor's
    cut-off); read with ``t``'s step off by two, its lines sit an octave away and the
    fit's reduced chi-square grows by thousands. The run fitting best at another rate
    than ``t``'s, by :data:`AMPLIFIER_RATE_PREFERENCE`, names ``t`` as wrong; without a
    Sercalo run, or when a fit fails, None.
    """

    ds = recordings.get("data_uch")
    if ds is None or "Uch" not in ds or "Vch" not in ds:
        return None
    fs = float(ds.attrs.get("fs_hz", 0.0))
    if fs <= 0:
        return None
    chi2 = {}
    for rate in (fs, 2.0 * fs, 0.5 * fs):
        moved = ds.assign_coords(t=ds["t"].values * fs / rate)
        moved.attrs["fs_hz"] = rate
        p = replace(params, converter=replace(params.converter, fs_hz=rate))
        try:
            fit = identify_current_amplifier(moved, axis="h", nominal=p, trim_s=trim_s * fs / rate,
                                             band_hz=(20.0, 200.0), window_s=fs / rate,
                                             estimator="welch")
        except ValueError:
            return None
        chi2[rate] = max(float(fit.reduced_chi2), 1e-12)
    best = min(chi2, key=lambda r: chi2[r])
    subject = "data_uch.mat: t, Uch, Vch"
    limit = f"the coil path Uch → Vch fits best at t's {fs:g} Hz"
    if best == fs or chi2[fs] < AMPLIFIER_RATE_PREFERENCE * chi2[best]:
        return Check("rate_vs_current_amplifier", True, fs, limit, subject, unit="Hz")
    return Check(
        "rate_vs_current_amplifier", False, best, limit, subject,
        f"the coil path Uch → Vch fits with a reduced chi-square of {chi2[best]:.3g} at "
        f"{best:g} Hz and {chi2[fs]:.3g} at t's {fs:g} Hz: its corners (the coil's R/L, the "
        f"monitor's cut-off) sit where a {best:g} Hz rate puts them, so the records were "
        f"sampled at {best:g} Hz and t was saved with the step of {fs:g} Hz (×{best / fs:g} "
        "off), or the coil circuit is not the bench file's by an octave; every frequency and "
        "delay would be off by that factor: check the rate the target recorded at",
        unit="Hz")


def controller_rate_check(witness: RateWitness, rate: RateEvidence) -> Check:
    """``rate_vs_controller``: the rate at which the ESRF study's controller explains the
    closed-loop commands against the rate ``t`` gives (ident.evidence.recorded_loop)."""
    left = {f: max(1.0 - e, 1e-12) for f, e in witness.explained.items()}
    own = left[witness.labelled_fs_hz]
    subject = f"{witness.record}.mat: t, {witness.command}"
    limit = (f"the ESRF study's controller explains {witness.command} best at t's "
             f"{witness.labelled_fs_hz:g} Hz")
    if not witness.contradicts:
        return Check("rate_vs_controller", True, witness.fs_hz, limit, subject, unit="Hz")
    factor = witness.fs_hz / witness.labelled_fs_hz
    others = len(rate.by_record) - 1
    return Check(
        "rate_vs_controller", False, witness.fs_hz, limit, subject,
        f"the controller discretised at {witness.fs_hz:g} Hz leaves {own / left[witness.fs_hz]:.3g}"
        f"× less of {witness.command} unexplained than at {witness.labelled_fs_hz:g} Hz: the "
        f"records were sampled at {witness.fs_hz:g} Hz and t was saved with the step of "
        f"{witness.labelled_fs_hz:g} Hz (×{factor:g} off"
        + (f", in this record and the {others} others that share its step" if others else "")
        + "), or the loop ran another controller than the ESRF study's, tuned an octave away; "
        "every frequency and delay would be off by that factor: check the rate the target "
        "recorded at, and save t = k / fs with it", unit="Hz")
