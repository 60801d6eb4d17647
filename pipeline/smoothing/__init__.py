"""Rauch–Tung–Striebel smoothing: of a whole recording, and step by step while a session runs."""

from typing import TYPE_CHECKING

from footnav.pipeline._lazy import lazy_exports

if TYPE_CHECKING:
    from .rts import smooth_recording as smooth_recording
    from .stepwise import StepSmoothingNavigator as StepSmoothingNavigator
    from .stepwise import step_smooth_recording as step_smooth_recording
else:  # type checkers read the imports above; at run time the same names are lazy attributes
    __all__, __getattr__, __dir__ = lazy_exports(__name__, __file__)
