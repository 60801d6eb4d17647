"""Shared error-state algebra of footnav's filters (compiled kernels).

The error-state layout of the foot filter, δx = [δp, δv, δθ, δb_a, δb_g] (15,) with any constant
states (floor levels) after it, and the operations every error-state filter here shares: the
Kalman update of three states and of one scalar measurement in Joseph form, the injection of the
error into the nominal state and the covariance reset (Solà, "Quaternion kinematics for the
error-state Kalman filter", arXiv:1711.02508, 2017, §7.2-7.3; global attitude error, R_true =
Exp(δθ) R̂). Public names are re-exported by ``footnav.pipeline.navigation.eskf``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from footnav.pipeline.jit import njit
from footnav.pipeline.navigation.quaternion import quat_from_rotvec_s, quat_mul_s
from numpy.typing import NDArray

F64 = NDArray[np.float64]

N_STATE = 15
"""Error states of the foot filter."""
P0, V0, TH0, BA0, BG0 = 0, 3, 6, 9, 12
"""First index of δp, δv, δθ, δb_a, δb_g in the error state."""
INTERNAL: dict[str, Any] = {"no_cpython_wrapper": True, "no_cfunc_wrapper": True}
"""numba options of a kernel only compiled code calls: no wrappers for calls from Python, which cost
compile time and are never used."""


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
    # s0 as an int64, not the caller's literal index: one compiled update for every caller
    _update3_sym(x, P, np.int64(s0), y, r0, 0.0, 0.0, r1, 0.0, r2, work)


@njit(cache=True, error_model="numpy", fastmath={"contract"}, **INTERNAL)
def _update3_sym(
    x: F64, P: F64, s0: int, y: F64, r00: float, r01: float, r02: float, r11: float, r12: float, r22: float, work: F64
) -> None:
    """Kalman update for a measurement z of the three error states s0, s0+1, s0+2 (noise R, symmetric,
    given by its upper triangle r00 .. r22).

    H = rows s0..s0+2 of the identity. Joseph form, expanded for this H (only rank-3 work):
    (I−KH) P (I−KH)ᵀ + K R Kᵀ = P − K P[s,:] − P[:,s] Kᵀ + K (P[s,s] + R) Kᵀ.
    The error is then injected into the nominal state ``x`` and the covariance reset (Solà §7.2-7.3).
    ``P`` is (n, n) and ``x`` (n + 1,): error state i ≥ 15 is nominal x[i + 1] (:func:`inject`).
    ``work`` is (10, n) scratch. Compiled once and called, not inlined: the filter's three updates
    (zero velocity, zero rate, a standing foot's zero rate) share one copy, which took numba's first
    compile of the filter from 33 s to 15 s (the documentation's design page "Estimator").
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
