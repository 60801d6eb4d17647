"""Quaternion and rotation helpers (scalar-first ``quat_wxyz``), compiled with numba.

Conventions follow Solà, "Quaternion kinematics for the error-state Kalman filter" (2017): Hamilton
product, ``q_nb`` rotates body vectors into the navigation frame, ``v_n = R(q_nb) v_b``.

The ``*_s`` and ``*_into`` variants take and return scalars or write into a given array, so compiled
per-sample loops (``footnav.pipeline.navigation.eskf``) allocate nothing; the array versions wrap them.
"""

from __future__ import annotations

import math

import numpy as np
from footnav.pipeline.jit import njit
from numpy.typing import NDArray

F64 = NDArray[np.float64]


@njit(cache=True, inline="always")
def quat_mul_s(
    pw: float, px: float, py: float, pz: float, qw: float, qx: float, qy: float, qz: float
) -> tuple[float, float, float, float]:  # pragma: no cover - compiled
    """Hamilton product ``p ⊗ q`` on scalars (no allocation, for compiled loops); see ``quat_mul``."""
    return (
        pw * qw - px * qx - py * qy - pz * qz,
        pw * qx + px * qw + py * qz - pz * qy,
        pw * qy - px * qz + py * qw + pz * qx,
        pw * qz + px * qy - py * qx + pz * qw,
    )


@njit(cache=True, inline="always")
def quat_from_rotvec_s(rx: float, ry: float, rz: float) -> tuple[float, float, float, float]:  # pragma: no cover
    """``exp(rv/2)`` of the rotation vector (rx, ry, rz) rad, on scalars; see ``quat_from_rotvec``."""
    angle = math.sqrt(rx * rx + ry * ry + rz * rz)
    if angle < 1e-9:
        return 1.0 - angle * angle / 8.0, 0.5 * rx, 0.5 * ry, 0.5 * rz
    s = math.sin(0.5 * angle) / angle
    return math.cos(0.5 * angle), s * rx, s * ry, s * rz


@njit(cache=True, inline="always")
def vertical_in_body_s(w: float, x: float, y: float, z: float) -> tuple[float, float, float]:  # pragma: no cover
    """The navigation frame's vertical in body axes: the last row of ``quat_to_mat`` of (w, x, y, z)."""
    return 2.0 * (x * z - w * y), 2.0 * (y * z + w * x), w * w - x * x - y * y + z * z


@njit(cache=True, inline="always")
def quat_to_mat_into(w: float, x: float, y: float, z: float, m: F64) -> None:  # pragma: no cover - compiled
    """Write the rotation matrix of the unit quaternion (w, x, y, z) into ``m`` (3, 3); see ``quat_to_mat``."""
    m[0, 0] = w * w + x * x - y * y - z * z
    m[0, 1] = 2.0 * (x * y - w * z)
    m[0, 2] = 2.0 * (x * z + w * y)
    m[1, 0] = 2.0 * (x * y + w * z)
    m[1, 1] = w * w - x * x + y * y - z * z
    m[1, 2] = 2.0 * (y * z - w * x)
    m[2, 0], m[2, 1], m[2, 2] = vertical_in_body_s(w, x, y, z)


@njit(cache=True)
def quat_mul(p: F64, q: F64) -> F64:  # pragma: no cover - compiled
    """Hamilton product ``p ⊗ q`` of two (4,) scalar-first quaternions (Solà eq. 12)."""
    out = np.empty(4)
    out[0], out[1], out[2], out[3] = quat_mul_s(p[0], p[1], p[2], p[3], q[0], q[1], q[2], q[3])
    return out


@njit(cache=True)
def quat_from_rotvec(rv: F64) -> F64:  # pragma: no cover - compiled
    """Quaternion of the rotation vector ``rv`` (3,) rad: ``exp(rv/2)`` (Solà eq. 101)."""
    out = np.empty(4)
    out[0], out[1], out[2], out[3] = quat_from_rotvec_s(rv[0], rv[1], rv[2])
    return out


@njit(cache=True)
def quat_to_mat(q: F64) -> F64:  # pragma: no cover - compiled
    """Rotation matrix (3, 3) of a unit quaternion (Solà eq. 115)."""
    m = np.empty((3, 3))
    quat_to_mat_into(q[0], q[1], q[2], q[3], m)
    return m


def quat_from_euler_zyx(roll_rad: float, pitch_rad: float, yaw_rad: float) -> F64:
    """``q_nb`` (4,) of the z-y-x (yaw, pitch, roll) Euler sequence (Groves 2013, eq. 2.40)."""
    cr, sr = math.cos(roll_rad / 2), math.sin(roll_rad / 2)
    cp, sp = math.cos(pitch_rad / 2), math.sin(pitch_rad / 2)
    cy, sy = math.cos(yaw_rad / 2), math.sin(yaw_rad / 2)
    return np.array(
        [
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ]
    )


def yaw_of(quat_nb_wxyz: F64) -> F64:
    """Heading (yaw about z up, rad) of (n, 4) or (4,) quaternions."""
    q = np.atleast_2d(quat_nb_wxyz)
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    yaw: F64 = np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return yaw
