"""Zero-velocity detectors on sample batches, causal and independent of how the stream is batched.

Test statistics (Skog, Händel, Nilsson, Rantakokko, "Zero-velocity detection — an algorithm
evaluation", IEEE Trans. Biomed. Eng. 57(11), 2010, eqs. 11-14), each over a window of W samples
ending at sample k, small when the foot is still:

- ``shoe`` (SHOE / GLRT): 1/W Σ ( |a_j − g ā/|ā||² / σa² + |ω_j|² / σg² )
- ``amv`` (acceleration moving variance): 1/W Σ |a_j − ā|² / σa²
- ``amag`` (acceleration magnitude): 1/W Σ (|a_j| − g)² / σa²
- ``are`` (angular rate energy): 1/W Σ |ω_j|² / σg²

with ā the window's mean specific force. Each window is summed on its own samples, so a stream gives
bit-identical results however it is cut into batches.

Thresholds: a fixed γ, or (the default) **adaptive**: every ``update_s`` the threshold is set from
the distribution of log10 T over the last ``history_s`` — its upper tail (the 95th percentile, the
level of the swing) minus ``margin_decades``. The statistic of a walking foot is bimodal over about
four decades (stance near the sensor noise, swing near 10⁴·⁵ with the default scales), and the level
of both modes moves with the unit, its mounting, the gait and the speed; the gap between the swing
level and the best threshold moves much less. When the history shows no motion (the spread between
its 5th and 95th percentiles is under ``motion_decades``) the threshold keeps its last value. It is
clamped to [``min_threshold``, ``max_threshold``]. Updates happen at fixed sample counts since the
start of the stream, so live, replay and batch runs detect identically.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]
DetectorKind = Literal["shoe", "amv", "amag", "are"]
DETECTOR_KINDS: tuple[DetectorKind, ...] = ("shoe", "amv", "amag", "are")


@dataclass(frozen=True, slots=True)
class DetectorParams:
    """Zero-velocity detector settings.

    Attributes:
        kind: which statistic (see the module docstring).
        window_s: window length in seconds (W = max(2, round(window_s · rate))).
        sigma_acc_mps2: accelerometer scale σa in the statistic, m/s².
        sigma_gyr_radps: gyroscope scale σg, rad/s.
        gravity_mps2: g in the statistic.
        adaptive: adapt the threshold to the stream (module docstring); else use ``threshold``.
        threshold: γ when fixed, and the starting value of the adaptive threshold. With the default
            scales, 25 admits |ω| up to 0.1 rad/s or a specific-force deviation of 0.5 m/s² alone;
            sensor noise of MEMS foot units gives T ≈ 0.1-1 at rest.
        history_s, update_s, margin_decades, motion_decades: the adaptive rule.
        min_threshold, max_threshold: bounds of the adaptive threshold (T units).
    """

    kind: DetectorKind = "shoe"
    window_s: float = 0.01
    sigma_acc_mps2: float = 0.1
    sigma_gyr_radps: float = 0.02
    gravity_mps2: float = 9.80665
    adaptive: bool = True
    threshold: float = 25.0
    history_s: float = 5.0
    update_s: float = 0.1
    margin_decades: float = 2.0
    motion_decades: float = 2.0
    min_threshold: float = 10.0
    max_threshold: float = 3e4


def _windows(x: F64, window: int) -> F64:
    """(n − W + 1, W, ...) views of every full window: each window's sums then depend on its own
    samples only, so results do not depend on where a stream was cut into batches."""
    out: F64 = np.lib.stride_tricks.sliding_window_view(x, window, axis=0)
    return np.moveaxis(out, -1, 1)


def statistic(acc_b_mps2: F64, gyr_b_radps: F64, window: int, p: DetectorParams) -> F64:
    """The detector statistic for every full window of a batch.

    Args:
        acc_b_mps2: (n, 3) specific force.
        gyr_b_radps: (n, 3) angular rate.
        window: W samples.
        p: which statistic, its noise scales and gravity.

    Returns:
        (n − W + 1,) statistic; element i belongs to the window ending at sample i + W − 1. A window
        holding a non-finite sample gets +inf (never still).
    """
    n = acc_b_mps2.shape[0]
    if n < window:
        return np.empty(0)
    g = p.gravity_mps2
    acc = _windows(acc_b_mps2, window)  # (m, W, 3)
    gyr = _windows(gyr_b_radps, window)
    m = acc.shape[0]
    acc_term: F64 = np.zeros(m)
    gyr_term: F64 = np.zeros(m)
    with np.errstate(invalid="ignore"):
        if p.kind in ("shoe", "amv"):
            mean = acc.mean(axis=1)
            acc_term = ((acc - mean[:, None, :]) ** 2).sum(axis=(1, 2))
            if p.kind == "shoe":  # Σ|a_j − g u|² = Σ|a_j − ā|² + W (|ā| − g)²
                acc_term = acc_term + window * (np.linalg.norm(mean, axis=1) - g) ** 2
        elif p.kind == "amag":
            acc_term = ((np.linalg.norm(acc, axis=2) - g) ** 2).sum(axis=1)
        if p.kind in ("shoe", "are"):
            gyr_term = (gyr**2).sum(axis=(1, 2))
        stat: F64 = (acc_term / p.sigma_acc_mps2**2 + gyr_term / p.sigma_gyr_radps**2) / window
    stat[~np.isfinite(stat)] = math.inf
    return stat


class StreamingDetector:
    """A zero-velocity detector over a stream of batches; one output per input sample.

    The first W−1 samples of a stream use the samples seen so far as their window.
    """

    def __init__(self, params: DetectorParams, rate_hz: float) -> None:
        self.params = params
        self.window = max(2, round(params.window_s * rate_hz))
        self._tail_acc = np.empty((0, 3))
        self._tail_gyr = np.empty((0, 3))
        self._log_threshold = math.log10(params.threshold)
        self._history = np.empty(0)
        self._history_len = max(2, round(params.history_s * rate_hz))
        self._update_every = max(1, round(params.update_s * rate_hz))
        self._seen = 0

    @property
    def threshold(self) -> float:
        """The threshold in force after the last sample."""
        return float(10.0**self._log_threshold)

    def update(self, acc_b_mps2: F64, gyr_b_radps: F64) -> tuple[F64, F64, NDArray[np.bool_]]:
        """Statistic, threshold and stance flag, each (n,), for the batch's samples."""
        n = acc_b_mps2.shape[0]
        stat = self._statistic(acc_b_mps2, gyr_b_radps)
        log_stat = np.log10(np.maximum(stat, 1e-12))
        log_th = np.empty(n)
        if not self.params.adaptive:
            log_th[:] = self._log_threshold
        else:
            start = 0
            while start < n:
                # the next update point (a multiple of update_every since the stream began)
                k_abs = self._seen + start
                next_update = -(-k_abs // self._update_every) * self._update_every
                if next_update == k_abs:
                    if k_abs > 0:
                        self._adapt()
                    next_update += self._update_every
                stop = min(n, start + (next_update - k_abs))
                log_th[start:stop] = self._log_threshold
                self._history = np.concatenate([self._history, log_stat[start:stop]])[-self._history_len :]
                start = stop
        self._seen += n
        threshold: F64 = 10.0**log_th
        return stat, threshold, log_stat < log_th

    def _adapt(self) -> None:
        p = self.params
        if self._history.size < self._update_every:
            return
        finite = self._history[np.isfinite(self._history)]
        if finite.size == 0:
            return
        lo, hi = np.percentile(finite, [5.0, 95.0])
        if hi - lo >= p.motion_decades:
            self._log_threshold = float(
                np.clip(hi - p.margin_decades, math.log10(p.min_threshold), math.log10(p.max_threshold))
            )

    def _statistic(self, acc_b_mps2: F64, gyr_b_radps: F64) -> F64:
        n = acc_b_mps2.shape[0]
        seen = self._tail_acc.shape[0]
        acc = np.concatenate([self._tail_acc, acc_b_mps2])
        gyr = np.concatenate([self._tail_gyr, gyr_b_radps])
        stat = np.empty(n)
        n_warm = min(n, max(0, self.window - 1 - seen))  # samples before the first full window
        for i in range(n_warm):
            end = seen + i + 1
            stat[i] = statistic(acc[:end], gyr[:end], end, self.params)[0]
        if n > n_warm:
            stat[n_warm:] = statistic(acc, gyr, self.window, self.params)[-(n - n_warm) :]
        keep = self.window - 1
        self._tail_acc = acc[-keep:].copy()
        self._tail_gyr = gyr[-keep:].copy()
        return stat
