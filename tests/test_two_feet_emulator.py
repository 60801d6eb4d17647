"""The emulated walker's two feet: they alternate (each swings past the other while it stands, their
still phases never overlap on the level), stay within a step of each other, walk either side of the
line (the outer foot's way round a turn is longer) and vary on their own; one-foot walks are
unchanged by it."""

from __future__ import annotations

import numpy as np
import pytest
from footnav.device.emulator.motion.gait import FOOT_SIDE_M, simulate_walk, two_feet_walks


def _separation_m(path: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    left, right = two_feet_walks(path, 60.0, seed=1)
    lp = left.pos_n_m + np.array([0.0, FOOT_SIDE_M, 0.0])  # each track starts at its own origin, side by side
    rp = right.pos_n_m - np.array([0.0, FOOT_SIDE_M, 0.0])
    walking = (left.t_s > 4.5) & (left.t_s < 50.0)
    return np.linalg.norm((lp - rp)[:, :2], axis=1), (left.stance & right.stance)[walking], left.stance[walking]


@pytest.mark.parametrize("path", ["rectangle", "figure8", "line"])
def test_two_feet_alternate_within_a_step_of_each_other(path: str) -> None:
    distance_m, both_still, left_still = _separation_m(path)
    assert 0.6 < distance_m.max() < 0.8  # a step (half a 1.47 m stride) plus the step width; not a stride
    assert both_still.sum() < 0.5 * left_still.sum()


def test_the_feet_walk_either_side_of_the_line_and_vary_on_their_own() -> None:
    # the rectangle turns left: the right foot (0.1 m right of the line) is the outer one
    on_line = simulate_walk("rectangle", 60.0, seed=2, lateral_m=0.0).distance_m
    outer = simulate_walk("rectangle", 60.0, seed=2, lateral_m=-FOOT_SIDE_M).distance_m
    inner = simulate_walk("rectangle", 60.0, seed=2, lateral_m=FOOT_SIDE_M).distance_m
    np.testing.assert_allclose([outer - on_line, on_line - inner], 0.88, atol=0.05)  # ≈ 0.1 m × the turns
    left, right = two_feet_walks("rectangle", 30.0, seed=1)
    swing_starts = [np.flatnonzero(np.diff(f.stance.astype(int)) == -1)[:6] / 1000.0 for f in (left, right)]
    assert not np.allclose(np.diff(swing_starts[0]), np.diff(swing_starts[1]))  # each its own strides
    assert swing_starts[1][0] < swing_starts[0][0]  # the right foot leads, with a half stride


def test_one_foot_walks_do_not_move() -> None:
    a = simulate_walk("figure8", 20.0, seed=3)
    b = simulate_walk("figure8", 20.0, seed=3, lateral_m=-FOOT_SIDE_M, half_stride_ahead=False)
    np.testing.assert_array_equal(a.pos_n_m, b.pos_n_m)
