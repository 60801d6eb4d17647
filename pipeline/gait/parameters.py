"""Gait parameters per stride: the spatial and temporal quantities of gait analysis, from one foot's track.

A stride is one gait cycle of the instrumented foot, from a footfall to its next footfall (Perry and Burnfield,
*Gait Analysis*, 2nd ed. 2010, ch. 1). A footfall is the first stance sample after a swing; a swing is a run
without stance of at least ``MIN_SWING_S`` (shorter runs are the detector's flicker within a stance); a
footfall within ``MIN_STRIDE_S`` of the last one belongs to the same stance. Left out: strides over
``MAX_STRIDE_S`` (a pause) and strides whose foot moved less than ``MIN_STEP_M`` (shuffling). The quantities
follow gaitmap's (Küderle et al., *JOSS* 9, 2024; ``gaitmap.parameters``, after Rampp et al., *IEEE TBME* 62,
2015, and Kanzler et al., *EMBC* 2015), whose spatial parameters run from mid-stance to mid-stance:

- **duration**: from footfall to footfall, s; **cadence** 120 / duration, steps/min (a stride is two steps).
- **stance** time: from the footfall to the start of the stride's swing; **swing** time: from there to the
  next footfall, s; and their **shares** of the duration. This stance is the detector's zero-velocity
  interval (foot flat), inside the ground contact (heel strike to toe-off) that force plates time: its share
  is well under the 60 % of a walking gait cycle.
- **length**: the horizontal distance between the foot's positions in the middle of the two stances, m;
  **speed**: length / duration, m/s. Live, where a stance's middle is not known yet, at the footfalls.
- **turning angle**: the heading change between the same two samples, rad, left positive, wrapped to
  (−π, π]; its **1σ** from the growth of the filter's heading variance between them (heading is not
  observed by zero-velocity updates: its error adds up as a random walk, so the growth is the change's
  variance; NaN for a smoothed track, and in a lead-in navigated backwards,
  ``footnav.pipeline.navigation.lead_in``). The other parameters have none: the difference of two
  positions needs the covariance between them, which the filter does not keep, and the growth of the
  position covariance is no stand-in (through the heading it even shrinks as a walk turns back).
- **lateral deviation**: the largest horizontal distance of the foot from the straight line between those
  two positions (gaitmap's maximum lateral excursion), m.
- **maximum clearance**: the largest ``NavBatch.clearance_m`` from footfall to footfall (the IMU above the
  floor of the stance it left, or above the ToF floor), m; **minimum clearance**: its mid-swing minimum
  (``footnav.pipeline.gait.clearance``: the MFC of Winter 1991 and Begg et al. 2007, at the IMU's point), m.

:func:`summarize` gives each parameter's mean, SD and coefficient of variation over a recording's strides.
Measured against motion capture and the emulator's truth: docs/guide/python-api.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Literal

import numpy as np
from footnav.pipeline.gait.clearance import MIN_SWING_S, StrideClearanceTracker
from footnav.pipeline.gait.steps import MIN_STEP_M
from footnav.pipeline.nav_types import NavBatch
from footnav.pipeline.navigation.quaternion import yaw_of
from numpy.typing import NDArray

F64 = NDArray[np.float64]

MIN_STRIDE_S = 0.4
"""A footfall this soon after the last one ends no stride: the detector's flicker, or the foot shifted
within one stance (running strides last 0.5 s and more: 0.53 s at the least in the PyShoe running
trials), s."""

MAX_STRIDE_S = 2.5
"""A stride longer than this holds a pause (standing), not one gait cycle (slow walking strides last
under 2 s), s."""


@dataclass(frozen=True, slots=True)
class StrideParameters:
    """Gait parameters of one foot's strides (module docstring): k strides, SI units.

    Attributes
    ----------
    start_index, toe_off_index, end_index
        (k,) sample indices of the footfall, of the start of the swing and of the next footfall.
    start_pos_index, end_pos_index
        (k,) the samples whose positions and headings the spatial parameters compare: the middles of the
        two stances (or the footfalls).
    start_s, end_s
        (k,) times of the two footfalls, s.
    duration_s
        (k,) stride duration, s.
    cadence_spm
        (k,) cadence, steps/min.
    stance_s, swing_s
        (k,) stance and swing time, s.
    stance_share, swing_share
        (k,) their shares of the duration (0 to 1).
    length_m
        (k,) stride length, m.
    speed_mps
        (k,) gait speed, m/s.
    turning_rad, turning_sd_rad
        (k,) turning angle and its 1σ (NaN where the filter gives none), rad.
    lateral_m
        (k,) lateral deviation, m.
    max_clearance_m, min_clearance_m
        (k,) maximum and mid-swing minimum clearance (NaN where the swing has no mid-swing), m.
    """

    start_index: NDArray[np.intp]
    toe_off_index: NDArray[np.intp]
    end_index: NDArray[np.intp]
    start_pos_index: NDArray[np.intp]
    end_pos_index: NDArray[np.intp]
    start_s: F64
    end_s: F64
    duration_s: F64
    cadence_spm: F64
    stance_s: F64
    swing_s: F64
    stance_share: F64
    swing_share: F64
    length_m: F64
    speed_mps: F64
    turning_rad: F64
    turning_sd_rad: F64
    lateral_m: F64
    max_clearance_m: F64
    min_clearance_m: F64

    def __len__(self) -> int:
        return int(self.start_s.shape[0])

    def columns(self) -> dict[str, NDArray[np.float64] | NDArray[np.intp]]:
        """Every attribute by name, in order (the columns of ``footnav export --gait``)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


def footfalls(
    t_s: F64, stance: NDArray[np.bool_], min_swing_s: float = MIN_SWING_S, min_stride_s: float = MIN_STRIDE_S
) -> NDArray[np.intp]:
    """Sample indices of the footfalls: the first stance sample after each swing (module docstring).

    Parameters
    ----------
    t_s
        (n,) sample times, s.
    stance
        (n,) the zero-velocity detector's flags.
    min_swing_s
        runs without stance shorter than this, between two stances, are flicker within a stance, s.
    min_stride_s
        a footfall this soon after the last one is dropped, s.

    Returns
    -------
    numpy.ndarray
        (m,) indices, increasing; the stance a track starts in is not a footfall.
    """
    st = _filled_stance(t_s, stance, min_swing_s)
    onsets = np.flatnonzero(st[1:] & ~st[:-1]) + 1
    kept: list[int] = []
    for k in onsets.tolist():
        if not kept or t_s[k] - t_s[kept[-1]] >= min_stride_s:
            kept.append(k)
    return np.asarray(kept, dtype=np.intp)


def _filled_stance(t_s: F64, stance: NDArray[np.bool_], min_swing_s: float) -> NDArray[np.bool_]:
    """``stance`` with its runs without stance shorter than ``min_swing_s`` between two stances set."""
    st = np.array(stance, dtype=bool)
    edges = np.flatnonzero(st[1:] != st[:-1]) + 1
    for a, b in zip(edges[:-1].tolist(), edges[1:].tolist(), strict=True):
        if not st[a] and t_s[b] - t_s[a] < min_swing_s:
            st[a:b] = True
    return st


def stride_parameters(
    t_s: F64,
    pos_n_m: F64,
    quat_nb_wxyz: F64,
    stance: NDArray[np.bool_],
    clearance_m: F64,
    *,
    yaw_var_rad2: F64 | None = None,
    falls: NDArray[np.intp] | None = None,
    at: Literal["mid-stance", "footfall"] = "mid-stance",
    max_stride_s: float = MAX_STRIDE_S,
) -> StrideParameters:
    """The gait parameters of the strides of one foot's track (module docstring).

    Parameters
    ----------
    t_s
        (n,) sample times, s.
    pos_n_m
        (n, 3) positions, navigation frame (z up), m.
    quat_nb_wxyz
        (n, 4) attitudes, body to navigation, scalar first.
    stance
        (n,) the zero-velocity detector's flags.
    clearance_m
        (n,) height above the floor (``NavBatch.clearance_m``), m.
    yaw_var_rad2
        (n,) the causal filter's heading variance (``NavBatch.cov_pos_yaw[:, 3, 3]``), rad², or None: no
        turning-angle uncertainty.
    falls
        the footfalls' indices; None: :func:`footfalls` of ``stance``.
    at
        where the spatial parameters take a stance's position: its middle, or its footfall (live).
    max_stride_s
        longer strides are left out (:data:`MAX_STRIDE_S`), s.

    Returns
    -------
    StrideParameters
        one entry per stride, in time order.
    """
    t_s = np.asarray(t_s, dtype=np.float64)
    st = _filled_stance(t_s, stance, MIN_SWING_S)
    f = footfalls(t_s, stance) if falls is None else np.asarray(falls, dtype=np.intp)
    run_end = np.flatnonzero(st & ~np.append(st[1:], False))  # the last sample of each stance
    p = f if at == "footfall" else (f + stance_ends(st, f)) // 2
    a, b, pa, pb = f[:-1], f[1:], p[:-1], p[1:]
    moved = np.linalg.norm(pos_n_m[pb] - pos_n_m[pa], axis=1) if a.size else np.zeros(0)
    keep = (t_s[b] - t_s[a] <= max_stride_s) & (moved >= MIN_STEP_M)
    a, b, pa, pb = a[keep], b[keep], pa[keep], pb[keep]
    # the swing starts after the last stance sample before the next footfall (a stride without one: at once)
    last = run_end[np.maximum(np.searchsorted(run_end, b) - 1, 0)] if run_end.size else a
    toe_off = np.where((last >= a) & (last < b), last + 1, a).astype(np.intp)
    duration, swing = t_s[b] - t_s[a], t_s[b] - t_s[toe_off]
    length = np.linalg.norm(pos_n_m[pb, :2] - pos_n_m[pa, :2], axis=1)
    turning_var = np.full(a.shape, np.nan) if yaw_var_rad2 is None else yaw_var_rad2[pb] - yaw_var_rad2[pa]
    pairs = list(zip(a.tolist(), b.tolist(), strict=True))
    return StrideParameters(
        start_index=a,
        toe_off_index=toe_off,
        end_index=b,
        start_pos_index=pa,
        end_pos_index=pb,
        start_s=t_s[a],
        end_s=t_s[b],
        duration_s=duration,
        cadence_spm=120.0 / duration,
        stance_s=duration - swing,
        swing_s=swing,
        stance_share=(duration - swing) / duration,
        swing_share=swing / duration,
        length_m=length,
        speed_mps=length / duration,
        turning_rad=np.angle(np.exp(1j * (yaw_of(quat_nb_wxyz[pb]) - yaw_of(quat_nb_wxyz[pa])))),
        turning_sd_rad=np.sqrt(np.maximum(turning_var, 0.0)),
        lateral_m=np.array([_lateral(pos_n_m[i : j + 1, :2]) for i, j in zip(pa.tolist(), pb.tolist(), strict=True)]),
        max_clearance_m=np.array([float(np.nanmax(clearance_m[i:j], initial=-np.inf)) for i, j in pairs]),
        min_clearance_m=_mid_swing_minimum(t_s, clearance_m, stance, t_s[b]),
    )


def stance_ends(stance: NDArray[np.bool_], k: NDArray[np.intp]) -> NDArray[np.intp]:
    """The last sample of the stance that each of the samples ``k`` is in (itself where it is in none)."""
    st = np.asarray(stance, dtype=bool)
    k = np.asarray(k, dtype=np.intp)
    run_end = np.flatnonzero(st & ~np.append(st[1:], False))
    if not run_end.size:
        return k.copy()
    return np.where(st[k], run_end[np.minimum(np.searchsorted(run_end, k), run_end.size - 1)], k).astype(np.intp)


def _lateral(xy: F64) -> float:
    """The largest distance of the points ``xy`` from the line through the first and the last, m."""
    d = xy[-1] - xy[0]
    length = math.hypot(float(d[0]), float(d[1]))
    rel = xy - xy[0]
    return float(np.max(np.abs(d[0] * rel[:, 1] - d[1] * rel[:, 0])) / length) if length > 0 else math.nan


def _mid_swing_minimum(t_s: F64, clearance_m: F64, stance: NDArray[np.bool_], ends_s: F64) -> F64:
    """The mid-swing minimum clearance of the swing that ends at each of ``ends_s``
    (``footnav.pipeline.gait.clearance``), NaN where it gives none."""
    out = np.full(ends_s.shape, np.nan)
    found = StrideClearanceTracker().update(t_s, clearance_m, np.asarray(stance, dtype=bool))
    if found is None or not ends_s.size:
        return out
    k = np.minimum(np.searchsorted(found.t_s, ends_s), len(found) - 1)
    ok = found.t_s[k] == ends_s
    out[ok] = found.min_m[k[ok]]
    return out


def gait_parameters(nav: NavBatch, *, causal_from: int | None = 0) -> StrideParameters:
    """:func:`stride_parameters` of a navigation solution.

    Parameters
    ----------
    nav
        one foot's estimates.
    causal_from
        the first sample whose covariance is the causal filter's forward run (after a lead-in navigated
        backwards: ``NavStats.samples_navigated_backwards``); strides before it have no turning-angle
        uncertainty. None: none has (a smoothed track).

    Returns
    -------
    StrideParameters
        one entry per stride.
    """
    yaw_var = None
    if causal_from is not None and nav.cov_pos_yaw is not None:
        yaw_var = nav.cov_pos_yaw[:, 3, 3].copy()
        yaw_var[:causal_from] = np.nan
    return stride_parameters(nav.t_s, nav.pos_n_m, nav.quat_nb_wxyz, nav.stance, nav.clearance_m, yaw_var_rad2=yaw_var)


@dataclass(frozen=True, slots=True)
class Summary:
    """One parameter over a recording's strides: ``mean``; ``sd``, the sample standard deviation
    (n − 1); ``cv``, sd / mean (NaN for :data:`SIGNED` parameters, whose mean is near zero); NaN where fewer
    than two strides have a value."""

    mean: float
    sd: float
    cv: float


SUMMARIZED = (
    "length_m",
    "duration_s",
    "cadence_spm",
    "speed_mps",
    "stance_s",
    "swing_s",
    "stance_share",
    "swing_share",
    "turning_rad",
    "lateral_m",
    "max_clearance_m",
    "min_clearance_m",
)
"""The parameters :func:`summarize` gives, in order."""


SIGNED = frozenset({"turning_rad", "lateral_deviation_m"})
"""Parameters whose mean is near zero (signed, either way): no CV."""


def summarize(strides: StrideParameters) -> dict[str, Summary]:
    """Mean, SD and CV of each of :data:`SUMMARIZED` over the strides (NaN values left out)."""
    out = {}
    for name in SUMMARIZED:
        v = getattr(strides, name)
        v = v[np.isfinite(v)]
        if v.size < 2:
            out[name] = Summary(float(v[0]) if v.size else math.nan, math.nan, math.nan)
            continue
        mean, sd = float(np.mean(v)), float(np.std(v, ddof=1))
        out[name] = Summary(mean, sd, math.nan if name in SIGNED else sd / mean)
    return out
