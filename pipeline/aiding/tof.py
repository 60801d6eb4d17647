"""Foot height from time-of-flight range sensors: readings, the floor reference, per-sample clearance.

The navigator (``footnav.pipeline.navigation.navigator``) splits its IMU batches at the readings' times and hands each
reading to :meth:`TofAiding.apply`, which updates the filter state in place through the compiled measurement of
:mod:`footnav.pipeline.aiding.tof_measurement` (Merat, Harvey, Mitsis, eqs. 20-21).

**Floor reference.** The update needs the height z_f of the floor the ray hits. footnav keeps the floor *levels*
stood on, starting with the start floor (z = 0: the IMU's reference point rests on it at alignment), and a
*reference level*, the floor of the current or last stance. Once a stance has lasted ``decide_after_s``, its next
``decide_readings`` valid readings are not applied but give floor observations ``p̂_z + w_z`` (where the ray hit);
their median decides the stance floor: the reference level if within ``same_floor_m`` of it, else a known level
within ``snap_m``, else a new level. The stance's later readings update the state against that level. A new level
is placed at ``p̂_z`` (the IMU's reference point resting on the tread) as a filter state: a stochastic clone of δp_z,
its variance plus ``new_level_sigma_m``² (Roumeliotis and Burdick, "Stochastic cloning", ICRA 2002). A reading on
it measures p_z + w_z − z_level (−1 at the level in the row of :mod:`.tof_measurement`), the propagation holds it
constant (F = I, Q = 0), and every update corrects it through its cross-covariances. The :data:`LEVEL_STATES` most
recently used levels are states; an older one is marginalised (its row and column dropped) and keeps its height.
In swing, readings are referenced to the last stance floor; a sensor whose reading was rejected there as a step
edge is not applied again until the next stance (its readings are counted as step edges).

**Clearance.** ``p̂_z`` minus the floor under the IMU: in a stance whose floor is decided, that floor; otherwise
from the last ``hit_memory`` hit points, each at its floor height snapped to a known level within ``snap_m`` and
counted only when another hit agrees with it within ``snap_m`` (a hit at no known level is taken at the mean height
of the hits that agree with it). In swing, hits and IMU are placed along the way walked since the last stance;
where the nearest hit behind the IMU and the nearest ahead are on different floors, the floor is interpolated
between them by distance (the tread reported is the nearer one). That bracket is intersected with the brackets of
the same edge (same two floors) learned at the end of earlier swings, between consecutive surfaces along the way,
each widened by ``EDGE_MARGIN_M``; an empty intersection is ignored. Before the IMU has moved ``SWING_MIN_M``, the
nearest hit's floor. Heights are in the navigation frame (z up), lever arms and directions in body axes; SI units.
Why this design, with its measurements: the documentation's design page "ToF aiding".
"""

from __future__ import annotations

import itertools
import math
from collections import deque
from collections.abc import Callable

import numpy as np
from footnav.pipeline.aiding import tof_measurement as tu
from footnav.pipeline.aiding.tof_types import (
    CODE_NAMES,
    DISABLED,
    FLOOR_PENDING,
    INVALID_STATUS,
    STATUS_NAMES,
    UNKNOWN_SENSOR,
    RangeBatch,
    TofConfig,
    TofCounts,
)
from footnav.pipeline.navigation.eskf import N_STATE, clone_height
from numpy.typing import NDArray

F64 = NDArray[np.float64]

SWING_MIN_M = 0.02
"""In swing, the floor under the IMU is looked up along the way from the last stance once the IMU
has moved this far from it (before, the nearest hit's)."""

EDGE_MAX_M = 0.15
"""A step edge crossed in a swing is remembered when the hits on either side of it are at most this
far apart along the way, m."""

EDGE_MARGIN_M = 0.01
"""Each remembered edge bracket is widened by this on both sides before use (the horizontal position
drifts between two passes over the same edge), m."""

EDGE_MEMORY = 2000
"""Edges remembered (the most recent)."""

LEVEL_STATES = 16
"""Floor levels kept as states of the filter (the most recently used; module docstring). An older
level leaves the state (marginalised: its row and column are dropped) and keeps its last value."""


class TofAiding:
    """The floor reference, the gate and the update of ToF readings for one foot (module docstring)."""

    def __init__(self, config: TofConfig) -> None:
        if len(config.lever_b_m) != len(config.dir_b):
            raise ValueError(f"{len(config.lever_b_m)} lever arms but {len(config.dir_b)} directions")
        self.config = config
        self._lever = np.asarray(config.lever_b_m, dtype=np.float64)
        dirs = np.asarray(config.dir_b, dtype=np.float64)
        self._dir = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
        self._par = tu.TofParams(
            float(config.sigma_range_m),
            float(config.sigma_floor_m),
            float(config.gate_chi2),
            float(config.step_m),
            float(config.below_m),
        )
        self._work = np.zeros((2, 15))
        self._res = np.zeros(tu.N_RES)
        self.counts = TofCounts()
        self.levels_z_m: list[float] = [0.0]
        """Height of each known level, m, as the filter had it at the last reading (:meth:`sync`)."""
        self._level_state: list[int] = [-1]
        """Per level, its error-state index in the filter (−1: not a state; the start floor, z = 0 by
        definition of the frame, never is)."""
        self._level_used: list[float] = [0.0]
        self._ref = 0
        """Index of the reference level (``floor_z_m`` is its height)."""
        self.floor_z_m = 0.0
        self._in_stance = False
        self._stance_obs: list[float] = []
        self._decided = False
        self._stance_t0 = -math.inf
        self._swing_origin: tuple[float, float] | None = None
        self._swing_hits: list[tuple[float, float, float, float]] = []
        self._edges: deque[tuple[float, float, float, float, float, float, float]] = deque(maxlen=EDGE_MEMORY)
        self._edges_arr = np.empty((0, 7))
        self._past_edge = np.zeros(self.n_sensors, dtype=bool)
        self._hits: deque[tuple[float, float, float, float]] = deque(maxlen=config.hit_memory)
        self._pending: list[RangeBatch] = []
        self.active = False
        """True once any reading arrived (the navigator then splits its batches and tracks the floor)."""
        self.last_hit: tuple[float, float, float, float] | None = None
        """The floor hit (x, y, surface height, on a known level) of the last reading applied, or None."""

    @property
    def n_sensors(self) -> int:
        return int(self._lever.shape[0])

    # --- queue ------------------------------------------------------------------------------------

    def add(self, readings: RangeBatch) -> None:
        """Queue readings (any order within the batch; applied in time order)."""
        if len(readings):
            self.active = True
            order = np.argsort(readings.t_s, kind="stable")
            self._pending.append(readings.select(order))

    def take_due(self, t_end_s: float) -> RangeBatch:
        """The queued readings with ``t_s <= t_end_s``, in time order (removed from the queue)."""
        if not self._pending:
            return RangeBatch(np.empty(0), np.empty(0, np.int64), np.empty(0), np.empty(0, np.uint8))
        allr = RangeBatch.concat(self._pending) if len(self._pending) > 1 else self._pending[0]
        order = np.argsort(allr.t_s, kind="stable")
        allr = allr.select(order)
        k = int(np.searchsorted(allr.t_s, t_end_s, side="right"))
        rest = allr.select(slice(k, None))
        self._pending = [rest] if len(rest) else []
        return allr.select(slice(0, k))

    def drop_before(self, t_s: float) -> int:
        """Forget queued readings older than ``t_s`` (before alignment); returns how many."""
        due = self.take_due(math.nextafter(t_s, -math.inf))
        self.counts.add("before_alignment", len(due))
        return len(due)

    # --- one reading ---------------------------------------------------------------------------------

    def reserve(self, x: F64, P: F64) -> tuple[F64, F64]:
        """The state ``x`` (16 + m,) and covariance ``P`` (15 + m, 15 + m) with room for one more floor
        level as a state (module docstring): grown by one (the new state unused, zero) when all m are
        taken and m < :data:`LEVEL_STATES`, else unchanged (also with ``use`` off: no level states)."""
        m = P.shape[0] - N_STATE
        if not self.config.use or m >= LEVEL_STATES or m > sum(i >= 0 for i in self._level_state):
            return x, P
        x_grown, P_grown = np.zeros(x.shape[0] + 1), np.zeros((P.shape[0] + 1, P.shape[1] + 1))
        x_grown[:-1] = x
        P_grown[:-1, :-1] = P
        self._work = np.zeros((2, P_grown.shape[0]))
        return x_grown, P_grown

    def sync(self, x: F64) -> None:
        """Read the heights of the levels that are states from ``x`` (the filter corrects them)."""
        for k, i in enumerate(self._level_state):
            if i >= 0:
                self.levels_z_m[k] = float(x[i + 1])
        self.floor_z_m = self.levels_z_m[self._ref]

    def _nearest_level(self, z_m: float) -> int | None:
        """Index of the known level nearest ``z_m`` if within ``snap_m``, else None."""
        k = min(range(len(self.levels_z_m)), key=lambda i: abs(self.levels_z_m[i] - z_m))
        return k if abs(self.levels_z_m[k] - z_m) <= self.config.snap_m else None

    def _level_height(self, z_m: float) -> float | None:
        k = self._nearest_level(z_m)
        return None if k is None else self.levels_z_m[k]

    def apply(
        self, x: F64, P: F64, t_s: float, sensor: int, range_m: float, status: int, stance: bool
    ) -> tuple[int, float, float]:
        """Handle one reading at the current filter time ``t_s``; returns (code, measured height,
        innovation). The levels' heights must be read from ``x`` since the filter last ran
        (:meth:`sync`, as the navigator does before each reading); an update here reads them again
        itself."""
        cfg = self.config
        self.last_hit = None
        if not stance and self._in_stance:
            self._swing_origin = (float(x[0]), float(x[1]))
        if stance and not self._in_stance:
            self._learn_edges(float(x[0]), float(x[1]))
            self._swing_hits = []
            self._past_edge[:] = False
            self._stance_obs = []
            self._decided = False
            self._stance_t0 = t_s
        self._in_stance = stance
        if status != 0:
            self.counts.add(STATUS_NAMES.get(int(status), f"status_{int(status)}"))
            return INVALID_STATUS, math.nan, math.nan
        if not 0 <= sensor < self.n_sensors:
            self.counts.add(CODE_NAMES[UNKNOWN_SENSOR])
            return UNKNOWN_SENSOR, math.nan, math.nan
        res = self._res
        deciding = stance and not self._decided
        past_edge = not stance and bool(self._past_edge[sensor])
        apply = cfg.use and not deciding and not past_edge and (stance or cfg.update_in_swing)
        state = self._level_state[self._ref]
        tu.tof_update(
            x,
            P,
            self._lever[sensor],
            self._dir[sensor],
            range_m,
            self.floor_z_m,
            state,
            self._par,
            apply,
            self._work,
            res,
        )
        if apply and int(res[tu.RES_CODE]) == tu.USED:
            self.sync(x)
        code = int(res[tu.RES_CODE])
        height = float(res[tu.RES_H]) if code != tu.NOT_FINITE else math.nan
        innovation = float(res[tu.RES_Y]) if code != tu.NOT_FINITE else math.nan
        if code == tu.NOT_FINITE:
            self.counts.add(CODE_NAMES[code])
            return code, height, innovation
        floor_obs = float(res[tu.RES_FLOOR_Z])
        if code == tu.STEP_EDGE and not stance:
            self._past_edge[sensor] = True
        elif past_edge and code != tu.BELOW_FLOOR:
            code = tu.STEP_EDGE
        if deciding and t_s - self._stance_t0 < cfg.decide_after_s:
            code = FLOOR_PENDING
        elif deciding and code != tu.BELOW_FLOOR:
            self._stance_obs.append(floor_obs)
            if len(self._stance_obs) >= cfg.decide_readings:
                self._decide(float(np.median(self._stance_obs)), x, P)
            code = FLOOR_PENDING
        elif code == tu.USED and not apply:
            code = DISABLED
        # the floor map for the clearance: surfaces seen (snapped to known levels)
        if code in (tu.USED, tu.STEP_EDGE, FLOOR_PENDING, DISABLED):
            level = self._level_height(floor_obs)
            hit_x, hit_y = float(res[tu.RES_HIT_X]), float(res[tu.RES_HIT_Y])
            self.last_hit = (hit_x, hit_y, floor_obs if level is None else level, float(level is not None))
            self._hits.append(self.last_hit)
            if not stance:
                self._swing_hits.append(self._hits[-1])
        self.counts.add(CODE_NAMES[code])
        return code, height, innovation

    def _decide(self, z_obs_m: float, x: F64, P: F64) -> None:
        """Set the stance floor from the median floor observation ``z_obs_m`` of the stance: the
        reference level, a known level, or a new one (module docstring)."""
        self._decided = True
        if abs(z_obs_m - self.floor_z_m) <= self.config.same_floor_m:
            self._level_used[self._ref] = self._stance_t0
            return
        level = self._nearest_level(z_obs_m)
        if level is None:
            level = self._new_level(x, P)
        self._ref = level
        self._level_used[level] = self._stance_t0
        self.floor_z_m = self.levels_z_m[level]

    def _new_level(self, x: F64, P: F64) -> int:
        """A new level where the state puts the IMU now, with the error of the state's height: a clone
        of δp_z into a level state (module docstring); returns its index. Without level states
        (``use`` off) only its height is kept."""
        self.counts.add("new_floor_levels")
        self.levels_z_m.append(float(x[2]))
        self._level_used.append(self._stance_t0)
        self._level_state.append(-1)
        if P.shape[0] > N_STATE:
            i = self._free_level_state(P)
            self._level_state[-1] = i
            clone_height(x, P, i, self.config.new_level_sigma_m**2)
        return len(self.levels_z_m) - 1

    def _free_level_state(self, P: F64) -> int:
        """An error-state index for a new level: an unused one, else the one of the level used longest
        ago (that level leaves the state and keeps its height)."""
        taken = {i for i in self._level_state if i >= 0}
        for i in range(N_STATE, P.shape[0]):
            if i not in taken:
                return i
        oldest = min(
            (k for k, i in enumerate(self._level_state) if i >= 0 and k != len(self._level_state) - 1),
            key=lambda k: self._level_used[k],
        )
        i = self._level_state[oldest]
        self._level_state[oldest] = -1
        self.counts.add("levels_left_state")
        return i

    def floor_under(self, pos_n_m: F64, stance: NDArray[np.bool_] | None = None) -> tuple[F64, F64]:
        """The floor under IMU positions (n, 3) (module docstring): the tread under each (n,) and the
        floor height to measure the clearance from (n,), the same except between the hits on both
        sides of a step edge, where it is interpolated. The stance's floor for the samples flagged
        ``stance`` (n,) once that floor is decided, else from the recent hits."""
        floor, expected = self._floor_from_hits(pos_n_m)
        if stance is not None and self._in_stance and self._decided:
            floor[stance] = self.floor_z_m
            expected[stance] = self.floor_z_m
        return floor, expected

    def _floor_from_hits(self, pos_n_m: F64) -> tuple[F64, F64]:
        if not self._hits:
            return np.full(pos_n_m.shape[0], self.floor_z_m), np.full(pos_n_m.shape[0], self.floor_z_m)
        return floor_from_hits(
            pos_n_m,
            np.asarray(self._hits),
            self.config.snap_m,
            self.floor_z_m,
            None if self._in_stance else self._swing_origin,
            self._narrow if self._edges_arr.shape[0] else None,
        )

    def _learn_edges(self, end_x: float, end_y: float) -> None:
        """Step edges crossed in the swing that just ended: between consecutive surfaces along the way."""
        if self._swing_origin is None or len(self._swing_hits) < 4:
            return
        ox, oy = self._swing_origin
        length = math.hypot(end_x - ox, end_y - oy)
        if length < 0.1:
            return
        ux, uy = (end_x - ox) / length, (end_y - oy) / length
        hits = np.asarray(self._swing_hits)
        s_hit = (hits[:, 0] - ox) * ux + (hits[:, 1] - oy) * uy
        z = hits[:, 2]
        order = np.argsort(z)
        snap = self.config.snap_m
        groups: list[NDArray[np.int64]] = []
        start = 0
        for k in range(1, order.size + 1):
            if k == order.size or z[order[k]] - z[order[k - 1]] > snap:
                if k - start >= 2:
                    groups.append(order[start:k])
                start = k
        surf = sorted(((float(np.median(s_hit[g])), float(np.mean(z[g])), g) for g in groups), key=lambda v: v[0])
        for (_, z1, g1), (_, z2, g2) in itertools.pairwise(surf):
            if abs(z2 - z1) <= snap:
                continue
            lo, hi = float(np.max(s_hit[g1])), float(np.min(s_hit[g2]))
            a, b = min(lo, hi), max(lo, hi)
            if b - a > EDGE_MAX_M:
                continue
            mid = 0.5 * (a + b)
            self._edges.append((ox + mid * ux, oy + mid * uy, ux, uy, 0.5 * (b - a), z1, z2))
        self._edges_arr = np.asarray(self._edges, dtype=np.float64).reshape(-1, 7)

    def _narrow(
        self, lo: float, hi: float, ox: float, oy: float, ux: float, uy: float, zb: float, za: float
    ) -> tuple[float, float]:
        """The bracket [lo, hi] of an edge between floors zb and za, along (ux, uy) from (ox, oy),
        intersected with the brackets of the same edge learned in earlier swings."""
        e = self._edges_arr
        snap = self.config.snap_m
        parallel = np.abs(e[:, 2] * ux + e[:, 3] * uy) > 0.9
        same = ((np.abs(e[:, 5] - zb) <= snap) & (np.abs(e[:, 6] - za) <= snap)) | (
            (np.abs(e[:, 5] - za) <= snap) & (np.abs(e[:, 6] - zb) <= snap)
        )
        s_e = (e[:, 0] - ox) * ux + (e[:, 1] - oy) * uy
        hw = e[:, 4] + EDGE_MARGIN_M
        for k in np.flatnonzero(parallel & same):
            a, b = max(lo, s_e[k] - hw[k]), min(hi, s_e[k] + hw[k])
            if a < b:
                lo, hi = a, b
        return lo, hi


Narrow = Callable[[float, float, float, float, float, float, float, float], tuple[float, float]]
"""(lo, hi, ox, oy, ux, uy, zb, za) -> the bracket [lo, hi] of an edge between floors zb and za along
(ux, uy) from (ox, oy), narrowed (``TofAiding._narrow``)."""


def floor_from_hits(
    pos_n_m: F64,
    hits: F64,
    snap_m: float,
    default_z_m: float,
    swing_origin: tuple[float, float] | None = None,
    narrow: Narrow | None = None,
    min_support: int = 2,
) -> tuple[F64, F64]:
    """The floor under IMU positions from floor hit points (module docstring, "Clearance").

    Parameters
    ----------
    pos_n_m : ndarray, shape (n, 3)
        IMU positions, m.
    hits : ndarray, shape (k, 4)
        Hit points: x, y, surface height (a known level, or where the ray hit), 1.0 when the height
        is a known level, else 0.0.
    snap_m : float
        Hits within this height of each other are on the same surface.
    default_z_m : float
        The floor when no hit has ``min_support`` hits at its height.
    swing_origin : tuple of float, optional
        Where the swing began (x, y); None in stance (the nearest hit's floor then).
    narrow : Narrow, optional
        Narrows a step edge's bracket with edges learned before, or None.
    min_support : int
        A hit counts when this many hits (itself included) lie within ``snap_m`` of its height.

    Returns
    -------
    tread : ndarray, shape (n,)
        The tread under each position.
    floor : ndarray, shape (n,)
        The floor height to measure the clearance from (interpolated between the hits on both sides
        of a step edge).
    """
    n = pos_n_m.shape[0]
    dz = np.abs(hits[:, None, 2] - hits[None, :, 2]) <= snap_m
    confirmed = dz.sum(axis=1) >= min_support  # others agree (a single reflection is not a floor)
    if not confirmed.any():
        return np.full(n, default_z_m), np.full(n, default_z_m)
    hits = hits.copy()
    free = hits[:, 3] == 0  # a surface at no known level (a tread seen in swing): its hits' mean
    if free.any():
        agree = dz & free[None, :]
        hits[free, 2] = ((agree * hits[None, :, 2]).sum(axis=1) / np.maximum(agree.sum(axis=1), 1))[free]
    hits = hits[confirmed]
    z = hits[:, 2]
    if z.max() == z.min():  # one floor around (most of the time): nothing to look up
        return np.full(n, z[0]), np.full(n, z[0])
    d2 = (pos_n_m[:, None, 0] - hits[None, :, 0]) ** 2 + (pos_n_m[:, None, 1] - hits[None, :, 1]) ** 2
    nearest = np.asarray(z[np.argmin(d2, axis=1)], dtype=np.float64)
    if swing_origin is None:
        return nearest, nearest.copy()
    # in swing: along the way from the last stance, between the nearest hits behind and ahead
    ox, oy = swing_origin
    dx, dy = pos_n_m[:, 0] - ox, pos_n_m[:, 1] - oy
    s_imu = np.hypot(dx, dy)
    moved = s_imu > SWING_MIN_M
    inv = np.where(moved, 1.0 / np.maximum(s_imu, 1e-9), 0.0)
    s_hit = (hits[None, :, 0] - ox) * (dx * inv)[:, None] + (hits[None, :, 1] - oy) * (dy * inv)[:, None]
    ds = s_hit - s_imu[:, None]
    behind = np.where(ds <= 0.0, -ds, np.inf)
    ahead = np.where(ds > 0.0, ds, np.inf)
    ib, ia = np.argmin(behind, axis=1), np.argmin(ahead, axis=1)
    rows = np.arange(n)
    db, da = behind[rows, ib], ahead[rows, ia]
    between = moved & np.isfinite(db) & np.isfinite(da)
    w = np.where(between, db / np.maximum(db + da, 1e-9), 0.0)
    zb, za = z[ib], z[ia]
    if narrow is not None:
        for i in np.flatnonzero(between & (np.abs(za - zb) > snap_m)):
            lo, hi = narrow(s_imu[i] - db[i], s_imu[i] + da[i], ox, oy, dx[i] * inv[i], dy[i] * inv[i], zb[i], za[i])
            w[i] = min(max((s_imu[i] - lo) / max(hi - lo, 1e-9), 0.0), 1.0)
    return np.where(between, np.where(w < 0.5, zb, za), nearest), np.where(between, zb + w * (za - zb), nearest)
