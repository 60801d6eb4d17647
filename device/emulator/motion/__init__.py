"""The emulated walker: courses, floors, and the motion of one instrumented foot."""

from typing import TYPE_CHECKING

from footnav.pipeline._lazy import lazy_exports

if TYPE_CHECKING:
    from .floors import Floor as Floor
    from .floors import floor_of as floor_of
    from .gait import GaitTruth as GaitTruth
    from .gait import simulate_walk as simulate_walk
    from .paths import PATHS as PATHS
    from .paths import Footholds as Footholds
    from .paths import footholds as footholds
else:  # type checkers read the imports above; at run time the same names are lazy attributes
    __all__, __getattr__, __dir__ = lazy_exports(__name__, __file__)
