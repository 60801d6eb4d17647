"""Two feet navigated together: a left and a right recording, time-matched, coupled or independent.

Each foot keeps its own causal navigator (``footnav.pipeline.navigation.navigator``). The two run in
lockstep on batches of ``FootSeparation.step_s`` cut at the same time stamps of both recordings, and
after each batch the inter-foot distance bound (``footnav.pipeline.two_feet.separation``) is applied
where it is violated. Without the bound (``coupling=None``, the command line's ``--independent-feet``)
the same batches are navigated with nothing between them, which is bit for bit the one-foot
navigation of each recording (the navigator's output does not depend on how its input is batched).
The correction after a batch shows from the next sample on; the batch's own estimates stay causal.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from footnav.pipeline.nav_types import NavBatch, concat_batches
from footnav.pipeline.navigation.navigator import NavConfig, Navigator, NavStats
from footnav.pipeline.samples import ImuBatch
from footnav.pipeline.two_feet.heading import HeadingCoupler
from footnav.pipeline.two_feet.separation import FootSeparation, apply_separation
from numpy.typing import NDArray

F64 = NDArray[np.float64]

DEFAULT_STEP_S = 0.05
"""The lockstep batch without coupling, s (any length gives the same estimates then)."""


@dataclass(frozen=True, slots=True)
class FootSignals:
    """One foot's recording: time stamps (n,) s on a clock both feet share, specific force and rate (n, 3)
    in body axes, the sample rate, and the rates marked clipped (n, 3) or None."""

    t_s: F64
    acc_b_mps2: F64
    gyr_b_radps: F64
    rate_hz: float
    gyr_clipped_b: NDArray[np.bool_] | None = None

    def batch(self) -> ImuBatch:
        n = self.t_s.shape[0]
        idx = np.arange(n, dtype=np.int64)
        return ImuBatch(self.t_s, self.acc_b_mps2, self.gyr_b_radps, idx, np.zeros(n, np.int64), self.gyr_clipped_b)


@dataclass
class TwoFeetResult:
    """Both feet's estimates, each in its own navigation frame (its start at the origin, x along the foot).

    Attributes
    ----------
    left, right
        the feet's estimates (None: that foot never aligned).
    left_stats, right_stats
        their navigators' counts.
    corrections
        times (s) at which the bound was violated and applied.
    distance_before_m
        the horizontal distance before each of those corrections, m.
    heading_updates
        times (s) at which the relative heading constraint was applied.
    heading_innovation_rad, heading_sigma_rad
        its innovation y and its 1σ (σ_ψ and the turn mismatch m) at each of them, rad.
    """

    left: NavBatch | None
    right: NavBatch | None
    left_stats: NavStats
    right_stats: NavStats
    corrections: list[float] = field(default_factory=list)
    distance_before_m: list[float] = field(default_factory=list)
    heading_updates: list[float] = field(default_factory=list)
    heading_innovation_rad: list[float] = field(default_factory=list)
    heading_sigma_rad: list[float] = field(default_factory=list)


def navigate_feet(
    left: FootSignals,
    right: FootSignals,
    config: NavConfig | None = None,
    coupling: FootSeparation | None = None,
    *,
    right_config: NavConfig | None = None,
) -> TwoFeetResult:
    """Navigate a left and a right recording together (module docstring).

    Parameters
    ----------
    left, right : FootSignals
        The two feet's samples, stamped on one clock.
    config : NavConfig, optional
        The navigator's configuration (both feet, unless ``right_config`` is given).
    coupling : FootSeparation, optional
        The distance bound between the feet; None navigates them independently.
    right_config : NavConfig, optional
        The right foot's configuration when it differs.

    Returns
    -------
    TwoFeetResult
        Both feet's estimates and where the bound acted.
    """
    cfg_l = config or NavConfig()
    nav_l = Navigator(cfg_l, left.rate_hz)
    nav_r = Navigator(right_config or cfg_l, right.rate_hz)
    bl, br = left.batch(), right.batch()
    step_s = DEFAULT_STEP_S if coupling is None else coupling.step_s
    t0 = min(float(left.t_s[0]) if len(bl) else math.inf, float(right.t_s[0]) if len(br) else math.inf)
    t1 = max(float(left.t_s[-1]) if len(bl) else -math.inf, float(right.t_s[-1]) if len(br) else -math.inf)
    out_l: list[NavBatch] = []
    out_r: list[NavBatch] = []
    result = TwoFeetResult(None, None, nav_l.stats, nav_r.stats)
    if not math.isfinite(t0):
        return result
    # batch k holds the samples with t0 + k·step ≤ t < t0 + (k + 1)·step (the last one: to the end)
    n_steps = max(1, math.ceil((t1 - t0) / step_s + 1e-9))
    edges = t0 + step_s * np.arange(n_steps + 1)
    edges[-1] = math.inf
    cut_l = np.searchsorted(left.t_s, edges, side="left")
    cut_r = np.searchsorted(right.t_s, edges, side="left")
    heading = None if coupling is None or coupling.heading is None else HeadingCoupler(coupling.heading)
    for k in range(n_steps):
        latest: list[NavBatch | None] = [None, None]
        for i, (nav, batch, cut, out) in enumerate(((nav_l, bl, cut_l, out_l), (nav_r, br, cut_r, out_r))):
            if cut[k + 1] > cut[k]:
                est = nav.process(batch.select(slice(int(cut[k]), int(cut[k + 1]))))
                if est is not None:
                    out.append(est)
                    latest[i] = est
        if heading is not None:
            heading.after_batch(nav_l, latest[0], nav_r, latest[1])
        if coupling is not None:
            d = apply_separation(nav_l, nav_r, coupling)
            if math.isfinite(d):
                result.corrections.append(float(edges[k + 1]) if k + 1 < n_steps else t1)
                result.distance_before_m.append(d)
    if heading is not None:
        result.heading_updates, result.heading_innovation_rad = heading.times_s, heading.innovations_rad
        result.heading_sigma_rad = heading.sigmas_rad
    result.left = concat_batches(out_l) if out_l else None
    result.right = concat_batches(out_r) if out_r else None
    return result
