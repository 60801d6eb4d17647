"""Clipped gyroscope samples: found, reconstructed and marked (``footnav.pipeline.navigation.saturation``)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from footnav.device.files.recordings import load_recording
from footnav.pipeline.navigation.saturation import (
    CLIPPED_RATE_SIGMA_SHARE,
    clipped_rate_variance,
    reconstruct_saturated_rates,
)


def _swing_rates(rate_hz: float = 200.0) -> tuple[np.ndarray, np.ndarray]:
    """Pitch-rate pulses of a foot: one a second, 12 rad/s peak, smooth (a raised cosine)."""
    t = np.arange(0.0, 5.0, 1.0 / rate_hz)
    phase = np.mod(t, 1.0)
    pulse = np.where(phase < 0.3, 0.5 * (1.0 - np.cos(2.0 * math.pi * phase / 0.3)), 0.0)
    gyr = np.zeros((t.size, 3))
    gyr[:, 1] = -12.0 * pulse
    gyr[:, 0] = 1.0 * np.sin(2.0 * math.pi * 0.7 * t)
    return t, gyr


def test_clipped_pulses_are_found_and_get_most_of_their_lost_rotation_back() -> None:
    t, true = _swing_rates()
    clipped = true.copy()
    clipped[:, 1] = np.maximum(clipped[:, 1], -9.0)  # a sensor range of 9 rad/s (516 °/s)
    dt = t[1] - t[0]
    lost = float(np.sum(clipped[:, 1] - true[:, 1]) * dt)  # rad of pitch the clipping loses
    sat = reconstruct_saturated_rates(t, clipped)
    left = float(np.sum(sat.gyr_b_radps[:, 1] - true[:, 1]) * dt)
    assert sat.reconstructed > 0
    assert abs(left) < 0.2 * abs(lost)
    # exactly the samples at the limit (within 5 % of it) are marked, on that axis only
    np.testing.assert_array_equal(sat.clipped_b[:, 1], clipped[:, 1] <= -0.95 * 9.0)
    assert not sat.clipped_b[:, [0, 2]].any()
    assert np.array_equal(clipped[:, 1], np.maximum(true[:, 1], -9.0))  # the input is not modified


def test_rates_that_never_clip_are_left_alone() -> None:
    t, true = _swing_rates()
    # one peak higher than the others: the axis's extreme is a single smooth peak, many swings below
    true[:, 1] *= 1.0 + 0.1 * (t < 1.0)
    sat = reconstruct_saturated_rates(t, true)
    assert not sat.clipped_b.any() and sat.reconstructed == 0
    np.testing.assert_array_equal(sat.gyr_b_radps, true)


def test_an_axis_far_below_the_largest_rate_is_not_taken_as_clipped() -> None:
    """A plateau of a slow axis is a pose held, not a range: ranges limit every axis alike."""
    t, gyr = _swing_rates()
    gyr[:, 2] = np.clip(3.0 * np.sin(2.0 * math.pi * 0.5 * t), -2.0, 2.0)  # flat tops at 2 rad/s
    sat = reconstruct_saturated_rates(t, gyr)
    assert not sat.clipped_b[:, 2].any()


def test_non_finite_samples_and_flat_axes_are_left_alone() -> None:
    t, gyr = _swing_rates()
    gyr[:, 1] = np.maximum(gyr[:, 1], -9.0)
    gyr[100, 1] = math.nan
    gyr[:, 2] = 0.0
    sat = reconstruct_saturated_rates(t, gyr)
    assert math.isnan(sat.gyr_b_radps[100, 1]) and not sat.clipped_b[100].any()
    assert np.all(sat.gyr_b_radps[:, 2] == 0.0)
    empty = reconstruct_saturated_rates(np.empty(0), np.empty((0, 3)))
    assert empty.gyr_b_radps.shape == (0, 3) and empty.reconstructed == 0


def test_clipped_rate_variance_is_a_share_of_the_rate_on_clipped_samples_only() -> None:
    gyr = np.array([[1.0, -10.0, 2.0], [np.nan, 10.0, 0.0], [1.0, 1.0, 1.0]])
    clipped = np.array([[False, True, False], [True, True, False], [False, False, False]])
    var = clipped_rate_variance(gyr, clipped)
    expected = np.array([[0.0, 100.0, 0.0], [0.0, 100.0, 0.0], [0.0, 0.0, 0.0]]) * CLIPPED_RATE_SIGMA_SHARE**2
    np.testing.assert_allclose(var, expected, rtol=1e-15, atol=0.0)


@pytest.mark.parametrize(
    ("relpath", "axes"),
    [
        ("pyshoe-vicon/2017-11-27-11-18-11.mat", {1, 2}),  # running: pitch and yaw axes
        ("pyshoe-vicon/2017-11-22-11-49-29.mat", {1}),  # walking: the pitch axis
        ("pyshoe-vicon/2018-02-09-11-29-43.mat", set()),  # slow: never clips
        ("openshoe/data_inert.txt", set()),
    ],
)
def test_clipped_axes_of_real_recordings(shared_data: Path, relpath: str, axes: set[int]) -> None:
    """The PyShoe unit clips at 520-540 °/s on its calibrated outputs; the others never clip."""
    rec = load_recording(shared_data / relpath)
    sat = reconstruct_saturated_rates(rec.t_s, rec.gyr_b_radps)
    assert set(np.flatnonzero(sat.clipped_b.any(axis=0)).tolist()) == axes
    if axes:
        assert np.all(np.abs(rec.gyr_b_radps[sat.clipped_b]) > math.radians(490.0))
