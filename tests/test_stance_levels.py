"""The stance height constraint (footnav.pipeline.stance.levels): level walks held on their floor, stairs kept.

Emulated walks with the platform's unit (its gyroscope's datasheet scale and cross-axis errors,
``gyro-bias-calibrated``), whose inertial-only height drifts by tens of centimetres in a minute.
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest
from footnav.device.emulator.motion.gait import simulate_walk
from footnav.device.emulator.sensors.imu_errors import corrupt
from footnav.device.files.recordings import load_recording
from footnav.pipeline.nav_types import NavBatch
from footnav.pipeline.navigation import eskf
from footnav.pipeline.navigation.navigator import NavConfig, Navigator, navigate
from footnav.pipeline.navigation.profiles import get_profile
from footnav.pipeline.samples import ImuBatch
from footnav.pipeline.smoothing.rts import smooth_recording
from footnav.pipeline.stance.levels import (
    MAX_LEVELS,
    StanceLevelParams,
    StanceLevels,
    height_update,
    stance_update_points,
)


def _stance_height_errors(path: str, seed: int, levels: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(estimated, true) IMU height at the stance samples, and the final position error (3,)."""
    truth = simulate_walk(path, 60.0, rate_hz=1000.0, seed=0)
    acc, gyr, _ = corrupt(
        truth.acc_b_mps2, truth.gyr_b_radps, truth.rate_hz, "mpu6500x4", seed=seed, axes="gyro-bias-calibrated"
    )
    cfg = NavConfig(profile=get_profile("mpu6500x4"), stance_levels=levels)
    nav, _ = navigate(truth.t_s, acc, gyr, truth.rate_hz, cfg)
    assert nav is not None
    true_pos = truth.pos_n_m[-len(nav) :]
    return nav.pos_n_m[nav.stance, 2], true_pos[nav.stance, 2], nav.pos_n_m[-1] - true_pos[-1]


@pytest.mark.parametrize("seed", [1, 2])
def test_level_walk_is_held_on_its_floor(seed: int) -> None:
    """Rectangle, 60 s: the stance height stays within 2 cm RMS of the truth (measured 0.13-0.66 cm for
    seeds 1-4 over 120 s; without the constraint 4.9-77 cm), and the end point is no worse."""
    est, true, end = _stance_height_errors("rectangle", seed, levels=True)
    est0, true0, end0 = _stance_height_errors("rectangle", seed, levels=False)
    rms, rms0 = float(np.sqrt(np.mean((est - true) ** 2))), float(np.sqrt(np.mean((est0 - true0) ** 2)))
    assert rms <= 0.02 and rms <= 0.2 * rms0
    assert np.linalg.norm(end) <= np.linalg.norm(end0) + 0.01


@pytest.mark.parametrize("seed", [1, 3])
def test_stairs_stay_stairs(seed: int) -> None:
    """Up and down a flight: the treads' heights are kept (the climb is not flattened), and the stance
    height error is lower than without the constraint (measured 1.4-2.3 cm RMS for seeds 1-4, against
    2.4-18 cm)."""
    est, true, _ = _stance_height_errors("stairs", seed, levels=True)
    est0, true0, _ = _stance_height_errors("stairs", seed, levels=False)
    assert true.max() > 1.0  # the walk climbs
    assert abs(est.max() - true.max()) <= 0.05 * true.max()
    rms, rms0 = float(np.sqrt(np.mean((est - true) ** 2))), float(np.sqrt(np.mean((est0 - true0) ** 2)))
    assert rms <= 0.035 and rms <= rms0 * 1.05


def _dense_update(x: np.ndarray, P: np.ndarray, level: int, z_level: float, r: float) -> tuple[np.ndarray, np.ndarray]:
    """The textbook Joseph-form update with full matrices (the reference)."""
    n = P.shape[0]
    H = np.zeros((1, n))
    H[0, 2] = 1.0
    if level >= 0:
        H[0, level] = -1.0
        z_level = float(x[level + 1])
    S = H @ P @ H.T + r
    K = P @ H.T / S
    y = z_level - x[2]
    A = np.eye(n) - K @ H
    P_new = A @ P @ A.T + r * K @ K.T
    return (K[:, 0] * y), P_new


@pytest.mark.parametrize("level", [-1, 15])
def test_height_update_matches_the_dense_joseph_form(level: int) -> None:
    rng = np.random.default_rng(3)
    n = 16
    L = rng.normal(size=(n, n)) * 0.01
    P = L @ L.T + 1e-6 * np.eye(n)
    P[6:9, :] *= 1e-2  # keep the attitude correction small: the reset's rotation is then close to I
    P[:, 6:9] *= 1e-2
    x = np.zeros(n + 1)
    x[6] = 1.0
    x[2], x[16] = 0.03, 0.01
    dx_ref, P_ref = _dense_update(x, P, level, 0.0, 1e-4)
    x_new, P_new = x.copy(), P.copy()
    height_update(x_new, P_new, level, 0.0, 1e-4, np.zeros((2, n)))
    np.testing.assert_allclose(x_new[:3], x[:3] + dx_ref[:3], rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(x_new[16], x[16] + dx_ref[15], rtol=1e-10, atol=1e-12)
    # the covariance differs from the dense one only by the attitude reset (second order in δθ)
    np.testing.assert_allclose(P_new[:6, :6], P_ref[:6, :6], rtol=1e-6, atol=1e-12)
    assert np.all(np.linalg.eigvalsh(P_new) > 0)


def _stand(levels: StanceLevels, x: np.ndarray, P: np.ndarray, z: float) -> tuple[np.ndarray, np.ndarray, float]:
    x[2] = z
    return levels.stance_update(x, P)


def _initial() -> tuple[np.ndarray, np.ndarray]:
    x = np.zeros(16)
    x[6] = 1.0
    return x, np.eye(eskf.N_STATE) * 1e-4


def test_levels_new_return_and_bounded() -> None:
    """A riser starts a level (no update), small changes are the same level, a known level is
    returned to, and at most ``level_states`` levels are states; the oldest leaves and keeps its height."""
    levels = StanceLevels(StanceLevelParams(level_states=2), 1000.0)
    x, P = _initial()
    x, P, z = _stand(levels, x, P, 0.01)
    assert z == 0.0 and abs(x[2]) < 0.01  # pulled towards the start floor
    heights = [0.17, 0.34, 0.51, 0.68]
    for h in heights:
        x, P, z = _stand(levels, x, P, h)
        assert math.isnan(z)  # a new level: placed, not updated against
        x, P, z = _stand(levels, x, P, h + 0.01)
        assert z == pytest.approx(h, abs=0.011)
    assert levels.counts.new_levels == 4
    assert P.shape == (eskf.N_STATE + 2, eskf.N_STATE + 2) and x.shape == (eskf.N_STATE + 3,)
    x, P, z = _stand(levels, x, P, 0.175)  # back on the first tread, no longer a state
    assert levels.counts.returns == 1 and z == pytest.approx(levels.levels_z_m[1])
    x, P, z = _stand(levels, x, P, 0.02)
    assert z == 0.0 and levels.counts.returns == 2
    assert np.all(np.linalg.eigvalsh(P) > -1e-15)


def test_a_state_that_is_not_finite_is_not_used() -> None:
    levels = StanceLevels(StanceLevelParams(), 1000.0)
    x, P = _initial()
    x[2] = math.nan
    x2, _, z = levels.stance_update(x, P)
    assert math.isnan(z) and levels.counts.not_finite == 1 and levels.counts.updates == 0 and x2 is x


def test_off_is_the_inertial_only_filter() -> None:
    levels = StanceLevels(StanceLevelParams(use=False), 1000.0)
    x, P = _initial()
    x[2] = 0.04
    x2, P2, z = levels.stance_update(x.copy(), P.copy())
    assert math.isnan(z) and x2[2] == 0.04 and np.array_equal(P2, P)


@pytest.mark.parametrize("after", [1, 3, 6])
def test_stance_update_points_across_batches(after: int) -> None:
    """One update per stance, after its ``after``-th sample or its last, however the flags are batched."""
    rng = np.random.default_rng(5)
    still = np.repeat(rng.random(40) < 0.5, rng.integers(1, 9, 40))
    whole, carried_whole = stance_update_points(still, 0, after)
    starts = np.flatnonzero(np.diff(np.r_[0, still.astype(int)]) == 1)
    ends = np.flatnonzero(np.diff(np.r_[still.astype(int), 0]) == -1)  # last sample of each stance
    expected = []
    for a, e in zip(starts.tolist(), ends.tolist(), strict=True):
        if e - a + 1 >= after:
            expected.append(a + after)
        elif e < still.size - 1:  # ended before it lasted ``after``; the record's end is not a stance's
            expected.append(e + 1)
    assert whole == expected
    for cut in range(1, still.size):
        first, carried = stance_update_points(still[:cut], 0, after)
        second, carried = stance_update_points(still[cut:], carried, after)
        assert first + [b + cut for b in second] == whole
        assert carried == carried_whole


def _stairs_with_axis_errors(seed: int = 2) -> tuple:  # type: ignore[type-arg]
    truth = simulate_walk("stairs", 60.0, rate_hz=1000.0, seed=0)
    acc, gyr, _ = corrupt(
        truth.acc_b_mps2, truth.gyr_b_radps, truth.rate_hz, "mpu6500x4", seed=seed, axes="gyro-bias-calibrated"
    )
    return truth, acc, gyr


def _batch(t: np.ndarray, acc: np.ndarray, gyr: np.ndarray, sl: slice) -> ImuBatch:
    idx = np.arange(t.size)[sl]
    return ImuBatch(t[sl], acc[sl], gyr[sl], idx, np.zeros(idx.size, np.int64))


def test_streamed_in_small_batches_equals_the_whole_run() -> None:
    """Live: the stance updates fall on the same samples however the stream is cut (new levels too)."""
    truth, acc, gyr = _stairs_with_axis_errors()
    cfg = NavConfig(profile=get_profile("mpu6500x4"))
    whole, _ = navigate(truth.t_s, acc, gyr, truth.rate_hz, cfg)
    nav = Navigator(cfg, truth.rate_hz)
    cuts = np.unique(np.concatenate([[0, truth.t_s.size], np.random.default_rng(1).integers(1, truth.t_s.size, 3000)]))
    outs = [nav.process(_batch(truth.t_s, acc, gyr, slice(a, b))) for a, b in itertools.pairwise(cuts)]
    assert whole is not None and nav.levels.counts.new_levels >= 10
    np.testing.assert_array_equal(np.concatenate([o.pos_n_m for o in outs if o is not None]), whole.pos_n_m)


def test_smoother_applies_the_levels_as_its_forward_filter_does() -> None:
    """The smoother's forward pass holds the levels as constants; its last sample is that causal
    filter's, bit for bit, and its height at footfalls is as good as the causal one's (seed 2: smoothed
    0.66 cm RMS, causal 1.15 cm with constant levels and 1.44 cm with level states; 12 cm without
    the constraint, smoothed or not)."""
    truth, acc, gyr = _stairs_with_axis_errors()
    cfg = NavConfig(profile=get_profile("mpu6500x4"))
    nav = Navigator(cfg, truth.rate_hz)
    nav.levels = StanceLevels(StanceLevelParams(level_states=0), truth.rate_hz)
    causal = nav.process(_batch(truth.t_s, acc, gyr, slice(None)))
    smoothed, _ = smooth_recording(truth.t_s, acc, gyr, truth.rate_hz, cfg)
    off, _ = smooth_recording(truth.t_s, acc, gyr, truth.rate_hz, NavConfig(profile=cfg.profile, stance_levels=False))
    assert causal is not None and smoothed is not None and off is not None
    np.testing.assert_array_equal(smoothed.pos_n_m[-1], causal.pos_n_m[-1])
    np.testing.assert_array_equal(smoothed.cov_pos_yaw[-1], causal.cov_pos_yaw[-1])
    st = causal.stance

    def rms(nb: NavBatch) -> float:
        return float(np.sqrt(np.mean((nb.pos_n_m[st, 2] - truth.pos_n_m[st, 2]) ** 2)))

    assert rms(smoothed) <= 1.1 * rms(causal) and rms(smoothed) <= 0.3 * rms(off)


def test_clearance_is_measured_from_the_stances_floor() -> None:
    """Inertial-only stairs: the clearance is the height above the level of the foot's stance (in swing,
    of the stance it left), so it is near zero in every stance instead of the tread's height above the
    start floor (seed 2: 0.54 cm RMS at footfalls, smoothed 0.19 cm; the climb is 4 m); the same with
    the smoother."""
    truth, acc, gyr = _stairs_with_axis_errors()
    cfg = NavConfig(profile=get_profile("mpu6500x4"))
    nav, _ = navigate(truth.t_s, acc, gyr, truth.rate_hz, cfg)
    smoothed, _ = smooth_recording(truth.t_s, acc, gyr, truth.rate_hz, cfg)
    assert nav is not None and smoothed is not None
    first = len(truth.t_s) - len(nav)
    st = truth.stance[first:] & nav.stance
    assert truth.pos_n_m[first:][st, 2].max() > 1.0
    for out in (nav, smoothed):
        assert float(np.sqrt(np.mean(out.clearance_m[st] ** 2))) <= 0.03
    # in swing the clearance tops a stair walk's foot lift (10-40 cm above the floor left), not metres
    assert 0.05 < float(np.max(nav.clearance_m)) < 0.6


def test_smoothing_does_not_depend_on_where_segments_cut_short_stances(shared_data: Path) -> None:
    """A PyShoe trial's stances come in 5-25 ms fragments, shorter than the update's 0.1 s, so their
    updates fall due after a stance's last sample, at the start of the next batch: with one-sample
    segments every such update lies on a segment boundary, after the segment's checkpoint."""
    rec = load_recording(shared_data / "pyshoe-vicon" / "2017-11-27-11-18-11.mat")
    n = 3000
    cfg = NavConfig(profile=get_profile(rec.profile))
    args = (rec.t_s[:n], rec.acc_b_mps2[:n], rec.gyr_b_radps[:n], rec.rate_hz, cfg)
    whole, _ = smooth_recording(*args)
    cut, _ = smooth_recording(*args, segment_samples=1)
    assert whole is not None and cut is not None
    np.testing.assert_array_equal(cut.pos_n_m, whole.pos_n_m)
    np.testing.assert_array_equal(cut.cov_pos_yaw, whole.cov_pos_yaw)


@pytest.mark.parametrize(
    ("rise_m", "swing_sigma_m", "kept_at_least", "kept_at_most"),
    [(0.06, 0.01, 0.99, 1.01), (0.04, 0.005, 0.85, 0.95), (0.02, 0.005, 0.4, 0.6), (0.01, 0.01, 0.0, 0.05)],
)
def test_a_ramp_is_kept_or_taken_for_drift(
    rise_m: float, swing_sigma_m: float, kept_at_least: float, kept_at_most: float
) -> None:
    """The documented limit: 25 strides up a ramp, each stride's height measured exactly but with the
    filter's height uncertainty growing by ``swing_sigma_m`` in the swing. A rise over 5 cm per stride
    starts a new level every stride and is kept; a smaller one is pulled towards the last level by
    each update, in part (a new level once the pull falls behind by 5 cm), and 1 cm per stride with
    1 cm of swing uncertainty is removed almost whole (README, Accuracy)."""
    levels = StanceLevels(StanceLevelParams(), 1000.0)
    x, P = _initial()
    P[:] = np.eye(eskf.N_STATE) * 1e-6
    for _ in range(25):
        x[2] += rise_m
        P[2, 2] += swing_sigma_m**2
        x, P, _ = levels.stance_update(x, P)
    assert kept_at_least * 25 * rise_m <= x[2] <= kept_at_most * 25 * rise_m


def test_levels_remembered_are_bounded() -> None:
    """A walk that makes a level at every stance (height drifting over 5 cm a stride) keeps at most
    ``MAX_LEVELS``: the start floor, the states and the recent ones stay, the oldest are forgotten."""
    levels = StanceLevels(StanceLevelParams(level_states=2), 1000.0)
    x, P = _initial()
    for k in range(1, MAX_LEVELS + 60):
        x, P, _ = _stand(levels, x, P, 0.17 * k)
    assert len(levels.levels_z_m) == MAX_LEVELS and levels.levels_z_m[0] == 0.0
    assert P.shape == (eskf.N_STATE + 2, eskf.N_STATE + 2)
    assert levels.floor_z_m == pytest.approx(0.17 * (MAX_LEVELS + 59))
    x, P, z = _stand(levels, x, P, 0.17 * (MAX_LEVELS + 50) + 0.01)  # a recent level: returned to
    assert z == pytest.approx(0.17 * (MAX_LEVELS + 50), abs=1e-9)
    x, P, z = _stand(levels, x, P, 0.17 * 5)  # an early one: forgotten, so a new level
    assert math.isnan(z)
