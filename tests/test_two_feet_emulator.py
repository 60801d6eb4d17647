"""The emulated walker's two feet: they alternate (stances overlap less than half the time), walk on
either side of the line (the outer foot's way round a turn is longer), and vary on their own; the
one-foot walks are unchanged by it."""

from __future__ import annotations

import numpy as np
from footnav.device.emulator.motion.gait import FOOT_SIDE_M, simulate_walk, two_feet_walks


def test_two_feet_alternate_on_either_side_of_the_line() -> None:
    left, right = two_feet_walks("rectangle", 60.0, seed=1)
    walking = (left.t_s > 4.0) & (left.t_s < 50.0)
    both = (left.stance & right.stance)[walking].sum()
    assert both < 0.5 * min(left.stance[walking].sum(), right.stance[walking].sum())
    # the rectangle turns left: the right foot is the outer one, the left the inner one
    on_line = simulate_walk("rectangle", 60.0, seed=2).distance_m
    outer = simulate_walk("rectangle", 60.0, seed=2, side_m=-FOOT_SIDE_M).distance_m
    inner = simulate_walk("rectangle", 60.0, seed=2, side_m=FOOT_SIDE_M).distance_m
    np.testing.assert_allclose([outer - on_line, on_line - inner], 0.88, atol=0.05)  # ≈ 0.2 m × the turns
    # in the start frame, mid first straight, the right foot stands 0.2 m to the right of the left one
    k = np.flatnonzero(left.stance & (left.pos_n_m[:, 0] > 5.0))[0]
    j = np.flatnonzero(right.stance & (right.t_s > left.t_s[k]))[0]
    lateral = (right.pos_n_m[j, 1] - FOOT_SIDE_M) - (left.pos_n_m[k, 1] + FOOT_SIDE_M)
    np.testing.assert_allclose(lateral, -2 * FOOT_SIDE_M, atol=0.02)
    swing_starts = [np.flatnonzero(np.diff(f.stance.astype(int)) == -1)[:5] / 1000.0 for f in (left, right)]
    assert not np.allclose(np.diff(swing_starts[0]), np.diff(swing_starts[1]))  # each its own strides


def test_one_foot_walks_do_not_move() -> None:
    a = simulate_walk("figure8", 20.0, seed=3)
    b = simulate_walk("figure8", 20.0, seed=3, side_m=0.0)
    np.testing.assert_array_equal(a.pos_n_m, b.pos_n_m)
