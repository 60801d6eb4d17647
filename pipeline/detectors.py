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
        (n − W + 1,) statistic; element i belongs to the window ending at sample i + W − 1.
    """
    n = acc_b_mps2.shape[0]
    if n < window:
        return np.empty(0)
    zero3 = np.zeros((1, 3))
    csum_a = np.concatenate([zero3, np.cumsum(acc_b_mps2, axis=0)])
    csum_a2 = np.concatenate([[0.0], np.cumsum(np.einsum("ij,ij->i", acc_b_mps2, acc_b_mps2))])
    csum_w2 = np.concatenate([[0.0], np.cumsum(np.einsum("ij,ij->i", gyr_b_radps, gyr_b_radps))])
    sum_a = csum_a[window:] - csum_a[:-window]
    sum_a2 = csum_a2[window:] - csum_a2[:-window]
    sum_w2 = csum_w2[window:] - csum_w2[:-window]
    norm_mean_a = np.linalg.norm(sum_a, axis=1) / window
    g = p.gravity_mps2
    acc_term = sum_a2 - 2.0 * g * window * norm_mean_a + window * g * g
    stat: F64 = (np.maximum(acc_term, 0.0) / p.sigma_acc_mps2**2 + sum_w2 / p.sigma_gyr_radps**2) / window
    return stat


class StreamingShoe:
    """SHOE detector over a stream of batches; output per input sample, same length as the batch."""

    def __init__(self, params: ShoeParams, rate_hz: float) -> None:
        self.params = params
        self.window = max(2, round(params.window_s * rate_hz))
        self._tail_acc = np.empty((0, 3))
        self._tail_gyr = np.empty((0, 3))
        self._warm = False

    @property
    def threshold(self) -> float:
        return self.params.threshold

    def update(self, acc_b_mps2: F64, gyr_b_radps: F64) -> tuple[F64, NDArray[np.bool_]]:
        """Statistic and stance flag (n,) for the batch's samples (inf until W samples were seen).

        The first W−1 samples of the stream take the statistic of the first full window.
        """
        n = acc_b_mps2.shape[0]
        acc = np.concatenate([self._tail_acc, acc_b_mps2])
        gyr = np.concatenate([self._tail_gyr, gyr_b_radps])
        stat_full = shoe_statistic(acc, gyr, self.window, self.params)
        stat = np.full(n, math.inf)
        if stat_full.size:
            stat[n - min(n, stat_full.size) :] = stat_full[-min(n, stat_full.size) :]
            if not self._warm:  # the first W−1 samples belong to the first full window
                stat[: n - stat_full.size] = stat_full[0]
                self._warm = True
        keep = self.window - 1
        self._tail_acc = acc[-keep:].copy()
        self._tail_gyr = gyr[-keep:].copy()
        return stat, stat < self.params.threshold
