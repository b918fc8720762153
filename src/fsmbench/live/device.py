"""``FsmBench``: the bench as a Tango device (PyTango high-level API).

A thin layer over :class:`fsmbench.live.core.LiveBench`: every attribute
reads a view the bench keeps up to date, every command calls one of its
methods. A bad argument raises ``ValueError`` with one line saying what is
wrong; PyTango hands it to the client as a ``DevFailed`` and the bench keeps
running.

Device properties (set by ``fsmbench serve`` or in the Tango database):
``Backend`` (``twin`` or ``playback``), ``PlaybackFolder``, ``ParamsFile``
(a bench TOML; empty: the packaged bench), ``BenchFolder`` (an identification
folder: the twin simulates the bench identified there), ``Seed``, ``Speed``
and ``OutputFolder``.

This module imports PyTango: it is the ``fsmbench[tango]`` extra. The
rest of fsmbench imports without it.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from tango import AttrWriteType, DevState, EnsureOmniThread
from tango.server import Device, attribute, command, device_property

from fsmbench.bench.params import default_bench, load_bench
from fsmbench.live.core import LiveBench

__all__ = ["DEFAULT_DEVICE_NAME", "FsmBench"]

DEFAULT_DEVICE_NAME = "fsmbench/bench/1"
_MAX_SPECTRUM = 100_000
_STATES = {"ON": DevState.ON, "RUNNING": DevState.RUNNING, "MOVING": DevState.MOVING,
           "ALARM": DevState.ALARM, "FAULT": DevState.FAULT}
_SCALAR_EVENTS: dict[str, Any] = {"polling_period": 1000, "period": "1000"}


class FsmBench(Device):
    """The fast-steering-mirror bench, live (the twin by default)."""

    Backend = device_property(dtype=str, default_value="twin",
                              doc="twin (the simulated bench) or playback (a folder replayed)")
    PlaybackFolder = device_property(dtype=str, default_value="",
                                     doc="folder of recordings for the playback backend")
    ParamsFile = device_property(dtype=str, default_value="",
                                 doc="bench parameters (TOML); empty: the packaged bench")
    BenchFolder = device_property(dtype=str, default_value="",
                                  doc="identification folder (fsmbench identify or study): the "
                                      "twin simulates that bench; empty: the bench file's")
    Seed = device_property(dtype=int, default_value=0, doc="seed of every noise source")
    Speed = device_property(dtype=float, default_value=1.0,
                            doc="bench seconds per wall-clock second")
    OutputFolder = device_property(dtype=str, default_value="fsmbench-live",
                                   doc="where RunExperiment and Record write")

    # -- life cycle ----------------------------------------------------------------

    def init_device(self) -> None:
        super().init_device()
        self.set_change_event("State", True, False)
        self.set_change_event("LoopClosed", True, False)
        bench = load_bench(self.ParamsFile) if self.ParamsFile else default_bench()
        if self.BenchFolder:
            from fsmbench.sim.identified import identified_bench

            bench = identified_bench(self.BenchFolder, bench=bench)
        self.bench = LiveBench(bench, backend=self.Backend,
                               playback_folder=self.PlaybackFolder or None, seed=self.Seed,
                               speed=self.Speed, output_folder=self.OutputFolder,
                               on_state=self._state_changed)
        self._loop_closed = False
        self.set_state(DevState.ON)
        self.set_status(self.bench.status)
        self.bench.start(thread_init=EnsureOmniThread)

    def delete_device(self) -> None:
        bench = getattr(self, "bench", None)
        if bench is not None:
            bench.stop()

    def _state_changed(self, state: str) -> None:
        # Called from the bench's thread (inside EnsureOmniThread).
        self.set_state(_STATES[state])
        self.set_status(self.bench.status)
        self.push_change_event("State", _STATES[state])
        closed = self.bench.loop_closed
        if closed != self._loop_closed:
            self._loop_closed = closed
            self.push_change_event("LoopClosed", closed)

    def dev_state(self) -> DevState:
        return _STATES[self.bench.state]

    def dev_status(self) -> str:
        return self.bench.status

    # -- scalar attributes ---------------------------------------------------------

    @attribute(dtype=float, unit="rad", format="%.3e",
               doc="horizontal beam angle on the 4QD, mean over the last 0.1 s", **_SCALAR_EVENTS)
    def BeamAngleH(self) -> float:
        return self.bench.monitor.beam_angle_rad()[0]

    @attribute(dtype=float, unit="rad", format="%.3e",
               doc="vertical beam angle on the 4QD, mean over the last 0.1 s", **_SCALAR_EVENTS)
    def BeamAngleV(self) -> float:
        return self.bench.monitor.beam_angle_rad()[1]

    @attribute(dtype=float, unit="m", format="%.4e",
               doc="Attocube distance Va, mean over the last 0.1 s", **_SCALAR_EVENTS)
    def Distance(self) -> float:
        return self.bench.monitor.distance_m()

    @attribute(dtype=float, unit="rad", format="%.3e",
               doc="rms of the horizontal beam angle about its mean over the last 1 s",
               **_SCALAR_EVENTS)
    def TrackingErrorRmsH(self) -> float:
        return self.bench.monitor.tracking_rms_rad()[0]

    @attribute(dtype=float, unit="rad", format="%.3e",
               doc="rms of the vertical beam angle about its mean over the last 1 s",
               **_SCALAR_EVENTS)
    def TrackingErrorRmsV(self) -> float:
        return self.bench.monitor.tracking_rms_rad()[1]

    @attribute(dtype=float, unit="", format="%.3f",
               doc="fraction of the last 1 s with Uch or Ucv on a DAC rail", **_SCALAR_EVENTS)
    def DacSaturation(self) -> float:
        return self.bench.monitor.dac_saturation()

    @attribute(dtype=bool, doc="the Sercalo loop is closed")
    def LoopClosed(self) -> bool:
        return self.bench.loop_closed

    @attribute(dtype=str, doc="controller in the loop, or loaded for the next CloseLoop")
    def Controller(self) -> str:
        return self.bench.controller_name

    @attribute(dtype=str, doc="the running excitation as JSON ({} when none)")
    def Excitation(self) -> str:
        return self.bench.excitation_text

    @attribute(dtype=float, unit="s", format="%.3f", doc="bench time since the server started",
               **_SCALAR_EVENTS)
    def BenchTime(self) -> float:
        return self.bench.bench_time_s

    @attribute(dtype=float, access=AttrWriteType.READ_WRITE, unit="",
               doc="bench seconds per wall-clock second (1: real time)")
    def SpeedFactor(self) -> float:
        return self.bench.speed

    @SpeedFactor.write  # type: ignore[no-redef]
    def SpeedFactor(self, value: float) -> None:
        self.bench.speed = value

    # -- spectra -------------------------------------------------------------------

    @attribute(dtype=(float,), max_dim_x=_MAX_SPECTRUM, unit="Hz",
               doc="frequencies of AsdVph, AsdVpv and AsdVa")
    def AsdFrequency(self) -> np.ndarray:
        return self.bench.asd_frequency()

    @attribute(dtype=(float,), max_dim_x=_MAX_SPECTRUM, unit="V/sqrt(Hz)",
               doc="ASD of Vph, Welch 1 s Hann over the last 10 s, updated every second")
    def AsdVph(self) -> np.ndarray:
        return self.bench.asd("Vph")

    @attribute(dtype=(float,), max_dim_x=_MAX_SPECTRUM, unit="V/sqrt(Hz)",
               doc="ASD of Vpv, Welch 1 s Hann over the last 10 s, updated every second")
    def AsdVpv(self) -> np.ndarray:
        return self.bench.asd("Vpv")

    @attribute(dtype=(float,), max_dim_x=_MAX_SPECTRUM, unit="m/sqrt(Hz)",
               doc="ASD of Va, Welch 1 s Hann over the last 10 s, updated every second")
    def AsdVa(self) -> np.ndarray:
        return self.bench.asd("Va")

    def _frf_rows(self, what: str) -> np.ndarray:
        snap = self.bench.frf()
        if snap is None:
            return np.zeros((0, 0))
        if what == "magnitude":
            return np.abs(snap.h1)
        if what == "phase":
            return np.degrees(np.angle(snap.h1))
        return np.asarray(snap.coherence)

    @attribute(dtype=(float,), max_dim_x=_MAX_SPECTRUM, unit="Hz",
               doc="frequencies of the live FRF")
    def FrfFrequency(self) -> np.ndarray:
        snap = self.bench.frf()
        return np.zeros(0) if snap is None else snap.frequency_hz

    @attribute(dtype=((float,),), max_dim_x=_MAX_SPECTRUM, max_dim_y=2, unit="V/V",
               doc="|H1| from the excited input to Vph (row 0) and Vpv (row 1)")
    def FrfMagnitude(self) -> np.ndarray:
        return self._frf_rows("magnitude")

    @attribute(dtype=((float,),), max_dim_x=_MAX_SPECTRUM, max_dim_y=2, unit="deg",
               doc="phase of H1 from the excited input to Vph (row 0) and Vpv (row 1)")
    def FrfPhase(self) -> np.ndarray:
        return self._frf_rows("phase")

    @attribute(dtype=((float,),), max_dim_x=_MAX_SPECTRUM, max_dim_y=2, unit="",
               doc="magnitude-squared coherence, excited input to Vph (row 0) and Vpv (row 1)")
    def FrfCoherence(self) -> np.ndarray:
        return self._frf_rows("coherence")

    # -- commands ------------------------------------------------------------------

    @command(doc_in="close the loop with the loaded controller (the seed's if none)")
    def CloseLoop(self) -> None:
        self.bench.close_loop()

    @command(doc_in="open the loop, holding the last command")
    def OpenLoop(self) -> None:
        self.bench.open_loop()

    @command(dtype_in=str, dtype_out=str,
             doc_in='path of controllers_sos.json / controllers.mat / a design folder, or '
                    '{"path": ..., "controller": name}',
             doc_out="name of the controller loaded")
    def LoadController(self, argument: str) -> str:
        return self.bench.load_controller(argument)

    @command(dtype_in=str, doc_in='{"input": "Uch", "kind": "noise"|"sine"|"multisine", '
                                  '"amplitude_v": V, "band_hz": [lo, hi], "frequency_hz": f}')
    def StartExcitation(self, argument: str) -> None:
        self.bench.start_excitation(argument)

    @command(doc_in="stop the excitation (the FRF keeps its last estimate)")
    def StopExcitation(self) -> None:
        self.bench.stop_excitation()

    @command(dtype_in=str, dtype_out=str, doc_in="experiment name, e.g. data_uch",
             doc_out="path of the .mat file, complete when the state leaves MOVING")
    def RunExperiment(self, name: str) -> str:
        return self.bench.run_experiment(name)

    @command(dtype_in=str, dtype_out=str,
             doc_in='{"signals": ["Vph", ...], "duration_s": s, "name": ..., '
                    '"format": "mat"|"nexus"}',
             doc_out="path of the file, complete when the state leaves MOVING")
    def Record(self, argument: str) -> str:
        return self.bench.record(argument)

    @command(doc_in="leave FAULT: loop open, command zero, excitation stopped")
    def Reset(self) -> None:
        self.bench.reset()
