"""The ToF height measurement (footnav.pipeline.aiding.tof_measurement): its Jacobian against finite differences, the
scalar Joseph-form update against the textbook full-matrix one, and the gate's reasons."""

from __future__ import annotations

import numpy as np
import pytest
from footnav.pipeline.aiding import tof_measurement as tu
from footnav.pipeline.navigation.eskf import N_STATE
from footnav.pipeline.navigation.quaternion import quat_from_rotvec, quat_mul


def _state(rng: np.random.Generator) -> np.ndarray:
    x = np.zeros(16)
    x[:3] = rng.normal(0.0, 0.2, 3)
    x[3:6] = rng.normal(0.0, 0.5, 3)
    x[6:10] = quat_from_rotvec(rng.normal(0.0, 0.5, 3))
    x[10:] = rng.normal(0.0, 0.01, 6)
    return x


def _g(x: np.ndarray, lever: np.ndarray, direction: np.ndarray, rho: float) -> float:
    H = np.zeros(N_STATE)
    return float(tu.height_row(x, lever, direction, rho, H)[0])


def _inject(x: np.ndarray, dx: np.ndarray) -> np.ndarray:
    """Nominal state for the error δx: p + δp, ..., q = Exp(δθ) ⊗ q (global attitude error)."""
    out = x.copy()
    out[:6] += dx[:6]
    out[6:10] = quat_mul(quat_from_rotvec(dx[6:9]), x[6:10])
    out[10:] += dx[9:]
    return out


@pytest.mark.parametrize("seed", range(5))
def test_jacobian_matches_finite_differences(seed: int) -> None:
    rng = np.random.default_rng(seed)
    x = _state(rng)
    lever = rng.normal(0.0, 0.1, 3)
    direction = rng.normal(0.0, 1.0, 3)
    direction /= np.linalg.norm(direction)
    rho = float(rng.uniform(0.02, 1.5))
    H = np.zeros(N_STATE)
    tu.height_row(x, lever, direction, rho, H)
    eps = 1e-6
    numeric = np.empty(N_STATE)
    for i in range(N_STATE):
        dx = np.zeros(N_STATE)
        dx[i] = eps
        numeric[i] = (_g(_inject(x, dx), lever, direction, rho) - _g(_inject(x, -dx), lever, direction, rho)) / (
            2 * eps
        )
    np.testing.assert_allclose(H, numeric, atol=1e-8)
    assert np.any(np.abs(H[6:9]) > 1e-3)  # the attitude part is really exercised


def _par(gate: float = 1e9, step: float = 1e9, below: float = 1e9) -> tu.TofParams:
    return tu.TofParams(sigma_range=0.01, sigma_floor=0.003, gate=gate, step=step, below=below)


@pytest.mark.parametrize("levels", [0, 2])
def test_update_equals_the_full_matrix_joseph_form(levels: int) -> None:
    """With the floor a constant, and with it a state (the second of two floor-level states: H has
    −1 there and the update corrects the level too)."""
    rng = np.random.default_rng(7)
    n = N_STATE + levels
    x = np.concatenate([_state(rng), rng.normal(0.3, 0.1, levels)])
    A = rng.normal(0.0, 0.05, (n, n))
    P = A @ A.T + np.eye(n) * 1e-4
    lever, direction, rho = np.array([0.12, 0.0, 0.03]), np.array([0.1, 0.0, -1.0]), 0.2
    direction /= np.linalg.norm(direction)
    level = n - 1 if levels else -1
    floor = float(x[level + 1]) if levels else -0.05
    H = np.zeros(n)
    g, _, _, uz = tu.height_row(x, lever, direction, rho, H)
    if levels:
        H[level] = -1.0
    r = (0.01 * uz) ** 2 + 0.003**2
    S = H @ P @ H + r
    K = P @ H / S
    y = floor - g
    I_KH = np.eye(n) - np.outer(K, H)
    P_joseph = I_KH @ P @ I_KH.T + r * np.outer(K, K)
    dx = K * y
    x1, P1, res = x.copy(), P.copy(), np.zeros(tu.N_RES)
    tu.tof_update(x1, P1, lever, direction, rho, floor, level, _par(), True, np.zeros((2, n)), res)
    assert res[tu.RES_CODE] == tu.USED
    assert res[tu.RES_Y] == pytest.approx(y)
    np.testing.assert_allclose(x1, _inject(x, dx), atol=1e-12)
    # the reset G P Gᵀ changes P by O(δθ) in the attitude block only
    G = np.eye(n)
    h = 0.5 * dx[6:9]
    G[6:9, 6:9] += np.array([[0, -h[2], h[1]], [h[2], 0, -h[0]], [-h[1], h[0], 0]])
    np.testing.assert_allclose(P1, G @ P_joseph @ G.T, atol=1e-12)
    # and the measurement now agrees better with the floor (the corrected one when it is a state)
    floor1 = float(x1[level + 1]) if levels else floor
    assert abs(floor1 - _g(x1, lever, direction, rho)) < abs(y)
    if levels:
        assert x1[level + 1] != x[level + 1]  # the level observed is corrected


def test_gate_reasons() -> None:
    x = np.zeros(16)
    x[6] = 1.0
    P = np.eye(N_STATE) * 1e-6
    lever, down = np.array([0.0, 0.0, 0.03]), np.array([0.0, 0.0, -1.0])
    work, res = np.zeros((2, N_STATE)), np.zeros(tu.N_RES)
    par = _par(gate=10.83, step=0.06, below=0.03)

    def code(rho: float, floor: float = 0.0) -> int:
        x1, P1 = x.copy(), P.copy()
        tu.tof_update(x1, P1, lever, down, rho, floor, -1, par, True, work, res)
        if res[tu.RES_CODE] != tu.USED:  # rejected readings change nothing
            np.testing.assert_array_equal(x1, x)
            np.testing.assert_array_equal(P1, P)
        return int(res[tu.RES_CODE])

    assert code(0.031) == tu.USED
    assert code(float("nan")) == tu.NOT_FINITE
    assert code(0.10) == tu.STEP_EDGE  # 7 cm above the floor while the state says on it
    assert code(0.065) == tu.OUTLIER  # 3.5 cm: within the step gate, far outside χ²
    lever[2] = 0.05  # a sensor 5 cm above the IMU reading 0: the IMU would be 5 cm under the floor
    assert code(0.0) == tu.BELOW_FLOOR
