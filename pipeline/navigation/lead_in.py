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
the run without the lead-in, bit for bit. A live session (:class:`LiveLeadIn`) keeps the samples
before its alignment, at most :data:`LEAD_IN_KEEP_S`, and navigates them the same way, with the same
functions, once its still period has ended: one more batch, earlier than those already shown. Why
this rather than a forward pass from the start: docs/design/estimator.md, "A recording that starts in
motion".
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
    assert end is not None  # the recording is complete
    clipped = None if gyr_clipped_b is None else gyr_clipped_b[:end]
    found = navigate_lead_in(
        t_s[:end], acc_b_mps2[:end], gyr_b_radps[:end], rate_hz, config, start, forward, run=run, gyr_clipped_b=clipped
    )
    if found is None:
        return forward, stats  # it aligned on another still period: the lead-in stays unnavigated
    lead_in, back_stats = found
    for name in COUNTERS:
        setattr(stats, name, getattr(stats, name) + getattr(back_stats, name))
    stats.samples_navigated_backwards += start
    stats.samples_out += start
    return concat_batches([lead_in, forward]), stats


def navigate_lead_in(
    t_s: F64,
    acc_b_mps2: F64,
    gyr_b_radps: F64,
    rate_hz: float,
    config: NavConfig,
    start: int,
    forward: NavBatch,
    *,
    run: RecordingRun = navigate,
    gyr_clipped_b: NDArray[np.bool_] | None = None,
) -> tuple[NavBatch, NavStats] | None:
    """The lead-in, samples ``[0, start)``, navigated backwards from the still period ``[start, n)``
    that follows it and moved onto the forward run (module docstring).

    Parameters
    ----------
    t_s, acc_b_mps2, gyr_b_radps, rate_hz, config, gyr_clipped_b
        the lead-in's samples and its still period's, (n,) and (n, 3), as for ``navigator.navigate``;
        the last one is the still period's last (:func:`still_period_end`).
    start : int
        the first sample of the still period, where the forward run aligned.
    forward : NavBatch
        the forward run's estimates from sample ``start`` on (its first sample is used).
    run : RecordingRun
        the navigation of the reversed samples.

    Returns
    -------
    tuple of NavBatch and NavStats, or None
        the lead-in's ``start`` estimates in time order and the backward run's statistics; None when
        the backward run aligned on no quiet samples of this still period.
    """
    t_r, acc_r, gyr_r, clipped_r = reverse_time(t_s, acc_b_mps2, gyr_b_radps, gyr_clipped_b)
    backward, back_stats = run(t_r, acc_r, gyr_r, rate_hz, config, gyr_clipped_b=clipped_r)
    # backward sample j is reversed sample r0 + j, sample n − 1 − r0 − j
    last = t_s.shape[0] - 1 - back_stats.samples_before_alignment  # the sample of backward sample 0
    if backward is None or last < start:
        return None
    return _onto_forward(backward, last - start, forward, t_s[:start]), back_stats


def still_period_end(
    t_s: F64, acc_b_mps2: F64, gyr_b_radps: F64, rate_hz: float, config: NavConfig, start: int, *, complete: bool = True
) -> int | None:
    """One past the last sample of the run of quiet samples (the alignment's criterion,
    ``NavConfig.align_max_rate_radps`` and ``align_max_acc_dev_mps2``) that begins at ``start``.

    A sample's flag depends on the samples within one alignment window of it only
    (``alignment.first_quiet_run``), so the flags are taken on the samples from a window before
    ``start`` on (cut at a multiple of 64 samples: the same sums, bit for bit). ``complete=False``:
    the samples are the first ones of a stream that goes on, and the flags of its last window are
    not yet decided; None while no decided flag after ``start`` is moving.
    """
    n = t_s.shape[0]
    navigator = Navigator(config, rate_hz)
    need = max(2, round(config.align_s * rate_hz))
    lo = max(0, start - need) // 64 * 64
    batch = ImuBatch(
        t_s[lo:], acc_b_mps2[lo:], gyr_b_radps[lo:], np.arange(lo, n, dtype=np.int64), np.zeros(n - lo, np.int64)
    )
    quiet = navigator._quiet(batch)[start - lo : n - lo if complete else max(start - lo, n - lo - need)]
    moving = np.flatnonzero(~quiet)
    if moving.size:
        return start + int(moving[0])
    return n if complete else None


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


LEAD_IN_KEEP_S = 120.0
"""A live session keeps at most this much of its samples before the alignment, s (two minutes:
120 000 samples, about 9 MB, at 1 kHz); earlier ones stay not navigated."""
LEAD_IN_STILL_S = 10.0
"""A live session fills its lead-in in at the latest this far into the still period, s: a longer still
period is taken to end there (the batch path takes the whole of it)."""


class LiveLeadIn:
    """The lead-in of a live session: its samples kept from the start, then navigated backwards
    (:func:`navigate_lead_in`, the causal filter) once the navigator has aligned and its still
    period has ended.

    Call :meth:`add` with each batch before the navigator processes it and :meth:`after` with what
    it returned; each returns the lead-in's estimates once (None otherwise), and :meth:`finish` at the
    end of the stream (a still period that lasts to the end). The still period's end is decided on
    the samples a window past it (:func:`still_period_end`), at the latest :data:`LEAD_IN_STILL_S`
    into it. At most :data:`LEAD_IN_KEEP_S` of samples are kept before the alignment; with all of
    them kept, the estimates equal those of :func:`navigate_every_sample` on the same samples when
    the still period is shorter than :data:`LEAD_IN_STILL_S`. The navigator's ``stats`` count the
    lead-in in ``samples_navigated_backwards`` and ``samples_out``; the backward run's own counts
    stay apart (``backward_stats``): the navigator rewrites its counters with every batch.
    """

    def __init__(
        self, navigator: Navigator, *, keep_s: float = LEAD_IN_KEEP_S, still_s: float = LEAD_IN_STILL_S
    ) -> None:
        self.navigator = navigator
        self.keep_s, self.still_s = keep_s, still_s
        self.backward_stats: NavStats | None = None
        self.done = False
        self._batches: list[ImuBatch] = []
        self._held = 0
        self._first = 0  # the session's index of the first sample held
        self._forward: NavBatch | None = None
        self._checked = 0  # samples held at the last look for the still period's end

    def add(self, batch: ImuBatch) -> None:
        """Keep ``batch`` (the samples as the navigator gets them) while the lead-in may need it."""
        if self.done or len(batch) == 0:
            return
        self._batches.append(batch)
        self._held += len(batch)
        if self._forward is None:  # not aligned yet: keep the last ``keep_s``
            keep = round(self.keep_s * self.navigator.rate_hz)
            while self._held - len(self._batches[0]) >= keep:
                dropped = self._batches.pop(0)
                self._held -= len(dropped)
                self._first += len(dropped)

    def after(self, nav: NavBatch | None) -> NavBatch | None:
        """The lead-in's estimates if the still period has ended with the samples added so far."""
        if self.done:
            return None
        if self._forward is None:
            if nav is None or len(nav) == 0:
                return None
            self._forward = nav
            if self.navigator.stats.samples_before_alignment <= self._first:
                self._close()  # no lead-in, or none of it kept
                return None
        need = max(2, round(self.navigator.config.align_s * self.navigator.rate_hz))
        if self._held - self._checked < need:
            return None
        self._checked = self._held
        return self._fill(complete=False)

    def finish(self) -> NavBatch | None:
        """The lead-in's estimates at the end of the stream (None: none to fill in)."""
        if self.done or self._forward is None:
            self._close()
            return None
        return self._fill(complete=True)

    def _fill(self, *, complete: bool) -> NavBatch | None:
        nav = self.navigator
        batch = ImuBatch.concat(self._batches)
        self._batches = [batch]
        start = nav.stats.samples_before_alignment - self._first
        end = still_period_end(
            batch.t_s, batch.acc_b_mps2, batch.gyr_b_radps, nav.rate_hz, nav.config, start, complete=complete
        )
        # at the latest ``still_s`` into the still period (not where the samples held end, which depends on
        # how the stream is cut into batches), once the flags up to there are decided
        latest = start + round(self.still_s * nav.rate_hz)
        need = max(2, round(nav.config.align_s * nav.rate_hz))
        if end is None and self._held < latest + need:
            return None
        end = latest if end is None else min(end, latest)
        clipped = None if batch.gyr_clipped_b is None else batch.gyr_clipped_b[:end]
        assert self._forward is not None
        found = navigate_lead_in(
            batch.t_s[:end], batch.acc_b_mps2[:end], batch.gyr_b_radps[:end], nav.rate_hz, nav.config, start,
            self._forward, gyr_clipped_b=clipped,
        )  # fmt: skip
        self._close()
        if found is None:
            return None
        lead_in, self.backward_stats = found
        nav.stats.samples_navigated_backwards += start
        nav.stats.samples_out += start
        return dataclasses.replace(lead_in, host_ns=np.ascontiguousarray(batch.host_ns[:start]))

    def _close(self) -> None:
        self.done = True
        self._batches, self._held, self._forward = [], 0, None
