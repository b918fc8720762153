"""The bench as a stream: advance it block by block, change its controller between blocks.

:class:`BenchStream` owns everything that has a state: the discrete plant
(with its delay lines), the controller, every noise and drift generator
(seeded, one stream per source), the excitations and the Attocube's
environment. ``step(n1)`` then ``step(n2)`` gives, sample for sample, the
bits of ``step(n1 + n2)``: the compiled loop hands its state back, numpy's
generators draw sample by sample, and every filter carries its state
(``tests/sim/test_stream.py`` checks it over random block lengths). The
twin's experiments, the identification's time-domain validation, the
design's verification and the live device all run on this one engine.

Controllers can be swapped between blocks without a bump in the command:

- closing the loop, or loading another controller, starts the new
  controller in the state of least norm whose first command equals the
  command the bench was holding (the previous controller's last output,
  or the held offset of an open loop), for the last error it read;
- opening the loop holds the controller's last command as a constant
  offset (``hold=True``), or drops it to zero (``hold=False``, what a
  protection trip does).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from fsmbench.bench.blocks import newport_beam_matrix
from fsmbench.bench.params import BenchParams
from fsmbench.sim.attocube import AttocubeStream, VaComponents
from fsmbench.sim.discretize import DiscretePlant
from fsmbench.sim.engine import DiscreteController, Quantiser, run_loop
from fsmbench.sim.excitation import Excitation, ExcitationStream
from fsmbench.sim.noise import (
    DriftStream,
    FlickerStream,
    MainsStream,
    WhiteStream,
    source_rng,
)
from fsmbench.sim.plant import ADC_CHANNELS, DAC_CHANNELS, INTERNAL_SIGNALS, twin_discrete

__all__ = ["BenchBlock", "BenchStream", "ControllerSwitch"]


@dataclass(frozen=True)
class BenchBlock:
    """The samples of one block.

    Attributes
    ----------
    start_sample : int
        Index of the block's first sample since the stream started.
    fs_hz : float
    dac : array (n, 4) [V]
        Commands as the DAC output them, :data:`DAC_CHANNELS` order.
    adc : array (n, 6) [V]
        ADC readings, :data:`ADC_CHANNELS` order.
    internal : array (n, 6) [rad]
        Noise-free mirror and beam angles, :data:`INTERNAL_SIGNALS` order.
    va : VaComponents or None
        The Attocube's distance and its parts [m]; None from a stream built without
        the Attocube (``BenchStream(distance=False)``).
    noise : dict of str to array (n, 2)
        The injected noises, h and v columns: ``newport_angle`` [rad],
        ``metrology`` [rad], ``qd`` [V] (white), ``vc`` [V], and
        ``qd_slow`` [V]: the real-bench 4QD disturbances (1/f noise, mains
        lines, offset drift; zeros when off).
    """

    start_sample: int
    fs_hz: float
    dac: np.ndarray
    adc: np.ndarray
    internal: np.ndarray
    va: VaComponents | None
    noise: dict[str, np.ndarray]

    @property
    def n(self) -> int:
        """Number of samples."""
        return int(self.dac.shape[0])

    def t_s(self) -> np.ndarray:
        """Bench time of every sample [s], shape (n,)."""
        return np.arange(self.start_sample, self.start_sample + self.n) / self.fs_hz

    def signal(self, name: str) -> np.ndarray:
        """One named signal: a DAC or ADC channel [V], ``Va`` [m] or an internal angle [rad]."""
        if name in DAC_CHANNELS:
            return self.dac[:, DAC_CHANNELS.index(name)]
        if name in ADC_CHANNELS:
            return self.adc[:, ADC_CHANNELS.index(name)]
        if name in INTERNAL_SIGNALS:
            return self.internal[:, INTERNAL_SIGNALS.index(name)]
        if name == "Va":
            if self.va is None:
                raise KeyError("no Va: this bench ran without the Attocube "
                               "(BenchStream(distance=False))")
            return self.va.total_m
        if name == "t":
            return self.t_s()
        raise KeyError(f"unknown signal {name!r}; known: t, Va, "
                       f"{', '.join(DAC_CHANNELS + ADC_CHANNELS + INTERNAL_SIGNALS)}")


@dataclass(frozen=True)
class ControllerSwitch:
    """What a controller change did to the command.

    Attributes
    ----------
    sample : int
        First sample under the new configuration.
    previous, current : str
        Controller names (``"open loop"`` when none).
    command_before_v, command_after_v : array (n_out,)
        The controlled channels' command just before the switch and the one
        the new configuration would give for the same error [V].
    """

    sample: int
    previous: str
    current: str
    command_before_v: np.ndarray
    command_after_v: np.ndarray

    @property
    def bump_v(self) -> float:
        """Largest change of the command the switch itself causes [V]."""
        return float(np.max(np.abs(self.command_after_v - self.command_before_v), initial=0.0))


class BenchStream:
    """The whole bench, advanced block by block (see the module notes).

    Parameters
    ----------
    params : BenchParams
        The bench simulated (the twin's ``bench.true``).
    seed : int
        Run seed; each noise source derives its own generator from it and ``name``.
    name : str
        Names the noise streams (the twin uses the experiment's name, so an
        experiment's record is the same whatever else runs).
    compensation_unit, shielding : bool
        Attocube environment (ESRF study Table 3).
    controller : DiscreteController, optional
        Closed loop from the first sample, controller state zero.
    excitations : sequence of Excitation
        Played from their start times.
    plant : DiscretePlant, optional
        :func:`~fsmbench.sim.plant.twin_discrete` of ``params`` (computed if not given).
    specialise : bool
        Run the loop compiled for this plant (:mod:`fsmbench.sim.codegen`).
    distance : bool
        Simulate the Attocube (``Va`` and its parts). False leaves it out (a record
        that holds no ``Va``): it reads the loop, never acts on it, and its noise
        sources have their own generators, so every other signal is the same bit for bit.
    """

    def __init__(self, params: BenchParams, *, seed: int, name: str,
                 compensation_unit: bool = True, shielding: bool = True,
                 controller: DiscreteController | None = None,
                 excitations: Sequence[Excitation] = (), plant: DiscretePlant | None = None,
                 specialise: bool = True, distance: bool = True) -> None:
        p = params
        self.params = p
        self.seed = seed
        self.name = name
        self.fs_hz = float(p.converter.fs_hz)
        self.plant = twin_discrete(p) if plant is None else plant
        self.converter = Quantiser(range_v=p.converter.range_v, bits=p.converter.bits)
        self._specialise = specialise
        self._k = 0
        self._z = np.zeros(self.plant.a.shape[0])
        self._controller = controller
        self._xk = np.zeros(0 if controller is None else controller.a.shape[0])
        self._hold = np.zeros(len(DAC_CHANNELS))
        self._last_adc = np.zeros(len(ADC_CHANNELS))
        self._excitations: list[ExcitationStream] = []
        self._references: list[ExcitationStream] = []
        self._n_added: dict[str, int] = {}
        for ex in excitations:
            self.add_excitation(ex)

        def white(source: str, rms: float) -> tuple[WhiteStream, WhiteStream]:
            return (WhiteStream(self.rng_for(f"{source}_h"), rms=rms),
                    WhiteStream(self.rng_for(f"{source}_v"), rms=rms))

        self._noise = {
            "newport_angle": white("newport_angle", p.newport.angle_noise_rms_rad),
            "metrology": white("metrology", p.newport.metrology_noise_rms_rad),
            "qd": (WhiteStream(self.rng_for("qd_h"), rms=p.quad_diode.noise_rms_v.h),
                   WhiteStream(self.rng_for("qd_v"), rms=p.quad_diode.noise_rms_v.v)),
            "vc": white("vc", p.voltage_amplifier.noise_rms_v),
        }
        self._qd_slow = self._qd_disturbances(p)
        self._adc_cubic = self._qd_cubic(p)
        self._beam = newport_beam_matrix(p).T
        self._gd = np.diag(p.quad_diode.gain_v_per_rad.as_array()).T
        self._attocube = AttocubeStream(p, compensation_unit=compensation_unit,
                                        shielding=shielding, fs_hz=self.fs_hz,
                                        rng_for=self.rng_for) if distance else None

    def _qd_disturbances(self, p: BenchParams) -> list[tuple[Any, Any]] | None:
        """The 4QD's 1/f noise, mains and drift streams (h, v), or None when all are off."""
        qd = p.quad_diode
        streams: list[tuple[Any, Any]] = []
        if np.any(qd.flicker_asd_v_per_rthz.as_array() != 0):
            streams.append(tuple(  # type: ignore[arg-type]
                FlickerStream(lambda i, a=axis: self.rng_for(f"qd_flicker_{a}_{i}"),
                              asd_at_1hz=qd.flicker_asd_v_per_rthz[axis],
                              f_min_hz=qd.flicker_min_hz, fs_hz=self.fs_hz)
                for axis in ("h", "v")))
        if any(a != 0 for a in qd.mains_amplitude_v):
            streams.append(tuple(  # type: ignore[arg-type]
                MainsStream(self.rng_for(f"qd_mains_{axis}"), fs_hz=self.fs_hz,
                            freq_hz=qd.mains_freq_hz, amplitudes=qd.mains_amplitude_v,
                            wander_rad_per_rts=qd.mains_phase_wander_rad_per_rts)
                for axis in ("h", "v")))
        if np.any(qd.offset_drift_v_per_s.as_array() != 0) or np.any(
                qd.offset_random_walk_v_per_rts.as_array() != 0):
            streams.append(tuple(  # type: ignore[arg-type]
                DriftStream(self.rng_for(f"qd_drift_{axis}"), fs_hz=self.fs_hz,
                            rate_per_s=qd.offset_drift_v_per_s[axis],
                            random_walk_per_rts=qd.offset_random_walk_v_per_rts[axis])
                for axis in ("h", "v")))
        return streams or None

    @staticmethod
    def _qd_cubic(p: BenchParams) -> np.ndarray | None:
        """Cubic coefficient of each ADC channel [1/V**2]: the 4QD's compression, or None.

        ``V = V_lin (1 - k (V_lin / V_fs)**2)``: the response falls short of the
        linear one by ``k = nonlinearity_pct / 100`` at the full swing
        ``V_fs = |gain| * nonlinearity_full_swing_rad`` (the calibration's).
        """
        qd = p.quad_diode
        if qd.nonlinearity_pct == 0.0:
            return None
        cubic = np.zeros(len(ADC_CHANNELS))
        k = qd.nonlinearity_pct / 100.0
        for axis, name in (("h", "Vph"), ("v", "Vpv")):
            v_fs = abs(qd.gain_v_per_rad[axis]) * qd.nonlinearity_full_swing_rad
            cubic[ADC_CHANNELS.index(name)] = -k / v_fs**2
        return cubic

    # -- configuration -------------------------------------------------------------

    def rng_for(self, source: str) -> np.random.Generator:
        """The generator of one named source of this stream."""
        return source_rng(self.seed, self.name, source)

    @property
    def samples_done(self) -> int:
        """Samples simulated so far."""
        return self._k

    @property
    def time_s(self) -> float:
        """Bench time of the next sample [s]."""
        return self._k / self.fs_hz

    @property
    def controller(self) -> DiscreteController | None:
        """The controller in the loop (None: open loop)."""
        return self._controller

    @property
    def held_command_v(self) -> np.ndarray:
        """Constant command added to every DAC channel since the loop was opened [V], (4,)."""
        return self._hold.copy()

    def add_excitation(self, excitation: Excitation, *, source: str | None = None,
                       at: str = "output") -> float:
        """Play ``excitation`` from its start time; returns its peak [V].

        Parameters
        ----------
        excitation : Excitation
        source : str, optional
            Name of its noise stream; default ``excitation_<channel>`` for the
            channel's first excitation (the twin's experiments), then
            ``excitation_<channel>_<i>``.
        at : {"output", "reference"}
            ``"output"``: added to the DAC command of its channel (the
            controller's output in closed loop). ``"reference"``: added to the
            loop's reference on the ADC channel the controller pairs with that
            DAC channel (``Vph`` for ``Uch`` with the Sercalo controllers), in
            4QD volts: the controller acts on ``reading - r``. In open loop a
            reference does nothing. The block's ADC samples stay the sensor's
            readings (see :meth:`step`).

        Raises
        ------
        ValueError
            Unknown channel or place, or an excitation whose peak leaves the
            DAC's range (the ADC's for a reference).
        """
        if excitation.channel not in DAC_CHANNELS:
            raise ValueError(f"unknown excitation channel {excitation.channel!r}; "
                             f"the DAC drives {', '.join(DAC_CHANNELS)}")
        if at not in ("output", "reference"):
            raise ValueError(f"an excitation is added at the output or the reference, not {at!r}")
        i = self._n_added.get(excitation.channel, 0)
        self._n_added[excitation.channel] = i + 1
        if source is None:
            source = f"excitation_{excitation.channel}" + (f"_{i}" if i else "")
        stream = ExcitationStream(excitation, fs_hz=self.fs_hz, rng=self.rng_for(source))
        peak = stream.peak_v()
        limit = self.params.converter.range_v / 2
        if peak > limit:
            where = "DAC" if at == "output" else "ADC"
            raise ValueError(f"excitation on {excitation.channel} peaks at {peak:.3g} V, beyond "
                             f"the {where}'s ±{limit:g} V range")
        (self._excitations if at == "output" else self._references).append(stream)
        return peak

    def set_plant(self, plant: DiscretePlant) -> None:
        """Step ``plant`` from the next sample, from the state the bench is in.

        The bench changing under a running loop (a resonance drifting): ``plant``
        must have the same states, inputs and outputs (the twin's plant of other
        parameters, :func:`~fsmbench.sim.plant.twin_discrete`), so that the state
        carries over; the compiled loop is the generic one.

        Raises
        ------
        ValueError
            Another state dimension or other signals.
        """
        if (plant.a.shape != self.plant.a.shape or plant.input_names != self.plant.input_names
                or plant.output_names != self.plant.output_names):
            raise ValueError("the new plant must have the same states, inputs and outputs as the "
                             f"running one ({self.plant.a.shape[0]} states)")
        self.plant = plant
        self._specialise = False

    def set_environment(self, *, compensation_unit: bool, shielding: bool) -> None:
        """Switch the Attocube's compensation unit and the beam path's shielding (Table 3)."""
        if self._attocube is not None:
            self._attocube.set_environment(compensation_unit=compensation_unit,
                                           shielding=shielding)

    def clear_excitations(self) -> None:
        """Stop every excitation (and reference) from the next sample."""
        self._excitations.clear()
        self._references.clear()

    def _reference_samples(self, k0: int, n: int) -> np.ndarray | None:
        """The references on the ADC channels the controller reads, (n, n_adc) [V], or None.

        Every reference stream advances each block (its noise and filter state stay
        those of one run); it acts only while a controller pairs its channel.
        """
        if not self._references:
            return None
        ref = np.zeros((n, len(ADC_CHANNELS)))
        ctrl = self._controller
        for ex in self._references:
            samples = ex.next(k0, n)
            if ctrl is None:
                continue
            j = DAC_CHANNELS.index(ex.excitation.channel)
            if j in ctrl.dac_outputs:
                ref[:, ctrl.adc_inputs[list(ctrl.dac_outputs).index(j)]] += samples
        return ref

    def _controller_command(self, controller: DiscreteController | None,
                            xk: np.ndarray) -> np.ndarray:
        """The command (4,) [V] the configuration adds for the last error read."""
        u = self._hold.copy()
        if controller is not None:
            e = self._last_adc[list(controller.adc_inputs)]
            u[list(controller.dac_outputs)] += controller.c @ xk + controller.d @ e
        return u

    def set_controller(self, controller: DiscreteController | None, *,
                       hold: bool = True) -> ControllerSwitch:
        """Close the loop with ``controller``, swap it, or open the loop (``None``).

        Parameters
        ----------
        controller : DiscreteController or None
        hold : bool
            When opening: keep the last command as a constant offset (True)
            or return it to zero (False). When closing: start from the held
            command (True) or from zero (False).
        """
        before = self._controller_command(self._controller, self._xk)
        previous = "open loop" if self._controller is None else self._controller.name
        target = before if hold else np.zeros_like(before)
        if controller is None:
            self._hold = target
            self._xk = np.zeros(0)
        else:
            out = list(controller.dac_outputs)
            e = self._last_adc[list(controller.adc_inputs)]
            want = target[out]
            # Least-norm state giving the wanted first command for the last error.
            xk, *_ = np.linalg.lstsq(controller.c, want - controller.d @ e, rcond=None) \
                if controller.a.shape[0] else (np.zeros(0),)
            self._xk = np.asarray(xk, dtype=float)
            hold_v = target.copy()
            hold_v[out] = 0.0
            self._hold = hold_v
        self._controller = controller
        after = self._controller_command(controller, self._xk)
        return ControllerSwitch(sample=self._k, previous=previous,
                                current="open loop" if controller is None else controller.name,
                                command_before_v=before, command_after_v=after)

    # -- running -------------------------------------------------------------------

    def step(self, n: int) -> BenchBlock:
        """Advance the bench ``n`` samples and return them."""
        if n < 0:
            raise ValueError(f"n must be >= 0, got {n}")
        k0 = self._k

        def pair(name: str) -> np.ndarray:
            h, v = self._noise[name]
            return np.column_stack([h.next(n), v.next(n)])

        # Same draws, same order of arithmetic as the whole-record twin always made.
        n_theta = pair("newport_angle")
        n_metro = pair("metrology")
        n_qd = pair("qd")
        n_vc = pair("vc")
        beam_noise = n_theta @ self._beam
        qd_noise = n_qd + beam_noise @ self._gd
        n_slow = np.zeros((n, 2))
        if self._qd_slow is not None:
            for h, v in self._qd_slow:
                n_slow += np.column_stack([h.next(n), v.next(n)])
            qd_noise = qd_noise + n_slow
        adc_noise = np.column_stack([n_vc, qd_noise,
                                     (n_theta + n_metro)
                                     * self.params.newport.metrology_sign.as_array()
                                     / self.params.newport.metrology_gain_rad_per_v])
        u_ext = np.zeros((n, len(DAC_CHANNELS)))
        for ex in self._excitations:
            u_ext[:, DAC_CHANNELS.index(ex.excitation.channel)] += ex.next(k0, n)
        if np.any(self._hold != 0.0):
            u_ext += self._hold[None, :]
        ref = self._reference_samples(k0, n)
        if ref is not None:
            # The controller reads reading - r: the reference enters where the ADC noise does.
            adc_noise = adc_noise - ref
        loop = run_loop(self.plant, u_ext=u_ext, adc_noise=adc_noise, adc=self.converter,
                        dac=self.converter, controller=self._controller,
                        n_adc=len(ADC_CHANNELS), z0=self._z,
                        xk0=self._xk if self._controller is not None else None,
                        specialise=self._specialise, adc_cubic=self._adc_cubic)
        self._z = loop.plant_state
        if self._controller is not None:
            self._xk = loop.controller_state
        if n:
            self._last_adc = loop.adc[-1].copy()
        adc = loop.adc
        if ref is not None:
            # What the sensor read (the controller saw it less the reference), on the ADC's grid.
            adc = self.converter.apply(loop.adc + ref)
        internal = loop.internal
        theta_c = internal[:, [INTERNAL_SIGNALS.index("theta_ch"),
                               INTERNAL_SIGNALS.index("theta_cv")]]
        theta_n = internal[:, [INTERNAL_SIGNALS.index("theta_nh"),
                               INTERNAL_SIGNALS.index("theta_nv")]] + n_theta
        va = (None if self._attocube is None
              else self._attocube.next(theta_c_rad=theta_c, theta_n_rad=theta_n))
        self._k += n
        return BenchBlock(start_sample=k0, fs_hz=self.fs_hz, dac=loop.dac, adc=adc,
                          internal=internal, va=va,
                          noise={"newport_angle": n_theta, "metrology": n_metro, "qd": n_qd,
                                 "vc": n_vc, "qd_slow": n_slow})

    def run(self, n: int, *, block: int | None = None,
            on_block: Callable[[BenchBlock], None] | None = None) -> BenchBlock:
        """Advance ``n`` samples (in blocks of ``block``) and return them as one block."""
        size = n if block is None else max(1, block)
        parts: list[BenchBlock] = []
        done = 0
        while done < n or (n == 0 and not parts):
            b = self.step(min(size, n - done))
            if on_block is not None:
                on_block(b)
            parts.append(b)
            done += b.n
            if n == 0:
                break
        return concatenate_blocks(parts)


def concatenate_blocks(blocks: Sequence[BenchBlock]) -> BenchBlock:
    """Consecutive blocks as one."""
    if len(blocks) == 1:
        return blocks[0]
    first = blocks[0]

    def cat(arrays: list[np.ndarray]) -> np.ndarray:
        return np.concatenate(arrays, axis=0)

    va = None if first.va is None else VaComponents(
        **{f: cat([getattr(b.va, f) for b in blocks]) for f in
           ("geometric_m", "perpendicular_m", "air_m", "frame_m", "noise_m", "total_m")})
    return BenchBlock(start_sample=first.start_sample, fs_hz=first.fs_hz,
                      dac=cat([b.dac for b in blocks]), adc=cat([b.adc for b in blocks]),
                      internal=cat([b.internal for b in blocks]), va=va,
                      noise={k: cat([b.noise[k] for b in blocks]) for k in first.noise})
