"""Per-stride foot clearance: the largest and the mid-swing smallest height of each swing.

A swing is a run of samples the zero-velocity detector did not flag as stance, between two stances.
For each swing that ends (at the next stance onset) this gives its largest clearance and its smallest
clearance over the middle half of the swing (25-75 % of its duration): the minimum foot clearance
(MFC) of gait studies is the local minimum between the toe-off and heel-strike peaks, in mid-swing
(Winter, *Biomechanics and Motor Control of Human Gait*, 1991; Begg et al., *Gait & Posture* 25,
2007), not the zero height at either end. The clearance is that of the IMU's reference point
(``NavBatch.clearance_m``). Streaming: batches may cut a swing anywhere; results do not depend on it.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]

MIN_SWING_S = 0.15
"""Shorter non-stance runs are detector flicker, not strides."""


@dataclass(frozen=True, slots=True)
class StrideClearance:
    """Clearance per completed swing: t_s (k,) swing end (stance onset), s; min_m (k,) mid-swing
    minimum; max_m (k,) maximum, m."""

    t_s: F64
    min_m: F64
    max_m: F64

    def __len__(self) -> int:
        return int(self.t_s.shape[0])


class StrideClearanceTracker:
    """Streaming per-stride clearance (module docstring)."""

    def __init__(self) -> None:
        self._in_swing = False
        self._seen_stance = False
        self._t: list[F64] = []
        self._c: list[F64] = []

    def update(self, t_s: F64, clearance_m: F64, stance: NDArray[np.bool_]) -> StrideClearance | None:
        """Strides completed within this batch (None: none)."""
        st = stance if stance.dtype == np.bool_ else np.asarray(stance, dtype=bool)
        if st.all():  # fast paths: the whole batch in one phase (most batches)
            if self._in_swing and self._t:
                return self._emit_single(float(t_s[0]))
            self._in_swing, self._seen_stance = False, True
            return None
        if self._seen_stance and not st.any():
            self._in_swing = True
            self._t.append(t_s)
            self._c.append(clearance_m)
            return None
        out_t: list[float] = []
        out_min: list[float] = []
        out_max: list[float] = []
        edges = np.flatnonzero(st[1:] != st[:-1]) + 1
        bounds = np.concatenate([[0], edges, [st.size]])
        # swings that begin after a stance of this batch and end before its last run: all at once when finite
        inner = _inner_swings(t_s, clearance_m, st, bounds) if bounds.size > 4 else None
        for r, (a, b) in enumerate(itertools.pairwise(bounds.tolist())):
            if st[a]:
                if self._in_swing and self._t:
                    self._finish(float(t_s[a]), out_t, out_min, out_max)
                self._in_swing = False
                self._seen_stance = True
                self._t, self._c = [], []
            else:
                self._in_swing = self._seen_stance
                if self._in_swing and (inner is None or r == 0 or b == st.size):
                    self._t.append(t_s[a:b])
                    self._c.append(clearance_m[a:b])
        if inner is not None:
            out_t += inner.t_s.tolist()
            out_min += inner.min_m.tolist()
            out_max += inner.max_m.tolist()
        if not out_t:
            return None
        return StrideClearance(np.asarray(out_t), np.asarray(out_min), np.asarray(out_max))

    def _emit_single(self, t_end: float) -> StrideClearance | None:
        out_t: list[float] = []
        out_min: list[float] = []
        out_max: list[float] = []
        self._finish(t_end, out_t, out_min, out_max)
        self._in_swing, self._seen_stance = False, True
        self._t, self._c = [], []
        if not out_t:
            return None
        return StrideClearance(np.asarray(out_t), np.asarray(out_min), np.asarray(out_max))

    def _finish(self, t_end: float, out_t: list[float], out_min: list[float], out_max: list[float]) -> None:
        t = self._t[0] if len(self._t) == 1 else np.concatenate(self._t)
        c = self._c[0] if len(self._c) == 1 else np.concatenate(self._c)
        if t.size and all(map(math.isfinite, (t[0], t[-1], c[0], c[-1]))) and not t[-1] - t[0] >= MIN_SWING_S:
            return  # too short, told by its first and last samples (kept by the filter below)
        finite = np.isfinite(t) & np.isfinite(c)  # bad samples (flagged upstream) say nothing here
        if not finite.all():
            t, c = t[finite], c[finite]
        if t.size == 0 or not t[-1] - t[0] >= MIN_SWING_S:
            return
        lo, hi = t[0] + 0.25 * (t[-1] - t[0]), t[0] + 0.75 * (t[-1] - t[0])
        mid = (t >= lo) & (t <= hi)
        c_mid = c[mid]
        if c_mid.size == 0:
            return
        out_t.append(t_end)
        out_min.append(float(np.min(c_mid)))
        out_max.append(float(np.max(c)))


def _inner_swings(
    t_s: F64, clearance_m: F64, stance: NDArray[np.bool_], bounds: NDArray[np.int64]
) -> StrideClearance | None:
    """What :meth:`StrideClearanceTracker._finish` gives, for every swing run of a batch between its first and its
    last run (each preceded and followed by a stance run of the batch), at once: ``bounds`` (k + 1,) the runs' first
    indices and the batch length. None when a time or clearance is not finite (the per-swing path handles those)."""
    if not (np.isfinite(t_s).all() and np.isfinite(clearance_m).all()):
        return None
    first, end = bounds[:-1], bounds[1:]
    t0, t1 = t_s[first], t_s[end - 1]
    lo, hi = t0 + 0.25 * (t1 - t0), t0 + 0.75 * (t1 - t0)
    length = end - first
    mid = (t_s >= np.repeat(lo, length)) & (t_s <= np.repeat(hi, length))
    min_mid = np.minimum.reduceat(np.where(mid, clearance_m, np.inf), first)
    has_mid = np.logical_or.reduceat(mid, first)
    max_all = np.maximum.reduceat(clearance_m, first)
    inner = np.zeros(first.size, dtype=np.bool_)
    inner[1:-1] = ~stance[first[1:-1]]
    keep = inner & (t1 - t0 >= MIN_SWING_S) & has_mid
    return StrideClearance(t_s[end[keep]], min_mid[keep], max_all[keep])
