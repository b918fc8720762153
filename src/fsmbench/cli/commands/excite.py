"""``fsmbench excite``: design an excitation, check it against the converters, write it.

    fsmbench excite OUT --input Uch --amplitude-rms 0.015
                        [--kind multisine|noise|chirp] [--band 1 2000] [--resolution 0.5]
                        [--periods P] [--transient-periods T] [--odd | --odd-odd]
                        [--log-grid [--lines-per-decade N]] [--phases minimised|schroeder|random]
                        [--duration S] [--sweep linear|log] [--seed N]
                        [--params TOML] [--model nominal|true] [--bench DIR]
                        [--max-4qd-compression PCT]
                        [--mains-hz F] [--skip-mains] [--timestamp]
                        [--closed-loop CONTROLLER [--at output|reference]
                         [--max-error-urad U]]

Checks the peak at the DAC and at every ADC channel the bench model carries
the input to, and the 4QD's compression at its peak
(:mod:`fsmbench.excite.limits`), before anything is written; a violation is
one line with the rms amplitude that would fit. A multisine with lines on
mains harmonics gets a one-line warning (:mod:`fsmbench.excite.mains`), or
loses those lines with ``--skip-mains``. Then writes
``OUT/excitation.mat`` (``t`` and the input's column at the bench's rate) and
``OUT/excitation.json`` (:mod:`fsmbench.excite.files`) as one transaction with
``run.json``, and prints the lines, crest factors and converter peaks.

With ``--closed-loop CONTROLLER`` the excitation is for a running loop: the peaks
are taken through the closed loop (:mod:`fsmbench.excite.closed_loop`), with the
beam error it adds against ``--max-error-urad``; without ``--amplitude-rms`` the
multisine is shaped and scaled to that bound (:mod:`fsmbench.excite.shaped`).
``excitation.json`` gets a ``closed_loop`` block.
"""

from __future__ import annotations

import argparse
import functools
import math
import sys
from pathlib import Path
from typing import Any

from fsmbench.cli.args import default_noted, positive, seconds, typed_option
from fsmbench.cli.inputs import bench_of, print_document
from fsmbench.cli.options import (
    add_bench,
    add_closed_loop,
    add_json,
    add_out,
    add_params,
    add_seed,
    add_timestamp,
    out_folder,
)
from fsmbench.cli.runfolder import check_inputs_first, run_folder

__all__ = ["register", "run", "summary"]

_CHANNELS = ("Uch", "Ucv", "Unh", "Unv")

# Longest multisine period with crest-factor-minimised phases: the optimisation runs ~1500
# FFTs of one period (300 clipping steps, then 6 norms x 200 L-BFGS iterations); measured
# 22 s and 0.63 GB at 1e6 samples (--resolution 0.01 at 10 kHz), 52 s and 0.98 GB at 2e6,
# and --resolution 0.0001 (1e8 samples) ran over 15 min at 4.3 GB.
_PERIOD_MAX_SAMPLES = 2**20
# Longest record (all periods): the converter checks convolve the whole record with the
# bench's responses, ~310 bytes per sample (measured 2.6 GB and 14 s for 2**23 samples of
# noise, 2.5 GB and 33 s for 8 periods of 1e6); 2**23 samples is 839 s at 10 kHz, 8x the
# seed's longest record (101 s).
_RECORD_MAX_SAMPLES = 2**23


def _count(text: str, *, least: int) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if value < least:
        raise argparse.ArgumentTypeError(f"{text!r} must be at least {least}")
    return value


def _mains_hz(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a frequency in Hz") from None
    if not (math.isfinite(value) and value >= 0):
        raise argparse.ArgumentTypeError(f"{text!r} is not 0 or a positive frequency in Hz")
    return value


def register(sub: Any) -> None:
    """Add ``excite`` to the sub-commands ``sub``."""
    hz = functools.partial(positive, unit="Hz")
    volts = functools.partial(positive, unit="volts")
    p = sub.add_parser("excite", help="design an excitation (multisine, noise, chirp) a "
                                      "real-time target or the twin can play")
    add_out(p, positional=True)
    p.add_argument("--input", required=True, choices=_CHANNELS,
                   help="DAC channel to excite (the ESRF study's signal name)")
    p.add_argument("--kind", choices=("multisine", "noise", "chirp"), default="multisine",
                   help="signal (default multisine)")
    p.add_argument("--band", metavar=("LOW", "HIGH"), nargs=2, type=hz, default=(1.0, 2000.0),
                   help="frequency band [Hz] (default 1 2000)")
    p.add_argument("--resolution", metavar="HZ", type=hz, default=1.0,
                   help="multisine line spacing = 1/period [Hz] (default 1)")
    p.add_argument("--amplitude-rms", metavar="V", type=volts, default=None,
                   dest="amplitude_rms", help="rms of the excitation [V] (required, except "
                                              "with --closed-loop and --max-error-urad: then "
                                              "the largest that keeps the beam within it)")
    p.add_argument("--periods", metavar="P", type=functools.partial(_count, least=1),
                   default=1, help="steady-state periods (default 1)")
    p.add_argument("--transient-periods", metavar="T", type=functools.partial(_count, least=0),
                   default=0, help="periods played first for the system to settle; the JSON "
                                   "says how many, for FRF estimators to drop (default 0)")
    grid = p.add_mutually_exclusive_group()
    grid.add_argument("--odd", action="store_const", const="odd", dest="grid", default="full",
                      help="odd lines only (multisine)")
    grid.add_argument("--odd-odd", action="store_const", const="odd-odd", dest="grid",
                      help="lines 1, 5, 9, ... only (multisine)")
    p.add_argument("--log-grid", action="store_true",
                   help="log-spaced lines: the grid lines nearest a geometric sequence")
    p.add_argument("--lines-per-decade", metavar="N", type=functools.partial(positive,
                                                                             unit="lines"),
                   default=50.0, help="density of --log-grid (default 50)")
    p.add_argument("--phases", choices=("minimised", "schroeder", "random"),
                   default="minimised",
                   help="multisine phases: crest factor minimised (default), Schroeder's, or "
                        "plain random from --seed")
    p.add_argument("--duration", metavar="S", type=seconds, default=30.0,
                   help="noise or chirp period [s] (default 30, the ESRF study's noise records)")
    p.add_argument("--sweep", choices=("linear", "log"), default="linear",
                   help="chirp sweep (default linear)")
    add_seed(p, help="seed of random phases and noise (default 0)")
    add_params(p)
    p.add_argument("--model", choices=("nominal", "true"), default="nominal",
                   help="parameters the limits are checked with: nominal (a real bench; the "
                        "larger gains) or true (the twin) (default nominal)")
    add_bench(p, alias=True, help="check the limits on the bench identified in DIR (a previous "
                                  "identify or study run: its plant, delays, 4QD gains and "
                                  "compression, where the packaged model's 4QD is linear) "
                                  "instead of the bench file's model")
    p.add_argument("--max-4qd-compression", metavar="PCT", dest="max_qd_compression",
                   type=functools.partial(positive, unit="percent"), default=1.0,
                   help="largest compression of the 4QD at the beam's peak [%%] (default 1: "
                        "it lowers the identified gain by at most 3/CF^2 of it, CF the crest "
                        "factor at the 4QD: 0.75 %% for a sine)")
    p.add_argument("--mains-hz", metavar="F", dest="mains_hz", type=_mains_hz, default=50.0,
                   help="mains frequency whose harmonics a multisine should not excite [Hz] "
                        "(default 50; 60 for US grids; 0: no check)")
    p.add_argument("--skip-mains", action="store_true",
                   help="leave the multisine lines on mains harmonics out of the excited grid")
    add_timestamp(p)
    add_closed_loop(p, help="the excitation is played with the loop closed by CONTROLLER (seed: "
                            "the ESRF study's; or a controllers file or fsmbench design folder, "
                            "PATH[::NAME]): its limits are checked through the closed loop",
                    max_error_default=None,
                    max_error_help="with --closed-loop: the rms beam error a user tolerates "
                                   "during the measurement [µrad]; without --amplitude-rms, a "
                                   "multisine shaped to move the beam equally on every line "
                                   "within it (odd lines, log grid, dense around the "
                                   "resonances)")
    add_json(p, help="print excitation.json's content on stdout instead of the summary")
    p.set_defaults(func=run)


def _closed_loop(args: argparse.Namespace, *, bench: Any, params: Any, plant: Any,
                 model: str) -> tuple[Any, Any]:
    """``--closed-loop``: the design (given or beam-bounded) and its closed-loop limits."""
    from fsmbench.control.loaded import running_controller
    from fsmbench.excite.closed_loop import check_closed_loop_limits
    from fsmbench.excite.shaped import beam_bounded_measurement
    from fsmbench.sim.plant import bench_discrete

    if args.input not in ("Uch", "Ucv"):
        raise ValueError(f"--closed-loop: the Sercalo loop drives Uch and Ucv, not {args.input}")
    ctrl = running_controller(args.closed_loop, bench=bench)
    loop_plant = plant if plant is not None else bench_discrete(bench)
    bound = None if args.max_error_urad is None else args.max_error_urad * 1e-6
    qd = args.max_qd_compression / 100.0
    if args.amplitude_rms is None:
        if bound is None:
            raise ValueError("--closed-loop without --amplitude-rms needs --max-error-urad (the "
                             "amplitude is then the largest that keeps the beam within it)")
        m = beam_bounded_measurement(
            bench=bench, params=params, controller=ctrl.feedback, channel=args.input,
            max_error_rad=bound, at=args.at, band_hz=tuple(args.band),
            resolution_hz=args.resolution, periods=args.periods,
            transient_periods=args.transient_periods, max_qd_compression=qd,
            controller_name=ctrl.name, model=model)
        return m.design, m.report
    design = _design(args, params.converter.fs_hz)
    report = check_closed_loop_limits(design, params=params, plant=loop_plant,
                                      controller=ctrl.feedback, controller_name=ctrl.name,
                                      at=args.at, model=model, max_qd_compression=qd,
                                      max_error_rad=bound)
    return design, report


def _check_band(args: argparse.Namespace, fs_hz: float) -> None:
    """Refuse a band reaching the Nyquist frequency (nothing can be excited there)."""
    lo, hi = (float(x) for x in args.band)
    nyquist = fs_hz / 2
    if hi >= nyquist:
        raise ValueError(f"{default_noted(args, 'band', f'--band {lo:g} {hi:g}')}: {hi:g} Hz "
                         "is not below the Nyquist frequency "
                         f"{nyquist:g} Hz of the bench's {fs_hz:g} Hz converters, where no "
                         f"line can be excited; give a high edge below {nyquist:g} Hz")


def _check_length(args: argparse.Namespace, fs_hz: float) -> None:
    """Refuse a period or a record too long to design and check (see the limits above)."""
    repeats = args.periods + args.transient_periods
    if args.kind == "multisine":
        period = fs_hz / args.resolution
        option = default_noted(args, "resolution", f"--resolution {args.resolution:g} Hz")
        if args.phases == "minimised" and period > _PERIOD_MAX_SAMPLES:
            raise ValueError(
                f"{option}: a period of {period:.4g} samples ({period / fs_hz:.4g} s at "
                f"{fs_hz:g} Hz); with --phases minimised the longest is {_PERIOD_MAX_SAMPLES} "
                f"samples ({_PERIOD_MAX_SAMPLES / fs_hz:.4g} s: --resolution "
                f"{fs_hz / _PERIOD_MAX_SAMPLES:.3g} Hz or more), as the crest-factor "
                "optimisation transforms the period ~1500 times (22 s and 0.6 GB measured at "
                "1e6 samples); choose a coarser --resolution or --phases schroeder")
    else:
        period = args.duration * fs_hz
        option = default_noted(args, "duration", f"--duration {args.duration:g} s")
    record = period * repeats
    if record > _RECORD_MAX_SAMPLES:
        counts = (default_noted(args, "periods", f"--periods {args.periods}") + ", "
                  + default_noted(args, "transient_periods",
                                  f"--transient-periods {args.transient_periods}"))
        raise ValueError(
            f"{option} x {repeats} period{'s' if repeats != 1 else ''} ({counts}): a record of "
            f"{record:.4g} samples ({record / fs_hz:.4g} s at {fs_hz:g} Hz), longer than the "
            f"{_RECORD_MAX_SAMPLES} samples ({_RECORD_MAX_SAMPLES / fs_hz:.4g} s) fsmbench "
            "designs and checks at the converters (2.6 GB of memory measured at that length); "
            "fewer or shorter periods")


def _design(args: argparse.Namespace, fs_hz: float) -> Any:
    from fsmbench.excite.design import design_chirp, design_multisine, design_noise

    common = {"input": args.input, "band_hz": tuple(args.band),
              "amplitude_rms_v": args.amplitude_rms, "fs_hz": fs_hz, "seed": args.seed,
              "periods": args.periods, "transient_periods": args.transient_periods}
    if args.kind == "multisine":
        return design_multisine(**common, resolution_hz=args.resolution, grid=args.grid,
                                log_grid=args.log_grid, lines_per_decade=args.lines_per_decade,
                                phase_method=args.phases, mains_hz=args.mains_hz,
                                skip_mains=args.skip_mains)
    if args.kind == "noise":
        return design_noise(**common, duration_s=args.duration)
    return design_chirp(**common, duration_s=args.duration, method=args.sweep)


def summary(design: Any, report: Any) -> list[str]:
    """The lines ``fsmbench excite`` prints: what was designed, crest factors, converter peaks."""
    from fsmbench.excite.design import N_RANDOM_REFERENCE

    d = design
    lines = []
    extra = (f" + {d.transient_periods} transient period{'s' if d.transient_periods != 1 else ''}"
             if d.transient_periods else "")
    if d.kind == "multisine":
        spacing = "log-spaced" if d.log_grid else f"every {d.fs_hz / d.period_samples:g} Hz"
        lines.append(f"{d.input} multisine: {d.lines_hz.size} lines from {d.lines_hz[0]:g} to "
                     f"{d.lines_hz[-1]:g} Hz ({d.grid} grid, {spacing}), "
                     f"{d.amplitude_rms_v:g} V rms")
    else:
        what = "band-limited noise" if d.kind == "noise" else f"{d.chirp_method} chirp"
        lines.append(f"{d.input} {what} from {d.band_hz[0]:g} to {d.band_hz[1]:g} Hz, "
                     f"{d.amplitude_rms_v:g} V rms")
    if d.skipped_lines_hz:
        from fsmbench.excite.mains import harmonic_list

        lines.append(f"{len(d.skipped_lines_hz)} lines on harmonics of the {d.mains_hz:g} Hz "
                     f"mains left out ({harmonic_list(list(d.skipped_lines_hz))})")
    lines.append(f"{d.periods} period{'s' if d.periods != 1 else ''} of {d.period_s:g} s{extra}: "
                 f"{d.samples_v.size} samples at {d.fs_hz:g} Hz ({d.duration_s:g} s)")
    cf = f"crest factor {d.crest_factor:.3f}"
    if d.crest_factor_random_phase is not None:
        cf += (f" ({d.phase_method} phases; random phases: {d.crest_factor_random_phase:.3f}, "
               f"median of {N_RANDOM_REFERENCE} draws from random seed {d.seed})")
    lines.append(cf)
    lines.append(f"peaks through the {report.model_words}:")
    lines += [f"  {c.line()}" for c in report.peaks]
    if report.qd_linear:
        lines.append(f"  {report.qd_line()}")
    else:
        lines += [f"  {q.line()}" for q in report.quad_diode]
    tau = report.slowest_time_constant_s
    if tau > 0:
        settle = d.transient_samples / d.fs_hz
        left = 100 * math.exp(-settle / tau)
        lines.append(f"slowest mode of the bench model (either axis): time constant {tau:.3g} s; "
                     f"{settle:g} s of transient periods leave {left:.2g} % of its start-up "
                     "transient in the first period kept")
    return lines


def run(args: argparse.Namespace) -> int:
    """Design, check and write the excitation; its summary (or excitation.json) is the
    result."""
    from fsmbench.excite.files import write_excitation
    from fsmbench.excite.limits import check_limits
    from fsmbench.excite.mains import mains_warning

    out = out_folder(args)
    assert out is not None  # out_folder raises for a command that needs one
    option = typed_option(args, "bench_dir", "--bench")  # or its alias --identification
    check_inputs_first(args, out, None)  # before anything is read or computed
    bench = bench_of(args)
    params = bench.nominal if args.model == "nominal" else bench.true
    model = args.model
    plant = None
    model_bench = bench  # what a closed-loop design is shaped on
    if args.bench_dir is not None:
        if Path(args.bench_dir).is_file():
            raise ValueError(f"{args.bench_dir}: is a file; {option} needs a folder written by "
                             "fsmbench identify or study (a bench TOML goes to --params)")
        from fsmbench.excite.identified import with_identified_quad_diode
        from fsmbench.ident.load import read_identification_json
        from fsmbench.sim.plant import bench_discrete
        from fsmbench.twin.identified import identified_bench

        _path, ident = read_identification_json(args.bench_dir, option=option)
        if "sercalo" in ident:
            identified = identified_bench(args.bench_dir, bench=bench, option=option)
            params, plant = identified.true, bench_discrete(identified)
            model_bench = identified
            model = f"bench identified in {args.bench_dir} (4QD identified in it too)"
        else:
            # Before the Sercalo is identified (the excitation is for that), the calibration
            # alone: the bench file's plant with the 4QD the calibration measured.
            params = with_identified_quad_diode(params, args.bench_dir, option=option)
            model = (f"{args.model} bench model, 4QD identified in {args.bench_dir} (no "
                     "identified Sercalo there yet)")
    _check_band(args, params.converter.fs_hz)  # before the design, which may take long
    _check_length(args, params.converter.fs_hz)
    closed = None
    if args.closed_loop is not None:
        design, closed = _closed_loop(args, bench=model_bench, params=params, plant=plant,
                                      model=model)
        report = closed.limits
    else:
        if args.amplitude_rms is None:
            raise ValueError("--amplitude-rms is required (the rms of the excitation in volts)")
        design = _design(args, params.converter.fs_hz)
        report = check_limits(design, params=params, model=model, plant=plant,  # before output
                              max_qd_compression=args.max_qd_compression / 100.0)
    warning = mains_warning(design)
    if warning:
        print(f"fsmbench excite: warning: {warning}", file=sys.stderr)
    # Two float64 columns, compressed or not, plus a JSON of the lines and phases.
    need = 16 * design.samples_v.size + 64 * design.lines_hz.size + 65536
    with run_folder(args, out, data=None, need_bytes=need) as folder:
        paths = write_excitation(design, folder.staging, limits=report)
        if closed is not None:
            # The closed loop's peaks and beam error beside the converter limits.
            import json

            from fsmbench.atomic import atomic_write_text

            js = json.loads(paths[1].read_text())
            js["closed_loop"] = closed.to_json()
            atomic_write_text(paths[1], json.dumps(js, indent=2, allow_nan=False) + "\n")
    for path in paths:
        print(f"wrote {folder.final_path(path)}", file=sys.stderr)
    if args.json:
        print_document(folder, paths, "excitation.json")
        return 0
    print("\n".join(summary(design, report)))
    if closed is not None:
        print("\n".join(closed.lines()[-2:]))
    return 0
