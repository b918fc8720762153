"""What a Monte Carlo run needs around its engine (:mod:`fsmbench.scale.montecarlo`): the
ranges file, a ``montecarlo.json`` read back, the controller (designed or loaded), the Dask
client, and the table ``fsmbench montecarlo`` prints."""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import tomllib
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fsmbench.bench.blocks import physical_plant
from fsmbench.control.analysis import control_objective
from fsmbench.control.controller import Controller, controller_of
from fsmbench.control.design import design_controller
from fsmbench.control.load import load_controllers, select_controller
from fsmbench.jsonutil import nested
from fsmbench.scale.breaches import breach_sentence, factors_sentence
from fsmbench.scale.montecarlo import (
    METRICS,
    MONTECARLO_FORMAT,
    Ranges,
    summarise,
)

# The command line imports this module to build its parser: the model, numba and Dask load
# only when a function runs.
if TYPE_CHECKING:
    from fsmbench.bench.params import Bench
    from fsmbench.scale.montecarlo import Ranges

__all__ = ["dask_client", "designed_controller", "format_table", "loaded_controller",
           "read_montecarlo", "read_ranges"]


def read_ranges(path: str | Path) -> Ranges:
    """Read ``--ranges``: a TOML file of ranges; keys left out keep their default.

    The file holds top-level ``key = [low, high]`` pairs, keys as the
    attributes, e.g. ``resonance_scale = [0.9, 1.1]`` or
    ``dac_delay_s = [0, 0]``.

    Raises
    ------
    ValueError
        One line naming the file and the key: not TOML, unknown key, not a
        pair of numbers, or an invalid range.
    """

    p = Path(path)
    try:
        data = tomllib.loads(p.read_text("utf-8"))
    except FileNotFoundError:
        raise ValueError(f"{p}: no such ranges file") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{p}: not valid TOML ({exc})") from None
    names = [f.name for f in dataclasses.fields(Ranges)]
    unknown = sorted(set(data) - set(names))
    if unknown:
        raise ValueError(f"{p}: unknown range(s) {', '.join(unknown)}; known: "
                         f"{', '.join(names)}")
    values: dict[str, tuple[float, float]] = {}
    for key, raw in data.items():
        ok = (isinstance(raw, list) and len(raw) == 2
              and all(isinstance(x, int | float) and not isinstance(x, bool) for x in raw))
        if not ok:
            raise ValueError(f"{p}: '{key}' must be a pair [low, high] of numbers, got {raw!r}")
        values[key] = (float(raw[0]), float(raw[1]))
    try:
        return dataclasses.replace(Ranges(), **values)
    except ValueError as exc:
        raise ValueError(f"{p}: {exc}") from None


def read_montecarlo(path: str | Path) -> dict[str, Any]:
    """Read a ``montecarlo.json`` (or the folder holding it) for the study's report.

    Raises
    ------
    ValueError
        One line naming the file: missing, not JSON, not ``fsmbench.montecarlo``, or a
        version without ``requirements`` (before 3: run ``fsmbench montecarlo`` again).
    """

    p = Path(path)
    p = p / "montecarlo.json" if p.is_dir() else p
    try:
        doc = json.loads(p.read_text("utf-8"))
    except FileNotFoundError:
        raise ValueError(f"{p}: no such file (the output of fsmbench montecarlo)") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{p}: not valid JSON ({exc})") from None
    name, version = MONTECARLO_FORMAT
    found = (doc.get("format"), doc.get("format_version")) if isinstance(doc, dict) else None
    if found is None or found[0] != name:
        raise ValueError(f"{p}: not a {name} file (format {None if found is None else found[0]})")
    if found[1] != version:
        raise ValueError(f"{p}: {name} version {found[1]}, this fsmbench reads version "
                         f"{version} (it lists the draws that break each requirement): run "
                         "fsmbench montecarlo again")
    return doc


def designed_controller(bench: Bench, *, plant: Any = None,
                        plant_source: str = "physical (nominal)") -> Controller:
    """fsmbench's controller designed on ``plant`` (default the nominal physical plant),
    with the 6.1 objective of ``bench.nominal``, Tustin at the converter rate.

    ``fsmbench design`` designs on the plant :func:`fsmbench.stages.choose_plant`
    picks: the identified one when the recordings allow it, else this nominal model.
    """

    model = physical_plant(bench.nominal, source=plant_source) if plant is None else plant
    k = design_controller(model, objective=control_objective(bench.nominal)).controller
    ts = bench.true.converter.ts_s
    gd = bench.nominal.quad_diode.gain_v_per_rad
    return controller_of(k, name="fsmbench controller", ts_s=ts, gd_v_per_rad=(gd.h, gd.v),
                         source=f"designed on the {plant_source} plant, Tustin at {1/ts:g} Hz")


def loaded_controller(path: str | Path, *, name: str | None, bench: Bench) -> Controller:
    """A controller of a ``controllers.mat`` / ``controllers_sos.json`` / design folder.

    ``name`` picks it (default fsmbench's, :func:`fsmbench.control.load.select_controller`);
    its recorded 4QD gain is used if the file has one, else ``bench.nominal``'s.
    """

    ts = bench.true.converter.ts_s
    chosen = select_controller(load_controllers(path, ts_s=ts), name)
    nominal = bench.nominal.quad_diode.gain_v_per_rad
    return dataclasses.replace(chosen, gd_v_per_rad=chosen.gd_v_per_rad or (nominal.h, nominal.v))


@contextlib.contextmanager
def dask_client(*, scheduler: str | None, workers: int) -> Iterator[Any]:
    """A ``distributed.Client``: to ``scheduler``, or to a new ``LocalCluster`` of
    ``workers`` single-threaded processes; ``None`` for ``workers == 1`` and no scheduler.

    A running scheduler's workers keep their own settings; the local ones run
    without glibc trimming and without the profiler (see the comment below).
    """
    if scheduler is None and workers == 1:
        yield None
        return
    try:
        import dask
        from distributed import Client, LocalCluster
    except ImportError:
        raise ValueError("fsmbench montecarlo on Dask needs dask.distributed: pip install "
                         "'fsmbench[dask]' (or run in one process with --workers 1)") from None
    if scheduler is not None:
        try:
            client = Client(scheduler, timeout="20s")
        except OSError as exc:
            raise ValueError(f"--scheduler {scheduler}: cannot connect ({exc})") from None
        with client:
            yield client
        return
    # Worker settings for these tasks (measured on 2 workers, 16 draws: 0.44 s of CPU per
    # draw with Dask's defaults, 0.32 s without them, 0.28-0.33 s in one process): distributed
    # sets MALLOC_TRIM_THRESHOLD_=64 kB, so each record's ~10 MB arrays go back to the OS
    # and fault in again (+30 %), and its profiler samples every 10 ms (+10 %). A draw's
    # memory is a few tens of MB, so nothing needs trimming.
    environ = {k: v for k, v in dask.config.get("distributed.nanny.pre-spawn-environ").items()
               if k != "MALLOC_TRIM_THRESHOLD_"}
    with dask.config.set({"distributed.nanny.pre-spawn-environ": environ,
                          "distributed.worker.profile.enabled": False}), \
            LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                         dashboard_address=None) as cluster, Client(cluster) as client:
        yield client


#: Breaches printed in full per requirement; the rest are named by index (all in the JSON).
_BREACHES_SHOWN = 20


def _requirement_lines(result: Any) -> list[str]:
    """Per requirement: draws meeting it, then every draw that breaks it, named."""

    n = len(result.draws)
    lines = ["requirements over the draws (a draw passes when both axes do):"]
    for outcome in result.requirements():
        req = outcome.to_json()
        ok = n - outcome.n_broken
        lines.append(f"  {req['description']:<58} {ok:>4} of {n} ({100 * ok / n:.0f} %)")
        if not outcome.breaches:
            continue
        indices = ", ".join(str(b.index) for b in outcome.breaches)
        lines.append(f"    broken by {outcome.n_broken} of {n} ({100 * outcome.share:.0f} %): "
                     f"draws {indices}")
        lines += [f"    {breach_sentence(req, b)}" for b in req["breaches"][:_BREACHES_SHOWN]]
        if outcome.n_broken > _BREACHES_SHOWN:
            lines.append(f"    … {outcome.n_broken - _BREACHES_SHOWN} more in montecarlo.json "
                         "(requirements[].breaches)")
    return lines


def format_table(result: Any) -> str:
    """The short table: per requirement the draws that meet it and every draw that breaks
    it (with its factors), quantiles of each metric in display units, the worst draws."""

    s = summarise(result)
    n = len(result.draws)
    lines = [f"{n} draws, random seed {result.seed}, controller {result.setup.controller.name}, "
             f"around {result.setup.bench.label}; not settled before the metrics: "
             f"{s['unsettled_draws']}", *_requirement_lines(result)]
    lines.append(f"{'metric':<50} {'unit':<9} {'5 %':>10} {'median':>10} {'95 %':>10} "
                 f"{'max':>10}")

    def num(x: float | None, factor: float) -> str:
        return "—" if x is None or not math.isfinite(x) else f"{x * factor:.4g}"

    for key, (words, unit, factor) in METRICS.items():
        q = s["quantiles"][key]
        lines.append(f"{words:<50} {unit:<9} " + " ".join(
            f"{num(q[k], factor):>10}" for k in ("p5", "p50", "p95", "max")))
    lines.append("worst draws (unstable first, then the larger tracking error):")
    for row in s["worst_draws"]:
        m, f = row.metrics, row.factors
        what = (f"unstable, spectral radius {num(m['spectral_radius'], 1.0)}" if not row.stable
                else f"tracking error h {num(m['tracking_error_rms_rad.h'], 1e6)}, "
                     f"v {num(m['tracking_error_rms_rad.v'], 1e6)} µrad rms")
        lines.append(f"  draw {row.index}: {what}; {factors_sentence(nested(f))}")
    return "\n".join(lines)


