"""The causal navigator: SHOE detection + error-state filter over a stream of sample batches.

``Navigator.process`` takes one ``ImuBatch`` at a time and returns the estimates for every sample it
could navigate. Until the unit has been quiet for ``align_s`` it buffers; it then aligns on that
period and navigates from its first sample, so a walk that starts still loses nothing. "Quiet" for
alignment is a physical bound of its own (|ω| and the spread of |f| small), independent of the
zero-velocity detector, whose adaptive threshold knows nothing before the first steps. Samples
before the first quiet period cannot be navigated and are counted, not guessed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from footnav.pipeline.aiding.baro import PressureAltimeter, PressureAltitude, PressureBatch
from footnav.pipeline.aiding.tof import TofAiding
from footnav.pipeline.aiding.tof_types import RangeBatch, RangeOutputs, TofConfig
from footnav.pipeline.gait.clearance import StrideClearanceTracker
from footnav.pipeline.nav_types import NavBatch
from footnav.pipeline.navigation import eskf
from footnav.pipeline.navigation._kernels import run_filter_kernel
from footnav.pipeline.navigation.alignment import Alignment, align_from_still, first_quiet_run, quiet_samples
from footnav.pipeline.navigation.batches import clip_variance, implausible_to_nan, nav_batch, zupt_ratio
from footnav.pipeline.navigation.params import FilterParams
from footnav.pipeline.navigation.profiles import G0_MPS2, UnitProfile, get_profile
from footnav.pipeline.navigation.warm import build_kernels
from footnav.pipeline.samples import ImuBatch
from footnav.pipeline.stance.detectors import DetectorParams, StreamingDetector, true_runs
from footnav.pipeline.stance.height_detector import HeightStanceDetector
from footnav.pipeline.stance.levels import StanceLevelParams, StanceLevels
from numpy.typing import NDArray

F64 = NDArray[np.float64]

DEFAULT_DT_MAX_S = 0.05
"""Intervals this long or longer are gaps in the stream (50 samples at 1 kHz, 10 at 200 Hz)."""
ZARU_GATE_CHI2_3DOF = 7.815
"""χ²(3) at 95 %: the gate of the zero-angular-rate update, which rejects the samples of a rotating foot
(Bar-Shalom, Li, Kirubarajan, "Estimation with Applications to Tracking and Navigation", 2001, §5.4.3)."""
ZUPT_GATE_NIS = 100.0
"""A zero-velocity sample the detector is unsure of is skipped when its NIS exceeds this (10σ: the
foot is moving; ``footnav.pipeline.navigation.eskf``)."""
ZUPT_GATE_RATIO = 0.5
"""Unsure: the detector's statistic above this share of its threshold (T/γ > 0.5)."""
STANDING_AFTER_S = 2.0
"""A stance this long is a standing foot, whose zero-rate update admits a turn about the vertical
(``footnav.pipeline.navigation.eskf``), s."""
STANDING_TURN_SIGMA_RADPS = math.radians(2.0)
"""1σ of a standing foot's turn about the vertical in its zero-rate update (``footnav.pipeline.navigation.eskf``),
rad/s."""


@dataclass(frozen=True, slots=True)
class NavConfig:
    """Everything the navigator needs besides the samples.

    Attributes
    ----------
    profile
        the unit's noise model (``footnav.pipeline.navigation.profiles``).
    detector
        zero-velocity detector settings.
    align_s
        continuous quiet time needed for the initial alignment, s.
    align_max_rate_radps
        quiet means |ω| below this at every sample of the window, rad/s.
    align_max_acc_dev_mps2
        and | |f| − mean |f| | below this, m/s².
    dt_max_s
        intervals this long or longer are gaps in the stream, counted and integrated as this long
        (``eskf.sample_intervals``), s.
    init_pos_sigma_m, init_vel_sigma_mps
        initial 1σ of position and velocity.
    init_tilt_sigma_rad, init_yaw_sigma_rad
        initial 1σ of roll/pitch and of yaw.
    max_wait_s
        how much unaligned data to keep while waiting for a still period, s.
    stance_levels
        apply the stance height constraint (``footnav.pipeline.stance.levels``: a stance on the floor of the last one is
        at its height; height changes of a stair or more are kept). With ToF readings their own floor levels
        (``footnav.pipeline.aiding.tof``) take its place.
    gravity_mps2
        the magnitude of gravity where the unit walks, m/s² (standard gravity by default: within 0.27 % of the value
        anywhere at sea level, 9.780 at the equator to 9.832 at the poles in the WGS 84 model, Groves 2013 ch. 2). The
        accelerometer's reading at rest differs from it by its bias, which the filter then estimates. 0 or less takes
        |f̄| of the still start for gravity instead (docs/design/estimator.md says why that is not the default).
    step_smoothing
        a live session (and its replay) also shows each step smoothed once it has ended
        (``footnav.pipeline.smoothing.stepwise``; its causal filter holds the stance levels as constants). Off by
        default for its cost (docs/design/smoothing.md). The :class:`Navigator` itself is causal only:
        ``footnav.app.feet.foot_run`` picks the class.
    """

    profile: UnitProfile = field(default_factory=lambda: get_profile("mpu6500x4"))
    detector: DetectorParams = field(default_factory=DetectorParams)
    align_s: float = 0.5
    align_max_rate_radps: float = 0.3
    align_max_acc_dev_mps2: float = 0.5
    dt_max_s: float = DEFAULT_DT_MAX_S
    init_pos_sigma_m: float = 1e-5
    init_vel_sigma_mps: float = 0.01
    init_tilt_sigma_rad: float = math.radians(0.5)
    init_yaw_sigma_rad: float = math.radians(0.01)
    max_wait_s: float = 30.0
    stance_levels: bool = True
    gravity_mps2: float = G0_MPS2
    step_smoothing: bool = False


@dataclass
class NavStats:
    """Running counts a person wants to see (all samples, since the start)."""

    samples_in: int = 0
    samples_out: int = 0
    samples_before_alignment: int = 0
    """Samples before the first still period the navigator aligned on."""
    samples_navigated_backwards: int = 0
    """Of those, the ones navigated backwards in time from that still period (whole recordings only:
    ``footnav.pipeline.navigation.lead_in``); the rest were not navigated."""
    bad_dt: int = 0
    gaps: int = 0
    bad_samples: int = 0
    zero_velocity_updates: int = 0
    zero_velocity_rejected: int = 0
    zero_rate_updates: int = 0
    zero_rate_rejected: int = 0
    rates_clipped: int = 0
    """Gyroscope values taken as clipped at the sensor's range and navigated as uncertain (whole
    recordings only: ``footnav.pipeline.navigation.saturation``)."""
    rates_reconstructed: int = 0
    """Of those, the values the reconstruction raised."""
    aligned_at_s: float | None = None


class InitialSigmas(Protocol):
    """The initial 1σ a navigator's configuration holds (``NavConfig``, ``DualEskfConfig``)."""

    @property
    def init_pos_sigma_m(self) -> float: ...
    @property
    def init_vel_sigma_mps(self) -> float: ...
    @property
    def init_tilt_sigma_rad(self) -> float: ...
    @property
    def init_yaw_sigma_rad(self) -> float: ...


def initial_error_sigmas(cfg: InitialSigmas, profile: UnitProfile, imus: int = 1) -> F64:
    """Initial 1σ of the error state (9 + 6·imus,): position, velocity, attitude (roll, pitch, yaw),
    then each IMU's accelerometer and gyroscope bias (the profile's turn-on priors)."""
    biases = [np.full(3, profile.acc_bias_init_mps2), np.full(3, profile.gyr_bias_init_radps)] * imus
    return np.concatenate(
        [
            np.full(3, cfg.init_pos_sigma_m),
            np.full(3, cfg.init_vel_sigma_mps),
            [cfg.init_tilt_sigma_rad, cfg.init_tilt_sigma_rad, cfg.init_yaw_sigma_rad],
            *biases,
        ]
    )


def filter_start(config: NavConfig, rate_hz: float, alignment: Alignment) -> tuple[F64, F64, FilterParams]:
    """The filter's nominal state (16,), covariance (15, 15) and parameters (``FilterParams``) after
    the alignment ``alignment`` of a still start, as the navigator starts it: the aligned attitude at
    the origin, at rest; the biases at 0, their prior the profile's (a quiet foot may still turn)."""
    x = np.zeros(16)
    x[6:10] = alignment.quat_nb_wxyz
    P = np.diag(initial_error_sigmas(config, config.profile) ** 2)
    par = filter_parameters(config.profile, rate_hz, alignment.gravity_for(config.gravity_mps2), config.dt_max_s)
    return x, P, par


def filter_parameters(profile: UnitProfile, rate_hz: float, gravity_mps2: float, dt_max_s: float) -> FilterParams:
    """Parameters of ``eskf.run_filter`` from a unit profile.

    The per-sample process noise combines the sensor's white noise at this rate (σ = density·√rate)
    with the profile's motion noise; the zero-angular-rate gate uses the gyroscope's white noise alone
    (``footnav.pipeline.navigation.eskf``).

    Parameters
    ----------
    profile : UnitProfile
        The unit's noise and error figures.
    rate_hz : float
        Sample rate, Hz.
    gravity_mps2 : float
        Local gravity, m/s².
    dt_max_s : float
        Intervals this long or longer are gaps, s.

    Returns
    -------
    FilterParams
        The filter's parameters.
    """
    gyr_white_radps = profile.gyr_noise_radps_rthz * math.sqrt(rate_hz)
    return FilterParams(
        sig_acc=math.hypot(profile.acc_noise_mps2_rthz * math.sqrt(rate_hz), profile.motion_acc_mps2),
        sig_gyr=math.hypot(profile.gyr_noise_radps_rthz * math.sqrt(rate_hz), profile.motion_gyr_radps),
        ba_rw=float(profile.acc_bias_rw_mps3_rthz),
        bg_rw=float(profile.gyr_bias_rw_radps2_rthz),
        zupt=float(profile.zupt_sigma_mps),
        zaru=math.hypot(profile.zaru_sigma_radps, gyr_white_radps),
        g=float(gravity_mps2),
        dt_max=float(dt_max_s),
        zaru_gate=float(ZARU_GATE_CHI2_3DOF),
        roll_lever=float(profile.roll_lever_m),
        acc_scale=float(profile.acc_scale_error),
        gyr_scale=float(profile.gyr_scale_error),
        zupt_vert_stat=float(profile.zupt_vertical_sigma_mps),
        zaru_gate_sig=float(gyr_white_radps),
        zupt_gate=float(ZUPT_GATE_NIS),
        zupt_gate_ratio=float(ZUPT_GATE_RATIO),
        standing_turn=float(STANDING_TURN_SIGMA_RADPS),
        standing_after=float(STANDING_AFTER_S * rate_hz),
    )


class Navigator:
    """Causal zero-velocity-aided INS over a stream of ``ImuBatch``es.

    ToF range readings (:meth:`add_ranges`) are applied between IMU samples: the batch is split at
    each reading's time, the filter runs up to the last sample not after it, the reading updates the
    state (``footnav.pipeline.aiding.tof``), and the filter goes on. A reading older than the last sample
    already navigated (it arrived in a later read than that sample) is applied before the next
    sample and counted as ``late``. Without readings the batch runs in one call, as fast as before.

    Parameters
    ----------
    config
        filter, detector and profile settings.
    rate_hz
        nominal sample rate (sizes the detector window and the process noise).
    tof
        ToF sensor mounting and aiding settings (default :class:`TofConfig`).
    """

    def __init__(self, config: NavConfig, rate_hz: float, tof: TofConfig | None = None) -> None:
        build_kernels()  # on two cores, the first time (``footnav.pipeline.navigation.warm``)
        self.config = config
        self.tof = TofAiding(tof or TofConfig())
        self.altimeter = PressureAltimeter()
        self._altitude: list[PressureAltitude] = []
        self._strides = StrideClearanceTracker()
        self.stats = NavStats()
        self._pending: list[tuple[ImuBatch, F64, F64, NDArray[np.bool_]]] = []
        self._x: F64 | None = None
        self._P = np.zeros((eskf.N_STATE, eskf.N_STATE))
        self._t_last = math.nan
        self._counters = np.zeros(eskf.N_CNT, dtype=np.int64)
        self._filter_state = eskf.new_filter_state()
        self._last_still = True  # the last sample's stance (for a reading due before a batch): aligned still
        self.whole_recording = False  # one batch holds the whole recording: its last quiet flags are final
        self._init_rate(rate_hz)
        self.level_updates: list[tuple[int, float]] | None = None
        """When a list: each stance height update, as (sample index since alignment, level height)."""
        self._filter_inputs: tuple[F64, F64, F64, F64, NDArray[np.bool_], F64] | None = None
        """The filter's inputs of the last batch: acc, gyr, clipped-rate variance, Δt, stance, T/γ."""

    def _init_rate(self, rate_hz: float) -> None:
        """The parts sized by the sample rate: detectors, stance levels, the filter's noise."""
        self.rate_hz = rate_hz
        tof_cfg = self.tof.config
        self.height_detector = (
            None
            if tof_cfg.detector.mode == "inertial"
            else HeightStanceDetector(
                tof_cfg.detector, np.asarray(tof_cfg.lever_b_m), np.asarray(tof_cfg.dir_b), rate_hz
            )
        )
        self.detector = StreamingDetector(self.config.detector, rate_hz)
        self._par = filter_parameters(self.config.profile, rate_hz, G0_MPS2, self.config.dt_max_s)  # until aligned
        self.levels = StanceLevels(StanceLevelParams(use=self.config.stance_levels), rate_hz)

    def retime(self, rate_hz: float) -> None:
        """Navigate at ``rate_hz`` instead of the rate given at construction (the unit's clock has
        told the real one); only before the first sample.

        Raises
        ------
        RuntimeError
            samples have already been given.
        """
        if self.stats.samples_in:
            raise RuntimeError("the sample rate can only change before the first sample")
        self._init_rate(rate_hz)

    @property
    def aligned(self) -> bool:
        return self._x is not None

    @property
    def state(self) -> F64 | None:
        """Nominal state (16,) [p, v, q_wxyz, b_a, b_g], or None before alignment."""
        return None if self._x is None else self._x[:16].copy()

    @property
    def position_cov(self) -> F64 | None:
        """Covariance of the position error (3, 3), m², or None before alignment."""
        return None if self._x is None else self._P[eskf.P0 : eskf.P0 + 3, eskf.P0 : eskf.P0 + 3].copy()

    def update_position(self, h_n: F64, innovation_m: float, var_m2: float) -> None:
        """One external scalar update of the position between batches: z = hᵀ p + e, e ~ N(0, ``var_m2``),
        innovation z − hᵀ p̂ = ``innovation_m``, h (3,) in the navigation frame. Joseph form, injection and
        reset as the filter's own updates (``eskf.update1``); the next sample starts from the result. For
        constraints between navigators (``footnav.pipeline.two_feet``); not used by one foot. No-op before
        alignment."""
        if self._x is None:
            return
        h = np.asarray(h_n, dtype=np.float64)
        u = np.ascontiguousarray(self._P[:, eskf.P0 : eskf.P0 + 3] @ h)
        s = float(h @ u[eskf.P0 : eskf.P0 + 3]) + var_m2
        eskf.update1(self._x, self._P, u, s, float(innovation_m), np.empty(self._P.shape[0]))
        if self.tof.active:
            self.tof.sync(self._x)

    @property
    def error_cov(self) -> F64 | None:
        """Covariance (15, 15) of the error state [δp, δv, δθ, δb_a, δb_g] (``eskf``), or None before
        alignment."""
        return None if self._x is None else self._P[: eskf.N_STATE, : eskf.N_STATE].copy()

    def update_error_state(self, h: F64, innovation: float, var: float) -> None:
        """One external scalar update over the error state between batches: z = h δx + e,
        e ~ N(0, ``var``), innovation ``innovation``, h (15,) over [δp, δv, δθ, δb_a, δb_g] (the
        attitude error δθ in the navigation frame: δθ_z at index ``eskf.TH0 + 2`` turns the heading).
        Joseph form, injection and reset as ``update_position``; for constraints between navigators
        (``footnav.pipeline.two_feet.heading``); not used by one foot. No-op before alignment."""
        if self._x is None:
            return
        h = np.asarray(h, dtype=np.float64)
        u = np.ascontiguousarray(self._P[:, : eskf.N_STATE] @ h)
        s = float(h @ u[: eskf.N_STATE]) + var
        eskf.update1(self._x, self._P, u, s, float(innovation), np.empty(self._P.shape[0]))
        if self.tof.active:
            self.tof.sync(self._x)

    def add_error_variance(self, index: int, var: float) -> None:
        """Add ``var`` to the variance of error state ``index`` (process noise the filter's own model
        lacks, added by a constraint between navigators); no-op before alignment."""
        if self._x is not None:
            self._P[index, index] += var

    def add_ranges(self, readings: RangeBatch) -> None:
        """Queue ToF readings; each is applied when the IMU samples reach its time (and, with a
        height-aided detector, gives the foot's height to the stance detection)."""
        self.tof.add(readings)
        if self.height_detector is not None and len(readings):
            order = np.argsort(readings.t_s, kind="stable")
            r = readings.select(order)
            self.height_detector.add(r.t_s, r.sensor, r.range_m, r.status)

    def add_pressure(self, readings: PressureBatch) -> None:
        """Barometer readings: converted to pressure altitude and passed on with the next estimates
        (shown, not used in estimation: see ``footnav.pipeline.aiding.baro``)."""
        if len(readings):
            self._altitude.append(self.altimeter.update(readings))

    def process(self, batch: ImuBatch) -> NavBatch | None:
        """Estimates for the samples of ``batch`` (and any buffered before alignment)."""
        if len(batch) == 0:
            return None
        self.stats.samples_in += len(batch)
        batch = implausible_to_nan(batch)
        stat, threshold, still = self.detector.update(batch.acc_b_mps2, batch.gyr_b_radps)
        if self.height_detector is not None:
            still = self.height_detector.update(batch.t_s, batch.acc_b_mps2, batch.gyr_b_radps, still)
        if self._x is None:
            self._pending.append((batch, stat, threshold, still))
            return self._try_align()
        return self._run(batch, stat, threshold, still)

    def _try_align(self) -> NavBatch | None:
        batch = ImuBatch.concat([b for b, _, _, _ in self._pending])
        stat = np.concatenate([s for _, s, _, _ in self._pending])
        threshold = np.concatenate([t for _, _, t, _ in self._pending])
        still = np.concatenate([z for _, _, _, z in self._pending])
        cfg = self.config
        need, limits = max(2, round(cfg.align_s * self.rate_hz)), (cfg.align_max_rate_radps, cfg.align_max_acc_dev_mps2)
        start = first_quiet_run(batch.acc_b_mps2, batch.gyr_b_radps, need, *limits, complete=self.whole_recording)
        if start < 0:
            keep = round(self.config.max_wait_s * self.rate_hz)
            if len(batch) > keep:  # bound memory while the unit never rests
                drop = len(batch) - keep
                self.stats.samples_before_alignment += drop
                batch, stat, threshold, still = (
                    batch.select(slice(drop, None)),
                    stat[drop:],
                    threshold[drop:],
                    still[drop:],
                )
            self._pending = [(batch, stat, threshold, still)]
            return None
        self._pending = []
        self.stats.samples_before_alignment += start
        window = slice(start, start + need)
        al = align_from_still(batch.acc_b_mps2[window], batch.gyr_b_radps[window])
        self._x, self._P, self._par = filter_start(self.config, self.rate_hz, al)
        self.stats.aligned_at_s = float(batch.t_s[start])
        self._t_last = float(batch.t_s[start]) - 1.0 / self.rate_hz  # one nominal interval before
        rest = batch.select(slice(start, None))
        self.tof.drop_before(float(batch.t_s[start]))
        return self._run(rest, stat[start:], threshold[start:], still[start:])

    def _quiet(self, batch: ImuBatch) -> NDArray[np.bool_]:
        """Samples quiet enough to align on (see ``NavConfig``)."""
        cfg = self.config
        need = max(2, round(cfg.align_s * self.rate_hz))
        return quiet_samples(
            batch.acc_b_mps2, batch.gyr_b_radps, need, cfg.align_max_rate_radps, cfg.align_max_acc_dev_mps2
        )

    def _run(self, batch: ImuBatch, stat: F64, threshold: F64, still: NDArray[np.bool_]) -> NavBatch:
        assert self._x is not None
        n = len(batch)
        dt = eskf.sample_intervals(batch.t_s, self._t_last, self.config.dt_max_s)
        self._t_last = float(batch.t_s[-1])
        pos, vel = np.empty((n, 3)), np.empty((n, 3))
        quat, cov = np.empty((n, 4)), np.empty((n, 4, 4))
        acc = np.ascontiguousarray(batch.acc_b_mps2, dtype=np.float64)
        gyr = np.ascontiguousarray(batch.gyr_b_radps, dtype=np.float64)
        gyr_var = clip_variance(batch)
        still_c = np.ascontiguousarray(still)
        ratio = zupt_ratio(stat, threshold)
        self._filter_inputs = (acc, gyr, gyr_var, dt, still_c, ratio)  # for subclasses that keep them
        floor_z: F64 | None = None
        floor_c: F64 | None = None
        ranges: RangeOutputs | None = None
        if not self.tof.active:
            floor_c = self._run_with_levels(acc, gyr, gyr_var, dt, still_c, ratio, pos, vel, quat, cov)
        else:
            floor_z, floor_c, ranges = self._run_with_ranges(
                batch, acc, gyr, gyr_var, dt, still_c, ratio, pos, vel, quat, cov
            )
        c = self._counters
        s = self.stats
        s.bad_dt, s.gaps = int(c[eskf.CNT_BAD_DT]), int(c[eskf.CNT_GAP])
        s.bad_samples, s.zero_velocity_updates = int(c[eskf.CNT_BAD_SAMPLE]), int(c[eskf.CNT_UPDATES])
        s.zero_rate_updates, s.zero_rate_rejected = int(c[eskf.CNT_ZARU]), int(c[eskf.CNT_ZARU_REJECTED])
        s.zero_velocity_rejected = int(c[eskf.CNT_ZUPT_REJECTED])
        s.samples_out += n
        self._last_still = bool(still[-1])
        clearance = pos[:, 2].copy() if floor_c is None else pos[:, 2] - floor_c
        strides = self._strides.update(batch.t_s, clearance, still)
        altitude = None
        if self._altitude:
            altitude = PressureAltitude(
                np.concatenate([a.t_s for a in self._altitude]), np.concatenate([a.altitude_m for a in self._altitude])
            )
            self._altitude = []
        return nav_batch(
            batch,
            pos,
            vel,
            quat,
            cov,
            stat,
            threshold,
            still,
            floor_z_m=floor_z,
            ranges=ranges,
            clearance_m=clearance,
            strides=strides,
            altitude=altitude,
        )

    def _run_with_levels(
        self, acc: F64, gyr: F64, gyr_var: F64, dt: F64, still: NDArray[np.bool_], ratio: F64,
        pos: F64, vel: F64, quat: F64, cov: F64,
    ) -> F64:  # fmt: skip
        """The filter over a batch with the stance height constraint applied once in each stance
        (``footnav.pipeline.stance.levels``): the batch is split there. Returns the height of the floor each
        sample's clearance is measured from (n,): the level of its stance, or in swing the level of
        the stance before (the start floor, z = 0, without the constraint)."""
        assert self._x is not None
        n = still.shape[0]
        floor = np.empty(n)
        levels, state, rejected = self.levels, self._filter_state, eskf.STATE_LAST_REJECTED
        points = np.asarray(levels.update_points(still), dtype=np.int64)
        # for an update after a stance sample of this batch, the stance's first sample here (-1: none): the
        # samples from it on stand on the stance's level
        firsts = np.full(points.shape[0] + 1, -1, dtype=np.int64)
        on_stance = (points > 0) & still[np.maximum(points - 1, 0)]
        if on_stance.any():
            stance_starts = true_runs(still)[0]
            firsts[:-1][on_stance] = stance_starts[np.searchsorted(stance_starts, points[on_stance] - 1, "right") - 1]
        a = 0
        for b, first in zip([*points.tolist(), None], firsts.tolist(), strict=True):  # None: the rest, no update
            end = n if b is None else b
            floor[a:end] = levels.floor_z_m
            if end > a:
                run_filter_kernel(
                    self._x, self._P, acc[a:end], gyr[a:end], gyr_var[a:end], dt[a:end], still[a:end], ratio[a:end],
                    self._par, pos[a:end], vel[a:end], quat[a:end], cov[a:end], self._counters, state,
                )  # fmt: skip
            # a stance whose update sample the filter found moving (``footnav.pipeline.navigation.eskf``) gives no level
            if b is not None and not state[rejected]:
                self._x, self._P, z_level = levels.stance_update(self._x, self._P)
                if self.level_updates is not None and math.isfinite(z_level):
                    self.level_updates.append((self.stats.samples_out + b - 1, z_level))
                if first >= 0:
                    floor[first:b] = levels.floor_z_m
            a = end
        return floor

    def _run_with_ranges(
        self,
        batch: ImuBatch,
        acc: F64,
        gyr: F64,
        gyr_var: F64,
        dt: F64,
        still: NDArray[np.bool_],
        ratio: F64,
        pos: F64,
        vel: F64,
        quat: F64,
        cov: F64,
    ) -> tuple[F64, F64, RangeOutputs]:
        """The filter over ``batch`` with the due ToF readings applied at their times (class docstring);
        returns the floor height under the IMU per sample, the floor height the clearance is measured
        from (``TofAiding.floor_under``, with the levels' heights as of the last reading before the sample,
        whatever the batches) and what became of each reading."""
        assert self._x is not None
        x, P, par, cnt = self._x, self._P, self._par, self._counters
        n = len(batch)
        due = self.tof.take_due(float(batch.t_s[-1]))
        m = len(due)
        # reading j is applied after sample at[j] (the last one not after it); -1: before sample 0
        at = np.searchsorted(batch.t_s, due.t_s, side="right") - 1
        self.tof.counts.add("late", int(np.count_nonzero(at < 0)))
        heights, codes, innov, floors = np.full(m, np.nan), np.zeros(m, np.int64), np.full(m, np.nan), np.zeros(m)
        hits = np.full((m, 4), np.nan)
        floor_z, floor_c = np.empty(n), np.empty(n)
        a = 0
        for j in range(m + 1):
            b = n if j == m else int(at[j]) + 1
            if b > a:
                eskf.run_filter(
                    x,
                    P,
                    acc[a:b],
                    gyr[a:b],
                    gyr_var[a:b],
                    dt[a:b],
                    still[a:b],
                    ratio[a:b],
                    par,
                    pos[a:b],
                    vel[a:b],
                    quat[a:b],
                    cov[a:b],
                    cnt,
                    self._filter_state,
                )
                floor_z[a:b], floor_c[a:b] = self.tof.floor_under(pos[a:b], still[a:b])
                a = b
            if j < m:
                self.tof.sync(x)
                x, P = self._x, self._P = self.tof.reserve(x, P)
                stance = bool(still[a - 1]) if a > 0 else self._last_still
                codes[j], heights[j], innov[j] = self.tof.apply(
                    x, P, float(due.t_s[j]), int(due.sensor[j]), float(due.range_m[j]), int(due.status[j]), stance
                )
                floors[j] = self.tof.floor_z_m
                if self.tof.last_hit is not None:
                    hits[j] = self.tof.last_hit
        outputs = RangeOutputs(
            due.t_s, due.sensor, due.status, heights, codes, innov, floors, hits[:, :3], hits[:, 3] == 1.0
        )
        return floor_z, floor_c, outputs


def navigate(
    t_s: F64,
    acc_b_mps2: F64,
    gyr_b_radps: F64,
    rate_hz: float,
    config: NavConfig | None = None,
    *,
    ranges: RangeBatch | None = None,
    tof: TofConfig | None = None,
    gyr_clipped_b: NDArray[np.bool_] | None = None,
) -> tuple[NavBatch | None, NavStats]:
    """Run the causal navigator over whole arrays (tests, export, evaluation), with ToF ``ranges``
    when given, and the rates marked clipped in ``gyr_clipped_b`` (n, 3)
    (``footnav.pipeline.navigation.saturation``)."""
    nav = Navigator(config or NavConfig(), rate_hz, tof=tof)
    nav.whole_recording = True
    if ranges is not None:
        nav.add_ranges(ranges)
    n = t_s.shape[0]
    out = nav.process(
        ImuBatch(t_s, acc_b_mps2, gyr_b_radps, np.arange(n, dtype=np.int64), np.zeros(n, dtype=np.int64), gyr_clipped_b)
    )
    return out, nav.stats
