"""Zero-velocity detection with foot height from the ToF sensors (Merat, Harvey, Mitsis, eqs. 23-24).

The multi-sensor platform declares the foot still when its angular-rate energy is small *and* the foot
is at its rest height above the floor:

    T_ω(k) = 1/W Σ_j |ω_j|² / σ_g²  <  γ_ω        (angular-rate energy, Skog et al. 2010, eq. 14)
    h(k) − h_rest  <  δ_h                         (the foot is down)

Height here needs no attitude estimate (it must not feed back from the filter it gates): each sensor's
latest valid range ρ_j is turned into the IMU's height assuming the foot is flat,
``h_j = ρ_j (−u_z,j) − l_z,j`` (lever arm ``l_b``, direction ``u_b``, body axes), which is 0 when the
foot rests flat on a level floor: the rest height is the mounting geometry, not a learned value.
``h(k)`` is the median over the sensors whose latest reading is at most ``hold_s`` old (robust to one
sensor overhanging a step edge or timing out); with none, the height test fails.

Modes (``HeightDetectorParams.mode``):

- ``inertial``: the inertial detector of ``footnav.pipeline.stance.detectors`` alone (default);
- ``height``: the two tests above alone (no accelerometer: Merat's detector);
- ``and``: stance when both the inertial detector and the height detector say so (fewer false
  stances: a foot held still in the air, or sliding, is not stance);
- ``or``: stance when either does (fewer missed stances, e.g. a slow shuffle the inertial statistic
  sees as motion).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from footnav.pipeline.stance.detectors import DetectorParams, StreamingDetector
from numpy.typing import NDArray

F64 = NDArray[np.float64]
HeightMode = Literal["inertial", "height", "and", "or"]
HEIGHT_MODES: tuple[HeightMode, ...] = ("inertial", "height", "and", "or")


@dataclass(frozen=True, slots=True)
class HeightDetectorParams:
    """Settings of the height-aided zero-velocity detector (module docstring).

    Attributes
    ----------
    mode
        how it combines with the inertial detector.
    rate_threshold
        γ_ω on the angular-rate energy (σ_g = ``sigma_gyr_radps``); 25 admits |ω| up to 5 σ_g = 0.1 rad/s.
    sigma_gyr_radps
        σ_g, rad/s.
    window_s
        window of the angular-rate energy, s.
    max_height_m
        δ_h, largest height above rest still counted as down, m (three times the range noise of one reading).
    hold_s
        a sensor's reading counts for this long, s (one measurement period and a half).
    """

    mode: HeightMode = "inertial"
    rate_threshold: float = 25.0
    sigma_gyr_radps: float = 0.02
    window_s: float = 0.01
    max_height_m: float = 0.03
    hold_s: float = 0.045


class HeightStanceDetector:
    """Stance flags from angular-rate energy and ToF height (module docstring), over a stream."""

    def __init__(self, params: HeightDetectorParams, lever_b_m: F64, dir_b: F64, rate_hz: float) -> None:
        if params.mode not in HEIGHT_MODES:
            raise ValueError(f"unknown detector mode {params.mode!r}; expected one of {HEIGHT_MODES}")
        self.params = params
        dirs = np.asarray(dir_b, dtype=np.float64)
        dirs = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
        self._gain = -dirs[:, 2]  # h = ρ (−u_z) − l_z for a flat foot
        self._offset = np.asarray(lever_b_m, dtype=np.float64)[:, 2]
        self._rate = StreamingDetector(
            DetectorParams(
                kind="are",
                window_s=params.window_s,
                sigma_gyr_radps=params.sigma_gyr_radps,
                adaptive=False,
                threshold=params.rate_threshold,
            ),
            rate_hz,
        )
        k = self._gain.shape[0]
        self._t: list[F64] = [np.empty(0) for _ in range(k)]
        self._h: list[F64] = [np.empty(0) for _ in range(k)]

    def add(self, t_s: F64, sensor: NDArray[np.int64], range_m: F64, status: NDArray[np.uint8]) -> None:
        """Readings (any batch of them, in time order per sensor)."""
        ok = (status == 0) & np.isfinite(range_m)
        for j in range(self._gain.shape[0]):
            sel = ok & (sensor == j)
            if sel.any():
                self._t[j] = np.concatenate([self._t[j], t_s[sel]])
                self._h[j] = np.concatenate([self._h[j], range_m[sel] * self._gain[j] - self._offset[j]])

    def height_m(self, t_s: F64) -> F64:
        """Median flat-foot height (n,) at the sample times from the latest fresh readings (NaN: none)."""
        k = self._gain.shape[0]
        per = np.full((k, t_s.shape[0]), np.nan)
        for j in range(k):
            if self._t[j].size == 0:
                continue
            i = np.searchsorted(self._t[j], t_s, side="right") - 1
            fresh = (i >= 0) & (t_s - self._t[j][np.maximum(i, 0)] <= self.params.hold_s)
            per[j, fresh] = self._h[j][i[fresh]]
        n_fresh = np.sum(np.isfinite(per), axis=0)
        out = np.full(t_s.shape[0], np.nan)
        have = n_fresh > 0
        if have.any():
            out[have] = np.nanmedian(per[:, have], axis=0)
        self._prune(float(t_s[-1]) - self.params.hold_s if t_s.size else -math.inf)
        return out

    def _prune(self, t_keep_s: float) -> None:
        """Drop readings no later sample can use (keep each sensor's latest before ``t_keep_s``)."""
        for j in range(self._gain.shape[0]):
            i = int(np.searchsorted(self._t[j], t_keep_s, side="right")) - 1
            if i > 0:
                self._t[j], self._h[j] = self._t[j][i:], self._h[j][i:]

    def update(
        self, t_s: F64, acc_b_mps2: F64, gyr_b_radps: F64, inertial_still: NDArray[np.bool_]
    ) -> NDArray[np.bool_]:
        """Stance flags (n,) of a batch in the configured mode."""
        _, _, rate_still = self._rate.update(acc_b_mps2, gyr_b_radps)
        height = self.height_m(t_s)
        with np.errstate(invalid="ignore"):
            down = height < self.params.max_height_m
        height_still: NDArray[np.bool_] = rate_still & down
        mode = self.params.mode
        if mode == "height":
            return height_still
        if mode == "and":
            return np.asarray(inertial_still & height_still, dtype=bool)
        if mode == "or":
            return np.asarray(inertial_still | height_still, dtype=bool)
        return inertial_still
