"""A device's failures in words, whatever the protocol ``tune --device`` speaks.

PyTango reports every failed call as a ``DevFailed``: a refusal (the device answered, with
a reason code ``FSM_Settling``, ``FSM_BadArgument``, ... and one sentence) and a lost
connection alike. The Channel Access client (:mod:`fsmbench.tune.ca_device`) raises the
protocol-neutral exceptions here instead: :class:`DeviceRefused` when the IOC's
``ReplyCode`` is not ``OK``, :class:`DeviceLost` when a PV does not answer.
:func:`device_failure` reads both kinds, and PyTango's ``DevFailed`` by its fields (PyTango
is never imported: the core imports without it), so that :mod:`fsmbench.tune.device` and
:mod:`fsmbench.tune.transaction` name a refusal or a lost connection in the same words on
either protocol.

They are ``ValueError``: a refusal or a device gone is a verdict for the user, which the
command line prints in one line.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["DeviceError", "DeviceLost", "DeviceRefused", "Failure", "device_failure"]


class DeviceError(ValueError):
    """A call the device did not carry out (the protocol-neutral ``DevFailed``).

    Parameters
    ----------
    message : str
        The whole message: the device, the call, what happened.
    command : str
        The command or attribute called (``LoadController``, ``Controller``).
    reason : str
        A code: the device's (``FSM_...``) or the client's (``CA_...``).
    words : str
        What the device (or the client) said, one line.
    """

    def __init__(self, message: str, *, command: str, reason: str, words: str) -> None:
        super().__init__(message)
        self.command, self.reason = command, reason
        self.words = " ".join(words.split())


class DeviceRefused(DeviceError):  # noqa: N818  (reads as what happened, as Refused)
    """The device answered and refused the command (its reason code and sentence)."""


class DeviceLost(DeviceError):  # noqa: N818  (reads as what happened: raise DeviceLost)
    """The device did not answer: the connection lost, the server stopped, a call that
    did not complete in time."""


@dataclass(frozen=True)
class Failure:
    """A device's failure, read from either protocol's exception.

    Attributes
    ----------
    refused : bool
        True when the device answered and refused; False when it failed or did not answer.
    command : str
        The command, when known ("" otherwise).
    reason : str
        The reason code ("" when none).
    words : str
        The device's sentence, one line.
    """

    refused: bool
    command: str
    reason: str
    words: str

    def cause(self) -> str:
        """What cut a loop change short, in words (``tune.json``'s ``transaction.cause``)."""
        if self.refused:
            what = self.command or "the command"
            # The device's sentence often starts with "<Command> refused: ": said once.
            core = self.words.removeprefix(f"{self.command} refused: ") if self.command \
                else self.words
            return f"the device refused {what} ({self.reason}: {core})"
        return f"the device failed or the connection was lost ({self.words})"

    def sentence(self) -> str:
        """The device's words with the reason code, for a list of refusals."""
        return f"{self.words} [{self.reason}]" if self.reason else self.words


def device_failure(exc: BaseException) -> Failure | None:
    """``exc`` read as a device's failure, or None when it is none.

    Parameters
    ----------
    exc : BaseException
        A :class:`DeviceError`, or PyTango's ``DevFailed`` (read by its first error's
        ``reason``, ``desc`` and ``origin``, ``<device>/<Command>``: a reason ``FSM_...``
        is the device's own refusal, any other, ``API_...``, a failed call or a lost
        connection).

    Returns
    -------
    Failure or None
    """
    if isinstance(exc, DeviceError):
        return Failure(isinstance(exc, DeviceRefused), exc.command, exc.reason, exc.words)
    if type(exc).__name__ != "DevFailed" or not exc.args:
        return None
    error = exc.args[0]
    desc = getattr(error, "desc", None)
    if not isinstance(desc, str):
        return None
    reason = str(getattr(error, "reason", "") or "")
    command = str(getattr(error, "origin", "") or "").rpartition("/")[2]
    refused = reason.startswith("FSM_")
    return Failure(refused, command if refused else "", reason, " ".join(desc.split()))
