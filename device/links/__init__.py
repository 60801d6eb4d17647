"""Byte links to a unit: USB-CDC serial, BLE, and the reconnecting link that survives faults."""

from typing import TYPE_CHECKING

from footnav.pipeline._lazy import lazy_exports

if TYPE_CHECKING:
    from .base import ByteLink as ByteLink
    from .base import CaptureTap as CaptureTap
    from .ble import BleBackend as BleBackend
    from .ble import BleLink as BleLink
    from .reconnecting import LinkEvent as LinkEvent
    from .reconnecting import LinkGap as LinkGap
    from .reconnecting import LinkHealth as LinkHealth
    from .reconnecting import ReconnectingLink as ReconnectingLink
    from .replay import CaptureReplayLink as CaptureReplayLink
    from .serial import SerialLink as SerialLink
else:  # type checkers read the imports above; at run time the same names are lazy attributes
    __all__, __getattr__, __dir__ = lazy_exports(__name__, __file__)
