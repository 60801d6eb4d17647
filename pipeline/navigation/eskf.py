"""Error-state Kalman filter for a foot-mounted IMU: the model, and the wrappers of its kernels.

Formulation: Solà, "Quaternion kinematics for the error-state Kalman filter" (arXiv:1711.02508,
2017), §5 and §7, attitude error in the navigation frame (R_true = Exp(δθ) R̂), the form of
OpenShoe's filter (Nilsson et al., IPIN 2012) with accelerometer and gyroscope bias states:

    nominal x = [p_n (3), v_n (3), q_nb (4), b_a (3), b_g (3)]          (16,)
    error  δx = [δp (3), δv (3), δθ (3), δb_a (3), δb_g (3)]          (15,)
    δp' = δv,  δv' = −[R (a_m − b_a)]× δθ − R δb_a − R a_n,  δθ' = −R δb_g − R ω_n

Nominal step over the interval dt ending at sample k, ω = ω_k − b_g, f = f_k − b_a:
q_k = q_{k−1} ⊗ Exp(ω dt), f_n = ½ (R_{k−1} + R_k) f, a = f_n − [0, 0, g], p += v dt + ½ a dt²,
v += a dt. Process noise per sample σ² = σ0² + (k |s|)² (white noise plus a fraction k of the
signal; IEEE Std 952-1997 / 1293-1998), and R diag(σ_i²) Rᵀ dt² on the attitude where a rate was
clipped (``footnav.pipeline.navigation.saturation``).

At stance samples: zero velocity (ZUPT, z = −v, noise σ_h² = σ_zupt² + (r |ω|)² horizontally and
σ_h² + σ_T² T/γ vertically, T/γ the detector's statistic over its threshold), skipped when the
detector is unsure (T/γ > ``zupt_gate_ratio``) and the normalised innovation exceeds
``zupt_gate``; then zero angular rate (ZARU, z = ω_m − b_g), applied when its NIS against the
gyroscope's white noise passes a 95 % χ² gate, with σ_s² u uᵀ added along the vertical u for a
foot standing longer than ``standing_after`` samples after the first stance. Each update is in
Joseph form, then injection and reset (Solà §7.3).

Frames: n is local level, z up (gravity −g along z); b the IMU's axes. Units SI (m, s, rad).
The decisions behind the gates and noise models, with their measurements, are in the
documentation's design page "Estimator". ``benchmarks.numpy_filter`` is the same filter with
full matrices, the reference ``tests/test_filter_reference.py`` checks the kernels against.
"""

from __future__ import annotations

import numpy as np
from footnav.pipeline.navigation._kernels import (
    run_filter_kernel,
    track_stance,
    zupt_gate,
    zupt_vertical_weight,
)
from footnav.pipeline.navigation._kernels_linalg import (
    BA0,
    BG0,
    N_STATE,
    P0,
    TH0,
    V0,
    _inv3_spd,  # noqa: F401 (used by dual_imu.dense_kf)
    inject,
    inject_attitude_and_reset,
    rotate_attitude_block,
    update1,
)
from footnav.pipeline.navigation.params import (
    CNT_BAD_DT,
    CNT_BAD_SAMPLE,
    CNT_GAP,
    CNT_UPDATES,
    CNT_ZARU,
    CNT_ZARU_REJECTED,
    CNT_ZUPT_REJECTED,
    N_CNT,
    N_FILTER_STATE,
    STATE_LAST_REJECTED,
    STATE_STANCE_RUN,
    STATE_STARTED,
    FilterParams,
)
from footnav.pipeline.samples import diff_after
from numpy.typing import NDArray

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

__all__ = [
    "BA0",
    "BG0",
    "CNT_BAD_DT",
    "CNT_BAD_SAMPLE",
    "CNT_GAP",
    "CNT_UPDATES",
    "CNT_ZARU",
    "CNT_ZARU_REJECTED",
    "CNT_ZUPT_REJECTED",
    "N_CNT",
    "N_FILTER_STATE",
    "N_STATE",
    "P0",
    "STATE_LAST_REJECTED",
    "STATE_STANCE_RUN",
    "STATE_STARTED",
    "TH0",
    "V0",
    "FilterParams",
    "clone_height",
    "inject",
    "inject_attitude_and_reset",
    "new_filter_state",
    "rotate_attitude_block",
    "run_filter",
    "sample_intervals",
    "track_stance",
    "update1",
    "zupt_gate",
    "zupt_vertical_weight",
]


def sample_intervals(t_s: F64, t_prev_s: float, dt_max_s: float) -> F64:
    """Intervals ending at each sample, capped at ``dt_max_s``.

    An interval of ``dt_max_s`` or more is a gap in the stream (lost packets, a corrupt time stamp):
    it is integrated as ``dt_max_s``, because the IMU says nothing about the motion in between and
    integrating one sample over seconds only adds error; the filter counts it as a gap. Non-positive
    or NaN intervals pass through: the filter skips and counts them.

    Parameters
    ----------
    t_s : ndarray, shape (n,)
        Sample times, s.
    t_prev_s : float
        Time of the sample before the first, s.
    dt_max_s : float
        Longest interval integrated, s.

    Returns
    -------
    ndarray, shape (n,)
        The interval before each sample, s.
    """
    dt = diff_after(t_prev_s, t_s)
    return np.minimum(dt, dt_max_s, out=dt)


def clone_height(x: F64, P: F64, i: int, extra_var_m2: float) -> None:
    """Make the constant error state ``i`` a copy of δp_z (stochastic cloning), in place.

    Roumeliotis and Burdick, ICRA 2002: nominal x[i + 1] becomes the height, row and column ``i`` of
    ``P`` those of δp_z, and its variance that of δp_z plus ``extra_var_m2`` (a floor level placed
    where the IMU rests).

    Parameters
    ----------
    x : ndarray, shape (n + 1,)
        Nominal state.
    P : ndarray, shape (n, n)
        Error covariance.
    i : int
        The error state to set, i ≥ 15.
    extra_var_m2 : float
        Variance added to the copy, m².
    """
    x[i + 1] = x[P0 + 2]
    P[i, :] = P[P0 + 2, :]
    P[:, i] = P[:, P0 + 2]
    P[i, i] = P[P0 + 2, P0 + 2] + extra_var_m2


def new_filter_state() -> I64:
    """The carried state of a filter that has not run yet (zeros, shape (N_FILTER_STATE,))."""
    return np.zeros(N_FILTER_STATE, dtype=np.int64)


def run_filter(
    x: F64,
    P: F64,
    acc_b_mps2: F64,
    gyr_b_radps: F64,
    gyr_clip_var_b: F64,
    dt_s: F64,
    stance: NDArray[np.bool_],
    zupt_ratio: F64,
    par: FilterParams,
    out_pos: F64,
    out_vel: F64,
    out_quat: F64,
    out_cov: F64,
    counters: I64,
    filter_state: I64 | None = None,
) -> None:
    """Run the filter over a batch, updating ``x``, ``P``, ``counters`` and ``filter_state`` in place.

    Parameters
    ----------
    x : ndarray, shape (16 + m,)
        Nominal state, carried between batches; m constant states (the floor levels of
        ``footnav.pipeline.aiding.tof``) after the sixteenth.
    P : ndarray, shape (15 + m, 15 + m)
        Error covariance, carried between batches.
    acc_b_mps2, gyr_b_radps : ndarray, shape (n, 3)
        IMU samples, m/s² and rad/s; sample k covers the interval ending at it.
    gyr_clip_var_b : ndarray, shape (n, 3) or (0, 3)
        Variance of each sample's rate error along each body axis beyond the profile's noise,
        rad²/s² (clipped samples: ``footnav.pipeline.navigation.saturation``); no rows: none.
    dt_s : ndarray, shape (n,)
        Interval before each sample, s. Non-positive intervals skip the propagation (duplicated
        timestamps); intervals of ``par.dt_max`` or more are counted as gaps
        (:func:`sample_intervals` caps them there).
    stance : ndarray of bool, shape (n,)
        Apply ZUPT and ZARU after propagating sample k.
    zupt_ratio : ndarray, shape (n,)
        The zero-velocity detector's statistic over its threshold, T/γ: sets the vertical noise of
        each ZUPT and whether it is gated; zeros give the same noise on all three axes.
    par : FilterParams
        Parameters (``footnav.pipeline.navigation.navigator.filter_parameters``).
    out_pos, out_vel : ndarray, shape (n, 3)
        Position and velocity after each sample, m and m/s.
    out_quat : ndarray, shape (n, 4)
        Attitude q_nb (w, x, y, z) after each sample.
    out_cov : ndarray, shape (n, 4, 4)
        Covariance of (x, y, z, ψ): position and the heading error (the z component of δθ).
    counters : ndarray of int64, shape (N_CNT,)
        Counts, incremented in place (the ``CNT_*`` indices).
    filter_state : ndarray of int64, shape (N_FILTER_STATE,), optional
        The stance the filter is in and whether the last update was rejected (the ``STATE_*``
        indices), carried between batches; None: a filter that has not run yet.

    Raises
    ------
    ValueError
        When the shapes of the arguments disagree.
    """
    run_filter_kernel(
        x, P, acc_b_mps2, gyr_b_radps, gyr_clip_var_b, dt_s, stance, zupt_ratio, par,
        out_pos, out_vel, out_quat, out_cov, counters, new_filter_state() if filter_state is None else filter_state,
    )  # fmt: skip
