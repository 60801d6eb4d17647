"""Foot clearance from each swing's floor hits, past and future: a second, later estimate.

Live, the floor under the IMU in a swing is looked up among the hits seen so far
(:mod:`footnav.pipeline.aiding.tof`, "Clearance"): at a step edge it is known only to lie between the last hit
behind the IMU and the first one ahead, and ahead there is only the toe sensor's, one reading every
30 ms per sensor, 9-12 cm apart at swing speed. The mid-foot and heel sensors cross the same edge
just after the IMU does, so once the swing is over every sensor's hits on both sides of the edge are
known, and the closest pair straddling the IMU brackets the edge far more tightly. Here each swing's
floor is looked up (:func:`footnav.pipeline.aiding.tof.floor_from_hits`, the same lookup as live) among all
the hits of readings from ``margin_s`` before the swing to ``margin_s`` after it, along the way from
where the swing began; stance samples keep the live value (the stance's decided floor). Streaming
(:class:`SwingClearanceTracker`), each swing's values come once ``margin_s`` has passed after it,
about 0.7 s after the swing began at walking pace: the views show this series beside the live one,
and replay and evaluation take it whole (:func:`swing_clearance`).

With a whole swing's hits, a spurious surface (reflections, valid status but 5-50 cm too long) is
more likely to find another hit that agrees with it than among the live lookup's last 12, so a hit
counts here only with :data:`MIN_SUPPORT` hits at its height: with 10 % reflections spread over 45
cm, a swing's window holds about 9 of them, about 1.6 within ±4 cm of any height, and 5 or more
others with about 2 % odds, while a tread the IMU passes over gets tens of hits.

Why :data:`MIN_SUPPORT` and the whole swing: docs/design/tof-aiding.md.
"""

from __future__ import annotations

import numpy as np
from footnav.pipeline.aiding.tof import floor_from_hits
from footnav.pipeline.aiding.tof_types import RangeOutputs
from numpy.typing import NDArray

F64 = NDArray[np.float64]

MARGIN_S = 0.25
"""Hits of readings this long before a swing's first and after its last sample count for it, s."""

MIN_SUPPORT = 6
"""Hits (itself included) within ``snap_m`` of a hit's height for it to count (module docstring)."""

MAX_SWING_S = 2.0
"""A run without stance longer than this is not a stride's swing (a walking swing lasts about 0.4 s,
a slow one under 1 s): the foot is carried, or the detector misses stances. Its samples keep their
live clearance and are returned at once, so neither the wait nor the buffers grow with it."""


class SwingClearanceTracker:
    """Streaming swing-complete clearance (module docstring): feed the navigator's batches in order;
    each call returns the samples whose value is final, in order, each sample once."""

    def __init__(self, snap_m: float, margin_s: float = MARGIN_S, min_support: int = MIN_SUPPORT) -> None:
        self.snap_m = snap_m
        self.margin_s = margin_s
        self.min_support = min_support
        self._t = np.empty(0)
        self._pos = np.empty((0, 3))
        self._stance = np.empty(0, dtype=bool)
        self._clear = np.empty(0)
        self._hit_t = np.empty(0)
        self._hits = np.empty((0, 4))
        self._before: tuple[float, float, float] | None = None
        """x, y and floor height of the last sample returned (where a swing that starts next began)."""
        self._long_run = False
        """The buffer starts inside a run without stance longer than MAX_SWING_S (passed through)."""

    def update(
        self, t_s: F64, pos_n_m: F64, stance: NDArray[np.bool_], clearance_m: F64, ranges: RangeOutputs | None
    ) -> tuple[F64, F64]:
        """Add a batch ((n,) times, (n, 3) positions, (n,) stance flags, (n,) live clearance, and
        its readings or None); returns (times, clearance) of the samples now final."""
        self._t = np.concatenate([self._t, t_s])
        self._pos = np.concatenate([self._pos, pos_n_m])
        self._stance = np.concatenate([self._stance, np.asarray(stance, dtype=bool)])
        self._clear = np.concatenate([self._clear, clearance_m])
        if ranges is not None and len(ranges):
            has_hit = np.isfinite(ranges.hit_point_n_m[:, 0])
            hits = np.column_stack([ranges.hit_point_n_m[has_hit], ranges.hit_on_level[has_hit].astype(np.float64)])
            self._hit_t = np.concatenate([self._hit_t, ranges.t_s[has_hit]])
            self._hits = np.concatenate([self._hits, hits])
        return self._emit(final=False)

    def finish(self) -> tuple[F64, F64]:
        """The rest (a swing still open is looked up with the hits there are)."""
        return self._emit(final=True)

    def _emit(self, final: bool) -> tuple[F64, F64]:
        t, n = self._t, self._t.shape[0]
        out = self._clear.copy()
        swing = ~self._stance
        done, a = n, 0
        if self._long_run:  # the rest of a long run without stance goes through as it is
            stances = np.flatnonzero(self._stance)
            a = int(stances[0]) if stances.size else n
            self._long_run = a == n
        while a < n:
            starts = np.flatnonzero(swing[a:])
            if starts.size == 0:
                break  # the rest is stance: final as it is
            a += int(starts[0])
            ends = np.flatnonzero(~swing[a:])
            b = a + int(ends[0]) if ends.size else n
            if t[b - 1] - t[a] > MAX_SWING_S:  # not a stride's swing: live values, at once
                self._long_run = b == n
            elif not final and (b == n or t[-1] < t[b] + self.margin_s):
                done = a  # the swing's hits are not all in yet
                break
            else:
                self._look_up(out, a, b)
            a = b
        if done:
            self._before = (
                float(self._pos[done - 1, 0]),
                float(self._pos[done - 1, 1]),
                float(self._pos[done - 1, 2] - self._clear[done - 1]),
            )
        t_out, c_out = t[:done], out[:done]
        self._t, self._pos, self._stance, self._clear = (
            self._t[done:],
            self._pos[done:],
            self._stance[done:],
            self._clear[done:],
        )
        if self._t.size:
            keep = self._hit_t >= self._t[0] - self.margin_s
            self._hit_t, self._hits = self._hit_t[keep], self._hits[keep]
        return t_out, c_out

    def _look_up(self, out: F64, a: int, b: int) -> None:
        """Samples [a, b) of the buffer are one swing: their clearance from the swing's hits."""
        window = (self._hit_t >= self._t[a] - self.margin_s) & (self._hit_t <= self._t[b - 1] + self.margin_s)
        if not window.any():
            return
        if a > 0:
            x0, y0 = float(self._pos[a - 1, 0]), float(self._pos[a - 1, 1])
            floor0 = float(self._pos[a - 1, 2] - self._clear[a - 1])
        elif self._before is not None:
            x0, y0, floor0 = self._before
        else:
            x0, y0 = float(self._pos[0, 0]), float(self._pos[0, 1])
            floor0 = float(self._pos[0, 2] - self._clear[0])
        pos = self._pos[a:b]
        _, floor = floor_from_hits(pos, self._hits[window], self.snap_m, floor0, (x0, y0), min_support=self.min_support)
        out[a:b] = pos[:, 2] - floor


def swing_clearance(
    t_s: F64,
    pos_n_m: F64,
    stance: NDArray[np.bool_],
    clearance_m: F64,
    ranges: RangeOutputs,
    snap_m: float,
    margin_s: float = MARGIN_S,
    min_support: int = MIN_SUPPORT,
) -> F64:
    """Clearance of every sample of a whole recording, in swing from the whole swing's hits.

    Parameters
    ----------
    t_s
        (n,) sample times, s.
    pos_n_m
        (n, 3) IMU positions.
    stance
        (n,) the zero-velocity detector's flags.
    clearance_m
        (n,) the live clearance (kept in stance, and in a swing without hits).
    ranges
        the readings of the same stretch (``NavBatch.ranges``), with their hit points.
    snap_m
        hits within this height of each other are on the same surface (``TofConfig.snap_m``).
    margin_s
        see :data:`MARGIN_S`.
    min_support
        see :data:`MIN_SUPPORT`.

    Returns
    -------
    F64
        (n,) clearance, m.
    """
    tracker = SwingClearanceTracker(snap_m, margin_s, min_support)
    _, first = tracker.update(t_s, pos_n_m, stance, clearance_m, ranges)
    _, rest = tracker.finish()
    return np.concatenate([first, rest])
