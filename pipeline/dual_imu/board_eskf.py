"""footnav's dual-IMU filter: one rigid-board error-state Kalman filter fed by both IMUs, with both
IMUs' biases estimated and the rigid-body relations as measurements (compiled core, no I/O).

Why a rigid-board nominal state. On a rigid board the specific force at the midpoint ``c`` of the
two IMUs is exactly the average of the two measured ones: ``f_i = f_c + ω̇ × ρ_i + ω × (ω × ρ_i)``
with ``ρ₁ = −m/2``, ``ρ₂ = +m/2``, and the lever-arm terms are linear in ``ρ``, so they cancel in
``½ (f₁ + f₂)``. Navigating the midpoint with ``f̄ = ½ (f₁ + f₂)`` and ``ω̄ = ½ (ω₁ + ω₂)`` therefore
needs no angular acceleration (which only a noisy derivative of the gyros would give), averages
both sensors' noise, and makes the paper's position and velocity relations (``p₂ − p₁ = C m``,
``v₂ − v₁ = C (ω × m)``; Chen et al. 2022 eq. 18) hold by construction: ``p_i = p_c + C ρ_i``.
What the two IMUs still tell apart, and what the constraints now measure, are the two bias sets:

    nominal x = [p_c, v_c, q_nb, b_a1, b_g1, b_a2, b_g2]                        (22,)
    error  δx = [δp, δv, δθ, δb_a1, δb_g1, δb_a2, δb_g2]                        (21,)
    δv' = −[R f̄]× δθ − R (w₁ δb_a1 + w₂ δb_a2),   δθ' = −R (w₁ δb_g1 + w₂ δb_g2)

(Solà 2017 §5 and §7, global attitude error, as :mod:`footnav.pipeline.navigation.eskf`), with weights ``w = (½, ½)``
when both IMUs are usable and ``(1, 0)`` or ``(0, 1)`` when only one is. Measurements:

- **equal angular rate** (swing and stance, both IMUs usable): ``ω₁ − ω₂ = b_g1 − b_g2 + n``,
  ``n ~ N(0, 2 σ_ω² / N)`` for the mean over ``N`` = :data:`RATE_EQ_SAMPLES` samples: the gyro-bias
  difference, continuously;
- **equal specific force in stance** (both usable): ``f₁ − f₂ + ω̇ × m + ω × (ω × m) = b_a1 − b_a2 + n``
  (the lever-arm terms vanish when the foot is still, but the detector's stance edges already turn;
  ``ω̇`` from a smoothed backward difference of the rate, its noise in ``n``), χ²-gated: the
  accelerometer-bias difference;
- **zero velocity** of the board in stance (``v_c = 0``), with the roll-lever noise of
  :mod:`footnav.pipeline.navigation.eskf`, and the χ²-gated **zero angular rate** on the averaged rate
  (``H = ½ I`` on each gyro bias).

With one IMU unusable (not finite, or at full scale: saturated) the filter navigates on the other,
its own bias estimates and the lever-arm terms it can form: ``f_c = f₁ + ω̇ × m/2 + ω × (ω × m/2)``
(``ω̇`` from a smoothed backward difference of the rate), and counts every such sample.

Output is IMU 1's point, ``p₁ = p_c − ½ C m``, and IMU 2's, ``p_c + ½ C m``. :class:`DualEskfStream`
carries the filter from batch to batch (bit for bit the same as one call, tested);
:func:`run_dual_eskf` runs a whole record; :mod:`footnav.pipeline.dual_imu.navigator` adds detection and
alignment for a live stream.

References
----------
- Solà, J. (2017). Quaternion kinematics for the error-state Kalman filter. arXiv:1711.02508.
- Chen, Lu, Xu, Liu and Bi (2022), *Sensors and Materials* (the dual-IMU board and its relations).
- Groves, P. D. (2013). *Principles of GNSS, Inertial, and Multisensor Integrated Navigation
  Systems*, 2nd ed., §2.5 (specific force at a lever arm).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np
from footnav.pipeline.dual_imu import dense_kf as kf_dense
from footnav.pipeline.dual_imu.model import (
    ACC_FULL_SCALE_MPS2,
    GYR_FULL_SCALE_RADPS,
    fault_report,
    quat_to_mats,
    sample_ok,
    still_window,
)
from footnav.pipeline.navigation.alignment import align_from_still
from footnav.pipeline.navigation.eskf import (
    inject_attitude_and_reset,
    sample_intervals,
    zupt_gate,
    zupt_vertical_weight,
)
from footnav.pipeline.navigation.navigator import (
    DEFAULT_DT_MAX_S,
    ZARU_GATE_CHI2_3DOF,
    ZUPT_GATE_NIS,
    ZUPT_GATE_RATIO,
    initial_error_sigmas,
)
from footnav.pipeline.navigation.profiles import G0_MPS2, UnitProfile, get_profile
from footnav.pipeline.navigation.quaternion import quat_from_rotvec_s, quat_mul_s, quat_to_mat_into
from numba import njit
from numpy.typing import NDArray

F64 = NDArray[np.float64]

N_STATE = 21
N_NOMINAL = 22
P0, V0, TH0, BA1, BG1, BA2, BG2 = 0, 3, 6, 9, 12, 15, 18

(
    PAR_SIG_ACC_BOTH,
    PAR_SIG_ACC_ONE,
    PAR_SIG_GYR_BOTH,
    PAR_SIG_GYR_ONE,
    PAR_BA_RW,
    PAR_BG_RW,
    PAR_ZUPT,
    PAR_ZARU,
    PAR_G,
    PAR_ZARU_GATE,
    PAR_ROLL_LEVER,
    PAR_ACC_SCALE,
    PAR_GYR_SCALE,
    PAR_GYR_WHITE,
    PAR_ACC_WHITE,
    PAR_ACC_FS,
    PAR_GYR_FS,
    PAR_WDOT_SIGMA,
    PAR_ZUPT_VERT_STAT,
    PAR_ZUPT_GATE,
    PAR_ZUPT_GATE_RATIO,
) = range(21)
N_PAR = 21

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

N_AUX = 11
AUX_LAST_REJECTED = 10
"""aux[10]: 1 when the last sample's zero-velocity update was rejected (its stance gives no level)."""
RATE_EQ_SAMPLES = 10
"""The equal-rate constraint is applied to the mean rate difference of this many samples."""
_WDOT_SMOOTHING = 0.2  # exponential smoothing of the backward-difference angular acceleration


@dataclass(frozen=True, slots=True)
class DualEskfConfig:
    """Settings of footnav's dual-IMU filter.

    Attributes:
        profile: noise model of one IMU (both are the same part).
        align_s: still time at the start of the record used for the alignment, s.
        init_pos_sigma_m, init_vel_sigma_mps, init_tilt_sigma_rad, init_yaw_sigma_rad: initial 1σ.
        dt_max_s: longer intervals are gaps, integrated as this long (``eskf.sample_intervals``), s.
        gravity_mps2: the local gravity, m/s²; 0 or less: the still start's |f̄| (as
            ``footnav.pipeline.navigation.navigator.NavConfig.gravity_mps2``).
    """

    profile: UnitProfile = field(default_factory=lambda: get_profile("generic"))
    align_s: float = 1.0
    dt_max_s: float = DEFAULT_DT_MAX_S
    init_pos_sigma_m: float = 1e-5
    init_vel_sigma_mps: float = 0.01
    init_tilt_sigma_rad: float = math.radians(0.5)
    init_yaw_sigma_rad: float = math.radians(0.01)
    gravity_mps2: float = G0_MPS2


@dataclass(frozen=True, slots=True)
class DualEskfTrack:
    """Per-sample output of :func:`run_dual_eskf`.

    Attributes:
        pos1_n_m: (n, 3) IMU 1's position, m.
        pos_imu_n_m: (n, 2, 3) IMU 1's and IMU 2's positions (rigidly C m apart), m.
        vel_n_mps: (n, 3) the board midpoint's velocity, m/s.
        quat_nb_wxyz: (n, 4) attitude.
        pos_cov_n_m2: (n, 3, 3) position covariance, m².
        bias_b: (n, 4, 3) bias estimates [b_a1, b_g1, b_a2, b_g2] (m/s², rad/s).
        residual_rate_radps: (n, 3) equal-rate innovation ``mean(ω₁ − ω₂) − (b_g1 − b_g2)`` (NaN where none).
        residual_force_mps2: (n, 3) equal-force innovation in stance (NaN where none).
        nis_rate: (n,) NIS of the equal-rate innovation (NaN where none).
        imu_ok: (n, 2) whether each IMU's sample was used.
        counters: named counts (see ``COUNTER_NAMES``).
        messages: plain-language report of unusable IMU samples (empty when there were none).
    """

    pos1_n_m: F64
    pos_imu_n_m: F64
    vel_n_mps: F64
    quat_nb_wxyz: F64
    pos_cov_n_m2: F64
    bias_b: F64
    residual_rate_radps: F64
    residual_force_mps2: F64
    nis_rate: F64
    imu_ok: NDArray[np.bool_]
    counters: dict[str, int]
    messages: tuple[str, ...] = ()


def concat_tracks(parts: list[DualEskfTrack]) -> DualEskfTrack:
    """One track of consecutive ones (counters and messages, which cover everything since the start,
    from the last)."""
    if len(parts) == 1:
        return parts[0]
    last = parts[-1]
    arrays = {
        f.name: np.concatenate([getattr(p, f.name) for p in parts])
        for f in dataclasses.fields(DualEskfTrack)
        if f.name not in ("counters", "messages")
    }
    return DualEskfTrack(**arrays, counters=last.counters, messages=last.messages)


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
    par: F64,
    out_x: F64,
    out_cov: F64,
    out_res: F64,
    out_nis: F64,
    out_ok: NDArray[np.bool_],
    counters: NDArray[np.int64],
) -> None:
    """The filter loop over n samples; ``x`` (22,) and ``P`` (21, 21) are updated in place.

    ``aux`` (N_AUX,) carries the rest of the state between batches (previous rate, smoothed ω̇, the
    running equal-rate sum and count, whether the last sample's zero-velocity update was rejected), so
    a stream cut into batches gives the same result as one call. An unsure stance sample whose
    velocity innovation says the foot is moving is skipped with the rest of that sample's stance
    updates (the gate of ``footnav.pipeline.navigation.eskf``).

    ``acc``, ``gyr``: (n, 2, 3); ``out_x`` (n, 22) nominal states; ``out_cov`` (n, 3, 3) position
    covariance; ``out_res`` (n, 6) = [equal-rate, equal-force innovations] (NaN where not formed);
    ``out_nis`` (n,) NIS of the equal-rate innovation; ``out_ok`` (n, 2).
    """  # pragma: no cover
    n = acc.shape[0]
    g = par[PAR_G]
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
    w_prev = aux[0:3]  # views: updated in place
    wdot = aux[3:6]
    rate_sum = aux[6:9]
    rate_count = int(aux[9])
    for k in range(n):
        dt = dt_s[k]
        ok0 = sample_ok(acc[k, 0], gyr[k, 0], par[PAR_ACC_FS], par[PAR_GYR_FS])
        ok1 = sample_ok(acc[k, 1], gyr[k, 1], par[PAR_ACC_FS], par[PAR_GYR_FS])
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
                    wdot[c] += _WDOT_SMOOTHING * ((w[c] - w_prev[c]) / dt - wdot[c])
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
            sig_a = par[PAR_SIG_ACC_BOTH] if (ok0 and ok1) else par[PAR_SIG_ACC_ONE]
            sig_g = par[PAR_SIG_GYR_BOTH] if (ok0 and ok1) else par[PAR_SIG_GYR_ONE]
            q_acc = (sig_a**2 + par[PAR_ACC_SCALE] ** 2 * f2) * dt * dt
            q_gyr = (sig_g**2 + par[PAR_GYR_SCALE] ** 2 * wn2) * dt * dt
            for c in range(3):
                q_diag[V0 + c] = q_acc
                q_diag[TH0 + c] = q_gyr
                q_diag[BA1 + c] = par[PAR_BA_RW] ** 2 * dt
                q_diag[BA2 + c] = par[PAR_BA_RW] ** 2 * dt
                q_diag[BG1 + c] = par[PAR_BG_RW] ** 2 * dt
                q_diag[BG2 + c] = par[PAR_BG_RW] ** 2 * dt
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
                    r[c] = 2.0 * par[PAR_GYR_WHITE] ** 2 / rate_count
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
                r[c] = par[PAR_ZUPT] ** 2 + par[PAR_ROLL_LEVER] ** 2 * w2sum
            r[2] += par[PAR_ZUPT_VERT_STAT] ** 2 * zupt_vertical_weight(zupt_ratio[k])  # soft vertical (eskf)
            # an unsure sample whose velocity says the foot moves is skipped (footnav.pipeline.navigation.eskf's gate)
            gate = zupt_gate(zupt_ratio[k], par[PAR_ZUPT_GATE], par[PAR_ZUPT_GATE_RATIO])
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
                r[c] = par[PAR_ZARU] ** 2
                # gated against the gyroscopes' own noise (of their mean when both), as footnav.pipeline.navigation.eskf
                r_gate[c] = par[PAR_GYR_WHITE] ** 2 * (0.5 if ok0 and ok1 else 1.0)
            if kf_dense.update3(dx, P, H, y, r, work, par[PAR_ZARU_GATE], r_gate) < par[PAR_ZARU_GATE]:
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
                r_arm = (m0 * m0 + m1 * m1 + m2 * m2) * par[PAR_WDOT_SIGMA] ** 2
                for c in range(3):
                    H[c, BA1 + c] = 1.0
                    H[c, BA2 + c] = -1.0
                    y[c] = (acc[k, 0, c] - acc[k, 1, c]) + (am0, am1, am2)[c] - (x[10 + c] - x[16 + c])
                    out_res[k, 3 + c] = y[c]
                    r[c] = 2.0 * par[PAR_ACC_WHITE] ** 2 + r_arm
                if kf_dense.update3(dx, P, H, y, r, work, par[PAR_ZARU_GATE]) < par[PAR_ZARU_GATE]:
                    _inject(x, P, dx)
                    counters[CNT_FORCE_EQ] += 1
        aux[9] = rate_count
        for i in range(N_NOMINAL):
            out_x[k, i] = x[i]
        for a in range(3):
            for b in range(3):
                out_cov[k, a, b] = P[P0 + a, P0 + b]


def dual_parameters(profile: UnitProfile, rate_hz: float, gravity_mps2: float) -> F64:
    """Parameter vector of :func:`run_dual_filter` (per-sample σ = density·√rate, as ``filter_parameters``)."""
    par = np.zeros(N_PAR)
    acc_white = profile.acc_noise_mps2_rthz * math.sqrt(rate_hz)
    gyr_white = profile.gyr_noise_radps_rthz * math.sqrt(rate_hz)
    par[PAR_SIG_ACC_BOTH] = math.hypot(acc_white / math.sqrt(2.0), profile.motion_acc_mps2)
    par[PAR_SIG_ACC_ONE] = math.hypot(acc_white, profile.motion_acc_mps2)
    par[PAR_SIG_GYR_BOTH] = math.hypot(gyr_white / math.sqrt(2.0), profile.motion_gyr_radps)
    par[PAR_SIG_GYR_ONE] = math.hypot(gyr_white, profile.motion_gyr_radps)
    par[PAR_BA_RW] = profile.acc_bias_rw_mps3_rthz
    par[PAR_BG_RW] = profile.gyr_bias_rw_radps2_rthz
    par[PAR_ZUPT] = profile.zupt_sigma_mps
    par[PAR_ZARU] = math.hypot(profile.zaru_sigma_radps, gyr_white)
    par[PAR_G] = gravity_mps2
    par[PAR_ZARU_GATE] = ZARU_GATE_CHI2_3DOF
    par[PAR_ROLL_LEVER] = profile.roll_lever_m
    par[PAR_ACC_SCALE] = profile.acc_scale_error
    par[PAR_GYR_SCALE] = profile.gyr_scale_error
    par[PAR_GYR_WHITE] = gyr_white
    par[PAR_ACC_WHITE] = acc_white
    par[PAR_ACC_FS] = ACC_FULL_SCALE_MPS2
    par[PAR_GYR_FS] = GYR_FULL_SCALE_RADPS
    par[PAR_ZUPT_VERT_STAT] = profile.zupt_vertical_sigma_mps
    par[PAR_ZUPT_GATE] = ZUPT_GATE_NIS
    par[PAR_ZUPT_GATE_RATIO] = ZUPT_GATE_RATIO
    # 1σ of the smoothed backward difference of the averaged rate (white, σ_w² = gyr_white²/2): with
    # e_k = (1 − α) e_{k−1} + α (u_k − u_{k−1})/Δt, Var e = (α/Δt)² σ_w² · 2/(2 − α)
    alpha = _WDOT_SMOOTHING
    par[PAR_WDOT_SIGMA] = alpha * gyr_white * rate_hz / math.sqrt(2.0 - alpha)
    return par


def run_dual_eskf(
    t_s: F64,
    acc_b_mps2: F64,
    gyr_b_radps: F64,
    stance: NDArray[np.bool_],
    lever_b_m: F64,
    rate_hz: float,
    config: DualEskfConfig | None = None,
    zupt_ratio: F64 | None = None,
) -> DualEskfTrack:
    """Run footnav's dual-IMU filter over a whole record.

    Parameters
    ----------
    t_s : ndarray, shape (n,)
        Sample times, s; the record must start with ``config.align_s`` still.
    acc_b_mps2, gyr_b_radps : ndarray, shape (n, 2, 3)
        IMU 1 and IMU 2 measurements (parallel axes), m/s² and rad/s.
    stance : ndarray of bool, shape (n,)
        Zero-velocity detector output.
    lever_b_m : ndarray, shape (3,)
        IMU 2's position in IMU 1's axes, m.
    zupt_ratio : ndarray, shape (n,), optional
        The detector's statistic over its threshold, T/γ: the vertical ZUPT noise follows it as in
        ``footnav.pipeline.navigation.eskf``; None: the same noise on every axis.
    """
    cfg = config or DualEskfConfig()
    acc = np.ascontiguousarray(acc_b_mps2, dtype=np.float64)
    gyr = np.ascontiguousarray(gyr_b_radps, dtype=np.float64)
    window = still_window(acc, gyr, rate_hz, cfg.align_s)
    stream = DualEskfStream(cfg, lever_b_m, rate_hz, acc[window], gyr[window])
    dt = sample_intervals(t_s, t_s[0] - 1.0 / rate_hz, cfg.dt_max_s)
    return stream.step(t_s, acc, gyr, stance, dt, zupt_ratio)


class DualEskfStream:
    """The filter's state between batches: :meth:`step` runs it over the next samples.

    Args:
        config: filter settings.
        lever_b_m: (3,) IMU 2's position in IMU 1's axes, m.
        rate_hz: nominal sample rate, Hz.
        acc_still_b_mps2, gyr_still_b_radps: (w, 2, 3) still samples to align on (the first of the stream).
    """

    def __init__(
        self, config: DualEskfConfig, lever_b_m: F64, rate_hz: float, acc_still_b_mps2: F64, gyr_still_b_radps: F64
    ) -> None:
        cfg, prof = config, config.profile
        al = align_from_still(acc_still_b_mps2.mean(axis=1), gyr_still_b_radps.mean(axis=1))
        self.lever_b_m = np.asarray(lever_b_m, dtype=np.float64).reshape(3)
        x = np.zeros(N_NOMINAL)
        x[6:10] = al.quat_nb_wxyz
        R = np.empty((3, 3))
        quat_to_mat_into(x[6], x[7], x[8], x[9], R)
        x[0:3] = 0.5 * (R @ self.lever_b_m)  # the midpoint; IMU 1 starts at the origin
        sig = initial_error_sigmas(cfg, prof, imus=2)
        self.x = x
        self.P = np.diag(sig**2)
        self.aux = np.zeros(N_AUX)
        self.par = dual_parameters(prof, rate_hz, al.gravity_for(cfg.gravity_mps2))
        self.counters = np.zeros(N_CNT, dtype=np.int64)
        self._imu_ok: list[NDArray[np.bool_]] = []
        self._t: list[F64] = []

    def step(
        self,
        t_s: F64,
        acc_b_mps2: F64,
        gyr_b_radps: F64,
        stance: NDArray[np.bool_],
        dt_s: F64,
        zupt_ratio: F64 | None = None,
    ) -> DualEskfTrack:
        """Run over (n,) samples: ``acc``/``gyr`` (n, 2, 3), ``stance`` (n,), ``dt_s`` (n,) the interval
        before each sample, s, ``zupt_ratio`` (n,) T/γ (:func:`run_dual_eskf`). Counters and messages
        cover everything since the start."""
        n = t_s.shape[0]
        ratio = np.zeros(n) if zupt_ratio is None else np.ascontiguousarray(zupt_ratio, dtype=np.float64)
        m = self.lever_b_m
        out_x = np.empty((n, N_NOMINAL))
        out_cov = np.empty((n, 3, 3))
        out_res = np.empty((n, 6))
        out_nis = np.empty(n)
        out_ok = np.empty((n, 2), dtype=np.bool_)
        run_dual_filter(
            self.x, self.P, self.aux,
            np.ascontiguousarray(acc_b_mps2, dtype=np.float64), np.ascontiguousarray(gyr_b_radps, dtype=np.float64),
            np.ascontiguousarray(dt_s, dtype=np.float64), np.ascontiguousarray(stance), ratio, m, self.par,
            out_x, out_cov, out_res, out_nis, out_ok, self.counters,
        )  # fmt: skip
        if not out_ok.all():
            self._imu_ok.append(out_ok)
            self._t.append(np.asarray(t_s, dtype=np.float64))
        quat = out_x[:, 6:10]
        half_cm = 0.5 * np.einsum("nij,j->ni", quat_to_mats(quat), m)
        centre = out_x[:, 0:3]
        return DualEskfTrack(
            pos1_n_m=centre - half_cm,
            pos_imu_n_m=np.stack([centre - half_cm, centre + half_cm], axis=1),
            vel_n_mps=out_x[:, 3:6].copy(),
            quat_nb_wxyz=quat.copy(),
            pos_cov_n_m2=out_cov,
            bias_b=out_x[:, 10:22].reshape(n, 4, 3).copy(),
            residual_rate_radps=out_res[:, :3],
            residual_force_mps2=out_res[:, 3:],
            nis_rate=out_nis,
            imu_ok=out_ok,
            counters={name: int(self.counters[i]) for i, name in enumerate(COUNTER_NAMES)},
            messages=self.messages(),
        )

    def messages(self) -> tuple[str, ...]:
        """Plain-language report of the unusable samples so far (batches where both IMUs were fine
        are not kept)."""
        if not self._imu_ok:
            return ()
        return tuple(fault_report(np.concatenate(self._imu_ok), np.concatenate(self._t)))
