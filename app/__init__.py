"""The command line, configuration and session assembly: :func:`main` is ``footnav``; and the Python API
(``footnav.app.api``): :func:`navigate`, :func:`read_recording`, :func:`gait_parameters`, :func:`batch`, and
:func:`navigate_pair` for a left and a right foot."""

from typing import TYPE_CHECKING

from footnav.pipeline._lazy import lazy_exports

if TYPE_CHECKING:
    from .api.feet import navigate_pair as navigate_pair
    from .api.folders import batch as batch
    from .api.navigation import Navigation as Navigation
    from .api.navigation import gait_parameters as gait_parameters
    from .api.navigation import navigate as navigate
    from .api.navigation import read_recording as read_recording
    from .cli import main as main
else:  # type checkers read the imports above; at run time the same names are lazy attributes
    __all__, __getattr__, __dir__ = lazy_exports(__name__, __file__)
