"""The unit's own solutions as footnav estimates: its INS states and its stepwise dead reckoning.

Both adapters take the decoded batches of :class:`footnav.device.unit.OpenShoeUnit` (already in
footnav's z-up frame, ``footnav.device.protocol.ins_states`` and ``.stepwise``) and give
:class:`footnav.pipeline.nav_types.NavBatch` es, so that the unit's on-board solution reaches the same
sinks, entity paths and blueprint as footnav's own filter.

- **INS states** (0x33, then states 0x01, 0x20–0x23): one estimate per packet at the unit's time
  stamp. The unit sends no zero-velocity flag; a sample is shown as stance when the on-board speed
  is below :data:`ONBOARD_STANCE_SPEED_MPS` (the ZUPT holds it near zero: OpenShoe's σ_v = 0.01 m/s,
  Nilsson et al. 2014). The error covariance P (state 0x23) gives the position block and, with the
  z component of the attitude error, the (x, y, z, ψ) covariance. Clearance is the height above the
  last stance's level.
- **Stepwise dead reckoning** (0x34; 0x14 on 2014 firmware): one estimate per applied packet, at its
  host receive time (the packets carry no device time), foot still (each packet is a filter reset in
  a stance), heading the accumulated ψ, covariance the accumulated first-order one of
  :class:`footnav.device.protocol.stepwise.StepwiseTracker`; packets of at least ``MIN_STEP_M`` are
  step onsets. There is no swing: velocity and clearance are zero.

Reference: J.-O. Nilsson, I. Skog, P. Händel, K. V. S. Hari, "Foot-mounted INS for everybody – an
open-source embedded implementation", IEEE/ION PLANS 2012; protocol-openshoe.md sections 5, 7.
"""

from __future__ import annotations

import numpy as np
from footnav.device.protocol.ins_states import InsStateBatch
from footnav.device.protocol.stepwise import StepBatch
from footnav.pipeline.nav_types import NavBatch
from footnav.pipeline.navigation.navigator import NavStats
from numpy.typing import NDArray

ONBOARD_STANCE_SPEED_MPS = 0.05
"""On-board INS samples slower than this are shown as stance, m/s (the unit sends no ZUPT flag)."""
MIN_STEP_SPACING_S = 1e-3
"""Stepwise packets read at once (one host stamp) are shown this far apart in time, s."""
POS_YAW_ROWS = np.array([0, 1, 2, 8])
"""Rows of (x, y, z, ψ) in the on-board 9-state error (δpos, δvel, δatt): ψ is δatt's z component."""


def yaw_quat_wxyz(heading_rad: NDArray[np.float64]) -> NDArray[np.float64]:
    """(n, 4) rotation by ``heading_rad`` (n,) about z, scalar first."""
    half = 0.5 * np.asarray(heading_rad, dtype=np.float64)
    zeros = np.zeros_like(half)
    return np.column_stack([np.cos(half), zeros, zeros, np.sin(half)])


class OnboardInsNavigator:
    """The unit's INS states (:class:`InsStateBatch`, t_s on the session clock) as NavBatches.

    A ``BatchNavigator`` for ``footnav.pipeline.runner.run_pipeline``: ``rate_hz`` is the unit's output
    rate (measured from its clock by the session); nothing here depends on it.
    """

    def __init__(self, rate_hz: float) -> None:
        self.rate_hz = rate_hz
        self.stats = NavStats()
        self._floor_z_m = 0.0

    def retime(self, rate_hz: float) -> None:
        """Take the rate the unit's clock gives (shown only: the unit integrates at its own rate)."""
        self.rate_hz = rate_hz

    def process(self, batch: InsStateBatch) -> NavBatch | None:
        """One estimate per packet; None for a batch without positions (states not requested)."""
        n = len(batch)
        self.stats.samples_in += n
        if n == 0 or batch.pos_n_m is None:
            return None
        vel = batch.vel_n_mps if batch.vel_n_mps is not None else np.full((n, 3), np.nan)
        quat = batch.quat_nb_wxyz if batch.quat_nb_wxyz is not None else np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
        stance = np.linalg.norm(vel, axis=1) < ONBOARD_STANCE_SPEED_MPS
        if batch.cov_9x9 is not None:
            cov4 = batch.cov_9x9[:, POS_YAW_ROWS[:, None], POS_YAW_ROWS]
            pos_cov = cov4[:, :3, :3]
        else:
            cov4, pos_cov = None, np.zeros((n, 3, 3))
        floor = self._floor_levels(batch.pos_n_m[:, 2], stance)
        self.stats.samples_out += n
        nan = np.full(n, np.nan)
        return NavBatch(
            t_s=batch.t_s,
            pos_n_m=batch.pos_n_m,
            vel_n_mps=vel,
            quat_nb_wxyz=quat,
            pos_cov_n_m2=pos_cov,
            stance=stance,
            detector_stat=nan,
            detector_threshold=nan,
            clearance_m=batch.pos_n_m[:, 2] - floor,
            host_ns=batch.host_ns,
            cov_pos_yaw=cov4,
        )

    def _floor_levels(self, z_m: NDArray[np.float64], stance: NDArray[np.bool_]) -> NDArray[np.float64]:
        """(n,) the height of the last stance sample at or before each sample (carried over batches)."""
        idx = np.where(stance, np.arange(z_m.size), -1)
        np.maximum.accumulate(idx, out=idx)
        floor = np.where(idx >= 0, z_m[np.maximum(idx, 0)], self._floor_z_m)
        self._floor_z_m = float(floor[-1])
        return floor


class OnboardStepNavigator:
    """The unit's stepwise dead reckoning (:class:`StepBatch`, host stamps on the session's clock) as
    NavBatches: t_s is the host time since the first packet, s.

    ``rate_hz`` is nominal (the packets come once per step, with no device clock); ``retime`` is never
    needed.
    """

    def __init__(self, rate_hz: float = 1.0) -> None:
        self.rate_hz = rate_hz
        self.stats = NavStats()
        self._host0_ns: int | None = None
        self._last_t_s = -np.inf

    def retime(self, rate_hz: float) -> None:
        self.rate_hz = rate_hz

    def process(self, batch: StepBatch) -> NavBatch | None:
        """One estimate per applied packet, in order."""
        n = len(batch)
        self.stats.samples_in += n
        if n == 0:
            return None
        if self._host0_ns is None:
            self._host0_ns = int(batch.host_ns[0])
        self.stats.samples_out += n
        t_s = (batch.host_ns - self._host0_ns) / 1e9
        # packets read at once share a host stamp: at least MIN_STEP_SPACING_S apart, in order
        ramp = MIN_STEP_SPACING_S * np.arange(n)
        u = t_s - ramp
        u[0] = max(u[0], self._last_t_s + MIN_STEP_SPACING_S)
        t_s = np.maximum.accumulate(u) + ramp
        self._last_t_s = float(t_s[-1])
        zeros = np.zeros(n)
        nan = np.full(n, np.nan)
        return NavBatch(
            t_s=t_s,
            pos_n_m=batch.pos_n_m,
            vel_n_mps=np.zeros((n, 3)),
            quat_nb_wxyz=yaw_quat_wxyz(batch.heading_rad),
            pos_cov_n_m2=batch.cov_4x4[:, :3, :3],
            stance=np.ones(n, dtype=bool),
            detector_stat=nan,
            detector_threshold=nan,
            clearance_m=zeros,
            host_ns=batch.host_ns,
            cov_pos_yaw=batch.cov_4x4,
            step_onsets=np.flatnonzero(batch.is_step),
        )
