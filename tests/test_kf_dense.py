"""The dense Kalman steps of the dual-IMU filters against the textbook formulas."""

from __future__ import annotations

import numpy as np
from footnav.pipeline.dual_imu import dense_kf as kf_dense


def _spd(n: int, rng: np.random.Generator) -> np.ndarray:
    a = rng.standard_normal((n, n))
    return a @ a.T + n * np.eye(n)


def test_propagate_over_the_pattern_equals_f_p_ft_plus_q() -> None:
    rng = np.random.default_rng(1)
    n = 21
    F = np.eye(n)
    F[0:3, 3:6] = 0.001
    F[3:6, 6:9] = rng.standard_normal((3, 3))
    F[6:9, 12:15] = rng.standard_normal((3, 3))
    ptr, idx = kf_dense.pattern(F)
    assert ptr[-1] == np.count_nonzero(F)
    P, q = _spd(n, rng), rng.uniform(0, 1, n)
    expected = F @ P @ F.T + np.diag(q)
    kf_dense.propagate(P, F, ptr, idx, q, np.empty((n, n)))
    np.testing.assert_allclose(P, expected, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(P, P.T)


def test_update3_is_the_joseph_form_and_returns_the_nis() -> None:
    rng = np.random.default_rng(2)
    n = 12
    P = _spd(n, rng)
    H = np.zeros((3, n))
    H[:, 0:3], H[:, 3:6] = -np.eye(3), np.eye(3)
    y, r = rng.standard_normal(3), rng.uniform(0.1, 1.0, 3)
    R = np.diag(r)
    S = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(S)
    IKH = np.eye(n) - K @ H
    expected_P = IKH @ P @ IKH.T + K @ R @ K.T
    dx = np.zeros(n)
    nis = kf_dense.update3(dx, P, H, y, r, np.empty((9, n)), np.inf)
    np.testing.assert_allclose(dx, K @ y, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(P, expected_P, rtol=1e-10, atol=1e-10)
    assert np.isclose(nis, y @ np.linalg.solve(S, y))


def test_update3_gate_leaves_state_and_covariance_alone() -> None:
    rng = np.random.default_rng(3)
    n = 6
    P = _spd(n, rng)
    P0 = P.copy()
    H = np.zeros((3, n))
    H[:, :3] = np.eye(3)
    dx = np.zeros(n)
    nis = kf_dense.update3(dx, P, H, np.full(3, 100.0), np.full(3, 0.01), np.empty((9, n)), 11.345)
    assert nis > 11.345 and not dx.any()
    np.testing.assert_array_equal(P, P0)


def test_update3_gate_can_use_its_own_noise() -> None:
    """The zero-angular-rate gate tests against the sensor noise and weighs with a larger one."""
    rng = np.random.default_rng(4)
    n = 6
    P = 1e-3 * _spd(n, rng)
    H = np.zeros((3, n))
    H[:, :3] = np.eye(3)
    y = np.array([0.3, -0.2, 0.1])
    r, r_gate = np.full(3, 0.5), np.full(3, 1e-3)
    S_gate = H @ P @ H.T + np.diag(r_gate)
    nis_gate = float(y @ np.linalg.solve(S_gate, y))
    # a gate the update's noise would pass but the sensor's noise does not: nothing changes
    assert float(y @ np.linalg.solve(H @ P @ H.T + np.diag(r), y)) < nis_gate * 0.9
    P_before, dx = P.copy(), np.zeros(n)
    nis = kf_dense.update3(dx, P, H, y, r, np.empty((9, n)), nis_gate * 0.9, r_gate)
    assert np.isclose(nis, nis_gate) and not dx.any()
    np.testing.assert_array_equal(P, P_before)
    # when it passes, the update is the one with r
    dx_ref, P_ref = np.zeros(n), P.copy()
    kf_dense.update3(dx_ref, P_ref, H, y, r, np.empty((9, n)), np.inf)
    nis = kf_dense.update3(dx, P, H, y, r, np.empty((9, n)), nis_gate * 1.1, r_gate)
    assert np.isclose(nis, nis_gate)
    np.testing.assert_allclose(dx, dx_ref, rtol=1e-12)
    np.testing.assert_allclose(P, P_ref, rtol=1e-12)
