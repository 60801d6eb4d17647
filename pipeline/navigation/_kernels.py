"""The foot filter's compiled kernels: propagation, zero-velocity and zero-rate updates, the batch loop.

The model, equations and references are in ``footnav.pipeline.navigation.eskf``, whose thin
wrappers call these kernels. The per-sample loop allocates nothing (scratch arrays are made once per
batch, quaternions are handled as scalars), uses numpy's error model and lets LLVM contract
multiply-adds (``fastmath={"contract"}``: FMA only, so non-finite samples are still caught by
``math.isfinite``). Parameters are a ``FilterParams`` named tuple, counts and carried state two
int64 arrays (``footnav.pipeline.navigation.params``).
"""

from __future__ import annotations

import math

import numpy as np
from footnav.pipeline.jit import njit
from footnav.pipeline.navigation._kernels_linalg import (
    BA0,
    BG0,
    N_STATE,
    P0,
    TH0,
    V0,
    _nis3,
    _update3,
    _update3_diag,
    _update3_sym,
)
from footnav.pipeline.navigation.params import (
    CNT_BAD_DT,
    CNT_BAD_SAMPLE,
    CNT_GAP,
    CNT_UPDATES,
    CNT_ZARU,
    CNT_ZARU_REJECTED,
    CNT_ZUPT_REJECTED,
    N_CNT,
    N_FILTER_STATE,
    STATE_LAST_REJECTED,
    STATE_STANCE_RUN,
    STATE_STARTED,
    FilterParams,
)
from footnav.pipeline.navigation.quaternion import quat_from_rotvec_s, quat_mul_s, quat_to_mat_into, vertical_in_body_s
from numpy.typing import NDArray

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]


@njit(cache=True, error_model="numpy", fastmath={"contract"}, inline="always")
def _propagate_cov(P: F64, M: F64, R: F64, f_n: F64, dt: float, q_diag: F64) -> None:
    """P ← F P Fᵀ + Q in place, F = I + A dt with the blocks of ``footnav.pipeline.navigation.eskf``.

    Only the rows and columns of p, v and θ change, so M = F P is formed for those nine rows
    (``M`` is (9, n) scratch), then P = M Fᵀ applies the same row operation to each of those
    rows of M and is mirrored: about 800 multiply-adds and no allocation. ``P`` is (n, n), n ≥ 15:
    states after the fifteenth (the floor levels of ``footnav.pipeline.aiding.tof``) are constants, F = I
    and Q = 0 for them (``q_diag`` (n,) is zero there).
    """  # pragma: no cover
    n = P.shape[0]
    f0, f1, f2 = f_n[0], f_n[1], f_n[2]
    s = -dt
    # M = F P for the rows of p, v, θ (row operations on P)
    for j in range(n):
        a0, a1, a2 = P[TH0, j], P[TH0 + 1, j], P[TH0 + 2, j]
        b0, b1, b2 = P[BA0, j], P[BA0 + 1, j], P[BA0 + 2, j]
        c0, c1, c2 = P[BG0, j], P[BG0 + 1, j], P[BG0 + 2, j]
        for r in range(3):
            M[P0 + r, j] = P[P0 + r, j] + dt * P[V0 + r, j]
        M[V0, j] = P[V0, j] + s * (-f2 * a1 + f1 * a2) + s * (R[0, 0] * b0 + R[0, 1] * b1 + R[0, 2] * b2)
        M[V0 + 1, j] = P[V0 + 1, j] + s * (f2 * a0 - f0 * a2) + s * (R[1, 0] * b0 + R[1, 1] * b1 + R[1, 2] * b2)
        M[V0 + 2, j] = P[V0 + 2, j] + s * (-f1 * a0 + f0 * a1) + s * (R[2, 0] * b0 + R[2, 1] * b1 + R[2, 2] * b2)
        for r in range(3):
            M[TH0 + r, j] = P[TH0 + r, j] + s * (R[r, 0] * c0 + R[r, 1] * c1 + R[r, 2] * c2)
    # P' = M Fᵀ: row i of P' is F applied to row i of M. Rows 0-8 are written with their mirror
    # images; the bias-bias block is unchanged.
    for i in range(9):
        a0, a1, a2 = M[i, TH0], M[i, TH0 + 1], M[i, TH0 + 2]
        b0, b1, b2 = M[i, BA0], M[i, BA0 + 1], M[i, BA0 + 2]
        c0, c1, c2 = M[i, BG0], M[i, BG0 + 1], M[i, BG0 + 2]
        for r in range(3):
            P[i, P0 + r] = M[i, P0 + r] + dt * M[i, V0 + r]
        P[i, V0] = M[i, V0] + s * (-f2 * a1 + f1 * a2) + s * (R[0, 0] * b0 + R[0, 1] * b1 + R[0, 2] * b2)
        P[i, V0 + 1] = M[i, V0 + 1] + s * (f2 * a0 - f0 * a2) + s * (R[1, 0] * b0 + R[1, 1] * b1 + R[1, 2] * b2)
        P[i, V0 + 2] = M[i, V0 + 2] + s * (-f1 * a0 + f0 * a1) + s * (R[2, 0] * b0 + R[2, 1] * b1 + R[2, 2] * b2)
        for r in range(3):
            P[i, TH0 + r] = M[i, TH0 + r] + s * (R[r, 0] * c0 + R[r, 1] * c1 + R[r, 2] * c2)
        for j in range(9, n):
            P[i, j] = M[i, j]
    # the lower triangle from the upper one: P' is symmetric by construction
    for i in range(n):
        for j in range(min(i, 9)):
            P[i, j] = P[j, i]
        P[i, i] += q_diag[i]


_POS_YAW = (P0, P0 + 1, P0 + 2, TH0 + 2)  # error-state indices of x, y, z and the heading


@njit(cache=True, error_model="numpy", fastmath={"contract"}, inline="always")
def _process_noise(par: FilterParams, f2: float, w2: float, dt: float, q_diag: F64) -> None:
    """Diagonal of Q for one interval (Solà §5.4.3, with per-sample noise σ over dt).

    Specific-force and rate noise have a constant part (white noise and unmodelled vibration) and a
    part proportional to the signal, σ² = σ0² + (k |s|)², for what scale-factor, cross-axis and
    timing errors add: an error of a fraction k of the signal (IEEE Std 952-1997 / 1293-1998 error
    models; Groves 2013 §4.4). ``f2`` = |f_b|², ``w2`` = |ω_b|² of the sample.
    """  # pragma: no cover
    q_acc = (par.sig_acc**2 + par.acc_scale**2 * f2) * dt * dt
    q_gyr = (par.sig_gyr**2 + par.gyr_scale**2 * w2) * dt * dt
    for r in range(3):
        q_diag[V0 + r] = q_acc
        q_diag[TH0 + r] = q_gyr
        q_diag[BA0 + r] = par.ba_rw**2 * dt
        q_diag[BG0 + r] = par.bg_rw**2 * dt


@njit(cache=True, error_model="numpy", fastmath={"contract"}, inline="always")
def _add_body_rate_noise(P: F64, R: F64, var_b: F64, k: int, dt: float) -> None:
    """P[θ, θ] += R diag(v) Rᵀ dt² for the body-axis rate variances v = ``var_b[k]`` (rad²/s²) of a
    sample whose rates are uncertain along their own axes (clipped: ``footnav.pipeline.navigation.saturation``); R the
    attitude at the sample. Nothing when ``var_b`` has no rows (no sample is marked)."""  # pragma: no cover
    if var_b.shape[0] == 0:
        return
    v0, v1, v2 = var_b[k, 0] * dt * dt, var_b[k, 1] * dt * dt, var_b[k, 2] * dt * dt
    if v0 == 0.0 and v1 == 0.0 and v2 == 0.0:
        return
    for r in range(3):
        for c in range(3):
            P[TH0 + r, TH0 + c] += R[r, 0] * v0 * R[c, 0] + R[r, 1] * v1 * R[c, 1] + R[r, 2] * v2 * R[c, 2]


@njit(cache=True, error_model="numpy", fastmath={"contract"}, inline="always")
def _predict(
    x: F64,
    P: F64,
    acc_b_mps2: F64,
    gyr_b_radps: F64,
    gyr_clip_var_b: F64,
    k: int,
    dt: float,
    par: FilterParams,
    q_diag: F64,
    f_n: F64,
    R0: F64,
    R1: F64,
    M: F64,
    counters: I64,
) -> tuple[bool, bool]:
    """Propagate ``x`` and ``P`` over the interval ``dt`` ending at sample ``k`` (in place).

    ``_predict`` then ``_correct`` (at stance samples that are not bad) are the loop body of
    :func:`run_filter_kernel` and of the smoother's storing pass (``footnav.pipeline.smoothing.rts``;
    ``tests/test_smoother.py`` checks that both give bit-identical states and covariances), inlined
    in both (the documentation's design page "Estimator", "Compiled filter kernels").

    Returns
    -------
    bad : bool
        The sample is not finite.
    propagated : bool
        The interval was usable (dt > 0). Afterwards ``f_n`` holds the mean specific force in the
        navigation frame, ``R0`` the rotation of the propagated attitude and ``q_diag`` the diagonal
        of Q: with ``dt`` they define F and Q of this interval (:func:`_propagate_cov`).
    """  # pragma: no cover
    g = par.g
    bad = False
    for r in range(3):
        if not (math.isfinite(acc_b_mps2[k, r]) and math.isfinite(gyr_b_radps[k, r])):
            bad = True
    if bad:
        counters[CNT_BAD_SAMPLE] += 1
    propagated = dt > 0.0 and math.isfinite(dt)
    if not propagated:
        counters[CNT_BAD_DT] += 1
    else:
        if dt >= par.dt_max:
            counters[CNT_GAP] += 1
        quat_to_mat_into(x[6], x[7], x[8], x[9], R0)
        if bad:
            # no usable sample: hold the nominal motion, let the uncertainty grow
            f_n[0], f_n[1], f_n[2] = 0.0, 0.0, g
        else:
            w0 = gyr_b_radps[k, 0] - x[13]
            w1 = gyr_b_radps[k, 1] - x[14]
            w2 = gyr_b_radps[k, 2] - x[15]
            fb0 = acc_b_mps2[k, 0] - x[10]
            fb1 = acc_b_mps2[k, 1] - x[11]
            fb2 = acc_b_mps2[k, 2] - x[12]
            ew, ex, ey, ez = quat_from_rotvec_s(w0 * dt, w1 * dt, w2 * dt)
            qw, qx, qy, qz = quat_mul_s(x[6], x[7], x[8], x[9], ew, ex, ey, ez)
            norm = math.sqrt(qw**2 + qx**2 + qy**2 + qz**2)
            qw, qx, qy, qz = qw / norm, qx / norm, qy / norm, qz / norm
            x[6], x[7], x[8], x[9] = qw, qx, qy, qz
            quat_to_mat_into(qw, qx, qy, qz, R1)
            for r in range(3):
                f_n[r] = (
                    0.0
                    + 0.5 * (R0[r, 0] + R1[r, 0]) * fb0
                    + 0.5 * (R0[r, 1] + R1[r, 1]) * fb1
                    + 0.5 * (R0[r, 2] + R1[r, 2]) * fb2
                )
            for r in range(3):
                for c in range(3):
                    R0[r, c] = R1[r, c]
        for r in range(3):
            a = f_n[r] - (g if r == 2 else 0.0)
            x[r] += x[3 + r] * dt + 0.5 * a * dt * dt
            x[3 + r] += a * dt
        if bad:
            f2, wn2 = 0.0, 0.0
        else:
            f2 = fb0 * fb0 + fb1 * fb1 + fb2 * fb2
            wn2 = w0 * w0 + w1 * w1 + w2 * w2
        _process_noise(par, f2, wn2, dt, q_diag)
        _propagate_cov(P, M, R0, f_n, dt, q_diag)
        if not bad:
            _add_body_rate_noise(P, R0, gyr_clip_var_b, k, dt)
    return bad, propagated


@njit(cache=True, error_model="numpy", fastmath={"contract"}, inline="always")
def _zupt_noise(par: FilterParams, w2: float, ratio: float) -> tuple[float, float]:
    """Horizontal and vertical variance of the zero-velocity pseudo-measurement (``eskf``):
    σ_h² = σ_zupt² + (r |ω|)², σ_z² = σ_h² + σ_T² ρ with ρ = T/γ in [0, 1]. ``w2`` = |ω|², ``ratio``
    the detector's statistic over its threshold (NaN, inf or above 1, a stance from another source
    than that statistic: 1)."""  # pragma: no cover
    r_h = par.zupt**2 + par.roll_lever**2 * w2
    return r_h, r_h + par.zupt_vert_stat**2 * zupt_vertical_weight(ratio)


@njit(cache=True, error_model="numpy", fastmath={"contract"}, inline="always")
def zupt_vertical_weight(ratio: float) -> float:
    """ρ = T/γ clamped to [0, 1] (NaN, inf or above 1: 1), the weight of σ_T² in the vertical ZUPT
    noise (``eskf``); shared with the dual-IMU filter."""  # pragma: no cover
    if not (ratio < 1.0):
        return 1.0
    return max(ratio, 0.0)


@njit(cache=True, error_model="numpy", fastmath={"contract"}, inline="always")
def zupt_gate(ratio: float, gate_nis: float, sure_below: float) -> float:
    """The NIS above which a zero-velocity sample is skipped (``eskf``): ``gate_nis`` when
    the detector is unsure of it (T/γ = ``ratio`` above ``sure_below``; NaN or inf, a stance from
    another source than the statistic), else inf (always applied); shared with the dual-IMU
    filter."""  # pragma: no cover
    return math.inf if ratio <= sure_below else gate_nis


@njit(cache=True, error_model="numpy", fastmath={"contract"}, inline="always")
def track_stance(stance_k: bool, filter_state: I64) -> None:
    """Count the stance samples in a row and mark the end of the first stance, in place.

    Parameters
    ----------
    stance_k : bool
        The current sample is a stance sample.
    filter_state : ndarray of int64, shape (N_FILTER_STATE,)
        Its ``STATE_STANCE_RUN`` and ``STATE_STARTED`` entries are advanced (the standing foot's
        zero-rate noise depends on them).
    """  # pragma: no cover
    if stance_k:
        filter_state[STATE_STANCE_RUN] += 1
    else:
        if filter_state[STATE_STANCE_RUN] > 0:
            filter_state[STATE_STARTED] = 1
        filter_state[STATE_STANCE_RUN] = 0


@njit(cache=True, error_model="numpy", fastmath={"contract"}, inline="always")
def _correct(
    x: F64,
    P: F64,
    gyr_b_radps: F64,
    zupt_ratio: F64,
    k: int,
    par: FilterParams,
    y: F64,
    work: F64,
    counters: I64,
    filter_state: I64,
) -> None:
    """Zero-velocity update, then the χ²-gated zero-angular-rate update, at stance sample ``k``.

    A sample the detector is unsure of whose velocity innovation is too large is skipped and marked
    in ``filter_state[STATE_LAST_REJECTED]`` (``footnav.pipeline.navigation.eskf``). ``y`` (3,) and
    ``work`` (10, n) are scratch; ``counters`` are incremented in place.
    """  # pragma: no cover
    r_zaru = par.zaru**2
    w2 = 0.0
    for r in range(3):
        y[r] = -x[3 + r]
        w2 += (gyr_b_radps[k, r] - x[13 + r]) ** 2
    r_h, r_v = _zupt_noise(par, w2, zupt_ratio[k])
    gate = zupt_gate(zupt_ratio[k], par.zupt_gate, par.zupt_gate_ratio)
    if gate < math.inf and _nis3(P, V0, y[0], y[1], y[2], r_h, r_h, r_v) > gate:  # NIS only when unsure
        counters[CNT_ZUPT_REJECTED] += 1
        filter_state[STATE_LAST_REJECTED] = 1
        return
    _update3_diag(x, P, V0, y, r_h, r_h, r_v, work)
    counters[CNT_UPDATES] += 1
    for r in range(3):
        y[r] = gyr_b_radps[k, r] - x[13 + r]
    g2 = par.zaru_gate_sig**2
    if _nis3(P, BG0, y[0], y[1], y[2], g2, g2, g2) < par.zaru_gate:
        s2 = par.standing_turn**2
        if s2 > 0.0 and filter_state[STATE_STARTED] == 1 and filter_state[STATE_STANCE_RUN] > par.standing_after:
            # a standing foot: R = r I + σ² u uᵀ, u the navigation frame's vertical in body axes
            u0, u1, u2 = vertical_in_body_s(x[6], x[7], x[8], x[9])
            _update3_sym(
                x, P, np.int64(BG0), y, r_zaru + s2 * u0 * u0, s2 * u0 * u1, s2 * u0 * u2,
                r_zaru + s2 * u1 * u1, s2 * u1 * u2, r_zaru + s2 * u2 * u2, work,
            )  # fmt: skip
        else:
            _update3(x, P, BG0, y, r_zaru, work)
        counters[CNT_ZARU] += 1
    else:
        counters[CNT_ZARU_REJECTED] += 1


@njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"})
def run_filter_kernel(
    x: F64,
    P: F64,
    acc_b_mps2: F64,
    gyr_b_radps: F64,
    gyr_clip_var_b: F64,
    dt_s: F64,
    stance: NDArray[np.bool_],
    zupt_ratio: F64,
    par: FilterParams,
    out_pos: F64,
    out_vel: F64,
    out_quat: F64,
    out_cov: F64,
    counters: I64,
    filter_state: I64,
) -> None:
    """The filter over a batch: the arguments of ``footnav.pipeline.navigation.eskf.run_filter``,
    ``filter_state`` given; raises ValueError for inconsistent shapes."""  # pragma: no cover
    n = acc_b_mps2.shape[0]
    # numba does not check bounds: refuse shapes that would write outside the outputs
    if (
        gyr_b_radps.shape[0] != n
        or dt_s.shape[0] != n
        or stance.shape[0] != n
        or zupt_ratio.shape[0] != n
        or (gyr_clip_var_b.shape[0] != n and gyr_clip_var_b.shape[0] != 0)
        or gyr_clip_var_b.shape[1] != 3
        or out_pos.shape[0] < n
        or out_vel.shape[0] < n
        or out_quat.shape[0] < n
        or out_cov.shape[0] < n
        or out_cov.shape[1] != 4
        or out_cov.shape[2] != 4
        or counters.shape[0] != N_CNT
        or filter_state.shape[0] != N_FILTER_STATE
        or P.shape[0] < N_STATE
        or P.shape[1] != P.shape[0]
        or x.shape[0] != P.shape[0] + 1
    ):
        raise ValueError("run_filter: inconsistent array shapes")
    q_diag = np.zeros(P.shape[0])
    y = np.empty(3)
    f_n = np.empty(3)
    R0 = np.empty((3, 3))
    R1 = np.empty((3, 3))
    M = np.empty((9, P.shape[0]))
    work = np.empty((10, P.shape[0]))
    for k in range(n):
        bad, _ = _predict(
            x, P, acc_b_mps2, gyr_b_radps, gyr_clip_var_b, k, dt_s[k], par, q_diag, f_n, R0, R1, M, counters
        )
        filter_state[STATE_LAST_REJECTED] = 0
        track_stance(stance[k], filter_state)
        if stance[k] and not bad:
            _correct(x, P, gyr_b_radps, zupt_ratio, k, par, y, work, counters, filter_state)
        for r in range(3):
            out_pos[k, r] = x[r]
            out_vel[k, r] = x[3 + r]
        for r in range(4):
            for c in range(4):
                out_cov[k, r, c] = P[_POS_YAW[r], _POS_YAW[c]]
        for r in range(4):
            out_quat[k, r] = x[6 + r]
