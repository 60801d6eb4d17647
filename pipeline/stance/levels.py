"""Floor levels from the stances alone: a gated height constraint for the inertial-only filter.

A foot at rest stands on a floor, and floors are level: a stance on the floor of the last stance puts the IMU at
the height it had there, within the stance-to-stance scatter of its rest height. The height constraint of
Abdulrahim, Hide, Moore and Hill ("Using constraints for shoe mounted indoor pedestrian navigation", J. Navigation
65(1), 2012) applies this when the height changed less than a threshold since the last stance and not otherwise,
so a stair (one or two risers per stride, 10-40 cm) starts a new level and a level walk is held on its floor.
footnav keeps every level stood on and returns to one within ``snap_m`` (the way back down a flight ends on the
floor it started from).

The measurement, once per stance, ``update_after_s`` after it began (or at its end if it is shorter:
:func:`stance_update_points`), when the loading response is over and the foot is flat (0-10 % of the gait cycle,
about 0.1 s at a walk; Perry and Burnfield, "Gait Analysis: Normal and Pathological Function", 2nd ed., 2010,
ch. 2; the zero-velocity updates hold the position from then to the stance's end):

    0 = p_z − z_level + w,   w ~ N(0, σ²),  σ = ``sigma_m`` (the scatter of the IMU's rest height on one floor)

The start floor is where the IMU rests at alignment (z = 0 for the single-IMU filter) and is not a state. Every
other level is a state of the filter, a stochastic clone of δp_z when it is placed (Roumeliotis and Burdick,
"Stochastic cloning", ICRA 2002; as the ToF floor levels of :mod:`footnav.pipeline.aiding.tof`), so what the filter
learns later corrects the level too; the ``level_states`` levels stood on most recently are states, an older one
is marginalised and keeps its height. With ``level_states = 0`` every level is a constant (the smoother's forward
pass and the dual-IMU navigator, whose filters have a fixed state).

A stance within ``same_level_m`` of the last level (or ``snap_m`` of another) is on it, so a height change of less
than that per stride (a thick mat, a 5 cm step) is taken for drift and removed, and a ramp is pulled towards the
last level as far as the filter's own height uncertainty lets it; larger changes are kept, so stairs stay stairs.
``use = False`` turns it off (zero-velocity aiding alone). Units SI, heights in the navigation frame (z up). What
it costs on ramps, and the measurement behind ``sigma_m``: the documentation's design page "Estimator".
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from footnav.pipeline.jit import njit
from footnav.pipeline.navigation.eskf import N_STATE, P0, clone_height, update1
from footnav.pipeline.stance.detectors import carried_runs
from numpy.typing import NDArray

F64 = NDArray[np.float64]

LEVEL_STATES = 8
"""Floor levels kept as states of the filter by default (the most recently stood on)."""

MAX_LEVELS = 256
"""Floor levels remembered; past this the one stood on longest ago is forgotten (a walk whose height
drifts more than ``same_level_m`` per stride, as a fast run can, makes a level at every stance)."""


@njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"})
def height_update(x: F64, P: F64, level: int, z_level_m: float, r_m2: float, work: F64) -> None:
    """The stance height update 0 = p_z − z_level + w, var(w) = ``r_m2``, on ``x`` (n + 1,) and ``P``
    (n, n) in place: z_level is the error state ``level`` (nominal x[level + 1]) when ``level`` ≥ 0,
    else the constant ``z_level_m``. H has +1 at δp_z and −1 at the level's state; the update is
    :func:`footnav.pipeline.navigation.eskf.update1` (scalar Joseph form, injection, reset). ``work``: (2, n)."""
    # pragma: no cover
    n = P.shape[0]
    u = work[0]
    for i in range(n):
        u[i] = P[i, P0 + 2] - (P[i, level] if level >= 0 else 0.0)
    s = u[P0 + 2] - (u[level] if level >= 0 else 0.0) + r_m2
    z_level = x[level + 1] if level >= 0 else z_level_m
    update1(x, P, u, s, z_level - x[P0 + 2], work[1])


def stance_update_points(still: NDArray[np.bool_], carried: int, after: int) -> tuple[list[int], int]:
    """Where a navigator applies the height update of each stance: after the stance's ``after``-th
    sample, or after its last one if it is shorter.

    Parameters
    ----------
    still
        (n,) stance flags of the batch.
    carried
        samples of the stance in progress at the end of the previous batch (0: in swing).
    after
        samples of stance before the update (≥ 1).

    Returns
    -------
    points : list[int]
        The indices b of the batch's samples before which an update is due (the update follows sample b − 1, of the
        previous batch when b = 0), in order.
    carried : int
        The samples of the stance in progress at the end of this batch (0 when it ends in swing), to carry on.
    """
    n = still.shape[0]
    if n == 0:
        return [], carried
    starts, ends, before, last = carried_runs(still, carried)
    # the sample where a run reaches ``after`` samples; else its last one if it ends in the batch short of that
    reach = starts + (after - 1 - before)
    full = (reach >= starts) & (reach < ends)
    short = (ends < n) & (ends - starts + before < after)
    points = (np.where(full, reach, ends - 1)[full | short] + 1).tolist()
    if not still[0] and 0 < carried < after:
        points.insert(0, 0)
    return points, last


@dataclass(frozen=True, slots=True)
class StanceLevelParams:
    """Settings of the stance height constraint (module docstring), SI units.

    Attributes
    ----------
    use
        apply the constraint (False: the inertial-only filter without it).
    sigma_m
        1σ of the IMU's rest height about its floor level, stance to stance.
    same_level_m
        a stance within this of the last stance's level is on that level.
    snap_m
        else, a stance within this of another known level is back on that level.
    update_after_s
        the update is made this long after the stance began (or at its end if it is shorter): the foot is flat by then
        (module docstring).
    new_level_sigma_m
        1σ added to a new level's clone of the height error.
    level_states
        how many levels are states of the filter (0: each level is a constant, its height where it was first stood on;
        the smoother's forward pass, ``footnav.pipeline.smoothing.rts``).
    """

    use: bool = True
    sigma_m: float = 0.01
    same_level_m: float = 0.05
    snap_m: float = 0.05
    update_after_s: float = 0.1
    new_level_sigma_m: float = 0.001
    level_states: int = LEVEL_STATES


@dataclass
class LevelCounts:
    """What the stances did since the start."""

    updates: int = 0
    new_levels: int = 0
    returns: int = 0
    not_finite: int = 0


class StanceLevels:
    """The floor levels of one foot and their height update (module docstring), for a stream at
    ``rate_hz``."""

    def __init__(self, params: StanceLevelParams, rate_hz: float) -> None:
        self.params = params
        self._after = max(1, round(params.update_after_s * rate_hz))
        """Stance samples before the update."""
        self._stance_samples = 0
        """Samples of the stance in progress at the end of the last batch (0 in swing)."""
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

    def update_points(self, still: NDArray[np.bool_]) -> list[int]:
        """The indices of the batch's samples before which a stance update is due
        (:func:`stance_update_points`), for consecutive batches of stance flags ``still`` (n,)."""
        points, self._stance_samples = stance_update_points(still, self._stance_samples, self._after)
        return points

    def sync(self, x: F64) -> None:
        """Read the heights of the levels that are states from ``x``."""
        for k, i in enumerate(self._state):
            if i >= 0:
                self.levels_z_m[k] = float(x[i + 1])

    def stance_update(self, x: F64, P: F64) -> tuple[F64, F64, float]:
        """The height update of a stance (at the sample :func:`stance_update_points` gives); returns
        the state and covariance (grown by one when a new level became a state, else the same arrays,
        updated in place) and the height of the level it was updated against (NaN: no update)."""
        cfg = self.params
        if not cfg.use:
            return x, P, math.nan
        if not math.isfinite(float(x[P0 + 2])):
            self.counts.not_finite += 1
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
        self._state.append(-1)
        self._ref = len(self.levels_z_m) - 1
        if len(self.levels_z_m) > MAX_LEVELS:
            self._forget_oldest()
        if self.params.level_states == 0:
            return x, P
        i = self._free_state(P)
        if i >= P.shape[0]:
            x_grown, P_grown = np.zeros(x.shape[0] + 1), np.zeros((P.shape[0] + 1, P.shape[1] + 1))
            x_grown[:-1], P_grown[:-1, :-1] = x, P
            x, P = x_grown, P_grown
        self._state[self._ref] = i
        clone_height(x, P, i, self.params.new_level_sigma_m**2)
        return x, P

    def _forget_oldest(self) -> None:
        """Forget the level stood on longest ago that is not a state (nor the start floor or the
        reference)."""
        old = [k for k in range(1, len(self.levels_z_m)) if self._state[k] < 0 and k != self._ref]
        if not old:
            return
        k = min(old, key=lambda k: self._used[k])
        del self.levels_z_m[k], self._state[k], self._used[k]
        if self._ref > k:
            self._ref -= 1

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
