"""The public Python API: the study step by step, and the loops of its controllers.

Each function wraps the stage the command line runs (:mod:`fsmbench.stages`,
:mod:`fsmbench.study`); nothing here computes on its own. The heavy modules
(scipy, python-control, xarray, numba) are imported inside each function, so
``import fsmbench`` stays light (the command line's start-up time).

Units are SI throughout (rad, V, A, s, m) and frequencies in Hz; python-control
objects keep rad/s as python-control does. The loop is closed as ``u = -K y``.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

if TYPE_CHECKING:
    import control as ct
    import xarray as xr

    from fsmbench.bench.blocks import PlantModel
    from fsmbench.bench.params import Bench
    from fsmbench.budget import BudgetResult
    from fsmbench.control.feedback import LoopMargins
    from fsmbench.ident.result import Identification, IdentifyOptions
    from fsmbench.io.folder import RecordingSet
    from fsmbench.stages import DesignStage
    from fsmbench.study import StudyResult
    from fsmbench.twin.simulate import TwinRun

__all__ = [
    "budget",
    "complementary",
    "design",
    "identify",
    "load_bench",
    "load_recordings",
    "loop_gain",
    "margins",
    "physical_plant",
    "sensitivity",
    "simulate",
    "study",
]

PathLike = str | os.PathLike[str]
Progress = Callable[[str], None]
Delays = Literal["pade", "exact", "none"]
#: The six identification experiments (ESRF study section 2).
IDENT_EXPERIMENTS = ("data_cal_pd_h", "data_cal_pd_v", "data_uch", "data_ucv", "data_unh",
                     "data_unv")


def load_bench(path: PathLike | None = None) -> Bench:
    """Bench parameters: the packaged Sercalo bench, or a TOML bench file.

    Parameters
    ----------
    path : str or os.PathLike, optional
        A bench file (``fsmbench params --write`` makes one; ``base = "default"``
        lists only the differences), or a packaged bench's name
        (``"real_bench.toml"``). None: the packaged default bench, the twin.

    Returns
    -------
    Bench
        ``nominal`` (what the user knows: every model number), ``true`` (the
        twin's truth) and ``datasheet`` parameter sets, each a frozen tree of
        floats in SI units.

    Raises
    ------
    fsmbench.bench.params.ParamsError
        The file is not TOML, or a key is missing, unknown or of the wrong type.

    Examples
    --------
    >>> import fsmbench
    >>> bench = fsmbench.load_bench()
    >>> bench.nominal.converter.fs_hz            # sampling rate [Hz]
    10000.0
    >>> bench.nominal.converter.ts_s             # sample time [s]
    0.0001
    """
    from fsmbench.bench.params import load_bench as _load

    return _load(None if path is None else Path(path))


def physical_plant(bench: Bench | None = None, *,
                   parameters: Literal["nominal", "true"] = "nominal") -> PlantModel:
    """The plant from physics: the bench's blocks assembled as the ESRF study's 2.5.

    Parameters
    ----------
    bench : Bench, optional
        Default: the packaged bench (:func:`load_bench`).
    parameters : {"nominal", "true"}
        The bench file's values, or the twin's truth.

    Returns
    -------
    PlantModel
        Inputs ``Uch, Ucv`` (Sercalo DAC [V]), ``Unh, Unv`` (Newport [V]); outputs
        ``Vch, Vcv`` [V], ``Ich, Icv`` [A], ``Rh, Rv`` (beam angle [rad]),
        ``Vph, Vpv`` (4QD [V]); ``input_delay_s`` per input [s].
        :meth:`~fsmbench.bench.blocks.PlantModel.to_control` gives the
        python-control model, :meth:`~fsmbench.bench.blocks.PlantModel.to_frd`
        its exact response.

    Examples
    --------
    >>> import fsmbench
    >>> plant = fsmbench.physical_plant(parameters="true")      # the twin's
    >>> sorted(plant.input_delay_s)
    ['Uch', 'Ucv', 'Unh', 'Unv']
    >>> g = plant.to_control(outputs=["Rh"], inputs=["Uch"])    # Padé, minimal
    >>> g.nstates                     # 6 Padé + coil current + two Sercalo modes
    11
    >>> plant.to_control(delays="exact", dt=1e-4, outputs=["Rh"], inputs=["Uch"]).nstates
    6
    """
    from fsmbench.bench.blocks import physical_plant as _plant
    from fsmbench.bench.params import default_bench

    b = default_bench() if bench is None else bench
    if parameters not in ("nominal", "true"):
        raise ValueError(f"parameters={parameters!r}: use 'nominal' or 'true'")
    return _plant(b.true if parameters == "true" else b.nominal,
                  source=f"physical ({parameters})")


def simulate(bench: Bench | None = None, *, seed: int = 0, duration_s: float | None = None,
             experiments: Sequence[str] | None = None, out_dir: PathLike | None = None,
             progress: Progress | None = None) -> TwinRun:
    """Record the ESRF study's experiments on the digital twin.

    Parameters
    ----------
    bench : Bench, optional
        Default: the packaged bench; the twin runs its ``true`` parameters.
    seed : int
        Random seed of the twin's noise: same seed, same records, bit for bit.
    duration_s : float, optional
        Length of every record [s] (at least 5 s for all of them); default the
        ESRF study's lengths (11–100 s).
    experiments : sequence of str, optional
        Which of the thirteen (``data_uch``, ``data_huddle_test_1`` …); default all.
    out_dir : str or os.PathLike, optional
        Also write them there as ``<name>.mat`` with ``twin_truth.json``, the
        folder :func:`load_recordings` and ``fsmbench study --data`` read.
    progress : callable, optional
        Receives one message per experiment.

    Returns
    -------
    TwinRun
        ``recordings``: experiment name to ``xarray.Dataset`` (dimension ``t``
        [s], one variable per signal [V]); ``truth``: the twin's parameters as
        identification keys.

    Examples
    --------
    >>> import fsmbench
    >>> run = fsmbench.simulate(seed=1, duration_s=5.0, experiments=["data_uch"])
    >>> ds = run.recordings["data_uch"]
    >>> ds.sizes["t"]                 # 5 s at 10 kHz
    50000
    >>> sorted(ds.data_vars)          # DAC command, coil voltage, 4QD [V]
    ['Uch', 'Vch', 'Vph', 'Vpv']
    """
    from fsmbench.twin.simulate import simulate_bench, write_twin

    run = simulate_bench(bench, seed=seed, duration_s=duration_s, experiments=experiments,
                         progress=progress)
    if out_dir is not None:
        write_twin(run, Path(out_dir))
    return run


def load_recordings(data_dir: PathLike, *, bench: Bench | None = None,
                    progress: Progress | None = None) -> RecordingSet:
    """Read and check every ESRF-study experiment in a folder.

    Parameters
    ----------
    data_dir : str or os.PathLike
        Folder of ``data_uch.mat`` … (MATLAB v5/v7.3, HDF5 or NeXus ``.h5``/``.nxs``).
    bench : Bench, optional
        Its converter (range [V], bits) judges saturation and quantisation;
        default the packaged bench.
    progress : callable, optional
        Receives one message per file read.

    Returns
    -------
    RecordingSet
        ``recordings``: experiment name to ``xarray.Dataset`` (dimension ``t``
        [s]); ``skipped``: experiment to the reason it is not used; ``checks``
        and ``notices``: what the plausibility checks found.

    Raises
    ------
    fsmbench.io.errors.RecordingError
        No recording could be read (the message says what the folder holds).

    Examples
    --------
    >>> import tempfile, fsmbench
    >>> folder = tempfile.mkdtemp()
    >>> _ = fsmbench.simulate(duration_s=5.0, experiments=["data_cal_pd_h", "data_uch"],
    ...                       out_dir=folder)
    >>> loaded = fsmbench.load_recordings(folder)
    >>> sorted(loaded.recordings)
    ['data_cal_pd_h', 'data_uch']
    >>> loaded.skipped["data_ucv"][:13]
    'no data_ucv.m'
    """
    from fsmbench.bench.params import default_bench
    from fsmbench.io.folder import load_recordings as _load

    conv = (default_bench() if bench is None else bench).nominal.converter
    # As the study reads them: the records' rate is judged by the identification.
    return _load(Path(data_dir), fs_hz=None, adc_range_v=conv.range_v, adc_bits=conv.bits,
                 progress=progress)


def _records(recordings: Any) -> tuple[Mapping[str, xr.Dataset], dict[str, str], str]:
    """Records by name, the files there but unusable, and where they come from."""
    folder = getattr(recordings, "folder", None)
    unusable = recordings.unusable() if hasattr(recordings, "unusable") else {}
    if hasattr(recordings, "truth") and hasattr(recordings, "recordings"):
        return recordings.recordings, {}, f"digital twin, random seed {recordings.seed}"
    if hasattr(recordings, "recordings"):
        return recordings.recordings, unusable, f"recorded data in {folder}"
    if isinstance(recordings, Mapping):
        return recordings, {}, "recordings"
    raise TypeError("recordings: a RecordingSet (load_recordings), a TwinRun (simulate) or a "
                    f"mapping of experiment name to xarray.Dataset, not {type(recordings)}")


def identify(recordings: RecordingSet | TwinRun | Mapping[str, xr.Dataset], *,
             bench: Bench | None = None, options: IdentifyOptions | None = None,
             out_dir: PathLike | None = None, progress: Progress | None = None) -> Identification:
    """Identify the plant from its records (ESRF study section 2).

    Parameters
    ----------
    recordings : RecordingSet, TwinRun or mapping of str to xarray.Dataset
        From :func:`load_recordings` or :func:`simulate`; the experiments
        ``data_cal_pd_h/v`` (4QD), ``data_uch/ucv`` (current amplifier and
        Sercalo), ``data_unh/unv`` (Newport) are used where present.
    bench : Bench, optional
        Its nominal parameters stand in for what the records cannot give.
    options : IdentifyOptions, optional
        FRF estimator and fit weights (default ``auto``, the ESRF study's).
    out_dir : str or os.PathLike, optional
        Also write ``identification.json``, ``plant.mat`` and ``frf.mat`` there.
    progress : callable, optional
        Receives one message per step.

    Returns
    -------
    Identification
        ``plant`` (a :class:`~fsmbench.bench.blocks.PlantModel`, or None when the
        Sercalo could not be identified; ``skipped`` says why), the steps'
        results, ``uncertainty`` (each value's standard deviation with its
        named parts), ``checks``, ``warnings`` and ``to_json()``.

    Examples
    --------
    >>> import fsmbench
    >>> run = fsmbench.simulate(seed=1, duration_s=5.0, experiments=[
    ...     "data_cal_pd_h", "data_cal_pd_v", "data_uch", "data_ucv", "data_unh", "data_unv"])
    >>> ident = fsmbench.identify(run)
    >>> ident.warnings
    ()
    >>> round(ident.plant.input_delay_s["Uch"] * 1e4, 1)   # DAC delay [samples]
    1.5
    >>> g = ident.plant.to_control(outputs=["Rh", "Rv"], inputs=["Uch", "Ucv"])
    >>> g.input_labels, g.output_labels
    (['Uch', 'Ucv'], ['Rh', 'Rv'])
    """
    from fsmbench.bench.params import default_bench
    from fsmbench.stages import identify_stage

    recs, unusable, source = _records(recordings)
    b = default_bench() if bench is None else bench
    if out_dir is None:
        from fsmbench.ident.pipeline import identify as _identify

        return _identify(recs, bench=b, options=options, source=source, progress=progress,
                         unusable=unusable)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    return identify_stage(recs, bench=b, out_dir=out, source=source, progress=progress,
                          options=options, unusable=unusable).result


def _plant_choice(plant: Any, recordings: Mapping[str, xr.Dataset] | None, bench: Bench,
                  progress: Progress | None) -> Any:
    """The stages' :class:`~fsmbench.stages.PlantChoice` for a plant argument."""
    from fsmbench.bench.blocks import PlantModel, physical_plant
    from fsmbench.ident.result import Identification
    from fsmbench.stages import PlantChoice, choose_plant

    if isinstance(plant, PlantModel):
        return PlantChoice(plant, plant.source, None)
    if isinstance(plant, Identification):
        if recordings is None and (plant.plant is None or plant.sercalo is None
                                   or plant.warnings):
            why = "; ".join(plant.warnings) or "; ".join(
                f"{k}: {v}" for k, v in plant.skipped.items()) or "no plant"
            raise ValueError(f"the identification gives no plant to design on ({why}); pass "
                             "a PlantModel (ident.plant, or fsmbench.physical_plant())")
        return choose_plant(recordings or {}, bench=bench, identification=plant,
                            progress=progress)
    if plant is None:
        if recordings is not None:  # as `fsmbench budget` does: identify if it can
            return choose_plant(recordings, bench=bench, progress=progress)
        return PlantChoice(physical_plant(bench.nominal, source="physical (nominal)"),
                           "nominal physical model (no plant given)", None)
    raise TypeError(f"plant: a PlantModel, an Identification or None, not {type(plant)}")


def budget(recordings: RecordingSet | TwinRun | Mapping[str, xr.Dataset], *,
           bench: Bench | None = None, plant: PlantModel | Identification | None = None,
           recommended: ct.StateSpace | None = None, out_dir: PathLike | None = None,
           progress: Progress | None = None) -> BudgetResult:
    """Noise and error budget, huddle tests and repeatability (ESRF study 3, 4, 11).

    Parameters
    ----------
    recordings : RecordingSet, TwinRun or mapping of str to xarray.Dataset
        ``data_huddle_test_1..5`` and ``data_rep_h/v`` are used where present.
    bench : Bench, optional
        Default: the packaged bench.
    plant : PlantModel or Identification, optional
        The plant the budget propagates through. An :class:`Identification`
        is used as the study uses it (its plant if trusted, its fitted noise);
        None identifies the records if they hold ``data_uch/ucv``, else the
        nominal physical model (as ``fsmbench budget``).
    recommended : control.StateSpace, optional
        fsmbench's controller (``design(...).result.controllers
        ["fsmbench_controller"]``): its budget beside the recorded loop's.
    out_dir : str or os.PathLike, optional
        Keep ``budget.json`` there (otherwise it is written to a temporary
        folder and removed).
    progress : callable, optional

    Returns
    -------
    BudgetResult
        ``total_rms_m`` (the distance error's rms [m]), ``budget`` (each
        source's row), ``huddle``, ``repeatability``, ``skipped``, ``checks``.

    Examples
    --------
    >>> import fsmbench
    >>> run = fsmbench.simulate(seed=1, duration_s=5.0, experiments=[
    ...     f"data_huddle_test_{i}" for i in range(1, 6)])
    >>> result = fsmbench.budget(run)          # nominal plant: no identification records
    >>> 1e-9 < result.total_rms_m < 1e-8      # the distance error [m]
    True
    >>> sorted(result.skipped)
    ['data_rep_h', 'data_rep_v']
    """
    import tempfile

    from fsmbench.bench.params import default_bench
    from fsmbench.stages import budget_stage

    recs, _, _ = _records(recordings)
    b = default_bench() if bench is None else bench
    choice = _plant_choice(plant, recs, b, progress)
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        return budget_stage(recs, bench=b, out_dir=out, plant=choice, progress=progress,
                            recommended=recommended).result
    with tempfile.TemporaryDirectory(prefix="fsmbench-budget-") as tmp:
        return budget_stage(recs, bench=b, out_dir=Path(tmp), plant=choice, progress=progress,
                            recommended=recommended).result


def design(plant: PlantModel | Identification | None = None, *, bench: Bench | None = None,
           out_dir: PathLike | None = None, twin_check: bool = False, seed: int = 0,
           progress: Progress | None = None) -> DesignStage:
    """Analyse the plant, verify the ESRF study's controllers, design fsmbench's (5–10).

    Parameters
    ----------
    plant : PlantModel or Identification, optional
        The design plant: an identification's (it must be trusted: a plant with
        the Sercalo identified and no warnings) or any plant model; None: the
        bench's nominal physical model.
    bench : Bench, optional
        Its nominal parameters give Table 5 and the 6.1 objective.
    out_dir : str or os.PathLike, optional
        Write ``design.json``, ``controllers.mat``, ``controllers_sos.json`` and
        ``fsmbench_load.m`` there (otherwise to a temporary folder, removed).
    twin_check : bool
        Also run fsmbench's controller on ``bench``'s twin (the repeatability
        experiment with quantisation and noise).
    seed : int
        Random seed of that run.
    progress : callable, optional

    Returns
    -------
    DesignStage
        ``result`` (a :class:`~fsmbench.control.study.DesignResult`:
        ``controllers`` by name, continuous ``Rh, Rv`` [rad] → ``Uch, Ucv`` [V],
        ``seed`` and ``fsmbench`` loop verifications with their margins),
        ``payload`` (``design.json``) and ``twin_check``.

    Examples
    --------
    >>> import fsmbench
    >>> stage = fsmbench.design()                         # the nominal plant
    >>> sorted(stage.result.controllers)
    ['fsmbench_controller', 'iff_controller', 'newport_controller', 'seed_controller']
    >>> k = stage.result.controllers["fsmbench_controller"]
    >>> k.input_labels, k.output_labels
    (['Rh', 'Rv'], ['Uch', 'Ucv'])
    >>> stage.result.fsmbench.axes["h"].margins.phase_margin_deg > 30
    True
    """
    import tempfile

    from fsmbench.bench.params import default_bench
    from fsmbench.stages import SimulationBench, design_stage

    b = default_bench() if bench is None else bench
    choice = _plant_choice(plant, None, b, progress)
    sim = SimulationBench(b) if twin_check else SimulationBench(None, "not asked (twin_check)")

    def run(folder: Path) -> DesignStage:
        return design_stage(bench=b, out_dir=folder, plant=choice, seed=seed,
                            progress=progress, simulated=sim)

    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        return run(out)
    with tempfile.TemporaryDirectory(prefix="fsmbench-design-") as tmp:
        return run(Path(tmp))


def study(*, out_dir: PathLike, data_dir: PathLike | None = None, bench: Bench | None = None,
          seed: int = 0, duration_s: float | None = None, figures: Sequence[str] = (),
          progress: Progress | None = None) -> StudyResult:
    """The whole study, as ``fsmbench study``: records to report.

    Parameters
    ----------
    out_dir : str or os.PathLike
        Output folder (created): ``report.html``, ``summary.json``, each stage's files.
    data_dir : str or os.PathLike, optional
        Folder of recordings; without it the twin records them
        (``out_dir/twin-data``).
    bench : Bench, optional
    seed : int
        Random seed of the twin.
    duration_s : float, optional
        Twin record length [s] (at least 5 s); default the ESRF study's lengths.
    figures : sequence of {"png", "pdf"}
        Also write every figure to ``out_dir/figures``.
    progress : callable, optional

    Returns
    -------
    StudyResult
        ``report`` (path), ``summary`` (the verdict: ``meets_specifications``),
        ``stages`` (what ran or was skipped, and why), ``plant``, ``design``.

    Examples
    --------
    >>> import tempfile, fsmbench
    >>> result = fsmbench.study(out_dir=tempfile.mkdtemp(), duration_s=5.0)
    >>> [s.name for s in result.stages]
    ['simulate', 'recordings', 'identify', 'design', 'budget', 'validation']
    >>> result.report.endswith("report.html")
    True
    """
    from fsmbench.study import run_study

    return run_study(out_dir=Path(out_dir),
                     data_dir=None if data_dir is None else Path(data_dir), bench=bench,
                     seed=seed, duration_s=duration_s, figures=figures, progress=progress)


def loop_gain(plant: PlantModel | ct.StateSpace | ct.TransferFunction,
              controller: ct.StateSpace | ct.TransferFunction | None = None, *,
              delays: Delays | None = None, order: int = 6) -> ct.StateSpace:
    """Loop gain ``L = G K`` of ``u = -K y``, a minimal python-control model.

    Parameters
    ----------
    plant : PlantModel or control.StateSpace or control.TransferFunction
        ``G``: its path from the controller's outputs to its inputs, by signal
        name (or in order, if unnamed). A :class:`PlantModel`'s delays are Padé
        approximants of ``order`` for a continuous controller and exact (zero-order
        hold at the controller's sample time) for a discrete one.
    controller : control.StateSpace or control.TransferFunction, optional
        ``K``: measurements (``Rh, Rv`` [rad]) to commands (``Uch, Ucv`` [V]).
        None: ``plant`` is already the loop.
    delays : {"pade", "exact", "none"}, optional
        Override how a :class:`PlantModel`'s delays enter.
    order : int
        Padé order.

    Returns
    -------
    control.StateSpace
        Square, from the error at the controller's input to the measurement
        (both named like the controller's inputs), minimal, with ``K``'s sample time.

    Examples
    --------
    >>> import control as ct, fsmbench
    >>> from fsmbench.control import esrf_decentralised_controller
    >>> plant = fsmbench.physical_plant(parameters="true")
    >>> k = esrf_decentralised_controller()                 # ESRF study 9.2
    >>> L = fsmbench.loop_gain(plant, k)
    >>> L.input_labels, L.nstates                         # 18 plant + 8 controller
    (['Rh', 'Rv'], 26)
    >>> Ld = fsmbench.loop_gain(plant, ct.sample_system(k, 1e-4, method="tustin"))
    >>> Ld.dt, Ld.nstates                                  # exact delays, sampled
    (0.0001, 16)
    """
    from fsmbench.control.feedback import loop_gain as _loop

    return _loop(plant, controller, delays=delays, order=order)


def sensitivity(plant: PlantModel | ct.StateSpace | ct.TransferFunction,
                controller: ct.StateSpace | ct.TransferFunction | None = None, *,
                delays: Delays | None = None, order: int = 6) -> ct.StateSpace:
    """Sensitivity ``S = (I + L)^-1``: output disturbance to measurement, minimal.

    Arguments as :func:`loop_gain`. ``S + T = I``
    (:func:`complementary`); ``|S(j 2 pi f)|`` is the disturbance rejection.

    Examples
    --------
    >>> import numpy as np, fsmbench
    >>> from fsmbench.control import esrf_decentralised_controller
    >>> plant = fsmbench.physical_plant(parameters="true")
    >>> k = esrf_decentralised_controller()
    >>> S = fsmbench.sensitivity(plant, k)
    >>> bool(abs(S(2j * np.pi * 1.0)[0, 0]) < 3e-3)      # 1 Hz rejected 300-fold
    True
    """
    from fsmbench.control.feedback import sensitivity as _s

    return _s(plant, controller, delays=delays, order=order)


def complementary(plant: PlantModel | ct.StateSpace | ct.TransferFunction,
                  controller: ct.StateSpace | ct.TransferFunction | None = None, *,
                  delays: Delays | None = None, order: int = 6) -> ct.StateSpace:
    """Complementary sensitivity ``T = L (I + L)^-1``: reference (or minus sensor
    noise) to measurement, minimal. Arguments as :func:`loop_gain`.

    Examples
    --------
    >>> import numpy as np, fsmbench
    >>> from fsmbench.control import esrf_decentralised_controller
    >>> plant = fsmbench.physical_plant(parameters="true")
    >>> k = esrf_decentralised_controller()
    >>> S, T = fsmbench.sensitivity(plant, k), fsmbench.complementary(plant, k)
    >>> s = 2j * np.pi * np.array([1.0, 30.0, 300.0])
    >>> bool(np.allclose(S(s) + T(s), np.eye(2)[:, :, None]))
    True
    """
    from fsmbench.control.feedback import complementary as _t

    return _t(plant, controller, delays=delays, order=order)


def margins(plant: PlantModel | ct.StateSpace | ct.TransferFunction,
            controller: ct.StateSpace | ct.TransferFunction | None = None, *,
            channel: int | str | None = None, delays: Delays | None = None, order: int = 6,
            f_min_hz: float | None = None, f_max_hz: float | None = None) -> LoopMargins:
    """Gain, gain-reduction, phase, delay and modulus margins of one loop.

    Read on the loop's exact rational response (no polynomial roots): they agree
    with ``control.stability_margins`` on the same minimal loop, and stay right on
    a sampled loop with integrators, where its polynomials in ``z`` do not.

    Parameters
    ----------
    plant, controller, delays, order
        As :func:`loop_gain` (``controller`` None: ``plant`` is the loop ``L``).
    channel : int or str, optional
        For a MIMO loop, the loop ``L_ii`` with the others open, by index or by
        measurement name (``"Rh"``).
    f_min_hz, f_max_hz : float, optional
        Range searched [Hz]; a sampled loop stops at its Nyquist frequency.

    Returns
    -------
    LoopMargins
        ``gain_margin_db`` [dB], ``gain_reduction_margin_db`` [dB] (a
        conditionally stable loop's), ``phase_margin_deg`` [deg],
        ``delay_margin_s`` [s], ``modulus_margin`` [1], ``crossover_hz`` and
        ``crossovers_hz`` [Hz], ``phase_crossover_hz`` [Hz], ``stable``.

    Examples
    --------
    >>> import control as ct, fsmbench
    >>> from fsmbench.control import esrf_decentralised_controller
    >>> plant = fsmbench.physical_plant(parameters="true")
    >>> k = esrf_decentralised_controller()
    >>> m = fsmbench.margins(plant, k, channel="Rh")
    >>> round(m.gain_margin_db, 1), round(m.phase_margin_deg, 1), round(m.crossover_hz, 1)
    (25.5, 28.6, 27.1)
    >>> md = fsmbench.margins(plant, ct.sample_system(k, 1e-4, method="tustin"), channel="Rh")
    >>> round(md.phase_margin_deg, 1), round(md.delay_margin_s * 1e3, 2)   # [deg], [ms]
    (28.6, 2.93)
    """
    from fsmbench.control.feedback import margins as _m

    return _m(plant, controller, channel=channel, delays=delays, order=order,
              f_min_hz=f_min_hz, f_max_hz=f_max_hz)
