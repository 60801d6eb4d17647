"""Bytes <-> packets and the units themselves: protocol codecs, transports, discovery, the emulator.

Re-exported: the unit driver, its output modes, discovery and the device errors."""

from typing import TYPE_CHECKING

from footnav.pipeline._lazy import lazy_exports

if TYPE_CHECKING:
    from .discovery import BleCandidate as BleCandidate
    from .discovery import ScanReport as ScanReport
    from .discovery import SerialCandidate as SerialCandidate
    from .discovery import scan as scan
    from .errors import DeviceError as DeviceError
    from .errors import ProtocolError as ProtocolError
    from .errors import UnsupportedModeError as UnsupportedModeError
    from .modes import InsMode as InsMode
    from .modes import Mode as Mode
    from .modes import NormalImuMode as NormalImuMode
    from .modes import RawImuMode as RawImuMode
    from .modes import StepwiseMode as StepwiseMode
    from .unit import Batch as Batch
    from .unit import LinkStats as LinkStats
    from .unit import OpenShoeUnit as OpenShoeUnit
else:  # type checkers read the imports above; at run time the same names are lazy attributes
    __all__, __getattr__, __dir__ = lazy_exports(__name__, __file__)
