"""Per-stride clearance (footnav.pipeline.gait.clearance) on the emulator's true clearance, batched any way."""

from __future__ import annotations

import numpy as np
import pytest
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


@pytest.mark.parametrize("seed", range(4))
def test_many_swings_at_once_equal_one_swing_at_a_time(seed: int) -> None:
    """A batch of many strides (finished all at once) against the same samples in batches of 7 (one swing at a
    time): runs of 1-60 samples at 100 Hz (swings shorter and longer than ``MIN_SWING_S``), times repeated now and
    then, and a second pass with a NaN (the per-swing path for the whole batch)."""
    rng = np.random.default_rng(seed)
    lengths = rng.integers(1, 60, 400)
    stance = np.repeat(np.arange(lengths.size) % 2 == 0, lengths)
    t_s = np.cumsum(rng.choice([0.0, 0.01], stance.size, p=[0.05, 0.95]))
    clearance = rng.uniform(0.0, 0.2, stance.size)
    for c in (clearance, np.where(np.arange(stance.size) == 2000, np.nan, clearance)):
        whole = StrideClearanceTracker().update(t_s, c, stance)
        tracker = StrideClearanceTracker()
        parts = [
            p
            for a in range(0, stance.size, 7)
            if (p := tracker.update(t_s[a : a + 7], c[a : a + 7], stance[a : a + 7]))
        ]
        assert whole is not None and len(whole) > 50
        for field in ("t_s", "min_m", "max_m"):
            np.testing.assert_array_equal(np.concatenate([getattr(p, field) for p in parts]), getattr(whole, field))
