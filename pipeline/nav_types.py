"""What the estimators hand to the sinks: navigation estimates with their covariance."""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from footnav.pipeline.aiding.baro import PressureAltitude
    from footnav.pipeline.aiding.tof import RangeOutputs
    from footnav.pipeline.gait.clearance import StrideClearance

F64 = NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class NavBatch:
    """Per-sample navigation estimates for a run of IMU samples.

    Navigation frame: right-handed, z up, origin at the start position (see architecture.md).

    Attributes:
        t_s: (n,) device time, s.
        pos_n_m: (n, 3) position of the IMU, m.
        vel_n_mps: (n, 3) velocity, m/s.
        quat_nb_wxyz: (n, 4) attitude, body to navigation, scalar first.
        pos_cov_n_m2: (n, 3, 3) position covariance, m².
        stance: (n,) True where the zero-velocity detector declared the foot still.
        detector_stat: (n,) the detector's test statistic (dimensionless).
        detector_threshold: (n,) the threshold in force at each sample (it adapts to the gait).
        clearance_m: (n,) height of the IMU above the floor under it, m: above ``floor_z_m`` when the
            ToF sensors give it (except between the hits on both sides of a step edge, where the
            floor is interpolated between the two treads: ``footnav.pipeline.aiding.tof``), else above the
            floor level of the foot's stance, in swing of the stance it left
            (``footnav.pipeline.stance.levels``; without them, the floor the walk started on, z = 0).
        host_ns: (n,) host receive time of each sample (latency accounting).
        cov_pos_yaw: (n, 4, 4) covariance of (x, y, z, ψ) when the estimator provides it (steps,
            heading uncertainty); ``pos_cov_n_m2`` is its upper-left block.
        floor_z_m: (n,) estimated height of the floor under the IMU (ToF units), else None.
        ranges: the ToF readings handled with these samples and what became of each, else None.
        strides: per-stride clearance of the swings that ended in these samples, else None.
        altitude: barometer pressure altitude of the readings received since the last batch, else None.
        smoothed: step-smoothed estimates of earlier samples whose step ended in this batch
            (``footnav.pipeline.smoothing.stepwise``), else None.
    """

    t_s: F64
    pos_n_m: F64
    vel_n_mps: F64
    quat_nb_wxyz: F64
    pos_cov_n_m2: F64
    stance: NDArray[np.bool_]
    detector_stat: F64
    detector_threshold: F64
    clearance_m: F64
    host_ns: NDArray[np.int64]
    cov_pos_yaw: F64 | None = None
    floor_z_m: F64 | None = None
    ranges: RangeOutputs | None = None
    strides: StrideClearance | None = None
    altitude: PressureAltitude | None = None
    smoothed: SmoothedSpan | None = None

    def __len__(self) -> int:
        return int(self.t_s.shape[0])


@dataclass(frozen=True, slots=True)
class SmoothedSpan:
    """Smoothed estimates of consecutive samples already given causally (``footnav.pipeline.smoothing.stepwise``).

    Attributes:
        first_sample: index of the first of them among the navigated samples (0: the first sample
            after alignment).
        t_s: (m,) their device time, s.
        pos_n_m, vel_n_mps, quat_nb_wxyz: (m, 3), (m, 3), (m, 4), as in :class:`NavBatch`.
        clearance_m: (m,) height of the IMU above the same floor as the causal estimate's, m.
        cov_pos_yaw: (m, 4, 4) covariance of (x, y, z, ψ), when it was asked for (it costs most of
            the smoothing: live sessions show the smoothed track alone).
    """

    first_sample: int
    t_s: F64
    pos_n_m: F64
    vel_n_mps: F64
    quat_nb_wxyz: F64
    clearance_m: F64
    cov_pos_yaw: F64 | None = None

    def __len__(self) -> int:
        return int(self.t_s.shape[0])

    @staticmethod
    def concat(spans: list[SmoothedSpan]) -> SmoothedSpan | None:
        """Consecutive spans joined into one (None for none); raises ValueError if they leave a gap."""
        if not spans:
            return None
        for s0, s1 in itertools.pairwise(spans):
            if s1.first_sample != s0.first_sample + len(s0):
                raise ValueError(f"smoothed spans are not consecutive: {s0.first_sample}+{len(s0)}, {s1.first_sample}")
        if len(spans) == 1:
            return spans[0]
        return SmoothedSpan(
            first_sample=spans[0].first_sample,
            t_s=np.concatenate([s.t_s for s in spans]),
            pos_n_m=np.concatenate([s.pos_n_m for s in spans]),
            vel_n_mps=np.concatenate([s.vel_n_mps for s in spans]),
            quat_nb_wxyz=np.concatenate([s.quat_nb_wxyz for s in spans]),
            clearance_m=np.concatenate([s.clearance_m for s in spans]),
            cov_pos_yaw=concat_if_all([s.cov_pos_yaw for s in spans]),
        )


def concat_if_all(parts: list[F64 | None]) -> F64 | None:
    """The arrays joined along their first axis when every part has one, else None."""
    present = [p for p in parts if p is not None]
    return np.concatenate(present) if len(present) == len(parts) else None
