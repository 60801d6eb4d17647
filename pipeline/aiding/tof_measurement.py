"""The ToF foot-height measurement: one range reading as a scalar error-state update (compiled).

A sensor at lever arm ``l_b`` from the IMU looks along the unit vector ``u_b`` (body axes) and reads range ρ. With
the attitude ``R = R(q_nb)`` its ray hits a level floor at height z_f where

    p_z + (R l_b)_z + ρ (R u_b)_z = z_f,

so the IMU's measured height above the floor is ``h = −(R l_b)_z − ρ (R u_b)_z`` and the predicted one ``p_z − z_f``
(Merat, Harvey, Mitsis, multi-sensor shoe platform, eqs. 20-21: the height from the range through the estimated
orientation and the sensor's lever arm). As a measurement of the error state:

    g(x) = p_z + w_z,  w = R (l_b + ρ u_b)  (the IMU-to-hit-point vector, navigation axes)
    innovation  y = z_f − g(x̂) = h − (p̂_z − z_f)

With the global attitude error of ``footnav.pipeline.navigation.eskf`` (R = Exp(δθ) R̂ ≈ (I + [δθ]×) R̂),
``R v ≈ R̂ v − [R̂ v]× δθ`` and the row of the Jacobian is

    H = ∂g/∂δx:  δp → (0, 0, 1);  δθ → −e_zᵀ [w]× = (w_y, −w_x, 0);  δv, δb_a, δb_g → 0

(``tests/test_tof_update.py`` checks it against finite differences of g). When the floor is a state of the filter
(a floor level of ``footnav.pipeline.aiding.tof``, error state ``level``, nominal x[level + 1]), z_f is that state
and the row has −1 there. The noise is the range noise along the vertical plus a floor term,
r = (σ_ρ (R̂ u_b)_z)² + σ_f². The update is the scalar Joseph form, expanded like ``_kernels_linalg._update3``:
P ← P − K uᵀ − u Kᵀ + K S Kᵀ with u = P Hᵀ, S = H u + r, K = u / S; then injection and the covariance reset for
the global attitude error (Solà 2017, §7.3).

Gating (before anything changes): a range that is not finite, a measured height more than ``below_m`` under the
floor (the estimate must never be pulled through it), an innovation larger than ``step_m`` (a step edge: the ray
sees another tread than the reference floor) and a normalised innovation y²/S above ``gate_chi2`` (an outlier,
e.g. a spurious reflection) are rejected with their reason code. Units SI (m, rad).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from footnav.pipeline.jit import njit
from footnav.pipeline.navigation.eskf import TH0, update1
from footnav.pipeline.navigation.quaternion import vertical_in_body_s
from numpy.typing import NDArray

F64 = NDArray[np.float64]

# result codes of tof_update
USED, NOT_FINITE, BELOW_FLOOR, STEP_EDGE, OUTLIER = range(5)


class TofParams(NamedTuple):
    """Parameters of :func:`tof_update` (floats; ``footnav.pipeline.aiding.tof_types.TofConfig``)."""

    sigma_range: float
    """Range noise, m."""
    sigma_floor: float
    """Floor noise (unevenness, the level's own error), m."""
    gate: float
    """Normalised innovation squared above which a reading is an outlier."""
    step: float
    """Innovation above which the ray sees another tread (a step edge), m."""
    below: float
    """Measured height under the floor beyond which a reading is rejected, m."""


# layout of the result vector: code, innovation y (m), measured height h (m), floor point z (m),
# hit point x, y (m), S (m²)
RES_CODE, RES_Y, RES_H, RES_FLOOR_Z, RES_HIT_X, RES_HIT_Y, RES_S = range(7)
N_RES = 7


@njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"})
def height_row(x: F64, lever_b_m: F64, dir_b: F64, range_m: float, H: F64) -> tuple[float, float, float, float]:
    """Fill H (n,) with the Jacobian row of g (the floor not a state); return (g(x̂) = p_z + w_z, w_x,
    w_y, (R̂ u_b)_z)."""  # pragma: no cover
    qw, qx, qy, qz = x[6], x[7], x[8], x[9]
    r00 = qw * qw + qx * qx - qy * qy - qz * qz
    r01 = 2.0 * (qx * qy - qw * qz)
    r02 = 2.0 * (qx * qz + qw * qy)
    r10 = 2.0 * (qx * qy + qw * qz)
    r11 = qw * qw - qx * qx + qy * qy - qz * qz
    r12 = 2.0 * (qy * qz - qw * qx)
    r20, r21, r22 = vertical_in_body_s(qw, qx, qy, qz)
    v0 = lever_b_m[0] + range_m * dir_b[0]
    v1 = lever_b_m[1] + range_m * dir_b[1]
    v2 = lever_b_m[2] + range_m * dir_b[2]
    wx = r00 * v0 + r01 * v1 + r02 * v2
    wy = r10 * v0 + r11 * v1 + r12 * v2
    wz = r20 * v0 + r21 * v1 + r22 * v2
    uz = r20 * dir_b[0] + r21 * dir_b[1] + r22 * dir_b[2]
    for i in range(H.shape[0]):
        H[i] = 0.0
    H[2] = 1.0
    H[TH0] = wy
    H[TH0 + 1] = -wx
    return x[2] + wz, wx, wy, uz


@njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"})
def tof_update(
    x: F64,
    P: F64,
    lever_b_m: F64,
    dir_b: F64,
    range_m: float,
    floor_z_m: float,
    level: int,
    par: TofParams,
    apply: bool,
    work: F64,
    res: F64,
) -> None:
    """Gate one range reading against the floor at ``floor_z_m`` and, if it passes and ``apply``,
    update ``x`` (n + 1,) and ``P`` (n, n) in place. ``level``: the error-state index of that floor
    when it is a state (``floor_z_m`` is then x[level + 1]), else −1. ``work`` is (2, n) scratch;
    ``res`` (N_RES,) receives the result (see the RES_* indices; RES_CODE one of the result
    codes)."""  # pragma: no cover
    n = P.shape[0]
    H = work[0]
    u = work[1]
    res[RES_CODE] = NOT_FINITE
    if not math.isfinite(range_m):
        return
    g, wx, wy, uz = height_row(x, lever_b_m, dir_b, range_m, H)
    px, py = x[0], x[1]
    res[RES_H] = x[2] - g  # −w_z: the IMU's height above the point hit
    res[RES_FLOOR_Z] = g
    res[RES_HIT_X] = px + wx
    res[RES_HIT_Y] = py + wy
    y = floor_z_m - g
    res[RES_Y] = y
    r = (par.sigma_range * uz) ** 2 + par.sigma_floor**2
    for i in range(n):
        u[i] = P[i, 2] + P[i, TH0] * H[TH0] + P[i, TH0 + 1] * H[TH0 + 1]
    if level >= 0:
        H[level] = -1.0
        for i in range(n):
            u[i] -= P[i, level]
    s = u[2] + H[TH0] * u[TH0] + H[TH0 + 1] * u[TH0 + 1] + r
    if level >= 0:
        s -= u[level]
    res[RES_S] = s
    if res[RES_H] < -par.below:
        res[RES_CODE] = BELOW_FLOOR
        return
    if abs(y) > par.step:
        res[RES_CODE] = STEP_EDGE
        return
    if y * y / s > par.gate:
        res[RES_CODE] = OUTLIER
        return
    res[RES_CODE] = USED
    if not apply:
        return
    update1(x, P, u, s, y, H)  # H is no longer needed: it receives δx = K y
