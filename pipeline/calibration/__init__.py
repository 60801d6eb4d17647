"""Field calibration of the IMU: the accelerometer and gyroscope model, and the guided procedure."""

from typing import TYPE_CHECKING

from footnav.pipeline._lazy import lazy_exports

if TYPE_CHECKING:
    from .model import CalibrationError as CalibrationError
    from .model import FaceCapture as FaceCapture
    from .model import IllDeterminedError as IllDeterminedError
    from .model import ImuCalibration as ImuCalibration
    from .model import MotionError as MotionError
    from .model import SaturationError as SaturationError
    from .model import TemperatureUnobservableError as TemperatureUnobservableError
    from .model import TooFewFacesError as TooFewFacesError
    from .model import face_from_samples as face_from_samples
    from .model import fit_calibration as fit_calibration
    from .procedure import FaceCollector as FaceCollector
    from .procedure import ProcedureEvent as ProcedureEvent
else:  # type checkers read the imports above; at run time the same names are lazy attributes
    __all__, __getattr__, __dir__ = lazy_exports(__name__, __file__)
