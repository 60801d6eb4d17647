"""Per-stride clearance (footnav.pipeline.gait.clearance) on the emulator's true clearance, batched any way."""

from __future__ import annotations

import numpy as np
from footnav.device.emulator.motion.gait import CLEARANCE_PEAK_M, simulate_walk
from footnav.pipeline.gait.clearance import StrideClearanceTracker


def test_stride_clearance_from_truth_in_any_batching() -> None:
    walk = simulate_walk("line", 20.0, seed=3)
    clearance = walk.pos_n_m[:, 2] - walk.floor_z_m
    whole = StrideClearanceTracker().update(walk.t_s, clearance, walk.stance)
    assert whole is not None
    assert len(whole) == walk.n_strides
    assert np.all(np.abs(whole.max_m - CLEARANCE_PEAK_M) <= 0.0151)  # 0.12 m ± 0.015 per stride
    assert np.all((whole.min_m > 0.0) & (whole.min_m < whole.max_m))
    tracker = StrideClearanceTracker()
    parts_all = [
        tracker.update(walk.t_s[a : a + 137], clearance[a : a + 137], walk.stance[a : a + 137])
        for a in range(0, len(walk), 137)
    ]
    parts = [p for p in parts_all if p is not None]
    np.testing.assert_array_equal(np.concatenate([p.max_m for p in parts]), whole.max_m)
    np.testing.assert_array_equal(np.concatenate([p.min_m for p in parts]), whole.min_m)
    np.testing.assert_array_equal(np.concatenate([p.t_s for p in parts]), whole.t_s)
