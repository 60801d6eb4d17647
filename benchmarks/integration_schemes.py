"""Integration schemes for the nominal strapdown state, measured on every recording (issue 4).

    .venv/bin/python -m benchmarks.integration_schemes [--schemes 0 1 2 ...] [--seeds 8] [--rate 1000]
                                                       [--no-real] [--data ../shared/data]

The filter (``pipeline.eskf.run_filter``) integrates the interval ending at sample k with that sample
alone: q_k = q_{k−1} ⊗ Exp(ω_k dt), f_n = ½(R_{k−1} + R_k) f_k, p += v dt + ½ a dt², v += a dt. That
is the midpoint rule for a sample that stands for the middle of its interval (or its mean over the
interval): second order on that time base. For samples that are instantaneous values at their time
stamps (the emulator's are: ``device.emulator.gait``, checked by ``tests/test_gait.py``) it is the
same second-order integration of the signals shifted half a sample earlier. The candidates, all with
the filter's error-state propagation, updates, bad-input rules and parameters (only the nominal step
differs):

0. ``end-sample``: the filter's own step (reproduces ``run_filter`` bit for bit);
1. ``trapezoid``: samples as instantaneous values; ω̄ = ½(ω_{k−1} + ω_k), q_k = q_{k−1} ⊗ Exp(ω̄ dt),
   f_n = ½(R_{k−1} f_{k−1} + R_k f_k) (Solà 2017, §5.3 and app. A; Groves 2013, §5.5);
2. ``trapezoid+coning``: 1 with the rotation vector of a linearly varying rate to second order,
   φ = ω̄ dt + (dt²/12) ω_{k−1} × ω_k (the Bortz term ½∫Δθ(t) × ω(t) dt; Savage 1998, part 1;
   Groves 2013, §5.5.1);
3. ``increments``: samples as means over the interval ending at them (α_k = ω_k dt, Δv_k = f_k dt),
   Savage's two-sample algorithms: φ = α_k + (1/12) α_{k−1} × α_k; Δv = Δv_k + ½ α_k × Δv_k +
   (1/12)(α_{k−1} × Δv_k + Δv_{k−1} × α_k) (rotation compensation and sculling; Savage 1998, parts
   1-2); f_n = R_{k−1} Δv / dt;
4. ``midpoint``: instantaneous samples, inputs at the interval's middle as the two samples' mean,
   f_n = R(q_{k−1} ⊗ Exp(ω̄ dt/2)) ½(f_{k−1} + f_k) (Runge-Kutta midpoint method);
5. ``rk4``: classical Runge-Kutta on q̇ = ½ q ⊗ ω(t), v̇ = R(q) f(t) − g, ṗ = v with ω(t), f(t)
   interpolated linearly between the two samples;
6. ``lag``: a diagnostic, not a candidate: the filter's step fed with the previous sample, i.e.
   scheme 0 delayed by one sample (half a sample later than the trapezoid, as scheme 0 is half a
   sample earlier). It separates the effect of a time shift of the strapdown trajectory against the
   zero-velocity updates from that of the integration order.

Schemes 1-6 need the previous sample: where it is unusable (the first sample, a NaN sample before,
a gap ≥ dt_max) the interval falls back to scheme 0. Whole recordings run in one filter call, so the
previous sample lives only within a call here (enough to measure; the live navigator cuts the
stream into batches).

Reported: the real recordings causally (``benchmarks.accuracy``'s metrics), the emulated walks of
``benchmarks.accuracy`` (1 kHz, its seeds), the same two walks over ``--seeds`` IMU error seeds, and
the integrator alone: noise-free emulator signals from the true initial state, no updates, at three
rates (global error ∝ dt² for a second-order scheme).

What it showed (issue 4; the README's "Accuracy" section): every scheme, the filter's included, is
second order on the emulator's exact signals, and the filter's is among the most accurate (free
integration for 20 s: 3.3 mm at 1 kHz; only scheme 3 is slightly better there, 2.9 mm, and it is
worse at 250 Hz). The instantaneous-sample schemes (1, 2, 4, 5) improve the two closed loops'
horizontal error on real data but make the 1 kHz emulated walks worse (vertically), and the
diagnostic 6 moves most of the same figures further the same way (the x-io loop in 2D and 3D, the
OpenShoe loop in 3D, the PyShoe ATE-3D, the emulated walks; not the OpenShoe loop in 2D), so what
they change is mainly the timing of the trajectory against the zero-velocity updates rather than the
integration error. The filter keeps scheme 0.

References: P. G. Savage, "Strapdown inertial navigation integration algorithm design, part 1:
attitude algorithms; part 2: velocity and position algorithms", J. Guidance, Control and Dynamics
21(1-2), 1998. P. D. Groves, "Principles of GNSS, Inertial, and Multisensor Integrated Navigation
Systems", 2nd ed., 2013, §5.5. J. Solà, "Quaternion kinematics for the error-state Kalman filter",
arXiv:1711.02508, 2017, §5.3 and appendix A (integration methods).
"""

from __future__ import annotations

import argparse
import contextlib
import math
import time
from collections.abc import Iterator
from pathlib import Path
from unittest import mock

import numpy as np
from numba import njit
from numpy.typing import NDArray

from benchmarks.accuracy import DEFAULT_DATA, EMULATED, emulated_row, real_rows
from device.emulator.gait import GRAVITY_MPS2, simulate_walk
from device.emulator.imu_errors import corrupt
from pipeline import eskf
from pipeline.eskf import (
    CNT_BAD_DT,
    CNT_BAD_SAMPLE,
    CNT_GAP,
    N_CNT,
    N_PAR,
    N_STATE,
    PAR_DT_MAX,
    PAR_G,
    _correct,
    _process_noise,
    _propagate_cov,
)
from pipeline.navigator import NavConfig, navigate
from pipeline.profiles import get_profile
from pipeline.quaternion import quat_from_rotvec_s, quat_mul_s, quat_to_mat_into

F64 = NDArray[np.float64]

END_SAMPLE, TRAPEZOID, CONING, INCREMENTS, MIDPOINT, RK4, LAG = range(7)
NAMES = ("end-sample", "trapezoid", "trapezoid+coning", "increments", "midpoint", "rk4", "lag")
_POS_YAW = (0, 1, 2, 8)


@njit(cache=True, error_model="numpy", fastmath={"contract"}, inline="always")
def _rotate_q(
    qw: float, qx: float, qy: float, qz: float, r0: float, r1: float, r2: float
) -> tuple[float, float, float, float]:  # pragma: no cover - compiled
    """q ⊗ Exp(r), normalised."""
    ew, ex, ey, ez = quat_from_rotvec_s(r0, r1, r2)
    a, b, c, d = quat_mul_s(qw, qx, qy, qz, ew, ex, ey, ez)
    norm = math.sqrt(a * a + b * b + c * c + d * d)
    return a / norm, b / norm, c / norm, d / norm


@njit(cache=True, error_model="numpy", fastmath={"contract"}, inline="always")
def _q_rate(
    qw: float, qx: float, qy: float, qz: float, w0: float, w1: float, w2: float
) -> tuple[float, float, float, float]:  # pragma: no cover - compiled
    """q̇ = ½ q ⊗ [0, ω]."""
    a, b, c, d = quat_mul_s(qw, qx, qy, qz, 0.0, w0, w1, w2)
    return 0.5 * a, 0.5 * b, 0.5 * c, 0.5 * d


@njit(cache=True, error_model="numpy", fastmath={"contract"}, inline="always")
def _q_apply(
    qw: float, qx: float, qy: float, qz: float, v0: float, v1: float, v2: float, R: F64
) -> tuple[float, float, float]:  # pragma: no cover - compiled
    """R(q / |q|) v, using ``R`` (3, 3) as scratch."""
    norm = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
    quat_to_mat_into(qw / norm, qx / norm, qy / norm, qz / norm, R)
    return (
        R[0, 0] * v0 + R[0, 1] * v1 + R[0, 2] * v2,
        R[1, 0] * v0 + R[1, 1] * v1 + R[1, 2] * v2,
        R[2, 0] * v0 + R[2, 1] * v1 + R[2, 2] * v2,
    )


@njit(cache=True, error_model="numpy", fastmath={"contract"})
def run_filter_scheme(
    x: F64,
    P: F64,
    acc_b_mps2: F64,
    gyr_b_radps: F64,
    dt_s: F64,
    stance: NDArray[np.bool_],
    zupt_ratio: F64,
    par: F64,
    out_pos: F64,
    out_vel: F64,
    out_quat: F64,
    out_cov: F64,
    counters: NDArray[np.int64],
    scheme: int,
) -> None:  # pragma: no cover - compiled
    """``eskf.run_filter`` with the nominal step of ``scheme`` (module docstring); same arguments."""
    n = acc_b_mps2.shape[0]
    g = par[PAR_G]
    q_diag = np.zeros(N_STATE)
    y = np.empty(3)
    f_n = np.empty(3)
    R0 = np.empty((3, 3))
    R1 = np.empty((3, 3))
    Rs = np.empty((3, 3))
    M = np.empty((9, N_STATE))
    work = np.empty((10, N_STATE))
    prev_ok = False
    pa = np.zeros(3)
    pg = np.zeros(3)
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
            gap = dt >= par[PAR_DT_MAX]
            if gap:
                counters[CNT_GAP] += 1
            quat_to_mat_into(x[6], x[7], x[8], x[9], R0)
            f2, wn2 = 0.0, 0.0
            rk_position = False
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
                f2 = fb0 * fb0 + fb1 * fb1 + fb2 * fb2
                wn2 = w0 * w0 + w1 * w1 + w2 * w2
                # the previous sample, bias-corrected with the current estimate
                u0, u1, u2 = pg[0] - x[13], pg[1] - x[14], pg[2] - x[15]
                e0, e1, e2 = pa[0] - x[10], pa[1] - x[11], pa[2] - x[12]
                s = scheme if (prev_ok and not gap) else END_SAMPLE
                if s == LAG:
                    w0, w1, w2, fb0, fb1, fb2 = u0, u1, u2, e0, e1, e2
                    s = END_SAMPLE
                qw0, qx0, qy0, qz0 = x[6], x[7], x[8], x[9]
                if s == END_SAMPLE:
                    qw, qx, qy, qz = _rotate_q(qw0, qx0, qy0, qz0, w0 * dt, w1 * dt, w2 * dt)
                    quat_to_mat_into(qw, qx, qy, qz, R1)
                    for r in range(3):
                        f_n[r] = (
                            0.0
                            + 0.5 * (R0[r, 0] + R1[r, 0]) * fb0
                            + 0.5 * (R0[r, 1] + R1[r, 1]) * fb1
                            + 0.5 * (R0[r, 2] + R1[r, 2]) * fb2
                        )
                elif s in (TRAPEZOID, CONING):
                    r0, r1, r2 = 0.5 * (u0 + w0) * dt, 0.5 * (u1 + w1) * dt, 0.5 * (u2 + w2) * dt
                    if s == CONING:
                        c = dt * dt / 12.0
                        r0 += c * (u1 * w2 - u2 * w1)
                        r1 += c * (u2 * w0 - u0 * w2)
                        r2 += c * (u0 * w1 - u1 * w0)
                    qw, qx, qy, qz = _rotate_q(qw0, qx0, qy0, qz0, r0, r1, r2)
                    quat_to_mat_into(qw, qx, qy, qz, R1)
                    for r in range(3):
                        f_n[r] = 0.5 * (
                            (R0[r, 0] * e0 + R0[r, 1] * e1 + R0[r, 2] * e2)
                            + (R1[r, 0] * fb0 + R1[r, 1] * fb1 + R1[r, 2] * fb2)
                        )
                elif s == INCREMENTS:
                    a0, a1, a2 = w0 * dt, w1 * dt, w2 * dt
                    b0, b1, b2 = u0 * dt, u1 * dt, u2 * dt
                    qw, qx, qy, qz = _rotate_q(
                        qw0,
                        qx0,
                        qy0,
                        qz0,
                        a0 + (b1 * a2 - b2 * a1) / 12.0,
                        a1 + (b2 * a0 - b0 * a2) / 12.0,
                        a2 + (b0 * a1 - b1 * a0) / 12.0,
                    )
                    quat_to_mat_into(qw, qx, qy, qz, R1)
                    d0, d1, d2 = fb0 * dt, fb1 * dt, fb2 * dt
                    p0, p1, p2 = e0 * dt, e1 * dt, e2 * dt
                    s0 = d0 + 0.5 * (a1 * d2 - a2 * d1) + ((b1 * d2 - b2 * d1) + (p1 * a2 - p2 * a1)) / 12.0
                    s1 = d1 + 0.5 * (a2 * d0 - a0 * d2) + ((b2 * d0 - b0 * d2) + (p2 * a0 - p0 * a2)) / 12.0
                    s2 = d2 + 0.5 * (a0 * d1 - a1 * d0) + ((b0 * d1 - b1 * d0) + (p0 * a1 - p1 * a0)) / 12.0
                    for r in range(3):
                        f_n[r] = (R0[r, 0] * s0 + R0[r, 1] * s1 + R0[r, 2] * s2) / dt
                elif s == MIDPOINT:
                    m0, m1, m2 = 0.5 * (u0 + w0), 0.5 * (u1 + w1), 0.5 * (u2 + w2)
                    hw, hx, hy, hz = _rotate_q(qw0, qx0, qy0, qz0, 0.5 * m0 * dt, 0.5 * m1 * dt, 0.5 * m2 * dt)
                    f_n[0], f_n[1], f_n[2] = _q_apply(
                        hw, hx, hy, hz, 0.5 * (e0 + fb0), 0.5 * (e1 + fb1), 0.5 * (e2 + fb2), Rs
                    )
                    qw, qx, qy, qz = _rotate_q(qw0, qx0, qy0, qz0, m0 * dt, m1 * dt, m2 * dt)
                    quat_to_mat_into(qw, qx, qy, qz, R1)
                else:  # RK4
                    h = dt
                    m0, m1, m2 = 0.5 * (u0 + w0), 0.5 * (u1 + w1), 0.5 * (u2 + w2)
                    n0, n1, n2 = 0.5 * (e0 + fb0), 0.5 * (e1 + fb1), 0.5 * (e2 + fb2)
                    k1w, k1x, k1y, k1z = _q_rate(qw0, qx0, qy0, qz0, u0, u1, u2)
                    a10, a11, a12 = _q_apply(qw0, qx0, qy0, qz0, e0, e1, e2, Rs)
                    q2w, q2x, q2y, q2z = (
                        qw0 + 0.5 * h * k1w,
                        qx0 + 0.5 * h * k1x,
                        qy0 + 0.5 * h * k1y,
                        qz0 + 0.5 * h * k1z,
                    )
                    k2w, k2x, k2y, k2z = _q_rate(q2w, q2x, q2y, q2z, m0, m1, m2)
                    a20, a21, a22 = _q_apply(q2w, q2x, q2y, q2z, n0, n1, n2, Rs)
                    q3w, q3x, q3y, q3z = (
                        qw0 + 0.5 * h * k2w,
                        qx0 + 0.5 * h * k2x,
                        qy0 + 0.5 * h * k2y,
                        qz0 + 0.5 * h * k2z,
                    )
                    k3w, k3x, k3y, k3z = _q_rate(q3w, q3x, q3y, q3z, m0, m1, m2)
                    a30, a31, a32 = _q_apply(q3w, q3x, q3y, q3z, n0, n1, n2, Rs)
                    q4w, q4x, q4y, q4z = qw0 + h * k3w, qx0 + h * k3x, qy0 + h * k3y, qz0 + h * k3z
                    k4w, k4x, k4y, k4z = _q_rate(q4w, q4x, q4y, q4z, w0, w1, w2)
                    a40, a41, a42 = _q_apply(q4w, q4x, q4y, q4z, fb0, fb1, fb2, Rs)
                    qw = qw0 + h / 6.0 * (k1w + 2.0 * k2w + 2.0 * k3w + k4w)
                    qx = qx0 + h / 6.0 * (k1x + 2.0 * k2x + 2.0 * k3x + k4x)
                    qy = qy0 + h / 6.0 * (k1y + 2.0 * k2y + 2.0 * k3y + k4y)
                    qz = qz0 + h / 6.0 * (k1z + 2.0 * k2z + 2.0 * k3z + k4z)
                    norm = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
                    qw, qx, qy, qz = qw / norm, qx / norm, qy / norm, qz / norm
                    quat_to_mat_into(qw, qx, qy, qz, R1)
                    f_n[0] = (a10 + 2.0 * a20 + 2.0 * a30 + a40) / 6.0
                    f_n[1] = (a11 + 2.0 * a21 + 2.0 * a31 + a41) / 6.0
                    f_n[2] = (a12 + 2.0 * a22 + 2.0 * a32 + a42) / 6.0
                    # ṗ = v by the same stages: p += v h + h² (a1 + a2 + a3) / 6
                    x[0] += x[3] * h + h * h * (a10 + a20 + a30) / 6.0
                    x[1] += x[4] * h + h * h * (a11 + a21 + a31) / 6.0
                    x[2] += x[5] * h + h * h * ((a12 + a22 + a32) / 6.0 - 0.5 * g)
                    for r in range(3):
                        x[3 + r] += (f_n[r] - (g if r == 2 else 0.0)) * h
                    rk_position = True
                x[6], x[7], x[8], x[9] = qw, qx, qy, qz
                for r in range(3):
                    for c in range(3):
                        R0[r, c] = R1[r, c]
            if not rk_position:
                for r in range(3):
                    a = f_n[r] - (g if r == 2 else 0.0)
                    x[r] += x[3 + r] * dt + 0.5 * a * dt * dt
                    x[3 + r] += a * dt
            _process_noise(par, f2, wn2, dt, q_diag)
            _propagate_cov(P, M, R0, f_n, dt, q_diag)
        prev_ok = not bad
        if prev_ok:
            for r in range(3):
                pa[r] = acc_b_mps2[k, r]
                pg[r] = gyr_b_radps[k, r]
        if stance[k] and not bad:
            _correct(x, P, gyr_b_radps, zupt_ratio, k, par, y, work, counters)
        for r in range(3):
            out_pos[k, r] = x[r]
            out_vel[k, r] = x[3 + r]
        for r in range(4):
            for c in range(4):
                out_cov[k, r, c] = P[_POS_YAW[r], _POS_YAW[c]]
        for r in range(4):
            out_quat[k, r] = x[6 + r]


@contextlib.contextmanager
def scheme_in_navigator(scheme: int) -> Iterator[None]:
    """Within the block, the navigator (``navigate``, ``navigate_recording``) runs ``scheme``."""

    def run(
        x: F64,
        P: F64,
        acc: F64,
        gyr: F64,
        dt: F64,
        stance: NDArray[np.bool_],
        zupt_ratio: F64,
        par: F64,
        pos: F64,
        vel: F64,
        quat: F64,
        cov: F64,
        counters: NDArray[np.int64],
    ) -> None:
        run_filter_scheme(x, P, acc, gyr, dt, stance, zupt_ratio, par, pos, vel, quat, cov, counters, scheme)

    with mock.patch.object(eskf, "run_filter", run):
        yield


def pure_strapdown(scheme: int, path: str, duration_s: float, rate_hz: float) -> tuple[float, float, float]:
    """Noise-free emulator signals integrated from the true initial state, no updates: the final
    (3D, 2D) position error, m, and attitude error, rad."""
    truth = simulate_walk(path, duration_s, rate_hz=rate_hz, seed=0)
    n = len(truth)
    x = np.zeros(16)
    x[0:3], x[3:6], x[6:10] = truth.pos_n_m[0], truth.vel_n_mps[0], truth.quat_nb_wxyz[0]
    par = np.zeros(N_PAR)
    par[PAR_G] = GRAVITY_MPS2
    par[PAR_DT_MAX] = 1.0
    dt = np.full(n, 1.0 / rate_hz)
    dt[0] = 0.0  # sample 0 is the initial state
    pos, vel, quat, cov = np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 4)), np.empty((n, 4, 4))
    counters = np.zeros(N_CNT, dtype=np.int64)
    stance = np.zeros(n, dtype=np.bool_)
    run_filter_scheme(
        x, np.eye(N_STATE), truth.acc_b_mps2, truth.gyr_b_radps, dt, stance, np.zeros(n), par, pos, vel, quat, cov,
        counters, scheme,
    )  # fmt: skip
    err = pos[-1] - truth.pos_n_m[-1]
    cos_half = min(1.0, abs(float(quat[-1] @ truth.quat_nb_wxyz[-1])))
    return float(np.linalg.norm(err)), float(np.linalg.norm(err[:2])), 2.0 * math.acos(cos_half)


def seeded_walks(scheme: int, seeds: int, rate_hz: float) -> F64:
    """(2 · seeds, 3): end error % of distance, horizontal end error % and final dz (m) of the
    rectangle and figure-eight walks of 240 s, one row per IMU error seed 1..seeds."""
    rows = []
    for path in ("rectangle", "figure8"):
        truth = simulate_walk(path, 240.0, rate_hz=rate_hz, seed=0)
        for seed in range(1, seeds + 1):
            acc, gyr, _ = corrupt(truth.acc_b_mps2, truth.gyr_b_radps, truth.rate_hz, "mpu6500x4", seed=seed)
            with scheme_in_navigator(scheme):
                nav, _ = navigate(truth.t_s, acc, gyr, truth.rate_hz, NavConfig(profile=get_profile("mpu6500x4")))
            assert nav is not None
            err = nav.pos_n_m[-1] - truth.pos_n_m[-1]
            d = truth.distance_m
            rows.append((100.0 * np.linalg.norm(err) / d, 100.0 * np.linalg.norm(err[:2]) / d, err[2]))
    return np.array(rows)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--schemes", type=int, nargs="+", default=list(range(len(NAMES))))
    ap.add_argument("--seeds", type=int, default=8, help="IMU error seeds per emulated walk (0: skip)")
    ap.add_argument("--rate", type=float, default=1000.0, help="sample rate of the seeded emulated walks, Hz")
    ap.add_argument("--no-real", action="store_true")
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA)
    args = ap.parse_args(argv)
    for s in args.schemes:
        t0 = time.perf_counter()
        print(f"=== {s} {NAMES[s]}")
        if not args.no_real:
            with scheme_in_navigator(s):
                rows = real_rows(args.data, smooth=False)
            pyshoe = [r for r in rows if r[1] == "pyshoe"]
            for r in pyshoe:
                print(f"  {r[0]:<22} ARMSE-2D {r[2]:.4f}  ATE-3D {r[3]:.4f}")
            a = np.array([r[2] for r in pyshoe])
            ate = np.array([r[3] for r in pyshoe])
            print(
                f"  PyShoe ARMSE-2D mean {a.mean():.4f} median {np.median(a):.4f} max {a.max():.4f}; "
                f"ATE-3D mean {ate.mean():.4f} median {np.median(ate):.4f} max {ate.max():.4f}"
            )
            for r in rows:
                if not math.isnan(r[4]):
                    print(f"  {r[0]:<22} loop 3D {r[4]:.4f}  2D {r[5]:.4f}")
        for path, dur, seed in EMULATED:
            with scheme_in_navigator(s):
                pct, dz, nees = emulated_row(path, dur, seed)
            print(f"  emulated {path:<10} end error {pct:.4f} % of distance, final dz {dz:+.4f} m, NEES {nees:.2f}")
        if args.seeds > 0:
            e = seeded_walks(s, args.seeds, args.rate)
            print(
                f"  {2 * args.seeds} seeded walks at {args.rate:.0f} Hz: end error % mean {e[:, 0].mean():.4f} "
                f"median {np.median(e[:, 0]):.4f} max {e[:, 0].max():.4f}; 2D % mean {e[:, 1].mean():.4f}; "
                f"dz mean {e[:, 2].mean():+.4f} m"
            )
        for rate in (250.0, 1000.0, 4000.0):
            e3, e2, att = pure_strapdown(s, "figure8", 20.0, rate)
            print(
                f"  integrator alone, figure-eight 20 s at {rate:4.0f} Hz: position {e3:.2e} m (2D {e2:.2e}), "
                f"attitude {math.degrees(att):.2e} deg"
            )
        print(f"  ({time.perf_counter() - t0:.0f} s)", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
