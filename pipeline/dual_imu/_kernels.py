"""footnav's dual-IMU filter, compiled: its parameters, the layout of its arrays, and the per-sample loop.

The model, measurements and references are in ``footnav.pipeline.dual_imu.board_eskf``, whose wrappers
(``run_dual_eskf``, ``DualEskfStream``) call :func:`run_dual_filter`. Parameters are a
:class:`DualFilterParams` named tuple of floats (numba passes it by value and reads its fields by name);
``counters`` is an int64 array of counts indexed by the ``CNT_*`` constants; what the filter carries
between batches besides ``x`` and ``P`` is the float array ``aux``, laid out by the ``AUX_*`` constants.
Units SI (m, s, rad).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from footnav.pipeline.dual_imu import dense_kf as kf_dense
from footnav.pipeline.dual_imu.model import sample_ok
from footnav.pipeline.jit import njit
from footnav.pipeline.navigation.eskf import inject_attitude_and_reset, zupt_gate, zupt_vertical_weight
from footnav.pipeline.navigation.quaternion import quat_from_rotvec_s, quat_mul_s, quat_to_mat_into
from numpy.typing import NDArray

F64 = NDArray[np.float64]


class DualFilterParams(NamedTuple):
    """Parameters of :func:`run_dual_filter` (all floats; built by ``board_eskf.dual_parameters``)."""

    sig_acc_both: float
    """Specific-force noise per sample of the two IMUs' mean (white noise at the rate and motion noise), m/s²."""
    sig_acc_one: float
    """Specific-force noise per sample of one IMU alone, m/s²."""
    sig_gyr_both: float
    """Angular-rate noise per sample of the two IMUs' mean, rad/s."""
    sig_gyr_one: float
    """Angular-rate noise per sample of one IMU alone, rad/s."""
    ba_rw: float
    """Accelerometer bias random walk, m/s³/√Hz."""
    bg_rw: float
    """Gyroscope bias random walk, rad/s²/√Hz."""
    zupt: float
    """Zero-velocity pseudo-measurement noise, m/s."""
    zaru: float
    """Zero-angular-rate pseudo-measurement noise, rad/s."""
    g: float
    """Local gravity, m/s²."""
    zaru_gate: float
    """χ² gate (3 degrees of freedom) of the zero-angular-rate and equal-force updates."""
    roll_lever: float
    """Distance from the IMUs to the contact point a stance foot may roll about, m."""
    acc_scale: float
    """Specific-force noise as a fraction of the signal (scale, cross-axis errors)."""
    gyr_scale: float
    """Angular-rate noise as a fraction of the signal."""
    gyr_white: float
    """White angular-rate noise per sample of one gyroscope, rad/s."""
    acc_white: float
    """White specific-force noise per sample of one accelerometer, m/s²."""
    acc_full_scale: float
    """Specific force at or above which an accelerometer reading is saturated, m/s²."""
    gyr_full_scale: float
    """Angular rate at or above which a gyroscope reading is saturated, rad/s."""
    wdot_sigma: float
    """1σ of the smoothed angular acceleration ω̇ (the equal-force lever-arm term), rad/s²."""
    zupt_vert_stat: float
    """Vertical zero-velocity noise added at the detector's threshold (1σ at T/γ = 1), m/s."""
    zupt_gate: float
    """Normalised innovation squared above which an unsure zero-velocity sample is skipped."""
    zupt_gate_ratio: float
    """T/γ above which the detector is unsure of a stance sample."""


N_STATE = 21
"""Error state [δp, δv, δθ, δb_a1, δb_g1, δb_a2, δb_g2]."""
N_NOMINAL = 22
"""Nominal state [p_c, v_c, q_nb (w, x, y, z), b_a1, b_g1, b_a2, b_g2]."""
P0, V0, TH0, BA1, BG1, BA2, BG2 = 0, 3, 6, 9, 12, 15, 18  # blocks of the error state

# counters of run_dual_filter: counts only
(
    CNT_BAD1,
    CNT_BAD2,
    CNT_BOTH_BAD,
    CNT_ZUPT,
    CNT_ZARU,
    CNT_ZARU_REJECTED,
    CNT_RATE_EQ,
    CNT_FORCE_EQ,
    CNT_ZUPT_REJECTED,
) = range(9)
N_CNT = 9
COUNTER_NAMES = (
    "imu1_bad_samples",
    "imu2_bad_samples",
    "both_bad_samples",
    "zero_velocity_updates",
    "zero_rate_updates",
    "zero_rate_rejected",
    "equal_rate_updates",
    "equal_force_updates",
    "zero_velocity_rejected",
)
"""The counters' names, in ``CNT_*`` order."""

# aux: the state carried between batches besides x and P
AUX_W_PREV = 0  # aux[0:3]: the previous sample's bias-corrected rate, rad/s
AUX_WDOT = 3  # aux[3:6]: the smoothed angular acceleration ω̇, rad/s²
AUX_RATE_SUM = 6  # aux[6:9]: running sum of ω₁ − ω₂ towards the next equal-rate update, rad/s
AUX_RATE_COUNT = 9  # aux[9]: samples in that sum
AUX_LAST_REJECTED = 10
"""aux[10]: 1 when the last sample's zero-velocity update was rejected (its stance gives no level)."""
N_AUX = 11

RATE_EQ_SAMPLES = 10
"""The equal-rate constraint is applied to the mean rate difference of this many samples."""
WDOT_SMOOTHING = 0.2
"""Exponential smoothing factor of the backward-difference angular acceleration ω̇."""


@njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"})
def _inject(x: F64, P: F64, dx: F64) -> None:
    """Add ``dx`` (21,) to the nominal ``x`` (22,), reset it to zero and ``P`` (Solà §7.2-7.3)."""  # pragma: no cover
    for c in range(3):
        x[c] += dx[P0 + c]
        x[3 + c] += dx[V0 + c]
    for c in range(12):
        x[10 + c] += dx[BA1 + c]
    inject_attitude_and_reset(x, P, dx[TH0], dx[TH0 + 1], dx[TH0 + 2])
    for i in range(P.shape[0]):
        dx[i] = 0.0


@njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"})
def run_dual_filter(
    x: F64,
    P: F64,
    aux: F64,
    acc: F64,
    gyr: F64,
    dt_s: F64,
    stance: NDArray[np.bool_],
    zupt_ratio: F64,
    lever_b_m: F64,
    par: DualFilterParams,
    out_x: F64,
    out_cov: F64,
    out_res: F64,
    out_nis: F64,
    out_ok: NDArray[np.bool_],
    counters: NDArray[np.int64],
) -> None:
    """The filter loop over n samples; ``x``, ``P``, ``aux`` and ``counters`` are updated in place.

    A stream cut into batches gives the same result as one call. An unsure stance sample whose
    velocity innovation says the foot is moving is skipped with the rest of that sample's stance
    updates (the gate of ``footnav.pipeline.navigation.eskf``).

    Parameters
    ----------
    x : ndarray, shape (22,)
        Nominal state (``N_NOMINAL``).
    P : ndarray, shape (21, 21)
        Error-state covariance.
    aux : ndarray, shape (N_AUX,)
        State carried between batches (``AUX_*``).
    acc, gyr : ndarray, shape (n, 2, 3)
        IMU 1 and IMU 2 specific force, m/s², and angular rate, rad/s.
    dt_s : ndarray, shape (n,)
        Interval before each sample, s (not positive or not finite: no propagation).
    stance : ndarray of bool, shape (n,)
        Zero-velocity detector output.
    zupt_ratio : ndarray, shape (n,)
        The detector's statistic over its threshold, T/γ.
    lever_b_m : ndarray, shape (3,)
        IMU 2's position in IMU 1's axes, m.
    par : DualFilterParams
        Noise, gates and constants.
    out_x : ndarray, shape (n, 22)
        Output: nominal state after each sample.
    out_cov : ndarray, shape (n, 3, 3)
        Output: position covariance, m².
    out_res : ndarray, shape (n, 6)
        Output: [equal-rate, equal-force] innovations, rad/s and m/s² (NaN where not formed).
    out_nis : ndarray, shape (n,)
        Output: NIS of the equal-rate innovation (NaN where none).
    out_ok : ndarray of bool, shape (n, 2)
        Output: whether each IMU's sample was usable.
    counters : ndarray of int64, shape (N_CNT,)
        Counts, incremented (``CNT_*``).
    """  # pragma: no cover
    n = acc.shape[0]
    g = par.g
    hm0, hm1, hm2 = 0.5 * lever_b_m[0], 0.5 * lever_b_m[1], 0.5 * lever_b_m[2]
    F = np.eye(N_STATE)
    for c in range(3):  # every block that can be non-zero (module docstring), for the pattern
        F[P0 + c, V0 + c] = 1.0
        for j in range(3):
            F[V0 + c, TH0 + j] = 1.0
            F[V0 + c, BA1 + j] = 1.0
            F[V0 + c, BA2 + j] = 1.0
            F[TH0 + c, BG1 + j] = 1.0
            F[TH0 + c, BG2 + j] = 1.0
    ptr, idx = kf_dense.pattern(F)
    q_diag = np.zeros(N_STATE)
    M = np.empty((N_STATE, N_STATE))
    work = np.empty((9, N_STATE))
    H = np.zeros((3, N_STATE))
    y = np.empty(3)
    r = np.empty(3)
    r_gate = np.empty(3)
    dx = np.zeros(N_STATE)
    R0 = np.empty((3, 3))
    R1 = np.empty((3, 3))
    fb = np.empty(3)
    w = np.empty(3)
    f_n = np.empty(3)
    w_prev = aux[AUX_W_PREV : AUX_W_PREV + 3]  # views: updated in place
    wdot = aux[AUX_WDOT : AUX_WDOT + 3]
    rate_sum = aux[AUX_RATE_SUM : AUX_RATE_SUM + 3]
    rate_count = int(aux[AUX_RATE_COUNT])
    for k in range(n):
        dt = dt_s[k]
        ok0 = sample_ok(acc[k, 0], gyr[k, 0], par.acc_full_scale, par.gyr_full_scale)
        ok1 = sample_ok(acc[k, 1], gyr[k, 1], par.acc_full_scale, par.gyr_full_scale)
        out_ok[k, 0], out_ok[k, 1] = ok0, ok1
        if not ok0:
            counters[CNT_BAD1] += 1
        if not ok1:
            counters[CNT_BAD2] += 1
        for i in range(6):
            out_res[k, i] = np.nan
        out_nis[k] = np.nan
        any_ok = ok0 or ok1
        w1 = 0.5 if (ok0 and ok1) else (1.0 if ok0 else 0.0)
        w2 = 0.5 if (ok0 and ok1) else (1.0 if ok1 else 0.0)
        quat_to_mat_into(x[6], x[7], x[8], x[9], R0)
        if any_ok:
            for c in range(3):  # (weights times a NaN sample would still be NaN: branch)
                if ok0 and ok1:
                    w[c] = 0.5 * ((gyr[k, 0, c] - x[13 + c]) + (gyr[k, 1, c] - x[19 + c]))
                    fb[c] = 0.5 * ((acc[k, 0, c] - x[10 + c]) + (acc[k, 1, c] - x[16 + c]))
                elif ok0:
                    w[c] = gyr[k, 0, c] - x[13 + c]
                    fb[c] = acc[k, 0, c] - x[10 + c]
                else:
                    w[c] = gyr[k, 1, c] - x[19 + c]
                    fb[c] = acc[k, 1, c] - x[16 + c]
            if dt > 0.0:
                for c in range(3):
                    wdot[c] += WDOT_SMOOTHING * ((w[c] - w_prev[c]) / dt - wdot[c])
            for c in range(3):
                w_prev[c] = w[c]
            if not (ok0 and ok1):
                # one IMU: move its specific force to the midpoint, ±(ω̇ × m/2 + ω × (ω × m/2))
                sgn = 1.0 if ok0 else -1.0
                wm0 = w[1] * hm2 - w[2] * hm1
                wm1 = w[2] * hm0 - w[0] * hm2
                wm2 = w[0] * hm1 - w[1] * hm0
                fb[0] += sgn * ((wdot[1] * hm2 - wdot[2] * hm1) + (w[1] * wm2 - w[2] * wm1))
                fb[1] += sgn * ((wdot[2] * hm0 - wdot[0] * hm2) + (w[2] * wm0 - w[0] * wm2))
                fb[2] += sgn * ((wdot[0] * hm1 - wdot[1] * hm0) + (w[0] * wm1 - w[1] * wm0))
        else:
            counters[CNT_BOTH_BAD] += 1
        if dt > 0.0 and math.isfinite(dt):
            if any_ok:
                ew, ex, ey, ez = quat_from_rotvec_s(w[0] * dt, w[1] * dt, w[2] * dt)
                qw, qx, qy, qz = quat_mul_s(x[6], x[7], x[8], x[9], ew, ex, ey, ez)
                norm = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
                x[6], x[7], x[8], x[9] = qw / norm, qx / norm, qy / norm, qz / norm
                quat_to_mat_into(x[6], x[7], x[8], x[9], R1)
                for c in range(3):
                    f_n[c] = 0.0
                    for j in range(3):
                        f_n[c] += 0.5 * (R0[c, j] + R1[c, j]) * fb[j]
            else:
                f_n[0], f_n[1], f_n[2] = 0.0, 0.0, g  # hold: no usable sample
                for c in range(3):
                    for j in range(3):
                        R1[c, j] = R0[c, j]
            for c in range(3):
                a = f_n[c] - (g if c == 2 else 0.0)
                x[c] += x[3 + c] * dt + 0.5 * a * dt * dt
                x[3 + c] += a * dt
            # F = I + A dt (module docstring), rebuilt in its non-constant blocks
            for c in range(3):
                F[P0 + c, V0 + c] = dt
            F[V0, TH0], F[V0, TH0 + 1], F[V0, TH0 + 2] = 0.0, f_n[2] * dt, -f_n[1] * dt
            F[V0 + 1, TH0], F[V0 + 1, TH0 + 1], F[V0 + 1, TH0 + 2] = -f_n[2] * dt, 0.0, f_n[0] * dt
            F[V0 + 2, TH0], F[V0 + 2, TH0 + 1], F[V0 + 2, TH0 + 2] = f_n[1] * dt, -f_n[0] * dt, 0.0
            for c in range(3):
                for j in range(3):
                    F[V0 + c, BA1 + j] = -w1 * R1[c, j] * dt
                    F[V0 + c, BA2 + j] = -w2 * R1[c, j] * dt
                    F[TH0 + c, BG1 + j] = -w1 * R1[c, j] * dt
                    F[TH0 + c, BG2 + j] = -w2 * R1[c, j] * dt
            f2 = fb[0] ** 2 + fb[1] ** 2 + fb[2] ** 2 if any_ok else 0.0
            wn2 = w[0] ** 2 + w[1] ** 2 + w[2] ** 2 if any_ok else 0.0
            sig_a = par.sig_acc_both if (ok0 and ok1) else par.sig_acc_one
            sig_g = par.sig_gyr_both if (ok0 and ok1) else par.sig_gyr_one
            q_acc = (sig_a**2 + par.acc_scale**2 * f2) * dt * dt
            q_gyr = (sig_g**2 + par.gyr_scale**2 * wn2) * dt * dt
            for c in range(3):
                q_diag[V0 + c] = q_acc
                q_diag[TH0 + c] = q_gyr
                q_diag[BA1 + c] = par.ba_rw**2 * dt
                q_diag[BA2 + c] = par.ba_rw**2 * dt
                q_diag[BG1 + c] = par.bg_rw**2 * dt
                q_diag[BG2 + c] = par.bg_rw**2 * dt
            kf_dense.propagate(P, F, ptr, idx, q_diag, M)
        if ok0 and ok1:
            # equal angular rate: ω₁ − ω₂ = b_g1 − b_g2 + n, as the mean over RATE_EQ_SAMPLES samples
            # (one update with noise 2σ²/N carries what N updates would: the biases hardly move)
            for c in range(3):
                rate_sum[c] += gyr[k, 0, c] - gyr[k, 1, c]
            rate_count += 1
            if rate_count == RATE_EQ_SAMPLES:
                H[:, :] = 0.0
                for c in range(3):
                    H[c, BG1 + c] = 1.0
                    H[c, BG2 + c] = -1.0
                    y[c] = rate_sum[c] / rate_count - (x[13 + c] - x[19 + c])
                    out_res[k, c] = y[c]
                    r[c] = 2.0 * par.gyr_white**2 / rate_count
                    rate_sum[c] = 0.0
                rate_count = 0
                out_nis[k] = kf_dense.update3(dx, P, H, y, r, work, np.inf)
                _inject(x, P, dx)
                counters[CNT_RATE_EQ] += 1
        else:
            rate_count = 0
            rate_sum[:] = 0.0
        moving = False
        aux[AUX_LAST_REJECTED] = 0.0
        if stance[k] and any_ok:
            w2sum = w[0] ** 2 + w[1] ** 2 + w[2] ** 2
            H[:, :] = 0.0
            for c in range(3):
                H[c, V0 + c] = 1.0
                y[c] = -x[3 + c]
                r[c] = par.zupt**2 + par.roll_lever**2 * w2sum
            r[2] += par.zupt_vert_stat**2 * zupt_vertical_weight(zupt_ratio[k])  # soft vertical (eskf)
            # an unsure sample whose velocity says the foot moves is skipped (footnav.pipeline.navigation.eskf's gate)
            gate = zupt_gate(zupt_ratio[k], par.zupt_gate, par.zupt_gate_ratio)
            moving = kf_dense.update3(dx, P, H, y, r, work, gate) >= gate
            if moving:
                counters[CNT_ZUPT_REJECTED] += 1
                aux[AUX_LAST_REJECTED] = 1.0
            else:
                _inject(x, P, dx)
                counters[CNT_ZUPT] += 1
        if stance[k] and any_ok and not moving:
            H[:, :] = 0.0
            for c in range(3):
                H[c, BG1 + c] = w1
                H[c, BG2 + c] = w2
                if ok0 and ok1:  # the rate of the usable IMU(s), corrected with the biases as now updated
                    y[c] = 0.5 * ((gyr[k, 0, c] - x[13 + c]) + (gyr[k, 1, c] - x[19 + c]))
                elif ok0:
                    y[c] = gyr[k, 0, c] - x[13 + c]
                else:
                    y[c] = gyr[k, 1, c] - x[19 + c]
                r[c] = par.zaru**2
                # gated against the gyroscopes' own noise (of their mean when both), as footnav.pipeline.navigation.eskf
                r_gate[c] = par.gyr_white**2 * (0.5 if ok0 and ok1 else 1.0)
            if kf_dense.update3(dx, P, H, y, r, work, par.zaru_gate, r_gate) < par.zaru_gate:
                _inject(x, P, dx)
                counters[CNT_ZARU] += 1
            else:
                counters[CNT_ZARU_REJECTED] += 1
            if ok0 and ok1:
                # equal specific force at rest, lever-arm terms put back for the stance edges (the
                # foot already turns there): f₁ − f₂ + ω̇ × m + ω × (ω × m) = b_a1 − b_a2 + n
                H[:, :] = 0.0
                m0, m1, m2 = 2.0 * hm0, 2.0 * hm1, 2.0 * hm2
                wm0 = w[1] * m2 - w[2] * m1
                wm1 = w[2] * m0 - w[0] * m2
                wm2 = w[0] * m1 - w[1] * m0
                am0 = (wdot[1] * m2 - wdot[2] * m1) + (w[1] * wm2 - w[2] * wm1)
                am1 = (wdot[2] * m0 - wdot[0] * m2) + (w[2] * wm0 - w[0] * wm2)
                am2 = (wdot[0] * m1 - wdot[1] * m0) + (w[0] * wm1 - w[1] * wm0)
                r_arm = (m0 * m0 + m1 * m1 + m2 * m2) * par.wdot_sigma**2
                for c in range(3):
                    H[c, BA1 + c] = 1.0
                    H[c, BA2 + c] = -1.0
                    y[c] = (acc[k, 0, c] - acc[k, 1, c]) + (am0, am1, am2)[c] - (x[10 + c] - x[16 + c])
                    out_res[k, 3 + c] = y[c]
                    r[c] = 2.0 * par.acc_white**2 + r_arm
                if kf_dense.update3(dx, P, H, y, r, work, par.zaru_gate) < par.zaru_gate:
                    _inject(x, P, dx)
                    counters[CNT_FORCE_EQ] += 1
        aux[AUX_RATE_COUNT] = rate_count
        for i in range(N_NOMINAL):
            out_x[k, i] = x[i]
        for a in range(3):
            for b in range(3):
                out_cov[k, a, b] = P[P0 + a, P0 + b]
