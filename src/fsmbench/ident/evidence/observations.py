"""The paths' signs the identification runs do not measure, and a closed-loop run in disguise.

:mod:`fsmbench.ident.consistency` measures each identification run's paths; these
observations come from the other records (:mod:`fsmbench.ident.evidence.signs`):

* ``data_rep_h/v``: the Newport's metrology against its drive (``n·r``);
* the closed-loop records: each one's controller sign against the one that closes
  a stable loop on the bench file's model (``q·m·i``,
  :mod:`fsmbench.ident.evidence.recorded_loop`);

and ``open_loop_record``: a Sercalo run whose command the ESRF study's controller
explains, a closed-loop record saved under the noise run's name.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from typing import Final

import numpy as np
import xarray as xr

from fsmbench.bench.blocks import PlantModel, physical_plant
from fsmbench.bench.params import BenchParams, default_bench
from fsmbench.checks import Check
from fsmbench.ident.evidence.recorded_loop import RecordedController, closed_loop_in_open_run
from fsmbench.ident.evidence.signs import SignObservation

__all__ = ["REP_AGREEMENT", "closed_loop_runs", "esrf_loop_signs", "loop_observations",
           "rep_observations"]

#: ``|corr(Un, Vn)|`` at which the repeatability run's metrology judges the Newport's sign:
#: cos 60° (the 1 Hz sine's metrology follows its command to r > 0.99; noise leaves ~0).
REP_AGREEMENT: Final = 0.5


def closed_loop_runs(recordings: Mapping[str, xr.Dataset], params: BenchParams
                      ) -> list[tuple[Check, list[str]]]:
    """``open_loop_record``: a Sercalo run whose command the ESRF study's controller explains
    (a closed-loop record saved as ``data_uch``): named, and its steps fall back."""
    out = []
    for name, command, reading in (("data_uch", "Uch", "Vph"), ("data_ucv", "Ucv", "Vpv")):
        ds = recordings.get(name)
        if ds is None:
            continue
        fit = closed_loop_in_open_run(ds, command=command, reading=reading,
                                      fs_hz=float(ds.attrs.get("fs_hz",
                                                               params.converter.fs_hz)),
                                      step_v=params.converter.lsb_v)
        if fit is None:
            continue
        out.append((Check(
            "open_loop_record", False, fit.explained, "an open-loop run's command is its "
            f"excitation, not a function of {reading}", f"{name}.mat: {command}",
            f"the ESRF study's controller explains {100 * fit.explained:.1f} % of {command} "
            f"from {reading}: {name}.mat was recorded with the loop closed (a closed-loop "
            "record saved under this name, or the loop left closed during the noise run); "
            "the open-loop identification cannot use it: record the noise run with the loop "
            "open"), [name]))
    return out


def rep_observations(recordings: Mapping[str, xr.Dataset], params: BenchParams
                      ) -> list[SignObservation]:
    """``Un → Vn`` in ``data_rep_h/v``: the Newport's drive against its metrology (n·r)."""
    out = []
    for axis in "hv":
        name, un, vn = f"data_rep_{axis}", f"Un{axis}", f"Vn{axis}"
        ds = recordings.get(name)
        if ds is None or un not in ds or vn not in ds:
            continue
        u = np.asarray(ds[un].values, dtype=np.float64)
        v = np.asarray(ds[vn].values, dtype=np.float64)
        if u.size != v.size or u.size < 3 or np.ptp(u) == 0 or np.ptp(v) == 0:
            continue
        corr = float(np.corrcoef(u, v)[0, 1])
        if not np.isfinite(corr):
            continue
        model = (float(np.sign(params.newport.gain_rad_per_v[axis]))
                 * params.newport.metrology_sign[axis])
        rho = corr * model
        if abs(rho) < REP_AGREEMENT:
            continue
        slope = float(np.polyfit(u, v, 1)[0])
        gain = (params.newport.gain_rad_per_v[axis] * params.newport.metrology_sign[axis]
                / params.newport.metrology_gain_rad_per_v)
        out.append(SignObservation(name, un, vn, ("n", "r"), 1 if rho > 0 else -1,
                                   f"{un} → {vn} {slope:+.3g} V/V (model {gain:+.3g})"))
    return out


def loop_observations(loops: Mapping[str, RecordedController], plant: PlantModel
                       ) -> list[SignObservation]:
    """Each closed-loop record's controller sign against the one that closes a stable loop
    on the bench file's model (q·m·i).

    The ESRF study's controller closes a stable loop when the static gain of the path
    ``Uc → Vp`` over the 4QD gain the loop divides by has the sign it had on the ESRF
    bench (:func:`esrf_loop_signs`): on the bench file's model, the divisor's sign
    follows; a recorded divisor of the other sign means the path's sign is the other.
    """
    out = []
    esrf = esrf_loop_signs()
    for axis, loop in loops.items():
        path = plant.dc_gain(output=loop.reading, input=loop.command)
        stable = float(np.sign(path)) * esrf[axis]
        for fit in loop.fits:
            if fit.verdict != "seed" or not np.isfinite(fit.gd_used_v_per_rad) or not stable:
                continue
            sign = 1 if fit.gd_used_v_per_rad * stable > 0 else -1
            out.append(SignObservation(
                fit.record, loop.reading, loop.command, ("q", "m", "i"), sign,
                f"{fit.record}: {loop.command} = −K{axis}({loop.reading} / "
                f"{fit.gd_used_v_per_rad:+.3g} V/rad), a divisor of sign {stable:+.0f} on the "
                "bench file's model"))
    return out


@functools.cache
def esrf_loop_signs() -> dict[str, float]:
    """sign(static ``Uc → Vp`` / the 4QD gain divided by) per axis on the ESRF bench (the
    packaged bench's nominal model), for which the study's controller of 9.2 was designed."""

    nominal = default_bench().nominal
    plant = physical_plant(nominal, source="nominal")
    gd = nominal.quad_diode.gain_v_per_rad
    return {a: float(np.sign(plant.dc_gain(output=f"Vp{a}", input=f"Uc{a}") / gd[a]))
            for a in "hv"}
