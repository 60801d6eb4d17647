"""Trajectory error metrics against ground truth or a known closed loop.

- ``armse_2d_pyshoe``: the PyShoe paper's ARMSE-2D (Wagstaff et al. 2019; ``utiasSTARS/pyshoe``,
  ``ins_tools/util.py`` ``align_plots`` and ``compute_error``): both tracks start at 0; the estimate
  is rotated about z so that its position at the first sample whose net horizontal displacement from
  the start reaches 0.8 m points the way the ground truth's does at that sample; the per-sample error
  is √(mean(dx², dy²)), i.e. the horizontal distance over √2; ARMSE-2D is its mean.
- ``ate``: absolute trajectory error after a 4-DoF alignment (yaw + translation, Horn/Umeyama
  restricted to rotations about z, since roll and pitch are observable from gravity), RMSE in 2D and
  3D, optionally testing the mirror image (for ground truth in a left-handed frame) and reporting it.
- ``loop_closure_error``: distance between the first and last position of a closed walk.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]

PYSHOE_ALIGN_DISTANCE_M = 0.8
PYSHOE_FALLBACK_INDEX = 300  # pyshoe's choice when the walk never gets 0.8 m from its start


def _rot_z(angle_rad: float) -> F64:
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def armse_2d_pyshoe(est_pos_m: F64, gt_pos_m: F64) -> float:
    """PyShoe ARMSE-2D of (n, 3) estimate against (n, 3) sample-aligned ground truth, m."""
    est = est_pos_m - est_pos_m[0]
    gt = gt_pos_m - gt_pos_m[0]
    d = np.hypot(est[:, 0], est[:, 1])
    hits = np.flatnonzero(d >= PYSHOE_ALIGN_DISTANCE_M)
    ind = int(hits[0]) if hits.size else min(PYSHOE_FALLBACK_INDEX, est.shape[0] - 1)
    a1 = math.atan2(est[ind, 1], est[ind, 0])
    a2 = math.atan2(gt[ind, 1], gt[ind, 0])
    rotated = est @ _rot_z(a2 - a1).T
    per_sample = np.sqrt(np.mean((rotated[:, :2] - gt[:, :2]) ** 2, axis=1))
    return float(per_sample.mean())


@dataclass(frozen=True)
class AteResult:
    """Absolute trajectory error after the best yaw + translation alignment.

    Attributes
    ----------
    rmse_2d_m, rmse_3d_m
        RMSE of horizontal and 3D position error.
    yaw_rad
        the rotation applied to the estimate.
    mirrored
        the estimate fitted better after mirroring y (a handedness mismatch).
    """

    rmse_2d_m: float
    rmse_3d_m: float
    yaw_rad: float
    mirrored: bool


def _align_4dof(est: F64, gt: F64) -> tuple[F64, float]:
    """Estimate rotated about z and translated to best fit ``gt`` in the least-squares sense."""
    mu_e, mu_g = est.mean(axis=0), gt.mean(axis=0)
    e, g = est - mu_e, gt - mu_g
    # maximise Σ gᵀ R(ψ) e over ψ: tan ψ = Σ(e_x g_y − e_y g_x) / Σ(e_x g_x + e_y g_y)
    yaw = math.atan2(
        float(np.sum(e[:, 0] * g[:, 1] - e[:, 1] * g[:, 0])),
        float(np.sum(e[:, 0] * g[:, 0] + e[:, 1] * g[:, 1])),
    )
    aligned = e @ _rot_z(yaw).T + mu_g
    return aligned, yaw


def ate(est_pos_m: F64, gt_pos_m: F64, *, mirror_test: bool = True) -> AteResult:
    """ATE of (n, 3) estimate against (n, 3) sample-aligned ground truth."""
    candidates = [(False, est_pos_m)]
    if mirror_test:
        candidates.append((True, est_pos_m * np.array([1.0, -1.0, 1.0])))
    best: AteResult | None = None
    for mirrored, est in candidates:
        aligned, yaw = _align_4dof(est, gt_pos_m)
        err = aligned - gt_pos_m
        res = AteResult(
            rmse_2d_m=float(np.sqrt(np.mean(np.sum(err[:, :2] ** 2, axis=1)))),
            rmse_3d_m=float(np.sqrt(np.mean(np.sum(err**2, axis=1)))),
            yaw_rad=yaw,
            mirrored=mirrored,
        )
        if best is None or res.rmse_3d_m < best.rmse_3d_m:
            best = res
    assert best is not None
    return best


def path_length_m(pos_m: F64) -> float:
    """Length of a (n, 3) polyline, m."""
    return float(np.linalg.norm(np.diff(pos_m, axis=0), axis=1).sum())


def loop_closure_error(pos_m: F64) -> tuple[float, float]:
    """(3D, horizontal) distance between the first and last position of a closed walk, m."""
    d = pos_m[-1] - pos_m[0]
    return float(np.linalg.norm(d)), float(np.hypot(d[0], d[1]))
