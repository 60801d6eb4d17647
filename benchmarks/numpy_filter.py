"""The navigation filter of ``footnav.pipeline.navigation.eskf`` written plainly: one Python iteration per sample, numpy
(15, 15) matrices, ``F P Fᵀ + Q`` with full matrices, Joseph-form updates with ``np.linalg``.

Two uses: the baseline the compiled filter's speed is quoted against (``python -m benchmarks``), and
an independent reference for its results (``tests/test_filter_reference.py``). It follows the model,
the parameters and the bad-input rules of ``footnav.pipeline.navigation.eskf.run_filter`` exactly, but none of its
shortcuts (block-sparse propagation, rank-3 updates, one-triangle symmetry), so agreement checks them.

References: Solà, "Quaternion kinematics for the error-state Kalman filter" (arXiv:1711.02508, 2017),
sections 5-7; the model equations are in the ``footnav.pipeline.navigation.eskf`` module docstring.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from footnav.pipeline.navigation import eskf
from numpy.typing import NDArray

F64 = NDArray[np.float64]

_P = slice(0, 3)
_POS_YAW = [0, 1, 2, 8]  # x, y, z and the heading error
_V = slice(3, 6)
_TH = slice(6, 9)
_BA = slice(9, 12)
_BG = slice(12, 15)
_I3 = np.eye(3)
_I15 = np.eye(15)


@dataclass(frozen=True, slots=True)
class FilterRun:
    """Outputs of one run, shaped like ``footnav.pipeline.navigation.eskf.run_filter``'s.

    Attributes
    ----------
    pos_n_m, vel_n_mps
        (n, 3).
    quat_nb_wxyz
        (n, 4).
    pos_cov_n_m2
        (n, 4, 4) of (x, y, z, ψ).
    counters
        (eskf.N_CNT,) the same counts as ``run_filter`` (see ``eskf.CNT_*``).
    filter_state
        (eskf.N_FILTER_STATE,) the same carried state (see ``eskf.STATE_*``).
    x, P
        the final nominal state (16,) and error covariance (15, 15).
    """

    pos_n_m: F64
    vel_n_mps: F64
    quat_nb_wxyz: F64
    pos_cov_n_m2: F64
    counters: NDArray[np.int64]
    filter_state: NDArray[np.int64]
    x: F64
    P: F64


def skew(v: F64) -> F64:
    """[v]×, the (3, 3) cross-product matrix of v (3,)."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def quat_mul(p: F64, q: F64) -> F64:
    """Hamilton product p ⊗ q of scalar-first quaternions: [p]_L q (Solà eqs. 12, 18)."""
    left = np.array(
        [
            [p[0], -p[1], -p[2], -p[3]],
            [p[1], p[0], -p[3], p[2]],
            [p[2], p[3], p[0], -p[1]],
            [p[3], -p[2], p[1], p[0]],
        ]
    )
    return left @ q


def quat_exp(rv: F64) -> F64:
    """Quaternion of the rotation vector rv (3,) rad (Solà eq. 101)."""
    angle = float(np.linalg.norm(rv))
    if angle < 1e-9:
        return np.concatenate([[1.0 - angle * angle / 8.0], 0.5 * rv])
    return np.concatenate([[math.cos(0.5 * angle)], math.sin(0.5 * angle) / angle * rv])


def quat_to_mat(q: F64) -> F64:
    """Rotation matrix (3, 3) of a unit quaternion: R = (w² − vᵀv) I + 2 v vᵀ + 2 w [v]× (Solà eq. 115)."""
    w, v = q[0], q[1:]
    return (w * w - v @ v) * _I3 + 2.0 * np.outer(v, v) + 2.0 * w * skew(v)


def _update(x: F64, P: F64, H: F64, y: F64, R: F64) -> tuple[F64, F64]:
    """Kalman update in Joseph form, injection and reset; returns the new (x, P)."""
    S = H @ P @ H.T + R
    K = np.linalg.solve(S, H @ P).T  # P Hᵀ S⁻¹ (S and P symmetric)
    I_KH = _I15 - K @ H
    P = I_KH @ P @ I_KH.T + K @ R @ K.T
    dx = K @ y
    x = x.copy()
    x[0:6] += dx[0:6]
    x[10:16] += dx[9:15]
    q = quat_mul(quat_exp(dx[_TH]), x[6:10])
    x[6:10] = q / np.linalg.norm(q)
    G = _I15.copy()
    G[_TH, _TH] += skew(0.5 * dx[_TH])
    P = G @ P @ G.T
    return x, 0.5 * (P + P.T)


def _zaru(
    x: F64,
    P: F64,
    gyr_b_radps: F64,
    par: eskf.FilterParams,
    H_bg: F64,
    R_zaru: F64,
    counters: NDArray[np.int64],
    state: NDArray[np.int64],
) -> tuple[F64, F64]:
    """The χ²-gated zero-angular-rate update; a standing foot's turn about the vertical added to its
    noise after the first stance (``footnav.pipeline.navigation.eskf``)."""
    y = gyr_b_radps - x[13:16]
    S = H_bg @ P @ H_bg.T + par.zaru_gate_sig**2 * _I3  # the gate's noise (footnav.pipeline.navigation.eskf)
    if float(y @ np.linalg.solve(S, y)) < par.zaru_gate:
        counters[eskf.CNT_ZARU] += 1
        if state[eskf.STATE_STARTED] and state[eskf.STATE_STANCE_RUN] > par.standing_after:
            up_b = quat_to_mat(x[6:10])[2]
            R_zaru = R_zaru + par.standing_turn**2 * np.outer(up_b, up_b)
        return _update(x, P, H_bg, y, R_zaru)
    counters[eskf.CNT_ZARU_REJECTED] += 1
    return x, P


def run_filter_numpy(
    x: F64,
    P: F64,
    acc_b_mps2: F64,
    gyr_b_radps: F64,
    dt_s: F64,
    stance: NDArray[np.bool_],
    zupt_ratio: F64,
    par: eskf.FilterParams,
    gyr_clip_var_b: F64 | None = None,
) -> FilterRun:
    """Run the filter sample by sample; arguments as ``footnav.pipeline.navigation.eskf.run_filter`` (not modified),
    ``gyr_clip_var_b`` (n, 3) or None for none."""
    n = acc_b_mps2.shape[0]
    x, P = x.astype(np.float64).copy(), P.astype(np.float64).copy()
    g = par.g
    g_n = np.array([0.0, 0.0, g])
    counters = np.zeros(eskf.N_CNT, dtype=np.int64)
    state = eskf.new_filter_state()
    H_v = _I15[_V]
    H_bg = _I15[_BG]
    R_zaru = par.zaru**2 * _I3
    pos, vel = np.empty((n, 3)), np.empty((n, 3))
    quat, pos_cov = np.empty((n, 4)), np.empty((n, 4, 4))
    for k in range(n):
        dt = float(dt_s[k])
        bad = not (np.isfinite(acc_b_mps2[k]).all() and np.isfinite(gyr_b_radps[k]).all())
        counters[eskf.CNT_BAD_SAMPLE] += bad
        if not (dt > 0.0 and math.isfinite(dt)):
            counters[eskf.CNT_BAD_DT] += 1
        else:
            counters[eskf.CNT_GAP] += dt >= par.dt_max
            R = quat_to_mat(x[6:10])
            f2 = w2 = 0.0
            if bad:  # hold the nominal motion, let the uncertainty grow
                f_n = g_n.copy()
            else:
                omega = gyr_b_radps[k] - x[13:16]
                f_b = acc_b_mps2[k] - x[10:13]
                f2, w2 = float(f_b @ f_b), float(omega @ omega)
                q = quat_mul(x[6:10], quat_exp(omega * dt))
                x[6:10] = q / np.linalg.norm(q)
                R_new = quat_to_mat(x[6:10])
                f_n = 0.5 * (R + R_new) @ f_b
                R = R_new
            a = f_n - g_n
            x[0:3] += x[3:6] * dt + 0.5 * a * dt * dt
            x[3:6] += a * dt
            F = _I15.copy()
            F[_P, _V] = dt * _I3
            F[_V, _TH] = -dt * skew(f_n)
            F[_V, _BA] = -dt * R
            F[_TH, _BG] = -dt * R
            q_block = [
                0.0,
                (par.sig_acc**2 + par.acc_scale**2 * f2) * dt * dt,
                (par.sig_gyr**2 + par.gyr_scale**2 * w2) * dt * dt,
                par.ba_rw**2 * dt,
                par.bg_rw**2 * dt,
            ]
            Q = np.diag(np.repeat(q_block, 3))
            if gyr_clip_var_b is not None and not bad:  # rate noise along the clipped body axes
                Q[_TH, _TH] += R @ np.diag(gyr_clip_var_b[k]) @ R.T * dt * dt
            P = F @ P @ F.T + Q
            P = 0.5 * (P + P.T)
        state[eskf.STATE_LAST_REJECTED] = 0
        if stance[k]:
            state[eskf.STATE_STANCE_RUN] += 1
        else:
            state[eskf.STATE_STARTED] |= state[eskf.STATE_STANCE_RUN] > 0
            state[eskf.STATE_STANCE_RUN] = 0
        if stance[k] and not bad:
            omega = gyr_b_radps[k] - x[13:16]
            r_zupt = par.zupt**2 + par.roll_lever**2 * float(omega @ omega)
            # vertical: + σ_T² T/γ, T/γ clamped to [0, 1] (NaN: 1)
            rho = float(np.clip(np.nan_to_num(zupt_ratio[k], nan=1.0), 0.0, 1.0))
            r_v = r_zupt + par.zupt_vert_stat**2 * rho
            R_v = np.diag([r_zupt, r_zupt, r_v])
            unsure = not (zupt_ratio[k] <= par.zupt_gate_ratio)
            v = x[3:6]
            if unsure and float(v @ np.linalg.solve(H_v @ P @ H_v.T + R_v, v)) > par.zupt_gate:
                counters[eskf.CNT_ZUPT_REJECTED] += 1  # the foot is moving: no update at this sample
                state[eskf.STATE_LAST_REJECTED] = 1
            else:
                x, P = _update(x, P, H_v, -x[3:6], R_v)
                counters[eskf.CNT_UPDATES] += 1
                x, P = _zaru(x, P, gyr_b_radps[k], par, H_bg, R_zaru, counters, state)
        pos[k], vel[k], quat[k] = x[0:3], x[3:6], x[6:10]
        pos_cov[k] = P[np.ix_(_POS_YAW, _POS_YAW)]
    return FilterRun(pos, vel, quat, pos_cov, counters, state, x, P)
