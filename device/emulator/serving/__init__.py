"""The emulated unit served to hosts: on a pseudo-terminal, as a BLE peripheral, with wire faults."""

from typing import TYPE_CHECKING

from footnav.pipeline._lazy import lazy_exports

if TYPE_CHECKING:
    from .ble_backend import bumble_backend as bumble_backend
    from .ble_peripheral import BleShoePeripheral as BleShoePeripheral
    from .faults import FaultInjector as FaultInjector
    from .faults import FaultLog as FaultLog
    from .faults import WireFaults as WireFaults
    from .pty import PtyShoeServer as PtyShoeServer
else:  # type checkers read the imports above; at run time the same names are lazy attributes
    __all__, __getattr__, __dir__ = lazy_exports(__name__, __file__)
