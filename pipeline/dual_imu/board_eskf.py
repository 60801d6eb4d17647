"""footnav's dual-IMU filter: one rigid-board error-state Kalman filter fed by both IMUs, with both
IMUs' biases estimated and the rigid-body relations as measurements (no I/O; the compiled loop is in ``_kernels``).

The nominal state is the board at the midpoint ``c`` of the two IMUs (``ρ₁ = −m/2``, ``ρ₂ = +m/2``, ``m`` IMU 2's
position in IMU 1's axes), navigated with ``f̄ = ½ (f₁ + f₂)`` and ``ω̄ = ½ (ω₁ + ω₂)``: on a rigid board the
lever-arm terms of ``f_i = f_c + ω̇ × ρ_i + ω × (ω × ρ_i)`` cancel in the average, and ``p_i = p_c + C ρ_i``:

    nominal x = [p_c, v_c, q_nb, b_a1, b_g1, b_a2, b_g2]                        (22,)
    error  δx = [δp, δv, δθ, δb_a1, δb_g1, δb_a2, δb_g2]                        (21,)
    δv' = −[R f̄]× δθ − R (w₁ δb_a1 + w₂ δb_a2),   δθ' = −R (w₁ δb_g1 + w₂ δb_g2)

(Solà 2017 §5 and §7, global attitude error, as :mod:`footnav.pipeline.navigation.eskf`), with weights ``w = (½, ½)``
when both IMUs are usable and ``(1, 0)`` or ``(0, 1)`` when only one is. Measurements:

- **equal angular rate** (swing and stance, both IMUs usable): ``ω₁ − ω₂ = b_g1 − b_g2 + n``,
  ``n ~ N(0, 2 σ_ω² / N)`` for the mean over ``N`` = :data:`RATE_EQ_SAMPLES` samples;
- **equal specific force in stance** (both usable): ``f₁ − f₂ + ω̇ × m + ω × (ω × m) = b_a1 − b_a2 + n``
  (``ω̇`` from a smoothed backward difference of the rate, its noise in ``n``), χ²-gated;
- **zero velocity** of the board in stance (``v_c = 0``), with the roll-lever noise of
  :mod:`footnav.pipeline.navigation.eskf`, and the χ²-gated **zero angular rate** on the averaged rate
  (``H = ½ I`` on each gyro bias).

With one IMU unusable (not finite, or at full scale: saturated) the filter navigates on the other, its own bias
estimates and the lever-arm terms it can form, ``f_c = f₁ + ω̇ × m/2 + ω × (ω × m/2)``, and counts every such sample.
Output is IMU 1's point, ``p_c − ½ C m``, and IMU 2's, ``p_c + ½ C m``; :class:`DualEskfStream` carries the filter
between batches (bit for bit one call), :func:`run_dual_eskf` runs a whole record. Units SI. Why: the design page
"Dual-IMU board". References: Solà (2017), arXiv:1711.02508; Chen, Lu, Xu, Liu and Bi (2022), *Sensors and
Materials* (the board and its relations); Groves (2013), *Principles of GNSS, Inertial, and Multisensor Integrated
Navigation Systems*, 2nd ed., §2.5 (specific force at a lever arm).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np
from footnav.pipeline.dual_imu._kernels import (
    AUX_LAST_REJECTED,
    COUNTER_NAMES,
    N_AUX,
    N_CNT,
    N_NOMINAL,
    RATE_EQ_SAMPLES,
    WDOT_SMOOTHING,
    DualFilterParams,
    run_dual_filter,
)
from footnav.pipeline.dual_imu.model import (
    ACC_FULL_SCALE_MPS2,
    GYR_FULL_SCALE_RADPS,
    fault_report,
    quat_to_mats,
    still_window,
)
from footnav.pipeline.navigation.alignment import align_from_still
from footnav.pipeline.navigation.eskf import sample_intervals
from footnav.pipeline.navigation.navigator import (
    DEFAULT_DT_MAX_S,
    ZARU_GATE_CHI2_3DOF,
    ZUPT_GATE_NIS,
    ZUPT_GATE_RATIO,
    initial_error_sigmas,
)
from footnav.pipeline.navigation.profiles import G0_MPS2, UnitProfile, get_profile
from footnav.pipeline.navigation.quaternion import quat_to_mat_into
from numpy.typing import NDArray

F64 = NDArray[np.float64]

__all__ = [
    "AUX_LAST_REJECTED",
    "COUNTER_NAMES",
    "N_AUX",
    "N_CNT",
    "N_NOMINAL",
    "RATE_EQ_SAMPLES",
    "DualEskfConfig",
    "DualEskfStream",
    "DualEskfTrack",
    "DualFilterParams",
    "concat_tracks",
    "dual_parameters",
    "run_dual_eskf",
    "run_dual_filter",
]


@dataclass(frozen=True, slots=True)
class DualEskfConfig:
    """Settings of footnav's dual-IMU filter.

    Attributes
    ----------
    profile
        Noise model of one IMU (both are the same part).
    align_s
        Still time at the start of the record used for the alignment, s.
    init_pos_sigma_m, init_vel_sigma_mps, init_tilt_sigma_rad, init_yaw_sigma_rad
        Initial 1σ.
    dt_max_s
        Longer intervals are gaps, integrated as this long (``eskf.sample_intervals``), s.
    gravity_mps2
        The local gravity, m/s²; 0 or less: the still start's |f̄| (as
        ``footnav.pipeline.navigation.navigator.NavConfig.gravity_mps2``).
    """

    profile: UnitProfile = field(default_factory=lambda: get_profile("generic"))
    align_s: float = 1.0
    dt_max_s: float = DEFAULT_DT_MAX_S
    init_pos_sigma_m: float = 1e-5
    init_vel_sigma_mps: float = 0.01
    init_tilt_sigma_rad: float = math.radians(0.5)
    init_yaw_sigma_rad: float = math.radians(0.01)
    gravity_mps2: float = G0_MPS2


@dataclass(frozen=True, slots=True)
class DualEskfTrack:
    """Per-sample output of :func:`run_dual_eskf`.

    Attributes
    ----------
    pos1_n_m
        (n, 3) IMU 1's position, m.
    pos_imu_n_m
        (n, 2, 3) IMU 1's and IMU 2's positions (rigidly C m apart), m.
    vel_n_mps
        (n, 3) the board midpoint's velocity, m/s.
    quat_nb_wxyz
        (n, 4) attitude.
    pos_cov_n_m2
        (n, 3, 3) position covariance, m².
    bias_b
        (n, 4, 3) bias estimates [b_a1, b_g1, b_a2, b_g2] (m/s², rad/s).
    residual_rate_radps
        (n, 3) equal-rate innovation ``mean(ω₁ − ω₂) − (b_g1 − b_g2)`` (NaN where none).
    residual_force_mps2
        (n, 3) equal-force innovation in stance (NaN where none).
    nis_rate
        (n,) NIS of the equal-rate innovation (NaN where none).
    imu_ok
        (n, 2) whether each IMU's sample was used.
    counters
        Named counts (see ``COUNTER_NAMES``).
    messages
        Plain-language report of unusable IMU samples (empty when there were none).
    """

    pos1_n_m: F64
    pos_imu_n_m: F64
    vel_n_mps: F64
    quat_nb_wxyz: F64
    pos_cov_n_m2: F64
    bias_b: F64
    residual_rate_radps: F64
    residual_force_mps2: F64
    nis_rate: F64
    imu_ok: NDArray[np.bool_]
    counters: dict[str, int]
    messages: tuple[str, ...] = ()


def concat_tracks(parts: list[DualEskfTrack]) -> DualEskfTrack:
    """One track of consecutive ones (counters and messages, which cover everything since the start,
    from the last)."""
    if len(parts) == 1:
        return parts[0]
    last = parts[-1]
    arrays = {
        f.name: np.concatenate([getattr(p, f.name) for p in parts])
        for f in dataclasses.fields(DualEskfTrack)
        if f.name not in ("counters", "messages")
    }
    return DualEskfTrack(**arrays, counters=last.counters, messages=last.messages)


def dual_parameters(profile: UnitProfile, rate_hz: float, gravity_mps2: float) -> DualFilterParams:
    """Parameters of :func:`run_dual_filter` from a unit profile.

    Per-sample noise is the sensor's white noise at this rate (σ = density·√rate, halved in variance
    for the two IMUs' mean) combined with the profile's motion noise, as ``navigator.filter_parameters``.

    Parameters
    ----------
    profile : UnitProfile
        Noise and error figures of one IMU (both are the same part).
    rate_hz : float
        Sample rate, Hz.
    gravity_mps2 : float
        Local gravity, m/s².

    Returns
    -------
    DualFilterParams
        The filter's parameters.
    """
    acc_white = profile.acc_noise_mps2_rthz * math.sqrt(rate_hz)
    gyr_white = profile.gyr_noise_radps_rthz * math.sqrt(rate_hz)
    # 1σ of the smoothed backward difference of the averaged rate (white, σ_w² = gyr_white²/2): with
    # e_k = (1 − α) e_{k−1} + α (u_k − u_{k−1})/Δt, Var e = (α/Δt)² σ_w² · 2/(2 − α)
    alpha = WDOT_SMOOTHING
    return DualFilterParams(
        sig_acc_both=math.hypot(acc_white / math.sqrt(2.0), profile.motion_acc_mps2),
        sig_acc_one=math.hypot(acc_white, profile.motion_acc_mps2),
        sig_gyr_both=math.hypot(gyr_white / math.sqrt(2.0), profile.motion_gyr_radps),
        sig_gyr_one=math.hypot(gyr_white, profile.motion_gyr_radps),
        ba_rw=float(profile.acc_bias_rw_mps3_rthz),
        bg_rw=float(profile.gyr_bias_rw_radps2_rthz),
        zupt=float(profile.zupt_sigma_mps),
        zaru=math.hypot(profile.zaru_sigma_radps, gyr_white),
        g=float(gravity_mps2),
        zaru_gate=float(ZARU_GATE_CHI2_3DOF),
        roll_lever=float(profile.roll_lever_m),
        acc_scale=float(profile.acc_scale_error),
        gyr_scale=float(profile.gyr_scale_error),
        gyr_white=float(gyr_white),
        acc_white=float(acc_white),
        acc_full_scale=float(ACC_FULL_SCALE_MPS2),
        gyr_full_scale=float(GYR_FULL_SCALE_RADPS),
        wdot_sigma=float(alpha * gyr_white * rate_hz / math.sqrt(2.0 - alpha)),
        zupt_vert_stat=float(profile.zupt_vertical_sigma_mps),
        zupt_gate=float(ZUPT_GATE_NIS),
        zupt_gate_ratio=float(ZUPT_GATE_RATIO),
    )


def run_dual_eskf(
    t_s: F64,
    acc_b_mps2: F64,
    gyr_b_radps: F64,
    stance: NDArray[np.bool_],
    lever_b_m: F64,
    rate_hz: float,
    config: DualEskfConfig | None = None,
    zupt_ratio: F64 | None = None,
) -> DualEskfTrack:
    """Run footnav's dual-IMU filter over a whole record.

    Parameters
    ----------
    t_s : ndarray, shape (n,)
        Sample times, s; the record must start with ``config.align_s`` still.
    acc_b_mps2, gyr_b_radps : ndarray, shape (n, 2, 3)
        IMU 1 and IMU 2 measurements (parallel axes), m/s² and rad/s.
    stance : ndarray of bool, shape (n,)
        Zero-velocity detector output.
    lever_b_m : ndarray, shape (3,)
        IMU 2's position in IMU 1's axes, m.
    zupt_ratio : ndarray, shape (n,), optional
        The detector's statistic over its threshold, T/γ: the vertical ZUPT noise follows it as in
        ``footnav.pipeline.navigation.eskf``; None: the same noise on every axis.
    """
    cfg = config or DualEskfConfig()
    acc = np.ascontiguousarray(acc_b_mps2, dtype=np.float64)
    gyr = np.ascontiguousarray(gyr_b_radps, dtype=np.float64)
    window = still_window(acc, gyr, rate_hz, cfg.align_s)
    stream = DualEskfStream(cfg, lever_b_m, rate_hz, acc[window], gyr[window])
    dt = sample_intervals(t_s, t_s[0] - 1.0 / rate_hz, cfg.dt_max_s)
    return stream.step(t_s, acc, gyr, stance, dt, zupt_ratio)


class DualEskfStream:
    """The filter's state between batches: :meth:`step` runs it over the next samples.

    Parameters
    ----------
    config : DualEskfConfig
        Filter settings.
    lever_b_m : ndarray, shape (3,)
        IMU 2's position in IMU 1's axes, m.
    rate_hz : float
        Nominal sample rate, Hz.
    acc_still_b_mps2, gyr_still_b_radps : ndarray, shape (w, 2, 3)
        Still samples to align on (the first of the stream).
    """

    def __init__(
        self, config: DualEskfConfig, lever_b_m: F64, rate_hz: float, acc_still_b_mps2: F64, gyr_still_b_radps: F64
    ) -> None:
        cfg, prof = config, config.profile
        al = align_from_still(acc_still_b_mps2.mean(axis=1), gyr_still_b_radps.mean(axis=1))
        self.lever_b_m = np.asarray(lever_b_m, dtype=np.float64).reshape(3)
        x = np.zeros(N_NOMINAL)
        x[6:10] = al.quat_nb_wxyz
        R = np.empty((3, 3))
        quat_to_mat_into(x[6], x[7], x[8], x[9], R)
        x[0:3] = 0.5 * (R @ self.lever_b_m)  # the midpoint; IMU 1 starts at the origin
        sig = initial_error_sigmas(cfg, prof, imus=2)
        self.x = x
        self.P = np.diag(sig**2)
        self.aux = np.zeros(N_AUX)
        self.par = dual_parameters(prof, rate_hz, al.gravity_for(cfg.gravity_mps2))
        self.counters = np.zeros(N_CNT, dtype=np.int64)
        self._imu_ok: list[NDArray[np.bool_]] = []
        self._t: list[F64] = []

    def step(
        self,
        t_s: F64,
        acc_b_mps2: F64,
        gyr_b_radps: F64,
        stance: NDArray[np.bool_],
        dt_s: F64,
        zupt_ratio: F64 | None = None,
    ) -> DualEskfTrack:
        """Run over (n,) samples: ``acc``/``gyr`` (n, 2, 3), ``stance`` (n,), ``dt_s`` (n,) the interval
        before each sample, s, ``zupt_ratio`` (n,) T/γ (:func:`run_dual_eskf`). Counters and messages
        cover everything since the start."""
        n = t_s.shape[0]
        ratio = np.zeros(n) if zupt_ratio is None else np.ascontiguousarray(zupt_ratio, dtype=np.float64)
        m = self.lever_b_m
        out_x = np.empty((n, N_NOMINAL))
        out_cov = np.empty((n, 3, 3))
        out_res = np.empty((n, 6))
        out_nis = np.empty(n)
        out_ok = np.empty((n, 2), dtype=np.bool_)
        run_dual_filter(
            self.x, self.P, self.aux,
            np.ascontiguousarray(acc_b_mps2, dtype=np.float64), np.ascontiguousarray(gyr_b_radps, dtype=np.float64),
            np.ascontiguousarray(dt_s, dtype=np.float64), np.ascontiguousarray(stance), ratio, m, self.par,
            out_x, out_cov, out_res, out_nis, out_ok, self.counters,
        )  # fmt: skip
        if not out_ok.all():
            self._imu_ok.append(out_ok)
            self._t.append(np.asarray(t_s, dtype=np.float64))
        quat = out_x[:, 6:10]
        half_cm = 0.5 * np.einsum("nij,j->ni", quat_to_mats(quat), m)
        centre = out_x[:, 0:3]
        return DualEskfTrack(
            pos1_n_m=centre - half_cm,
            pos_imu_n_m=np.stack([centre - half_cm, centre + half_cm], axis=1),
            vel_n_mps=out_x[:, 3:6].copy(),
            quat_nb_wxyz=quat.copy(),
            pos_cov_n_m2=out_cov,
            bias_b=out_x[:, 10:22].reshape(n, 4, 3).copy(),
            residual_rate_radps=out_res[:, :3],
            residual_force_mps2=out_res[:, 3:],
            nis_rate=out_nis,
            imu_ok=out_ok,
            counters={name: int(self.counters[i]) for i, name in enumerate(COUNTER_NAMES)},
            messages=self.messages(),
        )

    def messages(self) -> tuple[str, ...]:
        """Plain-language report of the unusable samples so far (batches where both IMUs were fine
        are not kept)."""
        if not self._imu_ok:
            return ()
        return tuple(fault_report(np.concatenate(self._imu_ok), np.concatenate(self._t)))
