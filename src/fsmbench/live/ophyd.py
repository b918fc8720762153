"""The live bench as an ophyd-async device, over Tango or EPICS, for Bluesky plans.

:func:`bench_device` makes one :class:`FsmBenchDevice` for ``fsmbench serve`` (the Tango
device) or ``fsmbench serve --protocol epics`` (the IOC), with the same signal names on
both:

- readables (``read()``): ``beam_angle_h``/``_v`` [µrad], ``distance`` [nm],
  ``tracking_error_rms_h``/``_v`` [µrad], ``dac_saturation`` [%], ``bench_time`` [s];
  their units and precisions come from the control system (Tango's attribute
  configuration, the records' ``EGU``/``PREC``);
- configuration (``read_configuration()``): ``controller``, ``loop_closed``,
  ``speed_factor`` (writable), ``speed_reached``;
- further signals, not read by ``read()``: ``state`` (:class:`BenchState`),
  ``status``, ``excitation``, ``task``, ``progress``, the spectra ``asd_frequency``,
  ``asd_vph``, ``asd_vpv``, ``asd_va``;
- commands (:class:`BenchCommand`): ``close_loop``, ``open_loop``, ``stop_excitation``,
  ``abort``, ``reset`` (no argument: ``trigger()`` runs them, so ``bps.trigger(bench.reset,
  wait=True)`` works), ``load_controller``, ``start_excitation``, ``run_experiment``,
  ``record`` (one string argument, JSON as the device takes it). ``await
  bench.record.execute(argument)`` gives the device's reply (a sentence; ``run_experiment``
  and ``record`` the file's path), in a plan :func:`fsmbench.live.plans.execute`; a
  refusal raises :class:`CommandRefusedError` with the reason code and the device's
  sentence.

Why a command backend of our own: the device's commands answer in a ``DevString``
(Tango) or in ``Reply``/``ReplyCode`` after the put (EPICS), and a refusal is a
``DevFailed`` or a ``ReplyCode``. ophyd-async's ``SignalX`` (deprecated) dropped the
reply and failed on the ``DevString``; :class:`BenchCommand` is an ophyd-async
``Command`` whose backends read the reply on either protocol, so a plan can tell a
command that ran from one that was refused.

This module needs the ``bluesky`` extra (``pip install 'fsmbench[bluesky]'``); nothing
else in fsmbench imports it.
"""

from __future__ import annotations

import asyncio
import inspect
import sys
from collections.abc import Callable
from typing import Any

import numpy as np
from ophyd_async.core import (
    DEFAULT_TIMEOUT,
    AsyncStatus,
    Command,
    CommandBackend,
    SignalR,
    SignalRW,
    StandardReadable,
    StandardReadableFormat,
    StrictEnum,
)

__all__ = ["ACTION_COMMANDS", "ARGUMENT_COMMANDS", "READ_SIGNALS", "BenchCommand",
           "BenchState", "CommandRefusedError", "FsmBenchDevice", "bench_device"]

#: Commands without argument and with one (the device's names), and their signal names.
ACTION_COMMANDS = {"close_loop": "CloseLoop", "open_loop": "OpenLoop",
                   "stop_excitation": "StopExcitation", "abort": "Abort", "reset": "Reset"}
ARGUMENT_COMMANDS = {"load_controller": "LoadController",
                     "start_excitation": "StartExcitation",
                     "run_experiment": "RunExperiment", "record": "Record"}
#: Readables (``read()``): signal name → attribute (Tango) or record (EPICS), all float.
READ_SIGNALS = {"beam_angle_h": "BeamAngleH", "beam_angle_v": "BeamAngleV", "distance": "Distance",
         "tracking_error_rms_h": "TrackingErrorRmsH",
         "tracking_error_rms_v": "TrackingErrorRmsV", "dac_saturation": "DacSaturation",
         "bench_time": "BenchTime"}
_CONFIG: dict[str, tuple[str, type]] = {"controller": ("Controller", str),
                                        "loop_closed": ("LoopClosed", bool),
                                        "speed_reached": ("SpeedReached", float)}
_OTHER: dict[str, tuple[str, type]] = {"status": ("Status", str),
                                       "excitation": ("Excitation", str),
                                       "task": ("Task", str), "progress": ("Progress", float),
                                       "heartbeat": ("Heartbeat", int)}
_SPECTRA = {"asd_frequency": "AsdFrequency", "asd_vph": "AsdVph", "asd_vpv": "AsdVpv",
            "asd_va": "AsdVa"}
#: How long a read waits for an INVALID Tango attribute to have a value [s] (the signals'
#: timeout is longer).
INVALID_WAIT_S = 5.0
_INVALID_POLL_S = 0.05
#: How long a command may take to answer [s] (the device answers within Tango's 3 s
#: client timeout; a busy machine is given more).
COMMAND_TIMEOUT_S = 30.0


class BenchState(StrictEnum):
    """The device's state (Tango ``State``, the IOC's ``PREFIX:State``)."""

    ON = "ON"
    RUNNING = "RUNNING"
    MOVING = "MOVING"
    ALARM = "ALARM"
    FAULT = "FAULT"


class CommandRefusedError(RuntimeError):
    """The device refused a command.

    Attributes
    ----------
    command : str
        The device's name for it (``RunExperiment`` …).
    reason : str
        The reason code (``FSM_Busy``, ``FSM_BadArgument`` …, the same on both protocols).
    sentence : str
        The device's sentence: why, and what to do.
    """

    def __init__(self, command: str, reason: str, sentence: str) -> None:
        super().__init__(f"{command} refused [{reason}]: {sentence}")
        self.command = command
        self.reason = reason
        self.sentence = sentence


def _signature(with_argument: bool) -> inspect.Signature:
    params = [inspect.Parameter("argument", inspect.Parameter.POSITIONAL_OR_KEYWORD,
                                annotation=str)] if with_argument else []
    return inspect.Signature(params, return_annotation=str)


class _TangoCommand(CommandBackend[..., str]):
    """A Tango command through PyTango's ``DeviceProxy`` (the blocking call in a thread):
    its ``DevString`` reply returned, a ``DevFailed`` raised as :class:`CommandRefusedError`."""

    def __init__(self, address: str, command: str, *, with_argument: bool) -> None:
        super().__init__(_signature(with_argument))
        self.address = address
        self.command = command
        self._proxy: Any = None

    def source(self, name: str) -> str:
        return f"{self.address}->{self.command}"

    async def connect(self, timeout: float) -> None:
        import tango

        def make() -> Any:
            proxy = tango.DeviceProxy(self.address)
            proxy.set_timeout_millis(round(COMMAND_TIMEOUT_S * 1000))
            proxy.command_query(self.command)  # raises when the device has no such command
            return proxy

        self._proxy = await asyncio.wait_for(asyncio.to_thread(make), timeout)

    async def execute(self, *args: Any, **kwargs: Any) -> str:
        import tango

        argument = [str(a) for a in (*args, *kwargs.values())]

        def call() -> str:
            try:
                return str(self._proxy.command_inout(self.command, *argument))
            except tango.DevFailed as exc:
                err = exc.args[0]
                raise CommandRefusedError(self.command, str(err.reason),
                                     " ".join(str(err.desc).split())) from None

        return await asyncio.to_thread(call)


class _CaCommand(CommandBackend[..., str]):
    """An IOC command: a put that completes when the command has run, then ``Reply`` and
    ``ReplyCode`` (the module notes). A put of 1 for an action, of the argument as a long
    string otherwise."""

    def __init__(self, prefix: str, command: str, *, with_argument: bool) -> None:
        super().__init__(_signature(with_argument))
        self.prefix = prefix
        self.command = command
        self._lock = asyncio.Lock()  # one command of this device at a time from this client

    def source(self, name: str) -> str:
        return f"ca://{self.prefix}:{self.command}"

    async def connect(self, timeout: float) -> None:
        from aioca import connect

        # The Channel Access context ophyd-async's CA signals use: pyepics' when pyepics is
        # imported. Connected first, aioca would make a context of its own on this thread,
        # and the signals could then not attach to pyepics' ('already attached').
        pyepics_ca = sys.modules.get("epics.ca")
        if pyepics_ca is not None:
            pyepics_ca.use_initial_context()
        await connect([f"{self.prefix}:{n}" for n in (self.command, "Reply", "ReplyCode",
                                                        "ReplyCount")], timeout=timeout)

    async def execute(self, *args: Any, **kwargs: Any) -> str:
        from aioca import DBR_CHAR_STR, caget, caput

        values = [str(a) for a in (*args, *kwargs.values())]
        async with self._lock:
            pv = f"{self.prefix}:{self.command}"
            if values:
                await caput(pv, values[0], datatype=DBR_CHAR_STR, wait=True,
                            timeout=COMMAND_TIMEOUT_S)
            else:
                await caput(pv, 1, wait=True, timeout=COMMAND_TIMEOUT_S)
            # The IOC writes Reply and ReplyCode before the put completes.
            code = str(await caget(f"{self.prefix}:ReplyCode"))
            reply = str(await caget(f"{self.prefix}:Reply", datatype=DBR_CHAR_STR))
        if code != "OK":
            raise CommandRefusedError(self.command, code, reply)
        head = f"{self.command}: "
        return reply[len(head):] if reply.startswith(head) else reply


class BenchCommand(Command[..., str]):
    """A command of the device: ``execute(argument)`` (or ``execute()``) gives a status whose
    ``value`` is the device's reply; ``trigger()`` runs a command without argument.

    A refusal fails the status with :class:`CommandRefusedError`.
    """

    @AsyncStatus.wrap
    async def trigger(self) -> None:
        """Run the command (one without argument); done when the device has answered."""
        await self.execute()


class FsmBenchDevice(StandardReadable):
    """The live bench (see the module notes); made by :func:`bench_device`.

    Parameters
    ----------
    signal_r, signal_rw : callable
        ``(datatype, attribute) -> signal`` of the protocol.
    command : callable
        ``(command, with_argument) -> CommandBackend`` of the protocol.
    address : str
        Where the device is, as given to :func:`bench_device`.
    name : str
    """

    def __init__(self, *, signal_r: Callable[[Any, str], SignalR[Any]],
                 signal_rw: Callable[[Any, str], SignalRW[Any]],
                 command: Callable[[str, bool], CommandBackend[..., str]],
                 address: str, name: str = "") -> None:
        from ophyd_async.core import Array1D

        self.address = address
        with self.add_children_as_readables():
            for attr, device_name in READ_SIGNALS.items():
                setattr(self, attr, signal_r(float, device_name))
        with self.add_children_as_readables(StandardReadableFormat.CONFIG_SIGNAL):
            for attr, (device_name, datatype) in _CONFIG.items():
                setattr(self, attr, signal_r(datatype, device_name))
            self.speed_factor = signal_rw(float, "SpeedFactor")
        self.state = signal_r(BenchState, "State")
        for attr, (device_name, datatype) in _OTHER.items():
            setattr(self, attr, signal_r(datatype, device_name))
        for attr, device_name in _SPECTRA.items():
            setattr(self, attr, signal_r(Array1D[np.float64], device_name))
        for attr, device_name in ACTION_COMMANDS.items():
            setattr(self, attr, BenchCommand(command(device_name, False),
                                             timeout=COMMAND_TIMEOUT_S))
        for attr, device_name in ARGUMENT_COMMANDS.items():
            setattr(self, attr, BenchCommand(command(device_name, True),
                                             timeout=COMMAND_TIMEOUT_S))
        super().__init__(name=name)

    # The children, for readers and type checkers (made in the loops above).
    beam_angle_h: SignalR[float]
    beam_angle_v: SignalR[float]
    distance: SignalR[float]
    tracking_error_rms_h: SignalR[float]
    tracking_error_rms_v: SignalR[float]
    dac_saturation: SignalR[float]
    bench_time: SignalR[float]
    controller: SignalR[str]
    loop_closed: SignalR[bool]
    speed_reached: SignalR[float]
    speed_factor: SignalRW[float]
    state: SignalR[BenchState]
    status: SignalR[str]
    excitation: SignalR[str]
    task: SignalR[str]
    progress: SignalR[float]
    heartbeat: SignalR[int]
    asd_frequency: SignalR[Any]
    asd_vph: SignalR[Any]
    asd_vpv: SignalR[Any]
    asd_va: SignalR[Any]
    close_loop: BenchCommand
    open_loop: BenchCommand
    stop_excitation: BenchCommand
    abort: BenchCommand
    reset: BenchCommand
    load_controller: BenchCommand
    start_excitation: BenchCommand
    run_experiment: BenchCommand
    record: BenchCommand


def _valid_tango_backend(datatype: Any, trl: str) -> Any:
    """ophyd-async's Tango backend that reads an INVALID attribute again.

    The device gives an attribute INVALID quality, with no value, when it has none to give
    (a spectrum before its first second of data, the bench's lock taken for longer than a
    read may wait on a busy machine). ophyd-async then fails to describe or read it; a
    plan should wait for the value as ``tune --device`` does
    (:func:`fsmbench.tune.reads.read_valid`): read again for up to
    :data:`INVALID_WAIT_S`, then fail naming the attribute.
    """
    from ophyd_async.core import make_datakey
    from ophyd_async.tango.core import TangoSignalBackend, get_source_metadata

    class ValidTangoSignalBackend(TangoSignalBackend[Any]):
        async def _valid(self, read: Callable[[], Any], value_of: Callable[[Any], Any]) -> Any:
            loop = asyncio.get_running_loop()
            deadline = loop.time() + INVALID_WAIT_S
            while True:
                got = await read()
                if value_of(got) is not None:
                    return got
                if loop.time() > deadline:
                    raise TimeoutError(f"{trl} stayed INVALID (no value) for "
                                       f"{INVALID_WAIT_S:g} s")
                await asyncio.sleep(_INVALID_POLL_S)

        async def get_reading(self) -> Any:
            return await self._valid(super().get_reading, lambda r: r["value"])

        async def get_value(self) -> Any:
            return await self._valid(super().get_value, lambda v: v)

        async def get_datakey(self, source: str) -> Any:
            proxy = self.proxies[source]
            if proxy is None:
                return await super().get_datakey(source)  # says it is not connected
            value = await self._valid(proxy.get, lambda v: v)
            return make_datakey(self.datatype, value, source,  # type: ignore[arg-type]
                                metadata=get_source_metadata(source, self.trl_configs))

    return ValidTangoSignalBackend(datatype, trl, trl)


def _tango_trl(address: str, attribute: str) -> str:
    """``tango://host:port/d/f/m/Attr#dbase=no`` (the suffix after the attribute)."""
    base, sep, suffix = address.partition("#")
    return f"{base}/{attribute}{sep}{suffix}"


def bench_device(address: str, *, name: str = "fsm_bench",
                 timeout: float = DEFAULT_TIMEOUT) -> FsmBenchDevice:
    """The ophyd-async device of the live bench at ``address`` (not yet connected).

    Parameters
    ----------
    address : str
        ``tango://HOST:PORT/dom/fam/member[#dbase=no]`` or a Tango name resolved through
        ``TANGO_HOST`` (``fsmbench serve``), or ``ca://PREFIX`` (``fsmbench serve
        --protocol epics --prefix PREFIX``, found through ``EPICS_CA_ADDR_LIST``), as
        ``fsmbench tune --device`` takes it.
    name : str
        The device's name in Bluesky's documents (the signals' are ``NAME-beam_angle_h``
        …).
    timeout : float
        Each signal's timeout [s].

    Returns
    -------
    FsmBenchDevice
        Connect it in the RunEngine's loop: ``with init_devices(): bench = bench_device(…)``
        or ``RE(ensure_connected(bench))``.

    Examples
    --------
    >>> from fsmbench.live.ophyd import bench_device
    >>> bench = bench_device("ca://BL1")
    >>> bench.run_experiment.source
    'ca://BL1:RunExperiment'
    """
    if address.startswith("ca://"):
        from ophyd_async.epics.core import epics_signal_r, epics_signal_rw

        prefix = address[len("ca://"):]

        def ca_r(datatype: Any, attr: str) -> SignalR[Any]:
            return epics_signal_r(datatype, f"ca://{prefix}:{attr}", timeout=timeout)

        def ca_rw(datatype: Any, attr: str) -> SignalRW[Any]:
            return epics_signal_rw(datatype, f"ca://{prefix}:{attr}", timeout=timeout)

        def ca_command(command: str, with_argument: bool) -> CommandBackend[..., str]:
            return _CaCommand(prefix, command, with_argument=with_argument)

        return FsmBenchDevice(signal_r=ca_r, signal_rw=ca_rw, command=ca_command,
                              address=address, name=name)
    def tango_r(datatype: Any, attr: str) -> SignalR[Any]:
        return SignalR(_valid_tango_backend(datatype, _tango_trl(address, attr)),
                       timeout=timeout)

    def tango_rw(datatype: Any, attr: str) -> SignalRW[Any]:
        return SignalRW(_valid_tango_backend(datatype, _tango_trl(address, attr)),
                        timeout=timeout)

    def tango_command(command: str, with_argument: bool) -> CommandBackend[..., str]:
        return _TangoCommand(address, command, with_argument=with_argument)

    return FsmBenchDevice(signal_r=tango_r, signal_rw=tango_rw, command=tango_command,
                          address=address, name=name)
