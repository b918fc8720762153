"""The seed's section 2 in one call: recordings → identified plant.

:func:`identify` runs each step on the experiments present and records, for
each step it could not run, why:

=====================  ==========================================  ==============
step                   needs                                       seed
=====================  ==========================================  ==============
4QD gains              ``data_cal_pd_h``, ``data_cal_pd_v``        2.1
current amplifier      ``data_uch``, ``data_ucv`` (``Vch``, ``Vcv``)  2.2
Sercalo                ``data_uch``, ``data_ucv`` + current amp    2.3
Newport                ``data_unh``, ``data_unv``                  2.4
full system            all of the above (nominal blocks stand in)  2.5
=====================  ==========================================  ==============

Before a step runs, its recordings pass the plausibility checks of
:func:`fsmbench.io.folder.check_recording` against the bench (rate, data
type, converter range, signals that move); after the 4QD calibration, its r²,
residual and gain against the nominal are checked
(:func:`fsmbench.ident.calibration.qd_checks`). A failed check makes the step
fall back to the nominal block, and ``skipped`` gives the check's name and
sentence as the reason; every check is in ``checks``.

:meth:`Identification.to_json` has the keys of ``twin_truth.json``
(``qd_gain_v_per_rad``, ``current_amp_gain_a_per_v``,
``sercalo.{h,v}.{resonance_hz, damping_ratio, dc_gain_v_per_a}``,
``newport_gain_v_per_v``, ``delay_s``) plus a ``diagnostics`` tree;
:func:`write_identification` puts ``format`` and ``format_version`` first.
"""

from __future__ import annotations

import warnings as pywarnings
from collections.abc import Callable, Mapping
from dataclasses import replace

import numpy as np
import xarray as xr

from fsmbench.bench.params import Bench
from fsmbench.checks import Notice
from fsmbench.forked import start_forked
from fsmbench.ident.compare import compare_records
from fsmbench.ident.crosscheck import (
    NOISE_CHECKS,
    cross_checks,
    floor_checks,
    newport_drive_gains,
)
from fsmbench.ident.evidence.departures import (
    departures,
    matching_datasheet,
    matching_params,
    measured_keys,
    merged_findings,
)
from fsmbench.ident.fit.quality import (
    quality_warnings,
)
from fsmbench.ident.model_band import model_band
from fsmbench.ident.result import (
    ESRF_TRIMS_S,
    IDENTIFICATION_FORMAT,
    Identification,
    IdentifyOptions,
    path_keyed_summary,
    write_identification,
)
from fsmbench.ident.steps import (
    NOISE_EXPERIMENTS,
    assemble_step,
    current_amp_step,
    newport_step,
    noise_step,
    qd_step,
    sercalo_step,
    start_run,
)

__all__ = [
    "ESRF_TRIMS_S",
    "IDENTIFICATION_FORMAT",
    "NOISE_EXPERIMENTS",
    "Identification",
    "IdentifyOptions",
    "identify",
    "path_keyed_summary",
    "quality_warnings",
    "write_identification",
]


Progress = Callable[[str], None]

_SERCALO_COLUMNS = (("data_uch", "Uch"), ("data_ucv", "Ucv"))
_NEWPORT_COLUMNS = (("data_unh", "Unh"), ("data_unv", "Unv"))


def identify(recordings: Mapping[str, xr.Dataset], *, bench: Bench,
             options: IdentifyOptions | None = None, source: str = "",
             progress: Progress | None = None,
             unusable: Mapping[str, str] | None = None,
             parallel: bool = True) -> Identification:
    """Run the seed's section 2 on the recordings present.

    Parameters
    ----------
    recordings : mapping of experiment name to Dataset
        As read by :func:`fsmbench.io.read_recording` (or simulated).
    bench : Bench
        Its nominal parameters supply what the seed takes as known (``Ga``,
        ``Zc``, the Newport metrology gain) and stand in for blocks that
        cannot be identified from the data present.
    options : IdentifyOptions, optional
    source : str
        Where the recordings come from (for the report and JSON).
    progress : callable, optional
        Receives one message per step.
    unusable : mapping of experiment name to reason, optional
        Files that were there but could not be read (the loader's reason): a
        step they would feed says so instead of "missing".
    parallel : bool
        Fit the noise model in a forked process beside the steps 2.2-2.4, and the
        Newport's two paths, the comparison with the records and the Bode band two by two
        (:mod:`fsmbench.forked`); False: every step here, one after the other, with the
        same result.
    """
    with pywarnings.catch_warnings(record=True) as caught:
        pywarnings.simplefilter("always")
        result = _identify(recordings, bench=bench, opts=options or IdentifyOptions(),
                           source=source, say=progress or (lambda _msg: None),
                           unusable=dict(unusable or {}), parallel=parallel)
    numeric = [Notice("numeric", "identification", f"{w.category.__name__}: {w.message}")
               for w in caught]
    # The identified values as bench-file keys: the departures from the bench file are
    # findings about the user's bench, and the bench file that matches the records is the
    # file with every measured key set (ident.evidence.departures).
    used = result.params or bench.nominal
    measured = measured_keys(result.to_json(), params=used)
    found = merged_findings(result.findings, departures(
        measured, bench_file=bench.nominal, fs_hz=used.converter.fs_hz))
    result = replace(result, findings=found, matching=replace(
        bench, nominal=matching_params(bench.nominal, measured, result.findings),
        datasheet=matching_datasheet(bench.datasheet, result.findings)))
    if result.plant is not None and result.matching is not None and (
            result.sercalo is not None or result.newport is not None):
        # The model's dynamics against the records (MATLAB's compare) and its Bode band
        # from the parameters' stds (bode(sys, 'sd', 3)): ident.compare, ident.model_band,
        # side by side.
        plant, nominal = result.plant, result.matching.nominal
        band_job = start_forked(lambda _say: model_band(
            plant, params=nominal, measured=measured,
            f_hz=np.geomspace(1.0, 0.5 * used.converter.fs_hz, 300)),
            progress=lambda _msg: None, parallel=parallel)
        try:
            comparison = compare_records(recordings, plant=plant,
                                         trims_s=result.options.trims_s)
            result = replace(result, comparison=comparison, bode_band=band_job.result())
        finally:
            band_job.cancel()
    # Records against each other and against the physical model (ident.crosscheck): a
    # failed one makes the identification untrusted, as a quality warning does.
    crossed = [*cross_checks(result.to_json(), params=used,
                             newport_drive_rad_per_v=newport_drive_gains(recordings, params=used)),
               *floor_checks(recordings, fs_hz=used.converter.fs_hz)]
    failed = [c for c in crossed if not c.passed and c.name not in NOISE_CHECKS]
    noise_failed = [c for c in crossed if not c.passed and c.name in NOISE_CHECKS]
    skipped = dict(result.skipped)
    if noise_failed:
        skipped["noise_model"] = ("the fitted noise contradicts the bench file ("
                                  + "; ".join(f"{c.subject}: {c.advice}" for c in noise_failed)
                                  + "): simulations use the bench file's noise, assumed")
    return replace(result, notices=result.notices + tuple(numeric),
                   checks=result.checks + tuple(crossed), skipped=skipped,
                   noise_model=None if noise_failed else result.noise_model,
                   warnings=result.warnings + tuple(
                       f"{c.subject}: {c.title} failed: {c.advice}" for c in failed))


def _identify(recordings: Mapping[str, xr.Dataset], *, bench: Bench, opts: IdentifyOptions,
              source: str, say: Progress, unusable: Mapping[str, str],
              parallel: bool) -> Identification:
    """Section 2's steps in order (:mod:`fsmbench.ident.steps`), each on what the ones
    before it found."""
    run = start_run(recordings, bench=bench, opts=opts, say=say, unusable=unusable,
                    parallel=parallel)
    qd = qd_step(run)
    # The noise model needs only the 4QD's gains: fitted in a forked process beside
    # 2.2-2.4 (fsmbench.forked), its warnings raised here when it is taken.
    noise_job = start_forked(lambda said: noise_step(run, qd=qd, say=said), progress=say,
                             parallel=parallel)
    try:
        gi = current_amp_step(run)
        sercalo = sercalo_step(run, qd=qd, gi=gi)
        newport = newport_step(run, qd=qd, gi=gi, sercalo_id=sercalo.sercalo)
        noise = noise_job.result()
    finally:
        noise_job.cancel()
    return assemble_step(run, source=source, qd=qd, gi=gi, sercalo_step=sercalo,
                         newport_step=newport, noise_step=noise)
