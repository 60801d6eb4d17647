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

Nominal state over the interval dt ending at sample k, with ω = ω_k − b_g, f = f_k − b_a:

    q_k = q_{k−1} ⊗ Exp(ω dt),   f_n = ½ (R_{k−1} + R_k) f,   a = f_n − [0, 0, g]
    p += v dt + ½ a dt²,   v += a dt

the midpoint rule with the sample standing for the middle of its interval (or its mean over it),
second order; for samples that are instantaneous values at their stamps, as the emulator's are, it
is the same integration shifted half a sample earlier, and the error of integrating the emulator's
exact signals still falls as dt² (``tests/test_filter_static.py``). The trapezoid of
instantaneous samples (with and without the coning term), Savage's two-sample coning and sculling,
the Runge-Kutta midpoint method and RK4 were measured against it on every recording (README
"Accuracy"): none is better on both the real recordings and the emulated walks, so the step needs no
previous sample.

Updates while the foot is still: zero velocity (ZUPT, z = 0 − v), then zero angular rate (ZARU,
z = ω_m − b_g), each in Joseph form followed by injection and reset (Solà §7.3). A stance that
passes the zero-velocity detector may still rotate (heel and toe roll, a pivot on the stance foot,
running), which would drag the gyro bias, so ZARU is applied only when its normalised innovation
passes a χ² gate (95 %). The gate and the update use different noise: the gate asks whether the
foot turns at all, so it tests the rate against the gyroscope's own white noise at this rate (and
the bias uncertainty); the update weighs a sample that passes with the profile's residual rotation
of a standing foot added (``zaru_sigma_radps``). Gated with the update's larger noise, slow
rotations of up to about 1.8 °/s at the PyShoe unit's 200 Hz passed as bias and turned the heading
(README "Accuracy": PyShoe ARMSE-2D mean 0.079 → 0.073 m). The price: a bias further from its
estimate than the gate admits (0.5 °/s for the MPU-6500 profile at 1 kHz, 1.2 °/s for the GX3 at
200 Hz; 1.5 °/s with the old gate) is not learned, so a profile's turn-on prior must cover its unit
(re-opening the bias after long rejected stretches took a standing foot's slow turning for bias:
README). For the same
reason the ZUPT noise admits the velocity of a foot rolling about a contact point at most r from
the IMU: σ_v² = σ_zupt² + (r |ω|)², since |v_imu| = |ω × r| ≤ r |ω| for a rigid foot.

A foot that stands for longer than a step (``PAR_STANDING_AFTER`` samples of one stance, 2 s; a
walking stance lasts 0.4-1 s) is a standing foot: the floor holds its roll and pitch, but not its
turn about the vertical (weight shifting, settling, turning on the spot). Its zero-rate update then
carries that turn as noise along the navigation frame's vertical, R = σ_z² I + σ_s² u uᵀ with u the
vertical in body axes and σ_s = ``PAR_STANDING_TURN`` (2 °/s, the size of the slow rocking measured
in the long stances of the OpenShoe and x-io recordings: 1.5-2.6 °/s), so its slow residual rotation
is not taken for a precise vertical bias whose correlation with the heading of the whole walk then
moves the standing foot (OpenShoe's last 4.6 s moved it 8 cm). Not in the first stance: the still
start is where the bias is learnt, and a unit is set down there on purpose (weakening it there took
the OpenShoe loop to 0.17-0.28 m). Measured with ``footnav evaluate`` (README "Accuracy"): OpenShoe
loop 0.097 → 0.041 m, x-io 0.050 → 0.057 m, PyShoe ARMSE-2D mean unchanged (0.067 m); σ_s 1-4 °/s
after 1-2 s give 0.034-0.062 / 0.055-0.058 / 0.067-0.068 m.

The vertical component's noise also grows with how close the detector's statistic T is to its
threshold γ (``zupt_ratio`` = T/γ, in [0, 1] at a stance sample), σ_z² = σ_v² + σ_T² T/γ, while
the horizontal ones stay σ_v²: a "soft" zero-velocity update, whose strength follows the detector's
evidence of motion instead of a hard binary decision (soft ZUPTs with a detector-derived contact
prior: "Posterior-contact soft-ZUPT for foot-mounted inertial navigation", Sensors 26(10), 3033,
2026, doi:10.3390/s26103033). The form is ours: T is the GLRT/SHOE statistic of Skog et al. 2010
(``footnav.pipeline.stance.detectors``), a mean of squared normalised deviations from rest, so a variance
proportional to it scales like the square of the velocity a deviating specific force builds up; at
a stance sample T < γ, so the added 1σ is at most σ_T, reached where the foot is barely still (the
onset and end of stance). Only the vertical axis, because that is where a foot just declared still
keeps moving: the heel pad and the shoe's sole compress under the load of heel strike and foot-flat
while friction holds the foot horizontally (Aerts, De Clercq, "Deformation characteristics of the
heel region of the shod foot during a simulated heel strike: the effect of varying midsole
hardness", J. Sports Sci. 11(5), 1993; Gefen, Megido-Ravid, Itzchak, "In vivo biomechanical
behavior of the human heel pad during the stance phase of gait", J. Biomech. 34, 2001), and the
recordings show it: the PyShoe VICON foot still sinks at up to 0.03 m/s when stance is declared,
the first ZUPT of an x-io stance lifted the foot 0.36 cm on average, and on error-free emulated
signals most of the height loss came from stance samples inside the emulator's heel-strike
transient (README "Accuracy"). The same soft update on all three axes, or a vertical one that
decays with the time since stance began, or one that grows with the specific force's deviation
from g instead of T/γ, were measured on every recording and did worse as a whole
(README "Accuracy"; the probe is in the history: ``git show aa8703a:benchmarks/zupt_noise.py``).

A stance sample the detector is unsure of (T/γ above ``PAR_ZUPT_GATE_RATIO``) is checked against
the filter's own prediction first: if the normalised innovation squared of the zero-velocity update
exceeds ``PAR_ZUPT_GATE`` (10σ) the filter knows the foot is moving, the sample is taken for a
detector error and skipped (counted in ``CNT_ZUPT_REJECTED``; ``FLAG_LAST_REJECTED`` tells the
navigator that a stance's height-update sample was one, so that stance gives no floor level). A
PyShoe walking trial has a 2-sample
"stance" in mid-swing at a true 1.9 m/s, which alone took its ARMSE-2D from 0.044 to 0.070 m.
Samples the detector is sure of are always applied, so a filter whose velocity has gone wrong
(running, whose reconstructed swings end with up to 1.5 m/s of velocity error) is not locked out of
its zero-velocity updates; gating those too (every sample at NIS 150, or 1.2 m/s) did exactly that.

A sample whose rate was clipped at the sensor's range (``footnav.pipeline.navigation.saturation``, whole recordings)
is uncertain along its own body axis: ``run_filter`` adds R diag(σ_i²) Rᵀ dt² to the attitude block
of Q there, σ_i a share of the rate on each clipped axis i (``gyr_clip_var_b``), so the tilt a
clipped pitch rate leaves is one the next stance's updates can explain; the heading is made
uncertain only as far as that axis points up (isotropic noise made it uncertain by the full amount).

The covariance propagation multiplies only the non-identity blocks of F and writes one triangle
(about 800 multiply-adds per sample instead of 2 × 15³); the updates observe three states each, so
their Joseph form is rank-3 work on one triangle. The per-sample loop allocates nothing (scratch
arrays are made once per batch, quaternions are handled as scalars), uses numpy's error model (no
Python-style division checks) and lets LLVM contract multiply-adds (``fastmath={"contract"}``: FMA
only, no reassociation and no assumption about NaN or inf, so bad samples are still caught by
``math.isfinite``). ``benchmarks.numpy_filter`` is the same filter with full matrices, the reference
``tests/test_filter_reference.py`` checks this one against.
"""

from __future__ import annotations

import math

import numpy as np
from footnav.pipeline.navigation.quaternion import quat_from_rotvec_s, quat_mul_s, quat_to_mat_into, vertical_in_body_s
from footnav.pipeline.samples import diff_after
from numba import njit
from numpy.typing import NDArray

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
    PAR_ACC_SCALE,
    PAR_GYR_SCALE,
    PAR_ZUPT_VERT_STAT,
    PAR_ZARU_GATE_SIG,
    PAR_ZUPT_GATE,
    PAR_ZUPT_GATE_RATIO,
    PAR_STANDING_TURN,
    PAR_STANDING_AFTER,
) = range(18)
N_PAR = 18

# counters returned by run_filter
CNT_BAD_DT, CNT_GAP, CNT_BAD_SAMPLE, CNT_UPDATES, CNT_ZARU, CNT_ZARU_REJECTED, CNT_ZUPT_REJECTED = range(7)
FLAG_LAST_REJECTED = 7  # not a count: 1 when the last sample's zero-velocity update was rejected
STATE_STANCE_RUN = 8  # not a count: stance samples in a row up to the current one
FLAG_STARTED = 9  # not a count: 1 once the first stance (the still start) has ended
N_CNT = 10


def sample_intervals(t_s: F64, t_prev_s: float, dt_max_s: float) -> F64:
    """Intervals (n,) ending at each sample of ``t_s`` (n,), s, the first one from ``t_prev_s``.

    An interval of ``dt_max_s`` or more is a gap in the stream (lost packets, a corrupt time stamp):
    it is integrated as ``dt_max_s``, because the IMU says nothing about the motion in between and
    integrating one sample over seconds (or over a corrupt stamp's years) only adds error; the filter
    counts it as a gap. Non-positive or NaN intervals pass through: the filter skips and counts them.
    """
    dt = diff_after(t_prev_s, t_s)
    return np.minimum(dt, dt_max_s, out=dt)


@njit(cache=True, error_model="numpy", fastmath={"contract"}, inline="always")
def _propagate_cov(P: F64, M: F64, R: F64, f_n: F64, dt: float, q_diag: F64) -> None:
    """P ← F P Fᵀ + Q in place, F = I + A dt with the blocks of the module docstring.

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


@njit(cache=True, error_model="numpy", fastmath={"contract"}, inline="always")
def _inv3_spd(
    s00: float, s01: float, s02: float, s11: float, s12: float, s22: float
) -> tuple[float, float, float, float, float, float]:
    """Inverse of a symmetric positive-definite 3×3 matrix by Cholesky factorisation, S = L Lᵀ,
    S⁻¹ = L⁻ᵀ L⁻¹; returns its upper triangle (00, 01, 02, 11, 12, 22)."""  # pragma: no cover
    l00 = math.sqrt(max(s00, 1e-300))
    l10 = s01 / l00
    l20 = s02 / l00
    l11 = math.sqrt(max(s11 - l10 * l10, 1e-300))
    l21 = (s12 - l20 * l10) / l11
    l22 = math.sqrt(max(s22 - l20 * l20 - l21 * l21, 1e-300))
    i00 = 1.0 / l00
    i11 = 1.0 / l11
    i22 = 1.0 / l22
    i10 = (0.0 - l10 * i00) / l11
    i21 = (0.0 - l21 * i11) / l22
    i20 = (0.0 - l20 * i00 - l21 * i10) / l22
    return (
        i00 * i00 + i10 * i10 + i20 * i20,
        i10 * i11 + i20 * i21,
        i20 * i22,
        i11 * i11 + i21 * i21,
        i21 * i22,
        i22 * i22,
    )


@njit(cache=True, error_model="numpy", fastmath={"contract"}, inline="always")
def rotate_attitude_block(P: F64, h0: float, h1: float, h2: float) -> None:
    """P ← G P Gᵀ in place for G = I except G[θ,θ] = I + [h]× (attitude error at rows/columns 6-8 of
    the (n, n) ``P``): rows θ, then columns θ. The filter's reset uses h = δθ/2
    (:func:`inject_attitude_and_reset`), the smoother undoes it with h = −δθ/2."""  # pragma: no cover
    n = P.shape[0]
    for j in range(n):
        a0, a1, a2 = P[TH0, j], P[TH0 + 1, j], P[TH0 + 2, j]
        P[TH0, j] = a0 + (-h2 * a1 + h1 * a2)
        P[TH0 + 1, j] = a1 + (h2 * a0 - h0 * a2)
        P[TH0 + 2, j] = a2 + (-h1 * a0 + h0 * a1)
    for i in range(n):
        a0, a1, a2 = P[i, TH0], P[i, TH0 + 1], P[i, TH0 + 2]
        P[i, TH0] = a0 + (-h2 * a1 + h1 * a2)
        P[i, TH0 + 1] = a1 + (h2 * a0 - h0 * a2)
        P[i, TH0 + 2] = a2 + (-h1 * a0 + h0 * a1)


@njit(cache=True, error_model="numpy", fastmath={"contract"}, inline="always")
def inject_attitude_and_reset(x: F64, P: F64, dth0: float, dth1: float, dth2: float) -> None:
    """Inject an attitude error δθ into ``x``'s quaternion (x[6:10], global error: q ← Exp(δθ) q) and
    reset the covariance ``P`` (n, n), attitude error at rows/columns 6-8, in place.

    Reset: P ← G P Gᵀ with G = I except G[θ,θ] = I + [δθ/2]× for a global attitude error (Solà 2017,
    §7.3.2; from Exp(δθ⁺) = Exp(δθ) Exp(−δθ̂) to first order): rows θ, then columns θ. Shared by
    every error-state filter here (this one, ``tof_update``, ``dual_imu_eskf``).
    """  # pragma: no cover
    ew, ex, ey, ez = quat_from_rotvec_s(dth0, dth1, dth2)
    qw, qx, qy, qz = quat_mul_s(ew, ex, ey, ez, x[6], x[7], x[8], x[9])
    norm = math.sqrt(qw**2 + qx**2 + qy**2 + qz**2)
    x[6], x[7], x[8], x[9] = qw / norm, qx / norm, qy / norm, qz / norm
    rotate_attitude_block(P, 0.5 * dth0, 0.5 * dth1, 0.5 * dth2)
    # outside the θθ block the two sides agree exactly; inside it, average them
    for a in range(3):
        for b in range(a + 1, 3):
            m = 0.5 * (P[TH0 + a, TH0 + b] + P[TH0 + b, TH0 + a])
            P[TH0 + a, TH0 + b] = m
            P[TH0 + b, TH0 + a] = m


@njit(cache=True, error_model="numpy", fastmath={"contract"}, inline="always")
def _nis3(P: F64, s0: int, y0: float, y1: float, y2: float, r0: float, r1: float, r2: float) -> float:
    """Normalised innovation squared yᵀ S⁻¹ y, S = P[s0:s0+3, s0:s0+3] + diag(r0, r1, r2)."""  # pragma: no cover
    i00, i01, i02, i11, i12, i22 = _inv3_spd(
        P[s0, s0] + r0, P[s0, s0 + 1], P[s0, s0 + 2], P[s0 + 1, s0 + 1] + r1, P[s0 + 1, s0 + 2], P[s0 + 2, s0 + 2] + r2
    )
    return (
        y0 * i00 * y0
        + y0 * i01 * y1
        + y0 * i02 * y2
        + y1 * i01 * y0
        + y1 * i11 * y1
        + y1 * i12 * y2
        + y2 * i02 * y0
        + y2 * i12 * y1
        + y2 * i22 * y2
    )


@njit(cache=True, error_model="numpy", fastmath={"contract"}, inline="always")
def _update3(x: F64, P: F64, s0: int, y: F64, r: float, work: F64) -> None:
    """Kalman update for a measurement z of the three error states s0, s0+1, s0+2 (noise r I);
    see :func:`_update3_diag`."""  # pragma: no cover
    _update3_diag(x, P, s0, y, r, r, r, work)


@njit(cache=True, error_model="numpy", fastmath={"contract"}, inline="always")
def _update3_diag(x: F64, P: F64, s0: int, y: F64, r0: float, r1: float, r2: float, work: F64) -> None:
    """Kalman update for a measurement z of the three error states s0, s0+1, s0+2 (noise
    diag(r0, r1, r2)); see :func:`_update3_sym`."""  # pragma: no cover
    _update3_sym(x, P, s0, y, r0, 0.0, 0.0, r1, 0.0, r2, work)


@njit(cache=True, error_model="numpy", fastmath={"contract"}, inline="always")
def _update3_sym(
    x: F64, P: F64, s0: int, y: F64, r00: float, r01: float, r02: float, r11: float, r12: float, r22: float, work: F64
) -> None:
    """Kalman update for a measurement z of the three error states s0, s0+1, s0+2 (noise R, symmetric,
    given by its upper triangle r00 .. r22).

    H = rows s0..s0+2 of the identity. Joseph form, expanded for this H (only rank-3 work):
    (I−KH) P (I−KH)ᵀ + K R Kᵀ = P − K P[s,:] − P[:,s] Kᵀ + K (P[s,s] + R) Kᵀ.
    The error is then injected into the nominal state ``x`` and the covariance reset (Solà §7.2-7.3).
    ``P`` is (n, n) and ``x`` (n + 1,): error state i ≥ 15 is nominal x[i + 1] (:func:`inject`).
    ``work`` is (10, n) scratch.
    """  # pragma: no cover
    n = P.shape[0]
    s00, s01, s02 = P[s0, s0] + r00, P[s0, s0 + 1] + r01, P[s0, s0 + 2] + r02
    s11, s12, s22 = P[s0 + 1, s0 + 1] + r11, P[s0 + 1, s0 + 2] + r12, P[s0 + 2, s0 + 2] + r22
    i00, i01, i02, i11, i12, i22 = _inv3_spd(s00, s01, s02, s11, s12, s22)
    y0, y1, y2 = y[0], y[1], y[2]
    # rows of ``work``: 0-2 Kᵀ = S⁻¹ P[s, :], 3-5 (K S)ᵀ, 6-8 P[s, :] (kept: P is overwritten), 9 δx
    for j in range(n):
        h0, h1, h2 = P[s0, j], P[s0 + 1, j], P[s0 + 2, j]
        k0 = h0 * i00 + h1 * i01 + h2 * i02
        k1 = h0 * i01 + h1 * i11 + h2 * i12
        k2 = h0 * i02 + h1 * i12 + h2 * i22
        work[0, j], work[1, j], work[2, j] = k0, k1, k2
        work[3, j] = (k0 * s00 + k1 * s01 + k2 * s02) - h0
        work[4, j] = (k0 * s01 + k1 * s11 + k2 * s12) - h1
        work[5, j] = (k0 * s02 + k1 * s12 + k2 * s22) - h2
        work[6, j], work[7, j], work[8, j] = h0, h1, h2
        work[9, j] = k0 * y0 + k1 * y1 + k2 * y2
    for i in range(n):
        ki0, ki1, ki2 = work[0, i], work[1, i], work[2, i]
        di0, di1, di2 = work[3, i], work[4, i], work[5, i]
        for j in range(i, n):
            P[i, j] = (
                P[i, j]
                + (di0 * work[0, j] - ki0 * work[6, j])
                + (di1 * work[1, j] - ki1 * work[7, j])
                + (di2 * work[2, j] - ki2 * work[8, j])
            )
    for i in range(n):
        for j in range(i):
            P[i, j] = P[j, i]
    inject(x, P, work[9])


@njit(cache=True, error_model="numpy", fastmath={"contract"}, inline="always")
def inject(x: F64, P: F64, dx: F64) -> None:
    """Inject the error estimate ``dx`` (n,) into the nominal state ``x`` (n + 1,) and reset ``P``
    (n, n) (Solà §7.2-7.3): p, v and the biases add, the attitude error rotates the quaternion, and
    each error state i ≥ 15 (a constant, such as a floor level) adds to x[i + 1]."""  # pragma: no cover
    for r3 in range(3):
        x[r3] += dx[P0 + r3]
        x[3 + r3] += dx[V0 + r3]
        x[10 + r3] += dx[BA0 + r3]
        x[13 + r3] += dx[BG0 + r3]
    for i in range(N_STATE, P.shape[0]):
        x[i + 1] += dx[i]
    inject_attitude_and_reset(x, P, dx[TH0], dx[TH0 + 1], dx[TH0 + 2])


@njit(cache=True, error_model="numpy", fastmath={"contract"}, inline="always")
def update1(x: F64, P: F64, u: F64, s: float, y: float, dx: F64) -> None:
    """One scalar measurement update of ``x`` (n + 1,) and ``P`` (n, n) in place, given u = P Hᵀ (n,),
    S = H u + r and the innovation y: the Joseph form expanded for one row, P ← P − K uᵀ − u Kᵀ +
    K S Kᵀ with K = u / S, on one triangle, then injection and reset of δx = K y (``dx`` (n,) scratch
    receives it). Shared by the ToF (``footnav.pipeline.aiding.tof_measurement``) and stance height
    (``footnav.pipeline.stance.levels``) updates."""  # pragma: no cover
    n = P.shape[0]
    for i in range(n):
        ki = u[i] / s
        for j in range(i, n):
            kj = u[j] / s
            P[i, j] = P[i, j] - ki * u[j] - u[i] * kj + ki * s * kj
    for i in range(n):
        for j in range(i):
            P[i, j] = P[j, i]
    for i in range(n):
        dx[i] = u[i] / s * y
    inject(x, P, dx)


def clone_height(x: F64, P: F64, i: int, extra_var_m2: float) -> None:
    """Stochastic cloning of the height (Roumeliotis and Burdick, ICRA 2002): the constant error state
    ``i`` (nominal x[i + 1]) becomes a copy of δp_z, its row and column of ``P`` those of δp_z and its
    variance that of δp_z plus ``extra_var_m2`` (a floor level placed where the IMU rests)."""
    x[i + 1] = x[P0 + 2]
    P[i, :] = P[P0 + 2, :]
    P[:, i] = P[:, P0 + 2]
    P[i, i] = P[P0 + 2, P0 + 2] + extra_var_m2


_POS_YAW = (P0, P0 + 1, P0 + 2, TH0 + 2)  # error-state indices of x, y, z and the heading


@njit(cache=True, error_model="numpy", fastmath={"contract"}, inline="always")
def _process_noise(par: F64, f2: float, w2: float, dt: float, q_diag: F64) -> None:
    """Diagonal of Q for one interval (Solà §5.4.3, with per-sample noise σ over dt).

    Specific-force and rate noise have a constant part (white noise and unmodelled vibration) and a
    part proportional to the signal, σ² = σ0² + (k |s|)², for what scale-factor, cross-axis and
    timing errors add: an error of a fraction k of the signal (IEEE Std 952-1997 / 1293-1998 error
    models; Groves 2013 §4.4). ``f2`` = |f_b|², ``w2`` = |ω_b|² of the sample.
    """  # pragma: no cover
    q_acc = (par[PAR_SIG_ACC] ** 2 + par[PAR_ACC_SCALE] ** 2 * f2) * dt * dt
    q_gyr = (par[PAR_SIG_GYR] ** 2 + par[PAR_GYR_SCALE] ** 2 * w2) * dt * dt
    for r in range(3):
        q_diag[V0 + r] = q_acc
        q_diag[TH0 + r] = q_gyr
        q_diag[BA0 + r] = par[PAR_BA_RW] ** 2 * dt
        q_diag[BG0 + r] = par[PAR_BG_RW] ** 2 * dt


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
    par: F64,
    q_diag: F64,
    f_n: F64,
    R0: F64,
    R1: F64,
    M: F64,
    counters: NDArray[np.int64],
) -> tuple[bool, bool]:
    """Propagate ``x`` and ``P`` over the interval ``dt`` ending at sample ``k`` (in place).

    ``_predict`` then ``_correct`` (at stance samples that are not bad) are ``run_filter``'s loop
    body, operation for operation, for the smoother's storing pass (``footnav.pipeline.smoothing.rts``);
    ``tests/test_smoother.py`` checks that the two give bit-identical states and covariances. (They
    are not called from ``run_filter`` itself: numba compiled the inlined version about 20 % slower.)

    Returns (bad, propagated): the sample is not finite; the interval was usable (dt > 0).
    Afterwards ``f_n`` holds the mean specific force in the navigation frame, ``R0`` the rotation of
    the propagated attitude and ``q_diag`` the diagonal of Q: with ``dt`` they define F and Q of this
    interval (``_propagate_cov``), which is what the smoother (``footnav.pipeline.smoothing.rts``) stores.
    """  # pragma: no cover
    g = par[PAR_G]
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
        if dt >= par[PAR_DT_MAX]:
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
def _zupt_noise(par: F64, w2: float, ratio: float) -> tuple[float, float]:
    """Horizontal and vertical variance of the zero-velocity pseudo-measurement (module docstring):
    σ_h² = σ_zupt² + (r |ω|)², σ_z² = σ_h² + σ_T² ρ with ρ = T/γ in [0, 1]. ``w2`` = |ω|², ``ratio``
    the detector's statistic over its threshold (NaN, inf or above 1, a stance from another source
    than that statistic: 1)."""  # pragma: no cover
    r_h = par[PAR_ZUPT] ** 2 + par[PAR_ROLL_LEVER] ** 2 * w2
    return r_h, r_h + par[PAR_ZUPT_VERT_STAT] ** 2 * zupt_vertical_weight(ratio)


@njit(cache=True, error_model="numpy", fastmath={"contract"}, inline="always")
def zupt_vertical_weight(ratio: float) -> float:
    """ρ = T/γ clamped to [0, 1] (NaN, inf or above 1: 1), the weight of σ_T² in the vertical ZUPT
    noise (module docstring); shared with the dual-IMU filter."""  # pragma: no cover
    if not (ratio < 1.0):
        return 1.0
    return max(ratio, 0.0)


@njit(cache=True, error_model="numpy", fastmath={"contract"}, inline="always")
def zupt_gate(ratio: float, gate_nis: float, sure_below: float) -> float:
    """The NIS above which a zero-velocity sample is skipped (module docstring): ``gate_nis`` when
    the detector is unsure of it (T/γ = ``ratio`` above ``sure_below``; NaN or inf, a stance from
    another source than the statistic), else inf (always applied); shared with the dual-IMU
    filter."""  # pragma: no cover
    return math.inf if ratio <= sure_below else gate_nis


@njit(cache=True, error_model="numpy", fastmath={"contract"}, inline="always")
def track_stance(stance_k: bool, counters: NDArray[np.int64]) -> None:
    """Count the stance samples in a row (``STATE_STANCE_RUN``) and mark the end of the first stance
    (``FLAG_STARTED``), for the standing foot's zero-rate noise (module docstring)."""  # pragma: no cover
    if stance_k:
        counters[STATE_STANCE_RUN] += 1
    else:
        if counters[STATE_STANCE_RUN] > 0:
            counters[FLAG_STARTED] = 1
        counters[STATE_STANCE_RUN] = 0


@njit(cache=True, error_model="numpy", fastmath={"contract"}, inline="always")
def _correct(
    x: F64,
    P: F64,
    gyr_b_radps: F64,
    zupt_ratio: F64,
    k: int,
    par: F64,
    y: F64,
    work: F64,
    counters: NDArray[np.int64],
) -> None:
    """Zero-velocity update, then the χ²-gated zero-angular-rate update, at stance sample ``k``; a
    sample the detector is unsure of whose velocity innovation is too large is skipped (module
    docstring)."""  # pragma: no cover
    r_zaru = par[PAR_ZARU] ** 2
    w2 = 0.0
    for r in range(3):
        y[r] = -x[3 + r]
        w2 += (gyr_b_radps[k, r] - x[13 + r]) ** 2
    r_h, r_v = _zupt_noise(par, w2, zupt_ratio[k])
    gate = zupt_gate(zupt_ratio[k], par[PAR_ZUPT_GATE], par[PAR_ZUPT_GATE_RATIO])
    if gate < math.inf and _nis3(P, V0, y[0], y[1], y[2], r_h, r_h, r_v) > gate:  # NIS only when unsure
        counters[CNT_ZUPT_REJECTED] += 1
        counters[FLAG_LAST_REJECTED] = 1
        return
    _update3_diag(x, P, V0, y, r_h, r_h, r_v, work)
    counters[CNT_UPDATES] += 1
    for r in range(3):
        y[r] = gyr_b_radps[k, r] - x[13 + r]
    g2 = par[PAR_ZARU_GATE_SIG] ** 2
    if _nis3(P, BG0, y[0], y[1], y[2], g2, g2, g2) < par[PAR_ZARU_GATE]:
        s2 = par[PAR_STANDING_TURN] ** 2
        if s2 > 0.0 and counters[FLAG_STARTED] == 1 and counters[STATE_STANCE_RUN] > par[PAR_STANDING_AFTER]:
            # a standing foot: R = r I + σ² u uᵀ, u the navigation frame's vertical in body axes
            u0, u1, u2 = vertical_in_body_s(x[6], x[7], x[8], x[9])
            _update3_sym(
                x, P, BG0, y, r_zaru + s2 * u0 * u0, s2 * u0 * u1, s2 * u0 * u2,
                r_zaru + s2 * u1 * u1, s2 * u1 * u2, r_zaru + s2 * u2 * u2, work,
            )  # fmt: skip
        else:
            _update3(x, P, BG0, y, r_zaru, work)
        counters[CNT_ZARU] += 1
    else:
        counters[CNT_ZARU_REJECTED] += 1


@njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"})
def run_filter(
    x: F64,
    P: F64,
    acc_b_mps2: F64,
    gyr_b_radps: F64,
    gyr_clip_var_b: F64,
    dt_s: F64,
    stance: NDArray[np.bool_],
    zupt_ratio: F64,
    par: F64,
    out_pos: F64,
    out_vel: F64,
    out_quat: F64,
    out_cov: F64,
    counters: NDArray[np.int64],
) -> None:
    """Run the filter over a batch, updating ``x`` (16,) and ``P`` (15, 15) in place.

    Args:
        x, P: nominal state and error covariance, carried between batches. With floor levels as
            states (``footnav.pipeline.aiding.tof``) ``x`` is (16 + m,) and ``P`` (15 + m, 15 + m).
        acc_b_mps2, gyr_b_radps: (n, 3) IMU samples; sample k covers the interval ending at it.
        gyr_clip_var_b: (n, 3) variance of each sample's rate error along each body axis beyond the
            profile's noise, rad²/s² (clipped samples: ``footnav.pipeline.navigation.saturation``), or (0, 3): none.
        dt_s: (n,) interval before each sample, s. Non-positive intervals skip the propagation
            (duplicated timestamps); intervals of ``par[PAR_DT_MAX]`` or more are counted as gaps
            (:func:`sample_intervals` caps them there).
        stance: (n,) apply ZUPT + ZARU after propagating sample k.
        zupt_ratio: (n,) the zero-velocity detector's statistic over its threshold, T/γ, at each sample:
            sets the vertical noise of that sample's ZUPT (module docstring); zeros give the same
            noise on all three axes.
        par: (N_PAR,) parameters (see the PAR_* indices).
        out_pos, out_vel: (n, 3) outputs; out_quat (n, 4); out_cov (n, 4, 4): the covariance of
            (x, y, z, ψ), position and the heading error (the z component of δθ).
        counters: (N_CNT,) incremented in place (see the CNT_* indices).

    All scratch space is allocated once per call, none per sample.
    """  # pragma: no cover
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
        or par.shape[0] != N_PAR
        or counters.shape[0] != N_CNT
        or P.shape[0] < N_STATE
        or P.shape[1] != P.shape[0]
        or x.shape[0] != P.shape[0] + 1
    ):
        raise ValueError("run_filter: inconsistent array shapes")
    g = par[PAR_G]
    q_diag = np.zeros(P.shape[0])
    y = np.empty(3)
    f_n = np.empty(3)
    R0 = np.empty((3, 3))
    R1 = np.empty((3, 3))
    M = np.empty((9, P.shape[0]))
    work = np.empty((10, P.shape[0]))
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
            if dt >= par[PAR_DT_MAX]:
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
                f2, w2 = 0.0, 0.0
            else:
                f2 = fb0 * fb0 + fb1 * fb1 + fb2 * fb2
                w2 = w0 * w0 + w1 * w1 + w2 * w2
            _process_noise(par, f2, w2, dt, q_diag)
            _propagate_cov(P, M, R0, f_n, dt, q_diag)
            if not bad:
                _add_body_rate_noise(P, R0, gyr_clip_var_b, k, dt)
        counters[FLAG_LAST_REJECTED] = 0
        track_stance(stance[k], counters)
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
