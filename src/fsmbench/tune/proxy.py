"""How ``tune --device`` reaches the live device: a PyTango proxy, or the EPICS IOC's.

:func:`device_proxy` reads the address: ``tango://HOST:PORT/dom/fam/member`` (or a bare
Tango name) is PyTango's ``DeviceProxy``; ``ca://PREFIX`` is
:class:`fsmbench.tune.ca_device.CaDevice`, the IOC of ``fsmbench serve --protocol epics
--prefix PREFIX`` over Channel Access, with the calls
:class:`fsmbench.tune.device.DeviceTarget` makes. A light module (neither the device
target's numerics nor a control system's binding imported until needed): ``tune`` reaches
the device before its heavy imports, so an address that does not answer is said at once.
"""

from __future__ import annotations

from typing import Any

__all__ = ["device_proxy", "release_proxy"]


def device_proxy(address: str) -> Any:
    """A proxy to the device at ``address``; release it with :func:`release_proxy`.

    Parameters
    ----------
    address : str
        ``tango://HOST:PORT/dom/fam/member[#dbase=no]`` (or a Tango name resolved through
        ``TANGO_HOST``): a PyTango ``DeviceProxy``; ``ca://PREFIX``: the EPICS IOC of
        ``fsmbench serve --protocol epics --prefix PREFIX`` over Channel Access
        (:class:`fsmbench.tune.ca_device.CaDevice`, found through ``EPICS_CA_ADDR_LIST``).

    Raises
    ------
    ValueError
        PyTango (or pyepics) missing, or the device not reachable (one line; an IOC that
        does not answer within :data:`fsmbench.tune.ca_device.CONNECT_S`).
    """
    if address.startswith("ca://"):
        from fsmbench.tune.ca_device import ca_device

        return ca_device(address)
    try:
        import tango
    except ImportError:
        raise ValueError("tune --device needs PyTango: pip install 'fsmbench[tango]' (or "
                         "ca://PREFIX for the EPICS IOC, with 'fsmbench[epics]')") from None
    try:
        proxy = tango.DeviceProxy(address)
        proxy.set_source(tango.DevSource.DEV)
        proxy.ping()
    except tango.DevFailed as exc:
        raise ValueError(f"--device {address}: not reachable "
                         f"({' '.join(exc.args[0].desc.split())})") from None
    return proxy


def release_proxy(proxy: Any) -> None:
    """Let go of a :func:`device_proxy`: a Channel Access device disconnects its PVs (not
    left to pyepics' exit handler); PyTango's proxy needs nothing."""
    close = getattr(proxy, "close", None)
    if callable(close):
        close()
