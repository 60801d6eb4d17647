"""Floor levels from the stances alone: a gated height constraint for the inertial-only filter.

A foot at rest stands on a floor, and floors are level: a stance on the floor of the previous stance
puts the IMU at the height it had there, within the stance-to-stance scatter of its rest height. The
height constraint of Abdulrahim, Hide, Moore and Hill ("Using constraints for shoe mounted indoor
pedestrian navigation", J. Navigation 65(1), 2012, §4) applies this when the height changed less than
a threshold since the last stance and not otherwise, so a stair (one or two risers, 10-40 cm, per
stride) starts a new level and a level walk is held on its floor. footnav keeps every level stood on
and returns to one within ``snap_m`` (the way back down a flight ends on the floor it started from).

The measurement, once per stance (at its last sample, when the zero-velocity updates have corrected
the position by what they learned about the swing; a stance shorter than ``min_stance_s`` is not
used):

    0 = p_z − z_level + w,   w ~ N(0, σ²),  σ = ``sigma_m``

with z_level the level's height. The start floor is z = 0 by definition of the frame (the IMU rests
on it at alignment) and is not a state. Every other level is a state of the filter, a stochastic
clone of δp_z when it is placed (Roumeliotis and Burdick, ICRA 2002; as the ToF floor levels of
:mod:`pipeline.tof_aiding`), so what the filter learns later corrects the level too. The levels
stood on most recently, up to :data:`LEVEL_STATES`, are states; an older one leaves the state
(marginalised) and keeps its height.

What it assumes, and what it costs: the floor under a stance is one of the levels already stood on
when it is within ``same_level_m`` of the last one (or ``snap_m`` of another); a height change of less
than that per stride (a ramp of under about 4 %, a 5 cm threshold, a thick mat) is taken for drift
and removed. Larger changes are kept as they are measured, so stairs stay stairs. ``use = False``
turns it off (the inertial-only filter of the README's "without levels" rows).

``sigma_m``: the rest height of the IMU scatters from stance to stance on one floor by the foot's
posture at rest. On the PyShoe VICON trials the motion-capture height of the foot at consecutive
detected stances differs by a median of 0.2-0.7 cm (90th percentile 0.5-2.7 cm, measured here on
the nine trials of ``../shared/data``); 1 cm is used.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit
from numpy.typing import NDArray

from pipeline.eskf import N_STATE, P0, inject

F64 = NDArray[np.float64]

LEVEL_STATES = 8
"""Floor levels kept as states of the filter by default (the most recently stood on)."""


@njit(cache=True, error_model="numpy", fastmath={"contract"})
def height_update(x: F64, P: F64, level: int, z_level_m: float, r_m2: float, work: F64) -> None:
    """The stance height update 0 = p_z − z_level + w, var(w) = ``r_m2``, on ``x`` (n + 1,) and ``P``
    (n, n) in place: z_level is the error state ``level`` (nominal x[level + 1]) when ``level`` ≥ 0,
    else the constant ``z_level_m``. Scalar Joseph form, P ← P − K uᵀ − u Kᵀ + K S Kᵀ with u = P Hᵀ,
    S = H u + r, K = u / S (as ``pipeline.tof_update``), then injection and reset (Solà 2017, §7.3).
    ``work`` is (2, n) scratch."""  # pragma: no cover
    n = P.shape[0]
    z_level = x[level + 1] if level >= 0 else z_level_m
    for i in range(n):
        work[0, i] = P[i, P0 + 2] - (P[i, level] if level >= 0 else 0.0)
    s = work[0, P0 + 2] - (work[0, level] if level >= 0 else 0.0) + r_m2
    y = z_level - x[P0 + 2]
    for i in range(n):
        work[1, i] = work[0, i] / s
    for i in range(n):
        for j in range(n):
            P[i, j] += s * work[1, i] * work[1, j] - work[1, i] * work[0, j] - work[0, i] * work[1, j]
    for i in range(n):
        work[0, i] = work[1, i] * y
    inject(x, P, work[0])


def stance_ends(still: NDArray[np.bool_], carried: int) -> tuple[list[tuple[int, int]], int]:
    """Where a batch's stances end, for a navigator that updates after each stance's last sample.

    Args:
        still: (n,) stance flags of the batch.
        carried: samples of the stance in progress at the end of the previous batch (0: in swing).

    Returns:
        (b, length) for each stance that ends in the batch: b the first sample after it (its last
        sample is b − 1, of the previous batch when b = 0), length its samples; and the samples of
        the stance in progress at the end of this batch (0 when it ends in swing), to carry on.
    """
    n = still.shape[0]
    prev = np.empty(n, dtype=np.bool_)
    prev[0], prev[1:] = carried > 0, still[:-1]
    starts = np.flatnonzero(~prev & still)
    ends = []
    for b in np.flatnonzero(prev & ~still).tolist():
        begun = starts[starts < b]
        ends.append((b, b - int(begun[-1]) if begun.size else carried + b))
    if n == 0 or not still[-1]:
        return ends, 0 if n else carried
    return ends, n - int(starts[-1]) if starts.size else carried + n


@dataclass(frozen=True, slots=True)
class StanceLevelParams:
    """Settings of the stance height constraint (module docstring), SI units.

    Attributes:
        use: apply the constraint (False: the inertial-only filter without it).
        sigma_m: 1σ of the IMU's rest height about its floor level, stance to stance.
        same_level_m: a stance within this of the last stance's level is on that level.
        snap_m: else, a stance within this of another known level is back on that level.
        min_stance_s: stances shorter than this are not used.
        new_level_sigma_m: 1σ added to a new level's clone of the height error.
        level_states: how many levels are states of the filter (0: each level is a constant, its
            height where it was first stood on; the smoother's forward pass, ``pipeline.smoother``).
    """

    use: bool = True
    sigma_m: float = 0.01
    same_level_m: float = 0.05
    snap_m: float = 0.05
    min_stance_s: float = 0.0
    new_level_sigma_m: float = 0.001
    level_states: int = LEVEL_STATES


@dataclass
class LevelCounts:
    """What the stances did since the start."""

    updates: int = 0
    new_levels: int = 0
    returns: int = 0
    short_stances: int = 0


class StanceLevels:
    """The floor levels of one foot and their height update (module docstring)."""

    def __init__(self, params: StanceLevelParams) -> None:
        self.params = params
        self.levels_z_m: list[float] = [0.0]
        self._state: list[int] = [-1]
        """Per level, its error-state index (−1: not a state; the start floor never is)."""
        self._used: list[int] = [0]
        self._ref = 0
        self._stance_no = 0
        self._work = np.zeros((2, N_STATE))
        self.counts = LevelCounts()

    @property
    def floor_z_m(self) -> float:
        """Height of the level of the last stance, m."""
        return self.levels_z_m[self._ref]

    def sync(self, x: F64) -> None:
        """Read the heights of the levels that are states from ``x``."""
        for k, i in enumerate(self._state):
            if i >= 0:
                self.levels_z_m[k] = float(x[i + 1])

    def stance_end(self, x: F64, P: F64, duration_s: float) -> tuple[F64, F64, float]:
        """The height update at the last sample of a stance of ``duration_s``; returns the state and
        covariance (grown by one when a new level became a state, else the same arrays, updated in
        place) and the height of the level it was updated against (NaN: no update)."""
        cfg = self.params
        if not cfg.use:
            return x, P, math.nan
        if duration_s < cfg.min_stance_s or not math.isfinite(float(x[P0 + 2])):
            self.counts.short_stances += 1
            return x, P, math.nan
        self.sync(x)
        self._stance_no += 1
        z = float(x[P0 + 2])
        if abs(z - self.floor_z_m) > cfg.same_level_m:
            k = min(range(len(self.levels_z_m)), key=lambda i: abs(self.levels_z_m[i] - z))
            if abs(self.levels_z_m[k] - z) <= cfg.snap_m:
                self._ref = k
                self.counts.returns += 1
            else:
                x, P = self._new_level(x, P)
                self._used[self._ref] = self._stance_no
                return x, P, math.nan
        self._used[self._ref] = self._stance_no
        z_level = self.floor_z_m
        if self._work.shape[1] != P.shape[0]:
            self._work = np.zeros((2, P.shape[0]))
        height_update(x, P, self._state[self._ref], z_level, cfg.sigma_m**2, self._work)
        self.counts.updates += 1
        self.sync(x)
        return x, P, z_level

    def _new_level(self, x: F64, P: F64) -> tuple[F64, F64]:
        """A new level where the state puts the IMU, its error a clone of δp_z."""
        self.counts.new_levels += 1
        self.levels_z_m.append(float(x[2]))
        self._used.append(self._stance_no)
        self._ref = len(self.levels_z_m) - 1
        if self.params.level_states == 0:
            self._state.append(-1)
            return x, P
        i = self._free_state(P)
        if i >= P.shape[0]:
            x_grown, P_grown = np.zeros(x.shape[0] + 1), np.zeros((P.shape[0] + 1, P.shape[1] + 1))
            x_grown[:-1], P_grown[:-1, :-1] = x, P
            x, P = x_grown, P_grown
        self._state.append(i)
        x[i + 1] = x[2]
        P[i, :] = P[P0 + 2, :]
        P[:, i] = P[:, P0 + 2]
        P[i, i] = P[P0 + 2, P0 + 2] + self.params.new_level_sigma_m**2
        return x, P

    def _free_state(self, P: F64) -> int:
        """An error-state index for a new level: an unused one, one more (up to ``level_states``),
        else the one of the level stood on longest ago, which leaves the state and keeps its height."""
        taken = {i for i in self._state if i >= 0}
        for i in range(N_STATE, P.shape[0]):
            if i not in taken:
                return i
        if P.shape[0] - N_STATE < self.params.level_states:
            return P.shape[0]
        oldest = min((k for k, i in enumerate(self._state) if i >= 0), key=lambda k: self._used[k])
        i = self._state[oldest]
        self._state[oldest] = -1
        P[i, :] = 0.0
        P[:, i] = 0.0
        return i
