"""Gyroscope samples cut off at the sensor's measurement range: found, reconstructed, and marked
uncertain (offline).

A saturated gyroscope reports its limit instead of the rate, so the strapdown integration loses part of the swing's
rotation; a foot's pitch rate reaches 500-1000 °/s at toe-off and in the swing when walking fast, beyond the range
of many foot units.

**Which axes clip.** The level a unit's calibrated output clips at is found in the recording itself, so this runs
on whole recordings (``footnav.app.commands.export.navigate_recording``: export, evaluation), not in the live
navigator. A direction (an axis, one sign) clips when its extreme is within ``CLIP_LEVEL_SHARE`` of the largest rate
of any axis of the recording and either at least ``PILE_MIN_SWINGS`` separate stretches (``SWING_GAP_S`` apart or
more) come within ``PILE_NEAR`` of it, or one stretch stays that close for ``PLATEAU_MIN_S``.

**Reconstruction.** Each stretch of a clipped direction within ``fraction`` of its extreme is replaced by the
quadratic fitted (least squares) through the ``neighbours`` samples on each side of it, where that quadratic is
larger in magnitude than the measurement and has its sign; magnitudes only grow (Dang and Suh, "Sensor saturation
compensated smoothing algorithm for inertial sensor based motion tracking", Sensors 14(5), 8167-8188, 2014,
doi:10.3390/s140508167).

**Uncertainty.** Each clipped sample carries rate noise of 1σ = ``CLIPPED_RATE_SIGMA_SHARE`` × its rate along its
own body axis (:func:`clipped_rate_variance`, added to the attitude block of Q by
``footnav.pipeline.navigation.eskf``), so the attitude error a clipped stretch leaves lies about that axis, a tilt
that the next stance's zero-velocity updates see and correct. Rates in rad/s, body axes; times in s. Why this
design, with its measurements: the documentation's design page "Estimator", section on clipped gyroscope rates.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]

SATURATION_FRACTION = 0.95
"""Samples of a clipped direction within 5 % of its extreme are taken as saturated."""
FIT_NEIGHBOURS = 3
"""Samples on each side of a saturated stretch the quadratic is fitted through (6 points, 3 unknowns)."""
PILE_NEAR = 0.98
""""At the extreme" of a direction: within 2 % of it."""
PILE_MIN_SWINGS = 4
"""A direction clips if it is at its extreme in at least this many separate stretches..."""
SWING_GAP_S = 0.02
"""... (stretches less than this apart are one)..."""
PLATEAU_MIN_S = 0.04
"""... or in one stretch this long, s..."""
CLIP_LEVEL_SHARE = 0.9
"""... and its extreme is within 10 % of the largest rate on any axis of the recording."""
CLIPPED_RATE_SIGMA_SHARE = 0.15
"""1σ of a clipped sample's rate error, as a share of its (reconstructed) rate (design page "Estimator")."""


@dataclass(frozen=True, slots=True)
class SaturatedRates:
    """Angular rates with their clipped samples found and reconstructed.

    Attributes
    ----------
    gyr_b_radps
        (n, 3) rates, reconstructed where clipped, rad/s.
    clipped_b
        (n, 3) the samples (rows) and axes (columns) taken as clipped.
    reconstructed
        How many values the reconstruction changed.
    """

    gyr_b_radps: F64
    clipped_b: NDArray[np.bool_]
    reconstructed: int


def clipped_directions(t_s: F64, gyr_b_radps: F64) -> tuple[NDArray[np.bool_], F64]:
    """Which axis directions clip (module docstring), (3, 2) for (+, −) per axis, and their extremes
    (3, 2), rad/s (NaN where an axis has no finite sample). ``t_s`` (n,) separates the swings."""
    extreme = np.full((3, 2), np.nan)
    clipped = np.zeros((3, 2), dtype=bool)
    signed = [(axis, s, sign * gyr_b_radps[:, axis]) for axis in range(3) for s, sign in enumerate((1.0, -1.0))]
    for axis, s, w in signed:
        finite = w[np.isfinite(w)]
        if finite.size:
            extreme[axis, s] = float(np.max(finite))
    if not np.isfinite(extreme).any():
        return clipped, extreme
    largest = float(np.nanmax(extreme))
    for axis, s, w in signed:
        top = extreme[axis, s]
        if not (np.isfinite(top) and top > 0.0 and top >= CLIP_LEVEL_SHARE * largest):
            continue
        with np.errstate(invalid="ignore"):
            near = w >= PILE_NEAR * top
        at_top = t_s[near]
        swings = 1 + int(np.count_nonzero(np.diff(at_top) > SWING_GAP_S))
        edges = np.flatnonzero(np.diff(np.concatenate([[0], near.astype(np.int8), [0]])))
        held_s = max((float(t_s[b - 1] - t_s[a]) for a, b in zip(edges[::2], edges[1::2], strict=True)), default=0.0)
        clipped[axis, s] = swings >= PILE_MIN_SWINGS or held_s >= PLATEAU_MIN_S
    return clipped, extreme


def reconstruct_saturated_rates(
    t_s: F64,
    gyr_b_radps: F64,
    fraction: float = SATURATION_FRACTION,
    neighbours: int = FIT_NEIGHBOURS,
) -> SaturatedRates:
    """Find the clipped samples of a whole recording and reconstruct them (module docstring).

    Parameters
    ----------
    t_s : ndarray, shape (n,)
        Sample times, s (the abscissa of the fit; duplicates and jitter are allowed).
    gyr_b_radps : ndarray, shape (n, 3)
        Angular rate as measured, rad/s; not modified.
    fraction : float
        A stretch is a run of samples of a clipped direction with ω ≥ fraction · extreme.
    neighbours : int
        Samples on each side used for the fit; a stretch at the start or end of the recording with
        fewer than three usable neighbours in all is left as it is (still marked).

    Returns
    -------
    SaturatedRates
        The reconstructed rates, the clipped samples and how many values changed.
    """
    out = np.array(gyr_b_radps, dtype=np.float64, copy=True)
    n = out.shape[0]
    clipped_b = np.zeros(out.shape, dtype=bool)
    changed = 0
    if n == 0:
        return SaturatedRates(out, clipped_b, 0)
    directions, extreme = clipped_directions(t_s, out)
    for axis, s in zip(*np.nonzero(directions), strict=True):
        w = gyr_b_radps[:, axis]
        sign = 1.0 if s == 0 else -1.0
        with np.errstate(invalid="ignore"):
            over = sign * w >= fraction * extreme[axis, s]
        clipped_b[:, axis] |= over
        edges = np.flatnonzero(np.diff(np.concatenate([[0], over.astype(np.int8), [0]])))
        for a, b in zip(edges[::2], edges[1::2], strict=True):  # the stretch [a, b)
            idx = np.concatenate([np.arange(max(0, a - neighbours), a), np.arange(b, min(n, b + neighbours))])
            idx = idx[np.isfinite(w[idx]) & np.isfinite(t_s[idx])]
            if idx.size < 3:
                continue
            t0 = t_s[a]
            coef = np.polyfit(t_s[idx] - t0, w[idx], 2)
            fit = np.polyval(coef, t_s[a:b] - t0)
            measured = np.abs(w[a:b])
            magnitude = np.maximum(np.where(np.sign(fit) == sign, np.abs(fit), 0.0), measured)
            changed += int(np.count_nonzero(magnitude != measured))
            out[a:b, axis] = sign * magnitude
    return SaturatedRates(out, clipped_b, changed)


def clipped_rate_variance(gyr_b_radps: F64, clipped_b: NDArray[np.bool_]) -> F64:
    """(n, 3) variance of each sample's rate error along each body axis, rad²/s²: (σ_share · ω)² at
    clipped samples (module docstring), 0 elsewhere; what ``footnav.pipeline.navigation.eskf.run_filter`` takes."""
    with np.errstate(invalid="ignore"):
        var: F64 = np.where(clipped_b & np.isfinite(gyr_b_radps), (CLIPPED_RATE_SIGMA_SHARE * gyr_b_radps) ** 2, 0.0)
    return np.ascontiguousarray(var, dtype=np.float64)
