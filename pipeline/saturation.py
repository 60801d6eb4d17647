"""Reconstruction of gyroscope samples cut off at the sensor's measurement range (offline).

A foot's pitch rate at toe-off and in the swing reaches 500-1000 °/s when walking fast and more when
running, beyond the range of many foot units. A saturated gyroscope reports its limit instead of
the rate, so the strapdown integration loses part of the swing's rotation: the attitude is wrong by
tens of degrees·ms per saturated stretch, and the velocity (and the heading, which no zero-velocity
update can see) with it. The MicroStrain 3DM-GX3-25 of the PyShoe VICON trials, for example, holds
−519 to −523 °/s for 40-50 ms at a time on its pitch axis.

Each stretch where an axis is within ``fraction`` of the largest magnitude that axis reaches in the
recording is replaced by the quadratic fitted (least squares) through the ``neighbours`` samples on
each side of it, where that quadratic is larger in magnitude than the measurement and has its sign
(the quadratic approximation of saturated inertial data of Dang and Suh, "Sensor saturation
compensated smoothing algorithm for inertial sensor based motion tracking", Sensors 14(5),
8167-8188, 2014, doi:10.3390/s140508167). Magnitudes only grow: below its limit a sensor reads the
rate, and at an unsaturated peak the fit through the flanks lies on or under the measured values, so
a recording that never saturates is changed only where a peak is flatter than a parabola.

The saturation level is taken from the recording itself (no unit datasheet states the level its
calibrated output clips at, which depends on the unit's own calibration), so this needs the whole
recording and a few samples after each stretch: it is applied to whole recordings
(``app.export.navigate_recording``: export, evaluation), not in the live navigator.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]

SATURATION_FRACTION = 0.95
"""Samples within 5 % of an axis's largest magnitude in the recording are treated as saturated."""
FIT_NEIGHBOURS = 3
"""Samples on each side of a saturated stretch the quadratic is fitted through (6 points, 3 unknowns)."""


def reconstruct_saturated_rates(
    t_s: F64,
    gyr_b_radps: F64,
    fraction: float = SATURATION_FRACTION,
    neighbours: int = FIT_NEIGHBOURS,
) -> tuple[F64, int]:
    """Angular rates (n, 3) with saturated stretches reconstructed, and how many values changed.

    Args:
        t_s: (n,) sample times, s (the abscissa of the fit; duplicates and jitter are allowed).
        gyr_b_radps: (n, 3) angular rate as measured; not modified.
        fraction: a stretch is a run of samples with |ω_i| ≥ fraction · max |ω_i|.
        neighbours: samples on each side used for the fit; a stretch at the start or end of the
            recording with fewer than three usable neighbours in all is left as it is.
    """
    out = np.array(gyr_b_radps, dtype=np.float64, copy=True)
    n = out.shape[0]
    changed = 0
    for axis in range(out.shape[1]):
        w = gyr_b_radps[:, axis]
        finite = np.isfinite(w)
        if not finite.any():
            continue
        level = fraction * float(np.max(np.abs(w[finite])))
        if level <= 0.0:
            continue
        with np.errstate(invalid="ignore"):
            over = np.abs(w) >= level
        edges = np.flatnonzero(np.diff(np.concatenate([[0], over.astype(np.int8), [0]])))
        for a, b in zip(edges[::2], edges[1::2], strict=True):  # the stretch [a, b)
            idx = np.concatenate([np.arange(max(0, a - neighbours), a), np.arange(b, min(n, b + neighbours))])
            idx = idx[np.isfinite(w[idx]) & np.isfinite(t_s[idx])]
            if idx.size < 3:
                continue
            t0 = t_s[a]
            coef = np.polyfit(t_s[idx] - t0, w[idx], 2)
            fit = np.polyval(coef, t_s[a:b] - t0)
            sign = np.sign(w[a])
            measured = np.abs(w[a:b])
            magnitude = np.maximum(np.where(np.sign(fit) == sign, np.abs(fit), 0.0), measured)
            changed += int(np.count_nonzero(magnitude != measured))
            out[a:b, axis] = sign * magnitude
    return out, changed
