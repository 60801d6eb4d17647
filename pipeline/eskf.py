"""Error-state Kalman filter for a foot-mounted IMU (compiled core, no I/O).

Formulation: Solà, "Quaternion kinematics for the error-state Kalman filter" (arXiv:1711.02508,
2017), sections 5 and 7, with the attitude error in the navigation frame (global error, Solà §7.2.1:
``R_true = Exp(δθ) R̂``), which is the form of OpenShoe's 9-state filter (Nilsson, Skog, Händel,
Hari, "Foot-mounted INS for everybody", IPIN 2012, eqs. 1-3) extended with accelerometer and
gyroscope bias states:

    nominal x = [p_n (3), v_n (3), q_nb (4), b_a (3), b_g (3)]          (16,)
    error  δx = [δp (3), δv (3), δθ (3), δb_a (3), δb_g (3)]          (15,)

    δp' = δv
    δv' = −[R (a_m − b_a)]× δθ − R δb_a − R a_n
    δθ' = −R δb_g − R ω_n
    δb_a' = a_w,  δb_g' = ω_w

Updates while the foot is still: zero velocity (ZUPT, z = 0 − v), then zero angular rate (ZARU,
z = ω_m − b_g), each in Joseph form followed by injection and reset (Solà §7.3). A stance that
passes the zero-velocity detector may still rotate (heel and toe roll, running), which would drag
the gyro bias, so ZARU is applied only when its normalised innovation passes a χ² gate. For the same
reason the ZUPT noise admits the velocity of a foot rolling about a contact point at most r from
the IMU: σ_v² = σ_zupt² + (r |ω|)², since |v_imu| = |ω × r| ≤ r |ω| for a rigid foot.
The covariance propagation multiplies only the non-identity blocks of F (about 1.5k multiply-adds
per sample instead of 2 × 15³).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

from pipeline.quaternion import quat_from_rotvec, quat_mul, quat_to_mat

F64 = NDArray[np.float64]

N_STATE = 15
# indices into the error state
P0, V0, TH0, BA0, BG0 = 0, 3, 6, 9, 12

# layout of the parameter vector handed to the compiled loop
(
    PAR_SIG_ACC,
    PAR_SIG_GYR,
    PAR_BA_RW,
    PAR_BG_RW,
    PAR_ZUPT,
    PAR_ZARU,
    PAR_G,
    PAR_DT_MAX,
    PAR_ZARU_GATE,
    PAR_ROLL_LEVER,
) = range(10)
N_PAR = 10

# counters returned by run_filter
CNT_BAD_DT, CNT_GAP, CNT_BAD_SAMPLE, CNT_UPDATES, CNT_ZARU, CNT_ZARU_REJECTED = range(6)
N_CNT = 6


@njit(cache=True)
def _skew_times_block_rows(P: F64, dst: int, src: int, vec: F64, scale: float, out: F64) -> None:
    """out[dst:dst+3, :] += scale · [vec]× · P[src:src+3, :]."""  # pragma: no cover
    n = P.shape[1]
    for j in range(n):
        a0, a1, a2 = P[src, j], P[src + 1, j], P[src + 2, j]
        out[dst, j] += scale * (-vec[2] * a1 + vec[1] * a2)
        out[dst + 1, j] += scale * (vec[2] * a0 - vec[0] * a2)
        out[dst + 2, j] += scale * (-vec[1] * a0 + vec[0] * a1)


@njit(cache=True)
def _mat_times_block_rows(P: F64, dst: int, src: int, M: F64, scale: float, out: F64) -> None:
    """out[dst:dst+3, :] += scale · M · P[src:src+3, :] for a (3, 3) M."""  # pragma: no cover
    n = P.shape[1]
    for j in range(n):
        a0, a1, a2 = P[src, j], P[src + 1, j], P[src + 2, j]
        for r in range(3):
            out[dst + r, j] += scale * (M[r, 0] * a0 + M[r, 1] * a1 + M[r, 2] * a2)


@njit(cache=True)
def _propagate_cov(P: F64, R: F64, f_n: F64, dt: float, q_diag: F64) -> None:
    """P ← F P Fᵀ + Q in place, F = I + A dt with the blocks of the module docstring."""  # pragma: no cover
    # M = F P  (row operations)
    M = P.copy()
    for j in range(N_STATE):
        for r in range(3):
            M[P0 + r, j] += dt * P[V0 + r, j]
    _skew_times_block_rows(P, V0, TH0, f_n, -dt, M)
    _mat_times_block_rows(P, V0, BA0, R, -dt, M)
    _mat_times_block_rows(P, TH0, BG0, R, -dt, M)
    # P = M Fᵀ = (F Mᵀ)ᵀ: apply the same row operations to Mᵀ, then transpose back
    Mt = M.T.copy()
    out = Mt.copy()
    for j in range(N_STATE):
        for r in range(3):
            out[P0 + r, j] += dt * Mt[V0 + r, j]
    _skew_times_block_rows(Mt, V0, TH0, f_n, -dt, out)
    _mat_times_block_rows(Mt, V0, BA0, R, -dt, out)
    _mat_times_block_rows(Mt, TH0, BG0, R, -dt, out)
    for i in range(N_STATE):
        for j in range(N_STATE):
            P[i, j] = 0.5 * (out[i, j] + out[j, i])
        P[i, i] += q_diag[i]


@njit(cache=True)
def _spd_inverse(S: F64) -> F64:
    """Inverse of a small symmetric positive-definite matrix by Cholesky factorisation."""  # pragma: no cover
    m = S.shape[0]
    L = np.zeros((m, m))
    for i in range(m):
        for j in range(i + 1):
            acc = S[i, j]
            for k in range(j):
                acc -= L[i, k] * L[j, k]
            if i == j:
                L[i, i] = math.sqrt(max(acc, 1e-300))
            else:
                L[i, j] = acc / L[j, j]
    Linv = np.zeros((m, m))
    for i in range(m):
        Linv[i, i] = 1.0 / L[i, i]
        for j in range(i):
            acc = 0.0
            for k in range(j, i):
                acc -= L[i, k] * Linv[k, j]
            Linv[i, j] = acc / L[i, i]
    out = np.empty((m, m))
    for i in range(m):
        for j in range(m):
            acc = 0.0
            for k in range(max(i, j), m):
                acc += Linv[k, i] * Linv[k, j]
            out[i, j] = acc
    return out


@njit(cache=True)
def _nis_selected(P: F64, idx: NDArray[np.int64], y: F64, r_diag: F64) -> float:
    """Normalised innovation squared yᵀ S⁻¹ y of a measurement observing the states ``idx``."""  # pragma: no cover
    m = idx.shape[0]
    S = np.empty((m, m))
    for a in range(m):
        for b in range(m):
            S[a, b] = P[idx[a], idx[b]]
        S[a, a] += r_diag[a]
    S_inv = _spd_inverse(S)
    nis = 0.0
    for a in range(m):
        for b in range(m):
            nis += y[a] * S_inv[a, b] * y[b]
    return nis


@njit(cache=True)
def _update_selected(x: F64, P: F64, idx: NDArray[np.int64], y: F64, r_diag: F64) -> None:
    """Kalman update for a measurement that observes the error states ``idx`` directly.

    H = rows of the identity at ``idx``. Joseph form, expanded for this H:
    (I−KH) P (I−KH)ᵀ + K R Kᵀ = P − K P[idx,:] − P[:,idx] Kᵀ + K (P[idx,idx] + R) Kᵀ.
    The error is then injected into the nominal state ``x`` and the covariance reset (Solà §7.2-7.3).
    """  # pragma: no cover
    m = idx.shape[0]
    S = np.empty((m, m))
    for a in range(m):
        for b in range(m):
            S[a, b] = P[idx[a], idx[b]]
        S[a, a] += r_diag[a]
    S_inv = _spd_inverse(S)
    K = np.zeros((N_STATE, m))
    for i in range(N_STATE):
        for b in range(m):
            acc = 0.0
            for a in range(m):
                acc += P[i, idx[a]] * S_inv[a, b]
            K[i, b] = acc
    dx = np.zeros(N_STATE)
    for i in range(N_STATE):
        for a in range(m):
            dx[i] += K[i, a] * y[a]
    KS = np.zeros((N_STATE, m))
    for i in range(N_STATE):
        for b in range(m):
            acc = 0.0
            for a in range(m):
                acc += K[i, a] * S[a, b]
            KS[i, b] = acc
    Pn = np.empty((N_STATE, N_STATE))
    for i in range(N_STATE):
        for j in range(i, N_STATE):
            acc = P[i, j]
            for a in range(m):
                acc += -K[i, a] * P[idx[a], j] - P[i, idx[a]] * K[j, a] + KS[i, a] * K[j, a]
            Pn[i, j] = acc
            Pn[j, i] = acc
    # injection
    for r in range(3):
        x[r] += dx[P0 + r]
        x[3 + r] += dx[V0 + r]
        x[10 + r] += dx[BA0 + r]
        x[13 + r] += dx[BG0 + r]
    half = np.empty(3)
    for r in range(3):
        half[r] = 0.5 * dx[TH0 + r]
    q = quat_mul(quat_from_rotvec(dx[TH0 : TH0 + 3].copy()), x[6:10])
    q /= math.sqrt(q[0] ** 2 + q[1] ** 2 + q[2] ** 2 + q[3] ** 2)
    x[6:10] = q
    # reset: P ← G P Gᵀ with G = I except G[θ,θ] = I + [δθ/2]× for a global attitude error
    # (Solà §7.3.2; from Exp(δθ⁺) = Exp(δθ) Exp(−δθ̂) to first order)
    rows = Pn.copy()
    _skew_times_block_rows(Pn, TH0, TH0, half, 1.0, rows)
    cols = rows.T.copy()
    out = cols.copy()
    _skew_times_block_rows(cols, TH0, TH0, half, 1.0, out)
    for i in range(N_STATE):
        for j in range(N_STATE):
            P[i, j] = 0.5 * (out[i, j] + out[j, i])


@njit(cache=True)
def run_filter(
    x: F64,
    P: F64,
    acc_b_mps2: F64,
    gyr_b_radps: F64,
    dt_s: F64,
    stance: NDArray[np.bool_],
    par: F64,
    out_pos: F64,
    out_vel: F64,
    out_quat: F64,
    out_pos_cov: F64,
    counters: NDArray[np.int64],
) -> None:
    """Run the filter over a batch, updating ``x`` (16,) and ``P`` (15, 15) in place.

    Args:
        x, P: nominal state and error covariance, carried between batches.
        acc_b_mps2, gyr_b_radps: (n, 3) IMU samples; sample k covers the interval ending at it.
        dt_s: (n,) interval before each sample, s. Non-positive intervals skip the propagation
            (duplicated timestamps); intervals above ``par[PAR_DT_MAX]`` are counted as gaps.
        stance: (n,) apply ZUPT + ZARU after propagating sample k.
        par: (N_PAR,) parameters (see the PAR_* indices).
        out_pos, out_vel: (n, 3) outputs; out_quat (n, 4); out_pos_cov (n, 3, 3).
        counters: (N_CNT,) incremented in place (see the CNT_* indices).
    """  # pragma: no cover
    n = acc_b_mps2.shape[0]
    g = par[PAR_G]
    q_diag = np.zeros(N_STATE)
    idx_v = np.array([V0, V0 + 1, V0 + 2], dtype=np.int64)
    idx_bg = np.array([BG0, BG0 + 1, BG0 + 2], dtype=np.int64)
    r_zupt = np.full(3, par[PAR_ZUPT] ** 2)
    r_zaru = np.full(3, par[PAR_ZARU] ** 2)
    y = np.empty(3)
    omega = np.empty(3)
    f_b = np.empty(3)
    rv = np.empty(3)
    for k in range(n):
        dt = dt_s[k]
        bad = False
        for r in range(3):
            if not (math.isfinite(acc_b_mps2[k, r]) and math.isfinite(gyr_b_radps[k, r])):
                bad = True
        if bad:
            counters[CNT_BAD_SAMPLE] += 1
        if dt <= 0.0 or not math.isfinite(dt):
            counters[CNT_BAD_DT] += 1
        else:
            if dt > par[PAR_DT_MAX]:
                counters[CNT_GAP] += 1
            R0 = quat_to_mat(x[6:10])
            if bad:
                # no usable sample: hold the nominal motion, let the uncertainty grow
                for r in range(3):
                    omega[r] = 0.0
                    f_b[r] = 0.0
                f_n = np.zeros(3)
                f_n[2] = g
            else:
                for r in range(3):
                    omega[r] = gyr_b_radps[k, r] - x[13 + r]
                    f_b[r] = acc_b_mps2[k, r] - x[10 + r]
                    rv[r] = omega[r] * dt
                q = quat_mul(x[6:10], quat_from_rotvec(rv))
                q /= math.sqrt(q[0] ** 2 + q[1] ** 2 + q[2] ** 2 + q[3] ** 2)
                x[6:10] = q
                R1 = quat_to_mat(q)
                f_n = np.zeros(3)
                for r in range(3):
                    for c in range(3):
                        f_n[r] += 0.5 * (R0[r, c] + R1[r, c]) * f_b[c]
                R0 = R1
            for r in range(3):
                a = f_n[r] - (g if r == 2 else 0.0)
                x[r] += x[3 + r] * dt + 0.5 * a * dt * dt
                x[3 + r] += a * dt
            for r in range(3):
                q_diag[V0 + r] = (par[PAR_SIG_ACC] * dt) ** 2
                q_diag[TH0 + r] = (par[PAR_SIG_GYR] * dt) ** 2
                q_diag[BA0 + r] = par[PAR_BA_RW] ** 2 * dt
                q_diag[BG0 + r] = par[PAR_BG_RW] ** 2 * dt
            _propagate_cov(P, R0, f_n, dt, q_diag)
        if stance[k] and not bad:
            w2 = 0.0
            for r in range(3):
                y[r] = -x[3 + r]
                w2 += (gyr_b_radps[k, r] - x[13 + r]) ** 2
            for r in range(3):
                r_zupt[r] = par[PAR_ZUPT] ** 2 + par[PAR_ROLL_LEVER] ** 2 * w2
            _update_selected(x, P, idx_v, y, r_zupt)
            counters[CNT_UPDATES] += 1
            for r in range(3):
                y[r] = gyr_b_radps[k, r] - x[13 + r]
            if _nis_selected(P, idx_bg, y, r_zaru) < par[PAR_ZARU_GATE]:
                _update_selected(x, P, idx_bg, y, r_zaru)
                counters[CNT_ZARU] += 1
            else:
                counters[CNT_ZARU_REJECTED] += 1
        for r in range(3):
            out_pos[k, r] = x[r]
            out_vel[k, r] = x[3 + r]
            for c in range(3):
                out_pos_cov[k, r, c] = P[P0 + r, P0 + c]
        for r in range(4):
            out_quat[k, r] = x[6 + r]
