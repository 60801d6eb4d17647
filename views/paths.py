"""Entity paths and the timeline: the one place footnav's Rerun layout is spelled out.

Per-foot entities take a foot name (``"foot"`` for a one-shoe session, ``"left"``/``"right"`` later),
so two feet become siblings under ``world/`` and in each plot:

- ``world/<foot>/track``  Points3D, one point per sample (class id 1 = stance), shown as a trail;
- ``world/<foot>/pose``   Transform3D (translation + rotation) of the IMU at each sample;
- ``world/<foot>/pose/shoe``  static Boxes3D drawn in the IMU frame (inherits the pose);
- ``world/<foot>/cov``    Ellipsoids3D, k-sigma position covariance in the navigation frame
  (sibling of ``pose``, positioned with ``centers``: it must not inherit the foot rotation);
- ``world/<foot>/line``   LineStrips3D, the decimated track, re-logged at most twice a second;
- ``world/<foot>/smoothed``  Points3D, the track smoothed step by step (every 10th sample), logged
  once each step has ended, shown as a trail (its clearance: ``plots/clearance/<foot>/smoothed``);
- ``world/<foot>/steps``  Points3D, one marker per step (stance onset), shown as a trail;
- ``world/<foot>/step_cov``  Ellipsoids3D, flat k-sigma ellipse of the horizontal position
  covariance at each step, on the floor under the marker;
- ``world/truth/<foot>``  optional ground-truth track;
- ``plots/<quantity>/<foot>``  Scalars, so one time-series view per quantity shows both feet
  (stance, clearance, pos_sigma, detector, speed, heading; link health: rate, link_errors;
  ToF units: tof_readings, altitude);
- ``plots/clearance/<foot>/tof<k>``  each ToF sensor's measured height of the IMU, per reading, and
  ``plots/clearance/<foot>/stride``  per-stride ``[mid-swing minimum, maximum]`` clearance, and
  ``plots/clearance/<foot>/swing`` the clearance from each swing's hits past and future, in the
  clearance view;
- ``gait/<foot>``  StateChange lane (stance/swing transitions only).
"""

from __future__ import annotations

from dataclasses import dataclass

TIMELINE = "imu_time"
"""Timeline name: device time as a duration in seconds (``rr.TimeColumn(TIMELINE, duration=t_s)``)."""

WORLD = "world"
"""Root of the 3D scene: navigation frame, right-handed, z up, origin at the start position."""

FLOOR = "world/floor"
"""Static patch of the floor the walk started on."""

EVENTS = "events"
"""TextLog entries (session events, warnings, dropped-data errors)."""

PLOTS = "plots"
PLAN = "plan"
"""Root of the plan view: the horizontal track from above (``footnav.views.plan``), in plan axes (x, −y)."""
GAIT = "gait"
STRIDES = "strides"
"""TextDocument: the last strides of every foot and their means (``footnav.views.strides``)."""
TRUTH = "world/truth"

DEFAULT_FOOT = "foot"


@dataclass(frozen=True, slots=True)
class FootPaths:
    """Entity paths of one foot.

    Attributes
    ----------
    foot
        name used in every path, e.g. ``"foot"``, ``"left"``, ``"right"``.
    """

    foot: str = DEFAULT_FOOT

    def __post_init__(self) -> None:
        if not self.foot or "/" in self.foot or not self.foot.isidentifier():
            raise ValueError(f"foot name must be a plain identifier like 'left', got {self.foot!r}")

    @property
    def root(self) -> str:
        """``world/<foot>``."""
        return f"{WORLD}/{self.foot}"

    @property
    def track(self) -> str:
        """Per-sample IMU positions (Points3D)."""
        return f"{self.root}/track"

    @property
    def pose(self) -> str:
        """Current IMU pose (Transform3D)."""
        return f"{self.root}/pose"

    @property
    def shoe(self) -> str:
        """Static box drawn in the IMU frame, child of :attr:`pose`."""
        return f"{self.pose}/shoe"

    @property
    def cov(self) -> str:
        """k-sigma position covariance ellipsoid (Ellipsoids3D with centers, navigation frame)."""
        return f"{self.root}/cov"

    @property
    def line(self) -> str:
        """Decimated track (LineStrips3D, re-logged at ≤ 2 Hz)."""
        return f"{self.root}/line"

    @property
    def smoothed(self) -> str:
        """IMU positions smoothed step by step (Points3D, every 10th sample), logged at their own
        times once their step has ended (``footnav.pipeline.smoothing.stepwise``)."""
        return f"{self.root}/smoothed"

    @property
    def steps(self) -> str:
        """One marker per step at stance onset (Points3D)."""
        return f"{self.root}/steps"

    @property
    def floor_hits(self) -> str:
        """Where each ToF reading's ray met a floor: x, y and that surface's height (a floor level,
        else where the ray hit), Points3D, one per reading (a ToF unit's floor map)."""
        return f"{self.root}/floor_hits"

    @property
    def step_cov(self) -> str:
        """Flat horizontal covariance ellipse at each step (Ellipsoids3D with centers)."""
        return f"{self.root}/step_cov"

    @property
    def truth(self) -> str:
        """Ground-truth track of this foot."""
        return f"{TRUTH}/{self.foot}"

    @property
    def stance(self) -> str:
        """Stance flag, 0.0 (swing) or 1.0 (stance), one scalar per sample."""
        return f"{PLOTS}/stance/{self.foot}"

    @property
    def clearance(self) -> str:
        """Foot clearance above the starting floor, m."""
        return f"{PLOTS}/clearance/{self.foot}"

    @property
    def pos_sigma(self) -> str:
        """Position standard deviations ``[σx, σy, σz, sqrt(trace P)]``, m."""
        return f"{PLOTS}/pos_sigma/{self.foot}"

    @property
    def detector(self) -> str:
        """Zero-velocity detector ``[statistic, threshold]``."""
        return f"{PLOTS}/detector/{self.foot}"

    @property
    def speed(self) -> str:
        """Horizontal speed of the IMU, m/s."""
        return f"{PLOTS}/speed/{self.foot}"

    @property
    def heading(self) -> str:
        """Heading (yaw of the body x axis, counter-clockwise from the start direction), degrees."""
        return f"{PLOTS}/heading/{self.foot}"

    @property
    def truth_error(self) -> str:
        """Horizontal distance of the estimate from the ground truth at the same time, m."""
        return f"{PLOTS}/truth_error/{self.foot}"

    @property
    def rate(self) -> str:
        """Link health: samples received per second of host time, Hz."""
        return f"{PLOTS}/rate/{self.foot}"

    @property
    def link_errors(self) -> str:
        """Link health: ``[lost packets, reconnects]`` since the start (cumulative counts)."""
        return f"{PLOTS}/link_errors/{self.foot}"

    def tof_height(self, sensor: int) -> str:
        """ToF sensor ``sensor``'s measured height of the IMU above the surface it hit, m (one point per
        valid reading), in the clearance view."""
        return f"{self.clearance}/tof{sensor}"

    @property
    def swing_clearance(self) -> str:
        """Foot clearance from each swing's floor hits past and future (``footnav.pipeline.gait.tof_clearance``),
        m, logged each swing about 0.25 s after it ends, in the clearance view."""
        return f"{self.clearance}/swing"

    @property
    def smoothed_clearance(self) -> str:
        """Foot clearance of the step-smoothed track, m, in the clearance view (logged with it)."""
        return f"{self.clearance}/smoothed"

    @property
    def stride_clearance(self) -> str:
        """Per-stride clearance ``[mid-swing minimum, maximum]``, m, at each swing's end."""
        return f"{self.clearance}/stride"

    @property
    def tof_readings(self) -> str:
        """ToF readings since the start ``[used, gated, invalid status]`` (cumulative counts)."""
        return f"{PLOTS}/tof_readings/{self.foot}"

    @property
    def altitude(self) -> str:
        """Barometer pressure altitude relative to the first reading, m."""
        return f"{PLOTS}/altitude/{self.foot}"

    @property
    def gait(self) -> str:
        """Stance/swing state lane (StateChange, logged on transitions)."""
        return f"{GAIT}/{self.foot}"


DUAL = "dual"
"""Root of the dual-IMU board's entities (under ``world/`` and ``plots/``)."""


@dataclass(frozen=True, slots=True)
class DualPaths:
    """Entity paths of one dual-IMU run (e.g. one course of ``footnav experiment dual-imu``).

    - ``world/dual/<run>/track/<method>``  Points3D, IMU 1's track as each method estimates it
      (``single``, ``classic``, ``paper``, ``footnav``: the fused tracks);
    - ``world/dual/<run>/imu/<imu>``  Points3D, each IMU's own track (``imu1``, ``imu2``);
    - ``world/dual/<run>/truth``  Points3D, IMU 1's true track;
    - ``plots/dual/<run>/<residual>/<axis>``  Scalars, a constraint residual over time.
    """

    run: str

    def __post_init__(self) -> None:
        if not self.run or not self.run.isidentifier():
            raise ValueError(f"run name must be a plain identifier like 'rectangle', got {self.run!r}")

    @property
    def root(self) -> str:
        """``world/dual/<run>``."""
        return f"{WORLD}/{DUAL}/{self.run}"

    def track(self, method: str) -> str:
        """IMU 1's track as ``method`` estimates it."""
        return f"{self.root}/track/{method}"

    def imu(self, imu: str) -> str:
        """One IMU's own track."""
        return f"{self.root}/imu/{imu}"

    @property
    def truth(self) -> str:
        """IMU 1's true track."""
        return f"{self.root}/truth"

    @property
    def plots(self) -> str:
        """``plots/dual/<run>``: the residual plots."""
        return f"{PLOTS}/{DUAL}/{self.run}"

    def residual(self, name: str, axis: str) -> str:
        """One axis of a constraint residual."""
        return f"{self.plots}/{name}/{axis}"


@dataclass(frozen=True, slots=True)
class PlanPaths:
    """Entity paths of one foot in the plan view (``plan/<foot>/...``, 2D, plan axes)."""

    foot: str = DEFAULT_FOOT

    @property
    def line(self) -> str:
        """The decimated track (LineStrips2D, re-logged with the 3D line)."""
        return f"{PLAN}/{self.foot}/line"

    @property
    def ends(self) -> str:
        """Start and current end of the track (Points2D, labelled)."""
        return f"{PLAN}/{self.foot}/ends"

    @property
    def steps(self) -> str:
        """One marker per step (Points2D), shown as a trail."""
        return f"{PLAN}/{self.foot}/steps"

    @property
    def step_cov(self) -> str:
        """The k-sigma ellipse of each step's horizontal position (LineStrips2D), shown as a trail."""
        return f"{PLAN}/{self.foot}/step_cov"

    @property
    def truth(self) -> str:
        """Ground-truth track from above (LineStrips2D)."""
        return f"{PLAN}/truth/{self.foot}"
