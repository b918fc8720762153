"""The control study of the ESRF study (sections 5 to 10) in one call.

:func:`design_study` runs, on one plant (physical or identified):

1. the plant analysis (5.1 coprime factors, 6 scaling and the 6.1 objective,
   7.2 RGA and singular values, 7.3 static gain);
2. the ESRF study's decentralised controller of 9.2, verified;
3. fsmbench's own controller, designed on the plant with its delay and
   verified, then checked over the perturbed set (resonance ±5 %, damping
   ×0.5 and ×2); the ESRF study's controller goes through the same set;
4. the Newport alignment loop of 10.2 on the Newport path ``Un -> R``;
5. integral force feedback of 8.2;
6. the Newport command to beam angle transfer with each Sercalo loop closed
   (Fig. 42).

:meth:`DesignResult.write` saves ``controllers.mat``, ``controllers_sos.json`` and
``fsmbench_load.m`` (MATLAB/Octave: ``[G, K, Kd] = fsmbench_load(OUT)``).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import control as ct
import numpy as np

from fsmbench.atomic import atomic_write_text
from fsmbench.bench.blocks import PlantModel
from fsmbench.bench.esrf import esrf_decentralised_controller, iff_controller, newport_controller
from fsmbench.bench.params import Bench
from fsmbench.checks import Check
from fsmbench.control.analysis import (
    ControlObjective,
    PlantAnalysis,
    analyse_plant,
    control_objective,
)
from fsmbench.control.antiwindup_loop import saturating_step
from fsmbench.control.design import (
    DesignOptions,
    FsmDesign,
    Robustness,
    design_controller,
    robustness,
)
from fsmbench.control.export import (
    DEFAULT_DISCRETISATION,
    InputScaling,
    write_controllers_mat,
    write_sos_json,
)
from fsmbench.control.float32_loop import float32_closed_loop
from fsmbench.control.freq import evaluate_ss, plain_json
from fsmbench.control.iff import IffAnalysis, iff_analysis
from fsmbench.control.loops import LoopAnalysis, LoopOptions, analyse_loop, newport_to_beam
from fsmbench.control.responses import ClosedLoopResponses, closed_loop_responses

__all__ = [
    "CONTROLLERS_MAT",
    "CONTROLLERS_SOS_JSON",
    "MATLAB_LOADER",
    "RESPONSE_DURATION_S",
    "DesignResult",
    "NewportToBeam",
    "StudyOptions",
    "design_study",
]

CONTROLLERS_MAT = "controllers.mat"
CONTROLLERS_SOS_JSON = "controllers_sos.json"
MATLAB_LOADER = "fsmbench_load.m"
#: Length of the closed-loop step responses [s]: the settling of both controllers.
RESPONSE_DURATION_S = 0.25

_DESCRIPTIONS = {
    "seed_controller": "ESRF study 9.2 decentralised controller (restored Kh, Kv); Rh,Rv -> "
                       "Uch,Ucv",
    "fsmbench_controller": "fsmbench loop-shaped controller; Rh,Rv -> Uch,Ucv",
    "newport_controller": "ESRF study 10.2 Newport alignment controller; Rh,Rv -> Unh,Unv",
    "iff_controller": "ESRF study 8.2 integral force feedback Kppf; Vch,Vcv -> Uch,Ucv, ADDED "
                      "to the command (u = +Kppf y); unstable on this bench, kept for reference",
}


@dataclass(frozen=True)
class StudyOptions:
    """Options of :func:`design_study`.

    Attributes
    ----------
    design : DesignOptions
        Requirements and robust set of the fsmbench controller.
    loop : LoopOptions
        Verification settings (Padé order, Tustin sample time, grids).
    newport_crossover_hz : float
        Crossover of the Newport loop (ESRF study 10.2: 10 Hz).
    newport_lead_ratio : float
        Lead ratio ``h`` of the Newport loop (ESRF study: 2).
    with_seed_robustness : bool
        Also run the ESRF study's controller over the perturbed set.
    """

    design: DesignOptions = field(default_factory=DesignOptions)
    loop: LoopOptions = field(default_factory=LoopOptions)
    newport_crossover_hz: float = 10.0
    newport_lead_ratio: float = 2.0
    with_seed_robustness: bool = True

    def to_json(self) -> dict[str, Any]:
        """Plain numbers."""
        return plain_json({"design": self.design.to_json(), "loop": self.loop.__dict__,
                           "newport_crossover_hz": self.newport_crossover_hz,
                           "newport_lead_ratio": self.newport_lead_ratio,
                           "with_seed_robustness": self.with_seed_robustness})


@dataclass(frozen=True, eq=False)
class NewportToBeam:
    """Newport command to beam angle, open and with each Sercalo loop closed (Fig. 42).

    Attributes
    ----------
    f_hz : array, shape (n,)
    open_loop : array, complex, shape (n, 2, 2)
        ``Unh, Unv -> Rh, Rv`` [rad/V].
    closed : dict name -> array, complex, shape (n, 2, 2)
        ``S Gn`` with the named Sercalo controller.
    """

    f_hz: np.ndarray
    open_loop: np.ndarray
    closed: dict[str, np.ndarray]

    def attenuation_at(self, f_hz: float, name: str) -> tuple[float, float]:
        """``|closed/open|`` of the diagonal paths (h, v) at ``f_hz`` (interpolated in log)."""
        out = []
        for i in range(2):
            ratio = np.abs(self.closed[name][:, i, i]) / np.abs(self.open_loop[:, i, i])
            out.append(float(np.exp(np.interp(np.log(f_hz), np.log(self.f_hz), np.log(ratio)))))
        return out[0], out[1]


@dataclass(frozen=True, eq=False)
class DesignResult:
    """Everything :func:`design_study` computed.

    Attributes
    ----------
    plant_source : str
    objective : ControlObjective
    plant : PlantAnalysis
    seed : LoopAnalysis
        The ESRF study's controller of 9.2 on the plant.
    fsmbench : LoopAnalysis
        fsmbench's controller on the plant it was designed on.
    design : FsmDesign
    newport : LoopAnalysis
        The Newport loop of 10.2.
    iff : IffAnalysis
    robustness : Robustness
        fsmbench's controller over the perturbed set.
    seed_robustness : Robustness or None
    newport_to_beam : NewportToBeam
    controllers : dict name -> control.StateSpace
        ``seed_controller``, ``fsmbench_controller``, ``newport_controller``,
        ``iff_controller`` (continuous).
    options : StudyOptions
    qd_gain_v_per_rad : tuple of 2 floats
        4QD gain ``Gd`` (h, v) of ``plant`` [V/rad]: a target reading the 4QD
        voltage divides by it to get the controllers' input ``R``.
    responses : dict name -> ClosedLoopResponses
        Closed-loop step and Newport-disturbance responses, time and frequency,
        of ``seed_controller`` and ``fsmbench_controller``
        (:func:`fsmbench.control.responses.closed_loop_responses`).
    saturating_steps : dict "name/axis" -> SaturatingStep
        The twin's reference step beyond the DAC's reach without and with
        anti-windup (:func:`fsmbench.control.antiwindup_loop.saturating_step`), per
        controller and axis, e.g. ``"fsmbench_controller/h"``.
    float32_loops : dict name -> Float32Loop
        The twin's closed-loop poles with each exported form rounded to
        float32 (:func:`fsmbench.control.float32_loop.float32_closed_loop`).
    """

    plant_source: str
    objective: ControlObjective
    plant: PlantAnalysis
    seed: LoopAnalysis
    fsmbench: LoopAnalysis
    design: FsmDesign
    newport: LoopAnalysis
    iff: IffAnalysis
    robustness: Robustness
    seed_robustness: Robustness | None
    newport_to_beam: NewportToBeam
    controllers: dict[str, ct.StateSpace]
    options: StudyOptions
    qd_gain_v_per_rad: tuple[float, float]
    responses: dict[str, ClosedLoopResponses] = field(default_factory=dict)
    saturating_steps: dict[str, Any] = field(default_factory=dict)
    float32_loops: dict[str, Any] = field(default_factory=dict)

    @property
    def loops(self) -> dict[str, LoopAnalysis]:
        """The three verified loops by JSON key."""
        return {"seed_controller": self.seed, "fsmbench_controller": self.fsmbench,
                "newport_controller": self.newport}

    def to_json(self) -> dict[str, Any]:
        """The study as plain numbers (NaN and inf as None).

        Keys: ``objective``, ``plant_analysis``, ``seed_controller``,
        ``fsmbench_controller`` (with ``design``), ``newport_controller``, each
        with ``{h,v}.{stable, gain_margin_db, phase_margin_deg, modulus_margin,
        crossover_hz, sensitivity_at_1hz}`` and ``meets_objective``; ``iff``;
        ``robustness`` (fsmbench's controller) and ``seed_robustness``;
        ``newport_to_beam``; ``options``; ``saturating_step`` (per controller and
        axis, :meth:`fsmbench.control.antiwindup_loop.SaturatingStep.to_json`);
        ``float32_closed_loop`` (per controller,
        :meth:`fsmbench.control.float32_loop.Float32Loop.to_json`).
        """
        f0 = self.objective.frequency_hz
        fsm = {**self.fsmbench.to_json(), "design": self.design.to_json()}
        n2b = {name: dict(zip(("h", "v"), self.newport_to_beam.attenuation_at(f0, name),
                              strict=True))
               for name in self.newport_to_beam.closed}
        return plain_json({
            "plant_source": self.plant_source,
            "objective": self.objective.to_json(),
            "plant_analysis": self.plant.to_json(),
            "seed_controller": self.seed.to_json(),
            "fsmbench_controller": fsm,
            "newport_controller": self.newport.to_json(),
            "iff": self.iff.to_json(),
            "robustness": self.robustness.to_json(),
            "seed_robustness": (None if self.seed_robustness is None
                                else self.seed_robustness.to_json()),
            "newport_to_beam": {"attenuation_at_1hz": n2b},
            "options": self.options.to_json(),
            "checks": [c.to_json() for c in self.checks],
            "saturating_step": _steps_json(self.saturating_steps),
            "float32_closed_loop": {k: v.to_json() for k, v in self.float32_loops.items()},
        })

    @property
    def checks(self) -> tuple[Check, ...]:
        """The optional analyses' checks: each computed, or failed with its reason."""
        return self.plant.checks

    def write(self, out_dir: str | Path, *,
              method: str = DEFAULT_DISCRETISATION) -> list[Path]:
        """Write ``controllers.mat``, ``controllers_sos.json`` and ``fsmbench_load.m``.

        Parameters
        ----------
        out_dir : str or Path
            Folder (created if missing); every file is written atomically.
        method : {"tustin_prewarp", "tustin"}
            Discretisation of ``Kd`` and of the sections
            (:data:`fsmbench.control.export.DISCRETISATIONS`): by default Tustin
            prewarped at each section's notch, ``"tustin"`` for the ESRF study's plain Tustin.

        Returns
        -------
        list of Path
            The three files, in that order.

        Notes
        -----
        The SOS file holds the three feedback controllers (the IFF controller,
        unstable on this bench, is only in the MAT-file). ``fsmbench_load.m``
        turns ``plant.mat`` (written by the identification into the same
        folder in ``fsmbench study``) and ``controllers.mat`` into ``ss`` objects.
        """
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        ts = self.options.loop.ts_s
        scaling = InputScaling(qd_gain_v_per_rad=self.qd_gain_v_per_rad,
                               plant_source=self.plant_source)
        mat = write_controllers_mat(out / CONTROLLERS_MAT, self.controllers, ts_s=ts,
                                    method=method, descriptions=_DESCRIPTIONS, scaling=scaling)
        sos = write_sos_json(out / CONTROLLERS_SOS_JSON,
                             {k: v for k, v in self.controllers.items() if k != "iff_controller"},
                             scaling=scaling, ts_s=ts, method=method, descriptions=_DESCRIPTIONS)
        loader = resources.files("fsmbench").joinpath("matlab", MATLAB_LOADER).read_text(
            encoding="utf-8")
        return [mat, sos, atomic_write_text(out / MATLAB_LOADER, loader)]


def _steps_json(steps: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """``{"controller/axis": step}`` as ``{controller: {axis: step.to_json()}}``."""
    out: dict[str, dict[str, Any]] = {}
    for key, step in steps.items():
        name, _, axis = key.partition("/")
        out.setdefault(name, {})[axis] = step.to_json()
    return out


def _qd_gain(plant: PlantModel) -> tuple[float, float]:
    """Diagonal of ``Gd`` (h, v) [V/rad], sign included."""
    gd = np.diag(np.asarray(plant.blocks["Gd"].D, dtype=float))
    return float(gd[0]), float(gd[1])


def _gd_scaling(plant: PlantModel) -> tuple[list[float], list[float]]:
    """Output scales ``1/|Gd|`` [rad/V] and unit input scales: ``b(G, K)`` in 5.1's units."""
    gd = np.abs(np.diag(np.asarray(plant.blocks["Gd"].D, dtype=float)))
    return [float(1.0 / x) for x in gd], [1.0, 1.0]


def design_study(plant: PlantModel, *, bench: Bench,
                 options: StudyOptions | None = None) -> DesignResult:
    """Analyse ``plant``, verify the ESRF study's controllers, design and verify fsmbench's.

    Parameters
    ----------
    plant : PlantModel
        Physical (``physical_plant(bench.true)``) or identified
        (``identify(...).plant``); its input delays are part of every loop.
    bench : Bench
        ``bench.nominal`` supplies Table 5 and the 6.1 objective.
    options : StudyOptions, optional

    Returns
    -------
    DesignResult
    """
    opts = options or StudyOptions()
    objective: ControlObjective = control_objective(bench.nominal)
    plant_an = analyse_plant(plant, params=bench.nominal)
    scaling = _gd_scaling(plant)

    k_seed = esrf_decentralised_controller()
    seed = analyse_loop(plant, k_seed, objective=objective, name="seed_controller",
                        scaling=scaling, options=opts.loop)
    design = design_controller(plant, objective=objective, options=opts.design)
    fsm = analyse_loop(plant, design.controller, objective=objective,
                       name="fsmbench_controller", scaling=scaling, options=opts.loop)

    gn0 = np.real(evaluate_ss(plant.subsystem(outputs=["Rh", "Rv"], inputs=["Unh", "Unv"]),
                              np.zeros(1))[0])
    k_newport = newport_controller(gn0_rad_per_v=(float(gn0[0, 0]), float(gn0[1, 1])),
                                   crossover_hz=opts.newport_crossover_hz,
                                   lead_ratio=opts.newport_lead_ratio)
    newport = analyse_loop(plant, k_newport, objective=objective, name="newport_controller",
                           scaling=scaling, options=opts.loop)
    iff = iff_analysis(plant, pade_order=opts.loop.pade_order)

    rob_opts = dataclasses.replace(opts.loop, per_decade=60)
    rob = robustness(plant, design.controller, objective=objective,
                     frequency_scales=opts.design.frequency_scales,
                     damping_scales=opts.design.damping_scales, options=rob_opts)
    seed_rob = (robustness(plant, k_seed, objective=objective,
                           frequency_scales=opts.design.frequency_scales,
                           damping_scales=opts.design.damping_scales, options=rob_opts)
                if opts.with_seed_robustness else None)

    f = np.logspace(-1, np.log10(5e3), 800)
    n2b = NewportToBeam(f_hz=f, open_loop=newport_to_beam(plant, None, f),
                        closed={"seed_controller": newport_to_beam(plant, k_seed, f),
                                "fsmbench_controller": newport_to_beam(plant, design.controller,
                                                                       f)})
    controllers = {"seed_controller": k_seed, "fsmbench_controller": design.controller,
                   "newport_controller": k_newport, "iff_controller": iff_controller()}
    responses = {
        name: closed_loop_responses(plant, controllers[name], name=words, f_hz=f,
                                    duration_s=RESPONSE_DURATION_S, dt_s=opts.loop.ts_s,
                                    pade_order=opts.loop.pade_order)
        for name, words in (("seed_controller", "the ESRF study's controller"),
                            ("fsmbench_controller", "fsmbench's controller"))}

    who = (("seed_controller", "the ESRF study's controller"),
           ("fsmbench_controller", "fsmbench's controller"))
    steps = {f"{name}/{axis}": saturating_step(bench, controllers[name], name=words, axis=axis)
             for name, words in who for axis in ("h", "v")}
    f32 = {name: float32_closed_loop(bench, controllers[name], name=words) for name, words in who}
    return DesignResult(plant_source=plant.source, objective=objective, plant=plant_an,
                        seed=seed, fsmbench=fsm, design=design, newport=newport, iff=iff,
                        robustness=rob, seed_robustness=seed_rob, newport_to_beam=n2b,
                        controllers=controllers, options=opts,
                        qd_gain_v_per_rad=_qd_gain(plant), responses=responses,
                        saturating_steps=steps, float32_loops=f32)
