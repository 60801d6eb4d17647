"""Between IMU batches and the filter: the inputs ``eskf.run_filter`` takes from a batch, the samples
no sensor can report, and the :class:`NavBatch` made of the filter's per-sample outputs."""

from __future__ import annotations

import dataclasses

import numpy as np
from footnav.pipeline.aiding.baro import PressureAltitude
from footnav.pipeline.aiding.tof_types import RangeOutputs
from footnav.pipeline.gait.clearance import StrideClearance
from footnav.pipeline.nav_types import NavBatch
from footnav.pipeline.navigation.saturation import clipped_rate_variance
from footnav.pipeline.samples import ImuBatch
from numpy.typing import NDArray

F64 = NDArray[np.float64]


def nav_batch(
    batch: ImuBatch,
    pos: F64,
    vel: F64,
    quat: F64,
    cov_pos_yaw: F64,
    stat: F64,
    threshold: F64,
    still: NDArray[np.bool_],
    *,
    floor_z_m: F64 | None = None,
    ranges: RangeOutputs | None = None,
    clearance_m: F64 | None = None,
    strides: StrideClearance | None = None,
    altitude: PressureAltitude | None = None,
) -> NavBatch:
    """The :class:`NavBatch` of ``batch``'s samples from the filter's per-sample outputs.

    Clearance is the height above ``floor_z_m`` (n,) when the floor under the IMU is known (ToF),
    else above the floor the walk started on (z = 0), unless given as ``clearance_m``.
    """
    if clearance_m is None:
        clearance_m = pos[:, 2].copy() if floor_z_m is None else pos[:, 2] - floor_z_m
    return NavBatch(
        t_s=batch.t_s,
        pos_n_m=pos,
        vel_n_mps=vel,
        quat_nb_wxyz=quat,
        pos_cov_n_m2=cov_pos_yaw[:, :3, :3],
        stance=still,
        detector_stat=stat,
        detector_threshold=threshold,
        clearance_m=clearance_m,
        host_ns=batch.host_ns,
        cov_pos_yaw=cov_pos_yaw,
        floor_z_m=floor_z_m,
        ranges=ranges,
        strides=strides,
        altitude=altitude,
    )


NO_CLIPPED_RATES = np.empty((0, 3))
"""``eskf.run_filter``'s clipped-rate variance when no sample is marked clipped."""


def clip_variance(batch: ImuBatch) -> F64:
    """The body-axis rate variance of ``batch``'s clipped samples (``footnav.pipeline.navigation.saturation``) as
    ``eskf.run_filter`` takes it: (n, 3), or (0, 3) when none is marked."""
    if batch.gyr_clipped_b is None or not batch.gyr_clipped_b.any():
        return NO_CLIPPED_RATES
    return clipped_rate_variance(batch.gyr_b_radps, batch.gyr_clipped_b)


def zupt_ratio(stat: F64, threshold: F64) -> F64:
    """The detector's statistic over its threshold, T/γ (n,), contiguous, as ``eskf.run_filter``
    takes it (the vertical noise of each zero-velocity update, ``footnav.pipeline.navigation.eskf``)."""
    return np.ascontiguousarray(stat / threshold, dtype=np.float64)


MAX_ABS_ACC_MPS2 = 2000.0
"""|specific force| no foot IMU can report (about 200 g: full scales are ±16-18 g, e.g. MPU-6500,
ADIS16367, 3DM-GX3 datasheets); a larger value is a corrupt sample."""
MAX_ABS_GYR_RADPS = 100.0
"""|angular rate| no foot IMU can report (about 5700 °/s: full scales are ±1200-2000 °/s)."""


def implausible_to_nan(batch: ImuBatch) -> ImuBatch:
    """``batch`` with samples no sensor can report (corrupt records: a flipped exponent bit) set to
    NaN, so the detector and the filter skip and count them as bad samples instead of integrating
    them (the same object when there are none)."""
    if _within(batch.acc_b_mps2, MAX_ABS_ACC_MPS2) and _within(batch.gyr_b_radps, MAX_ABS_GYR_RADPS):
        return batch  # the common case, by two reductions per array instead of a full mask
    bad = (np.abs(batch.acc_b_mps2) > MAX_ABS_ACC_MPS2).any(axis=1) | (
        np.abs(batch.gyr_b_radps) > MAX_ABS_GYR_RADPS
    ).any(axis=1)
    if not bad.any():
        return batch
    acc, gyr = batch.acc_b_mps2.copy(), batch.gyr_b_radps.copy()
    acc[bad], gyr[bad] = np.nan, np.nan
    return dataclasses.replace(batch, acc_b_mps2=acc, gyr_b_radps=gyr)


def _within(values: F64, bound: float) -> bool:
    """Every value of ``values`` is within ±``bound`` (False when one is NaN, or there are none)."""
    if values.size == 0:
        return False
    return bool(values.max() <= bound and values.min() >= -bound)
