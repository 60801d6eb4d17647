"""The inter-foot distance inequality: a walker's feet are never more than R apart.

The two feet's filters are coupled by the constraint ‖p_L + o_L − p_R − o_R‖_h ≤ R on their
horizontal positions (o_L, o_R the feet's start positions in a frame both navigation frames share),
applied, as Skog, Nilsson, Zachariah and Händel ("Fusing the information from two navigation systems
using an upper bound on their maximum spatial separation", IPIN 2012) do, only where it is violated:
inside the bound it carries no information the filters lack. Where the estimated distance d exceeds
R it is taken as the measurement d = R of the joint error state [δx_L, δx_R], linearised along the
unit vector u from the right foot to the left (horizontal):

    H = [uᵀ 0 … | −uᵀ 0 …],  y = R − d,  S = uᵀ P_L,pp u + uᵀ P_R,pp u + σ_R²,
    δx_L = P_L H_Lᵀ y / S,  δx_R = −P_R H_Rᵀ y / S  (H_L = [uᵀ 0 …], H_R likewise),

a truncated (active-set) update with a small noise σ_R, close to the projection of the estimate
onto the bound that weighs each foot by its own uncertainty. Because the two filters' covariances
are independent before the update, the joint update splits into one scalar update per foot, each
with the other foot's variance along u added to its noise (``Navigator.update_position``). The
foot whose position is less certain moves more, and the correlations in its covariance carry the
correction on to its heading and velocity: this is how the bound limits the heading drift the two
feet accumulate independently (Prateek, Girisha, Hari and Händel, "Data fusion of dual
foot-mounted INS to reduce the systematic heading drift", 2013).

The cross-covariance the update creates between the feet is dropped (each filter keeps its own
marginal covariance), as in the separate-filter form of Skog et al.: the filters are somewhat
over-confident about the difference of their positions after repeated corrections. The horizontal
distance is bounded, not the 3D one, because the heading drift is horizontal and on stairs the
feet differ in height by the floors' levels, which the stance levels already hold.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from footnav.pipeline.navigation.navigator import Navigator
from footnav.pipeline.two_feet.heading import RelativeHeading
from numpy.typing import NDArray

F64 = NDArray[np.float64]

DEFAULT_MAX_SEPARATION_M = 1.2
"""R, m. A bound the truth violates pulls both feet wrong, so R is above the largest horizontal
distance between a walker's feet: about a step (0.7-0.9 m walking; the emulated walker's 0.75-0.78 m
on the level and 1.02 m on its stairs, where a foot turns on the landing). Design page "Estimator",
section "Two feet coupled", has the sensitivity."""
DEFAULT_SIGMA_M = 0.001
"""σ_R, m: the bound's noise (a near-projection, kept positive so the covariance stays positive)."""
LEFT_ORIGIN_M = (0.0, 0.1, 0.0)
"""Where the left foot's IMU starts, in a frame centred between the feet with x forward, m."""
RIGHT_ORIGIN_M = (0.0, -0.1, 0.0)
"""Where the right foot's IMU starts, m (``LEFT_ORIGIN_M``)."""


DEFAULT_HEADING = RelativeHeading()
"""The relative heading constraint that ``FootSeparation`` applies by default."""


@dataclass(frozen=True, slots=True)
class FootSeparation:
    """The inter-foot distance bound.

    Attributes
    ----------
    max_m
        R, the largest horizontal distance between the two feet's IMUs, m.
    sigma_m
        1σ of the bound as a measurement, m.
    step_s
        the two navigators run in lockstep on batches this long, and the bound is checked after each, s.
    left_origin_m, right_origin_m
        each foot's start position (3,) in a frame both navigation frames share (the feet start
        parallel and still: each navigator's frame has its x along its own foot), m.
    heading
        the relative heading constraint applied with the bound (``footnav.pipeline.two_feet.heading``;
        the default), or None for the bound alone.
    """

    max_m: float = DEFAULT_MAX_SEPARATION_M
    sigma_m: float = DEFAULT_SIGMA_M
    step_s: float = 0.05
    left_origin_m: tuple[float, float, float] = LEFT_ORIGIN_M
    right_origin_m: tuple[float, float, float] = RIGHT_ORIGIN_M
    heading: RelativeHeading | None = DEFAULT_HEADING


def horizontal_separation(left: Navigator, right: Navigator, bound: FootSeparation) -> F64 | None:
    """The horizontal vector (3,) from the right foot to the left in the shared frame, m; None until
    both navigators are aligned."""
    xl, xr = left.state, right.state
    if xl is None or xr is None:
        return None
    delta = xl[:3] + np.asarray(bound.left_origin_m) - xr[:3] - np.asarray(bound.right_origin_m)
    delta[2] = 0.0
    return delta


def apply_separation(left: Navigator, right: Navigator, bound: FootSeparation) -> float:
    """Apply the distance bound to both navigators when it is violated (module docstring).

    Parameters
    ----------
    left, right : Navigator
        The two feet's navigators, at the same time (between batches).
    bound : FootSeparation
        R and its noise, and the feet's start positions.

    Returns
    -------
    float
        The horizontal distance before the update when the bound was violated and applied, m; NaN
        when it was not (within the bound, or a navigator not yet aligned or not finite).
    """
    delta = horizontal_separation(left, right, bound)
    if delta is None:
        return math.nan
    d = float(np.hypot(delta[0], delta[1]))
    if not (math.isfinite(d) and d > bound.max_m):
        return math.nan
    u = delta / d
    cov_l, cov_r = left.position_cov, right.position_cov
    assert cov_l is not None and cov_r is not None  # both aligned (state is not None)
    var_l, var_r = float(u @ cov_l @ u), float(u @ cov_r @ u)
    r = bound.sigma_m**2
    y = bound.max_m - d
    left.update_position(u, y, var_r + r)
    right.update_position(-u, y, var_l + r)
    return d
