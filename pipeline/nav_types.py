"""What the estimators hand to the sinks: navigation estimates with their covariance."""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple, TypeVar

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from footnav.pipeline.aiding.baro import PressureAltitude
    from footnav.pipeline.aiding.tof_types import RangeOutputs
    from footnav.pipeline.gait.clearance import StrideClearance

F64 = NDArray[np.float64]


class ClearanceSeries(NamedTuple):
    """Clearance of samples whose value became final with a batch (``NavBatch.swing_clearance``)."""

    t_s: F64
    """(m,) device time, s."""
    clearance_m: F64
    """(m,) height of the IMU above the floor under it, m."""


@dataclass(frozen=True, slots=True)
class NavBatch:
    """Per-sample navigation estimates for a run of IMU samples.

    Navigation frame: right-handed, z up, origin at the start position (see architecture.md).

    Attributes
    ----------
    t_s
        (n,) device time, s.
    pos_n_m
        (n, 3) position of the IMU, m.
    vel_n_mps
        (n, 3) velocity, m/s.
    quat_nb_wxyz
        (n, 4) attitude, body to navigation, scalar first.
    pos_cov_n_m2
        (n, 3, 3) position covariance, m².
    stance
        (n,) True where the zero-velocity detector declared the foot still.
    detector_stat
        (n,) the detector's test statistic (dimensionless).
    detector_threshold
        (n,) the threshold in force at each sample (it adapts to the gait).
    clearance_m
        (n,) height of the IMU above the floor under it, m: above ``floor_z_m`` when the
        ToF sensors give it (except between the hits on both sides of a step edge, where the
        floor is interpolated between the two treads: ``footnav.pipeline.aiding.tof``), else above the
        floor level of the foot's stance, in swing of the stance it left
        (``footnav.pipeline.stance.levels``; without them, the floor the walk started on, z = 0).
    host_ns
        (n,) host receive time of each sample (latency accounting).
    cov_pos_yaw
        (n, 4, 4) covariance of (x, y, z, ψ) when the estimator provides it (steps,
        heading uncertainty); ``pos_cov_n_m2`` is its upper-left block.
    floor_z_m
        (n,) estimated height of the floor under the IMU (ToF units), else None.
    ranges
        the ToF readings handled with these samples and what became of each, else None.
    strides
        per-stride clearance of the swings that ended in these samples, else None.
    altitude
        barometer pressure altitude of the readings received since the last batch, else None.
    smoothed
        step-smoothed estimates of earlier samples whose step ended in this batch
        (``footnav.pipeline.smoothing.stepwise``), else None.
    step_onsets
        (k,) indices of this batch's samples where a step lands
        (``footnav.pipeline.gait.events``), else None (not tracked).
    swing_clearance
        the whole-swing clearance of the samples, in this batch or earlier, whose
        swing has been seen whole (ToF units, ``footnav.pipeline.gait.tof_clearance``), else None.
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
    step_onsets: NDArray[np.intp] | None = None
    swing_clearance: ClearanceSeries | None = None

    def __len__(self) -> int:
        return int(self.t_s.shape[0])

    def since(self, start_s: float) -> NavBatch | None:
        """The samples at or after ``start_s`` (None: none). A batch cut in two keeps its per-sample
        arrays only: its readings, strides, altitude and smoothed span are left out (a replay window's
        first ones may be missing), its gait events are filled in again downstream."""
        if float(self.t_s[0]) >= start_s:
            return self
        if float(self.t_s[-1]) < start_s:
            return None
        k = int(np.searchsorted(self.t_s, start_s))

        def cut(a: F64 | None) -> F64 | None:
            return None if a is None else a[k:]

        return NavBatch(
            t_s=self.t_s[k:],
            pos_n_m=self.pos_n_m[k:],
            vel_n_mps=self.vel_n_mps[k:],
            quat_nb_wxyz=self.quat_nb_wxyz[k:],
            pos_cov_n_m2=self.pos_cov_n_m2[k:],
            stance=self.stance[k:],
            detector_stat=self.detector_stat[k:],
            detector_threshold=np.broadcast_to(self.detector_threshold, self.t_s.shape)[k:],
            clearance_m=self.clearance_m[k:],
            host_ns=self.host_ns[k:],
            cov_pos_yaw=cut(self.cov_pos_yaw),
            floor_z_m=cut(self.floor_z_m),
        )


@dataclass(frozen=True, slots=True)
class SmoothedSpan:
    """Smoothed estimates of consecutive samples already given causally (``footnav.pipeline.smoothing.stepwise``).

    Attributes
    ----------
    first_sample
        index of the first of them among the navigated samples (0: the first sample
        after alignment).
    t_s
        (m,) their device time, s.
    pos_n_m, vel_n_mps, quat_nb_wxyz
        (m, 3), (m, 3), (m, 4), as in :class:`NavBatch`.
    clearance_m
        (m,) height of the IMU above the same floor as the causal estimate's, m.
    cov_pos_yaw
        (m, 4, 4) covariance of (x, y, z, ψ), when it was asked for (it costs most of
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


def concat_batches(batches: Sequence[NavBatch]) -> NavBatch:
    """Join consecutive batches into one (a scalar detector threshold: the last batch's is kept)."""
    if len(batches) == 1:
        return batches[0]
    if not batches:
        raise ValueError("concat_batches needs at least one NavBatch")
    return NavBatch(
        floor_z_m=_concat_optional([b.floor_z_m for b in batches], [len(b) for b in batches]),
        ranges=_concat_dataclasses([b.ranges for b in batches]),
        strides=_concat_dataclasses([b.strides for b in batches]),
        altitude=_concat_dataclasses([b.altitude for b in batches]),
        t_s=np.concatenate([b.t_s for b in batches]),
        pos_n_m=np.concatenate([b.pos_n_m for b in batches]),
        vel_n_mps=np.concatenate([b.vel_n_mps for b in batches]),
        quat_nb_wxyz=np.concatenate([b.quat_nb_wxyz for b in batches]),
        pos_cov_n_m2=np.concatenate([b.pos_cov_n_m2 for b in batches]),
        stance=np.concatenate([b.stance for b in batches]),
        detector_stat=np.concatenate([b.detector_stat for b in batches]),
        detector_threshold=np.concatenate([np.broadcast_to(b.detector_threshold, (len(b),)) for b in batches]),
        clearance_m=np.concatenate([b.clearance_m for b in batches]),
        host_ns=np.concatenate([b.host_ns for b in batches]),
        cov_pos_yaw=concat_if_all([b.cov_pos_yaw for b in batches]),
        smoothed=SmoothedSpan.concat([b.smoothed for b in batches if b.smoothed is not None]),
        step_onsets=_concat_onsets(batches),
        swing_clearance=_concat_series([b.swing_clearance for b in batches]),
    )


def _concat_optional(parts: Sequence[F64 | None], lengths: Sequence[int]) -> F64 | None:
    """Per-sample optional arrays joined; NaN where a batch had none (None if none had any)."""
    if all(p is None for p in parts):
        return None
    return np.concatenate([np.full(n, np.nan) if p is None else p for p, n in zip(parts, lengths, strict=True)])


def _concat_onsets(batches: Sequence[NavBatch]) -> NDArray[np.intp] | None:
    """Step onsets of consecutive batches as indices into the joined batch (None if none has them)."""
    if all(b.step_onsets is None for b in batches):
        return None
    starts = np.cumsum([0] + [len(b) for b in batches[:-1]])
    return np.concatenate(
        [b.step_onsets + a for b, a in zip(batches, starts, strict=True) if b.step_onsets is not None]
    ).astype(np.intp)


def _concat_series(parts: Sequence[ClearanceSeries | None]) -> ClearanceSeries | None:
    """Clearance series joined in order (None if none has one)."""
    present = [p for p in parts if p is not None]
    if not present:
        return None
    return ClearanceSeries(np.concatenate([p.t_s for p in present]), np.concatenate([p.clearance_m for p in present]))


_T = TypeVar("_T")


def _concat_dataclasses(parts: Sequence[_T | None]) -> _T | None:
    """Dataclasses of per-event arrays (ToF readings, strides, altitude) joined field by field."""
    present = [p for p in parts if p is not None]
    if not present:
        return None
    if len(present) == 1:
        return present[0]
    cls = type(present[0])
    names = [f.name for f in dataclasses.fields(cls)]  # type: ignore[arg-type]
    return cls(**{k: np.concatenate([getattr(p, k) for p in present]) for k in names})
