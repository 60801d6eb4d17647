"""Walking courses and the gait truth: geometry, stillness, clearance, speed, strapdown consistency."""

from __future__ import annotations

import math

import numpy as np
import pytest
from footnav.device.emulator.motion import paths
from footnav.device.emulator.motion.gait import GRAVITY_MPS2, GaitTruth, simulate_walk
from numpy.typing import NDArray

F64 = NDArray[np.float64]


# --- helpers: quaternions and an independent strapdown integrator -------------------------------


def _quat_mul(a: F64, b: F64) -> F64:
    w1, x1, y1, z1 = np.moveaxis(a, -1, 0)
    w2, x2, y2, z2 = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ],
        axis=-1,
    )


def _rotate(quat_wxyz: F64, vec: F64) -> F64:
    """``q ⊗ [0, v] ⊗ q*``: body vectors to navigation axes for ``q = q_nb``."""
    vec_q = np.concatenate([np.zeros((vec.shape[0], 1)), vec], axis=1)
    return _quat_mul(_quat_mul(quat_wxyz, vec_q), quat_wxyz * [1.0, -1.0, -1.0, -1.0])[:, 1:]


def _rotvec_to_quat(rotvec: F64) -> F64:
    angle = np.linalg.norm(rotvec, axis=1)
    return np.column_stack([np.cos(0.5 * angle), 0.5 * np.sinc(angle / (2 * np.pi))[:, None] * rotvec])


def _prefix_product(quats: F64) -> F64:
    """``out[k] = quats[0] ⊗ quats[1] ⊗ ... ⊗ quats[k]`` by a log-depth scan."""
    out = quats.copy()
    step = 1
    while step < out.shape[0]:
        out[step:] = _quat_mul(out[:-step], out[step:])
        out /= np.linalg.norm(out, axis=1, keepdims=True)
        step *= 2
    return out


def _midpoints(x: F64) -> F64:
    """Values half-way between samples: cubic (4-point) interpolation, linear at the ends."""
    mid = 0.5 * (x[:-1] + x[1:])
    mid[1:-1] = (-x[:-3] + 9.0 * x[1:-2] + 9.0 * x[2:-1] - x[3:]) / 16.0
    return mid


def _strapdown(truth: GaitTruth) -> tuple[F64, F64, F64]:
    """Integrate the true IMU signals from the true initial state.

    Attitude: two-sub-interval rotation vector with the coning term ``(2/3) θ₁ × θ₂`` (Savage 1998),
    sub-interval increments from a quadratic through the samples and the interpolated midpoint.
    Velocity and position: Simpson's rule on ``f_n − g_n``. Returns pos (n, 3), vel (n, 3), quat (n, 4).
    """
    dt_s = 1.0 / truth.rate_hz
    gyr = truth.gyr_b_radps
    gyr_mid = _midpoints(gyr)
    half_1 = dt_s * (5.0 * gyr[:-1] + 8.0 * gyr_mid - gyr[1:]) / 24.0
    half_2 = dt_s * (-gyr[:-1] + 8.0 * gyr_mid + 5.0 * gyr[1:]) / 24.0
    rotvec = half_1 + half_2 + (2.0 / 3.0) * np.cross(half_1, half_2)
    quat = _prefix_product(np.concatenate([truth.quat_nb_wxyz[:1], _rotvec_to_quat(rotvec)]))
    acc_n = _rotate(quat, truth.acc_b_mps2) - [0.0, 0.0, GRAVITY_MPS2]
    acc_mid = _midpoints(acc_n)
    dvel = dt_s * (acc_n[:-1] + 4.0 * acc_mid + acc_n[1:]) / 6.0
    vel = truth.vel_n_mps[0] + np.concatenate([np.zeros((1, 3)), np.cumsum(dvel, axis=0)])
    dpos = vel[:-1] * dt_s + dt_s**2 * (acc_n[:-1] + 2.0 * acc_mid) / 6.0
    pos = truth.pos_n_m[0] + np.concatenate([np.zeros((1, 3)), np.cumsum(dpos, axis=0)])
    return pos, vel, quat


def _runs(mask: NDArray[np.bool_]) -> list[tuple[int, int]]:
    """(start, stop) sample ranges where ``mask`` is True."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(np.int8), [0]])))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True))


def _swing_runs(truth: GaitTruth) -> list[tuple[int, int]]:
    """(start, stop) sample ranges where the foot is not still."""
    return _runs(~truth.stance)


@pytest.fixture(scope="module")
def rectangle_30s() -> GaitTruth:
    return simulate_walk("rectangle", 30.0)


# --- courses -------------------------------------------------------------------------------------


def test_cadence_model_gives_about_105_s_per_stride_at_1_4_mps() -> None:
    assert paths.stride_period_s(1.4) == pytest.approx(1.05, abs=0.01)
    assert paths.stride_period_s(1.8) < paths.stride_period_s(1.4) < paths.stride_period_s(1.2)
    assert 1.3 < 1.4 * paths.stride_period_s(1.4) < 1.6


def test_rectangle_is_18_by_9_counter_clockwise_and_closes_each_lap() -> None:
    centre = paths.rectangle(200, 1.47, lateral_offset_m=0.0)
    k = centre.lap_strides
    lap = centre.pos_n_m[: k + 1]
    np.testing.assert_allclose(lap.max(axis=0) - lap.min(axis=0), [18.0, 9.0, 0.0], atol=1e-9)
    np.testing.assert_array_equal(centre.pos_n_m[0], [0.0, 0.0, 0.0])
    assert centre.yaw_rad[0] == 0.0
    # Counter-clockwise: positive signed area (shoelace) and yaw up by 2π per lap.
    x, y = lap[:, 0], lap[:, 1]
    assert 0.5 * np.sum(x[:-1] * y[1:] - x[1:] * y[:-1]) > 150.0
    assert centre.yaw_rad[k] == pytest.approx(2 * math.pi)
    # The foot, offset from the centreline, comes back to its start after every lap.
    foot = paths.rectangle(3 * k, 1.47)
    for lap_end in (k, 2 * k, 3 * k):
        np.testing.assert_allclose(foot.pos_n_m[lap_end], foot.pos_n_m[0], atol=1e-9)
    np.testing.assert_allclose(foot.pos_n_m[0], [0.0, paths.RIGHT_FOOT_OFFSET_M, 0.0])
    # Turns are spread over strides, at most 45° of yaw each, and strides stay walking-sized.
    assert np.max(np.abs(np.diff(foot.yaw_rad))) <= math.radians(45.0) + 1e-12
    assert np.count_nonzero(np.diff(foot.yaw_rad[: k + 1])) >= 8
    stride_m = np.linalg.norm(np.diff(foot.pos_n_m, axis=0), axis=1)
    assert stride_m.min() > 1.0
    assert stride_m.max() < 1.7


def test_figure8_is_two_opposite_loops_of_40_to_60_m() -> None:
    centre = paths.figure8(100, 1.47, lateral_offset_m=0.0)
    k = centre.lap_strides
    lap_length_m = np.sum(np.linalg.norm(np.diff(centre.pos_n_m[: k + 1], axis=0), axis=1))
    assert 40.0 < lap_length_m < 60.0
    np.testing.assert_allclose(centre.pos_n_m[k], [0.0, 0.0, 0.0], atol=1e-9)
    assert centre.yaw_rad[k] == pytest.approx(0.0, abs=1e-12)
    assert centre.yaw_rad.max() == pytest.approx(2 * math.pi)
    assert np.max(np.abs(np.diff(centre.yaw_rad))) <= math.radians(45.0)


def test_stairs_climb_24_risers_two_per_stride_then_come_back_down() -> None:
    feet = paths.stairs(200, 1.47)
    k = feet.lap_strides
    z_m = feet.pos_n_m[: k + 1, 2]
    assert z_m.max() == pytest.approx(24 * 0.16)
    up = np.flatnonzero(feet.stair_steps[:k] > 0)
    down = np.flatnonzero(feet.stair_steps[:k] < 0)
    assert len(up) == len(down) == 12
    np.testing.assert_allclose(np.diff(feet.pos_n_m[:, 2])[up], 2 * 0.16)
    np.testing.assert_allclose(np.diff(feet.pos_n_m[:, 2])[down], -2 * 0.16)
    tread_run_m = np.linalg.norm(np.diff(feet.pos_n_m[:, :2], axis=0), axis=1)
    np.testing.assert_allclose(tread_run_m[up], 2 * 0.343)
    # Every foothold stands on a tread: a whole number of risers above the ground.
    np.testing.assert_allclose(z_m / 0.16, np.round(z_m / 0.16), atol=1e-9)
    # On the landing the walk stays within its 6.415 m length past the top riser.
    x_top_m = feet.pos_n_m[up[-1] + 1, 0] - 0.343 / 2
    on_landing = z_m == z_m.max()
    assert np.all(feet.pos_n_m[: k + 1][on_landing, 0] - x_top_m < 6.415 - 0.3)
    np.testing.assert_allclose(feet.pos_n_m[k], feet.pos_n_m[0], atol=1e-9)


def test_unknown_path_is_refused() -> None:
    with pytest.raises(ValueError, match="unknown path"):
        paths.footholds("spiral", 10, 1.4)
    with pytest.raises(ValueError, match="unknown path"):
        simulate_walk("spiral", 10.0)


# --- gait truth ---------------------------------------------------------------------------------


@pytest.mark.parametrize("rate_hz", [1000.0, 819.2])
def test_strapdown_of_truth_imu_reproduces_truth(rate_hz: float) -> None:
    truth = simulate_walk("rectangle", 30.0, rate_hz=rate_hz)
    pos, vel, quat = _strapdown(truth)
    assert np.max(np.linalg.norm(pos - truth.pos_n_m, axis=1)) < 2e-3
    assert np.max(np.abs(vel - truth.vel_n_mps)) < 2e-4
    cos_half = np.clip(np.abs(np.sum(quat * truth.quat_nb_wxyz, axis=1)), 0.0, 1.0)
    assert np.max(2.0 * np.arccos(cos_half)) < 1e-6


def test_truth_starts_at_origin_still_and_level(rectangle_30s: GaitTruth) -> None:
    truth = rectangle_30s
    np.testing.assert_array_equal(truth.pos_n_m[0], [0.0, 0.0, 0.0])
    np.testing.assert_array_equal(truth.quat_nb_wxyz[0], [1.0, 0.0, 0.0, 0.0])
    assert np.all(truth.stance[truth.t_s < 3.0])
    assert not np.all(truth.stance[truth.t_s < 3.1])


def test_stance_is_exactly_still_with_gravity_as_specific_force(rectangle_30s: GaitTruth) -> None:
    truth = rectangle_30s
    still = truth.stance
    assert np.all(truth.vel_n_mps[still] == 0.0)
    assert np.all(truth.acc_n_mps2[still] == 0.0)
    assert np.all(truth.gyr_b_radps[still] == 0.0)
    # f_b = C_bn [0, 0, g]: rotate the measured specific force to nav axes and compare.
    f_n = _rotate(truth.quat_nb_wxyz[still], truth.acc_b_mps2[still])
    np.testing.assert_allclose(f_n, np.broadcast_to([0.0, 0.0, GRAVITY_MPS2], f_n.shape), atol=1e-12)
    # Position is constant within each still phase.
    for start, stop in _runs(still):
        assert np.ptp(truth.pos_n_m[start:stop], axis=0).max() == 0.0


def test_specific_force_and_attitude_are_consistent_everywhere(rectangle_30s: GaitTruth) -> None:
    truth = rectangle_30s
    np.testing.assert_allclose(np.linalg.norm(truth.quat_nb_wxyz, axis=1), 1.0, atol=1e-12)
    f_n = _rotate(truth.quat_nb_wxyz, truth.acc_b_mps2)
    np.testing.assert_allclose(f_n - [0.0, 0.0, GRAVITY_MPS2], truth.acc_n_mps2, atol=1e-9)


def test_stride_has_still_and_moving_phases_in_proportion(rectangle_30s: GaitTruth) -> None:
    truth = rectangle_30s
    runs = _swing_runs(truth)
    assert len(runs) == truth.n_strides >= 20
    starts_s = truth.t_s[[start for start, _ in runs]]
    moving_s = np.array([(stop - start) / truth.rate_hz for start, stop in runs])
    period_s = np.diff(starts_s)
    still_fraction = 1.0 - moving_s[:-1] / period_s
    assert np.all((still_fraction > 0.33) & (still_fraction < 0.42))
    assert np.median(period_s) == pytest.approx(paths.stride_period_s(1.4), rel=0.03)


@pytest.mark.parametrize("path", ["line", "rectangle", "figure8"])
def test_level_ground_peak_clearance_is_10_to_15_cm(path: str) -> None:
    truth = simulate_walk(path, 20.0, seed=7)
    clearance_m = truth.pos_n_m[:, 2] - truth.floor_z_m
    peaks_m = np.array([clearance_m[start:stop].max() for start, stop in _swing_runs(truth)])
    assert np.all((peaks_m >= 0.10) & (peaks_m <= 0.15))
    np.testing.assert_array_equal(truth.floor_z_m, 0.0)
    # Pitch reaches toe-down ~30° after heel-off and toe-up ~20° before heel strike.
    w, x, y, z = truth.quat_nb_wxyz.T
    pitch_deg = np.degrees(np.arcsin(np.clip(2.0 * (w * y - z * x), -1.0, 1.0)))
    assert 25.0 < pitch_deg.max() < 35.0
    assert -25.0 < pitch_deg.min() < -15.0


def test_stairs_rise_24_risers_and_the_foot_clears_every_tread() -> None:
    truth = simulate_walk("stairs", 40.0, seed=1)
    still = truth.stance
    assert truth.floor_z_m.max() == pytest.approx(24 * 0.16)
    # Resting on treads: the IMU height is a whole number of risers when still.
    z_still_m = truth.pos_n_m[still, 2]
    np.testing.assert_allclose(z_still_m / 0.16, np.round(z_still_m / 0.16), atol=1e-9)
    np.testing.assert_array_equal(truth.pos_n_m[still, 2], truth.floor_z_m[still])
    # In swing, above the tread underneath (the heel-strike dip of ~1 mm aside).
    clearance_m = truth.pos_n_m[:, 2] - truth.floor_z_m
    for start, stop in _swing_runs(truth):
        stop_swing = stop - round(0.045 * truth.rate_hz)  # leave out the heel-strike transient
        assert clearance_m[start + 1 : stop_swing].min() > 0.0
    assert clearance_m.min() > -0.002


@pytest.mark.parametrize("speed_mps", [1.2, 1.4, 1.8])
def test_average_walking_speed_follows_the_request(speed_mps: float) -> None:
    truth = simulate_walk("line", 30.0, speed_mps=speed_mps)
    runs = _swing_runs(truth)
    first, last = runs[0][0], runs[-1][0]
    walked_m = truth.pos_n_m[last, 0] - truth.pos_n_m[first, 0]
    speed = walked_m / (truth.t_s[last] - truth.t_s[first])
    assert 1.2 * 0.99 <= speed <= 1.8 * 1.01  # the allowed range, give or take stride jitter
    assert speed == pytest.approx(speed_mps, rel=0.03)
    assert truth.distance_m == pytest.approx(truth.pos_n_m[-1, 0], rel=1e-12)


def test_walk_ends_with_a_completed_stride_and_a_rest(rectangle_30s: GaitTruth) -> None:
    truth = rectangle_30s
    last_moving = np.flatnonzero(~truth.stance)[-1]
    assert truth.t_s[-1] - truth.t_s[last_moving] >= 1.0
    assert np.all(truth.stance[last_moving + 1 :])
    assert truth.t_s[-1] < 30.0


def test_819_2_hz_sampling() -> None:
    truth = simulate_walk("figure8", 30.0, rate_hz=819.2)
    assert len(truth) == 24576
    assert truth.rate_hz == 819.2
    np.testing.assert_allclose(np.diff(truth.t_s), 1.0 / 819.2, rtol=1e-9)
    assert truth.n_strides >= 20


def test_same_seed_same_walk_other_seed_other_walk() -> None:
    a = simulate_walk("figure8", 15.0, seed=3)
    b = simulate_walk("figure8", 15.0, seed=3)
    c = simulate_walk("figure8", 15.0, seed=4)
    np.testing.assert_array_equal(a.acc_b_mps2, b.acc_b_mps2)
    np.testing.assert_array_equal(a.gyr_b_radps, b.gyr_b_radps)
    assert not np.array_equal(a.acc_b_mps2, c.acc_b_mps2)


def test_too_short_a_record_is_all_standing() -> None:
    truth = simulate_walk("line", 3.5)
    assert truth.n_strides == 0
    assert np.all(truth.stance)
    assert truth.distance_m == 0.0


def test_bad_arguments_are_refused() -> None:
    with pytest.raises(ValueError, match="speed"):
        simulate_walk("line", 10.0, speed_mps=2.5)
    with pytest.raises(ValueError, match="rate"):
        simulate_walk("line", 10.0, rate_hz=0.0)
