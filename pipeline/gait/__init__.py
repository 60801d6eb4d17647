"""Gait quantities from a navigation solution: steps, foot clearance, gait parameters per stride."""

from typing import TYPE_CHECKING

from footnav.pipeline._lazy import lazy_exports

if TYPE_CHECKING:
    from .clearance import StrideClearance as StrideClearance
    from .clearance import StrideClearanceTracker as StrideClearanceTracker
    from .events import GaitEventTracker as GaitEventTracker
    from .events import step_onsets as step_onsets
    from .parameters import StrideParameters as StrideParameters
    from .parameters import Summary as Summary
    from .parameters import footfalls as footfalls
    from .parameters import gait_parameters as gait_parameters
    from .parameters import stride_parameters as stride_parameters
    from .parameters import summarize as summarize
    from .steps import Steps as Steps
    from .steps import accumulate_steps as accumulate_steps
    from .steps import segment_steps as segment_steps
    from .tof_clearance import SwingClearanceTracker as SwingClearanceTracker
    from .tof_clearance import swing_clearance as swing_clearance
else:  # type checkers read the imports above; at run time the same names are lazy attributes
    __all__, __getattr__, __dir__ = lazy_exports(__name__, __file__)
