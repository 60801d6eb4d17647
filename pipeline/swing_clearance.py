"""Foot clearance from each swing's floor hits, past and future: for replay and evaluation, not live.

Live, the floor under the IMU in a swing is looked up among the hits seen so far
(:mod:`pipeline.tof_aiding`, "Clearance"): at a step edge it is known only to lie between the last hit
behind the IMU and the first one ahead, and ahead there is only the toe sensor's, one reading every
30 ms per sensor, 9-12 cm apart at swing speed. The mid-foot and heel sensors cross the same edge
just after the IMU does, so once the swing is over every sensor's hits on both sides of the edge are
known, and the closest pair straddling the IMU brackets the edge far more tightly. Here each swing's
floor is looked up (:func:`pipeline.tof_aiding.floor_from_hits`, the same lookup as live) among all
the hits of readings from ``margin_s`` before the swing to ``margin_s`` after it, along the way from
where the swing began; stance samples keep the live value (the stance's decided floor).

With a whole swing's hits, a spurious surface (reflections, valid status but 5-50 cm too long) is
more likely to find another hit that agrees with it than among the live lookup's last 12, so a hit
counts here only with :data:`MIN_SUPPORT` hits at its height: with 10 % reflections spread over 45
cm, a swing's window holds about 9 of them, about 1.6 within ±4 cm of any height, and 5 or more
others with about 2 % odds, while a tread the IMU passes over gets tens of hits.

Measured on the emulated stairs (``footnav experiment tof``, seeds 1-8): clearance RMS 1.03-1.38 cm
live, 0.86-0.95 cm from the whole swing. With 20 % time-outs and 10 % reflections (the bad-input
test's sensors, walks 1-5): 3.05-4.80 cm live; from the whole swing 4.80-5.89 cm counting a hit with
one other agreeing, 2.24-3.72 cm with :data:`MIN_SUPPORT` (clean walks unchanged up to 10, worse from
14). Looked up among the hits within ±30 ms of each sample instead of the swing's: 1.14-1.59 cm,
±100 ms 0.93 cm (seed 1); narrowing the brackets with the edges learned on other passes, as live,
made it worse (1.01 cm at ±100 ms, seed 1), so it is not done.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from pipeline.tof_aiding import RangeOutputs, floor_from_hits

F64 = NDArray[np.float64]

MARGIN_S = 0.25
"""Hits of readings this long before a swing's first and after its last sample count for it, s."""

MIN_SUPPORT = 6
"""Hits (itself included) within ``snap_m`` of a hit's height for it to count (module docstring)."""


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
    """Clearance of every sample, in swing from the whole swing's hits (module docstring).

    Args:
        t_s: (n,) sample times, s.
        pos_n_m: (n, 3) IMU positions.
        stance: (n,) the zero-velocity detector's flags.
        clearance_m: (n,) the live clearance (kept in stance, and in a swing without hits).
        ranges: the readings of the same stretch (``NavBatch.ranges``), with their hit points.
        snap_m: hits within this height of each other are on the same surface
            (``TofConfig.snap_m``).
        margin_s: see :data:`MARGIN_S`.
        min_support: see :data:`MIN_SUPPORT`.

    Returns:
        (n,) clearance, m.
    """
    out = np.array(clearance_m, dtype=np.float64, copy=True)
    has_hit = np.isfinite(ranges.hit_point_n_m[:, 0])
    hit_t = ranges.t_s[has_hit]
    hits = np.column_stack([ranges.hit_point_n_m[has_hit], ranges.hit_on_level[has_hit].astype(np.float64)])
    flags = np.asarray(stance, dtype=np.int8)
    lifts = np.flatnonzero(np.diff(flags) == -1) + 1  # first swing sample
    lands = np.flatnonzero(np.diff(flags) == 1) + 1  # first stance sample after a swing
    for first in lifts:
        after = lands[lands > first]
        stop = int(after[0]) if after.size else len(t_s)
        window = (hit_t >= t_s[first] - margin_s) & (hit_t <= t_s[stop - 1] + margin_s)
        if not window.any():
            continue
        floor_live = float(pos_n_m[first - 1, 2] - clearance_m[first - 1])
        origin = (float(pos_n_m[first - 1, 0]), float(pos_n_m[first - 1, 1]))
        _, floor = floor_from_hits(
            pos_n_m[first:stop], hits[window], snap_m, floor_live, origin, min_support=min_support
        )
        out[first:stop] = pos_n_m[first:stop, 2] - floor
    return out
