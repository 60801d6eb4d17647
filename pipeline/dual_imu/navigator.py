"""The causal dual-IMU navigator: SHOE detection on IMU 1 + footnav's dual-IMU filter, over a stream.

``DualNavigator.process`` takes one two-IMU batch at a time (anything with ``t_s`` (n,),
``acc_b_mps2`` and ``gyr_b_radps`` (n, 2, 3) and ``host_ns`` (n,), e.g. the device layer's raw-IMU
batch of the dual board) and returns a :class:`~footnav.pipeline.nav_types.NavBatch` of IMU 1's position
(velocity: the board midpoint's, which differs from IMU 1's by ``C (ω × m/2)``), so every sink of
the single-IMU navigator (Rerun, export, status) works unchanged. Like
:class:`~footnav.pipeline.navigation.navigator.Navigator` it buffers until both IMUs have been quiet for ``align_s``,
aligns there, and navigates from that sample. The detector runs on IMU 1 (the same detector as the
single-IMU navigator, so the two see the same stance); if IMU 1 is unusable at a sample, IMU 2's
sample stands in for the detector.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from footnav.pipeline.dual_imu.board_eskf import (
    AUX_LAST_REJECTED,
    DualEskfConfig,
    DualEskfStream,
    DualEskfTrack,
    concat_tracks,
)
from footnav.pipeline.dual_imu.model import ACC_FULL_SCALE_MPS2, GYR_FULL_SCALE_RADPS
from footnav.pipeline.nav_types import NavBatch
from footnav.pipeline.navigation.batches import zupt_ratio
from footnav.pipeline.navigation.eskf import sample_intervals
from footnav.pipeline.navigation.navigator import NavStats
from footnav.pipeline.stance.detectors import DetectorParams, StreamingDetector
from footnav.pipeline.stance.levels import StanceLevelParams, StanceLevels
from numpy.typing import NDArray

F64 = NDArray[np.float64]

DEFAULT_LEVER_B_M: tuple[float, float, float] = (0.01, 0.01, 0.0)
"""IMU 2's position in IMU 1's body axes on the default board, m (1.4 cm apart; Chen et al. 2022 use 1-2 cm)."""


class TwoImuSamples(Protocol):
    """A batch of a two-IMU board (the device layer's ``RawImuBatch`` with two IMUs is one)."""

    @property
    def t_s(self) -> F64:
        """(n,) device time, s."""
        ...

    @property
    def acc_b_mps2(self) -> F64:
        """(n, 2, 3) specific force of IMU 1 and IMU 2, m/s²."""
        ...

    @property
    def gyr_b_radps(self) -> F64:
        """(n, 2, 3) angular rate, rad/s."""
        ...

    @property
    def host_ns(self) -> NDArray[np.int64]:
        """(n,) host receive time."""
        ...


@dataclass(frozen=True, slots=True)
class DualNavConfig:
    """Settings of the dual-IMU navigator.

    Attributes
    ----------
    filter
        the dual-IMU filter's settings (profile, alignment time, initial uncertainty).
    detector
        zero-velocity detector settings.
    lever_b_m
        IMU 2's position in IMU 1's axes, m.
    align_max_rate_radps
        quiet for alignment means |ω| below this on both IMUs, rad/s.
    max_wait_s
        unaligned data kept while waiting for a still period, s.
    stance_levels
        apply the stance height constraint of the single-IMU navigator (``footnav.pipeline.stance.levels``) to the
        board's midpoint, its levels constants (the dual filter's state has a fixed size).
    """

    filter: DualEskfConfig = field(default_factory=DualEskfConfig)
    detector: DetectorParams = field(default_factory=DetectorParams)
    lever_b_m: tuple[float, float, float] = DEFAULT_LEVER_B_M
    align_max_rate_radps: float = 0.3
    max_wait_s: float = 30.0
    stance_levels: bool = True


class DualNavigator:
    """Causal dual-IMU navigation over a stream of two-IMU batches (module docstring).

    Parameters
    ----------
    config
        settings.
    rate_hz
        nominal sample rate, Hz.
    """

    def __init__(self, config: DualNavConfig, rate_hz: float) -> None:
        self.config = config
        self.stats = NavStats()
        self.filter: DualEskfStream | None = None
        self.last_track: DualEskfTrack | None = None
        """The filter's full output for the samples of the last NavBatch returned (each IMU's track,
        biases, constraint residuals), for sinks that show more than the NavBatch holds."""
        self._pending: list[tuple[NDArray[Any], ...]] = []  # (t, acc, gyr, host, stat, threshold, still)
        self._t_last = math.nan
        self._init_rate(rate_hz)

    def _init_rate(self, rate_hz: float) -> None:
        """The parts sized by the sample rate: the detector and the stance levels."""
        self.rate_hz = rate_hz
        self.detector = StreamingDetector(self.config.detector, rate_hz)
        self.levels = StanceLevels(StanceLevelParams(use=self.config.stance_levels, level_states=0), rate_hz)

    def retime(self, rate_hz: float) -> None:
        """Navigate at ``rate_hz`` instead of the rate given at construction; only before the first
        sample (as ``Navigator.retime``).

        Raises
        ------
        RuntimeError
            samples have already been given.
        """
        if self.stats.samples_in:
            raise RuntimeError("the sample rate can only change before the first sample")
        self._init_rate(rate_hz)

    @property
    def messages(self) -> tuple[str, ...]:
        """What went wrong with either IMU so far, in plain language (empty: nothing)."""
        return () if self.filter is None else self.filter.messages()

    def process(self, batch: TwoImuSamples) -> NavBatch | None:
        """Estimates for the samples of ``batch`` (and any buffered before alignment)."""
        t = np.asarray(batch.t_s, dtype=np.float64)
        if t.shape[0] == 0:
            return None
        acc = np.asarray(batch.acc_b_mps2, dtype=np.float64)
        gyr = np.asarray(batch.gyr_b_radps, dtype=np.float64)
        if acc.ndim != 3 or acc.shape[1] != 2:
            raise ValueError(f"the dual-IMU navigator needs (n, 2, 3) samples of two IMUs, got {acc.shape}")
        self.stats.samples_in += t.shape[0]
        ok1 = np.all(np.isfinite(acc[:, 0]) & np.isfinite(gyr[:, 0]), axis=1)
        ok1 &= np.all(np.abs(np.nan_to_num(acc[:, 0])) < ACC_FULL_SCALE_MPS2, axis=1)
        ok1 &= np.all(np.abs(np.nan_to_num(gyr[:, 0])) < GYR_FULL_SCALE_RADPS, axis=1)
        det_acc = np.where(ok1[:, None], acc[:, 0], acc[:, 1])
        det_gyr = np.where(ok1[:, None], gyr[:, 0], gyr[:, 1])
        stat, threshold, still = self.detector.update(
            np.nan_to_num(np.ascontiguousarray(det_acc)), np.nan_to_num(np.ascontiguousarray(det_gyr))
        )
        host = np.asarray(batch.host_ns, dtype=np.int64)
        self._pending.append((t, acc, gyr, host, stat, threshold, still))
        if self.filter is None and not self._try_align():
            return None
        t, acc, gyr, host, stat, threshold, still = (
            np.concatenate(parts) for parts in zip(*self._pending, strict=True)
        )
        self._pending = []
        return self._run(t, acc, gyr, host, stat, threshold, still)

    def _try_align(self) -> bool:
        t, acc, gyr = (np.concatenate([p[i] for p in self._pending]) for i in range(3))
        need = max(2, round(self.config.filter.align_s * self.rate_hz))
        rate = np.linalg.norm(gyr, axis=2).max(axis=1)
        quiet = np.nan_to_num(rate, nan=np.inf) < self.config.align_max_rate_radps
        csum = np.concatenate([[0], np.cumsum(quiet, dtype=np.int64)])
        hits = np.flatnonzero(csum[need:] - csum[:-need] == need) if quiet.size >= need else np.empty(0, np.int64)
        if hits.size == 0:
            keep = round(self.config.max_wait_s * self.rate_hz)
            if t.shape[0] > keep:
                drop = t.shape[0] - keep
                self.stats.samples_before_alignment += drop
                self._pending = [tuple(np.concatenate([p[i] for p in self._pending])[drop:] for i in range(7))]
            return False
        start = int(hits[0])
        window = slice(start, start + need)
        self.filter = DualEskfStream(
            self.config.filter, np.asarray(self.config.lever_b_m), self.rate_hz, acc[window], gyr[window]
        )
        self.levels.levels_z_m[0] = float(self.filter.x[2])  # the start floor, under the board's midpoint
        self.stats.samples_before_alignment += start
        self.stats.aligned_at_s = float(t[start])
        self._t_last = float(t[start]) - 1.0 / self.rate_hz
        merged = [np.concatenate([p[i] for p in self._pending])[start:] for i in range(7)]
        self._pending = [tuple(merged)]
        return True

    def _run(
        self,
        t: F64,
        acc: F64,
        gyr: F64,
        host: NDArray[np.int64],
        stat: F64,
        threshold: F64,
        still: NDArray[np.bool_],
    ) -> NavBatch:
        assert self.filter is not None
        dt = sample_intervals(t, self._t_last, self.config.filter.dt_max_s)
        self._t_last = float(t[-1])
        ratio = zupt_ratio(stat, threshold)
        f = self.filter
        parts, a = [], 0
        for b in [*self.levels.update_points(still), None]:  # None: the rest of the batch, with no update after it
            end = t.shape[0] if b is None else b
            if end > a:
                parts.append(f.step(t[a:end], acc[a:end], gyr[a:end], still[a:end], dt[a:end], ratio[a:end]))
            if b is not None and not f.aux[AUX_LAST_REJECTED]:  # a stance the filter found moving: no level
                f.x, f.P, _ = self.levels.stance_update(f.x, f.P)
            a = end
        track = concat_tracks(parts)
        self.last_track = track
        c = track.counters
        s = self.stats
        s.samples_out += t.shape[0]
        s.bad_samples = c["both_bad_samples"]
        s.zero_velocity_updates, s.zero_velocity_rejected = c["zero_velocity_updates"], c["zero_velocity_rejected"]
        s.zero_rate_updates, s.zero_rate_rejected = c["zero_rate_updates"], c["zero_rate_rejected"]
        return NavBatch(
            t_s=t,
            pos_n_m=track.pos1_n_m,
            vel_n_mps=track.vel_n_mps,
            quat_nb_wxyz=track.quat_nb_wxyz,
            pos_cov_n_m2=track.pos_cov_n_m2,
            stance=still,
            detector_stat=stat,
            detector_threshold=threshold,
            clearance_m=track.pos1_n_m[:, 2].copy(),
            host_ns=host,
        )
