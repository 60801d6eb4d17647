"""The dual-IMU filter of Chen, Lu, Xu, Liu and Bi (2022), reconstructed: a linear Kalman filter on
the positions and velocities of two IMUs on one rigid board, with rigid-body observations.

The paper itself is not available to this project; this module rebuilds it from the relations the
paper states (issue 6): equal angular rate, velocity difference = rate × lever arm, position
difference = rotated lever arm, a linear KF that works in swing as well as in stance. Choices the
reconstruction had to make are marked *(assumed)*.

State and model (navigation frame, z up; ``m`` = IMU 2's position in IMU 1's body axes)::

    x = [r₁, r₂, v₁, v₂]                                                   (12,)
    eq. 17  r⁺ = r + v Δt + ½ a Δt²,  v⁺ = v + a Δt,  a_i = C f_i − g       (input u = [a₁, a₂])
    eq. 18  swing:   r₂ − r₁ = C m,   v₂ − v₁ = C (ω̄ × m)
    eq. 19  stance:  v₁ = 0, v₂ = 0,  r₂ − r₁ = C m

with ``ω̄ = ½ (ω₁ + ω₂)`` the averaged angular rate. The attitude ``C = C_nb`` is not a filter state:
it comes from strapdown integration of ``ω̄`` (one attitude for the rigid board), each gyro's bias
taken as its mean over the still alignment window *(assumed: the usual start-up calibration)*.
Nothing corrects the attitude afterwards: a linear KF on r and v cannot observe it. (A complementary
levelling of roll and pitch from the specific force in stance was tried and dropped: the detector's
stance edges include the start of toe-off, and levelling there made the height drift by decimetres
per lap even on error-free data.) The input noise is
the accelerometers' (per IMU, independent) plus the motion noise of the unit profile; eq. 18/19 noise
1σ: ``sigma_rel_pos_m``, ``sigma_rel_vel_mps``, ``sigma_zupt_mps``.

Output: IMU 1's position from both, ``½ (r₁ + r₂ − C m)``, each IMU's own track, and the eq. 18
residuals ``r₂ − r₁ − C m`` and ``v₂ − v₁ − C (ω̄ × m)`` before each update, with their NIS.

Bad input: a sample of one IMU that is not finite or at full scale (saturated) is replaced by the
other IMU's (specific force moved by the lever-arm terms it can compute, ``ω̄ × (ω̄ × m)``) and counted;
eq. 18 velocity is skipped then. With both bad, the sample is held (no motion, covariance grows).

References
----------
- Chen, Lu, Xu, Liu and Bi (2022), *Sensors and Materials* (eqs. 17-19 as numbered in issue 6).
- Skog, Händel, Nilsson and Rantakokko (2010), zero-velocity detection, IEEE TBME 57(11) (the
  detector that decides stance, shared with the other filters).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NamedTuple

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
from footnav.pipeline.jit import njit
from footnav.pipeline.navigation.alignment import align_from_still
from footnav.pipeline.navigation.profiles import UnitProfile, get_profile
from footnav.pipeline.navigation.quaternion import quat_from_rotvec_s, quat_mul_s, quat_to_mat_into
from numpy.typing import NDArray

F64 = NDArray[np.float64]

N_STATE = 12
R1, R2, V1, V2 = 0, 3, 6, 9

CNT_BAD1, CNT_BAD2, CNT_BOTH_BAD, CNT_SWING_UPDATES, CNT_STANCE_UPDATES = range(5)
N_CNT = 5


@dataclass(frozen=True, slots=True)
class PaperConfig:
    """Settings of the reconstructed paper filter.

    Attributes
    ----------
    profile
        accelerometer noise and motion noise (the same profile as the other filters).
    sigma_rel_pos_m
        1σ of eq. 18/19 ``r₂ − r₁ = C m``, m.
    sigma_rel_vel_mps
        1σ of eq. 18 ``v₂ − v₁ = C (ω̄ × m)``, m/s.
    sigma_zupt_mps
        1σ of eq. 19 ``v_i = 0``, m/s.
    align_s
        still time at the start used for alignment and gyro-bias calibration, s.
    """

    profile: UnitProfile = field(default_factory=lambda: get_profile("generic"))
    sigma_rel_pos_m: float = 1e-3
    sigma_rel_vel_mps: float = 0.01
    sigma_zupt_mps: float = 0.01
    align_s: float = 1.0


@dataclass(frozen=True, slots=True)
class DualTrack:
    """What a dual-IMU filter returns (per sample).

    Attributes
    ----------
    pos1_n_m
        (n, 3) IMU 1's position, the filter's best estimate from both IMUs, m.
    pos_imu_n_m
        (n, 2, 3) each IMU's own position track, m.
    vel1_n_mps
        (n, 3) IMU 1's velocity, m/s.
    quat_nb_wxyz
        (n, 4) board attitude.
    residual_pos_m
        (n, 3) position-constraint residual (NaN where none was formed), m.
    residual_vel_mps
        (n, 3) velocity/rate-constraint residual (NaN where none), m/s or rad/s.
    nis
        (n,) NIS of the constraint residual (NaN where none).
    imu_ok
        (n, 2) whether each IMU's sample was used.
    counters
        named counts (bad samples per IMU, updates).
    messages
        plain-language report of unusable IMU samples (empty when there were none).
    """

    pos1_n_m: F64
    pos_imu_n_m: F64
    vel1_n_mps: F64
    quat_nb_wxyz: F64
    residual_pos_m: F64
    residual_vel_mps: F64
    nis: F64
    imu_ok: NDArray[np.bool_]
    counters: dict[str, int]
    messages: tuple[str, ...] = ()


class PaperFilterParams(NamedTuple):
    """Parameters of :func:`run_paper_filter` (all floats; built by :func:`paper_parameters`)."""

    sig_acc: float
    """Specific-force noise per sample of one IMU (white noise at the rate and motion noise), m/s²."""
    rel_pos: float
    """1σ of eq. 18/19 ``r₂ − r₁ = C m``, m."""
    rel_vel: float
    """1σ of eq. 18 ``v₂ − v₁ = C (ω̄ × m)``, m/s."""
    zupt: float
    """1σ of eq. 19 ``v_i = 0``, m/s."""
    g: float
    """Local gravity, m/s²."""
    acc_full_scale: float
    """Specific force at or above which an accelerometer reading is saturated, m/s²."""
    gyr_full_scale: float
    """Angular rate at or above which a gyroscope reading is saturated, rad/s."""


@njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"})
def run_paper_filter(
    x: F64,
    P: F64,
    quat: F64,
    gyr_bias: F64,
    acc: F64,
    gyr: F64,
    dt_s: F64,
    stance: NDArray[np.bool_],
    lever_b_m: F64,
    par: PaperFilterParams,
    out_x: F64,
    out_quat: F64,
    out_res: F64,
    out_nis: F64,
    out_ok: NDArray[np.bool_],
    counters: NDArray[np.int64],
) -> None:
    """The filter loop over n samples; ``x``, ``P``, ``quat`` and ``counters`` are updated in place.

    Parameters
    ----------
    x : ndarray, shape (12,)
        State [r₁, r₂, v₁, v₂], m and m/s.
    P : ndarray, shape (12, 12)
        Its covariance.
    quat : ndarray, shape (4,)
        Board attitude q_nb (w, x, y, z).
    gyr_bias : ndarray, shape (2, 3)
        Each gyroscope's bias, rad/s.
    acc, gyr : ndarray, shape (n, 2, 3)
        IMU 1 and IMU 2 specific force, m/s², and angular rate, rad/s.
    dt_s : ndarray, shape (n,)
        Interval before each sample, s (not positive or not finite: no propagation).
    stance : ndarray of bool, shape (n,)
        Zero-velocity detector output.
    lever_b_m : ndarray, shape (3,)
        IMU 2's position in IMU 1's axes, m.
    par : PaperFilterParams
        Noise and constants.
    out_x : ndarray, shape (n, 12)
        Output: state after each sample.
    out_quat : ndarray, shape (n, 4)
        Output: attitude after each sample.
    out_res : ndarray, shape (n, 6)
        Output: [r₂ − r₁ − C m, v₂ − v₁ − C (ω̄ × m)] before the update, m and m/s (NaN where not formed).
    out_nis : ndarray, shape (n,)
        Output: NIS of the constraint update (NaN where none).
    out_ok : ndarray of bool, shape (n, 2)
        Output: whether each IMU's sample was usable.
    counters : ndarray of int64, shape (N_CNT,)
        Counts, incremented (``CNT_*``).
    """  # pragma: no cover
    n = acc.shape[0]
    g = par.g
    m0, m1, m2 = lever_b_m[0], lever_b_m[1], lever_b_m[2]
    F = np.eye(N_STATE)
    for i in range(6):
        F[i, 6 + i] = 1.0  # the pattern: r depends on v
    ptr, idx = kf_dense.pattern(F)
    q_diag = np.zeros(N_STATE)
    M = np.empty((N_STATE, N_STATE))
    work = np.empty((9, N_STATE))
    H = np.zeros((3, N_STATE))
    y = np.empty(3)
    r = np.empty(3)
    dx = np.zeros(N_STATE)
    R0 = np.empty((3, 3))
    R1m = np.empty((3, 3))
    f = np.empty((2, 3))
    w = np.empty(3)
    a = np.empty((2, 3))
    cm = np.empty(3)
    cwm = np.empty(3)
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
        quat_to_mat_into(quat[0], quat[1], quat[2], quat[3], R0)
        if not (ok0 or ok1):
            counters[CNT_BOTH_BAD] += 1
            w[:] = 0.0
            for i in range(2):
                f[i, 0], f[i, 1], f[i, 2] = R0[2, 0] * g, R0[2, 1] * g, R0[2, 2] * g  # hold: C f = g
        else:
            for c in range(3):
                if ok0 and ok1:
                    w[c] = 0.5 * (gyr[k, 0, c] - gyr_bias[0, c] + gyr[k, 1, c] - gyr_bias[1, c])
                elif ok0:
                    w[c] = gyr[k, 0, c] - gyr_bias[0, c]
                else:
                    w[c] = gyr[k, 1, c] - gyr_bias[1, c]
            # centripetal term ω̄ × (ω̄ × m): what IMU 2 feels beyond IMU 1 (tangential term unknown here)
            wm0 = w[1] * m2 - w[2] * m1
            wm1 = w[2] * m0 - w[0] * m2
            wm2 = w[0] * m1 - w[1] * m0
            cen0 = w[1] * wm2 - w[2] * wm1
            cen1 = w[2] * wm0 - w[0] * wm2
            cen2 = w[0] * wm1 - w[1] * wm0
            for c in range(3):
                f[0, c] = acc[k, 0, c] if ok0 else acc[k, 1, c] - (cen0, cen1, cen2)[c]
                f[1, c] = acc[k, 1, c] if ok1 else acc[k, 0, c] + (cen0, cen1, cen2)[c]
        propagated = dt > 0.0 and math.isfinite(dt)
        if propagated:
            ew, ex, ey, ez = quat_from_rotvec_s(w[0] * dt, w[1] * dt, w[2] * dt)
            qw, qx, qy, qz = quat_mul_s(quat[0], quat[1], quat[2], quat[3], ew, ex, ey, ez)
            norm = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
            quat[0], quat[1], quat[2], quat[3] = qw / norm, qx / norm, qy / norm, qz / norm
            quat_to_mat_into(quat[0], quat[1], quat[2], quat[3], R1m)
            # eq. 17: input a_i = C f_i − g (C averaged over the interval)
            for i in range(2):
                for c in range(3):
                    s = 0.0
                    for j in range(3):
                        s += 0.5 * (R0[c, j] + R1m[c, j]) * f[i, j]
                    a[i, c] = s - (g if c == 2 else 0.0)
            for i in range(2):
                for c in range(3):
                    x[3 * i + c] += x[6 + 3 * i + c] * dt + 0.5 * a[i, c] * dt * dt
                    x[6 + 3 * i + c] += a[i, c] * dt
            for i in range(6):
                F[i, 6 + i] = dt
            sa2 = par.sig_acc**2
            # input noise: each IMU's acceleration error enters r and v (diagonal approximation of Q)
            for i in range(6):
                q_diag[i] = 0.25 * dt**4 * sa2
                q_diag[6 + i] = dt * dt * sa2
            kf_dense.propagate(P, F, ptr, idx, q_diag, M)
        # observations at the new time: eq. 19 in stance, eq. 18 in swing
        quat_to_mat_into(quat[0], quat[1], quat[2], quat[3], R1m)
        for c in range(3):
            cm[c] = R1m[c, 0] * m0 + R1m[c, 1] * m1 + R1m[c, 2] * m2
        wm0 = w[1] * m2 - w[2] * m1
        wm1 = w[2] * m0 - w[0] * m2
        wm2 = w[0] * m1 - w[1] * m0
        for c in range(3):
            cwm[c] = R1m[c, 0] * wm0 + R1m[c, 1] * wm1 + R1m[c, 2] * wm2
        if ok0 or ok1:
            for i in range(N_STATE):
                dx[i] = 0.0
            # r₂ − r₁ = C m (both phases)
            H[:, :] = 0.0
            for c in range(3):
                H[c, R1 + c] = -1.0
                H[c, R2 + c] = 1.0
                y[c] = cm[c] - (x[R2 + c] - x[R1 + c])
                out_res[k, c] = -y[c]
                r[c] = par.rel_pos**2
            nis = kf_dense.update3(dx, P, H, y, r, work)
            if stance[k]:
                counters[CNT_STANCE_UPDATES] += 1
                for s0 in (V1, V2):
                    H[:, :] = 0.0
                    for c in range(3):
                        H[c, s0 + c] = 1.0
                        y[c] = -(x[s0 + c] + dx[s0 + c])
                        r[c] = par.zupt**2
                    kf_dense.update3(dx, P, H, y, r, work)
            elif ok0 and ok1:
                counters[CNT_SWING_UPDATES] += 1
                H[:, :] = 0.0
                for c in range(3):
                    H[c, V1 + c] = -1.0
                    H[c, V2 + c] = 1.0
                    y[c] = cwm[c] - ((x[V2 + c] + dx[V2 + c]) - (x[V1 + c] + dx[V1 + c]))
                    out_res[k, 3 + c] = -(cwm[c] - (x[V2 + c] - x[V1 + c]))
                    r[c] = par.rel_vel**2
                nis += kf_dense.update3(dx, P, H, y, r, work)
            out_nis[k] = nis
            for i in range(N_STATE):
                x[i] += dx[i]
        for i in range(N_STATE):
            out_x[k, i] = x[i]
        for i in range(4):
            out_quat[k, i] = quat[i]


def paper_parameters(config: PaperConfig, rate_hz: float, gravity_mps2: float) -> PaperFilterParams:
    """Parameters of :func:`run_paper_filter`.

    Parameters
    ----------
    config : PaperConfig
        The filter's settings (noise profile and constraint noise).
    rate_hz : float
        Sample rate, Hz.
    gravity_mps2 : float
        Local gravity, m/s².

    Returns
    -------
    PaperFilterParams
        The filter's parameters.
    """
    prof = config.profile
    return PaperFilterParams(
        sig_acc=math.hypot(prof.acc_noise_mps2_rthz * math.sqrt(rate_hz), prof.motion_acc_mps2),
        rel_pos=float(config.sigma_rel_pos_m),
        rel_vel=float(config.sigma_rel_vel_mps),
        zupt=float(config.sigma_zupt_mps),
        g=float(gravity_mps2),
        acc_full_scale=float(ACC_FULL_SCALE_MPS2),
        gyr_full_scale=float(GYR_FULL_SCALE_RADPS),
    )


def run_paper(
    t_s: F64,
    acc_b_mps2: F64,
    gyr_b_radps: F64,
    stance: NDArray[np.bool_],
    lever_b_m: F64,
    rate_hz: float,
    config: PaperConfig | None = None,
) -> DualTrack:
    """Run the reconstructed paper filter over a whole dual-IMU record.

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
    """
    cfg = config or PaperConfig()
    acc = np.ascontiguousarray(acc_b_mps2, dtype=np.float64)
    gyr = np.ascontiguousarray(gyr_b_radps, dtype=np.float64)
    window = still_window(acc, gyr, rate_hz, cfg.align_s)
    al = align_from_still(acc[window].mean(axis=1), gyr[window].mean(axis=1))
    gyr_bias = np.ascontiguousarray(gyr[window].mean(axis=0))
    m = np.asarray(lever_b_m, dtype=np.float64).reshape(3)
    quat = al.quat_nb_wxyz.copy()
    R = quat_to_mats(quat[None, :])[0]
    x = np.zeros(N_STATE)
    x[R2 : R2 + 3] = R @ m
    P = np.diag(np.concatenate([np.full(6, 1e-8), np.full(6, 1e-4)]))
    n = t_s.shape[0]
    dt = np.diff(t_s, prepend=t_s[0] - 1.0 / rate_hz)
    out_x = np.empty((n, N_STATE))
    out_quat = np.empty((n, 4))
    out_res = np.empty((n, 6))
    out_nis = np.empty(n)
    out_ok = np.empty((n, 2), dtype=np.bool_)
    counters = np.zeros(N_CNT, dtype=np.int64)
    run_paper_filter(
        x, P, quat, gyr_bias, acc, gyr, dt, np.ascontiguousarray(stance), m,
        paper_parameters(cfg, rate_hz, al.gravity_mps2),
        out_x, out_quat, out_res, out_nis, out_ok, counters,
    )  # fmt: skip
    Rs = quat_to_mats(out_quat)
    cm = Rs @ m
    r1, r2 = out_x[:, R1 : R1 + 3], out_x[:, R2 : R2 + 3]
    return DualTrack(
        pos1_n_m=0.5 * (r1 + r2 - cm),
        pos_imu_n_m=np.stack([r1, r2], axis=1),
        vel1_n_mps=out_x[:, V1 : V1 + 3].copy(),
        quat_nb_wxyz=out_quat,
        residual_pos_m=out_res[:, :3],
        residual_vel_mps=out_res[:, 3:],
        nis=out_nis,
        imu_ok=out_ok,
        counters={
            "imu1_bad_samples": int(counters[CNT_BAD1]),
            "imu2_bad_samples": int(counters[CNT_BAD2]),
            "both_bad_samples": int(counters[CNT_BOTH_BAD]),
            "swing_updates": int(counters[CNT_SWING_UPDATES]),
            "stance_updates": int(counters[CNT_STANCE_UPDATES]),
        },
        messages=tuple(fault_report(out_ok, t_s)),
    )
