"""Steps from a navigation solution: OpenShoe's stepwise dead-reckoning output, computed on the host.

OpenShoe's firmware emits, at each reset near the end of a stance, the displacement since the
previous reset in the frame whose heading was zeroed then, the heading change, and the 4×4
covariance of (x, y, z, ψ) accumulated since the reset, after which it zeroes position, heading and
their covariance (``warrenwhipple/3dpen:nav_eq.c``; protocol-openshoe.md §5.1). Here the epochs are
the last sample of every stance that lasts at least ``min_stance_s`` and comes at least
``min_interval_s`` after the previous epoch (any detected stance by default: a running stance lasts
5-25 ms, and the detector's debounce already drops a swing's brief dips; with 50 ms the PyShoe
running trial's 0.73 s strides came out as 14 steps of 1.9 s instead of 34); the increment is
rotated into the previous epoch's heading frame, and its covariance is the growth of the (x, y, z, ψ)
covariance block between the two epochs, rotated the same way (the firmware's reset makes its dP the
same growth; like the firmware, this neglects the cross-covariance between consecutive epochs).
Increments under 5 cm are marked as standing, not steps, as the vendor's host apps do. ``footnav
export --steps`` writes them (``footnav.app.commands.export.STEP_COLUMNS``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from footnav.pipeline.navigation.quaternion import yaw_of
from numpy.typing import NDArray

F64 = NDArray[np.float64]

MIN_STEP_M = 0.05  # GT Silicon's apps count a step only from 5 cm (protocol-openshoe.md §9)


@dataclass(frozen=True, slots=True)
class Steps:
    """Per-step output, m steps.

    Attributes
    ----------
    t_s
        (m,) time of each epoch (end of stance), s.
    index
        (m,) sample index of each epoch in the navigation solution.
    dpos_step_m
        (m, 3) displacement since the previous epoch in the previous epoch's heading frame (x forward along that
        heading, z up), m.
    dyaw_rad
        (m,) heading change since the previous epoch, wrapped to (−π, π].
    cov
        (m, 4, 4) covariance of (dx, dy, dz, dψ), m² and rad².
    is_step
        (m,) displacement of at least 5 cm (False: standing still).
    pos_n_m
        (m, 3) position at the epoch.
    yaw_rad
        (m,) heading at the epoch.
    """

    t_s: F64
    index: NDArray[np.int64]
    dpos_step_m: F64
    dyaw_rad: F64
    cov: F64
    is_step: NDArray[np.bool_]
    pos_n_m: F64
    yaw_rad: F64

    def __len__(self) -> int:
        return int(self.t_s.shape[0])


def _rot2(yaw: F64) -> F64:
    c, s = np.cos(yaw), np.sin(yaw)
    return np.stack([np.stack([c, -s], axis=-1), np.stack([s, c], axis=-1)], axis=-2)


def step_epochs(
    t_s: F64, stance: NDArray[np.bool_], min_stance_s: float = 0.0, min_interval_s: float = 0.4
) -> NDArray[np.int64]:
    """Indices of the last sample of each qualifying stance (see the module docstring)."""
    s = stance.astype(np.int8)
    starts = np.flatnonzero(np.diff(np.concatenate([[0], s])) == 1)
    ends = np.flatnonzero(np.diff(np.concatenate([s, [0]])) == -1)
    epochs: list[int] = [0]
    for a, b in zip(starts, ends, strict=True):
        if t_s[b] - t_s[a] >= min_stance_s and t_s[b] - t_s[epochs[-1]] >= min_interval_s:
            epochs.append(int(b))
    return np.asarray(epochs, dtype=np.int64)


def segment_steps(t_s: F64, pos_n_m: F64, quat_nb_wxyz: F64, stance: NDArray[np.bool_], cov_pos_yaw: F64) -> Steps:
    """Steps of a navigation solution.

    Parameters
    ----------
    t_s
        (n,) time, s.
    pos_n_m
        (n, 3).
    quat_nb_wxyz
        (n, 4).
    stance
        (n,).
    cov_pos_yaw
        (n, 4, 4) covariance of (x, y, z, ψ) per sample.

    Returns
    -------
    Steps
        One entry per epoch after the first (the first epoch is the start of the solution).
    """
    idx = step_epochs(t_s, stance)
    yaw = yaw_of(quat_nb_wxyz[idx])
    pos = pos_n_m[idx]
    prev, cur = slice(0, -1), slice(1, None)
    to_step = _rot2(-yaw[prev])  # nav -> previous epoch's heading frame
    dxy = np.einsum("mij,mj->mi", to_step, pos[cur, :2] - pos[prev, :2])
    dpos = np.column_stack([dxy, pos[cur, 2] - pos[prev, 2]])
    dyaw = np.angle(np.exp(1j * (yaw[cur] - yaw[prev])))
    growth = cov_pos_yaw[idx[cur]] - cov_pos_yaw[idx[prev]]
    jac = np.zeros((len(idx) - 1, 4, 4))
    jac[:, :2, :2] = to_step
    jac[:, 2, 2] = jac[:, 3, 3] = 1.0
    cov = jac @ growth @ np.swapaxes(jac, 1, 2)
    cov = 0.5 * (cov + np.swapaxes(cov, 1, 2))
    w, v = np.linalg.eigh(cov)  # the difference of two covariances may lose definiteness slightly
    cov = v @ (np.maximum(w, 0.0)[..., None] * np.swapaxes(v, 1, 2))
    return Steps(
        t_s=t_s[idx[cur]],
        index=idx[cur],
        dpos_step_m=dpos,
        dyaw_rad=dyaw,
        cov=cov,
        is_step=np.linalg.norm(dpos, axis=1) >= MIN_STEP_M,
        pos_n_m=pos[cur],
        yaw_rad=yaw[cur],
    )


def accumulate_steps(steps: Steps) -> F64:
    """Positions (m + 1, 3) from step increments, as OpenShoe's host apps do: rotate each increment
    by the accumulated heading, add it, then add the heading change (protocol-openshoe.md §5.1)."""
    out = np.zeros((len(steps) + 1, 3))
    yaw = 0.0
    for k in range(len(steps)):
        c, s = np.cos(yaw), np.sin(yaw)
        dx, dy, dz = steps.dpos_step_m[k]
        out[k + 1] = out[k] + [c * dx - s * dy, s * dx + c * dy, dz]
        yaw += steps.dyaw_rad[k]
    return out
