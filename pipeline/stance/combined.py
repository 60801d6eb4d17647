"""The three-condition stance detector of the dual-IMU paper (Chen et al. 2022, section 3).

A sample k is still when all three hold (Jiménez, Seco, Prieto and Guevara, "A comparison of
pedestrian dead-reckoning algorithms using a low-cost MEMS IMU", IEEE WISP 2009, section III-A, whose
conditions and thresholds Chen et al. combine):

- C1, acceleration magnitude: ``acc_min ≤ |a_k| ≤ acc_max`` (9 and 11 m/s²);
- C2, acceleration variance: the standard deviation of |a| over the centred window of 2s + 1 samples,
  ``σ_k = sqrt(1/(2s+1) Σ_{q=k−s}^{k+s} (|a_q| − ā_k)²) < acc_std_max`` (3 m/s²; s = 15 samples at
  100 Hz: ``half_window_s`` = 0.15 s);
- C3, angular-rate magnitude: ``|ω_k| ≤ gyr_max`` (50 °/s);

then C1 ∧ C2 ∧ C3 is smoothed by a median filter over ``median_s`` (11 samples at 100 Hz). Moving
sums make it O(n) in time and memory. Unlike
footnav's streaming detectors (``footnav.pipeline.stance.detectors``) the windows are centred: this is a
whole-record detector, for comparing stance decisions offline (``footnav experiment dual-imu``, ``paper-3c``).
Windows are cut at the record's ends.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class CombinedDetectorParams:
    """Thresholds and windows (module docstring); SI units."""

    acc_min_mps2: float = 9.0
    acc_max_mps2: float = 11.0
    acc_std_max_mps2: float = 3.0
    gyr_max_radps: float = math.radians(50.0)
    half_window_s: float = 0.15
    median_s: float = 0.11


def _centred_mean(values: F64, half: int) -> F64:
    """Mean over the centred window of 2·half + 1 samples of each sample (the ends padded with the edge values)."""
    c = np.concatenate(([0.0], np.cumsum(np.pad(values, half, mode="edge"))))
    width = 2 * half + 1
    return np.asarray((c[width:] - c[:-width]) / width)


def combined_stance(
    acc_b_mps2: F64, gyr_b_radps: F64, rate_hz: float, params: CombinedDetectorParams | None = None
) -> NDArray[np.bool_]:
    """(n,) True where the foot is still, from specific force and angular rate (n, 3) at ``rate_hz``."""
    p = params or CombinedDetectorParams()
    acc_norm = np.linalg.norm(acc_b_mps2, axis=1)
    c1 = (acc_norm >= p.acc_min_mps2) & (acc_norm <= p.acc_max_mps2)
    half = max(1, round(p.half_window_s * rate_hz))
    var = _centred_mean(acc_norm**2, half) - _centred_mean(acc_norm, half) ** 2
    c2 = np.sqrt(np.maximum(var, 0.0)) < p.acc_std_max_mps2
    c3 = np.linalg.norm(gyr_b_radps, axis=1) <= p.gyr_max_radps
    still = c1 & c2 & c3
    half_median = round(p.median_s * rate_hz) // 2
    if half_median == 0:
        return still
    # the median of a window of booleans of odd length: the majority
    return np.asarray(_centred_mean(still.astype(np.float64), half_median) > 0.5)
