"""Zero-velocity detectors on sample batches.

SHOE / GLRT (Skog, Händel, Nilsson, Rantakokko, "Zero-velocity detection — an algorithm evaluation",
IEEE Trans. Biomed. Eng. 57(11), 2010, eq. 11): for a window of W samples ending at k,

    T_k = 1/W Σ_j ( |a_j − g ā/|ā||² / σa² + |ω_j|² / σg² ),      stance if T_k < γ,

with ā the window's mean specific force. Expanding the square gives the form computed here with
cumulative sums: Σ|a_j|² − 2 g W |ā| + W g².

The window trails the sample (causal, delay (W−1)/2 samples); a streaming detector keeps the last
W−1 samples so batch boundaries change nothing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class ShoeParams:
    """SHOE detector settings.

    Attributes:
        window_s: window length in seconds (converted to W samples at the stream's rate).
        sigma_acc_mps2: accelerometer noise scale σa in the statistic, m/s².
        sigma_gyr_radps: gyroscope noise scale σg, rad/s.
        threshold: γ. With the defaults, γ = 25 admits |ω| up to 0.1 rad/s or a specific-force
            deviation of 0.5 m/s² alone; sensor noise of MEMS foot units gives T ≈ 0.1–1 at rest.
        gravity_mps2: g in the statistic.
    """

    window_s: float = 0.01
    sigma_acc_mps2: float = 0.1
    sigma_gyr_radps: float = 0.02
    threshold: float = 25.0
    gravity_mps2: float = 9.80665


def shoe_statistic(acc_b_mps2: F64, gyr_b_radps: F64, window: int, p: ShoeParams) -> F64:
    """SHOE statistic for every full window of a batch.

    Args:
        acc_b_mps2: (n, 3) specific force.
        gyr_b_radps: (n, 3) angular rate.
        window: W samples.
        p: noise scales and gravity.

    Returns:
        (n − W + 1,) statistic; element i belongs to the window ending at sample i + W − 1. A window
        holding a non-finite sample gets +inf (never still).
    """
    n = acc_b_mps2.shape[0]
    if n < window:
        return np.empty(0)
    finite = np.isfinite(acc_b_mps2).all(axis=1) & np.isfinite(gyr_b_radps).all(axis=1)
    bad = np.logical_not(finite)
    ref = acc_b_mps2[np.argmin(bad)] if not bad.all() else np.zeros(3)
    # Σ|a_j − g u|² = Σ|d_j − d̄|² + W (|ā| − g)² with d = a − ref: the shift keeps the sums small
    d: F64 = np.where(bad[:, None], 0.0, acc_b_mps2 - ref)
    w: F64 = np.where(bad[:, None], 0.0, gyr_b_radps)

    def window_sums(x: F64) -> F64:
        c = np.concatenate([np.zeros((1, *x.shape[1:])), np.cumsum(x, axis=0)])
        out: F64 = c[window:] - c[:-window]
        return out

    sum_d = window_sums(d)
    sum_d2 = window_sums(np.einsum("ij,ij->i", d, d))
    sum_w2 = window_sums(np.einsum("ij,ij->i", w, w))
    n_bad = window_sums(bad.astype(np.float64))
    mean_d = sum_d / window
    spread = np.maximum(sum_d2 - window * np.einsum("ij,ij->i", mean_d, mean_d), 0.0)
    tilt = window * (np.linalg.norm(mean_d + ref, axis=1) - p.gravity_mps2) ** 2
    stat: F64 = ((spread + tilt) / p.sigma_acc_mps2**2 + sum_w2 / p.sigma_gyr_radps**2) / window
    stat[n_bad > 0.5] = math.inf
    return stat


class StreamingShoe:
    """SHOE detector over a stream of batches; one output per input sample, whatever the batching.

    The first W−1 samples of a stream use the samples seen so far as their window.
    """

    def __init__(self, params: ShoeParams, rate_hz: float) -> None:
        self.params = params
        self.window = max(2, round(params.window_s * rate_hz))
        self._tail_acc = np.empty((0, 3))
        self._tail_gyr = np.empty((0, 3))

    @property
    def threshold(self) -> float:
        return self.params.threshold

    def update(self, acc_b_mps2: F64, gyr_b_radps: F64) -> tuple[F64, NDArray[np.bool_]]:
        """Statistic and stance flag, each (n,), for the batch's samples."""
        n = acc_b_mps2.shape[0]
        seen = self._tail_acc.shape[0]
        acc = np.concatenate([self._tail_acc, acc_b_mps2])
        gyr = np.concatenate([self._tail_gyr, gyr_b_radps])
        stat = np.empty(n)
        n_warm = min(n, max(0, self.window - 1 - seen))  # samples before the first full window
        for i in range(n_warm):
            end = seen + i + 1
            stat[i] = shoe_statistic(acc[:end], gyr[:end], end, self.params)[0]
        stat[n_warm:] = (
            shoe_statistic(acc, gyr, self.window, self.params)[-(n - n_warm) :] if n > n_warm else []
        )
        keep = self.window - 1
        self._tail_acc = acc[-keep:].copy()
        self._tail_gyr = gyr[-keep:].copy()
        return stat, stat < self.params.threshold
