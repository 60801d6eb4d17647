"""A miscalibrated unit that performs the icosahedron calibration procedure by itself.

The unit sits in a 3D-printed icosahedron and rests on each of its 20 faces in turn: gravity then
points along the face normals in the body frame. :func:`simulate_icosahedron` produces the true
motion: ``still_s`` seconds on each face (nearest unvisited face next), and between faces a rotation
about one fixed body axis with a smoothstep angle profile (zero rate at both ends, non-zero in between,
so a still detector sees motion). The IMU turns about its own centre, so the true specific force is
``f_b = C_bn (0, 0, g)`` and the true rate is ``θ̇ · axis_b``.

:class:`Miscalibration` applies the 15-parameter accelerometer model of
:mod:`footnav.pipeline.calibration.model` with known parameters, gyroscope biases with a temperature slope, and a
warm-up temperature profile; white noise and in-run drift come from a grade of
:mod:`.imu_errors` (without its turn-on biases: the miscalibration's biases are the known truth).

References: the icosahedron face normals are the normalised vertices of the dual dodecahedron,
``(±1, ±1, ±1), (0, ±1/φ, ±φ), (±1/φ, ±φ, 0), (±φ, 0, ±1/φ)``, φ the golden ratio (Coxeter,
*Regular Polytopes*, 3rd ed., 1973).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Final

import numpy as np
from footnav.device.emulator.sensors.imu_errors import IMU_GRADES, corrupt
from numpy.typing import NDArray

F64 = NDArray[np.float64]

STANDARD_GRAVITY_MPS2: Final = 9.80665
MISCALIBRATED_MCU_ID: Final = b"FNAV-CALIB-DEMO"
"""The 15-byte MCU id the emulated miscalibrated unit answers (``calibrate --demo``, ``demo --miscalibrated``)."""
_PHI: Final = (1.0 + math.sqrt(5.0)) / 2.0


def icosahedron_face_normals() -> F64:
    """(20, 3) unit outward normals of a regular icosahedron's faces."""
    v = [np.array([sx, sy, sz]) for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]
    for a in (-1, 1):
        for b in (-1, 1):
            v.append(np.array([0.0, a / _PHI, b * _PHI]))
            v.append(np.array([a / _PHI, b * _PHI, 0.0]))
            v.append(np.array([a * _PHI, 0.0, b / _PHI]))
    out = np.array(v, dtype=np.float64)
    return np.asarray(out / np.linalg.norm(out, axis=1, keepdims=True), dtype=np.float64)


def _quat_mul(p: F64, q: F64) -> F64:
    pw, px, py, pz = p[..., 0], p[..., 1], p[..., 2], p[..., 3]
    qw, qx, qy, qz = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack(
        [
            pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
        ],
        axis=-1,
    )


def _quat_to_mat(q: F64) -> F64:
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1),
        ],
        axis=-2,
    )


def quat_nb_resting_on(up_b: F64) -> F64:
    """A body-to-nav quaternion (4,) whose nav z axis (up) is ``up_b`` (3,) in the body frame.

    That is the attitude in which the specific force at rest, ``C_bn (0, 0, g)``, points along ``up_b``.
    """
    u = np.asarray(up_b, dtype=np.float64) / np.linalg.norm(up_b)
    z = np.array([0.0, 0.0, 1.0])
    # rotation taking body vector u to nav z: axis u × z, angle acos(u · z)
    axis = np.cross(u, z)
    s, c = float(np.linalg.norm(axis)), float(u @ z)
    if s < 1e-12:
        return np.array([1.0, 0.0, 0.0, 0.0]) if c > 0 else np.array([0.0, 1.0, 0.0, 0.0])
    half = 0.5 * math.atan2(s, c)
    return np.concatenate([[math.cos(half)], math.sin(half) * axis / s])


@dataclass(frozen=True, slots=True)
class IcosahedronTruth:
    """True motion of the procedure at ``rate_hz``.

    Attributes
    ----------
    t_s
        (n,) sample times from 0, s.
    quat_nb_wxyz
        (n, 4) attitude, body to navigation.
    acc_b_mps2
        (n, 3) true specific force, body frame, m/s².
    gyr_b_radps
        (n, 3) true angular rate, body frame, rad/s.
    face
        (n,) index into :func:`icosahedron_face_normals` while still on a face, −1 while turning.
    order
        (20,) faces in the order visited.
    """

    t_s: F64
    quat_nb_wxyz: F64
    acc_b_mps2: F64
    gyr_b_radps: F64
    face: NDArray[np.int64]
    order: NDArray[np.int64]
    rate_hz: float

    def __len__(self) -> int:
        return int(self.t_s.shape[0])


def visit_order(normals: F64, start: int = 0) -> NDArray[np.int64]:
    """Nearest-unvisited-face order through the normals (k, 3), from ``start``."""
    left = set(range(len(normals))) - {start}
    order = [start]
    while left:
        cur = normals[order[-1]]
        nxt = max(left, key=lambda j: float(normals[j] @ cur))
        order.append(nxt)
        left.remove(nxt)
    return np.asarray(order, dtype=np.int64)


def simulate_icosahedron(
    rate_hz: float = 1000.0,
    *,
    still_s: float = 3.0,
    turn_s: float = 1.5,
    first_still_s: float | None = None,
    n_faces: int = 20,
    gravity_mps2: float = STANDARD_GRAVITY_MPS2,
) -> IcosahedronTruth:
    """The procedure's true motion: ``n_faces`` faces, ``still_s`` each, ``turn_s`` turns between.

    ``first_still_s`` (default ``still_s``) for the first face; ``n_faces < 20`` visits only the first
    faces of the order (for tests of too few faces).
    """
    normals = icosahedron_face_normals()
    order = visit_order(normals)[:n_faces]
    first = still_s if first_still_s is None else first_still_s
    n_still = [round(first * rate_hz)] + [round(still_s * rate_hz)] * (len(order) - 1)
    n_turn = round(turn_s * rate_hz)
    quats: list[F64] = []
    gyrs: list[F64] = []
    faces: list[NDArray[np.int64]] = []
    q_prev: F64 | None = None
    for k, f in enumerate(order):
        q_face = quat_nb_resting_on(normals[f])
        if q_prev is not None:
            # relative rotation in the body frame: q_face = q_prev ⊗ dq
            dq = _quat_mul(q_prev * np.array([1.0, -1.0, -1.0, -1.0]), q_face)
            if dq[0] < 0:
                dq = -dq
            angle = 2.0 * math.atan2(float(np.linalg.norm(dq[1:])), float(dq[0]))
            axis = dq[1:] / max(float(np.linalg.norm(dq[1:])), 1e-15)
            x = (np.arange(1, n_turn + 1)) / n_turn  # the turn ends exactly on the face
            s = x**3 * (10.0 - 15.0 * x + 6.0 * x * x)  # smoothstep: zero rate at both ends
            ds = 30.0 * x**2 * (1.0 - x) ** 2 / turn_s
            half = 0.5 * angle * s
            step = np.column_stack([np.cos(half), np.sin(half)[:, None] * axis[None, :]])
            quats.append(_quat_mul(np.broadcast_to(q_prev, step.shape), step))
            gyrs.append((angle * ds)[:, None] * axis[None, :])
            faces.append(np.full(n_turn, -1, dtype=np.int64))
        m = n_still[k]
        quats.append(np.broadcast_to(q_face, (m, 4)).copy())
        gyrs.append(np.zeros((m, 3)))
        faces.append(np.full(m, f, dtype=np.int64))
        q_prev = q_face
    quat = np.concatenate(quats)
    mat_nb = _quat_to_mat(quat)
    acc_b = gravity_mps2 * mat_nb[:, 2, :]  # C_bn (0, 0, g) = g × (third row of C_nb)
    n = quat.shape[0]
    return IcosahedronTruth(
        t_s=np.arange(n) / rate_hz,
        quat_nb_wxyz=quat,
        acc_b_mps2=np.asarray(acc_b, dtype=np.float64),
        gyr_b_radps=np.concatenate(gyrs),
        face=np.concatenate(faces),
        order=order,
        rate_hz=rate_hz,
    )


def warm_up_c(t_s: F64, *, start_c: float = 22.0, end_c: float = 38.0, time_constant_s: float = 60.0) -> F64:
    """A unit warming up after power-on: ``end − (end − start) exp(−t/τ)``, °C, at times ``t_s`` (n,)."""
    t = np.asarray(t_s, dtype=np.float64)
    return np.asarray(end_c - (end_c - start_c) * np.exp(-t / time_constant_s), dtype=np.float64)


@dataclass(frozen=True, slots=True)
class Miscalibration:
    """Known sensor errors of an uncalibrated unit (the truth a calibration must recover).

    Accelerometer: ``y = K L u + (K_T u + b_T)(T − t_ref_c) + b`` (:mod:`footnav.pipeline.calibration.model`, θ order
    ``k(3), l_yx l_zx l_zy, b(3), k_T(3), b_T(3)``). Gyroscope: ``y = ω + b_g + b_gT (T − t_ref_c)``.

    Attributes
    ----------
    theta
        (15,) accelerometer parameters.
    gyr_bias_radps
        (3,) gyroscope bias at ``t_ref_c``, rad/s.
    gyr_bias_slope_radps_per_c
        (3,) its temperature slope.
    t_ref_c
        temperature at which the biases are given, °C.
    """

    theta: F64 = field(
        default_factory=lambda: np.array(
            [
                1.012,
                0.991,
                1.007,  # scale: +1.2 %, −0.9 %, +0.7 %
                math.radians(0.8),
                math.radians(-0.6),
                math.radians(1.1),  # misalignment, rad
                0.35,
                -0.25,
                0.45,  # bias, m/s² (36, −25, 46 mg)
                2e-4,
                -1.5e-4,
                1e-4,  # scale slope, 1/°C
                4e-3,
                -3e-3,
                5e-3,
            ]  # bias slope, m/s²/°C (0.4, −0.3, 0.5 mg/°C)
        )
    )
    gyr_bias_radps: F64 = field(default_factory=lambda: np.radians([0.8, -1.2, 0.5]))
    gyr_bias_slope_radps_per_c: F64 = field(default_factory=lambda: np.radians([0.01, 0.005, -0.008]))
    t_ref_c: float = 30.0

    def apply(self, acc_b_mps2: F64, gyr_b_radps: F64, temp_c: F64) -> tuple[F64, F64]:
        """Miscalibrated (n, 3) specific force and rate from the true ones at temperatures (n,)."""
        k = self.theta[0:3]
        low = np.eye(3)
        low[1, 0], low[2, 0], low[2, 1] = self.theta[3:6]
        kl = k[:, None] * low
        dt = (np.asarray(temp_c, dtype=np.float64) - self.t_ref_c)[:, None]
        u = np.asarray(acc_b_mps2, dtype=np.float64)
        acc = u @ kl.T + (u * self.theta[9:12] + self.theta[12:15]) * dt + self.theta[6:9]
        gyr = np.asarray(gyr_b_radps, dtype=np.float64) + self.gyr_bias_radps + dt * self.gyr_bias_slope_radps_per_c
        return np.asarray(acc, dtype=np.float64), np.asarray(gyr, dtype=np.float64)

    def gyr_bias_at(self, temp_c: float) -> F64:
        """(3,) gyroscope bias at ``temp_c``, rad/s."""
        return np.asarray(self.gyr_bias_radps + (temp_c - self.t_ref_c) * self.gyr_bias_slope_radps_per_c)

    def theta_at(self, t_ref_c: float) -> F64:
        """(15,) θ re-referenced to ``t_ref_c``: the same model written with ``T − t_ref_c``.

        ``K L + K_T d = K' L'`` with ``k' = k + k_T d`` and ``l'_ij = k_i l_ij / k'_i``; ``b' = b + b_T d``.
        """
        th = np.array(self.theta, dtype=np.float64)
        d = t_ref_c - self.t_ref_c
        k_new = th[0:3] + th[9:12] * d
        th[3] *= self.theta[1] / k_new[1]  # l_yx (row y)
        th[4] *= self.theta[2] / k_new[2]  # l_zx (row z)
        th[5] *= self.theta[2] / k_new[2]  # l_zy (row z)
        th[0:3] = k_new
        th[6:9] = th[6:9] + th[12:15] * d
        return th


def miscalibrated_signals(
    acc_b_mps2: F64,
    gyr_b_radps: F64,
    temp_c: F64,
    rate_hz: float,
    *,
    errors: Miscalibration | None = None,
    grade: str = "mpu6500x4",
    seed: int = 0,
) -> tuple[F64, F64]:
    """True signals -> what the miscalibrated unit measures: :class:`Miscalibration` + the grade's noise
    and in-run drift (its turn-on biases set to zero)."""
    errors = errors if errors is not None else Miscalibration()
    acc, gyr = errors.apply(acc_b_mps2, gyr_b_radps, temp_c)
    base = dataclasses.replace(IMU_GRADES[grade], acc_bias_sigma_mps2=0.0, gyr_bias_sigma_radps=0.0)
    acc_m, gyr_m, _ = corrupt(acc, gyr, rate_hz, base, seed)
    return acc_m, gyr_m
