"""Every sample of a whole recording navigated: the lead-in before the first still period, backwards in time.

The navigator aligns on the first still period and navigates forward from it; a recording that starts in
motion has a *lead-in* before it (``NavStats.samples_before_alignment``). Offline the whole recording is
known, so the lead-in is navigated backwards from that still period by the same filter, unchanged, fed
the samples from the end of the still period down to the first in reversed time.

Time reversal. With τ = t_E − t, the same motion run backwards has position p̃(τ) = p(t), attitude
C̃ⁿ_b(τ) = Cⁿ_b(t), velocity ṽ = dp̃/dτ = −v, and, from Ċⁿ_b = Cⁿ_b [ω]× (Groves, "Principles of GNSS,
Inertial, and Multisensor Integrated Navigation Systems", 2nd ed. 2013, ch. 2, without the Earth's
rotation), dC̃ⁿ_b/dτ = C̃ⁿ_b [−ω]×: the angular rate is negated, ω̃ = −ω. The acceleration
d²p̃/dτ² = a is unchanged, and so is the specific force f = C^b_n (a − g). A gyroscope reading
ω + b_g + w reversed reads ω̃ − b_g − w: its bias is negated and its white noise keeps its statistics;
the accelerometer's bias is unchanged. A still period stays still, a stance a stance, so the detector,
the alignment, the zero-velocity and zero-rate updates and the stance levels apply as they are, and
the filter's noise model, parameters and gates hold without retuning.

The backward run aligns on the same still period (its samples, the end of the quiet run first) and
navigates to the first sample, meeting the lead-in's stances on the way. Its frame has the forward
one's up axis (both level with gravity) but its own origin and heading, so it is moved onto the
forward run where they meet, at the forward run's first sample s: with ψ the heading difference of
the two attitudes there (the best rotation about z of C_f C_bᵀ) and R = R_z(ψ),

    p_k = R (p̃_k − p̃_s) + p_s,   v_k = −R ṽ_k,   C_k = R C̃_k,   P_k = T P̃_k Tᵀ, T = diag(R, 1)

for k < s, with P the covariance of (x, y, z, ψ). That covariance is the backward filter's: it grows
away from the still period where the frame is defined, as the forward run's does after it. The causal
backward run conditions each lead-in estimate on the samples from it to the end of the still period;
the smoothers run on the reversed samples as on the forward ones. The forward estimates are those of
the run without the lead-in, bit for bit. A live session cannot see the samples it has not had and
still counts the lead-in as not navigated. Why this rather than a forward pass from the start:
docs/design/estimator.md, "A recording that starts in motion".
"""

from __future__ import annotations

import dataclasses
import math
from typing import Protocol

import numpy as np
from footnav.pipeline.nav_types import NavBatch, concat_batches
from footnav.pipeline.navigation.navigator import NavConfig, Navigator, NavStats, navigate
from footnav.pipeline.navigation.quaternion import quat_to_mat
from footnav.pipeline.samples import ImuBatch
from numpy.typing import NDArray

F64 = NDArray[np.float64]

COUNTERS = (
    "bad_dt",
    "gaps",
    "bad_samples",
    "zero_velocity_updates",
    "zero_velocity_rejected",
    "zero_rate_updates",
    "zero_rate_rejected",
)
"""``NavStats`` counts of the backward run added to the forward run's (the lead-in's own handling)."""


class RecordingRun(Protocol):
    """A whole-recording navigation from the first still period on: ``navigator.navigate``,
    ``footnav.pipeline.smoothing.rts.smooth_recording`` or
    ``footnav.pipeline.smoothing.stepwise.step_smooth_recording``."""

    def __call__(
        self,
        t_s: F64,
        acc_b_mps2: F64,
        gyr_b_radps: F64,
        rate_hz: float,
        config: NavConfig | None = None,
        *,
        gyr_clipped_b: NDArray[np.bool_] | None = None,
    ) -> tuple[NavBatch | None, NavStats]: ...


def navigate_every_sample(
    t_s: F64,
    acc_b_mps2: F64,
    gyr_b_radps: F64,
    rate_hz: float,
    config: NavConfig | None = None,
    *,
    run: RecordingRun = navigate,
    gyr_clipped_b: NDArray[np.bool_] | None = None,
) -> tuple[NavBatch | None, NavStats]:
    """``run`` over a whole recording, with the lead-in before its first still period navigated
    backwards from it (module docstring): one estimate per sample.

    Parameters
    ----------
    t_s, acc_b_mps2, gyr_b_radps, rate_hz, config, gyr_clipped_b
        as for ``navigator.navigate``.
    run : RecordingRun
        the navigation of both directions: causal (``navigate``, the default) or smoothed.

    Returns
    -------
    NavBatch or None
        the estimates of every sample (None: the recording is never still long enough to align).
    NavStats
        the forward run's statistics, with the lead-in's count in ``samples_navigated_backwards``
        (``samples_before_alignment`` still counts the samples before the first still period) and
        the backward run's counts of :data:`COUNTERS` added.
    """
    config = config or NavConfig()
    forward, stats = run(t_s, acc_b_mps2, gyr_b_radps, rate_hz, config, gyr_clipped_b=gyr_clipped_b)
    start = stats.samples_before_alignment
    if forward is None or start == 0:
        return forward, stats
    end = still_period_end(t_s, acc_b_mps2, gyr_b_radps, rate_hz, config, start)
    clipped = None if gyr_clipped_b is None else gyr_clipped_b[:end]
    t_r, acc_r, gyr_r, clipped_r = reverse_time(t_s[:end], acc_b_mps2[:end], gyr_b_radps[:end], clipped)
    backward, back_stats = run(t_r, acc_r, gyr_r, rate_hz, config, gyr_clipped_b=clipped_r)
    # backward sample j is reversed sample r0 + j, recording sample end − 1 − r0 − j
    last = end - 1 - back_stats.samples_before_alignment  # the recording sample of backward sample 0
    if backward is None or last < start:
        return forward, stats  # it aligned on another still period: the lead-in stays unnavigated
    lead_in = _onto_forward(backward, last - start, forward, t_s[:start])
    for name in COUNTERS:
        setattr(stats, name, getattr(stats, name) + getattr(back_stats, name))
    stats.samples_navigated_backwards = start
    stats.samples_out += start
    return concat_batches([lead_in, forward]), stats


def still_period_end(t_s: F64, acc_b_mps2: F64, gyr_b_radps: F64, rate_hz: float, config: NavConfig, start: int) -> int:
    """One past the last sample of the run of quiet samples (the alignment's criterion,
    ``NavConfig.align_max_rate_radps`` and ``align_max_acc_dev_mps2``) that begins at ``start``."""
    n = t_s.shape[0]
    batch = ImuBatch(t_s, acc_b_mps2, gyr_b_radps, np.arange(n, dtype=np.int64), np.zeros(n, dtype=np.int64))
    quiet = Navigator(config, rate_hz)._quiet(batch)
    moving = np.flatnonzero(~quiet[start:])
    return n if moving.size == 0 else start + int(moving[0])


def reverse_time(
    t_s: F64, acc_b_mps2: F64, gyr_b_radps: F64, gyr_clipped_b: NDArray[np.bool_] | None = None
) -> tuple[F64, F64, F64, NDArray[np.bool_] | None]:
    """The samples in reversed time (module docstring): τ = t₀ + t_last − t, last sample first,
    specific force as it is, angular rate negated."""
    t_r = (t_s[0] + t_s[-1]) - t_s[::-1]
    acc_r = np.ascontiguousarray(acc_b_mps2[::-1])
    gyr_r = np.ascontiguousarray(-gyr_b_radps[::-1])
    clipped_r = None if gyr_clipped_b is None else np.ascontiguousarray(gyr_clipped_b[::-1])
    return t_r, acc_r, gyr_r, clipped_r


def heading_difference(quat_a_wxyz: F64, quat_b_wxyz: F64) -> float:
    """ψ of the rotation about z that best turns attitude b onto attitude a (both body to
    navigation, scalar first): the angle of the horizontal block of C_a C_bᵀ, rad."""
    a, b = np.asarray(quat_a_wxyz, dtype=np.float64), np.asarray(quat_b_wxyz, dtype=np.float64)
    m = quat_to_mat(a) @ quat_to_mat(b).T
    return math.atan2(m[1, 0] - m[0, 1], m[0, 0] + m[1, 1])


def _onto_forward(backward: NavBatch, meet: int, forward: NavBatch, t_s: F64) -> NavBatch:
    """The backward run's estimates of the lead-in, in time order and moved onto the forward run's
    frame at backward sample ``meet`` = forward sample 0 (module docstring); ``t_s`` their times."""
    psi = heading_difference(forward.quat_nb_wxyz[0], backward.quat_nb_wxyz[meet])
    c, s = math.cos(psi), math.sin(psi)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    turn = np.array([math.cos(psi / 2), 0.0, 0.0, math.sin(psi / 2)])
    order = slice(len(backward) - 1, meet, -1)  # the recording's first sample first
    pos = (backward.pos_n_m[order] - backward.pos_n_m[meet]) @ rot.T + forward.pos_n_m[0]
    vel = -backward.vel_n_mps[order] @ rot.T
    q = backward.quat_nb_wxyz[order]
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    quat = np.column_stack(  # turn ⊗ q, turn = (cos ψ/2, 0, 0, sin ψ/2)
        [turn[0] * w - turn[3] * z, turn[0] * x - turn[3] * y, turn[0] * y + turn[3] * x, turn[0] * z + turn[3] * w]
    )
    cov_pos_yaw = None
    if backward.cov_pos_yaw is not None:
        t4 = np.eye(4)
        t4[:3, :3] = rot
        cov_pos_yaw = t4 @ backward.cov_pos_yaw[order] @ t4.T
    pos_cov = cov_pos_yaw[:, :3, :3] if cov_pos_yaw is not None else rot @ backward.pos_cov_n_m2[order] @ rot.T
    threshold = np.broadcast_to(backward.detector_threshold, (len(backward),))[order]
    return dataclasses.replace(
        backward,
        t_s=np.ascontiguousarray(t_s),
        pos_n_m=pos,
        vel_n_mps=vel,
        quat_nb_wxyz=quat,
        pos_cov_n_m2=pos_cov,
        cov_pos_yaw=cov_pos_yaw,
        stance=backward.stance[order],
        detector_stat=backward.detector_stat[order],
        detector_threshold=np.ascontiguousarray(threshold),
        clearance_m=backward.clearance_m[order],  # above its stance's level: the same after the move
        host_ns=backward.host_ns[order],
        floor_z_m=None,
        ranges=None,
        strides=None,  # found in reversed time: swings end where they began
        altitude=None,
        smoothed=None,
        step_onsets=None,
        swing_clearance=None,
    )
