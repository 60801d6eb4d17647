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


def quiet_samples(
    acc_b_mps2: F64, gyr_b_radps: F64, window: int, max_rate_radps: float, max_acc_dev_mps2: float
) -> NDArray[np.bool_]:
    """The samples quiet enough to align on (n,): |ω| below ``max_rate_radps`` and | |f| − mean |f| |
    below ``max_acc_dev_mps2``, the mean over the centred window of ``window`` samples (normalised at
    the ends, where the window is cut short); ``acc_b_mps2`` and ``gyr_b_radps`` (n, 3), m/s² and rad/s."""
    norm_f = np.linalg.norm(acc_b_mps2, axis=1)
    rate = np.linalg.norm(gyr_b_radps, axis=1)
    kernel = np.ones(window) / window
    mean_f = np.convolve(norm_f, kernel, mode="same") / np.convolve(np.ones_like(norm_f), kernel, mode="same")
    with np.errstate(invalid="ignore"):
        quiet: NDArray[np.bool_] = (rate < max_rate_radps) & (np.abs(norm_f - mean_f) < max_acc_dev_mps2)
    return quiet


def first_quiet_run(
    acc_b_mps2: F64,
    gyr_b_radps: F64,
    window: int,
    max_rate_radps: float,
    max_acc_dev_mps2: float,
    *,
    complete: bool = False,
) -> int:
    """Index of the first run of ``window`` samples :func:`quiet_samples` finds quiet, or −1.

    The search runs on prefixes of 8, 16, 32 ... windows. A sample's flag depends only on the samples
    of the window centred on it, each summed in the same order (``numpy.convolve`` takes one dot product
    per output), so on a prefix every flag whose window lies inside it is the whole recording's, bit for
    bit: a walk that starts still is decided on its first seconds, not by an O(n · window) convolution
    of the whole recording, and a run found there is the first of the whole. The last (window − 1) // 2
    flags of the samples given are not used either, unless they are the whole recording (``complete``):
    in a stream they change with the samples still to come, and leaving them out makes the answer the
    same however the stream is cut into batches.
    """
    n = acc_b_mps2.shape[0]
    if n < window:  # (``numpy.convolve`` would return ``window`` values)
        return -1
    length = min(n, 8 * window)
    while True:
        quiet = quiet_samples(acc_b_mps2[:length], gyr_b_radps[:length], window, max_rate_radps, max_acc_dev_mps2)
        start = _first_run(quiet if complete and length == n else quiet[: length - (window - 1) // 2], window)
        if start >= 0 or length == n:
            return start
        length = min(n, 2 * length)


def _first_run(mask: NDArray[np.bool_], length: int) -> int:
    """Index of the first run of at least ``length`` True values in ``mask``, or −1."""
    if mask.size < length:
        return -1
    # run[i] = Σ mask[i:i+length], exactly (integer prefix sums: O(n), not O(n · length))
    csum = np.concatenate([[0], np.cumsum(mask, dtype=np.int64)])
    run = csum[length:] - csum[:-length]
    hits = np.flatnonzero(run == length)
    return int(hits[0]) if hits.size else -1
