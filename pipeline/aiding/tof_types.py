"""The ToF aiding's data: range readings, the sensors' mounting and settings, per-sample outputs and
the counts of what became of each reading (:mod:`footnav.pipeline.aiding.tof` uses them)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from footnav.pipeline.aiding import tof_measurement as tu
from footnav.pipeline.stance.height_detector import HeightDetectorParams
from numpy.typing import NDArray

F64 = NDArray[np.float64]


def _unit(v: tuple[float, float, float]) -> tuple[float, float, float]:
    n = math.sqrt(v[0] ** 2 + v[1] ** 2 + v[2] ** 2)
    return (v[0] / n, v[1] / n, v[2] / n)


DEFAULT_LEVER_B_M: tuple[tuple[float, float, float], ...] = (
    (0.12, 0.0, 0.03),  # toe
    (0.0, -0.045, 0.03),  # mid-foot, outer side
    (-0.10, 0.0, 0.04),  # heel
)
"""Sensor positions from the IMU's reference point, body axes (x toe, y left, z up), m. The
multi-sensor paper places three sensors along the sole without coordinates; these are assumptions,
shared with the emulator (``footnav.device.emulator.sensors.tof``)."""

DEFAULT_DIR_B: tuple[tuple[float, float, float], ...] = (
    _unit((0.17, 0.0, -1.0)),  # toe, tilted 10° forward
    (0.0, 0.0, -1.0),
    _unit((-0.17, 0.0, -1.0)),  # heel, tilted 10° back
)
"""Sensor viewing directions, unit vectors in body axes."""

STATUS_NAMES: dict[int, str] = {1: "timeout", 2: "no_target", 3: "weak_signal", 4: "sensor_error"}
"""Status codes of the ToF extension state (``footnav.device.protocol.extensions``); 0 is a valid reading."""

CODE_NAMES: dict[int, str] = {
    tu.USED: "used",
    tu.NOT_FINITE: "not_finite",
    tu.BELOW_FLOOR: "below_floor",
    tu.STEP_EDGE: "step_edge",
    tu.OUTLIER: "outlier",
}
# codes beyond the measurement's own
FLOOR_PENDING, INVALID_STATUS, UNKNOWN_SENSOR, DISABLED = 10, 11, 12, 13
CODE_NAMES |= {
    FLOOR_PENDING: "floor_pending",
    INVALID_STATUS: "invalid_status",
    UNKNOWN_SENSOR: "unknown_sensor",
    DISABLED: "not_used",
}


@dataclass(frozen=True, slots=True)
class RangeBatch:
    """ToF range readings handed to the navigator, in time order.

    Attributes
    ----------
    t_s
        (m,) device time of each measurement, s (the IMU's clock).
    sensor
        (m,) sensor index.
    range_m
        (m,) range, m (NaN when there is none).
    status
        (m,) the unit's status byte (0 valid; see :data:`STATUS_NAMES`).
    """

    t_s: F64
    sensor: NDArray[np.int64]
    range_m: F64
    status: NDArray[np.uint8]

    def __len__(self) -> int:
        return int(self.t_s.shape[0])

    def select(self, index: slice | NDArray[np.bool_] | NDArray[np.int64]) -> RangeBatch:
        return RangeBatch(self.t_s[index], self.sensor[index], self.range_m[index], self.status[index])

    @staticmethod
    def concat(batches: list[RangeBatch]) -> RangeBatch:
        return RangeBatch(
            np.concatenate([b.t_s for b in batches]),
            np.concatenate([b.sensor for b in batches]),
            np.concatenate([b.range_m for b in batches]),
            np.concatenate([b.status for b in batches]),
        )


@dataclass(frozen=True, slots=True)
class TofConfig:
    """ToF aiding settings (SI units).

    Attributes
    ----------
    lever_b_m, dir_b
        Per sensor, position from the IMU and unit viewing direction (body axes).
    use
        Apply the readings (False: decode, count and show them only; the inertial-only run).
    sigma_range_m
        Range noise 1σ (VL53L0X about 1 cm on a white target within 1.2 m, ST DS11555).
    sigma_floor_m
        Floor roughness and unlevelness 1σ added to each reading.
    gate_chi2
        Normalised-innovation gate, χ²(1) at 99.9 %.
    step_m
        Innovations larger than this are step edges (half the smallest riser footnav expects).
    below_m
        A measured height more than this under the floor is rejected.
    same_floor_m, snap_m, decide_readings, decide_after_s, hit_memory
        The floor reference (module docstring).
    new_level_sigma_m
        1σ of the vertical position relative to a new level when it is placed (the IMU's reference
        point resting on the tread; module docstring).
    update_in_swing
        Apply readings in swing too (else only in stance).
    detector
        Zero-velocity detection with the foot's height (``footnav.pipeline.stance.height_detector``).
    """

    lever_b_m: tuple[tuple[float, float, float], ...] = DEFAULT_LEVER_B_M
    dir_b: tuple[tuple[float, float, float], ...] = DEFAULT_DIR_B
    use: bool = True
    sigma_range_m: float = 0.01
    sigma_floor_m: float = 0.003
    gate_chi2: float = 10.83
    step_m: float = 0.06
    below_m: float = 0.03
    same_floor_m: float = 0.06
    snap_m: float = 0.04
    decide_readings: int = 5
    decide_after_s: float = 0.15
    update_in_swing: bool = True
    hit_memory: int = 12
    new_level_sigma_m: float = 0.001
    detector: HeightDetectorParams = field(default_factory=HeightDetectorParams)


@dataclass(frozen=True, slots=True)
class RangeOutputs:
    """What became of each reading handled in one batch (for the views and the counts).

    Attributes
    ----------
    t_s
        (m,) reading time, s.
    sensor
        (m,) sensor index.
    status
        (m,) the unit's status byte.
    height_m
        (m,) the IMU's height above the surface hit, measured through the estimated attitude (NaN
        when the reading had no range).
    code
        (m,) what was done (:data:`CODE_NAMES`).
    innovation_m
        (m,) innovation against the reference floor (NaN when not computed).
    floor_z_m
        (m,) the reference floor level in force.
    hit_point_n_m
        (m, 3) where the reading's ray hit a floor (x, y) and that surface's height (a known level,
        else where the ray hit), m; NaN for readings that gave no floor hit.
    hit_on_level
        (m,) the surface height is a known level.
    """

    t_s: F64
    sensor: NDArray[np.int64]
    status: NDArray[np.uint8]
    height_m: F64
    code: NDArray[np.int64]
    innovation_m: F64
    floor_z_m: F64
    hit_point_n_m: F64
    hit_on_level: NDArray[np.bool_]

    def __len__(self) -> int:
        return int(self.t_s.shape[0])


@dataclass
class TofCounts:
    """Readings by what became of them, since the start (names of :data:`CODE_NAMES` and, for invalid
    statuses, of :data:`STATUS_NAMES`), plus ``late`` (applied after the IMU sample of their time)."""

    by_reason: dict[str, int] = field(default_factory=dict)

    def add(self, name: str, n: int = 1) -> None:
        self.by_reason[name] = self.by_reason.get(name, 0) + n

    def get(self, name: str) -> int:
        return self.by_reason.get(name, 0)

    @property
    def total(self) -> int:
        return sum(v for k, v in self.by_reason.items() if k != "late")
