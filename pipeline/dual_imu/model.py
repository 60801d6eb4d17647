"""What the dual-IMU filters share: sample validity (finite, not saturated), the still window they
align on, vectorised rotation matrices, and the plain-language report of unusable IMU samples."""

from __future__ import annotations

import math

import numpy as np
from footnav.pipeline.jit import njit
from numpy.typing import NDArray

F64 = NDArray[np.float64]

ACC_FULL_SCALE_MPS2 = 9.80665 / 2048.0 * 32766.5
"""Half an LSB below the largest reading at ±16 g (2048 LSB/g, int16; protocol-openshoe.md 5.4): a
reading this large is the register at its limit, i.e. saturated."""
GYR_FULL_SCALE_RADPS = math.radians(1.0) / 16.4 * 32766.5
"""Likewise for the gyroscope at ±2000 °/s (16.4 LSB per °/s)."""


@njit(cache=True, nogil=True, error_model="numpy")
def sample_ok(f: F64, w: F64, acc_fs: float, gyr_fs: float) -> bool:  # pragma: no cover - compiled
    """One IMU's sample ``f`` (3,), ``w`` (3,) is finite and below full scale on every axis."""
    for r in range(3):
        if not (math.isfinite(f[r]) and math.isfinite(w[r])):
            return False
        if abs(f[r]) >= acc_fs or abs(w[r]) >= gyr_fs:
            return False
    return True


def still_window(acc_b_mps2: F64, gyr_b_radps: F64, rate_hz: float, align_s: float) -> slice:
    """The first ``align_s`` of the record, checked to be still (both IMUs' rates under 0.3 rad/s).

    Raises
    ------
    ValueError
        the record is shorter, or the unit moves or an IMU is not finite in it.
    """
    need = max(2, round(align_s * rate_hz))
    if acc_b_mps2.shape[0] < need:
        raise ValueError(f"need at least {align_s} s of still data at the start for the alignment")
    window = slice(0, need)
    rate = np.linalg.norm(gyr_b_radps[window], axis=-1)
    if not (np.all(np.nan_to_num(rate, nan=np.inf) < 0.3) and np.all(np.isfinite(acc_b_mps2[window]))):
        raise ValueError(
            f"the dual-IMU filters align on the first {align_s} s, which must be still (and finite on both IMUs)"
        )
    return window


def quat_to_mats(quat_wxyz: F64) -> F64:
    """(n, 4) scalar-first unit quaternions -> (n, 3, 3) body-to-navigation rotation matrices."""
    w, x, y, z = (quat_wxyz[:, i] for i in range(4))
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1),
        ],
        axis=1,
    )


def fault_report(imu_ok: NDArray[np.bool_], t_s: F64) -> list[str]:
    """Plain-language lines on the samples each IMU could not give (empty when both always could).

    Parameters
    ----------
    imu_ok : ndarray of bool, shape (n, 2)
        Whether IMU 1 and IMU 2 gave a usable sample (finite, below full scale).
    t_s : ndarray, shape (n,)
        Sample times, s.
    """
    lines: list[str] = []
    ok = np.asarray(imu_ok, dtype=bool)
    for i, other in ((0, 1), (1, 0)):
        bad = ~ok[:, i]
        if not bad.any():
            continue
        edges = np.flatnonzero(np.diff(np.concatenate([[0], bad.astype(np.int8), [0]])))
        spans = list(zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True))
        alone = int(np.count_nonzero(bad & ok[:, other]))
        first, last = spans[0], spans[-1]
        lines.append(
            f"IMU {i + 1} unusable (not finite or at full scale) for {int(bad.sum())} samples in {len(spans)} "
            f"span(s), {t_s[first[0]]:.2f}-{t_s[last[1] - 1]:.2f} s; navigated on IMU {other + 1} alone for "
            f"{alone} of them"
        )
    both = int(np.count_nonzero(~ok.any(axis=1)))
    if both:
        lines.append(f"both IMUs unusable for {both} samples: motion held, uncertainty grown")
    return lines
