"""The live bench's EPICS IOC as ``tune --device ca://PREFIX`` drives it (Channel Access).

:class:`CaDevice` gives :class:`fsmbench.tune.device.DeviceTarget` the part of PyTango's
``DeviceProxy`` it uses, over the PVs of ``fsmbench serve --protocol epics --prefix PREFIX``
(:mod:`fsmbench.live.epics`), through pyepics (the ``fsmbench[epics]`` extra):

* ``read_attribute(name)``: ``PREFIX:<name>`` read afresh (no monitor: a value a command
  just changed is read from the IOC, not from a monitor not yet updated), with its alarm
  severity; SEVR INVALID, or no answer within :data:`GET_S`, is quality ``ATTR_INVALID``
  and value None, as PyTango gives an INVALID attribute, so that
  :func:`fsmbench.tune.reads.read_valid` reads it again;
* ``state()``, ``status()``: ``PREFIX:State`` (the mbbi's string) and ``PREFIX:Status``;
* ``get_attribute_list()``: the attribute table the IOC's records are made from;
* the commands (``Record``, ``LoadController``, ``StartExcitation``, ``StopExcitation``,
  ``Abort``, ...): a put that completes when the command has run (1 to an action record,
  the argument to a long-string out), then ``PREFIX:ReplyCode`` and ``PREFIX:Reply`` once
  ``PREFIX:ReplyCount`` has grown past its value before the put and ``Reply`` names the
  command (the IOC's replies start with their command's name): the reply is this put's,
  not one still on its way from a command cut short, nor another client's. ``OK``: the
  command returns the reply after its ``<Command>: ``, the text the Tango device's command
  returns. Any other code raises :class:`~fsmbench.tune.device_errors.DeviceRefused` (the
  code, the sentence), which ``DeviceTarget`` and the transaction handle as they handle a
  Tango refusal. A put Ctrl-C cut short is waited for before the next command (its command
  runs on in the IOC, and replies).

A PV that does not connect within :data:`CONNECT_S`, a put that does not complete, a
reply that does not come raise :class:`~fsmbench.tune.device_errors.DeviceLost`: a lost
connection, as PyTango's ``DevFailed``, which rolls a loop change back the same way.
Every channel is made without a monitor and disconnected by :meth:`CaDevice.close` (pyepics'
exit handler, racing the interpreter's teardown, is left none to clear).
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from fsmbench.live.attributes import ATTRIBUTES
from fsmbench.live.epics import ACTIONS, ARGUMENT_COMMANDS, MAX_ARRAY_BYTES, check_prefix
from fsmbench.live.states import STATES
from fsmbench.tune.device_errors import DeviceError, DeviceLost, DeviceRefused
from fsmbench.tune.reads import INVALID_WAIT_S

__all__ = ["CONNECT_S", "GET_S", "PUT_S", "REPLY_S", "CaDevice", "CaReading", "ca_device"]

#: Wall clock a PV may take to connect before the IOC counts as absent or lost [s]: a CA
#: search is answered in milliseconds (libca sends six searches in that time), and an absent
#: IOC is said within it (pyepics' default; PyTango's client timeout is 3 s).
CONNECT_S = 2.0
#: Wall clock a read may take before it counts as INVALID (read again) [s].
GET_S = 3.0
#: Wall clock a command's put may take to complete [s]: LoadController checks the
#: controller on the device's bench before the put completes.
PUT_S = 120.0
#: Wall clock ``ReplyCount`` may take to grow once the put completed [s] (the IOC posts its
#: reply records through EPICS' scan queue, not within the put).
REPLY_S = 10.0
_POLL_S = 0.005  # wall clock between two looks at a put's completion or ReplyCount [s]
#: EPICS alarm severities (``SEVR``) as PyTango's qualities.
_QUALITY = {0: "ATTR_VALID", 1: "ATTR_WARNING", 2: "ATTR_ALARM", 3: "ATTR_INVALID"}
_INVALID = 3
_KINDS = {spec.name: spec.kind for spec in ATTRIBUTES}


@dataclass(frozen=True)
class CaReading:
    """One read of a PV, as PyTango's ``DeviceAttribute`` carries it.

    Attributes
    ----------
    value : Any
        The value (float, int, bool, str, or an array), None when INVALID.
    quality : str
        ``ATTR_VALID``, ``ATTR_WARNING`` (SEVR MINOR), ``ATTR_ALARM`` (MAJOR) or
        ``ATTR_INVALID`` (INVALID, or no answer in time).
    severity : int or None
        The PV's SEVR (0 to 3), None without an answer.
    """

    value: Any
    quality: str
    severity: int | None


def _convert(kind: str, value: Any) -> Any:
    """A PV's value as the Tango attribute of the same row gives it."""
    if kind == "bool":
        return bool(int(value))
    if kind == "int":
        return int(value)
    if kind == "float":
        return float(value)
    if kind == "str":
        return str(value)

    return np.asarray(value, dtype=float)


class CaDevice:
    """An IOC of ``fsmbench serve --protocol epics`` through PyTango's proxy interface.

    Parameters
    ----------
    prefix : str
        The IOC's ``--prefix``.
    pv_factory : callable, optional
        ``pv_factory(pvname, auto_monitor=, connection_timeout=, form=)``: a pyepics
        ``PV`` or anything with its ``connected``, ``wait_for_connection``,
        ``get_with_metadata``, ``put``, ``put_complete`` and ``disconnect``; default ``epics.PV``.
    connect_s, get_s, put_s, reply_s : float
        Wall-clock limits [s]: :data:`CONNECT_S`, :data:`GET_S`, :data:`PUT_S`,
        :data:`REPLY_S`.

    Raises
    ------
    DeviceLost
        ``PREFIX:State`` did not connect within ``connect_s`` (no such IOC).
    ValueError
        ``prefix`` is not a PV prefix.
    """

    def __init__(self, prefix: str, *, pv_factory: Callable[..., Any] | None = None,
                 connect_s: float = CONNECT_S, get_s: float = GET_S, put_s: float = PUT_S,
                 reply_s: float = REPLY_S) -> None:
        self.prefix = check_prefix(prefix)
        if pv_factory is None:
            pv_factory = _pyepics_pv()
        self._factory = pv_factory
        self.connect_s, self.get_s = float(connect_s), float(get_s)
        self.put_s, self.reply_s = float(put_s), float(reply_s)
        self._pvs: dict[str, Any] = {}
        self._abandoned: Any = None  # a command's PV whose put was left running
        # Every channel a command needs searched at once: they connect side by side.
        for name in ("State", "Status", "ReplyCount", "ReplyCode", "Reply"):
            self._make(name)
        try:
            self._channel("State")
        except BaseException:
            self.close()
            raise

    # -- channels ------------------------------------------------------------------

    def _make(self, name: str) -> Any:
        pv = self._pvs.get(name)
        if pv is None:
            pv = self._pvs[name] = self._factory(f"{self.prefix}:{name}", auto_monitor=False,
                                                 connection_timeout=self.connect_s,
                                                 form="time")
        return pv

    def _channel(self, name: str) -> Any:
        """``PREFIX:<name>``, connected (a PV that lost its IOC is waited for ``connect_s``)."""
        pv = self._make(name)
        if not pv.connected and not pv.wait_for_connection(timeout=self.connect_s):
            raise DeviceLost(f"ca://{self.prefix}: {self.prefix}:{name} did not connect "
                             f"within {self.connect_s:g} s of wall clock (the IOC stopped, or "
                             "EPICS_CA_ADDR_LIST does not reach it)", command=name,
                             reason="CA_NotConnected", words=f"{self.prefix}:{name} not "
                             "connected")
        return pv

    def _get(self, name: str, *, as_string: bool) -> dict[str, Any] | None:
        """A fresh read of ``PREFIX:<name>`` with its severity; None without an answer."""
        data = self._channel(name).get_with_metadata(use_monitor=False, as_string=as_string,
                                                     timeout=self.get_s, form="time")
        return data if isinstance(data, dict) else None

    def _text(self, name: str) -> str:
        """A string PV's value; read again while its channel stays connected, for up to
        :data:`~fsmbench.tune.reads.INVALID_WAIT_S` (an IOC on a busy machine let one get
        of ``State`` pass 3 s in the soak, and tune stopped on it), then a lost device."""
        deadline = time.monotonic() + INVALID_WAIT_S
        while True:
            data = self._get(name, as_string=True)
            if data is not None and data.get("value") is not None:
                return str(data["value"])
            if time.monotonic() >= deadline:
                raise DeviceLost(f"ca://{self.prefix}: {self.prefix}:{name} gave no value "
                                 f"within {INVALID_WAIT_S:g} s of wall clock", command=name,
                                 reason="CA_Timeout",
                                 words=f"{self.prefix}:{name} did not answer")

    def close(self) -> None:
        """Disconnect every channel this device made (idempotent)."""
        pvs, self._pvs = self._pvs, {}
        for pv in pvs.values():
            pv.disconnect()

    def __enter__(self) -> CaDevice:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- PyTango's DeviceProxy, the part DeviceTarget uses -------------------------

    def get_attribute_list(self) -> list[str]:
        """The attributes served as PVs (the table the IOC's records are made from)."""
        return ["State", "Status", *(spec.name for spec in ATTRIBUTES)]

    def read_attribute(self, name: str) -> CaReading:
        """``PREFIX:<name>`` read afresh: its value and quality (module notes).

        Raises
        ------
        DeviceError
            ``name`` is no attribute of the table (not a PV of the IOC).
        DeviceLost
            The PV did not connect within ``connect_s``.
        """
        kind = _KINDS.get(name)
        if kind is None or kind == "image":
            raise DeviceError(f"ca://{self.prefix}: {name} is not an attribute tune reads "
                              "over Channel Access", command=name, reason="CA_NoAttribute",
                              words=f"no attribute {name}")
        data = self._get(name, as_string=kind == "str")
        if data is None or data.get("value") is None:
            return CaReading(None, "ATTR_INVALID", None)  # no answer in time: read again
        severity = int(data.get("severity") or 0)
        if severity >= _INVALID:
            return CaReading(None, "ATTR_INVALID", severity)
        return CaReading(_convert(kind, data["value"]), _QUALITY.get(severity, "ATTR_VALID"),
                         severity)

    def state(self) -> str:
        """``PREFIX:State``: ON, RUNNING, MOVING, ALARM or FAULT."""
        state = self._text("State")
        if state not in STATES:
            raise DeviceError(f"ca://{self.prefix}: {self.prefix}:State is {state!r}, not "
                              f"one of {', '.join(STATES)}", command="State",
                              reason="CA_BadState", words=f"State {state!r}")
        return state

    def status(self) -> str:
        """``PREFIX:Status``: the state in words."""
        return self._text("Status")

    def command_inout(self, name: str, argument: str | None = None) -> str:
        """Run command ``name`` (with ``argument``, for the commands that take one).

        Returns
        -------
        str
            What it did: ``PREFIX:Reply`` after ``<name>: `` (the Tango command's reply).

        Raises
        ------
        DeviceRefused
            ``PREFIX:ReplyCode`` is not ``OK`` (its code, the reply's sentence), or
            Channel Access refused the put (the IOC's access security).
        DeviceLost
            A PV did not connect, the put did not complete within ``put_s``, or no reply
            came within ``reply_s``.
        DeviceError
            Another client's command replied after this one, before its reply was read.
        """
        if name not in ACTIONS and name not in ARGUMENT_COMMANDS:
            raise DeviceError(f"ca://{self.prefix}: no command {name}", command=name,
                              reason="CA_NoCommand", words=f"no command {name}")
        if (argument is None) != (name in ACTIONS):
            raise DeviceError(f"ca://{self.prefix}: {name} "
                              f"{'takes no' if name in ACTIONS else 'needs an'} argument",
                              command=name, reason="CA_BadArgument",
                              words=f"{name}: argument {argument!r}")
        self._finish_abandoned()
        before = self._count()
        pv = self._channel(name)
        self._put(pv, name, 1 if argument is None else argument)
        code, reply = self._reply(name, before)
        if code != "OK":
            core = reply.removeprefix(f"{name} refused: ")  # the IOC's words start so
            raise DeviceRefused(f"ca://{self.prefix}: {name} refused ({code}): {core}",
                                command=name, reason=code, words=reply)
        return reply.removeprefix(f"{name}: ")

    def _count(self) -> int:
        data = self._get("ReplyCount", as_string=False)
        if data is None or data.get("value") is None:
            raise DeviceLost(f"ca://{self.prefix}: {self.prefix}:ReplyCount gave no value "
                             f"within {self.get_s:g} s of wall clock", command="ReplyCount",
                             reason="CA_Timeout", words="ReplyCount did not answer")
        return int(data["value"])

    def _put(self, pv: Any, name: str, value: Any) -> None:
        """Put ``value`` and wait for its completion (the command has run), watching the
        connection: a disconnected channel is a lost device at once, not after ``put_s``."""
        t0 = time.monotonic()
        try:
            started = pv.put(value, wait=False, use_complete=True)
        except Exception as exc:  # pyepics' CASeverityException: ECA_NOWTACCESS, ...
            raise DeviceRefused(f"ca://{self.prefix}: {name} refused (CA_PutRefused): Channel "
                                f"Access refused the put to {self.prefix}:{name} ({exc}; the "
                                "IOC's access security?)", command=name,
                                reason="CA_PutRefused",
                                words=f"{name} refused: Channel Access refused the put "
                                      f"({exc})") from None
        if started is None:  # pyepics: not connected
            raise DeviceLost(f"ca://{self.prefix}: {self.prefix}:{name} is not connected",
                             command=name, reason="CA_NotConnected",
                             words=f"{self.prefix}:{name} not connected")
        self._abandoned = pv  # until it completes: a Ctrl-C leaves it running
        while not pv.put_complete:
            if not pv.connected:
                raise DeviceLost(f"ca://{self.prefix}: the connection to {self.prefix}:{name} "
                                 f"was lost while {name} ran (its outcome is unknown: read "
                                 f"{self.prefix}:Controller and {self.prefix}:Status)",
                                 command=name, reason="CA_Disconnected",
                                 words=f"{name}: disconnected during the put")
            if time.monotonic() - t0 > self.put_s:
                raise DeviceLost(f"ca://{self.prefix}: the put to {self.prefix}:{name} did not "
                                 f"complete within {self.put_s:g} s of wall clock (the IOC is "
                                 f"stuck or gone; read {self.prefix}:Status)", command=name,
                                 reason="CA_Timeout", words=f"{name}: no completion")
            time.sleep(_POLL_S)
        self._abandoned = None

    def _reply(self, name: str, before: int) -> tuple[str, str]:
        """``(ReplyCode, Reply)`` of this client's command ``name``, run once ``ReplyCount``
        was ``before``.

        Ours once ``ReplyCount`` has grown, stays put while both are read, and ``Reply``
        names ``name`` (every reply of the IOC starts with its command's name): a reply
        still on its way (the IOC posts its records through EPICS' scan queue, after the put
        can complete) is waited for. Grown by more than one with another command's reply:
        another client's command ran after this one.
        """
        t0 = time.monotonic()
        count = before
        while True:
            count = self._count()
            if count > before:
                code, reply = self._text("ReplyCode").strip(), self._text("Reply")
                if self._count() == count and reply.startswith((f"{name}:", f"{name} ")):
                    return code, reply
            if time.monotonic() - t0 > self.reply_s:
                break
            time.sleep(_POLL_S)
        if count <= before:
            raise DeviceLost(f"ca://{self.prefix}: {name} ran but {self.prefix}:ReplyCount did "
                             f"not grow within {self.reply_s:g} s of wall clock", command=name,
                             reason="CA_NoReply", words=f"{name}: no reply")
        raise DeviceError(f"ca://{self.prefix}: another client's command replied after {name} "
                          f"(ReplyCount {before} -> {count}); read {self.prefix}:Status for "
                          f"what {name} did", command=name, reason="CA_ReplyCrossed",
                          words=f"{name}: replies crossed")

    def _finish_abandoned(self) -> None:
        """Wait (``put_s`` at most) for a put left running when a command was cut short
        (Ctrl-C as it ran): its command still runs and replies, which must not be taken
        for the next command's reply."""
        if self._abandoned is None:
            return
        pv, self._abandoned = self._abandoned, None
        t0 = time.monotonic()
        while not pv.put_complete and pv.connected and time.monotonic() - t0 < self.put_s:
            time.sleep(_POLL_S)

    # The commands, named as the Tango device's (DeviceTarget calls them so).

    def Record(self, argument: str) -> str:
        """``PREFIX:Record``: the path of the file, complete when State leaves MOVING."""
        return self.command_inout("Record", argument)

    def LoadController(self, argument: str) -> str:
        """``PREFIX:LoadController``: what it loaded, checked on the device's bench."""
        return self.command_inout("LoadController", argument)

    def StartExcitation(self, argument: str) -> str:
        """``PREFIX:StartExcitation``: what it started."""
        return self.command_inout("StartExcitation", argument)

    def RunExperiment(self, argument: str) -> str:
        """``PREFIX:RunExperiment``: the path of the file."""
        return self.command_inout("RunExperiment", argument)

    def StopExcitation(self) -> str:
        """``PREFIX:StopExcitation``: what it stopped."""
        return self.command_inout("StopExcitation")

    def Abort(self) -> str:
        """``PREFIX:Abort``: what it stopped."""
        return self.command_inout("Abort")

    def CloseLoop(self) -> str:
        """``PREFIX:CloseLoop``: what it did."""
        return self.command_inout("CloseLoop")

    def OpenLoop(self) -> str:
        """``PREFIX:OpenLoop``: what it did."""
        return self.command_inout("OpenLoop")

    def Reset(self) -> str:
        """``PREFIX:Reset``: what it did."""
        return self.command_inout("Reset")


def _pyepics_pv() -> Callable[..., Any]:
    """pyepics' ``PV``, its libca allowed the IOC's array size (read when libca starts)."""
    try:
        have = int(os.environ.get("EPICS_CA_MAX_ARRAY_BYTES", "0"))
    except ValueError:
        have = 0
    if have < MAX_ARRAY_BYTES:
        # A spectrum is 64 KiB, above CA's 16 KiB default; no effect once libca has started.
        os.environ["EPICS_CA_MAX_ARRAY_BYTES"] = str(MAX_ARRAY_BYTES)
    try:
        import epics
    except ImportError:
        raise ValueError("tune --device ca://PREFIX needs pyepics: "
                         "pip install 'fsmbench[epics]'") from None
    return epics.PV


def ca_device(address: str) -> CaDevice:
    """The IOC at ``ca://PREFIX``, or a one-line ``ValueError`` (pyepics missing, no IOC).

    Parameters
    ----------
    address : str
        ``ca://PREFIX``.

    Returns
    -------
    CaDevice
        Connected to ``PREFIX:State``; close it when done.
    """
    prefix = address.removeprefix("ca://")
    try:
        check_prefix(prefix)
    except ValueError:
        raise ValueError(f"--device {address}: {prefix!r} is no PV prefix (1 to 40 letters, "
                         "digits, _, - or :, as fsmbench serve --prefix takes)") from None
    factory = _pyepics_pv()
    try:
        return CaDevice(prefix, pv_factory=factory)
    except DeviceLost:
        raise ValueError(f"--device {address}: no IOC answers for {prefix}:State within "
                         f"{CONNECT_S:g} s (is fsmbench serve --protocol epics --prefix "
                         f"{prefix} running, and on this client's EPICS_CA_ADDR_LIST?)"
                         ) from None
