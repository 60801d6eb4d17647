"""Initial alignment from a stationary period: roll, pitch, gravity magnitude, gyro bias.

At rest the accelerometer measures the reaction to gravity, f_b = C_bn [0, 0, g] (z up), so
roll = atan2(f_y, f_z) and pitch = atan2(−f_x, √(f_y² + f_z²)) (Groves, "Principles of GNSS,
Inertial, and Multisensor Integrated Navigation Systems", 2nd ed. 2013, eq. 5.101). Yaw is not
observable from gravity and is set to 0: the navigation frame's x axis is the unit's initial heading.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from footnav.pipeline.errors import InputFormatError
from footnav.pipeline.navigation.quaternion import quat_from_euler_zyx
from numpy.typing import NDArray

F64 = NDArray[np.float64]

G_MIN_MPS2, G_MAX_MPS2 = 9.0, 10.6  # plausible |f| at rest on Earth, allowing for scale errors


@dataclass(frozen=True, slots=True)
class Alignment:
    """Result of the coarse alignment.

    Attributes
    ----------
    quat_nb_wxyz
        (4,) initial attitude (yaw 0).
    gravity_mps2
        |mean specific force| over the still window (gravity plus the accelerometer's bias along it).
    gyr_bias_radps
        (3,) mean angular rate over the window (the foot is still).
    """

    quat_nb_wxyz: F64
    gravity_mps2: float
    gyr_bias_radps: F64

    def gravity_for(self, configured_mps2: float) -> float:
        """The g a filter navigates with: the configured local gravity, or, when that is 0 or less,
        this window's |f̄| (``footnav.pipeline.navigation.navigator.NavConfig.gravity_mps2``)."""
        return configured_mps2 if configured_mps2 > 0.0 else self.gravity_mps2


def align_from_still(acc_b_mps2: F64, gyr_b_radps: F64) -> Alignment:
    """Coarse alignment from (n, 3) samples of a still unit.

    Raises
    ------
    InputFormatError
        the mean specific force is not about 1 g (wrong units or not at rest).
    """
    f = acc_b_mps2.mean(axis=0)
    g = float(np.linalg.norm(f))
    if not G_MIN_MPS2 <= g <= G_MAX_MPS2:
        raise InputFormatError(
            f"at rest the accelerometer should read about 9.8 m/s², but it reads {g:.3f}; "
            "are the samples in m/s² (not g) and is the unit still at the start?"
        )
    roll = math.atan2(f[1], f[2])
    pitch = math.atan2(-f[0], math.hypot(f[1], f[2]))
    return Alignment(quat_from_euler_zyx(roll, pitch, 0.0), g, gyr_b_radps.mean(axis=0))
