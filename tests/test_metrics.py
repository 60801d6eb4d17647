"""Trajectory metrics on constructed tracks with known answers."""

from __future__ import annotations

import math

import numpy as np
import pytest
from footnav.pipeline.metrics import armse_2d_pyshoe, ate, loop_closure_error, path_length_m


def _square(n: int = 400) -> np.ndarray:
    s = np.linspace(0, 4, n)
    x = np.clip(s, 0, 1) - np.clip(s - 2, 0, 1)
    y = np.clip(s - 1, 0, 1) - np.clip(s - 3, 0, 1)
    return np.column_stack([x, y, 0.1 * np.sin(s)])


def _rot(yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def test_rotated_copy_scores_zero() -> None:
    gt = _square()
    est = gt @ _rot(0.7).T
    assert armse_2d_pyshoe(est, gt) == pytest.approx(0.0, abs=1e-12)
    res = ate(est + np.array([3.0, -2.0, 0.5]), gt)
    assert res.rmse_3d_m == pytest.approx(0.0, abs=1e-12) and not res.mirrored


def test_mirror_is_detected_and_reported() -> None:
    gt = _square()
    est = gt * np.array([1.0, -1.0, 1.0])
    res = ate(est, gt, mirror_test=True)
    assert res.mirrored and res.rmse_3d_m < 1e-12
    assert ate(est, gt, mirror_test=False).rmse_2d_m > 0.3


def test_armse_is_horizontal_distance_over_root_two() -> None:
    gt = _square()
    est = gt.copy()
    est[-100:, 0] += 0.2  # only the far end is off, so the 0.8 m heading alignment stays exact
    per_sample = np.zeros(len(gt))
    per_sample[-100:] = 0.2 / math.sqrt(2)
    assert armse_2d_pyshoe(est, gt) == pytest.approx(per_sample.mean(), rel=1e-9)


def test_loop_closure_and_length() -> None:
    track = _square()
    assert loop_closure_error(track)[1] < 1e-12
    flat = np.column_stack([track[:, :2], np.zeros(len(track))])
    assert path_length_m(flat) == pytest.approx(4.0, rel=5e-3)  # samples cut the corners slightly
