"""Reconstruction of saturated gyroscope stretches (``pipeline.saturation``)."""

from __future__ import annotations

import math

import numpy as np

from pipeline.saturation import reconstruct_saturated_rates


def _swing_rates(rate_hz: float = 200.0) -> tuple[np.ndarray, np.ndarray]:
    """Pitch-rate pulses of a foot: one a second, 12 rad/s peak, smooth (a raised cosine)."""
    t = np.arange(0.0, 5.0, 1.0 / rate_hz)
    phase = np.mod(t, 1.0)
    pulse = np.where(phase < 0.3, 0.5 * (1.0 - np.cos(2.0 * math.pi * phase / 0.3)), 0.0)
    gyr = np.zeros((t.size, 3))
    gyr[:, 1] = -12.0 * pulse
    gyr[:, 0] = 1.0 * np.sin(2.0 * math.pi * 0.7 * t)
    return t, gyr


def test_clipped_pulses_get_most_of_their_lost_rotation_back() -> None:
    t, true = _swing_rates()
    clipped = true.copy()
    clipped[:, 1] = np.maximum(clipped[:, 1], -9.0)  # a sensor range of 9 rad/s (516 °/s)
    dt = t[1] - t[0]
    lost = float(np.sum(clipped[:, 1] - true[:, 1]) * dt)  # rad of pitch the clipping loses
    fixed, changed = reconstruct_saturated_rates(t, clipped)
    left = float(np.sum(fixed[:, 1] - true[:, 1]) * dt)
    assert changed > 0
    assert abs(left) < 0.2 * abs(lost)
    assert np.array_equal(clipped[:, 1], np.maximum(true[:, 1], -9.0))  # the input is not modified


def test_unsaturated_rates_barely_change() -> None:
    t, true = _swing_rates()
    fixed, _ = reconstruct_saturated_rates(t, true)
    # magnitudes only grow, and at a smooth unsaturated peak by little
    assert np.all(np.abs(fixed) >= np.abs(true))
    assert np.max(np.abs(fixed - true)) < 0.01 * np.max(np.abs(true))


def test_non_finite_samples_and_flat_axes_are_left_alone() -> None:
    t, gyr = _swing_rates()
    gyr[100, 1] = math.nan
    gyr[:, 2] = 0.0
    fixed, _ = reconstruct_saturated_rates(t, gyr)
    assert math.isnan(fixed[100, 1])
    assert np.all(fixed[:, 2] == 0.0)
    empty, changed = reconstruct_saturated_rates(np.empty(0), np.empty((0, 3)))
    assert empty.shape == (0, 3) and changed == 0
