"""A virtual shoe: gait motion model, IMU error model, and the unit's protocol served on a pty.

Re-exported: the emulated firmware and the scripts of what it reports (INS states, steps, ToF, barometer)."""

from typing import TYPE_CHECKING

from footnav.pipeline._lazy import lazy_exports

if TYPE_CHECKING:
    from .firmware import ShoeFirmware as ShoeFirmware
    from .scripts import BaroScript as BaroScript
    from .scripts import InsTruth as InsTruth
    from .scripts import StepScript as StepScript
    from .scripts import TofScript as TofScript
    from .scripts import baro_from_height as baro_from_height
    from .scripts import steps_from_truth as steps_from_truth
else:  # type checkers read the imports above; at run time the same names are lazy attributes
    __all__, __getattr__, __dir__ = lazy_exports(__name__, __file__)
