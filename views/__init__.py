"""Rerun: entity paths, the default blueprint, archetype conversion and the logger thread; the Lab
Streaming Layer outlets (``--lsl``)."""

from typing import TYPE_CHECKING

from footnav.pipeline._lazy import lazy_exports
from footnav.views.rerun_env import prepare_sdk_environment

prepare_sdk_environment()  # before any footnav.views module imports rerun

if TYPE_CHECKING:
    from .blueprint import build_blueprint as build_blueprint
    from .dual_imu import DualRunView as DualRunView
    from .dual_imu import save_dual_runs as save_dual_runs
    from .logger import LoggerStats as LoggerStats
    from .logger import RerunLogger as RerunLogger
    from .lsl import LslOutlets as LslOutlets
    from .lsl import LslRequest as LslRequest
    from .lsl import open_lsl as open_lsl
    from .outputs import Output as Output
    from .outputs import SessionViews as SessionViews
    from .outputs import open_session_views as open_session_views
    from .paths import DualPaths as DualPaths
    from .paths import FootPaths as FootPaths
    from .sinks import ViewerStartError as ViewerStartError
else:  # type checkers read the imports above; at run time the same names are lazy attributes
    __all__, __getattr__, __dir__ = lazy_exports(__name__, __file__)
