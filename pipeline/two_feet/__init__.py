"""Two feet as one estimation problem: the inter-foot distance bound between the feet's filters, the
navigation of a left and a right recording together, and of two units' streams as they arrive."""

from typing import TYPE_CHECKING

from footnav.pipeline._lazy import lazy_exports

if TYPE_CHECKING:
    from .joint import FootSignals as FootSignals
    from .joint import TwoFeetResult as TwoFeetResult
    from .joint import navigate_feet as navigate_feet
    from .live import FeetLockstep as FeetLockstep
    from .live import lockstep_for as lockstep_for
    from .separation import FootSeparation as FootSeparation
    from .separation import apply_separation as apply_separation
else:  # type checkers read the imports above; at run time the same names are lazy attributes
    __all__, __getattr__, __dir__ = lazy_exports(__name__, __file__)
