"""Rauch–Tung–Striebel smoothing of a whole recording (replay, export and evaluation only, never live).

**Forward.** ``smooth_recording`` runs the causal ``Navigator`` itself, handed the recording in segments of
``segment_samples``, keeping the nominal state x̂ and covariance P at the start of each (a *checkpoint*).
**Backward** (Rauch, Tung, Striebel, AIAA J. 3(8), 1965), from the last segment: each is filtered again from its
checkpoint by ``_storing_pass`` (``run_filter``'s step, operation for operation, bit for bit:
``tests/test_smoother.py``; the stance height updates between its calls, from Python, as in the navigator),
keeping per sample the filtered x̂_k, P_k, the predicted x̂⁻_k, P⁻_k and F_k as (f_n, R, dt)
(``_kernels._propagate_cov``'s blocks). Then, for k from the end down:

    C_k      = P_k F_{k+1}ᵀ (P⁻_{k+1})⁻¹
    δ⁻_{k+1} = x^s_{k+1} ⊖ x̂⁻_{k+1}                   smoothed error against the *predicted* nominal
    P̃_{k+1}  = J P^s_{k+1} Jᵀ                           the same covariance in those coordinates
    δ^s_k    = C_k δ⁻_{k+1}
    P^s_k    = P_k + C_k (P̃_{k+1} − P⁻_{k+1}) C_kᵀ
    x^s_k    = x̂_k ⊕ δ^s_k

The error-state form with resets: the filter's error at k+1 is measured from the corrected nominal x̂_{k+1}, while
F_{k+1} and P⁻_{k+1} describe the error from the predicted one, so the smoothed state is re-expressed against
x̂⁻_{k+1} (``⊖``: differences for p, v and the biases, and δθ = Log(q^s ⊗ q̂⁻*) for the global attitude error,
exactly), which is x^s ⊖ x̂⁻ = δ^s_{k+1} + (x̂_{k+1} ⊖ x̂⁻_{k+1}) to first order, and its covariance is taken back
through the inverse of the filter's reset Jacobian, J = I − [ĉ/2]× on the attitude block with
ĉ = Log(q̂_{k+1} ⊗ q̂⁻*_{k+1}) the attitude correction applied at k+1 (Solà, "Quaternion kinematics for the
error-state Kalman filter", 2017, §7.3; the filter applies G = I + [ĉ/2]×). Without propagation (Δt ≤ 0) F = I,
Q = 0: x^s_k = x^s_{k+1}, P^s_k = P̃_{k+1}. At the last sample the smoothed solution is the filtered one. C_k comes
from a Cholesky solve of P⁻_{k+1} scaled to a unit diagonal (about 9 000 multiply-adds per sample, compiled).

**Memory** is fixed for any length: one segment's buffers (:data:`BYTES_PER_BUFFERED_SAMPLE`, about 3.9 KB, per
sample) plus one checkpoint per segment (1.9 KB). Units SI; frames as in ``footnav.pipeline.navigation.eskf``.
Why checkpointing, with its measurements: the documentation's design page "Smoothing".
"""

from __future__ import annotations

import bisect
import math

import numpy as np
from footnav.pipeline.jit import njit
from footnav.pipeline.nav_types import NavBatch
from footnav.pipeline.navigation import eskf
from footnav.pipeline.navigation._kernels import _correct, _predict, track_stance
from footnav.pipeline.navigation.batches import clip_variance, nav_batch, zupt_ratio
from footnav.pipeline.navigation.eskf import (
    BA0,
    BG0,
    N_CNT,
    N_FILTER_STATE,
    N_STATE,
    P0,
    TH0,
    V0,
    rotate_attitude_block,
    sample_intervals,
)
from footnav.pipeline.navigation.navigator import NavConfig, Navigator, NavStats
from footnav.pipeline.navigation.params import FilterParams
from footnav.pipeline.navigation.quaternion import quat_from_rotvec_s, quat_mul_s
from footnav.pipeline.samples import ImuBatch
from footnav.pipeline.stance.levels import StanceLevelParams, StanceLevels, height_update
from numpy.typing import NDArray

F64 = NDArray[np.float64]

SEGMENT_SAMPLES = 4096  # samples per checkpointed segment (working memory ≈ 3.9 KB × this)
BYTES_PER_BUFFERED_SAMPLE = 8 * (2 * N_STATE * N_STATE + 2 * 16 + 3 + 9 + 1) + 1


@njit(cache=True, inline="always")
def _quat_log_s(w: float, x: float, y: float, z: float) -> tuple[float, float, float]:  # pragma: no cover
    """Rotation vector of the unit quaternion (w, x, y, z), the shorter way round."""
    if w < 0.0:
        w, x, y, z = -w, -x, -y, -z
    s = math.sqrt(x * x + y * y + z * z)
    if s < 1e-9:
        return 2.0 * x, 2.0 * y, 2.0 * z  # 2 sin(a/2)/a → 1 for a → 0
    k = 2.0 * math.atan2(s, w) / s
    return k * x, k * y, k * z


@njit(cache=True, inline="always")
def _rot_diff_s(a: F64, b: F64) -> tuple[float, float, float]:  # pragma: no cover
    """δθ with R_a = Exp(δθ) R_b (global attitude error) for the quaternions in a[6:10], b[6:10]."""
    qw, qx, qy, qz = quat_mul_s(a[6], a[7], a[8], a[9], b[6], -b[7], -b[8], -b[9])
    return _quat_log_s(qw, qx, qy, qz)


@njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"})
def _storing_pass(
    x: F64,
    P: F64,
    acc_b_mps2: F64,
    gyr_b_radps: F64,
    gyr_clip_var_b: F64,
    dt_s: F64,
    stance: NDArray[np.bool_],
    zupt_ratio: F64,
    par: FilterParams,
    xf: F64,
    Pf: F64,
    xp: F64,
    Pp: F64,
    fn: F64,
    Rm: F64,
    counters: NDArray[np.int64],
    filter_state: NDArray[np.int64],
) -> None:
    """The causal filter over a segment (``run_filter``'s steps), keeping what the smoother needs.
    The stance height updates are applied between calls (``smooth_recording``).

    For sample j: ``xp[j]``, ``Pp[j]`` nominal state and covariance after the propagation (before any
    update), ``xf[j]``, ``Pf[j]`` after the updates, ``fn[j]``, ``Rm[j]`` and ``dt_s[j]`` the blocks of
    F over the interval ending at j (``fn[j, 0]`` is NaN where there was no propagation, Δt ≤ 0).
    ``x``, ``P``, ``counters`` and ``filter_state`` (the stance the filter is in) are advanced in
    place, as by ``run_filter``.
    """  # pragma: no cover
    n = acc_b_mps2.shape[0]
    if (
        gyr_b_radps.shape[0] != n
        or dt_s.shape[0] != n
        or stance.shape[0] != n
        or zupt_ratio.shape[0] != n
        or (gyr_clip_var_b.shape[0] != n and gyr_clip_var_b.shape[0] != 0)
        or xf.shape[0] < n
        or Pf.shape[0] < n
        or xp.shape[0] < n
        or Pp.shape[0] < n
        or fn.shape[0] < n
        or Rm.shape[0] < n
        or counters.shape[0] != N_CNT
        or filter_state.shape[0] != N_FILTER_STATE
    ):
        raise ValueError("_storing_pass: inconsistent array shapes")
    q_diag = np.zeros(N_STATE)
    y = np.empty(3)
    f_n = np.empty(3)
    R0 = np.empty((3, 3))
    R1 = np.empty((3, 3))
    M = np.empty((9, N_STATE))
    work = np.empty((10, N_STATE))
    for k in range(n):
        bad, propagated = _predict(
            x, P, acc_b_mps2, gyr_b_radps, gyr_clip_var_b, k, dt_s[k], par, q_diag, f_n, R0, R1, M, counters
        )
        for i in range(16):
            xp[k, i] = x[i]
        for i in range(N_STATE):
            for j in range(N_STATE):
                Pp[k, i, j] = P[i, j]
        if propagated:
            for r in range(3):
                fn[k, r] = f_n[r]
                for c in range(3):
                    Rm[k, r, c] = R0[r, c]
        else:
            fn[k, 0] = math.nan
        track_stance(stance[k], filter_state)
        if stance[k] and not bad:
            _correct(x, P, gyr_b_radps, zupt_ratio, k, par, y, work, counters, filter_state)
        for i in range(16):
            xf[k, i] = x[i]
        for i in range(N_STATE):
            for j in range(N_STATE):
                Pf[k, i, j] = P[i, j]


def _storing_segment(
    x: F64, P: F64, lo: int, hi: int, a: int, acc: F64, gyr: F64, gyr_var: F64, dt: F64, stance: NDArray[np.bool_],
    ratio: F64, par: FilterParams, xf: F64, Pf: F64, xp: F64, Pp: F64, fn: F64, Rm: F64,
    filter_state: NDArray[np.int64],
) -> None:  # fmt: skip
    """:func:`_storing_pass` over samples lo..hi−1 of the recording, into the buffers of the segment
    that starts at sample ``a``."""
    if hi > lo:
        b = slice(lo - a, None)
        _storing_pass(
            x, P, acc[lo:hi], gyr[lo:hi], gyr_var[lo:hi], dt[lo:hi], stance[lo:hi], ratio[lo:hi], par,
            xf[b], Pf[b], xp[b], Pp[b], fn[b], Rm[b], np.zeros(N_CNT, dtype=np.int64), filter_state,
        )  # fmt: skip


@njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"}, inline="always")
def _error_vs_predicted(xs: F64, xp: F64, k1: int, dp: F64) -> None:  # pragma: no cover
    """dp (15,) = the smoothed nominal ``xs`` (16,) ⊖ the predicted nominal ``xp[k1]``."""
    for r in range(3):
        dp[P0 + r] = xs[r] - xp[k1, r]
        dp[V0 + r] = xs[3 + r] - xp[k1, 3 + r]
        dp[BA0 + r] = xs[10 + r] - xp[k1, 10 + r]
        dp[BG0 + r] = xs[13 + r] - xp[k1, 13 + r]
    dp[TH0], dp[TH0 + 1], dp[TH0 + 2] = _rot_diff_s(xs, xp[k1])


@njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"}, inline="always")
def _f_times_p(Pf: F64, k: int, fn: F64, Rm: F64, dt: float, k1: int, B: F64) -> None:  # pragma: no cover
    """B = F_{k+1} P_k (rows of p, v, θ change; ``_kernels._propagate_cov``'s row operations)."""
    s = -dt
    f0, f1, f2 = fn[k1, 0], fn[k1, 1], fn[k1, 2]
    for j in range(N_STATE):
        a0, a1, a2 = Pf[k, TH0, j], Pf[k, TH0 + 1, j], Pf[k, TH0 + 2, j]
        b0, b1, b2 = Pf[k, BA0, j], Pf[k, BA0 + 1, j], Pf[k, BA0 + 2, j]
        g0, g1, g2 = Pf[k, BG0, j], Pf[k, BG0 + 1, j], Pf[k, BG0 + 2, j]
        for r in range(3):
            B[P0 + r, j] = Pf[k, P0 + r, j] + dt * Pf[k, V0 + r, j]
            B[TH0 + r, j] = Pf[k, TH0 + r, j] + s * (Rm[k1, r, 0] * g0 + Rm[k1, r, 1] * g1 + Rm[k1, r, 2] * g2)
            B[BA0 + r, j] = b0 if r == 0 else (b1 if r == 1 else b2)
            B[BG0 + r, j] = g0 if r == 0 else (g1 if r == 1 else g2)
        B[V0, j] = Pf[k, V0, j] + s * (-f2 * a1 + f1 * a2)
        B[V0 + 1, j] = Pf[k, V0 + 1, j] + s * (f2 * a0 - f0 * a2)
        B[V0 + 2, j] = Pf[k, V0 + 2, j] + s * (-f1 * a0 + f0 * a1)
        for r in range(3):
            B[V0 + r, j] += s * (Rm[k1, r, 0] * b0 + Rm[k1, r, 1] * b1 + Rm[k1, r, 2] * b2)


@njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"}, inline="always")
def _scaled_cholesky(Pp: F64, k1: int, d: F64, L: F64) -> None:  # pragma: no cover
    """d = diag(P⁻)^-½ and the Cholesky factor of the unit-diagonal scaling: D P⁻_{k+1} D = L Lᵀ."""
    for i in range(N_STATE):
        d[i] = 1.0 / math.sqrt(max(Pp[k1, i, i], 1e-300))
    for j in range(N_STATE):
        acc = Pp[k1, j, j] * d[j] * d[j]
        for m in range(j):
            acc -= L[j, m] * L[j, m]
        ljj = math.sqrt(max(acc, 1e-300))
        L[j, j] = ljj
        for i in range(j + 1, N_STATE):
            acc = Pp[k1, i, j] * d[i] * d[j]
            for m in range(j):
                acc -= L[i, m] * L[j, m]
            L[i, j] = acc / ljj


@njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"}, inline="always")
def _inject_smoothed(xf: F64, k: int, ds: F64, xs: F64) -> None:  # pragma: no cover
    """xs (16,) = x̂_k ⊕ δ^s_k."""
    for r in range(3):
        xs[r] = xf[k, r] + ds[P0 + r]
        xs[3 + r] = xf[k, 3 + r] + ds[V0 + r]
        xs[10 + r] = xf[k, 10 + r] + ds[BA0 + r]
        xs[13 + r] = xf[k, 13 + r] + ds[BG0 + r]
    ew, ex, ey, ez = quat_from_rotvec_s(ds[TH0], ds[TH0 + 1], ds[TH0 + 2])
    qw, qx, qy, qz = quat_mul_s(ew, ex, ey, ez, xf[k, 6], xf[k, 7], xf[k, 8], xf[k, 9])
    norm = math.sqrt(qw**2 + qx**2 + qy**2 + qz**2)
    xs[6], xs[7], xs[8], xs[9] = qw / norm, qx / norm, qy / norm, qz / norm


@njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"})
def _backward_pass(
    xf: F64,
    Pf: F64,
    xp: F64,
    Pp: F64,
    fn: F64,
    Rm: F64,
    dt_s: F64,
    last: int,
    write_last: bool,
    ds: F64,
    Ps: F64,
    xs: F64,
    out_pos: F64,
    out_vel: F64,
    out_quat: F64,
    out_cov: F64,
) -> None:
    """RTS backward recursion over the stored samples ``last`` down to 0 (module docstring).

    On entry ``ds`` (15,) and ``Ps`` (15, 15) hold the smoothed error at sample ``last`` relative to
    ``xf[last]`` and its covariance, ``xs`` (16,) the smoothed nominal there; on exit, at sample 0.
    Writes the outputs of samples 0 .. last − 1 (and ``last`` when ``write_last``).

    With ``out_cov`` of no rows the states alone are smoothed (``Ps`` is not used): δ^s_k = C δ⁻ =
    P_k Fᵀ (P⁻)⁻¹ δ⁻ needs one vector solve with P⁻ instead of the 15 of C and no covariance
    recursion, about 1 400 multiply-adds per sample instead of 9 000 (``footnav.pipeline.smoothing.stepwise``).
    """  # pragma: no cover
    with_cov = out_cov.shape[0] > 0
    pos_yaw = (P0, P0 + 1, P0 + 2, TH0 + 2)
    dp = np.empty(N_STATE)
    y = np.empty(N_STATE)
    B = np.empty((N_STATE, N_STATE))
    L = np.empty((N_STATE, N_STATE))
    Ct = np.empty((N_STATE, N_STATE))
    E = np.empty((N_STATE, N_STATE))
    d = np.empty(N_STATE)
    z = np.empty(N_STATE)
    first = last if write_last else last - 1
    for k in range(first, -1, -1):
        if k < last:
            k1 = k + 1
            # smoothed error at k+1 against the predicted nominal x̂⁻_{k+1}
            _error_vs_predicted(xs, xp, k1, dp)
            if with_cov:
                # P̃ = J Ps Jᵀ, J = I − [ĉ/2]× on θ (inverse of the filter's reset at k+1)
                c0, c1, c2 = _rot_diff_s(xf[k1], xp[k1])
                rotate_attitude_block(Ps, -0.5 * c0, -0.5 * c1, -0.5 * c2)
            if math.isnan(fn[k1, 0]):
                # no propagation into k+1: x̂⁻_{k+1} = x̂_k, P⁻_{k+1} = P_k, C = I
                for i in range(N_STATE):
                    ds[i] = dp[i]
            elif not with_cov:
                _f_times_p(Pf, k, fn, Rm, dt_s[k1], k1, B)
                _scaled_cholesky(Pp, k1, d, L)
                # y = (P⁻)⁻¹ δ⁻ = D (L Lᵀ)⁻¹ D δ⁻, then δ^s = Bᵀ y
                for i in range(N_STATE):
                    acc = d[i] * dp[i]
                    for m in range(i):
                        acc -= L[i, m] * y[m]
                    y[i] = acc / L[i, i]
                for i in range(N_STATE - 1, -1, -1):
                    acc = y[i]
                    for m in range(i + 1, N_STATE):
                        acc -= L[m, i] * y[m]
                    y[i] = acc / L[i, i]
                for i in range(N_STATE):
                    y[i] *= d[i]
                for i in range(N_STATE):
                    acc = 0.0
                    for m in range(N_STATE):
                        acc += B[m, i] * y[m]
                    ds[i] = acc
            else:
                _f_times_p(Pf, k, fn, Rm, dt_s[k1], k1, B)
                _scaled_cholesky(Pp, k1, d, L)
                # Cᵀ = P⁻⁻¹ B = D (L Lᵀ)⁻¹ D B, all columns at once (the innermost loops run along rows,
                # independent and contiguous, so they vectorise without reassociating any sum)
                for i in range(N_STATE):
                    for c in range(N_STATE):
                        Ct[i, c] = d[i] * B[i, c]
                    for m in range(i):
                        lim = L[i, m]
                        for c in range(N_STATE):
                            Ct[i, c] -= lim * Ct[m, c]
                    inv = 1.0 / L[i, i]
                    for c in range(N_STATE):
                        Ct[i, c] *= inv
                for i in range(N_STATE - 1, -1, -1):
                    for m in range(i + 1, N_STATE):
                        lmi = L[m, i]
                        for c in range(N_STATE):
                            Ct[i, c] -= lmi * Ct[m, c]
                    inv = 1.0 / L[i, i]
                    for c in range(N_STATE):
                        Ct[i, c] *= inv
                for i in range(N_STATE):
                    for c in range(N_STATE):
                        Ct[i, c] *= d[i]
                # δ^s_k = C δ⁻
                for i in range(N_STATE):
                    ds[i] = 0.0
                for m in range(N_STATE):
                    dm = dp[m]
                    for i in range(N_STATE):
                        ds[i] += Ct[m, i] * dm
                # P^s_k = P_k + C (P̃ − P⁻) Cᵀ: E = (P̃ − P⁻) Cᵀ, then one triangle of C E
                for i in range(N_STATE):
                    for m in range(N_STATE):
                        z[m] = Ps[i, m] - Pp[k1, i, m]
                    for c in range(N_STATE):
                        E[i, c] = 0.0
                    for m in range(N_STATE):
                        zm = z[m]
                        for c in range(N_STATE):
                            E[i, c] += zm * Ct[m, c]
                for i in range(N_STATE):
                    for c in range(N_STATE):
                        Ps[i, c] = Pf[k, i, c]
                    for m in range(N_STATE):
                        cmi = Ct[m, i]
                        for c in range(N_STATE):
                            Ps[i, c] += cmi * E[m, c]
                for i in range(N_STATE):
                    for c in range(i):
                        Ps[i, c] = Ps[c, i]
            _inject_smoothed(xf, k, ds, xs)
        for r in range(3):
            out_pos[k, r] = xs[r]
            out_vel[k, r] = xs[3 + r]
        for r in range(4):
            out_quat[k, r] = xs[6 + r]
            if with_cov:
                for c in range(4):
                    out_cov[k, r, c] = Ps[pos_yaw[r], pos_yaw[c]]


def store_span(
    x: F64,
    P: F64,
    a: int,
    stop: int,
    inputs: tuple[F64, F64, F64, F64, NDArray[np.bool_], F64],
    par: FilterParams,
    level_updates: list[tuple[int, float]],
    level_at: list[int],
    level_r: float,
    buffers: tuple[F64, F64, F64, F64, F64, F64],
    work: F64,
    filter_state: NDArray[np.int64],
) -> None:
    """The filter from ``x``, ``P`` and ``filter_state`` (advanced in place) over samples ``a`` .. ``stop`` − 1 of
    ``inputs`` (acc, gyr, gyr_var, dt, stance, T/γ, indexed alike), stored into ``buffers`` (xf, Pf,
    xp, Pp, fn, Rm, row 0 = sample ``a``) for :func:`_backward_pass`, with each stance height update
    (k, z) of ``level_updates`` (``level_at`` their k, sorted) for a ≤ k < stop applied after sample k.

    The run is split after each update's sample: the update runs here, from Python, as in the
    navigator, so both run the same compiled code (design page "Smoothing")."""
    xf, Pf = buffers[0], buffers[1]
    lo = a
    for j in range(bisect.bisect_left(level_at, a), bisect.bisect_left(level_at, stop)):
        k, z = level_updates[j]
        _storing_segment(x, P, lo, k + 1, a, *inputs, par, *buffers, filter_state)
        height_update(x, P, -1, z, level_r, work)
        xf[k - a], Pf[k - a] = x, P
        lo = k + 1
    _storing_segment(x, P, lo, stop, a, *inputs, par, *buffers, filter_state)


class _CheckpointingNavigator(Navigator):
    """The causal ``Navigator``, fed its post-alignment samples in segments with checkpoints.

    Detection, alignment and the filter are the parent's; the filter is sequential, so running it
    segment by segment gives bit for bit what one call gives. Before each segment the nominal state,
    covariance and previous timestamp are kept for the smoother's second forward pass.
    """

    def __init__(self, config: NavConfig, rate_hz: float, segment_samples: int) -> None:
        super().__init__(config, rate_hz)
        self.level_updates = []
        self.segment_samples = segment_samples
        self.checkpoints: list[tuple[int, F64, F64, float, int, NDArray[np.int64]]] = []
        """Per segment: first sample, x, P, the time before it, how many stance height updates had
        been applied (one due after the sample before the segment is applied in the segment's own
        run, after its checkpoint), and the filter's carried state (the stance it is in)."""
        self.inputs: list[tuple[ImuBatch, NDArray[np.bool_], F64]] = []  # samples, stance, T/γ

    def _init_rate(self, rate_hz: float) -> None:
        super()._init_rate(rate_hz)
        # the stance levels as constants, so that the updates are of the 15 states the passes store
        self.levels = StanceLevels(StanceLevelParams(use=self.config.stance_levels, level_states=0), rate_hz)

    def _run(self, batch: ImuBatch, stat: F64, threshold: F64, still: NDArray[np.bool_]) -> NavBatch:
        assert self._x is not None
        offset = sum(len(b) for b, _, _ in self.inputs)
        self.inputs.append((batch, still, zupt_ratio(stat, threshold)))
        n, seg = len(batch), self.segment_samples
        pos, vel = np.empty((n, 3)), np.empty((n, 3))
        quat, cov, clearance = np.empty((n, 4)), np.empty((n, 4, 4)), np.empty(n)
        for a in range(0, n, seg):
            b = min(n, a + seg)
            done = len(self.level_updates or ())
            self.checkpoints.append(
                (offset + a, self._x.copy(), self._P.copy(), self._t_last, done, self._filter_state.copy())
            )
            out = super()._run(batch.select(slice(a, b)), stat[a:b], threshold[a:b], still[a:b])
            pos[a:b], vel[a:b], quat[a:b], cov[a:b] = out.pos_n_m, out.vel_n_mps, out.quat_nb_wxyz, out.cov_pos_yaw
            clearance[a:b] = out.clearance_m
        return nav_batch(batch, pos, vel, quat, cov, stat, threshold, still, clearance_m=clearance)


def smooth_recording(
    t_s: F64,
    acc_b_mps2: F64,
    gyr_b_radps: F64,
    rate_hz: float,
    config: NavConfig | None = None,
    *,
    segment_samples: int = SEGMENT_SAMPLES,
    gyr_clipped_b: NDArray[np.bool_] | None = None,
) -> tuple[NavBatch | None, NavStats]:
    """The RTS-smoothed navigation solution of a whole recording (not causal: replay, export, evaluation).

    Same samples, stance flags, detector fields and statistics as ``navigator.navigate`` on the same
    arrays (the causal navigator runs underneath); positions, velocities, attitude, ``cov_pos_yaw``,
    ``pos_cov_n_m2`` and ``clearance_m`` are the smoothed ones. The last sample equals the causal
    solution. None, as from ``navigate``, when the recording never stands still long enough to align.

    Parameters
    ----------
    segment_samples : int
        Samples per checkpointed segment: bounds the working memory to about
        ``BYTES_PER_BUFFERED_SAMPLE`` (3.9 KB) times this; the result does not depend on it.
    gyr_clipped_b : ndarray of bool, shape (n, 3), optional
        The rates marked clipped (``footnav.pipeline.navigation.saturation``), as for ``navigate``.
    """
    if segment_samples < 1:
        raise ValueError("segment_samples must be at least 1")
    nav = _CheckpointingNavigator(config or NavConfig(), rate_hz, segment_samples)
    nav.whole_recording = True
    n_in = t_s.shape[0]
    out = nav.process(
        ImuBatch(
            t_s,
            acc_b_mps2,
            gyr_b_radps,
            np.arange(n_in, dtype=np.int64),
            np.zeros(n_in, dtype=np.int64),
            gyr_clipped_b,
        )
    )
    if out is None:
        return None, nav.stats
    batch = ImuBatch.concat([b for b, _, _ in nav.inputs]) if len(nav.inputs) > 1 else nav.inputs[0][0]
    still = np.concatenate([s for _, s, _ in nav.inputs])
    ratio = np.ascontiguousarray(np.concatenate([r for _, _, r in nav.inputs]))
    acc = np.ascontiguousarray(batch.acc_b_mps2, dtype=np.float64)
    gyr = np.ascontiguousarray(batch.gyr_b_radps, dtype=np.float64)
    gyr_var = clip_variance(batch)
    stance = np.ascontiguousarray(still)
    n = len(batch)
    level_updates = nav.level_updates or []
    level_at = [k for k, _ in level_updates]
    level_r = nav.levels.params.sigma_m**2
    work = np.empty((2, eskf.N_STATE))
    t_first = nav.checkpoints[0][3]
    dt = sample_intervals(batch.t_s, t_first, nav.config.dt_max_s)  # as Navigator._run computes it
    floor_z = out.pos_n_m[:, 2] - out.clearance_m  # the floor each clearance is measured from
    # the outputs are overwritten in place, the smoothed solution replacing the causal one
    pos, vel, quat, cov = out.pos_n_m, out.vel_n_mps, out.quat_nb_wxyz, out.cov_pos_yaw
    assert cov is not None
    cap = min(segment_samples, n) + 1
    xf, xp = np.empty((cap, 16)), np.empty((cap, 16))
    Pf, Pp = np.empty((cap, eskf.N_STATE, eskf.N_STATE)), np.empty((cap, eskf.N_STATE, eskf.N_STATE))
    fn, Rm = np.empty((cap, 3)), np.empty((cap, 3, 3))
    ds, Ps, xs = np.zeros(eskf.N_STATE), np.empty((eskf.N_STATE, eskf.N_STATE)), np.empty(16)
    starts = [c[0] for c in nav.checkpoints] + [n]
    for i in range(len(nav.checkpoints) - 1, -1, -1):
        a, x0, P0_, _, done, state0 = nav.checkpoints[i]
        end = starts[i + 1]
        is_last = end == n
        stop = end if is_last else end + 1  # one sample of overlap: the next segment's first
        m = stop - a
        x, P = x0.copy(), P0_.copy()
        for k, z in level_updates[done:]:
            if k < a:  # due after the previous segment's last sample, applied after this checkpoint
                height_update(x, P, -1, z, level_r, work)
        inputs = (acc, gyr, gyr_var, dt, stance, ratio)
        buffers = (xf, Pf, xp, Pp, fn, Rm)
        store_span(x, P, a, stop, inputs, nav._par, level_updates, level_at, level_r, buffers, work, state0.copy())
        if is_last:
            ds[:] = 0.0
            Ps[:] = Pf[m - 1]
            xs[:] = xf[m - 1]
        _backward_pass(
            xf,
            Pf,
            xp,
            Pp,
            fn,
            Rm,
            dt[a:stop],
            m - 1,
            is_last,
            ds,
            Ps,
            xs,
            pos[a:stop],
            vel[a:stop],
            quat[a:stop],
            cov[a:stop],
        )
    return (
        NavBatch(
            t_s=out.t_s,
            pos_n_m=pos,
            vel_n_mps=vel,
            quat_nb_wxyz=quat,
            pos_cov_n_m2=cov[:, :3, :3],
            stance=out.stance,
            detector_stat=out.detector_stat,
            detector_threshold=out.detector_threshold,
            clearance_m=pos[:, 2] - floor_z,
            host_ns=out.host_ns,
            cov_pos_yaw=cov,
        ),
        nav.stats,
    )
