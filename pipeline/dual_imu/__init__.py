"""The dual-IMU board: the shared rigid-body model, footnav's board filter, the Chen et al. (2022) filter, the
lever-arm check."""

from typing import TYPE_CHECKING

from footnav.pipeline._lazy import lazy_exports

if TYPE_CHECKING:
    from .board_eskf import DualEskfConfig as DualEskfConfig
    from .board_eskf import DualEskfStream as DualEskfStream
    from .board_eskf import DualEskfTrack as DualEskfTrack
    from .board_eskf import run_dual_eskf as run_dual_eskf
    from .chen2022 import DualTrack as DualTrack
    from .chen2022 import PaperConfig as PaperConfig
    from .chen2022 import run_paper as run_paper
    from .lever_arm import LeverArmCheck as LeverArmCheck
    from .lever_arm import check_lever_arm as check_lever_arm
    from .navigator import DualNavConfig as DualNavConfig
    from .navigator import DualNavigator as DualNavigator
    from .navigator import TwoImuSamples as TwoImuSamples
else:  # type checkers read the imports above; at run time the same names are lazy attributes
    __all__, __getattr__, __dir__ = lazy_exports(__name__, __file__)
