"""The relative heading of the two feet: in stance a walker's feet point the same way, up to a toe-out offset.

Each foot's heading drifts on its own (gyroscope bias, scale and cross-axis errors: the zero-velocity
updates do not observe yaw), and the heading drift is what makes a foot's track wander. A walker's
two feet, though, point along the walking direction, each turned out by a nearly constant angle, so
their heading difference in stance is a constant Δ plus the stride-to-stride variability of foot
placement. Prateek, Girisha, Hari and Händel ("Data fusion of dual foot-mounted INS to reduce the
systematic heading drift", 2013) use this between the feet's filters; the dual-foot heading
constraints of Zhao et al. and Niu et al. are of the same kind. Here, once in each stance of foot a,
when it has stood still ``settle_s``, against the last stance of the other foot b that began before
a's (the feet land in turn; feet that settle in one batch are taken in the order they landed, so a
foot that landed just before the other is not measured against the other's newer stance; ψ the
heading of the body x axis, atan2(2(wz + xy), 1 − 2(y² + z²)); ψ_a⁻ foot a's previous stance; s = +1
for a the left foot, −1 for the right):

    z = ψ_a − ψ_b − ½ (ψ_a − ψ_a⁻) = s Δ + e,   e ~ N(0, σ_ψ² + m²),   m = ½ |(ψ_a − ψ_a⁻) − (ψ_b − ψ_b⁻)|,

foot b's foothold taken half way through foot a's stride turn (exact on a straight walk and a
steady turn, off by at most m where the turn rate changes; skipped when m > ``turn_gate_rad``). Its
error is δθ_z,a − δθ_z,b (δθ_z, the heading component of the attitude error in the navigation frame,
``footnav.pipeline.navigation.eskf``; the heading error barely changes over a stride), so

    H = [e_θz | −e_θz],  y = wrap(s Δ − ẑ),  S = P_a,θzθz + P_b,θzθz + σ_ψ² + m²,

split, as the distance bound (``footnav.pipeline.two_feet.separation``), into one scalar update per
foot with the other foot's yaw variance added to the noise (``Navigator.update_error_state``); each
foot's covariance carries the correction on to its position, velocity and gyroscope bias.

Each filter's own model takes the gyroscope's scale error as white noise: its yaw variance grows far
slower than the heading error of a foot with the datasheet's axis errors (0.3-0.4° in 60 s against
1-4°), and a measurement against an over-confident yaw hardly moves it. Before each of a foot's
measurements its yaw variance is therefore raised by q² = q₀² + (k Δψ)², Δψ its turn since its last
measured stance: the scale-factor drift the filter lacks. The raise also bounds the other
over-confidence: the cross-covariance the update creates is dropped (each filter keeps its marginal),
so without it both feet's yaw variances would shrink with every update although only their
difference is observed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from footnav.pipeline.navigation import eskf
from footnav.pipeline.navigation.navigator import Navigator
from numpy.typing import NDArray

F64 = NDArray[np.float64]

YAW_INDEX = eskf.TH0 + 2
"""Index of δθ_z, the heading error, in the error state."""


@dataclass(frozen=True, slots=True)
class RelativeHeading:
    """The relative heading constraint (module docstring).

    Attributes
    ----------
    sigma_rad
        σ_ψ, 1σ of the heading difference in stance about its offset: the stride-to-stride
        variability of foot placement, several degrees in people (the emulated walker has none), rad.
    offset_rad
        Δ, the heading of the left foot minus the right in stance, beyond their difference at the
        still start (the feet start parallel: the navigators' frames share their x axes), rad.
    turn_gate_rad
        skip the measurement when m, half the difference of the two feet's last stride turns, is
        above this (a turn starts or ends: the midpoint model is off by up to m), rad.
    settle_s
        the measurement is taken once in each stance, when the foot has stood still this long, s.
    band_rad
        b, the constraint as an inequality |y| ≤ b + m (m the midpoint model's error bound): a stance
        whose innovation is inside it changes nothing (no drift raise, no update); outside, the
        update pulls to the band's edge, y − sign(y)(b + m); 0 applies it at every stance (an
        equality), rad. 0.1°: the smallest band that left every emulated walk without axis errors
        unchanged (design page "Estimator").
    drift_rad, drift_per_turn
        1σ of the heading drift per stride that the filter's own model lacks, q = hypot(q₀, k |Δψ|),
        q₀ rad and k times the foot's turn Δψ since its last measured stance, added to its yaw variance
        at each measurement, rad. k = 2 %: the gyroscope's scale factor and cross-axis errors of the
        datasheet (1 % and 0.67 %, 1σ) rounded up; q₀ = 0 because a constant q₀ made straight walks
        without axis errors worse by up to 2 cm (design page "Estimator").
    """

    sigma_rad: float = math.radians(4.0)
    offset_rad: float = 0.0
    band_rad: float = math.radians(0.1)
    turn_gate_rad: float = math.radians(10.0)
    settle_s: float = 0.1
    drift_rad: float = 0.0
    drift_per_turn: float = 0.02


def heading_rad(quat_nb_wxyz: F64) -> float:
    """The heading ψ of the body x axis (yaw of the ZYX Euler angles) of a scalar-first quaternion, rad."""
    w, x, y, z = (float(c) for c in quat_nb_wxyz)
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def wrap_rad(angle: float) -> float:
    """``angle`` wrapped to [−π, π), rad."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


class StepEstimates(Protocol):
    """What the constraint reads of a foot's estimates over one lockstep step (a ``NavBatch`` has it)."""

    @property
    def t_s(self) -> F64: ...
    @property
    def stance(self) -> NDArray[np.bool_]: ...
    @property
    def quat_nb_wxyz(self) -> F64: ...


@dataclass
class _FootStance:
    """One foot's stance bookkeeping: the start of its current still run, whether this stance was
    measured, the heading of its latest estimate and in its last two measured stances (as the filter
    now estimates them: the constraint's corrections are added to them)."""

    run_start_s: float = math.nan
    taken: bool = False
    psi_rad: float = math.nan
    headings: list[float] = field(default_factory=list)

    def observe(self, est: StepEstimates | None) -> None:
        """Follow the still run and the heading to the end of ``est``."""
        if est is None or len(est.t_s) == 0:
            return
        self.psi_rad = heading_rad(est.quat_nb_wxyz[-1])
        if not est.stance[-1]:
            self.run_start_s, self.taken = math.nan, False
            return
        moving = np.flatnonzero(~est.stance)
        if moving.size:  # a still run that started in this batch
            self.run_start_s, self.taken = float(est.t_s[int(moving[-1]) + 1]), False
        elif math.isnan(self.run_start_s):
            self.run_start_s, self.taken = float(est.t_s[0]), False

    def settled(self, t_s: float, settle_s: float) -> bool:
        return not self.taken and math.isfinite(self.run_start_s) and t_s - self.run_start_s >= settle_s

    def turn_to(self, psi_rad: float) -> float:
        """|ψ − ψ of the last measured stance|, 0 without one, rad."""
        return abs(wrap_rad(psi_rad - self.headings[-1])) if self.headings else 0.0

    def record(self, psi_rad: float) -> None:
        self.taken = True
        self.headings = [*self.headings[-1:], psi_rad]

    def corrected(self, dpsi_rad: float) -> None:
        self.psi_rad += dpsi_rad
        self.headings = [h + dpsi_rad for h in self.headings]


class HeadingCoupler:
    """Applies ``RelativeHeading`` between two navigators running in lockstep (module docstring).

    A foot's heading is read from its latest estimate (the last sample's attitude, with the corrections
    applied since), so the constraint sees the same values whether the lockstep navigated each step or
    several at once (``footnav.pipeline.two_feet.live``, "Leaps").

    Attributes
    ----------
    times_s, innovations_rad, sigmas_rad
        when the measurement was applied, its innovation y and its 1σ, rad.
    """

    def __init__(self, config: RelativeHeading) -> None:
        self.config = config
        self._feet = (_FootStance(), _FootStance())
        self.times_s: list[float] = []
        self.innovations_rad: list[float] = []
        self.sigmas_rad: list[float] = []

    def after_batch(
        self,
        left: Navigator,
        est_l: StepEstimates | None,
        right: Navigator,
        est_r: StepEstimates | None,
        *,
        dry: bool = False,
    ) -> bool:
        """Follow both feet's stances through their estimates of one step and apply the measurement for
        each foot that has just settled. ``dry``: apply nothing, and return False (the bookkeeping then
        half done) as soon as a measurement would be applied; True otherwise."""
        for foot, est in zip(self._feet, (est_l, est_r), strict=True):
            foot.observe(est)
        navs = (left, right)
        if math.isnan(self._feet[0].psi_rad) or math.isnan(self._feet[1].psi_rad) or (est_l is None and est_r is None):
            return True
        t = max(float(e.t_s[-1]) for e in (est_l, est_r) if e is not None)
        settled = [a for a in (0, 1) if self._feet[a].settled(t, self.config.settle_s)]
        # in the order the feet landed: a foot is measured against the other foot's stance that began
        # before its own, also when both settle in one batch
        for a in sorted(settled, key=lambda a: self._feet[a].run_start_s):
            foot, other = self._feet[a], self._feet[1 - a]
            psi_a = foot.psi_rad
            turn = foot.turn_to(psi_a)
            ready = len(foot.headings) > 0 and len(other.headings) > 1
            foot.record(psi_a)
            meas = self._measurement(foot, other, 1.0 if a == 0 else -1.0) if ready else None
            band = 0.0
            if self.config.band_rad > 0.0:
                if meas is None or abs(meas[0]) <= self.config.band_rad + meas[2]:
                    continue  # inside the band: nothing to correct
                band = self.config.band_rad + meas[2]
            if dry:
                return False
            drift = math.hypot(self.config.drift_rad, self.config.drift_per_turn * turn)
            if drift > 0.0:
                navs[a].add_error_variance(YAW_INDEX, drift**2)
            if meas is not None:
                y, var, _ = meas
                self._apply(navs[a], navs[1 - a], foot, other, y - math.copysign(band, y), var, t)
        return True

    def _measurement(self, foot: _FootStance, other: _FootStance, sign: float) -> tuple[float, float, float] | None:
        """Innovation y, its variance σ_ψ² + m² and m, rad, at a settled stance of foot a (``sign`` +1
        left, −1 right) against the other foot's last stance, the other foot's foothold taken half way
        through foot a's stride turn; None when the two feet's turns differ by more than the gate."""
        cfg = self.config
        psi_prev, psi_a = foot.headings
        turn_a = wrap_rad(psi_a - psi_prev)
        turn_b = wrap_rad(other.headings[-1] - other.headings[-2])
        mismatch = 0.5 * abs(turn_a - turn_b)
        if mismatch > cfg.turn_gate_rad:
            return None
        predicted = wrap_rad(psi_a - other.headings[-1] - 0.5 * turn_a)
        return wrap_rad(sign * cfg.offset_rad - predicted), cfg.sigma_rad**2 + mismatch**2, mismatch

    def _apply(
        self,
        nav_a: Navigator,
        nav_b: Navigator,
        foot: _FootStance,
        other: _FootStance,
        y: float,
        var: float,
        t_s: float,
    ) -> None:
        """The update of both feet's yaw with innovation ``y`` and measurement variance ``var``, rad²."""
        cov_a, cov_b = nav_a.error_cov, nav_b.error_cov
        assert cov_a is not None and cov_b is not None
        h = np.zeros(eskf.N_STATE)
        h[YAW_INDEX] = 1.0
        before = (_heading(nav_a), _heading(nav_b))
        nav_a.update_error_state(h, y, float(cov_b[YAW_INDEX, YAW_INDEX]) + var)
        nav_b.update_error_state(-h, y, float(cov_a[YAW_INDEX, YAW_INDEX]) + var)
        foot.corrected(wrap_rad(_heading(nav_a) - before[0]))
        other.corrected(wrap_rad(_heading(nav_b) - before[1]))
        self.times_s.append(t_s)
        self.innovations_rad.append(y)
        self.sigmas_rad.append(math.sqrt(var))


def _heading(nav: Navigator) -> float:
    x = nav.state
    assert x is not None
    return heading_rad(x[6:10])
