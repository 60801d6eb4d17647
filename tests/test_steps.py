"""Host-side step segmentation: OpenShoe's per-step output from any navigation solution."""

from __future__ import annotations

import numpy as np
from footnav.device.emulator.motion.gait import simulate_walk
from footnav.pipeline.gait.steps import accumulate_steps, segment_steps


def _truth_cov(n: int) -> np.ndarray:
    """A covariance of (x, y, z, ψ) that grows linearly in time (a random walk)."""
    rates = np.array([1e-6, 2e-6, 0.5e-6, 1e-7])
    return np.arange(n)[:, None, None] * np.diag(rates)[None]


def test_steps_of_the_emulated_rectangle() -> None:
    truth = simulate_walk("rectangle", 60.0, rate_hz=200.0, seed=0)
    steps = segment_steps(truth.t_s, truth.pos_n_m, truth.quat_nb_wxyz, truth.stance, _truth_cov(truth.t_s.size))
    walking = steps.is_step
    assert abs(int(walking.sum()) - truth.n_strides) <= 1  # one step per stride of the instrumented foot
    lengths = np.linalg.norm(steps.dpos_step_m[walking], axis=1)
    assert 1.1 < np.median(lengths) < 1.7  # stride length at 1.4 m/s
    # straight strides point forward in the previous step's frame
    straight = walking & (np.abs(steps.dyaw_rad) < 1e-3)
    assert np.all(steps.dpos_step_m[straight, 0] > 1.0) and np.all(np.abs(steps.dpos_step_m[straight, 1]) < 0.05)
    # 60 s covers one lap of the rectangle and part of the next: at least one full turn
    assert steps.dyaw_rad.sum() > 2 * np.pi - 0.05
    # accumulating the increments the way OpenShoe's host apps do reproduces the positions
    track = accumulate_steps(steps)
    np.testing.assert_allclose(track[1:], steps.pos_n_m - truth.pos_n_m[0], atol=1e-9)
    # the 3 s of standing still at the start give no steps
    assert not steps.is_step[steps.t_s < 3.0].any()


def test_step_covariance_is_the_growth_rotated_into_the_step_frame() -> None:
    truth = simulate_walk("rectangle", 40.0, rate_hz=200.0, seed=0)
    cov = _truth_cov(truth.t_s.size)
    steps = segment_steps(truth.t_s, truth.pos_n_m, truth.quat_nb_wxyz, truth.stance, cov)
    assert np.all(np.linalg.eigvalsh(steps.cov) >= -1e-15)
    gaps = np.diff(np.concatenate([[0], steps.index]))
    np.testing.assert_allclose(steps.cov[:, 3, 3], gaps * 1e-7, rtol=1e-9)  # heading variance growth
    np.testing.assert_allclose(steps.cov[:, 2, 2], gaps * 0.5e-6, rtol=1e-9)
    trace_xy = steps.cov[:, 0, 0] + steps.cov[:, 1, 1]  # rotation keeps the horizontal trace
    np.testing.assert_allclose(trace_xy, gaps * 3e-6, rtol=1e-9)
