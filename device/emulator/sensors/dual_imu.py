"""A dual-IMU board on the foot: two IMUs a fixed lever arm apart, rigid-body motion, independent errors.

IMU 1 moves as :func:`.gait.simulate_walk` says. IMU 2 sits at ``lever_b_m`` (m, IMU 1's body axes;
the two IMUs' axes are parallel) on the same rigid board, so, with ``R = C_nb`` and ``ω`` the body
rate in body axes (Chen et al. 2022, the rigid-body relations; Groves 2013 §2.5 for the kinematics)::

    ω₂ = ω₁                                   (equal angular rate)
    p₂ = p₁ + R m                             (position)
    v₂ = v₁ + R (ω × m)                       (velocity)
    f₂ = f₁ + ω̇ × m + ω × (ω × m)             (specific force, body axes)

The angular acceleration ``ω̇`` is the fourth-order central difference of the closed-form body rate
(``(−ω_{k+2} + 8ω_{k+1} − 8ω_{k−1} + ω_{k−2}) / 12Δt``, error ``Δt⁴ ω⁽⁵⁾ / 30``); the gait's rate is a
polynomial per phase, smooth across phase changes, so this is exact to well under the sensor noise
(``tests/test_dual_imu_emulator.py`` strapdown-integrates IMU 2's ideal signals against p₁ + R m).

Each IMU then gets its own errors from :func:`.imu_errors.corrupt` with independent seeds (default
grade ``icm20948``: TDK ICM-20948 datasheet DS-000189 noise densities, see :mod:`.imu_errors`).

References
----------
- Chen, Lu, Xu, Liu and Bi (2022), dual-IMU foot-mounted pedestrian navigation with rigid-body
  constraints, *Sensors and Materials* (the board, the lever arm and the relations above).
- Groves, P. D. (2013). *Principles of GNSS, Inertial, and Multisensor Integrated Navigation
  Systems*, 2nd ed., Artech House, §2.5 (motion of a point on a rotating body).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

import numpy as np
from footnav.device.emulator.motion import paths
from footnav.device.emulator.motion.gait import GaitTruth, simulate_walk
from footnav.device.emulator.sensors.imu_errors import FullScale, ImuErrorsApplied, ImuGrade, corrupt
from footnav.pipeline.dual_imu.model import quat_to_mats
from footnav.pipeline.dual_imu.navigator import DEFAULT_LEVER_B_M as DEFAULT_BOARD_LEVER_B_M
from numpy.typing import NDArray

F64 = NDArray[np.float64]

DEFAULT_LEVER_B_M: Final = DEFAULT_BOARD_LEVER_B_M
"""IMU 2's position in IMU 1's body axes on the emulated board, m: the navigator's default."""

DEFAULT_GRADE: Final = "icm20948"


def angular_acceleration(gyr_b_radps: F64, rate_hz: float) -> F64:
    """(n, 3) body angular acceleration, rad/s², by a fourth-order central difference.

    The two samples at each end use second-order one-sided differences (the walk is still there).
    """
    w = np.asarray(gyr_b_radps, dtype=np.float64)
    out = np.zeros_like(w)
    n = w.shape[0]
    if n >= 5:
        out[2:-2] = (-w[4:] + 8.0 * w[3:-1] - 8.0 * w[1:-3] + w[:-4]) * (rate_hz / 12.0)
    if n >= 3:
        edge = np.gradient(w, 1.0 / rate_hz, axis=0, edge_order=2)
        out[:2], out[-2:] = edge[:2], edge[-2:]
    return out


@dataclass(frozen=True, slots=True)
class DualImuTruth:
    """True motion of both IMUs of a rigid board.

    Attributes
    ----------
    imu1
        the gait truth of IMU 1 (the reference point).
    lever_b_m
        (3,) IMU 2's position in IMU 1's body axes, m.
    pos2_n_m
        (n, 3) IMU 2's position, navigation frame, m.
    vel2_n_mps
        (n, 3) IMU 2's velocity, m/s.
    acc_b_mps2
        (n, 2, 3) true specific force of IMU 1 and IMU 2, body axes, m/s².
    gyr_b_radps
        (n, 2, 3) true angular rate of IMU 1 and IMU 2 (equal), rad/s.
    angacc_b_radps2
        (n, 3) body angular acceleration, rad/s².
    """

    imu1: GaitTruth
    lever_b_m: F64
    pos2_n_m: F64
    vel2_n_mps: F64
    acc_b_mps2: F64
    gyr_b_radps: F64
    angacc_b_radps2: F64


def rigid_board(truth: GaitTruth, lever_b_m: F64 | tuple[float, float, float] = DEFAULT_LEVER_B_M) -> DualImuTruth:
    """IMU 2's true motion and signals from IMU 1's (module docstring)."""
    m = np.asarray(lever_b_m, dtype=np.float64).reshape(3)
    w = truth.gyr_b_radps
    wdot = angular_acceleration(w, truth.rate_hz)
    R = quat_to_mats(truth.quat_nb_wxyz)
    w_x_m = np.cross(w, m)
    acc2 = truth.acc_b_mps2 + np.cross(wdot, m) + np.cross(w, w_x_m)
    pos2 = truth.pos_n_m + R @ m
    vel2 = truth.vel_n_mps + np.einsum("nij,nj->ni", R, w_x_m)
    return DualImuTruth(
        imu1=truth,
        lever_b_m=m,
        pos2_n_m=pos2,
        vel2_n_mps=vel2,
        acc_b_mps2=np.stack([truth.acc_b_mps2, acc2], axis=1),
        gyr_b_radps=np.stack([w, w], axis=1),
        angacc_b_radps2=wdot,
    )


@dataclass(frozen=True, slots=True)
class DualImuRecording:
    """A simulated dual-IMU walk: truth and what the two IMUs measure.

    Attributes
    ----------
    truth
        the rigid-board truth.
    acc_b_mps2
        (n, 2, 3) measured specific force, IMU 1 then IMU 2, m/s².
    gyr_b_radps
        (n, 2, 3) measured angular rate, rad/s.
    errors
        the errors added to IMU 1 and IMU 2.
    path
        course name.
    seed
        the seed everything was drawn from.
    """

    truth: DualImuTruth
    acc_b_mps2: F64
    gyr_b_radps: F64
    errors: tuple[ImuErrorsApplied, ImuErrorsApplied]
    path: str
    seed: int

    @property
    def t_s(self) -> F64:
        """(n,) sample times, s."""
        return self.truth.imu1.t_s

    @property
    def rate_hz(self) -> float:
        """Sample rate, Hz."""
        return self.truth.imu1.rate_hz


def one_lap_duration_s(path: str, speed_mps: float, initial_still_s: float) -> tuple[int, float]:
    """Strides of one lap of a closed course and a record length that surely holds them, s."""
    period_s = paths.stride_period_s(speed_mps)
    feet = paths.footholds(path, 1, speed_mps * period_s)
    n = feet.lap_strides or 1
    slowest_s = max(period_s, paths.STAIR_STRIDE_PERIOD_S) * 1.05
    return n, initial_still_s + n * slowest_s + 2.0


def simulate_dual_imu(
    path: str,
    *,
    seed: int = 0,
    lever_b_m: F64 | tuple[float, float, float] = DEFAULT_LEVER_B_M,
    grade: ImuGrade | str = DEFAULT_GRADE,
    rate_hz: float = 1000.0,
    speed_mps: float = 1.4,
    initial_still_s: float = 3.0,
    laps: int = 1,
    axes: str = "none",
    full_scale: FullScale | None = None,
) -> DualImuRecording:
    """Walk ``laps`` laps of a closed course with a dual-IMU board (errors independent per IMU).

    Parameters
    ----------
    path : str
        A closed course of :data:`.paths.PATHS` (``rectangle``, ``stairs``, ``figure8``).
    seed : int
        Seeds the gait variation and both IMUs' errors (three independent streams).
    lever_b_m : array_like, shape (3,)
        IMU 2's position in IMU 1's axes, m.
    grade : ImuGrade or str
        Error grade of both IMUs (drawn independently).
    axes : str
        Scale-factor and cross-axis errors of both IMUs (a key of ``imu_errors.AXIS_ERRORS``; drawn
        independently).
    full_scale : FullScale or None
        Both IMUs' output range and ADC (None: unbounded, unquantised).
    """
    n_lap, lap_s = one_lap_duration_s(path, speed_mps, initial_still_s)
    duration_s = initial_still_s + laps * (lap_s - initial_still_s)
    gait_seed, seed1, seed2 = (int(s.generate_state(1)[0]) for s in np.random.SeedSequence(seed).spawn(3))
    truth = simulate_walk(
        path,
        duration_s,
        rate_hz,
        speed_mps,
        seed=gait_seed,
        initial_still_s=initial_still_s,
        max_strides=n_lap * laps,
    )
    if truth.n_strides != n_lap * laps:
        raise AssertionError(f"walked {truth.n_strides} strides, wanted {n_lap * laps}")  # pragma: no cover
    board = rigid_board(truth, lever_b_m)
    acc = np.empty_like(board.acc_b_mps2)
    gyr = np.empty_like(board.gyr_b_radps)
    errs = []
    for i, s in enumerate((seed1, seed2)):
        acc[:, i], gyr[:, i], applied = corrupt(
            board.acc_b_mps2[:, i], board.gyr_b_radps[:, i], rate_hz, grade, s, axes=axes, full_scale=full_scale
        )
        errs.append(applied)
    return DualImuRecording(board, acc, gyr, (errs[0], errs[1]), path, seed)
