"""Walking courses as footholds of one instrumented foot.

A course is a centreline made of straight runs, circular turns and straight stair flights, built from
the start point (origin, heading +x, on the ground). One *stride* of the instrumented foot goes from
one foothold to the next; a *foothold* is where the foot (and the IMU on it) rests during a stance:
``(x, y, z, yaw)`` in the navigation frame (right-handed, z up; yaw about +z, 0 along +x, counter-
clockwise positive). The foot walks a fixed lateral offset from the centreline (default: a right foot
0.1 m to the right of it).

Courses:

- ``line``: straight along +x.
- ``rectangle``: 18 m × 9 m (bounding box of the centreline), counter-clockwise, starting at the origin
  heading +x on the first long side; corners are circular turns of radius 2.5 m, walked over a few
  strides with at most 45° of yaw per stride.
- ``figure8``: two tangent circles of radius 4 m (one counter-clockwise, then one clockwise), meeting
  at the origin; one lap is 16π ≈ 50.3 m.
- ``stairs``: a straight flight of 24 steps (tread 0.343 m, riser 0.16 m; rise 3.84 m) going up, two
  steps per stride; a landing at the top, taken as 6.415 m along the walking direction and 1.26 m wide
  (the flight's width), where the walker goes on 5 m, turns round to the left (radius 0.4 m) and comes
  back; then the same flight down on its other half, then 2 m on the ground floor, a turn round and
  2 m back to the start. Geometry after Chen et al. (2022); the reading of the landing's two
  dimensions and the walk on it are this module's assumptions.

Closed courses (``rectangle``, ``figure8``, ``stairs``) are repeated lap after lap; each straight run
or turn is split into a whole number of equal strides, so every lap ends exactly where it began (its
yaw grows by 2π per counter-clockwise revolution: yaw is kept continuous, not wrapped).

Stride timing (the cadence model) is here too, so that stride length follows from walking speed:
:func:`stride_period_s`.

References
----------
- Chen, et al. (2022), dual-IMU foot-mounted pedestrian navigation, *Sensors and Materials*: the stair
  test course (24 steps of 0.343 m × 0.16 m, landing 6.415 m × 1.26 m).
- Sekiya, N. and Nagasaki, H. (1998). Reproducibility of the walking patterns of normal young adults:
  test-retest reliability of the walk ratio (step-length/step-rate). *Gait & Posture* 7(3), 225-227.
  The walk ratio, step length over cadence, stays near 0.0065 m/(steps/min) across walking speeds.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

RIGHT_FOOT_OFFSET_M = -0.1
"""Lateral offset of the instrumented (right) foot from the centreline, m, positive to the left."""

WALK_RATIO_M_PER_STEPS_PER_MIN = 0.0065
"""Walk ratio, step length (m) over cadence (steps/min); Sekiya & Nagasaki (1998), young adults."""

STAIR_STRIDE_PERIOD_S = 1.2
"""Stride period on stairs, s (about 100 steps/min; an assumption: stair gait is slower than level)."""

MAX_YAW_PER_STRIDE_RAD = math.pi / 4
"""Largest yaw change the foot makes in one stride while turning, rad (45°)."""

STAIR_TREAD_M = 0.343
"""Stair tread depth, m (Chen et al. 2022)."""

STAIR_RISER_M = 0.16
"""Stair riser height, m (Chen et al. 2022)."""

STAIR_N_STEPS = 24
"""Steps in the stair flight (Chen et al. 2022)."""

STAIR_STEPS_PER_STRIDE = 2
"""Steps the instrumented foot climbs (or descends) per stride."""

LANDING_LENGTH_M = 6.415
"""Landing length along the walking direction, m (Chen et al. 2022; orientation assumed)."""

LANDING_WIDTH_M = 1.26
"""Landing (and flight) width, m (Chen et al. 2022)."""

RECTANGLE_SIZE_M = (18.0, 9.0)
"""Rectangle course: length along x and width along y of the centreline's bounding box, m."""

RECTANGLE_CORNER_RADIUS_M = 2.5
"""Radius of the rectangle's rounded corners, m (keeps yaw per stride ≤ 45° up to 1.8 m/s)."""

FIGURE8_RADIUS_M = 4.0
"""Radius of each loop of the figure eight, m (lap 16π ≈ 50.3 m)."""

_U_TURN_RADIUS_M = 0.4
_LANDING_WALK_M = 5.0
_GROUND_WALK_M = 2.0


@dataclass(frozen=True, slots=True)
class Footholds:
    """Footholds of the instrumented foot, in walking order.

    Attributes
    ----------
    pos_n_m
        (m + 1, 3) foothold positions (IMU at rest), m; row 0 is the start.
    yaw_rad
        (m + 1,) foot heading at each foothold, rad, continuous (not wrapped).
    stair_steps
        (m,) signed number of stair steps climbed in each stride (0 on level ground, +2 up, -2 down).
    riser_m
        stair riser height, m (the floor under a stair stride changes by this per step).
    lap_strides
        strides in one lap of a closed course (0 for an open course).
    """

    pos_n_m: F64
    yaw_rad: F64
    stair_steps: I64
    riser_m: float
    lap_strides: int

    @property
    def n_strides(self) -> int:
        """Number of strides (one fewer than footholds)."""
        return int(self.stair_steps.shape[0])

    @property
    def xyz_yaw(self) -> F64:
        """(m + 1, 4) footholds as ``(x, y, z, yaw)`` rows."""
        return np.column_stack([self.pos_n_m, self.yaw_rad])


def stride_period_s(speed_mps: float) -> float:
    """Stride period (two steps) at a level walking speed, from a constant walk ratio.

    With walk ratio ``W`` (step length / cadence) constant, speed ``v = W c² / 60`` for cadence ``c``
    in steps/min, so ``c = sqrt(60 v / W)`` and the stride period is ``120 / c``:
    1.14 s at 1.2 m/s, 1.05 s at 1.4 m/s, 0.93 s at 1.8 m/s.

    Parameters
    ----------
    speed_mps : float
        Walking speed, m/s (> 0).

    Returns
    -------
    float
        Stride period, s.

    References
    ----------
    Sekiya & Nagasaki (1998), see the module docstring.
    """
    if speed_mps <= 0.0:
        raise ValueError(f"walking speed must be positive, got {speed_mps} m/s")
    cadence_steps_per_min = math.sqrt(60.0 * speed_mps / WALK_RATIO_M_PER_STEPS_PER_MIN)
    return 120.0 / cadence_steps_per_min


# A course is a sequence of segments:
#   ("straight", length_m), ("arc", radius_m, turn_rad [+ left]), ("stairs", n_steps [+ up]).
Segment = tuple[str, float] | tuple[str, float, float]


def _lap(segments: Sequence[Segment], stride_length_m: float) -> tuple[F64, F64, I64]:
    """Centreline footholds of one pass over ``segments`` from the origin, heading +x.

    Returns
    -------
    pos_m : ndarray, shape (k + 1, 3)
        Centreline points at the footholds, m.
    yaw_rad : ndarray, shape (k + 1,)
        Heading there, rad.
    stair_steps : ndarray, shape (k,)
        Signed stair steps per stride.
    """
    pos_m = [np.zeros(3)]
    yaw_rad = [0.0]
    steps: list[int] = []
    for seg in segments:
        here = pos_m[-1]
        heading = yaw_rad[-1]
        forward = np.array([math.cos(heading), math.sin(heading), 0.0])
        if seg[0] == "straight":
            length_m = seg[1]
            n = max(1, round(length_m / stride_length_m))
            for j in range(1, n + 1):
                pos_m.append(here + forward * (length_m * j / n))
                yaw_rad.append(heading)
                steps.append(0)
        elif seg[0] == "arc":
            assert len(seg) == 3
            radius_m, turn_rad = seg[1], seg[2]
            n = max(
                math.ceil(abs(turn_rad) / MAX_YAW_PER_STRIDE_RAD - 1e-9),
                round(radius_m * abs(turn_rad) / stride_length_m),
            )
            side = math.copysign(1.0, turn_rad)
            centre = here + side * radius_m * np.array([-math.sin(heading), math.cos(heading), 0.0])
            for j in range(1, n + 1):
                h = heading + turn_rad * j / n
                pos_m.append(centre - side * radius_m * np.array([-math.sin(h), math.cos(h), 0.0]))
                yaw_rad.append(h)
                steps.append(0)
        elif seg[0] == "stairs":
            n_steps = round(seg[1])
            up = 1 if n_steps > 0 else -1
            for _ in range(abs(n_steps) // STAIR_STEPS_PER_STRIDE):
                prev = pos_m[-1]
                rise = np.array([0.0, 0.0, up * STAIR_STEPS_PER_STRIDE * STAIR_RISER_M])
                pos_m.append(prev + forward * (STAIR_STEPS_PER_STRIDE * STAIR_TREAD_M) + rise)
                yaw_rad.append(heading)
                steps.append(up * STAIR_STEPS_PER_STRIDE)
        else:
            raise ValueError(f"unknown course segment {seg[0]!r}")
    pos_arr_m = np.array(pos_m)
    # Heights are whole numbers of risers: snap away the rounding of repeated additions.
    pos_arr_m[:, 2] = np.round(pos_arr_m[:, 2] / STAIR_RISER_M) * STAIR_RISER_M + 0.0
    return pos_arr_m, np.array(yaw_rad), np.array(steps, dtype=np.int64)


def _tile(
    segments: Sequence[Segment],
    n_strides: int,
    stride_length_m: float,
    lateral_offset_m: float,
    closed: bool,
    half_stride_ahead: bool = False,
) -> Footholds:
    """Repeat one lap until ``n_strides`` strides exist; offset the foot from the centreline; with
    ``half_stride_ahead`` the footholds lie half way between the centreline's (the other foot of a
    walker: its first stride is half as long, from the start beside the first foot)."""
    if n_strides < 0:
        raise ValueError(f"n_strides must be >= 0, got {n_strides}")
    if not 0.05 <= stride_length_m <= 3.0:
        raise ValueError(f"stride length {stride_length_m} m is outside 0.05..3 m")
    lap_pos_m, lap_yaw_rad, lap_steps = _lap(segments, stride_length_m)
    k = lap_steps.shape[0]
    if closed:
        if not np.allclose(lap_pos_m[-1], lap_pos_m[0], atol=1e-9):
            raise AssertionError(f"course does not close: lap ends at {lap_pos_m[-1]}")
        lap_pos_m[-1] = lap_pos_m[0]
    n_laps = max(1, math.ceil(n_strides / k))
    end_pos_m = lap_pos_m[-1]
    end_yaw_rad = lap_yaw_rad[-1]
    laps = np.arange(n_laps, dtype=np.float64)
    centre_m = np.concatenate([lap_pos_m[:1], (lap_pos_m[None, 1:] + laps[:, None, None] * end_pos_m).reshape(-1, 3)])
    yaw_rad = np.concatenate([lap_yaw_rad[:1], (lap_yaw_rad[None, 1:] + laps[:, None] * end_yaw_rad).reshape(-1)])
    steps = np.tile(lap_steps, n_laps)
    if half_stride_ahead:
        centre_m = np.concatenate([centre_m[:1], 0.5 * (centre_m[1:] + centre_m[:-1])])
        yaw_rad = np.concatenate([yaw_rad[:1], 0.5 * (yaw_rad[1:] + yaw_rad[:-1])])
        steps = np.concatenate([steps[:1] // 2, (steps[1:] + steps[:-1]) // 2])
    left_n = np.column_stack([-np.sin(yaw_rad), np.cos(yaw_rad), np.zeros_like(yaw_rad)])
    pos_n_m = centre_m + lateral_offset_m * left_n
    m = n_strides
    return Footholds(
        pos_n_m=pos_n_m[: m + 1],
        yaw_rad=yaw_rad[: m + 1],
        stair_steps=steps[:m],
        riser_m=STAIR_RISER_M,
        lap_strides=k if closed else 0,
    )


def line(
    n_strides: int,
    stride_length_m: float,
    lateral_offset_m: float = RIGHT_FOOT_OFFSET_M,
    half_stride_ahead: bool = False,
) -> Footholds:
    """Footholds of a straight walk along +x.

    Parameters
    ----------
    n_strides : int
        Number of strides wanted.
    stride_length_m : float
        Stride length (one foot, foothold to foothold), m.
    lateral_offset_m : float
        Foot offset from the centreline, m, positive to the left.

    Returns
    -------
    Footholds
        ``n_strides + 1`` footholds.
    """
    return _tile(
        [("straight", stride_length_m)],
        n_strides,
        stride_length_m,
        lateral_offset_m,
        closed=False,
        half_stride_ahead=half_stride_ahead,
    )


def rectangle(
    n_strides: int,
    stride_length_m: float,
    lateral_offset_m: float = RIGHT_FOOT_OFFSET_M,
    half_stride_ahead: bool = False,
) -> Footholds:
    """Footholds of laps of the 18 m × 9 m rectangle, counter-clockwise (see the module docstring)."""
    length_m, width_m = RECTANGLE_SIZE_M
    r = RECTANGLE_CORNER_RADIUS_M
    corner: Segment = ("arc", r, math.pi / 2)
    segments: list[Segment] = [
        ("straight", length_m - 2 * r),
        corner,
        ("straight", width_m - 2 * r),
        corner,
    ] * 2
    return _tile(
        segments, n_strides, stride_length_m, lateral_offset_m, closed=True, half_stride_ahead=half_stride_ahead
    )


def figure8(
    n_strides: int,
    stride_length_m: float,
    lateral_offset_m: float = RIGHT_FOOT_OFFSET_M,
    half_stride_ahead: bool = False,
) -> Footholds:
    """Footholds of laps of the figure eight: a left loop then a right loop of radius 4 m."""
    r = FIGURE8_RADIUS_M
    segments: list[Segment] = [("arc", r, 2 * math.pi), ("arc", r, -2 * math.pi)]
    return _tile(
        segments, n_strides, stride_length_m, lateral_offset_m, closed=True, half_stride_ahead=half_stride_ahead
    )


def stairs(
    n_strides: int,
    stride_length_m: float,
    lateral_offset_m: float = RIGHT_FOOT_OFFSET_M,
    half_stride_ahead: bool = False,
) -> Footholds:
    """Footholds of laps of the stair course: up 24 steps, landing, turn round, down, turn round.

    The start foothold is on the ground half a tread before the first riser, so the first stride
    lands on tread 2 and the twelfth on the landing (half a tread past its edge). Level strides use
    ``stride_length_m``; stair strides are two treads long whatever the speed.
    """
    u_turn: Segment = ("arc", _U_TURN_RADIUS_M, math.pi)
    segments: list[Segment] = [
        ("stairs", STAIR_N_STEPS),
        ("straight", _LANDING_WALK_M),
        u_turn,
        ("straight", _LANDING_WALK_M),
        ("stairs", -STAIR_N_STEPS),
        ("straight", _GROUND_WALK_M),
        u_turn,
        ("straight", _GROUND_WALK_M),
    ]
    return _tile(
        segments, n_strides, stride_length_m, lateral_offset_m, closed=True, half_stride_ahead=half_stride_ahead
    )


PATHS: dict[str, Callable[[int, float, float, bool], Footholds]] = {
    "line": line,
    "rectangle": rectangle,
    "figure8": figure8,
    "stairs": stairs,
}
"""Course name -> footholds builder ``(n_strides, stride_length_m, lateral_offset_m) -> Footholds``."""


def footholds(
    path: str,
    n_strides: int,
    stride_length_m: float,
    lateral_offset_m: float = RIGHT_FOOT_OFFSET_M,
    half_stride_ahead: bool = False,
) -> Footholds:
    """Footholds of the named course (one of :data:`PATHS`).

    Raises
    ------
    ValueError
        If ``path`` is not a known course.
    """
    try:
        builder = PATHS[path]
    except KeyError:
        raise ValueError(f"unknown path {path!r}; expected one of {sorted(PATHS)}") from None
    return builder(n_strides, stride_length_m, lateral_offset_m, half_stride_ahead)
