"""The navigation filter: the causal navigator, the error-state Kalman filter and its compiled kernels, alignment,
quaternions, unit profiles, clipped rates."""

from typing import TYPE_CHECKING

from footnav.pipeline._lazy import lazy_exports

if TYPE_CHECKING:
    from .alignment import Alignment as Alignment
    from .alignment import align_from_still as align_from_still
    from .navigator import NavConfig as NavConfig
    from .navigator import Navigator as Navigator
    from .navigator import NavStats as NavStats
    from .navigator import navigate as navigate
    from .params import FilterParams as FilterParams
    from .profiles import PROFILES as PROFILES
    from .profiles import UnitProfile as UnitProfile
    from .profiles import get_profile as get_profile
    from .saturation import SaturatedRates as SaturatedRates
    from .saturation import reconstruct_saturated_rates as reconstruct_saturated_rates
else:  # type checkers read the imports above; at run time the same names are lazy attributes
    __all__, __getattr__, __dir__ = lazy_exports(__name__, __file__)
