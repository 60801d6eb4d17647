"""Aiding beyond zero velocity: the ToF foot-height measurement and the barometer."""

from typing import TYPE_CHECKING

from footnav.pipeline._lazy import lazy_exports

if TYPE_CHECKING:
    from .baro import PressureAltimeter as PressureAltimeter
    from .baro import PressureAltitude as PressureAltitude
    from .baro import PressureBatch as PressureBatch
    from .tof import TofAiding as TofAiding
    from .tof_types import RangeBatch as RangeBatch
    from .tof_types import RangeOutputs as RangeOutputs
    from .tof_types import TofConfig as TofConfig
    from .tof_types import TofCounts as TofCounts
else:  # type checkers read the imports above; at run time the same names are lazy attributes
    __all__, __getattr__, __dir__ = lazy_exports(__name__, __file__)
