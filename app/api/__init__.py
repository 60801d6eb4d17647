"""The Python API: :func:`navigate`, :func:`read_recording`, :func:`gait_parameters`, :func:`batch` (also
importable from ``footnav.app``); the same code as the command line (docs/guide/python-api.md)."""

from typing import TYPE_CHECKING

from footnav.pipeline._lazy import lazy_exports

if TYPE_CHECKING:
    from .folders import batch as batch
    from .navigation import Navigation as Navigation
    from .navigation import gait_parameters as gait_parameters
    from .navigation import navigate as navigate
    from .navigation import read_recording as read_recording
else:  # type checkers read the imports above; at run time the same names are lazy attributes
    __all__, __getattr__, __dir__ = lazy_exports(__name__, __file__)
