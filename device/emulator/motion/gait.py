"""Motion of one instrumented foot over a course, and the true IMU signals it produces.

The walk is built analytically, stride by stride, from the footholds of :mod:`.paths`:

- **Still phases**: ``initial_still_s`` of standing first; each stride ends with the foot flat and
  exactly still on its next foothold; after the last stride at least :data:`FINAL_REST_S` of rest.
- **Stride timing**: the period of :func:`.paths.stride_period_s` (:data:`.paths.STAIR_STRIDE_PERIOD_S`
  on stairs), varied by up to ±4 % as the difference of two bounded draws (no cadence drift); the
  swing takes :data:`SWING_FRACTION` (±1 %) of the stride.
- **Swing**, normalised time ``τ ∈ [0, 1]``: horizontal position ``A + (B − A) S(τ)`` with the septic
  smoothstep ``S(τ) = 35τ⁴ − 84τ⁵ + 70τ⁶ − 20τ⁷`` (velocity, acceleration and jerk vanish at both
  ends); height ``z_A + (z_B − z_A) S(u) + h · 256 τ⁴(1 − τ)⁴``, ``u = τ`` on level ground and
  compressed into the first (up) or last (down) :data:`STAIR_RISE_FRACTION` on stairs, ``h`` the
  clearance (:data:`CLEARANCE_PEAK_M`, :data:`STAIR_CLEARANCE_M`); Euler angles ZYX with
  ``ψ = ψ_A + (ψ_B − ψ_A) S(τ)``, pitch ``θ = θ_down b₁(τ) − θ_up b₂(τ)`` (unit bumps
  ``b₁ ∝ τ⁴(1 − τ)⁸``, toe down at τ = 1/3; ``b₂ ∝ τ⁸(1 − τ)⁴``, toe up at 2/3; positive θ turns the
  toe down) and roll ``φ = φ₀ · 256 τ⁴(1 − τ)⁴``.
- **Heel strike**: at the start of each still phase ``Δz(t) = −c · s⁵(1 − s)⁵``,
  ``s = (t − t_hs)/W``, ``W`` = :data:`HEEL_STRIKE_DURATION_S`, ``c`` set by the peak acceleration
  :data:`HEEL_STRIKE_PEAK_ACC_MPS2` (the sole sinks about 1 mm); its samples are not stance.

Everything is closed form: velocity and acceleration are the profiles' polynomial derivatives, the
body rate is ``ω_b = [φ̇ − ψ̇ sin θ, θ̇ cos φ + ψ̇ sin φ cos θ, −θ̇ sin φ + ψ̇ cos φ cos θ]`` (Titterton
& Weston 2004, ch. 3; Groves 2013, ch. 2) and the specific force ``f_b = C_bn (a_n − g_n)``,
``g_n = [0, 0, −g]``: strapdown integration of the true signals reproduces the true motion up to the
integrator's own error. Why these shapes: docs/design/emulator.md.

Frames: navigation right-handed, z up, origin at the IMU's start, start heading +x. Body: x toe,
y left, z up when the foot is flat. Quaternions scalar first.

References
----------
- Titterton, D. H. and Weston, J. L. (2004). *Strapdown Inertial Navigation Technology*, 2nd ed., IET.
- Groves, P. D. (2013). *Principles of GNSS, Inertial, and Multisensor Integrated Navigation
  Systems*, 2nd ed., Artech House.
- Perry, J. and Burnfield, J. M. (2010). *Gait Analysis: Normal and Pathological Function*, 2nd ed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from footnav.device.emulator.motion import paths
from numpy.polynomial import polynomial as npoly
from numpy.typing import NDArray

F64 = NDArray[np.float64]

GRAVITY_MPS2 = 9.80665
"""Standard gravity, m/s² (3rd CGPM, 1901); the emulated world's constant gravity magnitude."""

SPEED_RANGE_MPS = (1.2, 1.8)
"""Walking speeds the gait model supports, m/s."""

SWING_FRACTION = 0.60
"""Nominal fraction of a stride the foot moves; the rest (40 %, of which the heel-strike transient
takes ~4 %) it is flat on the ground."""

CLEARANCE_PEAK_M = 0.12
"""Nominal peak IMU height above level ground in swing, m (±0.015 m from stride to stride)."""

STAIR_CLEARANCE_M = 0.05
"""Clearance bump added on top of the rise between treads on stairs, m."""

STAIR_RISE_FRACTION = 0.6
"""Fraction of the swing over which the foot changes height on stairs (early going up, late down)."""

TOE_DOWN_RAD = math.radians(30.0)
"""Nominal peak toe-down pitch just after heel-off, rad (±2° per stride)."""

TOE_UP_RAD = math.radians(20.0)
"""Nominal peak toe-up pitch before heel strike, rad (±2° per stride)."""

ROLL_PEAK_RAD = math.radians(3.0)
"""Peak magnitude of the small roll excursion in swing, rad (random sign and size per stride)."""

HEEL_STRIKE_DURATION_S = 0.04
"""Duration of the heel-strike transient at the start of each still phase, s."""

HEEL_STRIKE_PEAK_ACC_MPS2 = 3.0 * GRAVITY_MPS2
"""Peak vertical acceleration of the heel-strike transient, m/s² (3 g)."""

FINAL_REST_S = 1.0
"""Least time the foot rests after the end of the last stride's transient, s."""

_PERIOD_JITTER = 0.02
_SWING_FRACTION_JITTER = 0.01
_CLEARANCE_JITTER_M = 0.015
_PITCH_JITTER_RAD = math.radians(2.0)


def _bump(m: int, k: int) -> F64:
    """Coefficients (lowest order first) of ``τ^m (1 − τ)^k`` scaled to peak 1 at ``τ = m / (m + k)``."""
    coef = np.asarray(npoly.polymul(npoly.polypow([0.0, 1.0], m), npoly.polypow([1.0, -1.0], k)), dtype=np.float64)
    return coef / float(npoly.polyval(m / (m + k), coef))


def _der(coef: F64, order: int) -> F64:
    """Coefficients of the ``order``-th derivative of a polynomial."""
    return np.asarray(npoly.polyder(coef, order), dtype=np.float64)


def _poly(coef: F64, x: F64) -> F64:
    """Evaluate a polynomial (coefficients lowest order first) at ``x`` (Horner)."""
    out = np.full_like(x, coef[-1])
    for c in coef[-2::-1]:
        out *= x
        out += c
    return out


_SMOOTHSTEP = np.array([0.0, 0.0, 0.0, 0.0, 35.0, -84.0, 70.0, -20.0])
_SMOOTHSTEP_D1 = _der(_SMOOTHSTEP, 1)
_SMOOTHSTEP_D2 = _der(_SMOOTHSTEP, 2)
_CLEAR = _bump(4, 4)
_CLEAR_D1 = _der(_CLEAR, 1)
_CLEAR_D2 = _der(_CLEAR, 2)
_TOE_DOWN = _bump(4, 8)
_TOE_DOWN_D1 = _der(_TOE_DOWN, 1)
_TOE_UP = _bump(8, 4)
_TOE_UP_D1 = _der(_TOE_UP, 1)
_HEEL = _bump(5, 5)
_HEEL_D1 = _der(_HEEL, 1)
_HEEL_D2 = _der(_HEEL, 2)
_HEEL_D2_PEAK = float(np.max(np.abs(npoly.polyval(np.linspace(0.0, 1.0, 4001), _HEEL_D2))))
_HEEL_DEPTH_M = HEEL_STRIKE_PEAK_ACC_MPS2 * HEEL_STRIKE_DURATION_S**2 / _HEEL_D2_PEAK


@dataclass(frozen=True, slots=True)
class GaitTruth:
    """True motion of the instrumented foot and the ideal IMU signals, at the sample times.

    Attributes
    ----------
    t_s
        (n,) sample times from 0, s.
    pos_n_m
        (n, 3) IMU position, navigation frame, m; starts at exactly [0, 0, 0].
    vel_n_mps
        (n, 3) IMU velocity, m/s.
    acc_n_mps2
        (n, 3) IMU kinematic acceleration, m/s².
    quat_nb_wxyz
        (n, 4) attitude, body to navigation, scalar first; continuous in time (yaw is not wrapped), so after a full turn
        it is the negative of the start quaternion.
    gyr_b_radps
        (n, 3) true angular rate of the body w.r.t. the navigation frame, body axes, rad/s.
    acc_b_mps2
        (n, 3) true specific force in body axes, ``C_bn (a_n − g_n)``, m/s².
    stance
        (n,) True where the foot is exactly still.
    floor_z_m
        (n,) height of the floor or tread under the IMU, m (clearance = z − floor_z).
    distance_m
        distance walked, the sum of 3D foothold-to-foothold distances, m.
    rate_hz
        sample rate, Hz.
    n_strides
        number of strides walked.
    """

    t_s: F64
    pos_n_m: F64
    vel_n_mps: F64
    acc_n_mps2: F64
    quat_nb_wxyz: F64
    gyr_b_radps: F64
    acc_b_mps2: F64
    stance: NDArray[np.bool_]
    floor_z_m: F64
    distance_m: float
    rate_hz: float
    n_strides: int

    def __len__(self) -> int:
        return int(self.t_s.shape[0])


def euler_zyx_to_quat_wxyz(yaw_rad: F64, pitch_rad: F64, roll_rad: F64) -> F64:
    """Quaternion of ``C_nb = R_z(yaw) R_y(pitch) R_x(roll)``.

    Parameters
    ----------
    yaw_rad, pitch_rad, roll_rad : ndarray, shape (n,)
        ZYX Euler angles, rad.

    Returns
    -------
    ndarray, shape (n, 4)
        Body-to-navigation quaternion, scalar first.
    """
    cy, sy = np.cos(0.5 * yaw_rad), np.sin(0.5 * yaw_rad)
    cp, sp = np.cos(0.5 * pitch_rad), np.sin(0.5 * pitch_rad)
    cr, sr = np.cos(0.5 * roll_rad), np.sin(0.5 * roll_rad)
    return np.column_stack(
        [
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ]
    )


def rotate_n_to_b_zyx(yaw_rad: F64, pitch_rad: F64, roll_rad: F64, vec_n: F64) -> F64:
    """Resolve navigation-frame vectors in body axes, ``C_bn v_n`` for ``C_nb = R_z R_y R_x``.

    Applied as three plane rotations, ``R_x(roll)ᵀ R_y(pitch)ᵀ R_z(yaw)ᵀ v_n``.

    Parameters
    ----------
    yaw_rad, pitch_rad, roll_rad : ndarray, shape (n,)
        ZYX Euler angles, rad.
    vec_n : ndarray, shape (n, 3)
        Vectors in navigation axes.

    Returns
    -------
    ndarray, shape (n, 3)
        The same vectors in body axes.
    """
    cy, sy = np.cos(yaw_rad), np.sin(yaw_rad)
    cp, sp = np.cos(pitch_rad), np.sin(pitch_rad)
    cr, sr = np.cos(roll_rad), np.sin(roll_rad)
    x_n, y_n, z_n = vec_n[:, 0], vec_n[:, 1], vec_n[:, 2]
    x_1 = cy * x_n + sy * y_n
    y_1 = cy * y_n - sy * x_n
    x_b = cp * x_1 - sp * z_n
    z_2 = sp * x_1 + cp * z_n
    return np.column_stack([x_b, cr * y_1 + sr * z_2, cr * z_2 - sr * y_1])


def euler_zyx_rates_to_gyr_b(
    pitch_rad: F64, roll_rad: F64, yaw_rate_radps: F64, pitch_rate_radps: F64, roll_rate_radps: F64
) -> F64:
    """Body angular rate from ZYX Euler angle rates (Titterton & Weston 2004, ch. 3).

    Parameters
    ----------
    pitch_rad, roll_rad : ndarray, shape (n,)
        Pitch and roll, rad.
    yaw_rate_radps, pitch_rate_radps, roll_rate_radps : ndarray, shape (n,)
        Euler angle rates, rad/s.

    Returns
    -------
    ndarray, shape (n, 3)
        Angular rate of the body w.r.t. the navigation frame in body axes, rad/s.
    """
    cp, sp = np.cos(pitch_rad), np.sin(pitch_rad)
    cr, sr = np.cos(roll_rad), np.sin(roll_rad)
    return np.column_stack(
        [
            roll_rate_radps - yaw_rate_radps * sp,
            pitch_rate_radps * cr + yaw_rate_radps * sr * cp,
            -pitch_rate_radps * sr + yaw_rate_radps * cr * cp,
        ]
    )


class _Strides(NamedTuple):
    """The walk's stride schedule: ``m`` strides from foothold ``k`` to ``k + 1``."""

    swing_start_s: F64
    """(m,) start of each stride's swing, s."""
    swing_end_s: F64
    """(m,) end of each swing, s."""
    swing_s: F64
    """(m,) swing duration, s."""
    foot_pos_n_m: F64
    """(m + 1, 3) footholds relative to the start, m."""
    foot_yaw_rad: F64
    """(m + 1,) heading on each foothold, rad."""
    stair_steps: NDArray[np.int64]
    """(≥ m,) signed stair steps of each stride."""
    riser_m: float
    clearance_m: F64
    """(≥ m,) clearance bump of each swing, m."""
    toe_down_rad: F64
    toe_up_rad: F64
    roll_rad: F64
    """(≥ m,) peak toe-down and toe-up pitch and roll of each swing, rad."""


@dataclass(frozen=True, slots=True)
class _Motion:
    """The per-sample motion arrays that :func:`simulate_walk` fills piecewise (n samples)."""

    pos_n_m: F64
    vel_n_mps: F64
    acc_n_mps2: F64
    yaw_rad: F64
    pitch_rad: F64
    roll_rad: F64
    yaw_rate_radps: F64
    pitch_rate_radps: F64
    roll_rate_radps: F64
    floor_z_m: F64


def _stride_schedule(
    path: str,
    duration_s: float,
    speed_mps: float,
    seed: int,
    initial_still_s: float,
    max_strides: int | None,
    t_last_s: float,
    lateral_m: float = paths.RIGHT_FOOT_OFFSET_M,
    half_stride_ahead: bool = False,
) -> _Strides:
    """Enough candidate strides with their random variation, then those that end in time."""
    level_period_s = paths.stride_period_s(speed_mps)
    min_period_s = min(level_period_s, paths.STAIR_STRIDE_PERIOD_S) * (1.0 - 2.0 * _PERIOD_JITTER)
    n_max = max(0, math.ceil((duration_s - initial_still_s) / min_period_s)) + 1
    feet = paths.footholds(path, n_max, speed_mps * level_period_s, lateral_m, half_stride_ahead)
    rng = np.random.default_rng(seed)
    stair_steps = feet.stair_steps
    on_stairs = stair_steps != 0
    period_s = np.where(on_stairs, paths.STAIR_STRIDE_PERIOD_S, level_period_s)
    # Differenced jitter: each stride's period varies, but the cadence does not drift.
    jitter = np.clip(rng.standard_normal(n_max + 1), -1.0, 1.0)
    period_s = period_s * (1.0 + _PERIOD_JITTER * np.diff(jitter))
    swing_s = period_s * (SWING_FRACTION + _SWING_FRACTION_JITTER * rng.uniform(-1.0, 1.0, n_max))
    clearance_m = np.where(
        on_stairs, STAIR_CLEARANCE_M, CLEARANCE_PEAK_M + _CLEARANCE_JITTER_M * rng.uniform(-1.0, 1.0, n_max)
    )
    toe_down_rad = TOE_DOWN_RAD + _PITCH_JITTER_RAD * rng.uniform(-1.0, 1.0, n_max)
    toe_up_rad = TOE_UP_RAD + _PITCH_JITTER_RAD * rng.uniform(-1.0, 1.0, n_max)
    roll_rad = ROLL_PEAK_RAD * rng.uniform(-1.0, 1.0, n_max)
    swing_start_s = initial_still_s + np.concatenate([[0.0], np.cumsum(period_s[:-1])])
    swing_end_s = swing_start_s + swing_s
    fits = swing_end_s + HEEL_STRIKE_DURATION_S + FINAL_REST_S <= t_last_s
    m = int(np.count_nonzero(np.cumprod(fits)))
    if max_strides is not None:
        m = min(m, max(0, max_strides))
    return _Strides(
        swing_start_s=swing_start_s[:m],
        swing_end_s=swing_end_s[:m],
        swing_s=swing_s[:m],
        foot_pos_n_m=feet.pos_n_m[: m + 1] - feet.pos_n_m[0],
        foot_yaw_rad=feet.yaw_rad[: m + 1],
        stair_steps=stair_steps,
        riser_m=feet.riser_m,
        clearance_m=clearance_m,
        toe_down_rad=toe_down_rad,
        toe_up_rad=toe_up_rad,
        roll_rad=roll_rad,
    )


def _fill_swing(
    strides: _Strides, swing_samples: NDArray[np.intp], stride: NDArray[np.intp], since_start_s: F64, motion: _Motion
) -> None:
    """The swing samples of ``motion``: normalised time tau over stride i, from foothold i to i + 1."""
    sw, i = swing_samples, stride
    dur_s = strides.swing_s[i]
    tau = since_start_s / dur_s
    start_m = strides.foot_pos_n_m[i]
    delta_m = strides.foot_pos_n_m[i + 1] - start_m
    s0 = _poly(_SMOOTHSTEP, tau)
    s1 = _poly(_SMOOTHSTEP_D1, tau) / dur_s
    s2 = _poly(_SMOOTHSTEP_D2, tau) / dur_s**2
    for axis in (0, 1):
        motion.pos_n_m[sw, axis] = start_m[:, axis] + delta_m[:, axis] * s0
        motion.vel_n_mps[sw, axis] = delta_m[:, axis] * s1
        motion.acc_n_mps2[sw, axis] = delta_m[:, axis] * s2

    steps = strides.stair_steps[i]
    ramp_start = np.where(steps < 0, 1.0 - STAIR_RISE_FRACTION, 0.0)
    ramp_width = np.where(steps != 0, STAIR_RISE_FRACTION, 1.0)
    u = np.clip((tau - ramp_start) / ramp_width, 0.0, 1.0)
    dur_u_s = dur_s * ramp_width
    rise_m = delta_m[:, 2]
    height_m = strides.clearance_m[i]
    c0 = _poly(_CLEAR, tau)
    c1 = _poly(_CLEAR_D1, tau) / dur_s
    motion.pos_n_m[sw, 2] = start_m[:, 2] + rise_m * _poly(_SMOOTHSTEP, u) + height_m * c0
    motion.vel_n_mps[sw, 2] = rise_m * _poly(_SMOOTHSTEP_D1, u) / dur_u_s + height_m * c1
    motion.acc_n_mps2[sw, 2] = (
        rise_m * _poly(_SMOOTHSTEP_D2, u) / dur_u_s**2 + height_m * _poly(_CLEAR_D2, tau) / dur_s**2
    )
    edges_crossed = np.floor(s0 * np.abs(steps) + 0.5)
    motion.floor_z_m[sw] = start_m[:, 2] + np.sign(steps) * strides.riser_m * edges_crossed

    turn_rad = strides.foot_yaw_rad[i + 1] - strides.foot_yaw_rad[i]
    motion.yaw_rad[sw] = strides.foot_yaw_rad[i] + turn_rad * s0
    motion.yaw_rate_radps[sw] = turn_rad * s1
    down_rad, up_rad = strides.toe_down_rad[i], strides.toe_up_rad[i]
    motion.pitch_rad[sw] = down_rad * _poly(_TOE_DOWN, tau) - up_rad * _poly(_TOE_UP, tau)
    motion.pitch_rate_radps[sw] = (down_rad * _poly(_TOE_DOWN_D1, tau) - up_rad * _poly(_TOE_UP_D1, tau)) / dur_s
    motion.roll_rad[sw] = strides.roll_rad[i] * c0
    motion.roll_rate_radps[sw] = strides.roll_rad[i] * c1


FOOT_SIDE_M = 0.1
"""How far each foot's footholds lie from the walking line, m (half the step width)."""


def simulate_walk(
    path: str,
    duration_s: float,
    rate_hz: float = 1000.0,
    speed_mps: float = 1.4,
    *,
    seed: int = 0,
    initial_still_s: float = 3.0,
    max_strides: int | None = None,
    lateral_m: float = paths.RIGHT_FOOT_OFFSET_M,
    half_stride_ahead: bool = False,
) -> GaitTruth:
    """Simulate one instrumented foot walking a course, with its true IMU signals.

    Parameters
    ----------
    path : str
        Course name, one of :data:`.paths.PATHS` (``line``, ``rectangle``, ``figure8``, ``stairs``).
    duration_s : float
        Length of the record, s; samples are at ``k / rate_hz`` for ``0 <= k / rate_hz < duration_s``.
    rate_hz : float
        Sample rate, Hz (e.g. 1000 or 819.2).
    speed_mps : float
        Level walking speed, m/s, within :data:`SPEED_RANGE_MPS`; sets stride period and length.
    seed : int
        Seed of the stride-to-stride variation (timing, clearance, pitch and roll amplitudes).
    initial_still_s : float
        Standing still before the first stride, s.
    max_strides : int or None
        Walk at most this many strides (e.g. one lap, ``paths.footholds(...).lap_strides``), then rest
        to the end of the record; None walks as many as fit.
    lateral_m : float
        The foot's footholds lie this far to the left of the course's line (negative: right), m: on
        a turn the inner foot walks the shorter way. Default: the right foot, 0.1 m right.
    half_stride_ahead : bool
        The footholds lie half way between those of the course's (the other foot of a walker,
        :func:`two_feet_walks`); the first stride is half as long. The track still starts at the
        origin.

    Returns
    -------
    GaitTruth
        Truth arrays at the sample times. Only whole strides are walked: a stride starts only if it
        and :data:`FINAL_REST_S` of rest fit before the end.

    Raises
    ------
    ValueError
        On an unknown path, a speed outside :data:`SPEED_RANGE_MPS`, or a non-positive rate, or a
        negative duration or still time.
    """
    if path not in paths.PATHS:
        raise ValueError(f"unknown path {path!r}; expected one of {sorted(paths.PATHS)}")
    lo_mps, hi_mps = SPEED_RANGE_MPS
    if not lo_mps <= speed_mps <= hi_mps:
        raise ValueError(f"walking speed {speed_mps} m/s is outside the modelled {lo_mps}..{hi_mps} m/s")
    if not rate_hz > 0.0:
        raise ValueError(f"sample rate must be positive, got {rate_hz} Hz")
    if duration_s < 0.0 or initial_still_s < 0.0:
        raise ValueError(f"duration ({duration_s} s) and still time ({initial_still_s} s) must be >= 0")

    n = math.ceil(duration_s * rate_hz - 1e-9)
    t_s = np.arange(n) / rate_hz
    t_last_s = (n - 1) / rate_hz if n else 0.0

    strides = _stride_schedule(
        path, duration_s, speed_mps, seed, initial_still_s, max_strides, t_last_s, lateral_m, half_stride_ahead
    )
    m = strides.swing_start_s.size
    swing_start_s, swing_end_s, swing_s = strides.swing_start_s, strides.swing_end_s, strides.swing_s
    foot_pos_n_m, foot_yaw_rad = strides.foot_pos_n_m, strides.foot_yaw_rad

    # Which stride each sample belongs to (-1 before the first); moving (swing) or resting.
    if m:
        stride = np.searchsorted(swing_start_s, t_s, side="right") - 1
        safe = np.maximum(stride, 0)
        since_start_s = t_s - swing_start_s[safe]
        swing_mask = (stride >= 0) & (since_start_s < swing_s[safe])
    else:
        stride = np.full(n, -1, dtype=np.int64)
        since_start_s = np.zeros(n)
        swing_mask = np.zeros(n, dtype=np.bool_)
    sw = np.flatnonzero(swing_mask)
    rs = np.flatnonzero(~swing_mask)

    # Per-component outputs, filled piecewise.
    pos_n_m = np.empty((n, 3))
    vel_n_mps = np.zeros((n, 3))
    acc_n_mps2 = np.zeros((n, 3))
    yaw_rad = np.empty(n)
    pitch_rad = np.zeros(n)
    roll_rad_all = np.zeros(n)
    yaw_rate_radps = np.zeros(n)
    pitch_rate_radps = np.zeros(n)
    roll_rate_radps = np.zeros(n)
    floor_z_m = np.empty(n)

    # Resting: on the foothold after the last completed stride.
    hold = stride[rs] + 1
    pos_n_m[rs] = foot_pos_n_m[hold]
    yaw_rad[rs] = foot_yaw_rad[hold]
    floor_z_m[rs] = foot_pos_n_m[hold, 2]

    # Heel-strike transient at the start of each rest after a stride.
    after = rs[stride[rs] >= 0]
    s_hs = (t_s[after] - swing_end_s[stride[after]]) / HEEL_STRIKE_DURATION_S
    in_hs = s_hs < 1.0
    hs = after[in_hs]
    s_hs = s_hs[in_hs]
    pos_n_m[hs, 2] -= _HEEL_DEPTH_M * _poly(_HEEL, s_hs)
    vel_n_mps[hs, 2] = -_HEEL_DEPTH_M * _poly(_HEEL_D1, s_hs) / HEEL_STRIKE_DURATION_S
    acc_n_mps2[hs, 2] = -_HEEL_DEPTH_M * _poly(_HEEL_D2, s_hs) / HEEL_STRIKE_DURATION_S**2
    stance = ~swing_mask
    stance[hs] = False

    motion = _Motion(
        pos_n_m,
        vel_n_mps,
        acc_n_mps2,
        yaw_rad,
        pitch_rad,
        roll_rad_all,
        yaw_rate_radps,
        pitch_rate_radps,
        roll_rate_radps,
        floor_z_m,
    )
    _fill_swing(strides, sw, stride[sw], since_start_s[sw], motion)

    quat_nb_wxyz = euler_zyx_to_quat_wxyz(yaw_rad, pitch_rad, roll_rad_all)
    gyr_b_radps = euler_zyx_rates_to_gyr_b(pitch_rad, roll_rad_all, yaw_rate_radps, pitch_rate_radps, roll_rate_radps)
    specific_force_n_mps2 = acc_n_mps2.copy()
    specific_force_n_mps2[:, 2] += GRAVITY_MPS2
    acc_b_mps2 = rotate_n_to_b_zyx(yaw_rad, pitch_rad, roll_rad_all, specific_force_n_mps2)

    distance_m = float(np.sum(np.linalg.norm(np.diff(foot_pos_n_m, axis=0), axis=1)))
    return GaitTruth(
        t_s=t_s,
        pos_n_m=pos_n_m,
        vel_n_mps=vel_n_mps,
        acc_n_mps2=acc_n_mps2,
        quat_nb_wxyz=quat_nb_wxyz,
        gyr_b_radps=gyr_b_radps,
        acc_b_mps2=acc_b_mps2,
        stance=stance,
        floor_z_m=floor_z_m,
        distance_m=distance_m,
        rate_hz=float(rate_hz),
        n_strides=m,
    )


def two_feet_walks(
    path: str, duration_s: float, rate_hz: float = 1000.0, speed_mps: float = 1.4, *, seed: int = 0
) -> tuple[GaitTruth, GaitTruth]:
    """The left and the right foot of one walker: footholds 0.1 m either side of the course's line,
    alternating. The right foot leads with a half stride to half way between the left's footholds,
    half a stride period before the left foot's first stride, so each foot swings past the other
    while it stands. Each foot has its own stride-to-stride variation (seeds ``seed`` and
    ``seed + 1``); each track starts at its own origin, the feet side by side."""
    half_stride_s = 0.5 * paths.stride_period_s(speed_mps)
    left = simulate_walk(
        path, duration_s, rate_hz, speed_mps, seed=seed, lateral_m=FOOT_SIDE_M, initial_still_s=3.0 + half_stride_s
    )
    right = simulate_walk(
        path, duration_s, rate_hz, speed_mps, seed=seed + 1, lateral_m=-FOOT_SIDE_M, half_stride_ahead=True
    )
    return left, right
