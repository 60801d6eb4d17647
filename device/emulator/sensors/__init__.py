"""The emulated sensors: IMU errors, ToF range sensors, the dual-IMU board, the miscalibrated unit on its jig."""

from typing import TYPE_CHECKING

from footnav.pipeline._lazy import lazy_exports

if TYPE_CHECKING:
    from .dual_imu import DualImuRecording as DualImuRecording
    from .dual_imu import DualImuTruth as DualImuTruth
    from .dual_imu import simulate_dual_imu as simulate_dual_imu
    from .icosahedron import IcosahedronTruth as IcosahedronTruth
    from .icosahedron import Miscalibration as Miscalibration
    from .icosahedron import miscalibrated_signals as miscalibrated_signals
    from .icosahedron import simulate_icosahedron as simulate_icosahedron
    from .imu_errors import AXIS_ERRORS as AXIS_ERRORS
    from .imu_errors import IMU_GRADES as IMU_GRADES
    from .imu_errors import AxisErrors as AxisErrors
    from .imu_errors import ImuErrorsApplied as ImuErrorsApplied
    from .imu_errors import ImuGrade as ImuGrade
    from .imu_errors import corrupt as corrupt
    from .tof import DEFAULT_MOUNTS as DEFAULT_MOUNTS
    from .tof import TofMount as TofMount
    from .tof import TofSensorModel as TofSensorModel
    from .tof import tof_readings as tof_readings
else:  # type checkers read the imports above; at run time the same names are lazy attributes
    __all__, __getattr__, __dir__ = lazy_exports(__name__, __file__)
