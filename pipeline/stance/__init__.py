"""Stance detection: zero-velocity detectors on the IMU, the foot-height detector, floor levels from the stances."""

from typing import TYPE_CHECKING

from footnav.pipeline._lazy import lazy_exports

if TYPE_CHECKING:
    from .combined import CombinedDetectorParams as CombinedDetectorParams
    from .combined import combined_stance as combined_stance
    from .detectors import DETECTOR_KINDS as DETECTOR_KINDS
    from .detectors import DetectorKind as DetectorKind
    from .detectors import DetectorParams as DetectorParams
    from .detectors import StreamingDetector as StreamingDetector
    from .height_detector import HEIGHT_MODES as HEIGHT_MODES
    from .height_detector import HeightDetectorParams as HeightDetectorParams
    from .height_detector import HeightMode as HeightMode
    from .height_detector import HeightStanceDetector as HeightStanceDetector
    from .levels import LevelCounts as LevelCounts
    from .levels import StanceLevelParams as StanceLevelParams
    from .levels import StanceLevels as StanceLevels
else:  # type checkers read the imports above; at run time the same names are lazy attributes
    __all__, __getattr__, __dir__ = lazy_exports(__name__, __file__)
