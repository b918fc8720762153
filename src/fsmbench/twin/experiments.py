"""The seed's experiments as protocols the twin runs.

Thirteen records, named and shaped as the seed loads them:

==========================  ======  ===========================================
file                        seed    what happens
==========================  ======  ===========================================
data_cal_pd_h / _v          2.1     slow Newport motion on one axis (4QD calibration)
data_uch / data_ucv         2.2-2.3 white noise on one Sercalo input, after 1 s off
data_unh / data_unv         2.4     white noise on one Newport input (from 3 s / 1.5 s)
data_huddle_test_1 .. _5    3       no excitation; Table 3 configurations
data_rep_h / data_rep_v     11      closed loop, periodic 1 s Newport motion
==========================  ======  ===========================================

Start times match the seed's trimming (``t0`` in its scripts); default
lengths give the seed's 100 s huddle tests after its 1 s trim.

:func:`played_experiment` replaces the noise of ``data_uch``, ``data_ucv``,
``data_unh`` or ``data_unv`` by given samples (a designed excitation,
:mod:`fsmbench.excite`), played from the same start time.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fsmbench.bench.esrf import esrf_decentralised_controller
from fsmbench.bench.params import Bench
from fsmbench.io.signals import EXPERIMENTS
from fsmbench.io.signals import MIN_DURATION_S as SIGNAL_MIN_DURATION_S
from fsmbench.sim.controller import feedback_controller
from fsmbench.sim.discretize import DiscretePlant
from fsmbench.sim.engine import DiscreteController
from fsmbench.sim.excitation import Excitation, SampledExcitation
from fsmbench.sim.plant import bench_discrete
from fsmbench.sim.stream import BenchStream

__all__ = [
    "EXPERIMENT_NAMES",
    "INPUT_EXPERIMENTS",
    "MIN_DURATION_S",
    "REALIZED_NOISE",
    "Excitation",
    "ExperimentSpec",
    "esrf_experiments",
    "esrf_feedback",
    "experiment_stream",
    "played_experiment",
    "with_duration",
]

@dataclass(frozen=True)
class ExperimentSpec:
    """One experiment of the seed.

    Attributes
    ----------
    name : str
        File stem, e.g. ``data_uch``.
    description : str
    seed_section : str
    duration_s : float
        Record length [s].
    excitations : tuple of Excitation
    closed_loop : bool
        Sercalo loop closed with the twin's controller.
    compensation_unit : bool
        Attocube environmental compensation unit on (Table 3).
    shielding : bool
        Aluminium shielding of the beam path (Table 3).
    """

    name: str
    description: str
    seed_section: str
    duration_s: float
    excitations: tuple[Excitation, ...]
    closed_loop: bool
    compensation_unit: bool
    shielding: bool

    def min_duration_s(self) -> float:
        """Shortest record the seed's processing of this experiment accepts [s]."""
        return MIN_DURATION_S[self.name]


# Identification excitation levels: white noise keeps the coil-voltage
# channel (Uch -> Vch: 119 V/V at DC, 1 kHz low pass) below 1.5 V rms, far
# from the 10 V rails, while the 4QD coherence stays above 0.9 up to 1 kHz.
UC_NOISE_RMS_V = 0.02
UN_NOISE_RMS_V = 0.1
CAL_AMPLITUDE_V = 2.0
CAL_FREQ_HZ = 0.2
REP_AMPLITUDE_V = 1.0  # seed Table 5: expected perturbation 1 V
REP_FREQ_HZ = 1.0  # seed 11: 1 s periods

# Shortest lengths: start time plus what the seed's scripts then need (the analysis's own
# minimum, io.signals).
MIN_DURATION_S = dict(SIGNAL_MIN_DURATION_S)

EXPERIMENT_NAMES = tuple(MIN_DURATION_S)


def _huddle(i: int, closed: bool, comp: bool, alu: bool) -> ExperimentSpec:
    parts = ["closed loop" if closed else "open loop"]
    if comp:
        parts.append("compensation unit")
    if alu:
        parts.append("aluminium shielding")
    return ExperimentSpec(
        name=f"data_huddle_test_{i}", description=f"Huddle test {i}: " + ", ".join(parts),
        seed_section="3, Table 3", duration_s=101.0, excitations=(), closed_loop=closed,
        compensation_unit=comp, shielding=alu)


def esrf_experiments(*, duration_s: float | None = None) -> tuple[ExperimentSpec, ...]:
    """The thirteen experiments, at the seed's lengths or all at ``duration_s``.

    Raises
    ------
    ValueError
        ``duration_s`` is shorter than an experiment's minimum (named).
    """
    specs = (
        ExperimentSpec("data_cal_pd_h", "4QD calibration, slow horizontal Newport motion",
                       "2.1", 11.0,
                       (Excitation("Unh", "sine", CAL_AMPLITUDE_V, 1.0, CAL_FREQ_HZ),),
                       False, True, False),
        ExperimentSpec("data_cal_pd_v", "4QD calibration, slow vertical Newport motion",
                       "2.1", 11.0,
                       (Excitation("Unv", "sine", CAL_AMPLITUDE_V, 1.0, CAL_FREQ_HZ),),
                       False, True, False),
        ExperimentSpec("data_uch", "Noise on the horizontal Sercalo input (Sercalo off 1 s)",
                       "2.2, 2.3", 31.0, (Excitation("Uch", "noise", UC_NOISE_RMS_V, 1.0),),
                       False, True, False),
        ExperimentSpec("data_ucv", "Noise on the vertical Sercalo input (Sercalo off 1 s)",
                       "2.2, 2.3", 31.0, (Excitation("Ucv", "noise", UC_NOISE_RMS_V, 1.0),),
                       False, True, False),
        ExperimentSpec("data_unh", "Noise on the horizontal Newport input", "2.4", 33.0,
                       (Excitation("Unh", "noise", UN_NOISE_RMS_V, 3.0),), False, True, False),
        ExperimentSpec("data_unv", "Noise on the vertical Newport input", "2.4", 31.5,
                       (Excitation("Unv", "noise", UN_NOISE_RMS_V, 1.5),), False, True, False),
        _huddle(1, False, False, False),
        _huddle(2, False, True, False),
        _huddle(3, True, True, False),
        _huddle(4, False, True, True),
        _huddle(5, True, True, True),
        ExperimentSpec("data_rep_h", "Repeatability, closed loop, 1 s periodic horizontal "
                       "Newport motion", "11", 42.0,
                       (Excitation("Unh", "sine", REP_AMPLITUDE_V, 1.0, REP_FREQ_HZ),),
                       True, True, True),
        ExperimentSpec("data_rep_v", "Repeatability, closed loop, 1 s periodic vertical "
                       "Newport motion", "11", 42.0,
                       (Excitation("Unv", "sine", REP_AMPLITUDE_V, 1.0, REP_FREQ_HZ),),
                       True, True, True),
    )
    return specs if duration_s is None else with_duration(specs, duration_s=duration_s)


def with_duration(specs: Sequence[ExperimentSpec], *,
                  duration_s: float) -> tuple[ExperimentSpec, ...]:
    """The same experiments, all ``duration_s`` long [s].

    Raises
    ------
    ValueError
        ``duration_s`` is shorter than an experiment's minimum (named).
    """
    too_short = [s.name for s in specs if duration_s < s.min_duration_s()]
    if too_short:
        need = max(MIN_DURATION_S[n] for n in too_short)
        raise ValueError(f"--duration {duration_s:g} s is too short for {', '.join(too_short)}: "
                         f"they need at least {need:g} s")
    return tuple(dataclasses.replace(s, duration_s=float(duration_s)) for s in specs)


#: The identification experiment of each DAC channel.
INPUT_EXPERIMENTS = {"Uch": "data_uch", "Ucv": "data_ucv", "Unh": "data_unh",
                     "Unv": "data_unv"}


def played_experiment(*, channel: str, samples_v: np.ndarray, fs_hz: float,
                      loop_from: int | None = None, duration_s: float | None = None,
                      description: str = "designed excitation") -> ExperimentSpec:
    """The identification experiment of ``channel`` with ``samples_v`` instead of the noise.

    Parameters
    ----------
    channel : str
        ``Uch``, ``Ucv``, ``Unh`` or ``Unv`` (gives ``data_uch`` ... ``data_unv``).
    samples_v : ndarray, shape (n,)
        Commands [V] at the bench's rate ``fs_hz``, played from the seed's start
        time of that experiment (1 s, 1 s, 3 s, 1.5 s).
    fs_hz : float
        Sampling rate [Hz] (the record's length is counted in its samples).
    loop_from : int, optional
        After the last sample: zeros (None) or ``samples_v[loop_from:]`` repeated.
    duration_s : float, optional
        Record length [s]; default: start time plus the samples (at least the
        experiment's minimum), so every sample is played once.
    description : str
        What is played, for the experiment's description.

    Raises
    ------
    ValueError
        Unknown channel, or ``duration_s`` shorter than the experiment's minimum.
    """
    if channel not in INPUT_EXPERIMENTS:
        raise ValueError(f"unknown input {channel!r}; an excitation file can drive "
                         f"{', '.join(INPUT_EXPERIMENTS)}")
    name = INPUT_EXPERIMENTS[channel]
    spec = next(s for s in esrf_experiments() if s.name == name)
    start = spec.excitations[0].start_s
    x = np.asarray(samples_v, dtype=float)
    ex = SampledExcitation(channel, "samples", float(np.sqrt(np.mean(x * x))), start,
                           samples_v=x, loop_from=loop_from)
    if duration_s is None:
        # Whole samples: the record ends with the last one played.
        duration_s = max((round(start * fs_hz) + x.size) / fs_hz, spec.min_duration_s())
    spec = dataclasses.replace(spec, excitations=(ex,),
                               description=f"{description} on {channel} (from {start:g} s)")
    return with_duration((spec,), duration_s=duration_s)[0]


#: ``realized`` keys of ``twin_truth.json`` and the :class:`~fsmbench.sim.stream.BenchBlock`
#: noise each is measured on.
REALIZED_NOISE = (("qd_noise_v", "qd"), ("newport_angle_noise_rad", "newport_angle"),
                  ("newport_metrology_noise_rad", "metrology"), ("vc_noise_v", "vc"),
                  ("qd_slow_disturbance_v", "qd_slow"))


def esrf_feedback(bench: Bench) -> DiscreteController:
    """The seed's decentralised controller of 9.2, Tustin at the converter rate, in the loop."""
    return feedback_controller(esrf_decentralised_controller(),
                               gd_v_per_rad=bench.nominal.quad_diode.gain_v_per_rad,
                               ts_s=bench.true.converter.ts_s, name="seed K (9.2)")


def experiment_stream(bench: Bench, spec: ExperimentSpec, *, seed: int,
                      plant: DiscretePlant | None = None,
                      controller: DiscreteController | None = None) -> BenchStream:
    """The twin's bench set up for one experiment (loop, environment, excitations).

    ``controller`` closes the loop when ``spec.closed_loop`` (default: :func:`esrf_feedback`).
    The Attocube is simulated unless the ESRF study's record of that name holds no ``Va``.
    """
    if spec.closed_loop and controller is None:
        controller = esrf_feedback(bench)
    return BenchStream(bench.true, seed=seed, name=spec.name,
                       compensation_unit=spec.compensation_unit, shielding=spec.shielding,
                       controller=controller if spec.closed_loop else None,
                       excitations=spec.excitations,
                       plant=bench_discrete(bench) if plant is None else plant,
                       distance=spec.name not in EXPERIMENTS
                       or "Va" in EXPERIMENTS[spec.name].required)
