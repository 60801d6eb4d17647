"""Unit profiles: the sensor noise and bias parameters the filter assumes, per kind of unit.

The filter never estimates these from the recording; they come from datasheets and the literature,
so one configuration serves every recording of a kind of unit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

DEG = math.pi / 180.0
G0_MPS2 = 9.80665  # standard gravity (CGPM 1901); the navigator's default gravity (NavConfig.gravity_mps2)


@dataclass(frozen=True, slots=True)
class UnitProfile:
    """Noise model of one kind of unit, continuous-time densities in SI units.

    Attributes
    ----------
    name
        profile key.
    acc_noise_mps2_rthz
        accelerometer white noise density (velocity random walk), m/s²/√Hz.
    gyr_noise_radps_rthz
        gyroscope white noise density (angle random walk), rad/s/√Hz.
    acc_bias_rw_mps3_rthz
        accelerometer bias random walk density, m/s³/√Hz.
    gyr_bias_rw_radps2_rthz
        gyroscope bias random walk density, rad/s²/√Hz.
    acc_bias_init_mps2
        1σ turn-on accelerometer bias left after calibration, m/s².
    gyr_bias_init_radps
        1σ turn-on gyroscope bias left after calibration, rad/s.
    motion_acc_mps2
        extra process noise on specific force covering vibration, quantisation and unmodelled high-frequency foot
        dynamics (1σ per sample), m/s². Foot-mounted filters inflate this well above the sensor noise (OpenShoe uses
        0.7 m/s², pyshoe 0.5); here part of that moves into the signal-proportional term below.
    motion_gyr_radps
        likewise for angular rate, rad/s (OpenShoe 0.3°/s, pyshoe 0.5°/s).
    zupt_sigma_mps
        zero-velocity pseudo-measurement 1σ, m/s (OpenShoe 0.1, pyshoe 0.01).
    zaru_sigma_radps
        zero-angular-rate pseudo-measurement 1σ during stance, rad/s: the residual rotation of a standing foot, added to
        the sensor noise to weigh the update (its χ² gate tests against the sensor noise alone,
        ``footnav.pipeline.navigation.eskf``).
    acc_scale_error, gyr_scale_error
        1σ of the error proportional to the signal (scale factor, cross-axis sensitivity, acc/gyro timing), as a
        fraction; process noise grows by it.
    roll_lever_m
        distance from the IMU to the point the foot rolls about during stance (heel, toe), m; the ZUPT noise grows by
        this times the angular rate (see ``footnav.pipeline.navigation.eskf``).
    zupt_vertical_sigma_mps
        σ_T, the extra 1σ of the ZUPT's vertical component where the detector's statistic reaches its threshold; it
        scales as √(T/γ) below it (see ``footnav.pipeline.navigation.eskf``: the heel pad and sole still compress as
        stance begins). 0 gives the hard update (docs/design/estimator.md).
    """

    name: str
    acc_noise_mps2_rthz: float
    gyr_noise_radps_rthz: float
    acc_bias_rw_mps3_rthz: float
    gyr_bias_rw_radps2_rthz: float
    acc_bias_init_mps2: float
    gyr_bias_init_radps: float
    motion_acc_mps2: float = 0.2
    motion_gyr_radps: float = 0.5 * DEG
    zupt_sigma_mps: float = 0.01
    zaru_sigma_radps: float = 0.5 * DEG
    roll_lever_m: float = 0.1  # about half a shoe length
    zupt_vertical_sigma_mps: float = 0.2
    acc_scale_error: float = 0.02  # MEMS scale + cross-axis residuals of 0.5-2 % plus acc/gyro skew
    gyr_scale_error: float = 0.01


PROFILES: dict[str, UnitProfile] = {
    # Four MPU-6500 averaged (GT Silicon MIMU22BL / Oblu). MPU-6500 datasheet (InvenSense
    # PS-MPU-6500A-01 rev 1.1): gyro 0.01 °/s/√Hz, accel 300 µg/√Hz; averaging four halves both.
    # Turn-on residuals after the factory calibration are assumptions (0.1 °/s, 5 mg).
    "mpu6500x4": UnitProfile(
        name="mpu6500x4",
        acc_noise_mps2_rthz=0.5 * 300e-6 * G0_MPS2,
        gyr_noise_radps_rthz=0.5 * 0.01 * DEG,
        acc_bias_rw_mps3_rthz=1e-4,
        gyr_bias_rw_radps2_rthz=1e-5,
        acc_bias_init_mps2=5e-3 * G0_MPS2,
        gyr_bias_init_radps=0.1 * DEG,
    ),
    # OpenShoe: ADIS16367 (Analog Devices datasheet rev. B): ARW 2 °/√h, in-run bias 0.007 °/s,
    # VRW 0.2 m/s/√h, accel in-run bias 0.1 mg.
    "adis16367": UnitProfile(
        name="adis16367",
        acc_noise_mps2_rthz=0.2 / 60.0,
        gyr_noise_radps_rthz=2.0 * DEG / 60.0,
        acc_bias_rw_mps3_rthz=1e-5,
        gyr_bias_rw_radps2_rthz=1e-6,
        acc_bias_init_mps2=3e-3 * G0_MPS2,
        gyr_bias_init_radps=0.05 * DEG,
    ),
    # MicroStrain 3DM-GX2 / GX3-25 (LORD datasheets): gyro noise 0.03 °/s/√Hz (GX3-25),
    # accel 80 µg/√Hz; bias stability 18 °/h, 0.04 mg.
    "gx3": UnitProfile(
        name="gx3",
        acc_noise_mps2_rthz=80e-6 * G0_MPS2,
        gyr_noise_radps_rthz=0.03 * DEG,
        acc_bias_rw_mps3_rthz=1e-5,
        gyr_bias_rw_radps2_rthz=1e-6,
        acc_bias_init_mps2=2e-3 * G0_MPS2,
        gyr_bias_init_radps=0.1 * DEG,
    ),
    # A single consumer MEMS part with a user calibration (e.g. ICM-20948 datasheet DS-000189:
    # gyro 0.015 °/s/√Hz, accel 230 µg/√Hz), residual biases 0.3 °/s and 10 mg assumed.
    "generic": UnitProfile(
        name="generic",
        acc_noise_mps2_rthz=230e-6 * G0_MPS2,
        gyr_noise_radps_rthz=0.015 * DEG,
        acc_bias_rw_mps3_rthz=2e-4,
        gyr_bias_rw_radps2_rthz=2e-5,
        acc_bias_init_mps2=10e-3 * G0_MPS2,
        gyr_bias_init_radps=0.3 * DEG,
    ),
}


def get_profile(name: str) -> UnitProfile:
    """The profile called ``name``; raises ``KeyError`` listing the known names."""
    try:
        return PROFILES[name]
    except KeyError:
        raise KeyError(f"unknown unit profile {name!r}; known: {', '.join(sorted(PROFILES))}") from None
